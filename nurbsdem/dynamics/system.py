"""A DEM system: particles + prescribed walls + a contact provider, advanced by deck steps.

Usage (what the solver does)::

    from nurbsdem.dynamics import DemSystem, ContactLaw, InterfaceTable, PrescribedMotion
    table = InterfaceTable(default=ContactLaw(en=1e5, cn=1e2, et=1e4, ct=0.0, mu=0.5))
    sysm = DemSystem(dt=1e-3, gravity=(0, 0, -9.81), interfaces=table)
    i = sysm.add_particle(mass, J0, x, R=R, material=0, centroid_file=shape.centroid,
                          radius=shape.bounding_radius)
    w = sysm.add_wall(PrescribedMotion.piecewise_linear([0, 1], [[0, 0, 0], [0, 0, -0.08]]))
    sysm.set_contact_provider(provider)        # provider(kin: Kinematics) -> ContactSet | None
    sysm.initialize()                          # first force evaluation, time-step control, E(0)
    for _ in range(n): sysm.step()             # one deck step = sysm.substeps internal steps
    e = sysm.energy(); r = sysm.wall_reaction; st = sysm.get_state(); sysm.set_state(st)

Global body indices in a ContactSet: particles 0..N-1 in the order added, walls N..N+W-1.

Time-step control (sub-stepping)
--------------------------------
The deck's Δt may exceed the explicit stability limit (the paper's 1e-3 s does for the small
particles: C–C Δt_cr = 4.7e-4 s).  :meth:`DemSystem.critical_time_step` estimates, for every
contact interface that can occur (particle–particle between the materials present, particle–wall),

    Δt_cr = (2/ω) (√(1+ζ²) − ζ),   ω = √(k/m*),   ζ = c / (2√(k m*))

for the normal mode (k = εn, c = cn, m* the smallest reduced mass of a possible pair — a wall's
mass is infinite, so m* = m) and the tangential mode (k = εt, c = ct, with the *rotational*
effective mass m_t = 1/(1/m + r²/I_min) per body, r its bounding radius, which for a sphere is
the exact 2m/7).  The safe step is ``safety × min Δt_cr`` (default safety 0.5) and a deck step is
split into ``substeps = ceil(Δt / Δt_safe)`` internal steps of ``dt_internal = Δt / substeps``
(logged on logger ``'nurbsdem'``).  The safety factor covers what the pair estimate leaves out:
an off-centre normal contact of a non-spherical body lowers its effective mass (by ≈ 20 % for the
paper's particles), several simultaneous contacts on one body add their stiffnesses (a factor
√2–√3 in ω in a pack), and the no-tension clip.

Instability guard
-----------------
After every internal step the state must be finite; after every deck step the mechanical energy
gain ``E_mech − E_mech(0) − W_ext`` and the balance error must stay below
``energy_tolerance × scale`` (scale = the largest kinetic + elastic energy seen so far, at least
Σ m|g| r).  Otherwise the system is rolled back to the state at the start of that deck step (the
last good state, still available as ``system.get_state()``) and :class:`InstabilityError` is
raised.  Runs are deterministic: the same inputs give bit-for-bit the same results.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any, Callable, Protocol

import numpy as np

from ..errors import InputError, NurbsdemError
from .energy import EnergyLedger, EnergySample, potential_energy
from .forces import (InterfaceTable, contact_forces, contact_velocities, kick_work,
                     match_history, store_history)
from .integrator import drift, half_kick, kinetic_energies, state_is_finite
from .rigid import PrescribedMotion, RigidBodies, Walls, omega_world

log = logging.getLogger("nurbsdem")


class InstabilityError(NurbsdemError):
    """The explicit integration became unstable (non-finite state or spurious energy gain).

    The system has been rolled back to the last good state (start of the failing deck step).
    Attributes: time (s) of that state, reason (str), step (deck step index).
    """

    def __init__(self, message: str, time: float, reason: str, step: int) -> None:
        super().__init__(message)
        self.time = time
        self.reason = reason
        self.step = step


@dataclass(frozen=True)
class Kinematics:
    """What a contact provider is given (SI units, world frame).

    t (s); x (N,3) centroids; R (N,3,3) file->world rotations; position (N,3) pose positions
    (x − R c, DEVNOTES); v (N,3) and omega (N,3) velocities (the half-step values of the
    integrator); wall_displacement, wall_velocity (W,3); n_particles N, n_bodies N+W.
    """

    t: float
    x: np.ndarray
    R: np.ndarray
    position: np.ndarray
    v: np.ndarray
    omega: np.ndarray
    wall_displacement: np.ndarray
    wall_velocity: np.ndarray
    n_particles: int
    n_bodies: int


class ContactProvider(Protocol):
    def __call__(self, kin: Kinematics) -> Any:  # returns a ContactSet (DEVNOTES) or None
        ...


@dataclass(frozen=True)
class ModeLimit:
    """Critical step of one contact mode: interface (mat_a, mat_b, 'pp'|'pw'), 'normal'|'tangential'."""

    interface: tuple
    mode: str
    m_eff: float
    omega: float
    zeta: float
    dt_cr: float


def critical_step(k: float, c: float, m: float) -> tuple[float, float, float]:
    """(ω rad/s, ζ, Δt_cr s) of a spring k (N/m) – dashpot c (N s/m) – mass m (kg) for the
    explicit scheme: Δt_cr = (2/ω)(√(1+ζ²) − ζ).  Δt_cr = inf when k = 0."""
    if k <= 0 or not math.isfinite(m):
        return 0.0, 0.0, math.inf
    omega = math.sqrt(k / m)
    zeta = c / (2.0 * math.sqrt(k * m))
    return omega, zeta, (2.0 / omega) * (math.sqrt(1.0 + zeta * zeta) - zeta)


def _smallest_pair(m_i: np.ndarray, m_j: np.ndarray | None) -> float:
    """Smallest reduced mass of a pair drawn from m_i (same group: two distinct) and m_j."""
    if m_j is None:
        if m_i.size < 2:
            return math.inf
        s = np.sort(m_i)
        return float(s[0] * s[1] / (s[0] + s[1]))
    if m_i.size == 0 or m_j.size == 0:
        return math.inf
    a, b = float(m_i.min()), float(m_j.min())
    return a * b / (a + b)


_STATE_KEYS = ("x", "q", "v", "L", "force", "torque", "hist_keys", "hist_springs",
               "c_a", "c_b", "c_point", "c_ftot", "c_fdn", "c_fdt", "c_fet", "c_fn", "c_eel", "c_stick",
               "c_key", "wall_d", "wall_u", "wall_work", "ledger")


class DemSystem:
    """Particles, walls, contact laws and a contact provider; advanced by deck steps of ``dt``.

    Parameters
    ----------
    dt: deck time step (s).
    gravity: (3,) m/s².
    interfaces: contact laws per material pair.
    safety: fraction of the estimated critical step used (0 < safety <= 1, default 0.5).
    substeps: force this number of internal steps per deck step (None: automatic).
    max_substeps: refuse (InputError) when more would be needed.
    energy_tolerance: relative tolerance of the instability guard (default 0.25).
    check_energy: enable the energy part of the guard.
    """

    def __init__(self, dt: float, gravity=(0.0, 0.0, -9.81), interfaces: InterfaceTable | None = None,
                 safety: float = 0.5, substeps: int | None = None, max_substeps: int = 100000,
                 energy_tolerance: float = 0.25, check_energy: bool = True, t0: float = 0.0) -> None:
        if not (dt > 0 and math.isfinite(dt)):
            raise InputError(f"time step must be positive, got {dt}")
        if not (0 < safety <= 1):
            raise InputError(f"time-step safety factor must be in (0, 1], got {safety}")
        if substeps is not None and int(substeps) < 1:
            raise InputError(f"substeps must be >= 1, got {substeps}")
        self.dt = float(dt)
        self.t0 = float(t0)
        self.gravity = np.asarray(gravity, dtype=float).reshape(3)
        self.interfaces = interfaces if interfaces is not None else InterfaceTable()
        self.safety = float(safety)
        self.forced_substeps = None if substeps is None else int(substeps)
        self.max_substeps = int(max_substeps)
        self.energy_tolerance = float(energy_tolerance)
        self.check_energy = bool(check_energy)
        self.bodies = RigidBodies()
        self.walls = Walls()
        self.provider: ContactProvider | None = None
        self.step_count = 0
        self.substeps = 1
        self.dt_internal = self.dt
        self.dt_critical = math.inf
        self.mode_limits: list[ModeLimit] = []
        self.last_contacts: Any = None
        self._initialized = False
        self._peak = 0.0
        #: (keys, springs) of tangential springs to start from (set before initialize()).
        self.initial_history: tuple[np.ndarray, np.ndarray] | None = None

    # ------------------------------------------------------------------ set-up
    def add_particle(self, mass: float, J0: np.ndarray, x, R=None, v=None, omega=None,
                     material: int = 0, centroid_file=None, radius: float = 0.0) -> int:
        """Add a particle (see :meth:`RigidBodies.add` for units); returns its global index."""
        self._check_not_initialized()
        return self.bodies.add(mass, J0, x, R=R, v=v, omega=omega, material=material,
                               centroid_file=centroid_file, radius=radius)

    def add_wall(self, motion: PrescribedMotion | None = None, material: int = 0, name: str = "") -> int:
        """Add a fixed (motion None) or prescribed-motion wall; returns its **global** index N+k
        (valid once all particles are added: add walls after particles)."""
        self._check_not_initialized()
        k = self.walls.add(motion, material, name)
        return self.bodies.n + k

    def set_contact_provider(self, provider: ContactProvider | Callable) -> None:
        """Register the callable that returns the ContactSet for a :class:`Kinematics`."""
        self.provider = provider

    def _check_not_initialized(self) -> None:
        if self._initialized:
            raise RuntimeError("bodies must be added before initialize()")

    @property
    def n_particles(self) -> int:
        return self.bodies.n

    @property
    def n_bodies(self) -> int:
        return self.bodies.n + self.walls.n

    @property
    def time(self) -> float:
        """Current time (s) = t0 + step_count·dt (no accumulation of round-off)."""
        return self.t0 + self.step_count * self.dt

    # ------------------------------------------------------------------ time-step control
    def critical_time_step(self) -> tuple[float, list[ModeLimit]]:
        """Estimated explicit critical step (s) over every possible interface and mode (module
        docstring), and the per-mode details."""
        b = self.bodies
        mats_p = sorted(set(int(m) for m in b.material))
        mats_w = sorted(set(int(m) for m in self.walls.material))
        r = b.radius
        rot = np.where(r > 0, r * r / b.I[:, 0], 2.5 / b.mass)      # r²/I_min (sphere if unknown)
        m_t = 1.0 / (1.0 / b.mass + rot)
        limits: list[ModeLimit] = []
        pairs = []
        for i, ma in enumerate(mats_p):
            for mb in mats_p[i:]:
                pairs.append(((ma, mb, "pp"), ma, mb, False))
            for mw in mats_w:
                pairs.append(((ma, mw, "pw"), ma, mw, True))
        for iface, ma, mb, wall in pairs:
            sel_a = b.material == ma
            if wall:
                mn, mtn = float(b.mass[sel_a].min()), float(m_t[sel_a].min())
            elif ma == mb:
                mn, mtn = _smallest_pair(b.mass[sel_a], None), _smallest_pair(m_t[sel_a], None)
            else:
                sel_b = b.material == mb
                mn = _smallest_pair(b.mass[sel_a], b.mass[sel_b])
                mtn = _smallest_pair(m_t[sel_a], m_t[sel_b])
            if not math.isfinite(mn):
                continue          # no such pair can occur (e.g. a single particle)
            try:
                law = self.interfaces.get(ma, mb)
            except InputError:
                continue          # undefined interface: an error if such a contact ever occurs
            for mode, k, c, m in (("normal", law.en, law.cn, mn), ("tangential", law.et, law.ct, mtn)):
                if not math.isfinite(m):
                    continue
                w, z, dtc = critical_step(k, c, m)
                limits.append(ModeLimit(iface, mode, m, w, z, dtc))
        dt_cr = min((lim.dt_cr for lim in limits), default=math.inf)
        return dt_cr, limits

    def _choose_substeps(self) -> None:
        self.dt_critical, self.mode_limits = self.critical_time_step()
        dt_safe = self.safety * self.dt_critical
        auto = 1 if not math.isfinite(dt_safe) else max(1, math.ceil(self.dt / dt_safe * (1 - 1e-12)))
        worst = min(self.mode_limits, key=lambda m: m.dt_cr) if self.mode_limits else None
        why = (f"critical step {self.dt_critical:.3g} s from the {worst.mode} mode of interface "
               f"{worst.interface} (m*={worst.m_eff:.4g} kg, omega={worst.omega:.4g} rad/s, "
               f"zeta={worst.zeta:.3g}), safety {self.safety}") if worst else "no contact modes"
        if self.forced_substeps is not None:
            self.substeps = self.forced_substeps
            if self.dt / self.substeps > dt_safe:
                log.warning("substeps forced to %d: internal step %.3g s exceeds the safe step "
                            "%.3g s (%s)", self.substeps, self.dt / self.substeps, dt_safe, why)
        else:
            if auto > self.max_substeps:
                raise InputError(f"time step {self.dt} s would need {auto} sub-steps "
                                 f"(> {self.max_substeps}); {why}")
            self.substeps = auto
        self.dt_internal = self.dt / self.substeps
        log.info("time step: deck dt %.4g s, %d sub-step(s) of %.4g s; %s", self.dt,
                 self.substeps, self.dt_internal, why)

    # ------------------------------------------------------------------ initialisation
    def initialize(self) -> None:
        """Freeze the body lists, choose the sub-stepping, evaluate the forces at t0 and record
        the initial mechanical energy.  Called by :meth:`step` when needed."""
        if self._initialized:
            return
        if self.provider is None:
            self.provider = lambda kin: None
        b = self.bodies
        self._inv_mass = 1.0 / b.mass
        self._inv_I = 1.0 / b.I
        nm = 1 + int(max(np.max(b.material, initial=0), np.max(self.walls.material, initial=0)))
        self._table = self.interfaces.as_array(nm)
        self._mat_all = np.concatenate([b.material, self.walls.material]).astype(np.int64)
        self._choose_substeps()
        ell = np.where(b.radius > 0, b.radius, np.sqrt(b.I.sum(axis=1) / (2 * b.mass)))
        self._scale_floor = max(float(np.sum(b.mass * np.linalg.norm(self.gravity) * ell)), 1e-300)
        self.hist_keys = np.zeros(0, dtype=np.int64)
        self.hist_springs = np.zeros((0, 3))
        if self.initial_history is not None:   # tangential springs carried over from a previous step
            self.hist_keys = np.array(self.initial_history[0], dtype=np.int64)
            self.hist_springs = np.array(self.initial_history[1], dtype=float).reshape(-1, 3)
        self.wall_work = np.zeros(self.walls.n)
        self.ledger = EnergyLedger()
        self._initialized = True
        self._evaluate(self.time, 0.0)
        if self.initial_history is not None:
            # carried-over springs bring their stored energy with them: none of it is dissipated
            self.ledger.tangential_spring_work = float(self.c_eel[:, 1].sum()) if self.c_eel.shape[0] else 0.0
        e = self.energy()
        self.ledger.initial_mechanical = e.mechanical
        self._peak = e.kinetic + e.elastic

    # ------------------------------------------------------------------ force evaluation
    def _kinematics(self, t: float) -> Kinematics:
        b = self.bodies
        R = b.rotations()
        return Kinematics(t=t, x=b.x.copy(), R=R, position=b.pose_positions(R), v=b.v.copy(),
                          omega=omega_world(b.q, b.L, self._inv_I),
                          wall_displacement=self.wall_d.copy(), wall_velocity=self.wall_u.copy(),
                          n_particles=b.n, n_bodies=self.n_bodies)

    def _all_kinematics(self, wall_u: np.ndarray | None = None
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        b = self.bodies
        pos = np.concatenate([b.x, self.wall_d])
        vel = np.concatenate([b.v, self.wall_u if wall_u is None else wall_u])
        omg = np.concatenate([omega_world(b.q, b.L, self._inv_I), np.zeros((self.walls.n, 3))])
        return pos, vel, omg

    def _evaluate(self, t: float, h: float) -> None:
        """Walls to time t, contact detection by the provider, Eq. 16–17, loads incl. gravity."""
        b = self.bodies
        self.wall_d, self.wall_u = self.walls.kinematics(t)
        cs = self.provider(self._kinematics(t))
        self.last_contacts = cs
        a, bb, pa, pb, nrm, dep, key = _unpack(cs, self.n_bodies)
        K = a.shape[0]
        if K and np.isnan(self._table[self._mat_all[a], self._mat_all[bb], 0]).any():
            raise InputError("a contact occurred between materials with no contact interface")
        spring = match_history(self.hist_keys, self.hist_springs, key)
        B = self.n_bodies
        force = np.zeros((B, 3))
        torque = np.zeros((B, 3))
        point = np.empty((K, 3))
        ftot = np.empty((K, 3))
        fdn = np.empty((K, 3))
        fdt = np.empty((K, 3))
        fet = np.empty((K, 3))
        fn = np.empty(K)
        eel = np.empty((K, 2))
        stick = np.empty(K, dtype=np.int64)
        pos, vel, omg = self._all_kinematics()
        slip = contact_forces(a, bb, pa, pb, nrm, dep, pos, vel, omg, self._mat_all, self._table,
                              spring, h, force, torque, point, ftot, fdn, fdt, fet, fn, eel, stick)
        self.last_slip_work = slip
        self.hist_keys, self.hist_springs = store_history(key, spring)
        force[: b.n] += b.mass[:, None] * self.gravity[None, :]
        self.force, self.torque = force, torque
        self.c_a, self.c_b, self.c_point, self.c_ftot = a, bb, point, ftot
        self.c_fet = fet
        self.c_fdn, self.c_fdt, self.c_fn, self.c_eel, self.c_stick, self.c_key = fdn, fdt, fn, eel, stick, key

    def _kick(self, hk: float, wall_u: np.ndarray) -> None:
        """Half kick with the stored loads, accumulating the exact discrete work of the impulses.

        wall_u (W,3): the walls' mean velocity over the current internal step, (d(t+h) − d(t))/h,
        so that the external work adds up to force × the walls' exact displacement (trapezoidal
        in the force, no error at kinks of a piecewise-linear motion)."""
        b = self.bodies
        K = self.c_a.shape[0]
        if K:
            pos, vel, omg = self._all_kinematics(wall_u)
            w0 = contact_velocities(self.c_a, self.c_b, self.c_point, pos, vel, omg)
        half_kick(b.v, b.L, self.force, self.torque, self._inv_mass, hk)
        if K:
            pos, vel, omg = self._all_kinematics(wall_u)
            w1 = contact_velocities(self.c_a, self.c_b, self.c_point, pos, vel, omg)
            acc = np.zeros(4)
            kick_work(self.c_a, self.c_b, b.n, w0, w1, wall_u, self.c_ftot, self.c_fdn,
                      self.c_fdt, self.c_fet, hk, acc, self.wall_work)
            self.ledger.dissipated_normal += acc[0]
            self.ledger.dissipated_tangential += acc[1]
            self.ledger.external_work += acc[2]
            self.ledger.tangential_spring_work += acc[3]

    def _internal_step(self, t_new: float, h: float) -> None:
        b = self.bodies
        d_new, _ = self.walls.kinematics(t_new)
        u_mean = (d_new - self.wall_d) / h
        self._kick(0.5 * h, u_mean)
        drift(b.x, b.v, b.q, b.L, self._inv_I, h)
        self._evaluate(t_new, h)
        self._kick(0.5 * h, u_mean)

    # ------------------------------------------------------------------ stepping
    def step(self) -> EnergySample:
        """Advance one deck step (``substeps`` internal steps); returns the energies at its end.

        Raises InstabilityError (after rolling back to the state at the start of the step)."""
        self.initialize()
        good = self.get_state()
        t_start = self.time
        n = self.substeps
        try:
            for k in range(1, n + 1):
                t_new = t_start + self.dt * k / n
                with np.errstate(all="ignore"):
                    self._internal_step(t_new, self.dt_internal)
                b = self.bodies
                if not (state_is_finite(b.x, b.v, b.q, b.L) and np.isfinite(self.force).all()):
                    raise _Unstable(f"non-finite state at t = {t_new:.6g} s")
            self.step_count += 1
            e = self.energy()
            self._check_energy(e)
        except _Unstable as exc:
            self.set_state(good)
            msg = (f"integration unstable in the deck step starting at t = {t_start:.6g} s: {exc}; "
                   f"deck dt {self.dt:.4g} s with {n} sub-step(s) of {self.dt_internal:.4g} s, "
                   f"estimated critical step {self.dt_critical:.4g} s (safety {self.safety}). "
                   f"Rolled back to the last good state (t = {t_start:.6g} s); reduce the time "
                   f"step or let the solver sub-step")
            log.error(msg)
            raise InstabilityError(msg, time=t_start, reason=str(exc), step=self.step_count) from None
        self._peak = max(self._peak, e.kinetic + e.elastic)
        return e

    def advance(self, n_steps: int, callback: Callable[["DemSystem", EnergySample], None] | None = None
                ) -> EnergySample | None:
        """Run n deck steps, calling ``callback(system, energy)`` after each; returns the last energy."""
        e = None
        for _ in range(int(n_steps)):
            e = self.step()
            if callback is not None:
                callback(self, e)
        return e

    def _check_energy(self, e: EnergySample) -> None:
        if not self.check_energy:
            return
        scale = max(self._peak, self._scale_floor)
        gain = e.mechanical - e.initial_mechanical - e.external_work
        tol = self.energy_tolerance * scale
        if not math.isfinite(e.mechanical) or not math.isfinite(e.balance_error):
            raise _Unstable("non-finite energy")
        if gain > tol:
            raise _Unstable(f"mechanical energy grew by {gain:.4g} J without external work "
                            f"(tolerance {tol:.3g} J)")
        if abs(e.balance_error) > tol:
            raise _Unstable(f"energy balance error {e.balance_error:.4g} J exceeds {tol:.3g} J")

    # ------------------------------------------------------------------ outputs
    def energy(self) -> EnergySample:
        """Energies at the current state (J); see :mod:`nurbsdem.dynamics.energy`."""
        b = self.bodies
        et, er = kinetic_energies(b.mass, b.v, b.q, b.L, self._inv_I)
        eel = self.c_eel.sum(axis=0) if self.c_eel.shape[0] else np.zeros(2)
        eel = [float(eel[0]), float(eel[1])]
        lg = self.ledger
        return EnergySample(time=self.time, kinetic_translational=float(et),
                            kinetic_rotational=float(er),
                            potential=potential_energy(b.mass, b.x, self.gravity),
                            elastic_normal=float(eel[0]), elastic_tangential=float(eel[1]),
                            dissipated_normal=lg.dissipated_normal,
                            dissipated_tangential=lg.dissipated_tangential,
                            dissipated_friction=lg.tangential_spring_work - float(eel[1]),
                            external_work=lg.external_work, initial_mechanical=lg.initial_mechanical)

    @property
    def wall_contact_force(self) -> np.ndarray:
        """(W,3) sum of the contact forces the particles exert on each wall (N), last evaluation."""
        return self.force[self.n_particles:].copy()

    @property
    def wall_reaction(self) -> np.ndarray:
        """(W,3) force that holds each wall on its prescribed path (N) = −wall_contact_force."""
        return -self.wall_contact_force

    @property
    def wall_displacement(self) -> np.ndarray:
        """(W,3) current wall displacements (m)."""
        return self.wall_d.copy()

    def contact_table(self) -> dict[str, np.ndarray]:
        """Per-contact results of the last evaluation: body_a, body_b, key, point (application
        point, m), force (on B, N), fn (N), stick (1/0), elastic (K,2) J."""
        return dict(body_a=self.c_a.copy(), body_b=self.c_b.copy(), key=self.c_key.copy(),
                    point=self.c_point.copy(), force=self.c_ftot.copy(), fn=self.c_fn.copy(),
                    stick=self.c_stick.copy(), elastic=self.c_eel.copy())

    # ------------------------------------------------------------------ checkpoints
    def get_state(self) -> dict[str, np.ndarray]:
        """Complete dynamic state as a dict of numpy arrays (copies; np.savez-friendly): body
        state, last loads, tangential histories, last contact data, energy ledger, counters.
        Restoring it into a system built the same way continues bit-for-bit."""
        self.initialize()
        st = {k: np.array(getattr(self, k), copy=True) for k in _STATE_KEYS
              if k not in ("x", "q", "v", "L", "ledger")}
        b = self.bodies
        st.update(x=b.x.copy(), q=b.q.copy(), v=b.v.copy(), L=b.L.copy(),
                  ledger=self.ledger.to_array(),
                  counters=np.array([self.step_count, self.substeps], dtype=np.int64),
                  scalars=np.array([self.t0, self.dt, self._peak]))
        return st

    def set_state(self, st: dict[str, np.ndarray]) -> None:
        """Restore a state from :meth:`get_state` (the system must have the same bodies/walls)."""
        self.initialize()
        b = self.bodies
        if st["x"].shape != b.x.shape or st["wall_d"].shape != (self.walls.n, 3):
            raise InputError("checkpoint does not match the system's bodies and walls")
        b.x, b.q, b.v, b.L = (np.array(st[k], dtype=float, copy=True) for k in ("x", "q", "v", "L"))
        for k in _STATE_KEYS:
            if k in ("x", "q", "v", "L", "ledger"):
                continue
            setattr(self, k, np.array(st[k], copy=True))
        self.ledger = EnergyLedger.from_array(st["ledger"])
        self.step_count = int(st["counters"][0])
        self.t0 = float(st["scalars"][0])
        if float(st["scalars"][1]) != self.dt:
            raise InputError("checkpoint was written with a different deck time step")
        self._peak = float(st["scalars"][2])


class _Unstable(Exception):
    pass


def _unpack(cs: Any, n_bodies: int):
    """Contiguous typed arrays from a ContactSet (duck-typed, DEVNOTES); None or K=0 -> empty."""
    if cs is None or len(np.asarray(cs.body_a)) == 0:
        e3 = np.zeros((0, 3))
        ei = np.zeros(0, dtype=np.int64)
        return ei, ei.copy(), e3, e3.copy(), e3.copy(), np.zeros(0), ei.copy()
    a = np.ascontiguousarray(cs.body_a, dtype=np.int64)
    b = np.ascontiguousarray(cs.body_b, dtype=np.int64)
    key = getattr(cs, "key", None)
    key = a * n_bodies + b if key is None else np.ascontiguousarray(key, dtype=np.int64)
    return (a, b, np.ascontiguousarray(cs.point_a, dtype=float),
            np.ascontiguousarray(cs.point_b, dtype=float),
            np.ascontiguousarray(cs.normal, dtype=float),
            np.ascontiguousarray(cs.depth, dtype=float), key)

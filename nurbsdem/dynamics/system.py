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
    done = sysm.steps(n)                       # or up to n at once (compiled deck steps)
    e = sysm.energy(); r = sysm.wall_reaction; st = sysm.get_state(); sysm.set_state(st)

Global body indices in a ContactSet: particles 0..N-1 in the order added, walls N..N+W-1.

Time-step control (sub-stepping)
--------------------------------
The deck's Δt may exceed the explicit stability limit (the paper's 1e-3 s does for the small
particles: C–C Δt_cr = 4.7e-4 s).  A deck step is split into ``substeps`` internal steps of
``dt_internal = Δt / substeps``, with ``dt_internal <= safety × Δt_cr`` (default safety 0.5) and
Δt_cr the smaller of two estimates (:mod:`nurbsdem.dynamics.stepcontrol`):

* **a priori**, for contacts that may appear anywhere (:meth:`DemSystem.critical_time_step`):
  Δt_cr = (2/ω)(√(1+ζ²) − ζ), ω = √(k/m*), ζ = c/(2√(k m*)) for every interface that can occur
  and its normal (εn, cn) and tangential (εt, ct) modes, m* the smallest reduced *effective*
  mass of a possible pair: each body's worst point compliance over its surface
  (``compliance=`` of :meth:`DemSystem.add_particle`, from
  :func:`~nurbsdem.dynamics.stepcontrol.shape_compliance`; without it a sphere of the body's
  bounding radius is assumed);
* **the contact network**, re-evaluated after every deck step from the contacts present and
  the separated pairs that can close within one deck step: the highest frequency and damping
  rate of the whole linearised network (Lanczos on the mass-scaled stiffness and damping
  operators, with each contact's true lever arms), so that a body with many contacts, or an
  off-centre contact on a flat body, is seen.  After every deck step a rigorous bound (block
  Gershgorin, O(K)) is compared with its value at the last Lanczos estimate; the Lanczos
  estimate is repeated when the bound shows a stiffer network that the present count might
  not cover, and every ``NETWORK_RECHECK_STEPS`` deck steps.

With ``implicit_damping`` (the deck's ``Damping Implicit``) the normal dashpots act at the
velocity after each evaluation's two half kicks (:mod:`nurbsdem.dynamics.implicit`, stable
whatever the damping) and both estimates leave them out of the damping rate γ.

The count rises at once when the network needs it and falls again (with 20 % hysteresis) when
the pack loosens; every change is logged on logger ``'nurbsdem'`` with the reason (the particle
that dominates the stiffest mode and its number of contacts).

Instability guard
-----------------
After every internal step the state must be finite and no particle may be in **period-2
motion** (half-step velocities reversing at every internal step, which the full-step kinetic
energy of the monitors cannot see; :func:`~nurbsdem.dynamics.stepcontrol.alternation_update`);
after every deck step the mechanical energy gain ``E_mech − E_mech(0) − W_ext`` and the balance
error must stay below ``energy_tolerance × scale`` (scale = the largest kinetic + elastic energy
seen so far, at least Σ m|g| r).  Otherwise the deck step is rolled back and **repeated with
twice the sub-steps** (the refinement is kept, and halved again after
``REFINE_DECAY_STEPS`` quiet deck steps), up to ``max_refinements`` times; only then is the
system left at the last good state (the start of that deck step, ``system.get_state()``) and
:class:`InstabilityError` raised, with a diagnosis (failed contact problems, penetration
depth) instead of advice to reduce a time step that was already refined.
Runs are deterministic: the same inputs give bit-for-bit the same results.
"""
from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass
from typing import Any, Callable, Protocol

import numpy as np

from ..errors import InputError, NurbsdemError
from ..geometry.rotation import matrix_to_quat
from ..jit import launch_threads
from .accuracy import accuracy_budget, after_accepted, repeat_for_accuracy
from .energy import EnergyLedger, EnergySample, balance_terms, energy_terms
from .forces import InterfaceTable, add_kick_work, match_history, store_history
from .laws import needs_contact_radius
from .laws.engine import engine_kernels
from .laws.table import CN, CT, EN, ET
from .integrator import drift, kick_with_terms, state_is_finite
from .monitor import MonitorSample, StateSample, contact_output_of, energy_sample
from .rigid import PrescribedMotion, RigidBodies, Walls, body_poses, omega_world
from .deck_steps import (ACTIVE_MAX, ACTIVE_SUM, CONTROL, DEGENERATED_SUM, GUARD, REFINE,
                         DeckSteps)
from .stepcontrol import (ALTERNATION_STEPS, FALL_HYSTERESIS, HEAVY_SUBSTEPS,
                          NETWORK_BOUND_SLACK, NETWORK_RECHECK_STEPS, REFINE_DECAY_STEPS,
                          alternation_update, body_speeds, contact_network, critical_step,
                          critical_step_from_rates, needed_substeps, network_count_stands,
                          network_gershgorin, network_rates, periodic_recheck)

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
    (x − R c, docs/conventions.md); v (N,3) and omega (N,3) velocities (the half-step values
    of the integrator); wall_displacement, wall_velocity (W,3); n_particles N, n_bodies N+W.
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
    def __call__(self, kin: Kinematics) -> Any:  # a ContactSet (docs/conventions.md) or None
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


#: the parts of the solver's "forces + integration" time a system measures
#: (:attr:`DemSystem.split`): the integration (half kicks with their work, the period-2 watch,
#: drift), the contact forces (the poses for the search, contact arrays, histories and loads,
#: with MPI the exchange of the ghosts' loads; not the search, the LCPs and the dashpots),
#: the implicit dashpots, the time-step control.  What the solver's figure holds beyond them:
#: the guards, snapshots and monitor rows of the deck steps and the Python around the
#: compiled loop
SPLIT_PARTS = ("integration", "contact forces", "implicit dashpots", "time-step control")

_STATE_KEYS = ("x", "q", "v", "L", "force", "torque", "hist_keys", "hist_springs",
               "c_a", "c_b", "c_point", "c_normal", "c_ftot", "c_fdn", "c_fdt", "c_fet", "c_fn",
               "c_eel", "c_stick", "c_key", "wall_d", "wall_u", "wall_work", "ledger",
               "alt_count", "alt_prev_v", "alt_prev_L", "c_coeffs", "c_radius")

#: the arrays of the state besides the bodies' x, q, v, L that the compiled deck steps change
#: in place (:func:`~nurbsdem.dynamics.deck_steps.run_deck_steps`)
_LOOP_IN_PLACE = ("wall_work", "alt_count", "alt_prev_v", "alt_prev_L")



@dataclass(frozen=True)
class StepTally:
    """What the last :meth:`DemSystem.steps` did: internal steps (the sub-steps actually run;
    a repeated deck step counts once, with the count that passed), and the sum and maximum
    over its deck steps of the active contacts at their ends; and the monitor samples taken at the
    ends of the deck steps asked for (:meth:`DemSystem.steps`)."""

    substeps: int = 0
    active_sum: int = 0
    active_max: int = 0
    #: sums over its deck steps of the degenerated and the failed contacts at their ends
    degenerated_sum: int = 0
    failed_sum: int = 0
    #: MonitorSample of each deck step asked for, in order
    samples: tuple = ()
    #: StateSample of each deck step asked for but the last one done, in order
    #: (:meth:`DemSystem.steps`)
    states: tuple = ()


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
    max_refinements: how often a deck step found unstable is repeated with twice the sub-steps
        before :class:`InstabilityError` is raised (0: stop at once).
    watch_period2: enable the period-2 part of the guard (disable only to demonstrate it).
    implicit_damping: implicit normal dashpots (:mod:`nurbsdem.dynamics.implicit`); one MPI
        rank only.
    accuracy: η of the accuracy control (:mod:`nurbsdem.dynamics.accuracy`): a deck step whose
        energy-balance error grows by more than η × the energy scale is repeated with more
        sub-steps; None: off.
    """

    def __init__(self, dt: float, gravity=(0.0, 0.0, -9.81), interfaces: InterfaceTable | None = None,
                 safety: float = 0.5, substeps: int | None = None, max_substeps: int = 100000,
                 energy_tolerance: float = 0.25, check_energy: bool = True, t0: float = 0.0,
                 max_refinements: int = 3, watch_period2: bool = True,
                 implicit_damping: bool = False, accuracy: float | None = None) -> None:
        if not (dt > 0 and math.isfinite(dt)):
            raise InputError(f"time step must be positive, got {dt}")
        if not (0 < safety <= 1):
            raise InputError(f"time-step safety factor must be in (0, 1], got {safety}")
        if substeps is not None and int(substeps) < 1:
            raise InputError(f"substeps must be >= 1, got {substeps}")
        if accuracy is not None and not (0 < accuracy < 1):
            raise InputError(f"accuracy must be in (0, 1), got {accuracy}")
        if accuracy is not None and substeps is not None:
            raise InputError("forced substeps and the accuracy control exclude each other")
        launch_threads()
        self.dt = float(dt)
        self.t0 = float(t0)
        self.gravity = np.asarray(gravity, dtype=float).reshape(3)
        self.interfaces = interfaces if interfaces is not None else InterfaceTable()
        self.safety = float(safety)
        self.forced_substeps = None if substeps is None else int(substeps)
        self.max_substeps = int(max_substeps)
        self.max_refinements = int(max_refinements)
        self.watch_period2 = bool(watch_period2)
        #: normal dashpots at the end of each internal step (:mod:`.implicit`); the time-step
        #: control then leaves them out of the damping rate of Eq. (1)
        self.implicit_damping = bool(implicit_damping)
        #: active-set rounds and CG iterations of the implicit dashpots so far
        self.dashpot_solves = np.zeros(3, np.int64)
        #: seconds spent so far in the parts of the solver's "forces + integration" time
        #: (:data:`SPLIT_PARTS`: the integration, the contact forces, the implicit dashpots of
        #: :meth:`_implicit_dashpots`, the time-step control of :meth:`_control_step`), the
        #: compiled deck steps' included
        self.split = dict.fromkeys(SPLIT_PARTS, 0.0)
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
        self.dt_apriori = math.inf      # a-priori critical step (s), from the possible pairs
        self.dt_network = math.inf      # critical step of the current contact network (s)
        self.dt_bound = math.inf        # its Gershgorin lower bound at the last exact estimate
        self.network_estimates = 0      # exact (Lanczos) estimates taken so far
        self.refine = 1                 # factor on the sub-steps after a guard fired
        self.calm_steps = 0             # deck steps since the guard last fired
        #: η of the accuracy control (:mod:`.accuracy`; None: off), its factor on the
        #: sub-steps of the stability control, its calm deck steps in a row, and the deck
        #: steps it repeated so far
        self.accuracy = None if accuracy is None else float(accuracy)
        self.acc_refine = 1
        self.acc_calm = 0
        #: the balance error's growth (J) in the last rejected attempt at the present deck
        #: step (inf: none)
        self.acc_last_growth = math.inf
        self.accuracy_repeats = 0
        self.failed_in_step = 0         # failed contact problems reported in the last deck step
        self._warned_heavy = False
        self._apriori_zeta = self._network_zeta = 0.0
        self.last_contacts: Any = None
        self._compliance: list[tuple[float, float] | None] = []
        self._initialized = False
        self._peak = 0.0
        #: run scenes in compiled deck steps (:meth:`steps`)
        self.compiled_steps = True
        self._deck_steps = None
        #: (W,6) per wall: the angular velocity (rad/s) and the centre (m) it turns about (a
        #: mesh or surface wall, :mod:`nurbsdem.contact.curved_walls`); None: no wall turns
        self.wall_spin: np.ndarray | None = None
        self.last_steps = StepTally()
        #: (keys, springs) of tangential springs to start from (set before initialize()).
        self.initial_history: tuple[np.ndarray, np.ndarray] | None = None
        #: the domain decomposition of a run on several MPI ranks
        #: (:class:`nurbsdem.parallel.Domain`, set before initialize()); None: serial
        self.domain = None

    # ------------------------------------------------------------------ set-up
    def add_particle(self, mass: float, J0: np.ndarray, x, R=None, v=None, omega=None,
                     material: int = 0, centroid_file=None, radius: float = 0.0,
                     compliance: tuple[float, float] | None = None) -> int:
        """Add a particle (see :meth:`RigidBodies.add` for units); returns its global index.

        compliance: (g_n, g_t) the body's worst normal and tangential point compliances (1/kg,
        :func:`~nurbsdem.dynamics.stepcontrol.shape_compliance`) for the a-priori step
        estimate; None: a sphere of bounding radius ``radius`` (g_n = 1/m, g_t = 1/m + r²/I)."""
        self._check_not_initialized()
        i = self.bodies.add(mass, J0, x, R=R, v=v, omega=omega, material=material,
                            centroid_file=centroid_file, radius=radius)
        self._compliance.append(None if compliance is None else
                                (float(compliance[0]), float(compliance[1])))
        return i

    def add_particles(self, particles: list[dict]) -> None:
        """Add many particles at once (each a mapping of :meth:`add_particle`'s arguments;
        O(N) where N calls of :meth:`add_particle` cost O(N²))."""
        self._check_not_initialized()
        rows = [dict(p) for p in particles]
        compliance = [r.pop("compliance", None) for r in rows]
        self.bodies.add_many(rows)
        self._compliance.extend(None if g is None else (float(g[0]), float(g[1]))
                                for g in compliance)

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
        m_n, m_t = self._effective_masses()
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
                mn, mtn = float(m_n[sel_a].min()), float(m_t[sel_a].min())
            elif ma == mb:
                mn, mtn = _smallest_pair(m_n[sel_a], None), _smallest_pair(m_t[sel_a], None)
            else:
                sel_b = b.material == mb
                mn = _smallest_pair(m_n[sel_a], m_n[sel_b])
                mtn = _smallest_pair(m_t[sel_a], m_t[sel_b])
            if not math.isfinite(mn):
                continue          # no such pair can occur (e.g. a single particle)
            try:
                law = self.interfaces.get(ma, mb)
            except InputError:
                continue          # undefined interface: an error if such a contact ever occurs
            row = law.as_row()      # its EN..CT columns: the law's linearisation
            cn = 0.0 if self.implicit_damping else float(row[CN])
            for mode, k, c, m in (("normal", float(row[EN]), cn, mn),
                                  ("tangential", float(row[ET]), float(row[CT]), mtn)):
                if not math.isfinite(m):
                    continue
                w, z, dtc = critical_step(k, c, m)
                limits.append(ModeLimit(iface, mode, m, w, z, dtc))
        dt_cr = min((lim.dt_cr for lim in limits), default=math.inf)
        return dt_cr, limits

    def _effective_masses(self) -> tuple[np.ndarray, np.ndarray]:
        """(N,) worst normal and tangential effective masses (kg) of each particle's contacts."""
        b = self.bodies
        r = b.radius
        rot = np.where(r > 0, r * r / b.I[:, 0], 2.5 / b.mass)      # r²/I_min (sphere if unknown)
        g_n = 1.0 / b.mass
        g_t = 1.0 / b.mass + rot
        for i, g in enumerate(self._compliance):
            if g is not None:
                g_n[i], g_t[i] = g
        return 1.0 / g_n, 1.0 / g_t

    def _apriori_limit(self) -> None:
        """The a-priori critical step over the possible pairs (computed once per system)."""
        self.dt_apriori, self.mode_limits = self.critical_time_step()
        worst = min(self.mode_limits, key=lambda m: m.dt_cr) if self.mode_limits else None
        self._apriori_why = (
            f"{worst.mode} mode of interface {worst.interface} (m*={worst.m_eff:.4g} kg, "
            f"omega={worst.omega:.4g} rad/s, zeta={worst.zeta:.3g})") if worst else "no contact modes"
        self._apriori_zeta = worst.zeta if worst else 0.0

    def _network(self):
        """The contacts of the last evaluation plus the separated pairs that can close within
        one deck step (:func:`~nurbsdem.dynamics.stepcontrol.contact_network`): (a, b, point,
        normal, coeffs (K,4)), or None when there is none.  The contacts keep their own
        (tangent) coefficients from the force evaluation (Hertz: they grow with the overlap)."""
        a, bb = self.c_a, self.c_b
        k = a.shape[0]
        coeffs = self.c_coeffs
        if coeffs.ndim != 2 or coeffs.shape[0] != k:
            coeffs = np.ascontiguousarray(self._table[self._mat_all[a], self._mat_all[bb]][:, :4])
        cs = self.last_contacts
        if getattr(cs, "near_gap", None) is not None and len(cs.near_gap):
            near = (np.asarray(cs.near_a, np.int64), np.asarray(cs.near_b, np.int64),
                    np.asarray(cs.near_point, float), np.asarray(cs.near_normal, float),
                    np.asarray(cs.near_gap, float))
        else:
            near = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)),
                    np.zeros((0, 3)), np.zeros(0))
        b = self.bodies
        speed = body_speeds(b.v, omega_world(b.q, b.L, self._inv_I), self._ell, self.wall_u)
        net = contact_network(a, bb, self.c_point, self.c_normal, coeffs, *near, speed, self.dt,
                              self._g_norm, self._table, self._mat_all)
        if self.implicit_damping:
            net[4][:, 1] = 0.0      # implicit normal dashpots do not limit the step
        return net if net[0].shape[0] else None

    def _network_bound(self, net) -> float:
        """A lower bound (s) of the network's critical step, from the Gershgorin bounds of its
        frequency and damping rate (O(K), every deck step)."""
        if net is None:
            return math.inf
        b = self.bodies
        omega2, gamma = network_gershgorin(*net, b.x, b.principal_rotations(), self._inv_mass,
                                           self._inv_I, False)   # the compiled loop's types
        return critical_step_from_rates(omega2, gamma)

    def _count_stands(self, net) -> bool:
        """The gate: whether the present sub-step count stands without the exact estimate
        (:func:`~nurbsdem.dynamics.stepcontrol.network_count_stands`; no network: it does)."""
        if net is None:
            return True
        b = self.bodies
        return bool(network_count_stands(*net, b.x, b.principal_rotations(), self._inv_mass,
                                         self._inv_I, self.dt, self.safety, self.dt_apriori,
                                         self.dt_bound, NETWORK_BOUND_SLACK, self.refine,
                                         self.substeps))

    def _network_limit(self, net) -> tuple[float, str]:
        """Critical step (s) of the network ``net`` (:meth:`_network`) by Lanczos, and why."""
        if net is None:
            return math.inf, "no contacts"
        b = self.bodies
        a, bb, p, n, coeffs = net
        args = (a, bb, p, n, coeffs, b.x, b.principal_rotations(), b.mass, b.I)
        omega2, gamma, body = (network_rates(*args) if self.domain is None
                               else self.domain.on_root(network_rates, *args))
        dt = critical_step_from_rates(omega2, gamma)
        self._network_zeta = gamma / (2.0 * math.sqrt(omega2)) if omega2 > 0 else 0.0
        n_contacts = int(np.count_nonzero(a == body) + np.count_nonzero(bb == body))
        why = (f"contact network of {a.shape[0]} pairs ({self.c_a.shape[0]} in contact): highest "
               f"frequency {math.sqrt(omega2):.4g} rad/s, damping rate {gamma:.4g} 1/s, "
               f"centred on particle {body} with {n_contacts} contacts")
        return dt, why

    def _needed_substeps(self, dt_safe: float) -> int:
        """Sub-steps that keep the internal step within the safe step dt_safe (s)."""
        return int(needed_substeps(self.dt, dt_safe))

    def _control_step(self, initial: bool = False) -> None:
        """Choose the sub-steps of the next deck step from both limits (module docstring);
        its time is added to ``split``."""
        if not initial and self.forced_substeps is not None:
            return
        t0 = time.perf_counter()
        try:
            self._choose_substeps(initial)
        finally:
            self.split["time-step control"] += time.perf_counter() - t0

    def _choose_substeps(self, initial: bool) -> None:
        """:meth:`_control_step` (the sub-step count and its log or error)."""
        net = self._network()
        if not initial and not periodic_recheck(self.step_count, NETWORK_RECHECK_STEPS,
                                                self.refine, FALL_HYSTERESIS, self.substeps):
            if self._count_stands(net):
                return      # no stiffer than at the last exact estimate, or allowed anyway
        self.dt_bound = self._network_bound(net)
        self.dt_network, net_why = self._network_limit(net)
        self.network_estimates += 1
        self.dt_critical = min(self.dt_apriori, self.dt_network)
        dt_safe = self.safety * self.dt_critical
        why = (f"critical step {self.dt_critical:.3g} s from the "
               + (self._apriori_why if self.dt_apriori <= self.dt_network else net_why)
               + f", safety {self.safety}")
        if self.forced_substeps is not None:
            self.substeps = self.forced_substeps
            self.dt_internal = self.dt / self.substeps
            if self.dt_internal > dt_safe:
                log.warning("substeps forced to %d: internal step %.3g s exceeds the safe step "
                            "%.3g s (%s)", self.substeps, self.dt_internal, dt_safe, why)
            log.info("time step: deck dt %.4g s, %d sub-step(s) of %.4g s (forced); %s", self.dt,
                     self.substeps, self.dt_internal, why)
            return
        need = self._needed_substeps(dt_safe) * self.refine
        if need > self.max_substeps:
            raise InputError(f"time step {self.dt} s would need {need} sub-steps "
                             f"(> {self.max_substeps}); {why}")
        old = self.substeps
        if initial or need > old or need < FALL_HYSTERESIS * old:
            self.substeps = need
        self.dt_internal = self.dt / self.substeps
        if self.substeps >= HEAVY_SUBSTEPS and not self._warned_heavy:
            self._warned_heavy = True
            self._warn_heavy(why)
        if initial:
            log.info("time step: deck dt %.4g s, %d sub-step(s) of %.4g s; %s", self.dt,
                     self.substeps, self.dt_internal, why)
        elif self.substeps != old:
            log.info("time step at t = %.6g s: %d -> %d sub-step(s) of %.4g s (%s); %s",
                     self.time, old, self.substeps, self.dt_internal,
                     "the contact network stiffened" if self.substeps > old else "the pack loosened",
                     why + (f", refined x{self.refine} by the guard" if self.refine > 1 else ""))

    def _warn_heavy(self, why: str) -> None:
        """One warning per system when the deck step is sub-stepped heavily: what limits the
        step and what the user could change (like LIGGGHTS' and Yade's step-size warnings)."""
        zeta = self._apriori_zeta if self.dt_apriori <= self.dt_network else self._network_zeta
        if zeta > 1.0:
            lever = (f"the damping limits it (zeta {zeta:.3g} > 1: the dashpots' rate, not the "
                     f"springs, sets the step): less damping (NormalDamping / TangentialDamping; "
                     f"Hertz-Mindlin: a higher Restitution) would allow a larger one"
                     + ("" if self.implicit_damping else
                        ", and so would implicit normal dashpots (Damping Implicit on the step, "
                        "with Accuracy to keep impacts accurate)"))
        else:
            lever = ("the stiffness limits it: softer contacts (NormalPenalty / "
                     "TangentialPenalty; Hertz-Mindlin: YoungModulus) or heavier particles would "
                     "allow a larger one")
        log.warning("the time step %.4g s is sub-stepped %d times (internal step %.4g s, "
                    "%.2f of the critical step): %s; %s", self.dt, self.substeps,
                    self.dt_internal, self.dt_internal / self.dt_critical, lever, why)

    # ------------------------------------------------------------------ initialisation
    def initialize(self) -> None:
        """Freeze the body lists, choose the sub-stepping, evaluate the forces at t0 and record
        the initial mechanical energy.  Called by :meth:`step` when needed."""
        if self._initialized:
            return
        if self.provider is None:
            self.provider = lambda kin: None
        if self.implicit_damping and self.domain is not None:
            raise InputError("Damping Implicit runs on one MPI rank only (its dashpot forces "
                             "couple the whole contact network); run with one rank or "
                             "Damping Explicit")
        b = self.bodies
        self._inv_mass = 1.0 / b.mass
        self._inv_I = 1.0 / b.I
        self._sq_m, self._sq_I = np.sqrt(b.mass), np.sqrt(b.I)
        nm = 1 + int(max(np.max(b.material, initial=0), np.max(self.walls.material, initial=0)))
        self._table = self.interfaces.as_array(nm)
        #: the force kernels of the table's laws (:func:`~nurbsdem.dynamics.laws.engine.engine_kernels`)
        self._kernels = engine_kernels(self._table)
        self._mat_all = np.concatenate([b.material, self.walls.material]).astype(np.int64)
        ell = np.where(b.radius > 0, b.radius, np.sqrt(b.I.sum(axis=1) / (2 * b.mass)))
        self._ell = ell
        self._g_norm = float(np.linalg.norm(self.gravity))
        self._scale_floor = max(float(np.sum(b.mass * np.linalg.norm(self.gravity) * ell)), 1e-300)
        # period-2 guard: round-off floors of a step's displacement (m) and rotation (kg m²)
        self._alt_floor_x = 1e-9 * ell
        self._alt_floor_L = 1e-9 * b.I[:, 2]
        self.alt_count = np.zeros(b.n, np.int64)
        self.alt_prev_v = np.zeros((b.n, 3))
        self.alt_prev_L = np.zeros((b.n, 3))
        self.hist_keys = np.zeros(0, dtype=np.int64)
        self.hist_springs = np.zeros((0, 3))
        if self.initial_history is not None:   # tangential springs carried over from a previous step
            self.hist_keys = np.array(self.initial_history[0], dtype=np.int64)
            self.hist_springs = np.array(self.initial_history[1], dtype=float).reshape(-1, 3)
        self.wall_work = np.zeros(self.walls.n)
        self.ledger = EnergyLedger()
        self.c_a = self.c_key = np.zeros(0, np.int64)     # no previous evaluation
        self.c_eel = np.zeros((0, 2))
        self._initialized = True
        self._evaluate(self.time, 0.0)
        if self.domain is not None:
            self.domain.end_of_deck_step()
        self._apriori_limit()
        self._control_step(initial=True)
        if self.initial_history is not None:
            # carried-over springs bring their stored energy with them: none of it is dissipated
            self.ledger.tangential_spring_work = float(self.c_eel[:, 1].sum()) if self.c_eel.shape[0] else 0.0
        e = self.energy()
        self.ledger.initial_mechanical = e.mechanical
        self._peak = e.kinetic + e.elastic

    # ------------------------------------------------------------------ force evaluation
    def _kinematics(self, t: float) -> Kinematics:
        b = self.bodies
        R, position = body_poses(b.q, b.P, b.x, b.centroid_file)
        return Kinematics(t=t, x=b.x.copy(), R=R, position=position, v=b.v.copy(),
                          omega=omega_world(b.q, b.L, self._inv_I),
                          wall_displacement=self.wall_d.copy(), wall_velocity=self.wall_u.copy(),
                          n_particles=b.n, n_bodies=self.n_bodies)

    def _all_kinematics(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions, velocities and angular velocities (B,3) of particles then walls."""
        b = self.bodies
        pos = np.concatenate([b.x, self.wall_d])
        vel = np.concatenate([b.v, self.wall_u])
        omg = np.concatenate([omega_world(b.q, b.L, self._inv_I), np.zeros((self.walls.n, 3))])
        if self.wall_spin is not None:       # a turning wall: its points move at u + ω × (p − c)
            pos[b.n:] += self.wall_spin[:, 3:]
            omg[b.n:] = self.wall_spin[:, :3]
        return pos, vel, omg

    def _spun_contacts(self, wall_u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(body_b, wall_d, wall_u) for the kick's work terms when walls turn: each contact
        with a turning wall gets a wall of its own (index W + j) that moves at that wall's
        point velocity u + ω × (p − c) (m/s) at the contact point p."""
        n, W = self.bodies.n, self.walls.n
        w = self.c_b - n
        idx = np.flatnonzero(w >= 0)
        idx = idx[np.any(self.wall_spin[w[idx], :3] != 0.0, axis=1)]
        if idx.size == 0:
            return self.c_b, self.wall_d, wall_u
        ws = w[idx]
        arm = self.c_point[idx] - self.wall_spin[ws, 3:] - self.wall_d[ws]
        u_point = wall_u[ws] + np.cross(self.wall_spin[ws, :3], arm)
        body_b = self.c_b.copy()
        body_b[idx] = n + W + np.arange(idx.size)
        return (body_b, np.concatenate([self.wall_d, self.wall_d[ws]]),
                np.ascontiguousarray(np.concatenate([wall_u, u_point])))

    def _evaluate(self, t: float, h: float) -> None:
        """Walls to time t, contact detection by the provider, Eq. 16–17, loads incl. gravity."""
        b = self.bodies
        t0, dashpots = time.perf_counter(), self.split["implicit dashpots"]
        self.wall_d, self.wall_u = self.walls.kinematics(t)
        kinematics = self._kinematics(t)
        t1 = time.perf_counter()
        cs = self.provider(kinematics)          # the search and the LCPs (the scene's timers)
        t2 = time.perf_counter()
        self.last_contacts = cs
        self._book_dropped(cs)
        a, bb, pa, pb, nrm, dep, key = _unpack(cs, self.n_bodies)
        K = a.shape[0]
        if K and np.isnan(self._table[self._mat_all[a], self._mat_all[bb], 0]).any():
            raise InputError("a contact occurred between materials with no contact interface")
        spring = match_history(self.hist_keys, self.hist_springs, key)
        pos, vel, omg = self._all_kinematics()
        if self.__dict__.get("_inv_mass_all") is None:
            self._inv_mass_all = np.concatenate([self._inv_mass, np.zeros(self.walls.n)])
        if self.uses_hertz:   # a law that needs the contacts' exact curvature radii (Hertz)
            from ..geometry.curvature import contact_radii_for
            self.c_radius, self.hertz_fallback = contact_radii_for(self.provider, cs, b, K)
        else:
            self.c_radius = np.zeros(K)
        law = (a, bb, pa, pb, nrm, dep, pos, vel, omg, self._mat_all, self._table)
        dashpot = (self._implicit_dashpots(law, spring, h)
                   if self.implicit_damping and h > 0.0 and K else None)
        (force, torque, point, ftot, fdn, fdt, fet, fn, eel, stick, self.c_coeffs,
         self.last_slip_work) = self._kernels.contact_loads(
             *law, spring, h, self._inv_mass_all, self.c_radius, b.mass, self.gravity,
             dashpot is not None, np.zeros(0) if dashpot is None else dashpot)
        self.hist_keys, self.hist_springs = store_history(key, spring)
        if self.domain is not None:          # the owners' loads of this rank's ghosts
            self.domain.exchange_loads(force, torque)
        self.force, self.torque = force, torque
        self.c_a, self.c_b, self.c_point, self.c_ftot, self.c_normal = a, bb, point, ftot, nrm
        self.c_fet = fet
        self.c_fdn, self.c_fdt, self.c_fn, self.c_eel, self.c_stick, self.c_key = fdn, fdt, fn, eel, stick, key
        self.split["contact forces"] += ((t1 - t0) + (time.perf_counter() - t2)
                                         - (self.split["implicit dashpots"] - dashpots))

    def _implicit_dashpots(self, law: tuple, spring: np.ndarray, h: float) -> np.ndarray:
        """The normal dashpot forces (K,) N at the end of the internal step h (s)
        (:func:`~nurbsdem.dynamics.implicit.dashpots_of_evaluation`)."""
        b = self.bodies
        t0 = time.perf_counter()
        f, rounds, iterations = self._kernels.dashpots_of_evaluation(
            *law, spring, h, self._inv_mass_all, self.c_radius, b.mass, self.gravity, b.q, b.L,
            self._inv_I, b.principal_rotations(), self._sq_m, self._sq_I)
        self.split["implicit dashpots"] += time.perf_counter() - t0
        self.dashpot_solves += (1, rounds, iterations)
        return f

    def _book_dropped(self, cs: Any) -> None:
        """A pair the provider left out after a failed contact problem takes its normal elastic
        energy with it: book it as dissipated (normal), so the energy balance stays closed."""
        dropped = getattr(cs, "dropped_keys", None)
        gone = (np.isin(self.c_key, dropped) if dropped is not None and len(dropped)
                else np.zeros(self.c_key.shape[0], bool))
        if self.domain is not None:          # booked at the deck end, in the serial order
            self.domain.log_dropped(self.c_a[gone], self.c_key[gone], self.c_eel[gone, 0])
            return
        if gone.any():
            self.ledger.dissipated_normal += float(self.c_eel[gone, 0].sum())

    def _kick(self, hk: float, wall_u: np.ndarray) -> None:
        """Half kick with the stored loads, accumulating the exact discrete work of the impulses.

        wall_u (W,3): the walls' mean velocity over the current internal step, (d(t+h) − d(t))/h,
        so that the external work adds up to force × the walls' exact displacement (trapezoidal
        in the force, no error at kinks of a piecewise-linear motion)."""
        b = self.bodies
        body_b, wall_d = self.c_b, self.wall_d
        if self.wall_spin is not None and self.c_a.shape[0]:
            body_b, wall_d, wall_u = self._spun_contacts(wall_u)
        terms = kick_with_terms(b.v, b.L, b.x, b.q, self._inv_I, self._inv_mass, self.force,
                                self.torque, hk, self.c_a, body_b, self.c_point, wall_d,
                                wall_u, self.c_ftot, self.c_fdn, self.c_fdt, self.c_fet)
        if self.domain is not None:          # added at the deck end, in the serial order
            self.domain.log_kick(self.c_a, self.c_b, self.c_key, terms)
            return
        acc = np.zeros(4)
        add_kick_work(terms, self.c_a, self.c_b, b.n, acc, self.wall_work)
        if self.c_a.shape[0]:
            self.ledger.dissipated_normal += acc[0]
            self.ledger.dissipated_tangential += acc[1]
            self.ledger.external_work += acc[2]
            self.ledger.tangential_spring_work += acc[3]

    def _internal_step(self, t_new: float, h: float) -> None:
        b = self.bodies
        d_new, _ = self.walls.kinematics(t_new)
        u_mean = (d_new - self.wall_d) / h
        t0 = time.perf_counter()
        self._kick(0.5 * h, u_mean)
        self._watch_alternation(h)
        drift(b.x, b.v, b.q, b.L, self._inv_I, h)
        t1 = time.perf_counter()
        self._evaluate(t_new, h)
        t2 = time.perf_counter()
        self._kick(0.5 * h, u_mean)
        self.split["integration"] += (t1 - t0) + (time.perf_counter() - t2)

    def _watch_alternation(self, h: float) -> None:
        """Period-2 guard on the half-step velocities (module docstring)."""
        b = self.bodies
        if b.n == 0 or not self.watch_period2:
            return
        worst = alternation_update(b.v, b.L, self.alt_prev_v, self.alt_prev_L, self.alt_count,
                                   self._alt_floor_x, self._alt_floor_L, 1.0 / h)
        count = int(self.alt_count[worst]) if worst >= 0 else 0
        amp = float(np.linalg.norm(b.v[worst])) * h if worst >= 0 else 0.0
        if self.domain is not None:
            worst, count, amp = self.domain.worst_alternation(worst, count, amp)
        if worst >= 0 and count >= ALTERNATION_STEPS:
            raise _Unstable(f"period-2 motion of particle {worst}: its motion reversed at each "
                            f"of the last {count} internal steps (displacement "
                            f"{amp:.3g} m per step), a mode beyond the stability limit")

    # ------------------------------------------------------------------ stepping
    def step(self) -> EnergySample:
        """Advance one deck step (``substeps`` × ``acc_refine`` internal steps); returns the
        energies at its end.

        A deck step the guard finds unstable is rolled back and repeated with twice the
        sub-steps, up to ``max_refinements`` times; then InstabilityError is raised (with the
        system rolled back to the start of the step).  With the accuracy control
        (:mod:`nurbsdem.dynamics.accuracy`) a stable deck step whose energy-balance error grew
        by more than its budget is rolled back and repeated with twice the sub-steps too."""
        self.initialize()
        good = self.get_state()
        snapshot = getattr(self.provider, "snapshot", None)
        provider_state = snapshot() if snapshot is not None else None
        balance0 = self._balance() if self.accuracy is not None else 0.0
        tried: list[str] = []
        while True:
            control = (self.substeps, self.refine, self.calm_steps, self.acc_refine,
                       self.acc_calm, self.acc_last_growth)
            n_sub, refine, _, acc, _, _ = control
            try:
                e = self._try_step()
            except _Unstable as exc:
                self._roll_back(good, provider_state, control)
                tried.append(f"{n_sub * acc} sub-step(s): {exc}")
                if (self.forced_substeps is not None or len(tried) > self.max_refinements
                        or 2 * n_sub * acc > self.max_substeps):
                    self._give_up(tried)
                self.refine = 2 * refine
                self.substeps = 2 * n_sub
                self.dt_internal = self.dt / self.substeps
                self.calm_steps = 0
                log.warning("deck step at t = %.6g s repeated with %d sub-steps of %.4g s: %s",
                            self.time, self.substeps * acc, self.dt / (self.substeps * acc), exc)
                continue
            growth = self._repeat_for_accuracy(balance0, n_sub, acc)
            if growth is not None:
                self._roll_back(good, provider_state, control)
                self.acc_refine, self.acc_calm, self.acc_last_growth = 2 * acc, 0, growth
                continue
            self.last_substeps = n_sub * acc
            break
        self._peak = max(self._peak, e.kinetic + e.elastic)
        self.calm_steps += 1
        if self.refine > 1 and self.calm_steps >= REFINE_DECAY_STEPS:
            self.refine //= 2
            self.calm_steps = 0
        if self.domain is not None:
            self.domain.after_deck_step()      # re-cut the domain when due
        self._control_step()
        return e

    def _roll_back(self, good: dict, provider_state: Any, control: tuple) -> None:
        """Undo a deck step: the state ``good`` and the provider's snapshot, with the step
        control's figures ``control`` (substeps, refine, calm_steps, acc_refine, acc_calm,
        acc_last_growth) of the attempt (a repeat may follow another)."""
        self.set_state(good)
        if provider_state is not None:
            self.provider.restore(provider_state)
        (self.substeps, self.refine, self.calm_steps, self.acc_refine, self.acc_calm,
         self.acc_last_growth) = control
        self.dt_internal = self.dt / self.substeps

    def _balance(self) -> float:
        """The energy-balance error (J) of the present state
        (:func:`~nurbsdem.dynamics.energy.balance_terms`, as the compiled deck steps take it)."""
        b = self.bodies
        return float(balance_terms(b.mass, b.x, b.v, b.q, b.L, self._inv_I, self.gravity,
                                   np.ascontiguousarray(self.c_eel, float).reshape(-1, 2),
                                   self.ledger.to_array())[1])

    def _repeat_for_accuracy(self, balance0: float, n_sub: int, acc: int) -> float | None:
        """The accuracy control after a deck step that passed the guards
        (:mod:`nurbsdem.dynamics.accuracy`; off: None): the growth of the balance error (J)
        when the step is to be repeated with twice the sub-steps; else None, and the factor
        and its calm count are updated."""
        if self.accuracy is None:
            return None
        growth = abs(self._balance() - balance0)
        budget = accuracy_budget(self.accuracy, self._peak, self._scale_floor)
        if repeat_for_accuracy(growth, budget, acc, n_sub * acc, self.max_substeps,
                               self.acc_last_growth):
            self.accuracy_repeats += 1
            log.debug("deck step at t = %.6g s repeated with %d sub-steps for accuracy: balance "
                      "error grew by %.3g J (budget %.3g J)", self.time - self.dt,
                      2 * n_sub * acc, growth, budget)
            return growth
        self.acc_refine, self.acc_calm = after_accepted(growth, budget, acc, self.acc_calm)
        self.acc_last_growth = math.inf
        return None

    def _compiled_stepper(self) -> "DeckSteps | None":
        """The compiled deck steps of this system (made once), or None where they do not
        apply (:meth:`DeckSteps.for_system`, several ranks, ``compiled_steps`` off)."""
        if not self.compiled_steps or self.domain is not None:
            return None
        if self._deck_steps is None:
            self._deck_steps = DeckSteps.for_system(self) or False
        return self._deck_steps or None

    def load_compiled(self) -> None:
        """Load the compiled deck steps now (numba's cache), so that the first call of
        :meth:`steps` does not (the solver counts this as set-up)."""
        self.initialize()
        fast = self._compiled_stepper()
        if fast is not None:
            fast.load()

    def steps(self, n_max: int, sample_at: np.ndarray | None = None,
              state_at: np.ndarray | None = None) -> int:
        """Advance up to ``n_max`` deck steps (at least one) and return how many were done.

        sample_at (n_max,) bool: the deck steps (0 = the first of this call) at whose end the
        monitors are sampled (:meth:`monitor_sample`); the samples are in
        ``last_steps.samples``.  The compiled loop records them as rows
        (:mod:`nurbsdem.dynamics.monitor`), so it need not return at each sample.  state_at
        (n_max,) bool: the deck steps at whose end the state is kept for the ParaView and
        results output (:class:`~nurbsdem.dynamics.monitor.StateSample`, in
        ``last_steps.states``), all but the last deck step done: the caller takes that one
        live.

        A scene provider on one rank (:class:`~nurbsdem.dynamics.deck_steps.DeckSteps`; not
        Hertz–Mindlin with NURBS particles) runs them in compiled code, with the same results
        as :meth:`step`; it returns early when the time-step control changes the sub-step
        count (it takes the exact estimate itself where the count stands), and a deck step on
        which a guard fires or an LCP fails is repeated by :meth:`step`
        (which refines it, answers the failed LCP, or raises).  Other scenes: one
        :meth:`step`."""
        self.initialize()
        fast = self._compiled_stepper() if n_max >= 1 else None
        sample_at = (np.zeros(max(int(n_max), 1), bool) if sample_at is None
                     else np.asarray(sample_at, bool))
        state_at = (np.zeros(max(int(n_max), 1), bool) if state_at is None
                    else np.asarray(state_at, bool))
        self.last_steps = StepTally()
        if not fast:
            self._tallied_step(bool(sample_at[0]))
            return 1
        while True:
            good = self._changed_in_place()
            snap = self.provider.snapshot()
            n_run = self.substeps * self.acc_refine
            t0, count = self.t0, self.step_count
            status, done, counters, rows, kept = fast.run(int(n_max), sample_at, state_at)
            if status == GUARD:
                self._put_back(good)
                self.provider.restore(snap)
                for j in range(done + 1):
                    self._tallied_step(bool(sample_at[j]), bool(state_at[j]) and j < done)
                return done + 1
            if status != REFINE or done:
                break       # REFINE on the first deck step: again with the new count
        W = self.walls.n
        samples = [MonitorSample.from_row(t0 + (count + j + 1) * self.dt, rows[j], W)
                   for j in range(done - 1) if sample_at[j]]
        if done and sample_at[done - 1]:       # the present state: taken live (Hertz rows too)
            samples.append(self.monitor_sample())
        states = tuple(self._state_of_loop(t0 + (count + k[0] + 1) * self.dt, k) for k in kept
                       if k[0] < done - 1)
        self.last_steps = StepTally(done * n_run, int(counters[ACTIVE_SUM]),
                                    int(counters[ACTIVE_MAX]), int(counters[DEGENERATED_SUM]),
                                    0, tuple(samples), states)
        if status == CONTROL:
            self._control_step()
        return done

    def _changed_in_place(self) -> dict[str, np.ndarray]:
        """Copies of the arrays the compiled loop changes in place (:data:`_LOOP_IN_PLACE`):
        what a GUARD return restores.  The loop replaces the rest of the state only when it
        does not return GUARD (:meth:`DeckSteps.run`), so the rest needs no copy (the 29
        arrays of :meth:`get_state` took 0.5 ms per call of the loop)."""
        b = self.bodies
        kept = {k: getattr(self, k).copy() for k in _LOOP_IN_PLACE}
        kept.update(x=b.x.copy(), q=b.q.copy(), v=b.v.copy(), L=b.L.copy())
        return kept

    def _put_back(self, kept: dict[str, np.ndarray]) -> None:
        """Undo a call of the compiled loop that returned GUARD (:meth:`_changed_in_place`)."""
        b = self.bodies
        b.x, b.q, b.v, b.L = kept["x"], kept["q"], kept["v"], kept["L"]
        for k in _LOOP_IN_PLACE:
            setattr(self, k, kept[k])

    def _tallied_step(self, sample: bool = False, state: bool = False) -> None:
        """:meth:`step`, counted in :attr:`last_steps` (with its monitor sample and its state
        sample if asked)."""
        self.step()
        n_sub = self.last_substeps
        cs = self.last_contacts
        active = int(getattr(cs, "active", 0) or 0)
        t = self.last_steps
        self.last_steps = StepTally(
            t.substeps + n_sub, t.active_sum + active, max(t.active_max, active),
            t.degenerated_sum + int(getattr(cs, "degenerated_count", 0) or 0),
            t.failed_sum + int(getattr(cs, "failed", 0) or 0),
            t.samples + ((self.monitor_sample(),) if sample else ()),
            t.states + ((self.state_sample(),) if state else ()))

    def _try_step(self) -> EnergySample:
        """The internal steps of one deck step and the guards; raises _Unstable."""
        t_start = self.time
        n = self.substeps * self.acc_refine
        h = self.dt / n
        self.failed_in_step = 0
        if self.domain is not None:
            self.domain.begin_deck_step()
        for k in range(1, n + 1):
            t_new = t_start + self.dt * k / n
            with np.errstate(all="ignore"):
                self._internal_step(t_new, h)
            self.failed_in_step += int(getattr(self.last_contacts, "failed", 0) or 0)
            b = self.bodies
            finite = state_is_finite(b.x, b.v, b.q, b.L) and bool(np.isfinite(self.force).all())
            if self.domain is not None:
                finite = self.domain.all(finite)
            if not finite:
                raise _Unstable(f"non-finite state at t = {t_new:.6g} s")
        self.step_count += 1
        if self.domain is not None:
            self.domain.end_of_deck_step()     # every rank: the serial state
        e = self.energy()
        self._check_energy(e)
        return e

    def _give_up(self, tried: list[str]) -> None:
        """Raise InstabilityError with what was tried and a diagnosis (the state is the last
        good one, at the start of the deck step)."""
        t = self.time
        depth = self._max_relative_depth()
        cause = []
        if self.failed_in_step:
            cause.append(f"{self.failed_in_step} contact problem(s) (LCP) failed in this step")
        if depth > 0.1:
            cause.append(f"contacts penetrate up to {depth:.2g} of the particle size (the normal "
                         f"penalty is too soft for this load or impact speed)")
        if self.forced_substeps is not None:
            advice = "the sub-steps are forced: let the solver choose them"
        elif len(tried) > 1:
            advice = (f"repeating it with up to {2 ** (len(tried) - 1)}x the sub-steps did not "
                      f"help" + (": " + "; ".join(cause) if cause else ""))
        else:
            advice = "; ".join(cause) if cause else "reduce the time step"
        msg = (f"integration unstable in the deck step starting at t = {t:.6g} s (deck dt "
               f"{self.dt:.4g} s, estimated critical step {self.dt_critical:.4g} s, safety "
               f"{self.safety}); tried {' / '.join(tried)}. Rolled back to the last good state "
               f"(t = {t:.6g} s): {advice}")
        log.error(msg)
        raise InstabilityError(msg, time=t, reason=tried[-1], step=self.step_count) from None

    def _max_relative_depth(self) -> float:
        """Largest penetration of the last evaluation over the smaller body's size (-)."""
        cs = self.last_contacts
        depth = np.asarray(getattr(cs, "depth", np.zeros(0)), float)
        if depth.size == 0:
            return 0.0
        size = np.concatenate([self._ell, np.full(self.walls.n, np.inf)])
        a = np.asarray(cs.body_a, np.int64)
        bb = np.asarray(cs.body_b, np.int64)
        return float(np.max(depth / np.minimum(size[a], size[bb])))

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
        terms = energy_terms(b.mass, b.x, b.v, b.q, b.L, self._inv_I, self.gravity,
                             np.ascontiguousarray(self.c_eel, float).reshape(-1, 2))
        return energy_sample(self.time, *terms, self.ledger)

    @property
    def uses_hertz(self) -> bool:
        """Whether the interfaces include a law that needs each contact's equivalent radius
        (Hertz–Mindlin: :func:`~nurbsdem.dynamics.laws.needs_contact_radius` of the interface
        table, fixed once the system is built; taken once)."""
        hertz = self.__dict__.get("_hertz_table")
        if hertz is None:
            hertz = self._hertz_table = needs_contact_radius(self._table)
        return hertz

    def monitor_sample(self) -> MonitorSample:
        """The monitors' sample of the present state (:mod:`nurbsdem.dynamics.monitor`)."""
        cs = self.last_contacts
        hertz = None
        if self.uses_hertz:
            hertz = (int(self.c_a.shape[0]), int(getattr(self, "hertz_fallback", 0)),
                     np.asarray(self.c_radius, float), np.asarray(self.c_coeffs[:, 0], float))
        return MonitorSample(self.time, self.energy(), int(getattr(cs, "monitored", 0) or 0),
                             int(getattr(cs, "active", 0) or 0),
                             int(getattr(cs, "degenerated_count", 0) or 0),
                             int(getattr(cs, "failed", 0) or 0), self.wall_displacement,
                             self.wall_reaction, hertz)

    def body_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The particles' state as the model and the writers hold it (copies): centroids
        (N,3) m, file->world quaternions (N,4) (w, x, y, z), velocities (N,3) m/s and angular
        velocities (N,3) rad/s, world frame."""
        b = self.bodies
        return self._body_state_of(b.x.copy(), b.q, b.v.copy(), b.L)

    def _body_state_of(self, x: np.ndarray, q: np.ndarray, v: np.ndarray,
                       L: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`body_state` of the centroids x, principal quaternions q, velocities v and
        angular momenta L (N,·) given (x and v are returned as they are)."""
        b = self.bodies
        R, _ = body_poses(q, b.P, x, b.centroid_file)
        return x, matrix_to_quat(R).reshape(-1, 4), v, omega_world(q, L, self._inv_I)

    def contact_output(self) -> dict | None:
        """The last evaluation's contacts as the ParaView writer takes them
        (:func:`~nurbsdem.dynamics.monitor.contact_output_of`; None without any)."""
        cs = self.last_contacts
        active = int(getattr(cs, "active", 0) or 0)
        if active == 0 or self.c_a.shape[0] != active:
            return None
        return self._contacts_for_output(cs.body_a, cs.body_b, self.c_point, self.c_ftot,
                                         self.c_fn, cs.normal, cs.depth, cs.degenerated,
                                         self.c_coeffs, self.c_radius)

    def _contacts_for_output(self, a, b, point, ftot, fn, normal, depth, deg, coeffs,
                             radius) -> dict | None:
        """:func:`~nurbsdem.dynamics.monitor.contact_output_of` of the contacts a, b (None
        without any), with the Hertz–Mindlin columns (coeffs, radius) only under those laws."""
        active = a.shape[0]
        if active == 0:
            return None
        hertz = self.uses_hertz and coeffs.shape[0] == active
        return contact_output_of(a, b, point, ftot, fn, normal, depth, deg,
                                 coeffs if hertz else None, radius if hertz else None)

    def state_sample(self) -> StateSample:
        """The present state for the ParaView and results output (copies)."""
        return StateSample(self.time, *self.body_state(), self.wall_displacement,
                           self.contact_output())

    def _state_of_loop(self, time: float, kept: tuple) -> StateSample:
        """The StateSample of a state the compiled loop kept at a deck step's end
        (:func:`~nurbsdem.dynamics.deck_steps.run_deck_steps`): the same arrays
        :meth:`state_sample` takes live."""
        _, x, q, v, L, wall_d, *contacts = kept
        return StateSample(time, *self._body_state_of(x, q, v, L), wall_d,
                           self._contacts_for_output(*contacts))

    def state_sample_bytes(self, contacts: int | None = None) -> int:
        """Bytes of one state the compiled loop keeps for the output (at most; the particles'
        state, the walls' displacements and the contacts' arrays of
        :func:`~nurbsdem.dynamics.deck_steps._kept`, 8 bytes a number), with ``contacts``
        contacts (default: the last evaluation's): what the solver budgets the states kept in
        one call by (tested against the arrays' nbytes)."""
        k = int(self.c_a.shape[0]) if contacts is None else int(contacts)
        return 8 * (16 * self.n_particles + 24 * k + 3 * self.walls.n)

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
                  counters=np.array([self.step_count, self.substeps, self.refine,
                                     self.calm_steps, self.acc_refine, self.acc_calm],
                                    dtype=np.int64),
                  scalars=np.array([self.t0, self.dt, self._peak, self.dt_bound,
                                    self.dt_network, self.dt_critical, self.acc_last_growth]))
        return st

    def set_state(self, st: dict[str, np.ndarray]) -> None:
        """Restore a state from :meth:`get_state` (the system must have the same bodies/walls)."""
        self.initialize()
        b = self.bodies
        if st["x"].shape != b.x.shape or st["wall_d"].shape != (self.walls.n, 3):
            raise InputError("checkpoint does not match the system's bodies and walls")
        b.x, b.q, b.v, b.L = (np.array(st[k], dtype=float, copy=True) for k in ("x", "q", "v", "L"))
        for k in _STATE_KEYS:
            if k in ("x", "q", "v", "L", "ledger") or k not in st:
                continue
            setattr(self, k, np.array(st[k], copy=True))
        self.ledger = EnergyLedger.from_array(st["ledger"])
        self.step_count = int(st["counters"][0])
        if st["counters"].shape[0] >= 4:
            self.substeps, self.refine, self.calm_steps = (int(c) for c in st["counters"][1:4])
            self.dt_internal = self.dt / self.substeps
        acc = st["counters"][4:6] if st["counters"].shape[0] >= 6 else (1, 0)
        self.acc_refine, self.acc_calm = int(acc[0]), int(acc[1])
        self.t0 = float(st["scalars"][0])
        if float(st["scalars"][1]) != self.dt:
            raise InputError("checkpoint was written with a different deck time step")
        self._peak = float(st["scalars"][2])
        if st["scalars"].shape[0] >= 6:
            self.dt_bound, self.dt_network, self.dt_critical = (float(v) for v in st["scalars"][3:6])
        self.acc_last_growth = (float(st["scalars"][6]) if st["scalars"].shape[0] >= 7
                                else math.inf)


class _Unstable(Exception):
    pass


def _unpack(cs: Any, n_bodies: int):
    """Contiguous typed arrays from a ContactSet (duck-typed, docs/conventions.md); None or
    K=0 -> empty."""
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

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
seen so far or the walls' work |W_ext| if larger, at least Σ m|g| r).  Otherwise the deck step
is rolled back and **repeated with twice the sub-steps** (the refinement is kept, and halved
again after ``REFINE_DECAY_STEPS`` quiet deck steps), up to ``max_refinements`` times; only
then is the system left at the last good state (the start of that deck step,
``system.get_state()``) and :class:`InstabilityError` raised, with a diagnosis (failed contact
problems, penetration depth) instead of advice to reduce a time step that was already
refined.
Runs are deterministic: the same inputs give bit-for-bit the same results.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from ..errors import InputError, NurbsdemError
from ..jit import launch_threads
from .accuracy import accuracy_budget, after_accepted, repeat_for_accuracy
from .contact_state import no_contacts
from .energy import EnergySample, balance_terms
from .forces import InterfaceTable
from .laws.engine import engine_kernels
from .monitor import MonitorSample
from .rigid import PrescribedMotion, RigidBodies, Walls, kind_rows
from .deck_steps import (ACTIVE_MAX, ACTIVE_SUM, CONTROL, DEGENERATED_SUM, GUARD, REFINE,
                         DeckSteps)
from .internal_step import ContactProvider, InternalSteps, Kinematics, _Unstable
from .exact_sum import exact_zeros
from .step import EXACT_WALLS, L_SPRING, BodyConst, ledger_of
from .stepcontrol import REFINE_DECAY_STEPS
from .substep_control import ModeLimit, SubstepControl
from .rolling import NSPRING, widened
from .system_state import SystemState

__all__ = ["DemSystem", "InstabilityError", "Kinematics", "ModeLimit", "StepTally"]

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


#: the parts of the solver's "forces + integration" time a system measures
#: (:attr:`DemSystem.split`): the integration (half kicks with their work, the period-2 watch,
#: drift), the contact forces (the poses for the search, contact arrays, histories and loads,
#: with MPI the exchange of the ghosts' loads; not the search, the LCPs and the dashpots),
#: the implicit dashpots, the time-step control.  What the solver's figure holds beyond them:
#: the guards, snapshots and monitor rows of the deck steps and the Python around the
#: compiled loop
SPLIT_PARTS = ("integration", "contact forces", "implicit dashpots", "time-step control")


#: the arrays of the state besides the bodies' x, q, v, L that the compiled deck steps change
#: in place (:func:`~nurbsdem.dynamics.deck_steps.run_deck_steps`)
_LOOP_IN_PLACE = ("exact_ledger", "alt_count", "alt_prev_v", "alt_prev_L")


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


class DemSystem(SubstepControl, InternalSteps, SystemState):
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
    implicit_damping: implicit normal dashpots (:mod:`nurbsdem.dynamics.implicit`).
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
        #: (W,6) per wall: the angular velocity (rad/s) and the centre c (m) it turns about
        #: before its displacement d (the centre is c + d: a mesh or surface wall,
        #: :mod:`nurbsdem.contact.curved_walls`); None: no wall turns
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

    def add_particle_kinds(self, kind: np.ndarray, kinds: list[dict], R: np.ndarray,
                           x: np.ndarray, v: np.ndarray, omega: np.ndarray) -> None:
        """Add N particles of K kinds at once: ``kind`` (N,) indices into ``kinds`` (K
        mappings of what the particles of one kind share of :meth:`add_particle`'s arguments:
        mass, J0, material, centroid_file, radius, compliance), and per particle R (N,3,3),
        x (N,3) m, v (N,3) m/s, omega (N,3) rad/s.  The same particles as
        :meth:`add_particles` with one mapping per particle, bit for bit
        (:func:`~nurbsdem.dynamics.rigid.kind_rows`), without forming the mappings."""
        self._check_not_initialized()
        kind = np.asarray(kind, np.int64)
        if len(kind) == 0:
            return
        self.bodies.add_rows(kind_rows(
            kind, np.array([float(k["mass"]) for k in kinds]),
            np.array([np.asarray(k["J0"], float) for k in kinds]).reshape(-1, 3, 3),
            np.array([np.zeros(3) if k.get("centroid_file") is None else
                      np.asarray(k["centroid_file"], float).reshape(3) for k in kinds]),
            np.array([int(k.get("material", 0)) for k in kinds], np.int64),
            np.array([float(k.get("radius", 0.0)) for k in kinds]), R, x, v, omega))
        shared = [None if k.get("compliance") is None else
                  (float(k["compliance"][0]), float(k["compliance"][1])) for k in kinds]
        self._compliance.extend([shared[k] for k in kind.tolist()])

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
        self._sq_m, self._sq_I = np.sqrt(b.mass), np.sqrt(b.I)
        nm = 1 + int(max(np.max(b.material, initial=0), np.max(self.walls.material, initial=0)))
        self._table = self.interfaces.as_array(nm)
        #: the force kernels of the table's laws (:func:`~nurbsdem.dynamics.laws.engine.engine_kernels`)
        self._kernels = engine_kernels(self._table)
        self._mat_all = np.concatenate([b.material, self.walls.material]).astype(np.int64)
        self._inv_mass_all = np.concatenate([self._inv_mass, np.zeros(self.walls.n)])
        ell = np.where(b.radius > 0, b.radius, np.sqrt(b.I.sum(axis=1) / (2 * b.mass)))
        self._ell = ell
        self._g_norm = float(np.linalg.norm(self.gravity))
        self._scale_floor = max(float(np.sum(b.mass * np.linalg.norm(self.gravity) * ell)), 1e-300)
        # period-2 guard: round-off floors of a step's displacement (m) and rotation (kg m²)
        self._alt_floor_x = 1e-9 * ell
        self._alt_floor_L = 1e-9 * b.I[:, 2]
        #: the constants the internal step's compiled parts take (:mod:`.step`)
        self._bc = BodyConst(b.mass, self._inv_mass, self._inv_I, b.P, b.centroid_file, ell,
                             self._inv_mass_all, self._mat_all, self._table, self.gravity,
                             self._g_norm, self._alt_floor_x, self._alt_floor_L, self._sq_m,
                             self._sq_I)
        self.alt_count = np.zeros(b.n, np.int64)
        self.alt_prev_v = np.zeros((b.n, 3))
        self.alt_prev_L = np.zeros((b.n, 3))
        self.hist_keys = np.zeros(0, dtype=np.int64)
        self.hist_springs = np.zeros((0, NSPRING))
        if self.initial_history is not None:   # springs carried over from a previous step
            self.hist_keys = np.array(self.initial_history[0], dtype=np.int64)
            self.hist_springs = widened(self.initial_history[1])
        #: the mechanical energy (J) at the start of the run, NaN until it is taken below
        self.initial_mechanical = float("nan")
        #: the ledger's entries and the walls' work as exact sums (:mod:`.exact_sum`, rows as
        #: :data:`~nurbsdem.dynamics.forces.EXACT_WALLS` says), their only store (``ledger``
        #: and ``wall_work`` read them): their bits depend on neither the order of the terms
        #: nor the MPI ranks' shares
        self.exact_ledger = exact_zeros(EXACT_WALLS + self.walls.n)
        #: the last evaluation's contacts (:mod:`.contact_state`); none before the first
        self.contacts = no_contacts()
        #: the potential energy (J) a wrap into the periodic cell changed at the first
        #: evaluation (:meth:`_apply_wrap`)
        self.initial_wrap_work = 0.0
        self._initialized = True
        self._evaluate(self.time, 0.0)
        if self.domain is not None:
            self.domain.end_of_deck_step()
        self._apriori_limit()
        self._first_control_step()
        if self.initial_history is not None:
            # carried-over springs bring their stored energy with them: none of it is dissipated
            eel = self.contacts.eel
            self._book(L_SPRING, np.ascontiguousarray(eel[:, 1], float))
        e = self.energy()
        self.initial_mechanical = e.mechanical
        self._peak = e.kinetic + e.elastic

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
                                   np.ascontiguousarray(self.contacts.eel, float).reshape(-1, 2),
                                   ledger_of(self.exact_ledger, self.initial_mechanical))[1])

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
        count (it takes the exact estimate itself where the count stands).  When a guard fires
        or an LCP fails in a deck step, the call is rolled back and the deck steps before that
        one are run again in the loop (the same bits), so that the failed one comes first in
        the next call: there it is repeated by :meth:`step` alone (which refines it, answers
        the failed LCP, or raises).  Other scenes: one :meth:`step`."""
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
                if done == 0:       # the Python path repeats it: refined, answered or raised
                    self._tallied_step(bool(sample_at[0]))
                    return 1
                n_max = done        # the deck steps before it again (the same bits); the
                continue            # failed one is the next call's first
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
        does not return GUARD (:meth:`DeckSteps.run`), so the rest needs no copy (copying
        all the arrays of :meth:`get_state` at every call of the loop is the larger cost
        where the loop returns often, for output)."""
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

    def _give_up(self, tried: list[str]) -> None:
        """Raise InstabilityError with what was tried and a diagnosis (the state is the last
        good one, at the start of the deck step)."""
        msg = instability_text(self, tried)
        log.error(msg)
        raise InstabilityError(msg, time=self.time, reason=tried[-1],
                               step=self.step_count) from None

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
        # the work the walls did counts in the scale: without gravity and motion a scene's
        # peak and floor are ~0 J, and the round-off of a wall's first push would trip it
        scale = max(self._peak, abs(e.external_work), self._scale_floor)
        gain = e.mechanical - e.initial_mechanical - e.external_work
        tol = self.energy_tolerance * scale
        if not math.isfinite(e.mechanical) or not math.isfinite(e.balance_error):
            raise _Unstable("non-finite energy")
        if gain > tol:
            raise _Unstable(f"mechanical energy grew by {gain:.4g} J without external work "
                            f"(tolerance {tol:.3g} J)")
        if abs(e.balance_error) > tol:
            raise _Unstable(f"energy balance error {e.balance_error:.4g} J exceeds {tol:.3g} J")


def instability_text(system: DemSystem, tried: list[str]) -> str:
    """The message of a deck step the guards gave up on: what was ``tried`` (the sub-step
    counts), and a diagnosis (failed contact problems, deep penetrations) or advice."""
    t = system.time
    depth = max_relative_depth(system.last_contacts, system._ell, system.walls.n)
    cause = []
    if system.failed_in_step:
        cause.append(f"{system.failed_in_step} contact problem(s) (LCP) failed in this step")
    if depth > 0.1:
        cause.append(f"contacts penetrate up to {depth:.2g} of the particle size (the normal "
                     f"penalty is too soft for this load or impact speed)")
    if system.forced_substeps is not None:
        advice = "the sub-steps are forced: let the solver choose them"
    elif len(tried) > 1:
        advice = (f"repeating it with up to {2 ** (len(tried) - 1)}x the sub-steps did not "
                  f"help" + (": " + "; ".join(cause) if cause else ""))
    else:
        advice = "; ".join(cause) if cause else "reduce the time step"
    return (f"integration unstable in the deck step starting at t = {t:.6g} s (deck dt "
            f"{system.dt:.4g} s, estimated critical step {system.dt_critical:.4g} s, safety "
            f"{system.safety}); tried {' / '.join(tried)}. Rolled back to the last good state "
            f"(t = {t:.6g} s): {advice}")


def max_relative_depth(cs: Any, ell: np.ndarray, n_walls: int) -> float:
    """Largest penetration of the contacts ``cs`` (a ContactSet, or None) over the smaller
    body's size (-): the particles' sizes ell (N,) m, walls of no size."""
    depth = np.asarray(getattr(cs, "depth", np.zeros(0)), float)
    if depth.size == 0:
        return 0.0
    size = np.concatenate([ell, np.full(n_walls, np.inf)])
    a = np.asarray(cs.body_a, np.int64)
    b = np.asarray(cs.body_b, np.int64)
    return float(np.max(depth / np.minimum(size[a], size[b])))

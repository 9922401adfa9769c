"""The solver a user runs: a deck's solution steps, one after the other.

Data flow (one way): deck -> :class:`~nurbsdem.model.Model` -> :class:`Solver` (per step:
global search -> LCP -> forces -> integrator, i.e. :class:`~nurbsdem.contact.scene.SceneContacts`
inside a :class:`~nurbsdem.dynamics.DemSystem`) -> writers (VTK, CSV, HDF5, checkpoints).

Steps (PyBaMM-like: an experiment is a list of steps):

* ``Dynamic``: integrate ``Duration`` with the deck's ``TimeStep`` (sub-stepped when it
  exceeds the explicit stability limit; the log says what was chosen).
* ``Replicate``: stack copies of the particles (:func:`~nurbsdem.placement.replicate_step`);
  the energy the copies bring is booked as external work so the balance stays closed (a
  Replicate before the first energy row books nothing: the copies are the initial state).
* ``MoveWall … ToContact``: translate a wall until its gap to the nearest particle is ``Gap``.
* ``MoveWall … Displacement``: a dynamic step in which the wall translates at constant
  velocity; its reaction force, torque and work are monitored.
* ``MoveWall … Rotate``: a dynamic step in which a mesh or surface wall turns about a centre
  (translating too, the centre with it, when the step gives a ``Displacement``).

Energies written to ``monitors/energy.csv`` are cumulative over the whole run.
Checkpoints (``checkpoint.h5``) are written every ``Checkpoint Every`` seconds of simulated
time and at the end of each step; ``--restart`` continues bit-for-bit.  Each output interval
is served by the first deck time step at or after each of its multiples
(:mod:`nurbsdem.io.intervals`).  Ctrl-C (SIGINT) during the time loop stops the run at the
end of a deck time step, after a checkpoint of that moment (:class:`Interrupted`, a
KeyboardInterrupt; ``nurbsdem solve`` exits with status 130).
"""
from __future__ import annotations

import contextlib
import copy
import logging
import math
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from . import __version__
from .contact.scene import SceneContacts
from .dynamics import DemSystem, InterfaceTable, PrescribedMotion
from .dynamics.energy import EnergySample
from .dynamics.laws import law_named
from .dynamics.monitor import MonitorSample, StateSample
from .dynamics.stepcontrol import shape_compliance
from .dynamics.system import SPLIT_PARTS, InstabilityError
from .errors import InputError
from .geometry.rotation import quat_to_matrix
from .io import intervals
from .io.checkpoint import save_checkpoint
from .io.writers import OutputWriters
from .jit import launch_threads
from .model import Bodies, DynamicStep, Model, MoveWallStep, ReplicateStep, material_pair
from .placement import replicate_step

log = logging.getLogger("nurbsdem")

CHECKPOINT_NAME = "checkpoint.h5"
#: most deck steps handed to DemSystem.steps at once (compiled scenes; progress granularity)
MAX_COMPILED_STEPS = 200
#: the most bytes of ParaView/results states (:class:`~nurbsdem.dynamics.monitor.StateSample`)
#: the compiled loop keeps in one call: a call ends at the sample that would pass it (10^5
#: particles with 2.4·10^5 contacts: ~57 MB per sample)
STATE_BUDGET_BYTES = 256 * 2 ** 20


class Interrupted(KeyboardInterrupt):
    """Ctrl-C (SIGINT) stopped a run at the end of a deck time step, after a checkpoint of
    that moment (``str()`` says when, and where the checkpoint is)."""


@dataclass
class RunSummary:
    """What :meth:`Solver.run` reports at the end (also printed by ``nurbsdem solve``)."""

    wall_time: float = 0.0
    steps: int = 0
    substeps: int = 0
    lcps: int = 0
    #: contact evaluations (calls of the contact search, rejected attempts included)
    evaluations: int = 0
    degenerated: int = 0
    failed: int = 0
    active_max: int = 0
    active_total: int = 0
    balance_error: float = 0.0
    balance_scale: float = 0.0
    #: deck steps the accuracy control repeated with more sub-steps (``Accuracy`` on a step)
    accuracy_repeats: int = 0
    simulated_time: float = 0.0
    particles: int = 0
    timers: dict = field(default_factory=dict)
    #: two parts of ``timers["forces + integration"]`` (s): the implicit dashpots' solves and
    #: the time-step control (Gershgorin gates and exact estimates) in the time loop
    split: dict = field(default_factory=dict)

    def _balance_share(self) -> str:
        """The balance error relative to the energy turned over (dissipated + external work),
        or that energy itself when it is too small for a ratio to mean anything."""
        err, scale = abs(self.balance_error), abs(self.balance_scale)
        if scale > 0 and math.isfinite(scale) and err <= scale:
            return f"({err / scale:.2e} of the {scale:.3g} J turned over)"
        return f"(only {scale:.3g} J of energy was turned over)"

    def text(self) -> str:
        t = self.timers
        total = max(self.wall_time, 1e-12)
        split = ", ".join(f"{k} {v:.1f} s ({100 * v / total:.0f} %)" for k, v in t.items())
        parts = ", ".join(f"{k} {v:.1f} s" for k, v in self.split.items() if v > 0.0)
        return (f"done: {self.simulated_time:.4g} s simulated, {self.particles} particles, "
                f"{self.steps} time steps ({self.substeps} internal), wall time "
                f"{self.wall_time:.1f} s\n"
                f"contacts: {self.lcps} LCPs solved, at most {self.active_max} active; over all "
                f"steps {self.active_total} active contacts, {self.degenerated} of them "
                f"degenerated ({100 * self.degenerated / max(self.active_total, 1):.2f} %), "
                f"{self.failed} failed LCPs\n"
                f"energy balance error: {self.balance_error:.3e} J {self._balance_share()}\n"
                + (f"accuracy control: {self.accuracy_repeats} deck steps repeated with more "
                   f"sub-steps\n" if self.accuracy_repeats else "")
                + f"time split: {split}"
                + (f" (of forces + integration: {parts})" if parts else ""))


class Progress:
    """A one-line progress display per step on stderr (simulated time, time step, active
    contacts, estimated time left). Silent when ``quiet``."""

    def __init__(self, quiet: bool, stream=None) -> None:
        self.quiet = quiet
        self.stream = stream or sys.stderr
        self.last = 0.0
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()

    def start(self, label: str, duration: float) -> None:
        self.label, self.duration, self.t_start, self.t_wall = label, duration, None, time.perf_counter()

    def update(self, t_step: float, dt: float, substeps: int, active: int, force: bool = False) -> None:
        if self.quiet:
            return
        now = time.perf_counter()
        if not force and now - self.last < (0.5 if self.tty else 10.0):
            return
        self.last = now
        frac = min(1.0, t_step / self.duration) if self.duration > 0 else 1.0
        el = now - self.t_wall
        eta = el * (1 - frac) / frac if frac > 0 else float("nan")
        bar = "#" * int(30 * frac)
        line = (f"{self.label} [{bar:<30s}] {100 * frac:5.1f} %  t={t_step:.4f}/{self.duration:g} s  "
                f"dt={dt:.3g} s x{substeps}  contacts={active}  left~{eta:5.0f} s")
        end = "\r" if self.tty else "\n"
        print(line, end=end, file=self.stream, flush=True)

    def finish(self) -> None:
        if not self.quiet and self.tty:
            print(file=self.stream)


class Solver:
    """Runs the steps of a model.

    Parameters
    ----------
    model: parsed deck (with its initial bodies).
    output: results directory (default: the deck's ``Output Directory``).
    restart: a checkpoint file to continue from.
    quiet: no progress display.
    safety: fraction of the critical time step used by the sub-stepping (0.5).
    progress_stream: where the progress line goes (default stderr).
    contact_options: keywords of :class:`~nurbsdem.contact.scene.SceneContacts` (``skin``,
        ``certificates``): e.g. ``dict(skin=0, certificates=False)`` searches and solves every
        pair at every evaluation (the same results, more work: a test says so).
    write_output: False writes no files at all (no results, monitors, checkpoints).
    restart_check: ``check(path) -> state``, reads the restart checkpoint and checks that it
        belongs to this model (default :func:`~nurbsdem.io.checkpoint.restart_state`: the
        decks compared; a model whose steps are added while it runs passes its own).
    compiled_steps: run the internal steps of a scene in compiled deck steps
        (:mod:`~nurbsdem.dynamics.deck_steps`; the same results, bit for bit: a test says so).
    background_output: write the ParaView files from a worker thread while the time loop
        goes on (the same files, byte for byte; a checkpoint waits for them).
    comm: an MPI communicator with several ranks: the particles are decomposed over them
        (:mod:`nurbsdem.parallel`; results bit for bit those of the serial run, written by
        rank 0); None: the world of ``mpiexec -n P`` when so started
        (:func:`nurbsdem.parallel.world`), else serial; False: serial.

    :meth:`run` runs every step; it is :meth:`start`, :meth:`run_pending` (or
    :meth:`run_step` per step) and :meth:`finish`, which a model extended step by step calls
    in turn (:class:`~nurbsdem.simulation.Simulation`).
    """

    def __init__(self, model: Model, output: str | Path | None = None,
                 restart: str | Path | None = None, quiet: bool = False,
                 safety: float = 0.5, progress_stream=None,
                 contact_options: dict | None = None, write_output: bool = True,
                 restart_check=None, compiled_steps: bool = True,
                 background_output: bool = True, comm=None) -> None:
        self.model = model
        launch_threads()
        if comm is None:
            from .parallel import world
            comm = world()
        self.comm = comm or None
        #: the domain decomposition of the current (or last) dynamic step on several ranks
        self.domain = None
        self.rank = int(self.comm.rank) if self.comm is not None else 0
        if self.comm is not None:
            _share_cores(self.comm)
            quiet = quiet or self.rank > 0      # one progress line: rank 0's
        self.compiled_steps = bool(compiled_steps)
        self.background_output = bool(background_output)
        if output is not None:
            model.output.directory = Path(output)
        self.outdir = Path(model.output.directory)
        self.quiet = quiet
        self.safety = safety
        self.contact_options = dict(contact_options or {})
        self.progress = Progress(quiet, progress_stream)
        self.restart_path = Path(restart) if restart is not None else None
        self.write_output = bool(write_output)
        self.restart_check = restart_check
        self._writers = None
        self._results_deck = model.text
        self._finished_once = False
        self._restored: dict | None = None
        self._wall0 = time.perf_counter()
        # materials: deck ids -> 0..M-1; walls: M + k, k the index of their material among the
        # walls' materials (None, rigid walls, first)
        mats = sorted(model.materials)
        self.mat_index = {m: i for i, m in enumerate(mats)}
        wall_mats = sorted({w.material_id for w in model.walls + model.curved_walls},
                           key=lambda m: (m is not None, m if m is not None else 0))
        self.wall_index = {wm: len(mats) + k for k, wm in enumerate(wall_mats)}
        self.shape_ids = sorted(model.shapes)
        self.shape_index = {s: i for i, s in enumerate(self.shape_ids)}
        self.shapes = [model.shapes[s].shape for s in self.shape_ids]
        self.interfaces = self._interface_table()
        #: each wall's displacement (m) from its deck position: flat walls, then mesh and
        #: surface walls (their turns are in ``_curved_rest``)
        self.wall_offset = np.zeros((len(model.wall_names), 3))
        self.bodies: Bodies = model.bodies.copy() if model.bodies is not None else Bodies.empty()
        self.time = 0.0
        self.step_index = 0          # next step to run
        self.step_progress = 0       # deck time steps done inside the current step
        self.energy_offset = {"dissipated": 0.0, "external_work": 0.0}
        self.mech0: float | None = None
        self.system: DemSystem | None = None
        self.scene: SceneContacts | None = None
        self.summary = RunSummary()
        #: parts of timers["forces + integration"] (:attr:`RunSummary.split`)
        self.split = dict.fromkeys(SPLIT_PARTS, 0.0)
        self.timers = {"global search": 0.0, "LCP": 0.0, "forces + integration": 0.0,
                       "output": 0.0, "setup": 0.0}
        self._carry_hist = None
        #: SIGINT while the time loop runs sets this; the loop stops at the next deck-step
        #: boundary (:meth:`_deferring_interrupts`)
        self._interrupt_requested = False
        self._loop_active = False
        self._compliances: dict = {}
        self._motion_spec: dict = {}
        self._last_energy: dict = {}
        self.end_energy: dict | None = None      # see _snapshot
        self.end_contacts: dict | None = None

    # ------------------------------------------------------------------ set-up helpers
    def _interface_table(self) -> InterfaceTable:
        """Contact laws per pair of material indices (walls: material M), from the deck."""
        table = InterfaceTable(default=None)
        mats = sorted(self.mat_index)

        def law(itf, ma, mb=None, wall=None):    # mb None: a wall of material `wall`
            kind = law_named(itf.model)
            pair = (material_pair(self.model, itf, kind.name, ma, mb, wall)
                    if kind.uses_materials else None)
            return kind.from_interface(itf, pair)
        for i, ma in enumerate(mats):
            for mb in mats[i:]:
                itf = self.model.interface("particle-particle", (ma, mb))
                if itf is not None:
                    table.set(self.mat_index[ma], self.mat_index[mb], law(itf, ma, mb))
            itf = self.model.interface("particle-wall", (ma,))
            if itf is not None:
                for wm, k in self.wall_index.items():
                    table.set(self.mat_index[ma], k, law(itf, ma, wall=wm))
        return table

    def _compliance(self, shape_id: int, rho: float) -> tuple[float, float]:
        """Worst point compliances (1/kg) of a shape at density rho, for the a-priori time-step
        estimate (:func:`~nurbsdem.dynamics.stepcontrol.shape_compliance`), once per pair."""
        key = (shape_id, rho)
        if key not in self._compliances:
            entry = self.model.shapes[shape_id]
            self._compliances[key] = shape_compliance(entry.shape, entry.mass(rho),
                                                      entry.mass_inertia(rho), entry.centroid)
        return self._compliances[key]

    def _particle_kind(self, shape_id: int, material_id: int) -> dict:
        """The arguments of :meth:`DemSystem.add_particle` that every particle of one shape
        and material shares: mass (kg), inertia J0 (kg m^2, file frame), material index,
        centroid in the file frame and bounding radius (m), a-priori compliances."""
        entry = self.model.shapes[shape_id]
        rho = self.model.materials[material_id].density
        return dict(mass=entry.mass(rho), J0=entry.mass_inertia(rho),
                    material=self.mat_index[material_id], centroid_file=entry.centroid,
                    radius=entry.bounding_radius, compliance=self._compliance(shape_id, rho))

    def _wall_patches(self) -> list:
        return [w.patch for w in self.model.walls]

    def _build_system(self, dt: float, motions: list[PrescribedMotion],
                      implicit_damping: bool = False, accuracy: float | None = None,
                      safety: float | None = None) -> DemSystem:
        """A DemSystem for the current bodies (order = self.bodies), walls with ``motions``;
        ``safety``: the step's fraction of the stability limit (None: the solver's)."""
        t0 = time.perf_counter()
        model = self.model
        sysm = DemSystem(dt=dt, gravity=model.gravity, interfaces=self.interfaces,
                         safety=self.safety if safety is None else safety, t0=self.time,
                         implicit_damping=implicit_damping,
                         accuracy=accuracy)
        sysm.compiled_steps = self.compiled_steps
        b = self.bodies
        Rs = b.rotation_matrices()
        kinds: dict[tuple[int, int], dict] = {}     # what particles of a shape and material share
        particles = []
        for i, kind in enumerate(zip(b.shape_id.tolist(), b.material_id.tolist())):
            if kind not in kinds:
                kinds[kind] = self._particle_kind(*kind)
            particles.append(dict(kinds[kind], x=b.position[i], R=Rs[i], v=b.velocity[i],
                                  omega=b.angular_velocity[i]))
        sysm.add_particles(particles)
        for k, w in enumerate(model.walls + model.curved_walls):    # mesh, surface: last
            sysm.add_wall(motions[k], material=self.wall_index[w.material_id], name=w.name)
        body_shape = np.array([self.shape_index[int(s)] for s in b.shape_id], np.int64)
        if self.scene is None or self.scene.n != len(b):
            self.scene = SceneContacts(self.shapes, body_shape, self._wall_patches(),
                                       **self.contact_options)
        sysm.set_contact_provider(self._curved_walls(self.scene) if model.curved_walls
                                  else self.scene)
        if model.curved_walls:
            sysm.wall_spin = self._wall_spin(sysm.walls.n)
        if self.comm is not None:
            self._decompose(sysm)
        if self._carry_hist is not None:
            sysm.initial_history = self._carry_hist
        self.timers["setup"] += time.perf_counter() - t0
        return sysm

    def _curved_walls(self, scene: SceneContacts):
        """The scene with the model's mesh and surface walls (exact spheres only; the
        Python path of the deck steps: :mod:`nurbsdem.contact.curved_walls`)."""
        from .contact.curved_walls import CurvedWall, CurvedWallContacts
        from .io.deck_curved import curved_wall_geometry, refuse_nurbs_particles, sphere_radii
        model = self.model
        shape_ids = self.bodies.shape_id
        refuse_nurbs_particles(model, shape_ids)
        if self.comm is not None:
            raise InputError("mesh and surface walls run on one MPI rank only")
        if getattr(self, "_curved_geometry", None) is None:
            self._curved_geometry = [curved_wall_geometry(w, f"{model.path}:{w.line}")
                                     for w in model.curved_walls]
        radius, spheres = sphere_radii(model, shape_ids)
        walls = [CurvedWall(kind, geom, self._curved_pose(k))
                 for k, (kind, geom) in enumerate(self._curved_geometry)]
        return CurvedWallContacts(scene, radius, spheres, walls, first_wall=len(model.walls))

    def _curved_pose(self, k: int):
        """The pose in time of mesh or surface wall k: where earlier Rotate steps left it,
        turning now when the current step rotates it (:attr:`_rotation`)."""
        from .contact.curved_walls import WallPose
        poses = self.__dict__.setdefault("_curved_rest", {})
        R0, shift0 = poses.get(k, (np.eye(3), np.zeros(3)))
        rot = getattr(self, "_rotation", None)
        if rot is None or rot[0] != k:
            return WallPose(R0=R0, shift0=shift0)
        return WallPose(omega=rot[1], center=rot[2], t0=rot[3], R0=R0, shift0=shift0)

    def _curved_poses(self, t: float, wall_d: np.ndarray) -> list | None:
        """(R, t) of each mesh or surface wall at time t (s) with the walls' displacements
        wall_d (W,3) m, for walls.pvd; None: none."""
        if not self.model.curved_walls:
            return None
        first = len(self.model.walls)
        return [self._curved_pose(k).at(t, wall_d[first + k])
                for k in range(len(self.model.curved_walls))]

    def _wall_spin(self, n_walls: int) -> np.ndarray:
        """(W,6) angular velocity and centre of each wall of the system (the one a Rotate
        step turns; 0 for the others)."""
        spin = np.zeros((n_walls, 6))
        rot = getattr(self, "_rotation", None)
        if rot is not None:
            spin[len(self.model.walls) + rot[0]] = np.concatenate([rot[1], rot[2]])
        return spin

    def _decompose(self, sysm: DemSystem) -> None:
        """Decompose the system over the ranks (a scene carried over from the previous step
        keeps its cut and ghosts)."""
        from .parallel import Domain
        old = self.scene.domain
        sysm.compiled_steps = False
        dom = Domain(self.comm, sysm, self.scene, owner=None if old is None else old.owner,
                     plan=None if old is None else old.plan)
        dom.cuts = old.cuts if old is not None else 1
        sysm.domain = self.scene.domain = self.domain = dom

    def _fixed_motions(self) -> list[PrescribedMotion]:
        return [_constant_motion(d) for d in self.wall_offset]

    def _sync_bodies_from_system(self) -> None:
        """Copy the system's body state into ``self.bodies`` (positions, orientations, velocities)."""
        b = self.bodies
        b.position, b.quaternion, b.velocity, b.angular_velocity = self.system.body_state()

    # ------------------------------------------------------------------ energies
    def _energy_row(self, e: EnergySample) -> dict:
        diss = self.energy_offset["dissipated"] + e.dissipated
        ext = self.energy_offset["external_work"] + e.external_work
        mech = e.mechanical
        if self.mech0 is None:
            self.mech0 = mech
        row = dict(kinetic=e.kinetic, potential=e.potential, elastic=e.elastic,
                   dissipated=diss, external_work=ext, mechanical=mech,
                   balance_error=mech - self.mech0 - ext + diss)
        self._last_energy = row
        return row

    def _snapshot(self) -> None:
        """Keep what the end of a dynamic step leaves to read between steps (no side effects
        on the run): :attr:`end_energy` (the energies of ``monitors/energy.csv`` now) and
        :attr:`end_contacts` (the active contacts of the last evaluation, arrays)."""
        e = self.system.energy()
        diss = self.energy_offset["dissipated"] + e.dissipated
        ext = self.energy_offset["external_work"] + e.external_work
        mech0 = self.mech0 if self.mech0 is not None else e.mechanical
        self.end_energy = dict(step=self.step_index, time=float(self.time),
                               kinetic=float(e.kinetic), potential=float(e.potential),
                               elastic=float(e.elastic), dissipated=float(diss),
                               external_work=float(ext), mechanical=float(e.mechanical),
                               balance_error=float(e.mechanical - mech0 - ext + diss))
        out = self._contact_output()
        n = len(self.bodies)
        if out is None:
            z3 = np.zeros((0, 3))
            out = dict(point=z3, force_normal=z3, force_tangential=z3.copy(),
                       penetration=np.zeros(0), degenerated=np.zeros(0, np.int64),
                       body_a=np.zeros(0, np.int64), body_b=np.zeros(0, np.int64))
            normal = z3.copy()
        else:
            normal = np.array(self.scene.last.normal, float)
        self.end_contacts = dict(
            body_a=np.array(out["body_a"], np.int64), body_b=np.array(out["body_b"], np.int64),
            point=np.array(out["point"], float), normal=normal,
            depth=np.array(out["penetration"], float),
            force_normal=np.array(out["force_normal"], float),
            force_tangential=np.array(out["force_tangential"], float),
            degenerated=np.array(out["degenerated"]), n_particles=n, step=self.step_index)

    def _close_system(self) -> None:
        """Fold the current system's cumulative energies into the offsets before replacing it."""
        if self.system is None:
            return
        e = self.system.energy()
        self.energy_offset["dissipated"] += e.dissipated
        self.energy_offset["external_work"] += e.external_work
        self._carry_hist = (self.system.hist_keys.copy(), self.system.hist_springs.copy())
        self.system = None

    # ------------------------------------------------------------------ output
    def _write_monitors(self, writers: OutputWriters, smp: MonitorSample) -> None:
        """The rows of ``monitors/*.csv`` of one sample (energies with the run's offsets)."""
        t = smp.time
        row = self._energy_row(smp.energy)
        writers.monitors.energy(t, row["kinetic"], row["potential"], row["elastic"],
                                row["dissipated"], row["external_work"], row["balance_error"])
        if self.scene is not None and self.scene.last is not None:
            writers.monitors.contacts(t, smp.monitored, smp.active, smp.degenerated, smp.failed)
            if smp.hertz is not None:          # Hertz–Mindlin interfaces (not linear laws)
                writers.monitors.hertz(t, *smp.hertz)
        if self.model.wall_names:
            writers.monitors.walls(t, smp.wall_displacement, smp.wall_reaction, smp.wall_torque)

    def _sample(self, writers: OutputWriters, force: bool = False,
                samples: tuple[MonitorSample, ...] = (),
                states: tuple[StateSample, ...] = ()) -> None:
        """Write the monitor ``samples`` and the ParaView and results ``states`` the deck
        steps took, then what falls due now (with ``force`` the monitors too: the start of a
        run)."""
        t0 = time.perf_counter()
        out = self.model.output
        t = self.time
        s = self.system
        with writers.monitors.batch():          # the rows of all samples, flushed once
            for smp in samples:
                self._write_monitors(writers, smp)
            if force:
                self._write_monitors(writers, s.monitor_sample())
        for st in states:
            self._write_state(writers, st)
        vtk = force or _due(t, out.vtk_every, s.dt)
        results = force or _due(t, out.results_interval, s.dt)
        if vtk or results:
            self._sync_bodies_from_system()
        if vtk:
            writers.paraview.write(t, self.bodies, wall_displacement=s.wall_displacement,
                                   contacts=self._contact_output(),
                                   curved_poses=self._curved_poses(t, s.wall_displacement))
        if results:
            writers.results.append(t, self.bodies)
        self.timers["output"] += time.perf_counter() - t0

    def _write_state(self, writers: OutputWriters, st: StateSample) -> None:
        """The ParaView and results samples due at a state the deck steps kept (what
        :meth:`_sample` writes live from the system at the present time)."""
        out = self.model.output
        bodies = replace(self.bodies, position=st.position, quaternion=st.quaternion,
                         velocity=st.velocity, angular_velocity=st.angular_velocity)
        dt = self.system.dt
        if _due(st.time, out.vtk_every, dt):
            writers.paraview.write(st.time, bodies, wall_displacement=st.wall_displacement,
                                   contacts=st.contacts,
                                   curved_poses=self._curved_poses(st.time, st.wall_displacement))
        if _due(st.time, out.results_interval, dt):
            writers.results.append(st.time, bodies)

    def _contact_output(self) -> dict | None:
        """The last evaluation's contacts for the ParaView writer (None without a scene)."""
        if self.scene is None or self.system is None:
            return None
        return self.system.contact_output()

    # ------------------------------------------------------------------ checkpoints
    def _checkpoint(self, writers: OutputWriters) -> None:
        if not self.write_output:
            return
        t0 = time.perf_counter()
        state = {
            "version": __version__, "deck": self.model.text, "time": self.time,
            "step_index": self.step_index, "step_progress": self.step_progress,
            "bodies": self.bodies.as_dict(), "wall_offset": self.wall_offset,
            "energy_offset": dict(self.energy_offset),
            "mech0": self.mech0 if self.mech0 is not None else float("nan"),
            "system": self.system.get_state() if self.system is not None else {},
            "scene": self.scene.state() if self.scene is not None else {},   # collective
            "carry_hist": ({"keys": self._carry_hist[0], "springs": self._carry_hist[1]}
                           if self._carry_hist is not None else {}),
            "motion": self._motion_spec,
            # where Rotate steps left the mesh and surface walls: R (9,) then t (3,) each
            "curved_rest": {str(k): np.concatenate([R.ravel(), t]) for k, (R, t)
                            in self.__dict__.get("_curved_rest", {}).items()},
        }
        if self.rank == 0:          # written by the output worker: a copy of the state
            writers.checkpoint(save_checkpoint, self.outdir / CHECKPOINT_NAME,
                               copy.deepcopy(state))
        self.timers["output"] += time.perf_counter() - t0

    def _load_restart(self) -> dict:
        """Read the checkpoint, check it belongs to this deck (the parsed model is compared,
        so comments and layout may change) and restore the run's state from it."""
        from .io.checkpoint import restart_state
        if self.restart_check is not None:
            st = self.restart_check(self.restart_path)
        else:
            st = restart_state(self.restart_path, self.model)
        try:
            self.time = float(st["time"])
            self.step_index = int(st["step_index"])
            self.step_progress = int(st["step_progress"])
            self.bodies = Bodies.from_dict(st["bodies"])
            off = np.array(st["wall_offset"], float).reshape(-1, 3)
            self.wall_offset = np.zeros((len(self.model.wall_names), 3))
            self.wall_offset[:len(off)] = off     # mesh and surface walls: after the flat
            self.energy_offset = {k: float(v) for k, v in dict(st["energy_offset"]).items()}
            self.mech0 = None if math.isnan(st["mech0"]) else float(st["mech0"])
            ch = st.get("carry_hist") or {}
            self._carry_hist = (ch["keys"], ch["springs"]) if ch else None
            self._curved_rest = {int(k): (np.asarray(v, float)[:9].reshape(3, 3),
                                          np.asarray(v, float)[9:12])
                                 for k, v in dict(st.get("curved_rest") or {}).items()}
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            raise InputError(f"the checkpoint is incomplete or corrupted ({type(exc).__name__}: "
                             f"{exc})", path=str(self.restart_path)) from None
        if not 0 <= self.step_index <= (len(self.model.steps) if self.restart_check is None
                                        else 10 ** 9):
            raise InputError(f"the checkpoint is corrupted (step index {self.step_index})",
                             path=str(self.restart_path))
        return st

    # ------------------------------------------------------------------ steps
    def _run_dynamic(self, step, writers: OutputWriters, motions: list[PrescribedMotion],
                     restored: dict | None) -> None:
        duration = float(step.duration)
        dt = float(step.time_step)
        n_total = max(1, int(round(duration / dt)))
        if abs(n_total * dt - duration) > 1e-9 * duration:
            raise self.model.error(f"Step {step.id}: Duration {duration} is not a whole number "
                                   f"of TimeStep {dt}", step.line)
        step_t0 = self.time - self.step_progress * dt
        self.system = self._build_system(dt, motions, step.damping == "implicit",
                                         getattr(step, "accuracy", None),
                                         getattr(step, "safety", None))
        scene_state = restored.get("scene") if restored else None
        if scene_state:
            self.scene.set_state(scene_state)
        self.system.initialize()
        if restored and restored.get("system"):
            self.system.set_state(restored["system"])
            if scene_state:
                self.scene.set_state(scene_state)
        elif self.mech0 is None:
            self._sample(writers, force=True)
        sysm = self.system
        log.info("step %d: %s, %d time steps of %g s (%d sub-step(s) of %.3g s each)",
                 step.id, step.kind, n_total, dt, sysm.substeps, sysm.dt_internal)
        if sysm.domain is not None:
            log.info("step %d: %s", step.id, sysm.domain.describe())
        t_load = time.perf_counter()
        sysm.load_compiled()        # numba's cached kernels: set-up, not the time loop
        self.timers["setup"] += time.perf_counter() - t_load
        self.progress.start(f"step {step.id} {step.kind}", duration)
        self._loop_active = True
        try:
            self._time_loop(writers, n_total, step_t0, dt)
        finally:
            self._loop_active = False
        self.progress.update(self.time - step_t0, dt, sysm.substeps, self.scene.last.active, force=True)
        self.progress.finish()
        self._sync_bodies_from_system()
        self.summary.accuracy_repeats += sysm.accuracy_repeats
        self.wall_offset = sysm.wall_displacement.copy()
        self._snapshot()
        self._close_system()

    def _time_loop(self, writers: OutputWriters, n_total: int, step_t0: float,
                   dt: float) -> None:
        """The deck steps of a dynamic step, in compiled chunks up to the next checkpoint or
        the step's end; output of each chunk written after it, a Ctrl-C obeyed between them
        (a checkpoint of that moment first)."""
        sysm = self.system
        ck_every = self.model.output.checkpoint_every
        while self.step_progress < n_total:
            t_before = time.perf_counter()
            g0, l0, n0 = self.scene.timers.global_search, self.scene.timers.lcp, self.scene.timers.lcps
            e0 = self.scene.timers.calls
            parts0 = dict(sysm.split)
            n, monitors_due, states_due = self._steps_to_event(n_total - self.step_progress,
                                                               ck_every)
            try:
                done = sysm.steps(n, monitors_due, states_due)
            except InstabilityError:
                self.time = sysm.time
                for smp in sysm.last_steps.samples:     # the deck steps done before it
                    self._write_monitors(writers, smp)
                for st in sysm.last_steps.states:
                    self._write_state(writers, st)
                self._sync_bodies_from_system()
                self._checkpoint(writers)
                raise
            dt_wall = time.perf_counter() - t_before
            g = self.scene.timers.global_search - g0
            lc = self.scene.timers.lcp - l0
            self.timers["global search"] += g
            self.timers["LCP"] += lc
            self.timers["forces + integration"] += dt_wall - g - lc
            for k, v in sysm.split.items():
                self.split[k] += v - parts0[k]
            self.step_progress += done
            self.time = sysm.time
            self.summary.steps += done
            self.summary.lcps += self.scene.timers.lcps - n0
            self.summary.evaluations += self.scene.timers.calls - e0
            cs = self.scene.last
            tally = sysm.last_steps
            self.summary.substeps += tally.substeps
            self.summary.active_max = max(self.summary.active_max, tally.active_max)
            self.summary.active_total += tally.active_sum
            self.summary.degenerated += tally.degenerated_sum
            self.summary.failed += tally.failed_sum
            self._sample(writers, samples=tally.samples, states=tally.states)
            if self.step_progress < n_total and (_due(self.time, ck_every, dt)
                                                 or self._interrupt_requested):
                self._sync_bodies_from_system()
                self._checkpoint(writers)
                if self._interrupt_requested:
                    self.progress.finish()
                    raise self._interrupted(writers)
            self.progress.update(self.time - step_t0, dt, sysm.substeps, cs.active)

    def _steps_to_event(self, left: int,
                        ck_every: float) -> tuple[int, np.ndarray, np.ndarray]:
        """Deck steps n from now to the next one at which a checkpoint falls due (monitors too
        with Hertz–Mindlin laws), or to the end of the solution step (``left`` deck steps), at
        most MAX_COMPILED_STEPS, and at most as many ParaView/results states as
        STATE_BUDGET_BYTES holds; with the flags of :meth:`_due_flags` for those n deck
        steps.  The monitors, ParaView and results samples in between are taken by the system
        at the deck steps' ends: the compiled loop runs on through them."""
        out = self.model.output
        sysm = self.system
        n = min(left, MAX_COMPILED_STEPS)
        # monitors are recorded inside the compiled loop, except the Hertz row (taken live)
        monitors = out.monitors_every if sysm.uses_hertz else 0.0
        for every in (monitors, ck_every):
            if every > 0:
                n = min(n, _steps_to_due(sysm.t0, sysm.step_count, sysm.dt, every, n))
        monitors_due, states_due = self._due_flags(n)
        due = np.flatnonzero(states_due)
        most = max(1, STATE_BUDGET_BYTES // max(sysm.state_sample_bytes(), 1))
        if len(due) > most:             # the last deck step's sample is taken live
            n = int(due[most - 1]) + 1
        return n, monitors_due[:n], states_due[:n]

    def _due_flags(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """(monitors, states), (n,) bool each: the next n deck steps at whose end the monitors
        fall due, and the ParaView or results output."""
        sysm, out = self.system, self.model.output
        times = sysm.t0 + (sysm.step_count + np.arange(1, n + 1)) * sysm.dt
        dt = sysm.dt
        return (_due_mask(times, out.monitors_every, dt),
                _due_mask(times, out.vtk_every, dt) | _due_mask(times, out.results_interval, dt))

    def _run_replicate(self, step: ReplicateStep, writers: OutputWriters) -> None:
        before = self._mechanical_of(self.bodies)
        self.bodies = replicate_step(self.model, self.bodies, step)
        after = self._mechanical_of(self.bodies)
        if self.mech0 is not None:
            # the ledger has its reference (the first energy row): the copies' energy enters
            # from outside; before that row the copies are part of the initial state, which
            # the reference takes in (booking them too would count their energy twice)
            self.energy_offset["external_work"] += after - before
        self.scene = None
        self._carry_hist = None
        log.info("step %d: replicated into %d layers: %d particles", step.id, step.layers,
                 len(self.bodies))

    def _mechanical_of(self, bodies: Bodies) -> float:
        """Kinetic + potential energy of a set of bodies (no contacts), J."""
        g = self.model.gravity
        e = 0.0
        for i in range(len(bodies)):
            entry = self.model.shapes[int(bodies.shape_id[i])]
            rho = self.model.materials[int(bodies.material_id[i])].density
            m = entry.mass(rho)
            R = quat_to_matrix(bodies.quaternion[i])
            J = R @ entry.mass_inertia(rho) @ R.T
            w = bodies.angular_velocity[i]
            e += 0.5 * m * bodies.velocity[i] @ bodies.velocity[i] + 0.5 * w @ J @ w
            e -= m * g @ bodies.position[i]
        return float(e)

    def _wall_index(self, name: str) -> int:
        return self.model.wall_names.index(name)

    def _to_contact(self, step: MoveWallStep) -> None:
        """Translate the wall along its direction until the nearest particle is ``gap`` away."""
        k = self._wall_index(step.wall)
        wall = self.model.walls[k]
        n = wall.normal
        direction = n if step.direction is None else np.asarray(step.direction, float)
        direction = direction / np.linalg.norm(direction)
        speed = float(direction @ n)     # how fast the gap closes per metre of travel
        if speed <= 1e-12:
            raise self.model.error(f"Step {step.id}: the direction does not move wall "
                                   f"'{step.wall}' towards the particles", step.line)
        origin = wall.center + self.wall_offset[k]
        dist = self._distance_to_plane(origin, n)
        travel = (dist - step.gap) / speed
        self.wall_offset[k] = self.wall_offset[k] + travel * direction
        log.info("step %d: wall %s moved %.6g m to a gap of %g m", step.id, step.wall, travel,
                 step.gap)

    def _distance_to_plane(self, origin: np.ndarray, n: np.ndarray) -> float:
        """Smallest signed distance (m) from the particles to the plane (origin, n), measured
        along n, exactly: the support point of each particle along −n (paper Eq. 8)."""
        from .contact.wall import detect_wall
        b = self.bodies
        if len(b) == 0:
            raise InputError("MoveWall ToContact needs particles")
        t1 = np.cross(n, [1.0, 0, 0])
        if np.linalg.norm(t1) < 0.5:
            t1 = np.cross(n, [0, 1.0, 0])
        t1 /= np.linalg.norm(t1)
        t2 = np.cross(n, t1)
        big = 1e3 * (1.0 + float(np.abs(b.position).max()))
        o = origin - big * (t1 + t2)
        Rs = b.rotation_matrices()
        best = math.inf
        for i in range(len(b)):
            entry = self.model.shapes[int(b.shape_id[i])]
            pos = b.position[i] - Rs[i] @ entry.centroid
            # move a probe plane through the particle's centroid so the sphere test passes
            shift = float(n @ (b.position[i] - origin))
            res = detect_wall(entry.shape, (pos, Rs[i]), (o + shift * n, 2 * big * t1, 2 * big * t2))
            best = min(best, shift + res.signed_distance)
        return best

    # ------------------------------------------------------------------ main loop
    def run(self) -> RunSummary:
        """Run every step (or the rest of them after a restart); returns the summary."""
        self.start()
        try:
            self.run_pending()
        except BaseException:
            self.abort()
            raise
        return self.finish()

    @property
    def started(self) -> bool:
        """Whether :meth:`start` has opened the writers (and :meth:`finish` not yet closed them)."""
        return self._writers is not None

    def start(self) -> None:
        """Begin a run: read the restart checkpoint if any and open the writers. Steps are then
        run by :meth:`run_pending` (all of ``model.steps`` not run yet; a model may gain steps
        between calls, as :class:`~nurbsdem.simulation.Simulation` adds them) and the run is
        ended by :meth:`finish` (or :meth:`abort` after an error)."""
        self._wall0 = time.perf_counter()
        self._restored = None
        self._interrupt_requested = False
        resumed = self._finished_once     # writers closed by finish(): continue their files
        if self.restart_path is not None and not resumed:
            self._restored = self._load_restart()
        if self.write_output and self.rank == 0:
            self._writers = OutputWriters(self.model, restart_time=(
                self.time if (self._restored or resumed) else None),
                background=self.background_output)
            if self._restored:
                self._results_deck = None       # the checkpointed run's deck: written anew
            elif not resumed:
                self._results_deck = self.model.text
        else:
            self._writers = _NoWriters()
        self._motion_spec = {}

    def run_pending(self) -> None:
        """Run the steps of ``model.steps`` from :attr:`step_index` on (after a restart, the
        steps before the checkpoint's are done already and are not run again)."""
        steps = self.model.steps
        while self.step_index < len(steps):
            self.run_step(steps[self.step_index])

    def run_step(self, step) -> None:
        """Run one step, the one at :attr:`step_index` (the next to run), with the open writers;
        then write the end-of-step checkpoint."""
        writers = self._writers
        if writers is None:
            raise RuntimeError("Solver.run_step before Solver.start")
        with self._deferring_interrupts():
            self._run_step(step, writers)
        if self._interrupt_requested:    # Ctrl-C in the step's last chunk: after its checkpoint
            raise self._interrupted(writers)

    def _run_rotation(self, step: MoveWallStep, writers: OutputWriters, restored) -> None:
        """``MoveWall NAME Rotate``: a dynamic step in which mesh or surface wall NAME turns
        at the step's angular velocity about its centre, translating with the centre when
        the step has a displacement; it stays where it turned to."""
        k = self._wall_index(step.wall) - len(self.model.walls)
        motions = self._wall_motions(step, restored)
        d0, t_start = self._motion_spec["d0"], self._motion_spec["t_start"]
        # the centre before the wall's displacement (the pose adds it back: WallPose)
        self._rotation = (k, np.asarray(step.angular_velocity, float),
                          np.asarray(step.center, float) - d0, t_start)
        try:
            self._run_dynamic(step, writers, motions, restored)
            end = self._curved_pose(k).at(self.time)
        finally:
            self._rotation = None
        self.__dict__.setdefault("_curved_rest", {})[k] = end

    def _wall_motions(self, step: MoveWallStep, restored) -> list[PrescribedMotion]:
        """The walls' motions in a MoveWall step: the step's wall translates by its
        ``displacement`` (if any) at constant velocity over the step, from where it is; the
        others stay where they are.  Where the wall was (d0, m) and when the step started
        (t_start, s) are kept for the checkpoint (``motion``), so that a restart continues
        from the same numbers."""
        k = self._wall_index(step.wall)
        spec = restored.get("motion") if restored else None
        if spec:
            d0, t_start = np.array(spec["d0"], float), float(spec["t_start"])
        else:
            d0 = self.wall_offset[k].copy()
            t_start = self.time - self.step_progress * float(step.time_step)
        self._motion_spec = {"d0": d0, "t_start": t_start}
        motions = self._fixed_motions()
        if step.displacement is not None:
            motions[k] = PrescribedMotion.piecewise_linear(
                [t_start, t_start + step.duration], [d0, d0 + step.displacement])
        return motions

    def _run_step(self, step, writers: OutputWriters) -> None:
        restored = self._restored
        if isinstance(step, DynamicStep):
            self._motion_spec = {}
            self._run_dynamic(step, writers, self._fixed_motions(), restored)
        elif isinstance(step, ReplicateStep):
            self._run_replicate(step, writers)
        elif isinstance(step, MoveWallStep) and step.to_contact:
            self._to_contact(step)
        elif isinstance(step, MoveWallStep) and step.rotate:
            self._run_rotation(step, writers, restored)
        elif isinstance(step, MoveWallStep):
            self._run_dynamic(step, writers, self._wall_motions(step, restored), restored)
        else:  # pragma: no cover - the parser knows no other steps
            raise InputError(f"unknown step kind {step.kind}")
        self._restored = None
        self.step_index += 1
        self.step_progress = 0
        self._checkpoint_end_of_step(writers)

    def abort(self) -> None:
        """End a run that failed: a run without a complete sample puts the previous results back."""
        writers, self._writers = self._writers, None
        if writers is not None:
            try:
                writers.abort()
            finally:
                writers.close()

    def finish(self) -> RunSummary:
        """Close the writers and return the summary of the run."""
        writers, self._writers = self._writers, None
        if writers is not None:
            t0 = time.perf_counter()
            writers.close()             # waits for the background writes
            self.timers["output"] += time.perf_counter() - t0
            self._finished_once = True
        s = self.summary
        s.wall_time = time.perf_counter() - self._wall0
        s.simulated_time = self.time
        s.particles = len(self.bodies)
        s.timers = {k: v for k, v in self.timers.items()}
        s.split = dict(self.split)
        row = self._last_energy
        s.balance_error = row.get("balance_error", 0.0)
        s.balance_scale = max(abs(row.get("dissipated", 0.0)) + abs(row.get("external_work", 0.0)), 0.0)
        return s

    @contextlib.contextmanager
    def _deferring_interrupts(self):
        """While a step runs, Ctrl-C (SIGINT) inside its time loop only sets a flag, obeyed
        at the next deck-step boundary (:meth:`_time_loop`): a KeyboardInterrupt raised in
        the middle of the compiled loop's threads or of a background write kills the process
        or leaves files behind the checkpoint.  Outside the time loop (set-up, compiling) the
        handler that was there is called.  Installed only where Python allows it (the main
        thread) and on one rank (several MPI ranks would have to agree on where to stop);
        the previous handler is put back after the step."""
        import signal
        import threading
        previous = signal.getsignal(signal.SIGINT)
        if (self.comm is not None or threading.current_thread() is not threading.main_thread()
                or previous in (None, signal.SIG_IGN)):
            yield
            return

        def handler(signum, frame):
            if self._loop_active:
                self._interrupt_requested = True
            elif callable(previous):
                previous(signum, frame)
            else:                               # SIG_DFL
                raise KeyboardInterrupt

        signal.signal(signal.SIGINT, handler)
        try:
            yield
        finally:
            signal.signal(signal.SIGINT, previous)

    def _interrupted(self, writers: OutputWriters) -> Interrupted:
        """The exception that ends a run stopped by Ctrl-C, once the checkpoint just queued
        (and everything before it) is on disk."""
        self._interrupt_requested = False
        where = ""
        if self.write_output and self.rank == 0:
            writers.paraview.sync()             # the background worker's checkpoint
            path = self.outdir / CHECKPOINT_NAME
            where = (f"; its checkpoint is {path} (continue with --restart {path}, or "
                     f"Simulation.from_deck(..., restart=...))")
        return Interrupted(f"interrupted at t = {self.time:.9g} s{where}")

    def _checkpoint_end_of_step(self, writers: OutputWriters) -> None:
        self._motion_spec = {}
        self._checkpoint(writers)
        if self.write_output and self.rank == 0 and self.model.text != self._results_deck:
            # a model extended step by step: results.h5 keeps the deck of the steps run so far
            self._results_deck = self.model.text
            writers.results.set_deck(self._results_deck)


class _NoWriters:
    """The writers of a run that writes no files (a :class:`~nurbsdem.simulation.Simulation`
    without ``output``): every call does nothing."""

    class _Sink:
        def __getattr__(self, name):
            return lambda *args, **kwargs: None

        def batch(self):            # MonitorWriter.batch
            return contextlib.nullcontext()

    def __init__(self) -> None:
        self.paraview = self.monitors = self.results = self._Sink()

    def sync(self) -> None:
        pass

    def abort(self) -> None:
        pass

    def close(self) -> None:
        pass


def _share_cores(comm) -> None:
    """The compiled kernels' threads of a rank: its node's cores shared among the node's
    ranks (unless NUMBA_NUM_THREADS says otherwise), so that ranks do not oversubscribe."""
    import os

    import numba

    from .parallel import threads_per_rank
    if "NUMBA_NUM_THREADS" not in os.environ:
        numba.set_num_threads(min(numba.config.NUMBA_NUM_THREADS, threads_per_rank(comm)))


def _constant_motion(d: np.ndarray) -> PrescribedMotion:
    return PrescribedMotion.fixed(d)


def _steps_to_due(t0: float, count: int, dt: float, every: float, n_max: int) -> int:
    """The first k in 1..n_max whose deck step (ending at t0 + (count + k)·dt) is due for
    output at interval ``every`` (:func:`nurbsdem.io.intervals.steps_to_due`), n_max if none."""
    return intervals.steps_to_due(t0, count, dt, every, n_max)


def _due(t: float, every: float, dt: float) -> bool:
    """Whether the deck step of ``dt`` s ending at time t (s) is the first at or after a
    multiple of ``every`` (s) (:mod:`nurbsdem.io.intervals`)."""
    return intervals.due(t, every, dt)


def _due_mask(t: np.ndarray, every: float, dt: float) -> np.ndarray:
    """(n,) bool: :func:`_due` of each time t (n,) s."""
    return intervals.due_mask(t, every, dt)

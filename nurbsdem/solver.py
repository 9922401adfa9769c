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
* ``MoveWall … Table``: a dynamic step in which a wall follows a table of displacements (and
  turns, mesh and surface walls); a step moves several walls when its id repeats
  (:mod:`nurbsdem.wall_moves`).
* ``MoveWall … Force``: a dynamic step in which a flat wall is servo-controlled to a push of
  the particles, its speed set after each deck step (:mod:`nurbsdem.wall_servo`).

Energies written to ``monitors/energy.csv`` are cumulative over the whole run.
Checkpoints (``checkpoint.h5``, :mod:`nurbsdem.run_checkpoint`) are written every
``Checkpoint Every`` seconds of simulated time and at the end of each step; ``--restart``
continues bit-for-bit.  Each output interval is served by the first deck time step at or
after each of its multiples (:mod:`nurbsdem.output_schedule`).  Ctrl-C (SIGINT) during the
time loop stops the run at the end of a deck time step, after a checkpoint of that moment
(:class:`~nurbsdem.sigint.Interrupted`, a KeyboardInterrupt; ``nurbsdem solve`` exits with
status 130).  The Solver composes these parts: :class:`~nurbsdem.system_assembly.SystemAssembly`
(the system of a step), :class:`~nurbsdem.curved_wall_motion.CurvedWallMotion` (mesh and
surface walls in time), :mod:`nurbsdem.instant_steps` (steps that take no time),
:mod:`nurbsdem.flow_run` (inlets and outlets: a timed step in segments, the particle set
changed and the system built anew between them) and :mod:`nurbsdem.run_report` (progress
line and summary).
"""
from __future__ import annotations

import contextlib
import logging
import time
from dataclasses import replace
from pathlib import Path
from typing import Callable

import numpy as np

from .contact.scene import SceneContacts
from . import wall_moves
from .curved_wall_motion import CurvedWallMotion
from .dynamics import DemSystem, PrescribedMotion
from .dynamics.monitor import MonitorSample, StateSample
from .dynamics.system import SPLIT_PARTS, InstabilityError
from .energy_ledger import EnergyLedger
from .errors import InputError
from .flow_run import FlowRun, exchange
from .instant_steps import mechanical_energy, to_contact
from .io.intervals import due
from .io.writers import OutputWriters
from .jit import launch_threads
from .model import Bodies, DynamicStep, Model, MoveWallStep, ReplicateStep
from .output_schedule import steps_to_event
from .placement import replicate_step
from .run_checkpoint import CHECKPOINT_NAME, load_restart, write_checkpoint
from .run_report import ChunkMeter, Progress, RunSummary
from .sigint import Interrupted, SigintDeferral
from .system_assembly import SystemAssembly, decompose

log = logging.getLogger("nurbsdem")


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
        #: the inlets and outlets (:mod:`nurbsdem.flow_run`)
        self.flow = FlowRun(model)
        if self.comm is not None:
            _share_cores(self.comm)
            quiet = quiet or self.rank > 0      # one progress line: rank 0's
        self.compiled_steps = bool(compiled_steps)
        #: while :attr:`compiled_steps` is off, an optional test, asked before each chunk of
        #: deck steps, of whether the compiled loop may be taken now (``nurbsdem solve``'s
        #: first run: the loop's compilation in the background is done); True turns
        #: compiled_steps on for the rest of the run (the same results, bit for bit)
        self.compiled_when: Callable[[], bool] | None = None
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
        self.assembly = SystemAssembly(model)
        self.mat_index = self.assembly.mat_index
        self.wall_index = self.assembly.wall_index
        self.interfaces = self.assembly.interfaces
        self.curved = CurvedWallMotion(model)
        #: each wall's displacement (m) from its deck position: flat walls, then mesh and
        #: surface walls (their turns are in ``curved``)
        self.wall_offset = np.zeros((len(model.wall_names), 3))
        self.bodies: Bodies = model.bodies.copy() if model.bodies is not None else Bodies.empty()
        self.time = 0.0
        self.step_index = 0          # next step to run
        self.step_progress = 0       # deck time steps done inside the current step
        self.ledger = EnergyLedger()
        self.system: DemSystem | None = None
        self.scene: SceneContacts | None = None
        self.summary = RunSummary()
        #: parts of timers["forces + integration"] (:attr:`RunSummary.split`)
        self.split = dict.fromkeys(SPLIT_PARTS, 0.0)
        self.timers = {"global search": 0.0, "LCP": 0.0, "forces + integration": 0.0,
                       "output": 0.0, "setup": 0.0}
        #: the contact history (keys, springs) the last system left to the next one
        self.carry_hist = None
        #: the last LCP rows and certificates with the bodies' odometers (keys, rows_f,
        #: rows_i, budget, odo) an exchange of particles left to the next scene
        #: (:func:`~nurbsdem.flow_run._carried_rows`)
        self.carry_rows = None
        self.sigint = SigintDeferral()
        #: where the walls of the running ``MoveWall`` step started and when (``d0``,
        #: ``offsets``, ``t_start``) and its servo walls' state (``servo``:
        #: :mod:`nurbsdem.wall_servo`), kept in checkpoints
        self.motion_spec: dict = {}
        #: the servo walls of the running MoveWall step (:class:`~nurbsdem.wall_servo.Servo`;
        #: None: none), their speeds set after each deck step
        self.servo = None
        self.end_energy: dict | None = None      # see _snapshot
        self.end_contacts: dict | None = None

    # ------------------------------------------------------------------ systems
    def _build_system(self, dt: float, motions: list[PrescribedMotion],
                      implicit_damping: bool = False, accuracy: float | None = None,
                      safety: float | None = None) -> DemSystem:
        """A DemSystem for the current bodies (order = self.bodies), walls with ``motions``;
        ``safety``: the step's fraction of the stability limit (None: the solver's)."""
        t0 = time.perf_counter()
        model = self.model
        sysm = self.assembly.system(self.bodies, self.time, dt, motions,
                                    self.safety if safety is None else safety,
                                    self.compiled_steps, implicit_damping, accuracy)
        self.scene = self.assembly.scene(self.scene, self.bodies, self.contact_options)
        if self.carry_rows is not None:      # an exchange's renumbered rows: warm starts
            self.scene.carry_rows(*self.carry_rows)
            self.carry_rows = None
        if model.curved_walls:
            self.curved.attach(sysm, self.curved.contacts(self.scene, self.bodies.shape_id))
        else:
            sysm.set_contact_provider(self.scene)
        if self.comm is not None:
            self.domain = decompose(self.comm, sysm, self.scene)
        if self.carry_hist is not None:
            sysm.initial_history = self.carry_hist
        self.timers["setup"] += time.perf_counter() - t0
        return sysm

    def _fixed_motions(self) -> list[PrescribedMotion]:
        return [PrescribedMotion.fixed(d) for d in self.wall_offset]

    def _sync_bodies_from_system(self) -> None:
        """Copy the system's body state into ``self.bodies`` (positions, orientations, velocities)."""
        b = self.bodies
        b.position, b.quaternion, b.velocity, b.angular_velocity = self.system.body_state()

    # ------------------------------------------------------------------ energies
    @property
    def energy_offset(self) -> dict:
        """The dissipated energy and external work (J) of the systems closed so far."""
        return self.ledger.offset

    def _snapshot(self) -> None:
        """Keep what the end of a dynamic step leaves to read between steps (no side effects
        on the run): :attr:`end_energy` (the energies of ``monitors/energy.csv`` now) and
        :attr:`end_contacts` (the active contacts of the last evaluation, arrays)."""
        self.end_energy = self.ledger.end_row(self.system.energy(), self.step_index, self.time)
        out = self._contact_output()
        normal = None if out is None else np.array(self.scene.last.normal, float)
        self.end_contacts = _contact_arrays(out, normal, len(self.bodies), self.step_index)

    def _close_system(self) -> None:
        """Fold the current system's cumulative energies into the offsets before replacing it."""
        if self.system is None:
            return
        self.ledger.close(self.system.energy())
        self.carry_hist = (self.system.hist_keys.copy(), self.system.hist_springs.copy())
        self.system = None

    # ------------------------------------------------------------------ output
    def _write_monitors(self, writers: OutputWriters, smp: MonitorSample) -> None:
        """The rows of ``monitors/*.csv`` of one sample (energies with the run's offsets)."""
        t = smp.time
        row = self.ledger.row(smp.energy)
        writers.monitors.energy(t, row["kinetic"], row["potential"], row["elastic"],
                                row["dissipated"], row["external_work"], row["balance_error"])
        if self.scene is not None and self.scene.last is not None:
            writers.monitors.contacts(t, smp.monitored, smp.active, smp.degenerated, smp.failed)
            if smp.hertz is not None:          # Hertz–Mindlin interfaces (not linear laws)
                writers.monitors.hertz(t, *smp.hertz)
        if self.model.wall_names:
            writers.monitors.walls(t, smp.wall_displacement, smp.wall_reaction, smp.wall_torque,
                                   smp.wall_work)

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
        if force or due(t, out.vtk_every, s.dt) or due(t, out.results_interval, s.dt):
            self._sync_bodies_from_system()
            b = self.bodies
            self._write_state(writers, StateSample(t, b.position, b.quaternion, b.velocity,
                                                   b.angular_velocity, s.wall_displacement,
                                                   self._contact_output()), force)
        self.timers["output"] += time.perf_counter() - t0

    def _write_state(self, writers: OutputWriters, st: StateSample, force: bool = False) -> None:
        """The ParaView and results samples due (all with ``force``) at the state ``st``: one
        the deck steps kept, or the present one (:meth:`_sample`)."""
        out = self.model.output
        bodies = replace(self.bodies, position=st.position, quaternion=st.quaternion,
                         velocity=st.velocity, angular_velocity=st.angular_velocity)
        dt = self.system.dt
        if force or due(st.time, out.vtk_every, dt):
            writers.paraview.write(st.time, bodies, wall_displacement=st.wall_displacement,
                                   contacts=st.contacts,
                                   curved_poses=self.curved.poses(st.time, st.wall_displacement))
        if force or due(st.time, out.results_interval, dt):
            writers.results.append(st.time, bodies)

    def _contact_output(self) -> dict | None:
        """The last evaluation's contacts for the ParaView writer (None without a scene)."""
        if self.scene is None or self.system is None:
            return None
        return self.system.contact_output()

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
        if self.step_progress == 0:
            self.flow.begin_step(step_t0)     # a step restarted inside keeps the checkpoint's
        self._build = lambda: self._build_system(dt, motions, step.damping == "implicit",
                                                 getattr(step, "accuracy", None),
                                                 getattr(step, "safety", None))
        self.system = self._build()
        scene_state = restored.get("scene") if restored else None
        if scene_state:
            self.scene.set_state(scene_state)
        self.system.initialize()
        if restored and restored.get("system"):
            self.system.set_state(restored["system"])
            if scene_state:
                self.scene.set_state(scene_state)
        elif self.ledger.mech0 is None:
            self._sample(writers, force=True)
        else:       # a wrap into the periodic cell at the first evaluation (internal_step)
            self.ledger.book_external(self.system.initial_wrap_work)
        sysm = self.system
        log.info("step %d: %s, %d time steps of %g s (%d sub-step(s) of %.3g s each)",
                 step.id, step.kind, n_total, dt, sysm.substeps, sysm.dt_internal)
        if sysm.domain is not None:
            log.info("step %d: %s", step.id, sysm.domain.describe())
        t_load = time.perf_counter()
        sysm.load_compiled()        # numba's cached kernels: set-up, not the time loop
        self.timers["setup"] += time.perf_counter() - t_load
        self.progress.start(f"step {step.id} {step.kind}", duration)
        with self.sigint.time_loop():
            self._time_loop(writers, n_total, step_t0, dt)
        sysm = self.system          # inlets and outlets may have built it anew
        self.progress.update(self.time - step_t0, dt, sysm.substeps, self.scene.last.active, force=True)
        self.progress.finish()
        self._sync_bodies_from_system()
        self.summary.accuracy_repeats += sysm.accuracy_repeats
        self.wall_offset = sysm.wall_displacement.copy()
        self._snapshot()
        self._close_system()

    def rebuild(self, t0: float, step_count: int, warned: bool,
                control: tuple | None = None) -> None:
        """A new system of the present bodies for the running step (inlets and outlets
        changed them), initialised; its clock goes on from the last one's (start ``t0`` s,
        ``step_count`` deck steps done), so that times stay t0 + k·dt, it warns of heavy
        sub-stepping only if the last one did not (``warned``), and its time-step control
        goes on from the last one's state ``control``
        (:meth:`~nurbsdem.dynamics.substep_control.SubstepControl.control_state`; None: a
        fresh start)."""
        self.system = self._build()
        self.system.t0, self.system.step_count = t0, step_count
        self.system._warned_heavy = warned
        self.system.carried_control = control
        t0 = time.perf_counter()
        self.system.initialize()
        self.ledger.book_external(self.system.initial_wrap_work)
        if not getattr(self, "_rebuilt_loaded", False):
            # the compiled deck steps, loaded at this solver's first rebuild: later systems
            # step with the same compiled loop (the same kinds of arrays), and loading it
            # again (a call of zero deck steps) changes nothing but costs its dispatch
            self.system.load_compiled()
            self._rebuilt_loaded = True
        self.timers["setup"] += time.perf_counter() - t0

    def _time_loop(self, writers: OutputWriters, n_total: int, step_t0: float,
                   dt: float) -> None:
        """The deck steps of a dynamic step, in compiled chunks up to the next checkpoint,
        segment end (inlets and outlets, which also exchange particles at the step's end) or
        the step's end; output of each chunk written after it, a Ctrl-C obeyed between them
        (a checkpoint of that moment first)."""
        ck_every = self.model.output.checkpoint_every
        flow = self.flow.active
        servo = self.servo
        if servo is not None and self.step_progress == 0:
            servo.update(self.system)       # the first deck step's speeds: the push at t0
        while self.step_progress < n_total:
            sysm = self.system
            meter = ChunkMeter(self.scene, sysm)
            left = 1 if servo is not None else n_total - self.step_progress
            if flow:
                left = min(left, self.flow.steps_to_segment_end(self.step_progress, dt))
            n, monitors_due, states_due = steps_to_event(sysm, self.model.output, left,
                                                         ck_every)
            self._take_the_compiled_loop_when_ready(sysm)
            try:
                done = sysm.steps(n, monitors_due, states_due)
            except InstabilityError:
                self._checkpoint_unstable(writers)
                raise
            meter.book(self.scene, sysm, done, self.timers, self.split, self.summary)
            self.step_progress += done
            self.time = sysm.time
            if servo is not None:
                servo.update(sysm)          # the next deck step's speeds
            cs = self.scene.last
            tally = sysm.last_steps
            self._sample(writers, samples=tally.samples, states=tally.states)
            if flow and (self.step_progress == n_total
                         or self.step_progress % self.flow.segment_steps(dt) == 0):
                exchange(self, writers)       # at each segment end and at the step's end
            if self.step_progress < n_total and (due(self.time, ck_every, dt)
                                                 or self.sigint.requested):
                self._sync_bodies_from_system()
                write_checkpoint(self, writers)
                if self.sigint.requested:
                    self.progress.finish()
                    raise self._interrupted(writers)
            self.progress.update(self.time - step_t0, dt, sysm.substeps, cs.active)

    def _take_the_compiled_loop_when_ready(self, sysm: DemSystem) -> None:
        """Turn :attr:`compiled_steps` on (this system's and the later ones') once
        :attr:`compiled_when` says so."""
        if self.compiled_when is not None and not self.compiled_steps and self.compiled_when():
            self.compiled_when = None
            self.compiled_steps = sysm.compiled_steps = True

    def _checkpoint_unstable(self, writers: OutputWriters) -> None:
        """After an unstable deck step (:class:`InstabilityError`): the output of the deck
        steps done before it and a checkpoint of the last good state."""
        sysm = self.system
        self.time = sysm.time
        for smp in sysm.last_steps.samples:     # the deck steps done before it
            self._write_monitors(writers, smp)
        for st in sysm.last_steps.states:
            self._write_state(writers, st)
        self._sync_bodies_from_system()
        write_checkpoint(self, writers)

    def _run_replicate(self, step: ReplicateStep, writers: OutputWriters) -> None:
        before = mechanical_energy(self.model, self.bodies)
        self.bodies = replicate_step(self.model, self.bodies, step)
        after = mechanical_energy(self.model, self.bodies)
        self.ledger.book_external(after - before)     # the copies' energy enters from outside
        self.scene = None
        self.carry_hist = None
        log.info("step %d: replicated into %d layers: %d particles", step.id, step.layers,
                 len(self.bodies))

    def _to_contact(self, step: MoveWallStep) -> None:
        """Translate the wall along its direction until the nearest particle is ``gap`` away."""
        travel = to_contact(self.model, self.bodies, self.wall_offset, step, self.curved,
                            self.time)
        log.info("step %d: wall %s moved %.6g m to a gap of %g m", step.id, step.wall, travel,
                 step.gap)

    def _run_move(self, step: MoveWallStep, writers: OutputWriters, restored) -> None:
        """``MoveWall`` over time: a dynamic step in which the step's walls translate and the
        mesh and surface walls among them turn (:func:`nurbsdem.wall_moves.plan`); each
        stays where its motion leaves it."""
        motions, poses = wall_moves.plan(self, step, restored)
        try:
            with self.curved.moving(poses):
                self._run_dynamic(step, writers, motions, restored)
                ends = {k: pose.at(self.time) for k, pose in poses.items()}
        finally:
            self.servo = None
        self.curved.rest.update(ends)

    def _run_step(self, step, writers: OutputWriters) -> None:
        restored = self._restored
        if isinstance(step, DynamicStep):
            self.motion_spec = {}
            self._run_dynamic(step, writers, self._fixed_motions(), restored)
        elif isinstance(step, ReplicateStep):
            self._run_replicate(step, writers)
        elif isinstance(step, MoveWallStep) and step.to_contact:
            self._to_contact(step)
        elif isinstance(step, MoveWallStep):
            self._run_move(step, writers, restored)
        else:  # pragma: no cover - the parser knows no other steps
            raise InputError(f"unknown step kind {step.kind}")
        self._restored = None
        self.step_index += 1
        self.step_progress = 0
        self._checkpoint_end_of_step(writers)

    # ------------------------------------------------------------------ a run
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
        self.sigint.requested = False
        resumed = self._finished_once     # writers closed by finish(): continue their files
        if self.restart_path is not None and not resumed:
            self._restored = load_restart(self)
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
        self.motion_spec = {}

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
        with self.sigint.deferring(self.comm):
            self._run_step(step, writers)
        if self.sigint.requested:    # Ctrl-C in the step's last chunk: after its checkpoint
            raise self._interrupted(writers)

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
        s.balance_error, s.balance_scale = self.ledger.balance()
        return s

    def _interrupted(self, writers: OutputWriters) -> Interrupted:
        """The exception that ends a run stopped by Ctrl-C, once the checkpoint just queued
        (and everything before it) is on disk."""
        self.sigint.requested = False
        where = ""
        if self.write_output and self.rank == 0:
            writers.paraview.sync()             # the background worker's checkpoint
            path = self.outdir / CHECKPOINT_NAME
            where = (f"; its checkpoint is {path} (continue with --restart {path}, or "
                     f"Simulation.from_deck(..., restart=...))")
        return Interrupted(f"interrupted at t = {self.time:.9g} s{where}")

    def _checkpoint_end_of_step(self, writers: OutputWriters) -> None:
        self.motion_spec = {}
        write_checkpoint(self, writers)
        if self.write_output and self.rank == 0 and self.model.text != self._results_deck:
            # a model extended step by step: results.h5 keeps the deck of the steps run so far
            self._results_deck = self.model.text
            writers.results.set_deck(self._results_deck)


def _contact_arrays(out: dict | None, normal: np.ndarray | None, n_particles: int,
                    step: int) -> dict:
    """The active contacts of a step's last evaluation as arrays (:attr:`Solver.end_contacts`):
    ``out`` the system's contact output (None: no contacts), ``normal`` their normals (C,3)."""
    if out is None:
        z3 = np.zeros((0, 3))
        out = dict(point=z3, force_normal=z3, force_tangential=z3.copy(),
                   penetration=np.zeros(0), degenerated=np.zeros(0, np.int64),
                   body_a=np.zeros(0, np.int64), body_b=np.zeros(0, np.int64))
        normal = z3.copy()
    return dict(
        body_a=np.array(out["body_a"], np.int64), body_b=np.array(out["body_b"], np.int64),
        point=np.array(out["point"], float), normal=normal,
        depth=np.array(out["penetration"], float),
        force_normal=np.array(out["force_normal"], float),
        force_tangential=np.array(out["force_tangential"], float),
        degenerated=np.array(out["degenerated"]), n_particles=n_particles, step=step)


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

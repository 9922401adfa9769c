"""Compiling the kernels ahead of a run (``nurbsdem warmup``) and telling what is compiled.

numba compiles each kernel at its first call and keeps the machine code in its on-disk cache
(:mod:`nurbsdem.cachecheck`); the first run after an install, an upgrade or an edit of a
kernel's sources compiles before it starts.  :func:`warm_up` compiles them ahead by running
small scenes of the kinds a deck builds, in stages (:data:`STAGES`): the stages without
kernels in common run at the same time in separate processes (numba compiles in one thread
per process, under a lock), each writing its kernels into the shared cache; the compiled
time loop, which calls nearly all of them, comes last and loads theirs from the cache.

:class:`CompileReport` tells the user, one line per kernel that starts compiling at the top
(a kernel called by another compiles within its caller), which one it is and how many of the
run's entry kernels (:data:`ENTRY_KERNELS`) are compiled or cached so far.

Units: SI; the small scenes' sizes in metres.
"""
from __future__ import annotations

import contextlib
import os
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, TextIO

#: the kernels a run calls from Python (the entry points), each with the words the user reads
#: while it compiles: every other kernel compiles within one of them
ENTRY_KERNELS = {
    "listed.solve_due": "contact detection (closed forms, point-to-surface, LCP batches)",
    "listed.scene_list": "the neighbour list (bounding spheres, patch boxes)",
    "verlet.contact_arrays": "the contacts' arrays",
    "step.step_start": "the integration (half kicks, drift)",
    "step.contact_part": "the contact forces",
    "deck_steps.run_deck_steps": "the compiled time loop (forces, time-step control)",
    "deflate._blocks": "compressed ParaView output",
}
#: each entry kernel's share of a first solve's compile time (the quick paper deck from an
#: empty cache, the kernels it calls included: ``benchmarks/bench_compile.py --compiles``;
#: the step's start compiles inside the time loop there), for the time left that
#: :class:`CompileReport` tells
ENTRY_SHARES = {"listed.scene_list": 0.12, "listed.solve_due": 0.42,
                "verlet.contact_arrays": 0.01, "step.step_start": 0.0,
                "step.contact_part": 0.08, "deck_steps.run_deck_steps": 0.29,
                "deflate._blocks": 0.02}


def _box_deck_text(folder: Path, shapes: str, particles: str, vtk_every: float) -> str:
    """The text of a small deck of the warm-up: the ``Shapes`` and ``Particles`` lines
    given, in a 0.25 m box of flat walls with a lid, the paper's linear law,
    ``Damping Implicit`` with ``Accuracy`` as the paper example, four deck steps, results
    in ``folder``/results with VTU output every ``vtk_every`` s."""
    return f"""Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2700
Shapes
{shapes}Particles
{particles}Walls
  Box 1 Min 0 0 0 Max 0.25 0.25 0.40
  Wall 6 Name lid Point 0.125 0.125 0.40 Normal 0 0 -1 Size 0.25 0.25
Contact
  Interface 1 NormalPenalty 1e5 TangentialPenalty 1e4 NormalDamping 1e2 TangentialDamping 0 Friction 0.5
Steps
  Step 1 Dynamic Duration 0.004 TimeStep 1e-3 Damping Implicit Accuracy 3e-5 Safety 0.7
Output
  Directory {folder / 'results'}
  VTK Every {vtk_every} Resolution 4
  Monitors Every 0.001
"""


def _deck(folder: Path, output: bool) -> Path:
    """A small deck in ``folder``: two of the paper's particles, an exact sphere and a box of
    flat walls, one lid (the kinds of pair a deck has: NURBS-NURBS, NURBS-wall, sphere-NURBS,
    sphere-wall), ``Damping Implicit`` with ``Accuracy`` as the paper example; VTU output
    when ``output``."""
    from .io.shapefile import save_shape
    from .shapes import paper_particle
    for kind in "AB":
        save_shape(folder / f"{kind}.yaml", paper_particle(kind), name=kind)
    text = _box_deck_text(folder, """  Shape 1 File A.yaml
  Shape 2 File B.yaml
  Shape 3 Sphere Radius 0.02
""", """  Particle 1 Shape 1 Material 1 Position 0.06 0.06 0.05
  Particle 2 Shape 2 Material 1 Position 0.06 0.06 0.115
  Particle 3 Shape 3 Material 1 Position 0.17 0.17 0.03
""", 0.002 if output else 1.0)
    (folder / "warmup.inp").write_text(text)
    return folder / "warmup.inp"


def _run_deck(compiled_steps: bool, output: bool,
              write_deck: Callable[[Path], Path] | None = None) -> None:
    """Solve the deck ``write_deck(folder)`` writes in a temporary folder (default: the small
    deck, :func:`_deck`, with VTU output when ``output``), with the compiled loop or the
    Python driver; without ``output`` nothing is written."""
    from .simulation import Simulation
    with tempfile.TemporaryDirectory(prefix="nurbsdem-warmup-") as tmp:
        deck = write_deck(Path(tmp)) if write_deck else _deck(Path(tmp), output)
        sim = Simulation.from_deck(deck, quiet=True)
        sim.solver.compiled_steps = compiled_steps
        if not output:
            sim.solver.write_output = False
        sim.run()


def _spheres_deck(folder: Path) -> Path:
    """A small deck in ``folder``: two exact spheres in a box of flat walls with a lid,
    ``Damping Implicit`` with ``Accuracy`` as the paper example.  Its kernels are those of
    every scene on the Python driver but the LCP's, which exact spheres never solve: the
    dispatch, the neighbour list, the contact laws and the step's parts take arguments of
    the same types for every scene."""
    text = _box_deck_text(folder, "  Shape 1 Sphere Radius 0.02\n", """  Particle 1 Shape 1 Material 1 Position 0.06 0.06 0.03
  Particle 2 Shape 1 Material 1 Position 0.06 0.06 0.075
""", 1.0)
    (folder / "spheres.inp").write_text(text)
    return folder / "spheres.inp"


def _contacts() -> None:
    """The contact kernels as the Python driver calls them (its steps, no output): the
    dispatch, the neighbour list, the contact laws, the step's parts, on a deck of exact
    spheres (:func:`_spheres_deck`), so that it compiles no LCP and runs beside the LCP's
    stages; the contact forces load from the cache where :func:`_forces` has compiled them
    by the time this stage reaches them."""
    _run_deck(compiled_steps=False, output=False, write_deck=_spheres_deck)


class _Evaluated(Exception):
    """Ends the run of :func:`_forces` at its first evaluation (:func:`_evaluation_only`)."""


@contextlib.contextmanager
def _evaluation_only():
    """While open, every scene's evaluation (:class:`~nurbsdem.contact.scene.SceneContacts`)
    answers with the contacts of its empty neighbour list, of the types a real evaluation
    gives, without building the list or solving a pair; and a step ends with
    :class:`_Evaluated` after its first evaluation, where it loads its compiled parts
    (:meth:`~nurbsdem.dynamics.system.DemSystem.load_compiled`)."""
    import numpy as np
    from .contact.scene import SceneContacts
    from .dynamics.system import DemSystem
    evaluate, load = SceneContacts.__call__, DemSystem.load_compiled

    def no_contacts(self, kin):
        self.last = self.contact_set(np.zeros(0), monitored=0)
        return self.last

    def evaluated(self):
        raise _Evaluated
    SceneContacts.__call__, DemSystem.load_compiled = no_contacts, evaluated
    try:
        yield
    finally:
        SceneContacts.__call__, DemSystem.load_compiled = evaluate, load


def _forces() -> None:
    """The first evaluation of the deck of :func:`_contacts` with no contact detection
    (:func:`_evaluation_only`): the contact forces and the implicit dashpots
    (:func:`~nurbsdem.dynamics.step.contact_part`), which an evaluation calls with arguments
    of the same types with or without contacts.  It runs beside :func:`_contacts`, which
    compiles the neighbour list and the dispatch meanwhile, then loads these kernels and
    compiles the step's parts: the Python driver's kernels in two halves on two cores."""
    with _evaluation_only():
        try:
            _contacts()
        except _Evaluated:
            pass


#: pairs of the batches: enough for the parallel batch kernel
#: (:data:`nurbsdem.contact.detect.PARALLEL_MIN_PAIRS`)
N_PAIRS = 40


def _pairs(n: int = N_PAIRS, spheres: bool = False) -> tuple:
    """A contact table of the paper's particles A and B (``spheres``: of two exact spheres,
    whose table leaves the LCP's kernels uncompiled, :func:`~nurbsdem.jit.fill_lazy_kernels`;
    the table's arrays have the same types) and n poses of the pair (B above A), for the
    batch kernels (the poses matter to the results, not to the code)."""
    import numpy as np
    from .contact.detect import ContactTable
    from .shapes import paper_particle_shape, sphere
    table = ContactTable([sphere(0.02), sphere(0.02)] if spheres else
                         [paper_particle_shape("A"), paper_particle_shape("B")])
    pos = np.zeros((n, 3))
    pos[:, 2] = np.linspace(0.05, 0.08, n)
    rot = np.tile(np.eye(3), (n, 1, 1))
    return table, pos, rot


def _lcp_batches(n: int = N_PAIRS, spheres: bool = False) -> None:
    """The parallel LCP batch kernel and the kernels it calls, with arguments of the types
    the scene's dispatch passes (:func:`nurbsdem.contact.detect.solve_rows`), for n pairs of
    :func:`_pairs`."""
    import numba
    import numpy as np
    from .contact.detect import _batch_kernel
    from .contact.lcp import NF, NI
    t, pos, rot = _pairs(n, spheres)
    k = np.arange(n, dtype=np.int64)
    no_mask = np.zeros((n, 0), np.bool_)
    _batch_kernel(t.tab, t.info, t.centroid, t.radius, t.seeds, t.nonconvexity,
                  np.concatenate((np.zeros(n, np.int64), np.ones(n, np.int64))),
                  np.concatenate((np.zeros((n, 3)), pos)), np.concatenate((rot, rot)),
                  k, n + k, k, no_mask, no_mask, np.zeros((n, NF)),
                  np.zeros((n, NI), np.int64), numba.get_num_threads())


def _wall_batches(n: int = N_PAIRS, spheres: bool = False) -> None:
    """The parallel body-against-flat-wall kernel and the kernels it calls, with arguments of
    the types the scene's dispatch passes (:func:`nurbsdem.contact.flat_wall.solve_wall_rows`),
    for n bodies of :func:`_pairs`."""
    import numba
    import numpy as np
    from .contact.lcp import NF, NI
    from .contact.flat_wall import _wall_batch_kernel
    t, pos, rot = _pairs(n, spheres)
    k = np.arange(n, dtype=np.int64)
    rows = lambda *row: np.tile(np.array(row, float), (n, 1))   # noqa: E731
    _wall_batch_kernel(t.tab, t.info, t.centroid, t.radius, t.seeds, np.zeros(n, np.int64),
                       pos, rot, k, k, 0, k, rows(-0.2, -0.2, 0.0), rows(0.4, 0.0, 0.0),
                       rows(0.0, 0.4, 0.0), rows(0.0, 1.0, 0.0, 1.0), np.zeros((n, NF)),
                       np.zeros((n, NI), np.int64), numba.get_num_threads())


def _batch_shells() -> None:
    """The two batch kernels (:func:`_lcp_batches`, :func:`_wall_batches`) without the LCP
    they call through lazy pointers (:class:`~nurbsdem.jit.PointerKernel`), for no pair of two
    exact spheres: the scene's dispatch compiles them for every scene, one of exact spheres
    too, so this stage takes them off the contact detection's path, and the LCP's stages
    compile the LCP alone."""
    _lcp_batches(0, spheres=True)
    _wall_batches(0, spheres=True)


def _output() -> None:
    """The compressed ParaView output's kernels (:func:`nurbsdem.io.deflate.encode_repeated`:
    its arguments have the same types for any data)."""
    import numpy as np
    from .io.deflate import encode_repeated
    encode_repeated(np.arange(6.0).reshape(2, 3), np.array([3, 2]))


def _walls_deck(folder: Path) -> Path:
    """A small deck in ``folder``: an ellipsoid and an exact sphere in a turning exact NURBS
    drum with a triangle-mesh baffle and flat end plates (the kinds of pair of mesh and
    surface walls: sphere and NURBS particle against each)."""
    import numpy as np
    import trimesh

    from .geometry.surfaces import cylinder_patch
    from .io.shapefile import save_shape
    save_shape(folder / "drum.yaml", [cylinder_patch(0.06, 0.04, axis=(0, 0, 1))])
    v = np.array([[-0.02, -0.02, -0.045], [0.02, -0.02, -0.045], [0.02, 0.02, -0.045],
                  [-0.02, 0.02, -0.045]])
    trimesh.Trimesh(v, np.array([[0, 1, 2], [0, 2, 3]]), process=False).export(
        folder / "baffle.stl")
    text = f"""Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2500
Shapes
  Shape 1 Ellipsoid SemiAxes 0.008 0.0065 0.005
  Shape 2 Sphere Radius 0.005
Particles
  Particle 1 Shape 1 Material 1 Position 0.0 0.03 -0.038
  Particle 2 Shape 2 Material 1 Position 0.0 -0.03 -0.044
Walls
  Surface 1 Name drum File drum.yaml Rotation 0 1.5707963267948966 0 Position -0.02 0 0
  Mesh 2 Name baffle File baffle.stl
  Wall 3 Name plate_x_min Point -0.02 0 0 Normal 1 0 0 Size 0.15 0.15
  Wall 4 Name plate_x_max Point 0.02 0 0 Normal -1 0 0 Size 0.15 0.15
Contact
  Interface 1 NormalPenalty 2e4 NormalDamping 6 TangentialPenalty 2e4 Friction 0.5
Steps
  Step 1 MoveWall drum Rotate AngularVelocity 4 0 0 Center 0 0 0 Duration 0.004 TimeStep 1e-3
Output
  Directory {folder / 'results'}
  VTK Every 1.0 Resolution 4
  Monitors Every 0.002
"""
    (folder / "walls.inp").write_text(text)
    return folder / "walls.inp"


def _walls() -> None:
    """The mesh and surface walls' kernels as the Python driver calls them (:func:`_walls_deck`,
    no output)."""
    _run_deck(compiled_steps=False, output=False, write_deck=_walls_deck)


def _periodic_deck(folder: Path) -> Path:
    """A small deck in ``folder``: exact spheres in a cell periodic in x and y over a floor
    (the periodic cell's kernels of the compiled loop, which a scene without a cell does not
    compile)."""
    text = f"""Environment
  Gravity 0 0 -9.81
  Periodic X 0 0.03 Y 0 0.03
Materials
  Material 1 Density 2700
Shapes
  Shape 1 Sphere Radius 0.005
Particles
  Particle 1 Shape 1 Material 1 Position 0.0051 0.015 0.0051
  Particle 2 Shape 1 Material 1 Position 0.0249 0.015 0.0051
  Particle 3 Shape 1 Material 1 Position 0.015 0.015 0.02
Walls
  Wall 1 Name floor Point 0.015 0.015 0 Normal 0 0 1 Size 0.06 0.06
Contact
  Interface 1 NormalPenalty 1e5 TangentialPenalty 1e4 NormalDamping 1 Friction 0.5
Steps
  Step 1 Dynamic Duration 0.004 TimeStep 1e-3
Output
  Directory {folder / 'results'}
  VTK Every 1.0
  Monitors Every 0.002
"""
    (folder / "periodic.inp").write_text(text)
    return folder / "periodic.inp"


def _loop() -> None:
    """The compiled time loop with its output (loads the kernels the other stages cached),
    then with a periodic cell."""
    _run_deck(compiled_steps=True, output=True)
    _run_deck(compiled_steps=True, output=False, write_deck=_periodic_deck)


def _loop_and_curved_walls() -> None:
    """:func:`_loop`, then the walls deck (:func:`_walls_deck`) in the compiled loop: its
    kernels of mesh and surface walls are lazy (a scene without such walls does not compile
    them), so only a scene with them compiles them, here once for every later run."""
    _loop()
    _run_deck(compiled_steps=True, output=False, write_deck=_walls_deck)


@dataclass(frozen=True)
class Stage:
    """One part of :func:`warm_up`: ``run()`` compiles its kernels; ``after``: the stages
    whose kernels it calls (run before it, in any process); ``weight``: its share of the
    compile work, for the progress bar."""
    name: str
    run: Callable[[], None]
    weight: float
    after: tuple[str, ...] = ()


#: the stages of :func:`warm_up` (weights: their shares of a cold compilation, rounded)
STAGES = (
    Stage("batch kernels", _batch_shells, 0.03),
    Stage("LCP batches", _lcp_batches, 0.15, after=("batch kernels",)),
    Stage("wall contacts", _wall_batches, 0.04, after=("batch kernels",)),
    Stage("ParaView output", _output, 0.03),
    Stage("contact forces", _forces, 0.19),
    Stage("contact detection", _contacts, 0.24),
    Stage("time loop", _loop, 0.34,
          after=("LCP batches", "wall contacts", "contact forces", "contact detection",
                 "ParaView output")),
)
#: the stages a first solve compiles before it starts (:func:`first_run_stages`)
FIRST_RUN_STAGES = ("batch kernels", "LCP batches", "wall contacts", "ParaView output",
                    "contact forces", "contact detection")
#: the stages only a scene with bodies other than exact spheres needs (the LCP's)
LCP_STAGES = ("LCP batches", "wall contacts")


#: :data:`STAGES` and the kernels of mesh and surface walls (``nurbsdem warmup --all``; the
#: test runner's warm-up): the Python driver's in a stage of their own, beside the contact
#: detection; the compiled loop's in the time loop's stage, which then comes after it
ALL_STAGES = STAGES[:-1] + (
    Stage("mesh and surface walls", _walls, 0.22, after=("LCP batches", "wall contacts")),
    Stage("time loop", _loop_and_curved_walls, 0.41,
          after=("contact forces", "contact detection", "ParaView output",
                 "mesh and surface walls")),
)


def first_run_stages(needs_lcp: bool) -> tuple[Stage, ...]:
    """The stages of :data:`FIRST_RUN_STAGES` a first solve compiles in parallel processes
    before it starts, without those of the LCP (:data:`LCP_STAGES`) unless ``needs_lcp``
    (a scene of exact spheres solves none).  On two cores the Python driver's kernels
    compile in two halves side by side: the contact detection and the step's parts
    (:func:`_contacts`) on one, the contact forces (:func:`_forces`) on the other, which then
    compiles the batch kernels and the LCP's; the compiled time loop, which calls them all,
    compiles afterwards in the background (:func:`compile_loop_in_background`) while the
    first run goes on the Python driver."""
    names = [n for n in FIRST_RUN_STAGES if needs_lcp or n not in LCP_STAGES]
    return tuple(s for s in STAGES if s.name in names)


#: the file in the compiled loop's cache folder that holds the process id of a background
#: compilation of the loop (:func:`compile_loop_in_background`) while it runs
LOOP_PID_FILE = "nurbsdem-loop-compiling.pid"


def _loop_pid_file() -> Path | None:
    from .cachecheck import PACKAGE, cache_folder
    folder = cache_folder(PACKAGE / "dynamics")
    return None if folder is None else folder / LOOP_PID_FILE


def loop_compiling_in_background() -> bool:
    """Whether a background compilation of the time loop is running (its process alive)."""
    path = _loop_pid_file()
    try:
        pid = int(path.read_text()) if path is not None else 0
        if pid > 0:
            os.kill(pid, 0)
            return True
    except (OSError, ValueError):
        pass
    return False


def compile_loop_in_background() -> int | None:
    """Start the time loop's stage (:func:`_loop`) in a process of its own session, which
    outlives the solve that starts it, at the lowest CPU priority, with its output discarded;
    returns its process id (None: one runs already, or the cache folder is not writable).
    The next solve loads the loop from numba's cache; one that starts before it is done runs
    on the Python driver too (the same results)."""
    import subprocess
    path = _loop_pid_file()
    if path is None or loop_compiling_in_background():
        return None
    code = f"from nurbsdem.warmup import _loop_in_background as run; run({str(path)!r})"
    try:
        proc = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.DEVNULL,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                start_new_session=True)
        path.write_text(str(proc.pid))
    except OSError:
        return None
    return proc.pid


def _loop_in_background(pid_file: str, niceness: int = 19) -> None:
    """The process :func:`compile_loop_in_background` starts: the time loop's stage at the
    lowest CPU priority (``niceness`` added; the solve that started it runs beside it);
    ``pid_file`` is removed at the end."""
    try:
        os.nice(niceness)
        _loop()
    finally:
        try:
            Path(pid_file).unlink()
        except OSError:
            pass


def _run_stage(run: Callable[[], None]) -> float:
    """``run()`` (in a worker process); returns its seconds."""
    t0 = time.perf_counter()
    run()
    return time.perf_counter() - t0


def warm_up(jobs: int | None = None, on_done: Callable[[str, float], None] | None = None,
            stages: tuple[Stage, ...] = STAGES) -> dict[str, float]:
    """Compile the kernels of ``stages`` into numba's cache, each stage in a fresh process
    once the stages it comes ``after`` are done, up to ``jobs`` at a time (default: the
    usable cores): whenever a process is free, the ready stage that leads the longest chain
    of work (:func:`_priorities`) starts.  ``on_done(name, seconds)`` after each stage.
    Returns stage name -> seconds, in the order they finished."""
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, wait
    priority = _priorities(stages)
    workers = max(1, jobs or _usable_cores())
    done: dict[str, float] = {}
    pending = list(stages)
    ctx = multiprocessing.get_context("spawn")     # numba's threads do not survive a fork
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx,
                             max_tasks_per_child=1) as pool:
        running = {}
        while pending or running:
            ready = [s for s in pending if all(a in done for a in s.after)]
            for stage in sorted(ready, key=lambda s: -priority[s.name])[:workers - len(running)]:
                pending.remove(stage)
                running[pool.submit(_run_stage, stage.run)] = stage.name
            finished, _ = wait(list(running), return_when=FIRST_COMPLETED)
            for future in finished:
                name = running.pop(future)
                done[name] = future.result()
                if on_done is not None:
                    on_done(name, done[name])
    return done


def _priorities(stages: tuple[Stage, ...]) -> dict[str, float]:
    """Each stage's weight plus the largest priority of the stages that come after it: the
    work of the longest chain it starts (a stage others wait for starts before an equal one
    that nobody waits for).  Raises ValueError for a stage after an unknown one or a cycle."""
    names = {s.name: s for s in stages}
    for s in stages:
        if not set(s.after) <= set(names):
            raise ValueError(f"stage {s.name!r} comes after unknown stages {s.after}")
    priority: dict[str, float] = {}

    def of(name: str, seen: tuple[str, ...]) -> float:
        if name in seen:
            raise ValueError("the stages' order has a cycle: " + ", ".join(seen))
        if name not in priority:
            later = [of(s.name, seen + (name,)) for s in stages if name in s.after]
            priority[name] = names[name].weight + max(later, default=0.0)
        return priority[name]
    for s in stages:
        of(s.name, ())
    return priority


def _usable_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:          # not Linux
        return os.cpu_count() or 1


class CompileReport:
    """While installed (a context manager): one line to ``stream`` when a kernel starts
    compiling at the top of the call stack, naming it, counting the entry kernels
    (:data:`ENTRY_KERNELS`) done so far and, once a tenth of the work is done, the time left
    at the pace so far (:data:`ENTRY_SHARES`); nothing when everything loads from the
    cache."""

    def __init__(self, stream: TextIO | None = None) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.depth = 0
        self.started = 0.0
        self.seen: set[str] = set()

    def on_start(self, event) -> None:
        if self.depth == 0:
            name = _short_name(event.data["dispatcher"].py_func)
            if name in ENTRY_KERNELS and name not in self.seen:
                self.seen.add(name)
                if not self.started:
                    self.started = time.perf_counter()
                left = len(ENTRY_KERNELS) - len(self.seen)
                elapsed = time.perf_counter() - self.started
                self.stream.write(f"nurbsdem: compiling {ENTRY_KERNELS[name]} ({name}; "
                                  f"{left} of {len(ENTRY_KERNELS)} parts left after it, "
                                  f"{elapsed:.0f} s so far{self._time_left(name, elapsed)})\n")
                self.stream.flush()
        self.depth += 1

    def on_end(self, event) -> None:
        self.depth -= 1

    def _time_left(self, name: str, elapsed: float) -> str:
        """", about N s left" when entry ``name`` starts after ``elapsed`` s: the shares of the
        entries not compiled yet (``name``'s included) at the pace of those done, once they
        hold a tenth of the work; "" before."""
        done = sum(ENTRY_SHARES.get(n, 0.0) for n in self.seen if n != name)
        left = sum(share for n, share in ENTRY_SHARES.items()
                   if n in ENTRY_KERNELS and (n == name or n not in self.seen))
        if done < 0.1 or elapsed <= 0.0:
            return ""
        return f", about {elapsed * left / done:.0f} s left"

    def __enter__(self) -> "CompileReport":
        from numba.core import event
        listener = self

        class _Listener(event.Listener):
            def on_start(self, ev):
                listener.on_start(ev)

            def on_end(self, ev):
                listener.on_end(ev)

        self._listener = _Listener()
        event.register("numba:compile", self._listener)
        return self

    def __exit__(self, *exc) -> None:
        from numba.core import event
        event.unregister("numba:compile", self._listener)


def _short_name(func) -> str:
    """``module.function`` of a kernel (the last part of its module's name)."""
    return f"{func.__module__.rsplit('.', 1)[-1]}.{func.__qualname__}"


def reporting_compiles(enabled: bool = True, stream: TextIO | None = None):
    """A :class:`CompileReport` on ``stream`` (default stderr) where ``enabled``, else a
    context that does nothing."""
    import contextlib
    return CompileReport(stream) if enabled else contextlib.nullcontext()

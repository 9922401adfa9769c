"""Scripting a simulation in Python: :class:`Simulation`.

A scene is built in Python (or read from a deck) and solution steps are run one at a time,
with the state read in between::

    import nurbsdem
    sim = nurbsdem.Simulation(gravity=(0, 0, -9.81), output="results")   # output: optional
    sim.add_material(1, density=2700)
    sim.add_interface(normal_penalty=1e5, normal_damping=1e2, friction=0.5)
    sim.add_box(min=(0, 0, 0), max=(0.1, 0.1, 0.1))
    sim.add_particle(nurbsdem.shapes.sphere(0.01), material=1, position=(0.05, 0.05, 0.03))
    sim.run_dynamic(duration=0.2, time_step=1e-3)
    print(sim.positions, sim.energy()["kinetic"], sim.contacts()["force_normal"])

Every method maps to one deck entry (:mod:`nurbsdem.io.deck`), with the deck's keys as
keyword arguments, and every step method makes the same step object a deck line makes
(:class:`~nurbsdem.model.DynamicStep`, :class:`~nurbsdem.model.ReplicateStep`,
:class:`~nurbsdem.model.MoveWallStep`) and runs it through the same
:class:`~nurbsdem.solver.Solver` code: ``nurbsdem solve CASE.inp`` is
``Simulation.from_deck("CASE.inp").run()``, and a scene built here gives bit for bit the
results of the same scene written as a deck (``tests/test_simulation.py``).
:attr:`Simulation.deck_text` is the deck of the scene and of the steps run so far.

Identifiers: particles are numbered 1, 2, ... in the order of :meth:`~Simulation.add_particle`
(which returns the id); shapes in the order of first use; walls like the deck's (``add_box``
makes five walls ``bottom, x_min, x_max, y_min, y_max`` and ``top`` with ``top=True``).
Steps are numbered 1, 2, ... in the order they are run (error messages say ``Step 2: ...``).

Checks: the whole scene is validated when the first step runs (the checks of ``nurbsdem
check``: overlaps, walls, ranges, time steps ...) and every later step before it runs; each
problem is an :class:`~nurbsdem.errors.InputError` with a one-line message (no deck line);
a step refused that way is not run, and the simulation can go on with another.

Output and restart: with ``output=DIR`` the run writes what ``nurbsdem solve`` writes (ParaView
series, monitors, ``results.h5``, ``checkpoint.h5`` every ``checkpoint_every`` seconds and at
the end of each step). ``restart=DIR/checkpoint.h5`` continues a run that stopped: build the
same scene and call the same steps (e.g. run the same script again): the steps the checkpoint
has done are skipped, the interrupted one continues where the checkpoint left it, bit for bit.
"""
from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .api import checks, state
from .api.checks import PYTHON_SCENE, optional_path, strip_location
from .api.flow import add_inlet, add_outlet
from .api.restart import check_restart_step, checkpoint_of_scene
from .api.scene import SceneBuilder
from .api.start import make_solver, start_solver
from .api.steps import dynamic_step, keep_tables, move_wall_of, next_step_id, replicate_step
from .errors import InputError
from .flow_spec import DEFAULT_EVERY
from .model import Bodies, Model, MoveWallStep, Output, ReplicateStep, ShapeEntry, Step


class Simulation:
    """A DEM scene and its solution steps, run one at a time (see the module docstring).

    Parameters
    ----------
    gravity: (3,) m/s^2 (default 0 0 0, as in a deck).
    output: results folder; ``None`` writes no files (the state is read in Python).
    restart: a ``checkpoint.h5`` to continue from (see the module docstring).
    vtk_every, vtk_resolution, monitors_every, results_every, checkpoint_every: the deck's
        ``Output`` settings (s, quads per patch direction), used with ``output``.
    quiet: no progress display (default True; False shows the progress line of ``solve``).
    contact_options, safety: passed to :class:`~nurbsdem.solver.Solver`.

    The scene's entries are checked and added by a :class:`~nurbsdem.api.scene.SceneBuilder`,
    the steps' arguments by :mod:`nurbsdem.api.steps`, the solver made at the first step by
    :mod:`nurbsdem.api.start`; the state is read by :mod:`nurbsdem.api.state`.
    """

    def __init__(self, gravity: Sequence[float] = (0.0, 0.0, 0.0), output: str | Path | None = None,
                 restart: str | Path | None = None, *, vtk_every: float = 0.01,
                 vtk_resolution: int = 8, monitors_every: float = 1e-3,
                 results_every: float | None = None, checkpoint_every: float = 0.1,
                 quiet: bool = True, safety: float = 0.5,
                 contact_options: dict | None = None) -> None:
        self.model = Model(path=PYTHON_SCENE, text="")
        self.model.gravity = checks.vector("Gravity", gravity, "gravity")
        output = optional_path(output, "output")
        restart = optional_path(restart, "restart")
        self._output_dir = Path(output) if output is not None else None
        checks.output_settings(vtk_every, vtk_resolution, monitors_every, results_every,
                               checkpoint_every)
        if output is not None:
            self.model.output = Output(Path(output), float(vtk_every), int(vtk_resolution),
                                       float(monitors_every),
                                       None if results_every is None else float(results_every),
                                       float(checkpoint_every))
        else:
            self.model.output = Output(Path("."), 0.0, int(vtk_resolution), 0.0, 0.0, 0.0)
        self._restart = Path(restart) if restart is not None else None
        self._quiet = quiet
        self._solver_options = checks.solver_options(dict(safety=safety,
                                                          contact_options=contact_options))
        self._from_deck = False
        self._init_parts()
        self.solver = None

    def _init_parts(self) -> None:
        """What a simulation keeps besides the model and the solver: the scene builder (its
        boxes and flat walls as given, for :attr:`deck_text`), the shapes' geometry hashes,
        the step lines of the checkpoint restarted from (None: not restarted) and the error
        that stopped the run (None: none)."""
        self._scene = SceneBuilder(self.model, _generated_sphere_radius)
        self._boxes, self._wall_args = self._scene.boxes, self._scene.wall_args
        self._geometry_hash: dict[int, str] = {}
        self._ckpt_steps: list[str] | None = None
        self._failed: BaseException | None = None

    # ------------------------------------------------------------------ from a deck
    @classmethod
    def from_deck(cls, path: str | Path, output: str | Path | None = None,
                  restart: str | Path | None = None, steps: bool = True, quiet: bool = True,
                  **solver_options: Any) -> "Simulation":
        """The scene of a deck (parsed, placed and validated as by ``nurbsdem check``).

        steps: keep the deck's steps (run them with :meth:`run`); False keeps only the scene,
            for steps run from Python. output: replaces the deck's ``Output Directory``.
        restart: a checkpoint of this deck to continue from (as ``nurbsdem solve --restart``).
        """
        from .io.deck import parse_deck
        from .solver import Solver

        output = optional_path(output, "output")
        restart = optional_path(restart, "restart")
        solver_options = checks.solver_keywords(solver_options)
        model = parse_deck(optional_path(path, "path"))
        if not steps:
            model.steps = []
        sim = cls.__new__(cls)
        sim.model = model
        sim._output_dir = Path(output) if output is not None else Path(model.output.directory)
        sim._restart = Path(restart) if restart is not None else None
        sim._quiet = quiet
        sim._solver_options = solver_options
        sim._from_deck = True
        sim._init_parts()
        sim.solver = Solver(model, output=output, restart=restart, quiet=quiet,
                            **solver_options)
        return sim

    def _editable(self, what: str) -> None:
        if self._from_deck:
            raise InputError(f"{what}: the scene of a deck is edited in the deck")
        if self.solver is not None:
            raise InputError(f"{what}: the scene is fixed once a step has run (add materials, "
                             f"shapes, particles, walls and interfaces before the first step)")

    # ------------------------------------------------------------------ the scene
    def add_material(self, id: int, density: float, young_modulus: float | None = None,
                     poisson_ratio: float = 0.0) -> int:
        """``Material ID Density RHO [YoungModulus E] [PoissonRatio NU]`` (kg/m^3, Pa, -; the
        elastic constants are used by Hertz–Mindlin interfaces). Returns the id."""
        self._editable("add_material")
        return self._scene.add_material(id, density, young_modulus, poisson_ratio)

    def add_interface(self, normal_penalty: float | None = None,
                      tangential_penalty: float | None = None,
                      normal_damping: float | None = None, tangential_damping: float | None = None,
                      friction: float | None = None, between: str | None = None,
                      materials: Sequence[int] | None = None, id: int | None = None,
                      model: str = "LinearPenalty", restitution: float | None = None,
                      rolling_friction: float | None = None,
                      rolling_damping: float | None = None, **law_keys: float) -> int:
        """``Interface``: contact law of the pairs it covers.

        ``model="LinearPenalty"`` (paper Eqs. 16-17): normal_penalty, tangential_penalty (N/m),
        normal_damping, tangential_damping (N s/m). ``model="HertzMindlin"``: restitution
        (0 < e <= 1), the stiffness from the materials' young_modulus and poisson_ratio (walls:
        the ``material`` of add_box / add_wall, default rigid). Both: friction (Coulomb, -),
        rolling_friction (μ_r, -: a rolling-resistance torque up to μ_r R_r f_n,
        :mod:`nurbsdem.dynamics.rolling`; default 0, none), rolling_damping (η_r, -: the
        rolling spring's damping ratio while it holds; default 0, none);
        between: ``None`` (all pairs), ``"particle-particle"`` or ``"particle-wall"``;
        materials: ``(m1, m2)`` or ``(m,)`` as in the deck; a law added at run time takes its
        keys by their Python names (``law_keys``). Later interfaces override earlier ones.
        The rules and messages are the deck's
        (:func:`~nurbsdem.dynamics.laws.interface.build_interface`). Returns the id (default:
        the next free one).
        """
        self._editable("add_interface")
        given = dict(normal_penalty=normal_penalty, tangential_penalty=tangential_penalty,
                     normal_damping=normal_damping, tangential_damping=tangential_damping,
                     friction=friction, restitution=restitution,
                     rolling_friction=rolling_friction, rolling_damping=rolling_damping,
                     **law_keys)
        return self._scene.add_interface(given, between, materials, id, model)

    def add_particle(self, shape: Any, material: int, position: Sequence[float],
                     rotation: Sequence[float] | None = None,
                     velocity: Sequence[float] | None = None,
                     angular_velocity: Sequence[float] | None = None) -> int:
        """``Particle``: one body of ``shape`` (a :class:`~nurbsdem.geometry.shape.Shape`, e.g.
        from :mod:`nurbsdem.shapes`, or a shape file) and ``material`` (an id of
        :meth:`add_material`); mass and inertia come from the shape and the density.

        position: the centroid in the world (m). rotation: rotation vector (rad) or a (3, 3)
        matrix, file frame to world. velocity (m/s), angular_velocity (rad/s): world frame.
        Returns the particle id (1, 2, ... in the order of the calls).
        """
        self._editable("add_particle")
        return self._scene.add_particle(shape, material, position, rotation, velocity,
                                        angular_velocity)

    def set_periodic(self, x: Sequence[float] | None = None, y: Sequence[float] | None = None,
                     z: Sequence[float] | None = None) -> None:
        """``Periodic [X lo hi] [Y lo hi] [Z lo hi]`` (block Environment): the box [lo, hi)
        (m) repeats along each axis given as (lo, hi); flat walls lie along those axes and
        cover the cell (docs/user-guide.md, Periodic cells)."""
        self._editable("set_periodic")
        self.model.periodic = checks.periodic(x, y, z)

    def add_box(self, min: Sequence[float], max: Sequence[float], top: bool = False,
                material: int | None = None) -> list[str]:
        """``Box``: the walls of the box [min, max] (m), normals inwards; returns their names
        (``bottom, x_min, x_max, y_min, y_max`` and ``top`` with ``top=True``). material: the
        walls' material for Hertz–Mindlin interfaces (default rigid)."""
        self._editable("add_box")
        return self._scene.add_box(min, max, top, material)

    def add_wall(self, name: str, point: Sequence[float], normal: Sequence[float],
                 size: Sequence[float], axis: Sequence[float] | None = None,
                 material: int | None = None) -> str:
        """``Wall``: a flat rectangle centred at ``point`` (m), ``size`` (lu, lv) (m), its
        ``normal`` pointing to the particles; ``axis`` orients the first side; ``material``
        as for :meth:`add_box`. Returns the name."""
        self._editable("add_wall")
        return self._scene.add_wall(name, point, normal, size, axis, material)

    def add_mesh_wall(self, name: str, file, scale: float = 1.0, position=(0.0, 0.0, 0.0),
                      rotation=(0.0, 0.0, 0.0), material: int | None = None,
                      one_sided: bool = False) -> str:
        """``Mesh``: a wall of the triangles of an STL, OBJ or PLY ``file``, placed at
        ``x = R(rotation) (scale x_file) + position`` (m; rotation vector, rad); two-sided
        unless ``one_sided``; for exact-sphere particles. Returns the name."""
        self._editable("add_mesh_wall")
        return self._scene.add_curved_wall("mesh", name, file, scale, position, rotation,
                                           material, one_sided)

    def add_surface_wall(self, name: str, file, position=(0.0, 0.0, 0.0),
                         rotation=(0.0, 0.0, 0.0), material: int | None = None) -> str:
        """``Surface``: a wall of the open NURBS patches of a shape ``file`` (their front
        towards the particles; ``nurbsdem shape cylinder|cone|plane`` writes them), placed
        at ``x = R(rotation) x_file + position``; for exact-sphere particles."""
        self._editable("add_surface_wall")
        return self._scene.add_curved_wall("surface", name, file, 1.0, position, rotation,
                                           material, False)

    def add_inlet(self, shapes: Sequence[Any], material: int, box: Sequence[float] | None,
                  rate: float, count: int, fractions: Sequence[float] | None = None,
                  velocity: Sequence[float] = (0.0, 0.0, 0.0), seed: int = 0,
                  every: float = DEFAULT_EVERY, name: str | None = None, *,
                  disc: Sequence[float] | None = None, normal: Sequence[float] | None = None,
                  radius: float | None = None, thickness: float = 0.0) -> str:
        """``Inlet`` (the deck's block ``Flow``): during every timed step, ``count`` particles
        of ``shapes`` (Shape objects, shape files or shape ids; by number ``fractions``,
        summing to 1) and ``material`` enter the box (x0, y0, z0, x1, y1, z1) (m), or with
        ``box=None`` the disc of centre ``disc`` (m), axis ``normal``, ``radius`` and
        ``thickness`` (m; 0: the centroids lie in the disc's plane), at ``rate`` particles/s
        counted from the start of each timed step, with ``velocity`` (m/s), clear of the
        particles present, at the end of each ``every`` s and of each step; ``seed`` of its
        own random stream. Returns the name."""
        self._editable("add_inlet")
        return add_inlet(self._scene, shapes, material, box, rate, count, fractions, velocity,
                         seed, every, name, disc, normal, radius,
                         thickness if disc is not None or thickness else None)

    def add_outlet(self, box: Sequence[float] | None = None,
                   point: Sequence[float] | None = None,
                   normal: Sequence[float] | None = None, every: float = DEFAULT_EVERY,
                   name: str | None = None) -> str:
        """``Outlet``: during every timed step, the particles whose centroid lies in ``box``
        (x0, y0, z0, x1, y1, z1) (m), or beyond the plane through ``point`` on the side
        ``normal`` points to, are removed at the end of each ``every`` s and counted
        (``monitors/outlet_<name>.csv``). Returns the name."""
        self._editable("add_outlet")
        return add_outlet(self.model, box, point, normal, every, name)

    # ------------------------------------------------------------------ steps
    def run_dynamic(self, duration: float, time_step: float, damping: str = "explicit",
                    accuracy: float | None = None, safety: float | None = None) -> None:
        """``Dynamic``: integrate ``duration`` s with deck time step ``time_step`` s
        (sub-stepped below the stability limit, as ``solve`` does); ``damping`` "explicit" or
        "implicit" (the deck's ``Damping``); ``accuracy`` η of the accuracy control (the
        deck's ``Accuracy``, :mod:`nurbsdem.dynamics.accuracy`; None: off); ``safety`` the
        fraction of the stability limit the sub-step takes (the deck's ``Safety``; None: the
        solver's, 0.5)."""
        self._run(dynamic_step(next_step_id(self.model), duration, time_step, damping,
                               accuracy, safety))

    def replicate(self, layers: int, height: float) -> None:
        """``Replicate``: the particles become layer 0 of ``layers`` layers spread over
        ``height`` m upwards (velocities zeroed)."""
        self._run(replicate_step(next_step_id(self.model), layers, height))

    def move_wall(self, name: str | Sequence, displacement: Sequence[float] | None = None,
                  duration: float | None = None, time_step: float | None = None, *,
                  to_contact: bool = False, gap: float = 0.0,
                  direction: Sequence[float] | None = None, damping: str = "explicit",
                  accuracy: float | None = None, safety: float | None = None,
                  angular_velocity: Sequence[float] | None = None,
                  center: Sequence[float] = (0.0, 0.0, 0.0), table=None,
                  force: float | None = None, max_speed: float | None = None,
                  gain: float | None = None) -> None:
        """``MoveWall``: either ``displacement`` (m) at constant velocity over ``duration`` s
        with time step ``time_step`` s (the particles move meanwhile), or ``to_contact=True``:
        translate the wall (along ``direction``, default its normal) until the nearest
        particle is ``gap`` m away (no time passes; a mesh or surface wall needs
        ``direction``: :mod:`nurbsdem.curved_to_contact`), or ``angular_velocity``
        (rad/s): a mesh or surface wall turns about ``center`` (m) over ``duration`` s
        (``Rotate``), translating by ``displacement`` too when given (the centre with it), or
        ``table``: a CSV file or an array of rows t, x, y, z[, rx, ry, rz] (s, m, rad) the
        wall follows (``Table``; ``duration`` default: the last time; an array is written to
        ``<output>/tables/`` for the deck text when the simulation has an output folder).
        ``force`` (N): a wall servo-controlled over ``duration`` s to that push of the
        particles along its normal (a mesh or surface wall: along ``direction``, required),
        its speed ``gain`` (m/(s N)) times the push's error, at most ``max_speed`` (m/s)
        (``Force``; :mod:`nurbsdem.wall_servo`).
        ``damping``, ``accuracy``, ``safety``: as for :meth:`run_dynamic`.

        Several walls in one step: ``name`` a list of ``(name, motion)`` pairs, ``motion`` a
        dict of ``displacement``, ``table`` or ``angular_velocity`` (and ``center``) or
        ``force`` (and ``max_speed``, ``gain``, ``direction``), the timing shared (``Step``
        lines of one id in the deck)."""
        step = move_wall_of(self.model, name, displacement, duration, time_step,
                            to_contact=to_contact, gap=gap, direction=direction,
                            damping=damping, accuracy=accuracy, safety=safety,
                            angular_velocity=angular_velocity, center=center, table=table,
                            force=force, max_speed=max_speed, gain=gain)
        if self._output_dir is not None and (self.solver is None or self.solver.rank == 0):
            keep_tables(step, self._output_dir)
        self._run(step)

    def run(self):
        """Run the steps not run yet (a deck's steps), then close the files; returns the
        :class:`~nurbsdem.run_report.RunSummary`. This is what ``nurbsdem solve`` does.

        An interrupt (Ctrl-C, a notebook's stop button) ends it at the end of a deck time
        step with a checkpoint of that moment: :class:`~nurbsdem.sigint.Interrupted` (a
        KeyboardInterrupt) reaches the caller, :attr:`time` and the bodies are the
        checkpoint's, and a new Simulation continues from it with ``restart=``."""
        self._usable()
        if self.solver is None:
            raise InputError("nothing to run: a scene built in Python runs its steps as they "
                             "are called (run_dynamic, replicate, move_wall)")
        try:
            if not self.solver.started:
                start_solver(self.solver, self._output_dir, self._restart)
            self.solver.run_pending()
        except BaseException as exc:
            self._fail(exc)
            raise
        return self.close()

    def close(self):
        """Close the output files (flushed after every step anyway); returns the run's
        :class:`~nurbsdem.run_report.RunSummary`. Steps run after it open them again and
        continue them."""
        if self.solver is None:
            return None
        if self.solver.started:
            self.summary = self.solver.finish()
        return getattr(self, "summary", None)

    def __enter__(self) -> "Simulation":
        return self

    def __exit__(self, *exc) -> None:
        if self.solver is not None and self.solver.started and exc[0] is None:
            self.close()
        elif self.solver is not None and self.solver.started:
            self.solver.abort()

    def _usable(self) -> None:
        if self._failed is not None:
            raise InputError(f"the simulation stopped after an error ({self._failed}); "
                             f"continue from its last checkpoint with restart=")

    def _fail(self, exc: BaseException) -> None:
        if isinstance(exc, InputError) and not (self.solver and self.solver.started):
            return
        self._failed = exc if not isinstance(exc, InputError) else strip_location(exc)
        if self.solver is not None and self.solver.started:
            self.solver.abort()

    def _run(self, step: Step) -> None:
        """Validate, add and run one step through the solver (after the deck's steps not run
        yet, for a scene read from a deck)."""
        self._usable()
        model = self.model
        model.steps.append(step)
        model.text = self.deck_text
        try:
            if self.solver is None:
                self._create_solver()
            else:
                from .validation import check_model
                check_model(model)
        except BaseException as exc:
            model.steps.pop()
            model.text = self.deck_text
            if isinstance(exc, InputError):
                raise strip_location(exc) from None
            raise
        try:
            if not self.solver.started:
                start_solver(self.solver, self._output_dir, self._restart)
            self._check_restart_step(step)
            self.solver.run_pending()
        except InputError as exc:
            instantaneous = isinstance(step, ReplicateStep) or (
                isinstance(step, MoveWallStep) and step.to_contact)
            if not self.solver.started or (instantaneous and
                                           self.solver.step_index == len(model.steps) - 1):
                # refused before it changed anything (no such checkpoint; copies behind a
                # wall): not run
                model.steps.pop()
                model.text = self.deck_text
                raise strip_location(exc) from None
            self._fail(exc)
            raise strip_location(exc) from None
        except BaseException as exc:
            self._fail(exc)
            raise

    def _create_solver(self) -> None:
        """The first step: validate the whole scene (as ``nurbsdem check``), place the bodies
        and make the solver."""
        self.solver = make_solver(self.model, restart=self._restart, quiet=self._quiet,
                                  write_output=self._output_dir is not None,
                                  restart_check=self._restart_state,
                                  options=self._solver_options)

    # ------------------------------------------------------------------ restart
    def _restart_state(self, path: Path) -> dict:
        """Read a checkpoint of a scene built in Python and check it was written for this
        scene (its deck text, Output block aside); its steps are compared as they are run."""
        st, self._ckpt_steps = checkpoint_of_scene(path, self.deck_text)
        return st

    def _check_restart_step(self, step: Step) -> None:
        """After a restart, a step the checkpoint has run (or started) must be the same."""
        if self._ckpt_steps is not None:
            check_restart_step(step, len(self.model.steps) - 1, self._ckpt_steps,
                               self.deck_text, self._restart)

    # ------------------------------------------------------------------ the state
    @property
    def bodies(self) -> Bodies:
        """The particles' current state (a copy): ids, shape and material ids, centroids,
        quaternions, velocities."""
        return state.bodies(self.model, self.solver)

    @property
    def time(self) -> float:
        """Simulated time (s)."""
        return state.time(self.solver)

    @property
    def ids(self) -> np.ndarray:
        """(N,) particle ids (rows of the state arrays)."""
        return self.bodies.id

    @property
    def positions(self) -> np.ndarray:
        """(N, 3) centroids in the world (m)."""
        return self.bodies.position

    @property
    def velocities(self) -> np.ndarray:
        """(N, 3) centroid velocities (m/s)."""
        return self.bodies.velocity

    @property
    def angular_velocities(self) -> np.ndarray:
        """(N, 3) angular velocities, world frame (rad/s)."""
        return self.bodies.angular_velocity

    @property
    def rotations(self) -> np.ndarray:
        """(N, 3, 3) rotation matrices, shape file frame to world."""
        return self.bodies.rotation_matrices()

    @property
    def quaternions(self) -> np.ndarray:
        """(N, 4) unit quaternions (w, x, y, z), shape file frame to world."""
        return self.bodies.quaternion

    @property
    def wall_names(self) -> list[str]:
        """Wall names in id order (wall k is body N + k in :meth:`contacts`)."""
        return self.model.wall_names

    @property
    def wall_displacements(self) -> dict[str, np.ndarray]:
        """Each wall's displacement from where it was defined (m)."""
        return state.wall_displacements(self.model, self.solver)

    def energy(self) -> dict[str, float]:
        """The energies of ``monitors/energy.csv`` (J) at the end of the last dynamic step:
        time, kinetic, potential, elastic, dissipated, external_work, mechanical,
        balance_error (dissipated and external work cumulative since the start). Before any
        step: the kinetic and potential energy of the bodies, the rest 0. After a Replicate
        or MoveWall ToContact step (until the next dynamic step): the kinetic and potential
        energy of the bodies, elastic 0 and balance_error NaN (not measured there)."""
        return state.energy(self.model, self.solver)

    def contacts(self) -> dict[str, np.ndarray]:
        """The active contacts at the end of the last dynamic step (arrays over K contacts):
        ``pairs`` (K, 2) body indices (rows of :attr:`positions`; N + k is wall k of
        :attr:`wall_names`), ``ids`` (K, 2) particle ids (0 for a wall), ``point`` (K, 3)
        force application points (m), ``normal`` (K, 3) unit, from the first body towards the
        second, ``depth`` (K,) penetration (m), ``force_normal``, ``force_tangential``, ``force``
        (K, 3) on the second body (N). Empty before any dynamic step and after a Replicate or
        MoveWall ToContact step (until the next dynamic step)."""
        return state.contacts(self.model, self.solver)

    # ------------------------------------------------------------------ the deck
    @property
    def deck_text(self) -> str:
        """The deck of this scene and of the steps run so far (what ``results.h5`` and the
        checkpoint store). Shapes given as Python objects that are not exact generator
        spheres appear as ``File "<python object ...>"`` with a hash of their geometry."""
        import copy
        from dataclasses import replace
        from .io.deck_format import box_entry, format_model, wall_entry
        from .io.deck_schema import Entry
        m = self.model
        if self._from_deck:
            return m.text
        boxes = {b[0]: b for b in self._boxes}
        walls = [box_entry(*boxes[w.id]) if w.id in boxes
                 else wall_entry(w.id, w.name, *self._wall_args[w.name], w.material_id)
                 for w in m.walls if w.id in boxes or w.kind == "wall"]

        def python_object(e: ShapeEntry) -> Entry:
            if e.id not in self._geometry_hash:
                self._geometry_hash[e.id] = _geometry_hash(e.shape)
            label = "".join(c for c in str(e.shape.name or "shape") if c not in '"#\n')
            return Entry("Shapes", "Shape", 0, e.id, values={"File": f"<python object {label}>"},
                         comment=f"geometry sha256 {self._geometry_hash[e.id]}")
        scene = copy.copy(m)          # materials and shapes by id; Output only with output=
        scene.materials, scene.shapes = dict(sorted(m.materials.items())), dict(
            sorted(m.shapes.items()))
        scene.output = (replace(m.output, directory=Path(m.output.directory).resolve())
                        if self._output_dir is not None and m.output is not None else None)
        return format_model(scene, "scene built in Python (nurbsdem.Simulation)", walls,
                            python_object)

    def write_deck(self, path: str | Path) -> Path:
        """Write :attr:`deck_text` (``nurbsdem solve`` runs it when every shape is a file or
        a generator sphere)."""
        from .io.atomic import atomic_write_text
        atomic_write_text(path, self.deck_text)
        return Path(path)


# ---------------------------------------------------------------------------- helpers


def _geometry_hash(shape) -> str:
    h = hashlib.sha256()
    for p in shape.patches:
        for arr in (p.knots_u, p.knots_v, p.control_points, p.weights):
            h.update(np.ascontiguousarray(np.asarray(arr, float)).tobytes())
        h.update(np.array([p.degree_u, p.degree_v], np.int64).tobytes())
    return h.hexdigest()[:16]


def _generated_sphere_radius(shape) -> float | None:
    """r when ``shape`` is exactly ``nurbsdem.shapes.sphere(r)`` (the deck's ``Sphere Radius
    r``), else None."""
    from .geometry.analytic import exact_sphere
    from .geometry.generators import sphere_patches
    if len(shape.patches) != 6:
        return None
    found = exact_sphere(shape)
    if found is None:
        return None
    r = found[1]
    target = _geometry_hash(shape)
    for digits in (17, 16, 15, 14, 13, 12):
        cand = float(f"{r:.{digits}g}")
        if _geometry_hash(type("S", (), {"patches": sphere_patches(cand)})) == target:
            return cand
    return None


__all__ = ["Simulation"]

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
import logging
import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .errors import InputError
from .model import (DAMPING_SCHEMES, Bodies, CurvedWallSpec, DynamicStep, Material, Model,
                    MoveWallStep, Output, ParticleSpec, ReplicateStep, ShapeEntry, Step,
                    WallSpec)

#: ``Model.path`` of a scene built in Python (its errors carry no file location).
PYTHON_SCENE = "<python>"


def _f(x: float) -> str:
    """A float as the deck writes it: the shortest text that reads back exactly."""
    return repr(float(x))


def _v(x) -> str:
    return " ".join(_f(c) for c in np.ravel(x))


def _curved_line(w: CurvedWallSpec) -> str:
    """The deck line of a mesh or surface wall (its file by its absolute path)."""
    head = "Mesh" if w.kind == "mesh" else "Surface"
    text = f'  {head} {w.id} Name {w.name} File "{w.file}"'
    if w.kind == "mesh":
        text += f" Scale {_f(w.scale)}"
    text += f" Position {_v(w.position)} Rotation {_v(w.rotation)}"
    if w.material_id is not None:
        text += f" Material {w.material_id}"
    return text + (" OneSided yes" if w.one_sided else "")


def _strip_location(exc: InputError) -> InputError:
    """The same error without the pseudo file location of a scene built in Python."""
    if exc.path == PYTHON_SCENE:
        return InputError(exc.detail, where=exc.where)
    return exc


def _shown(value: Any, limit: int = 60) -> str:
    """repr(value), cut to ``limit`` characters (a message stays one short line)."""
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _optional_path(value: Any, what: str) -> Any:
    """``value`` when it is None, a str or a path; else an :class:`InputError`."""
    if value is None or isinstance(value, (str, Path)):
        return value
    import os
    if isinstance(value, os.PathLike):
        return value
    raise InputError(f"{what} must be a folder or file path (str or pathlib.Path) or None, "
                     f"got {value!r}")


def _contact_option_defaults() -> dict[str, Any]:
    """The keywords :class:`~nurbsdem.contact.scene.SceneContacts` takes from
    ``contact_options``, with their defaults (its own signature)."""
    import inspect
    from .contact.scene import SceneContacts
    params = inspect.signature(SceneContacts.__init__).parameters
    return {k: p.default for k, p in params.items()
            if p.default is not inspect.Parameter.empty and k != "walls"}


def _checked_solver_options(options: dict[str, Any]) -> dict[str, Any]:
    """The solver's keywords checked as a deck checks its values: ``safety`` in the deck's
    ``Safety`` range, ``contact_options`` a dict of :class:`SceneContacts` keywords (booleans
    for its switches, finite lengths >= 0 in m for the others); raises :class:`InputError`."""
    out = dict(options)
    if out.get("safety") is not None:
        out["safety"] = Simulation._number("Safety", out["safety"], "safety", positive=True)
    opts = out.get("contact_options")
    if opts is None:
        return out
    if not isinstance(opts, dict):
        raise InputError(f"contact_options must be a dict of keywords, got {opts!r}")
    known = _contact_option_defaults()
    checked = {}
    for key, value in opts.items():
        if key not in known:
            raise InputError(f"contact_options: unknown keyword {key!r} (known: "
                             f"{', '.join(sorted(known))})")
        if isinstance(known[key], bool):
            if not isinstance(value, (bool, np.bool_)):
                raise InputError(f"contact_options: {key} must be True or False, got {value!r}")
            checked[key] = bool(value)
        elif value is None and known[key] is None:
            checked[key] = None
        else:
            checked[key] = Simulation._number(key, value, "contact_options", nonnegative=True)
    out["contact_options"] = checked
    return out


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
    """

    def __init__(self, gravity: Sequence[float] = (0.0, 0.0, 0.0), output: str | Path | None = None,
                 restart: str | Path | None = None, *, vtk_every: float = 0.01,
                 vtk_resolution: int = 8, monitors_every: float = 1e-3,
                 results_every: float | None = None, checkpoint_every: float = 0.1,
                 quiet: bool = True, safety: float = 0.5,
                 contact_options: dict | None = None) -> None:
        self.model = Model(path=PYTHON_SCENE, text="")
        self.model.gravity = self._vector("Gravity", gravity, "gravity")
        output = _optional_path(output, "output")
        restart = _optional_path(restart, "restart")
        self._output_dir = Path(output) if output is not None else None
        for key, val in (("Every", vtk_every), ("Every", monitors_every),
                         ("Every", checkpoint_every)) + ((("Every", results_every),)
                                                        if results_every is not None else ()):
            self._number(key, val, "an output interval", positive=True)
        if not (isinstance(vtk_resolution, (int, np.integer)) and 1 <= vtk_resolution <= 10 ** 4):
            raise InputError(f"vtk_resolution must be an integer between 1 and 10000, got "
                             f"{vtk_resolution!r}")
        if output is not None:
            self.model.output = Output(Path(output), float(vtk_every), int(vtk_resolution),
                                       float(monitors_every),
                                       None if results_every is None else float(results_every),
                                       float(checkpoint_every))
        else:
            self.model.output = Output(Path("."), 0.0, int(vtk_resolution), 0.0, 0.0, 0.0)
        self._restart = Path(restart) if restart is not None else None
        self._quiet = quiet
        self._solver_options = _checked_solver_options(dict(safety=safety,
                                                            contact_options=contact_options))
        self._from_deck = False
        self._shape_ids: dict[Any, int] = {}
        self._boxes: list[tuple[int, np.ndarray, np.ndarray, bool]] = []
        self._ckpt_steps: list[str] | None = None
        self._geometry_hash: dict[int, str] = {}
        self._wall_args: dict[str, tuple] = {}
        self.solver = None
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

        output = _optional_path(output, "output")
        restart = _optional_path(restart, "restart")
        import inspect
        known = set(inspect.signature(Solver.__init__).parameters) - {"self", "model", "output",
                                                                      "restart", "quiet"}
        for key in solver_options:
            if key not in known:
                raise InputError(f"from_deck: unknown keyword {key!r} (solver options: "
                                 f"{', '.join(sorted(known))})")
        solver_options = _checked_solver_options(solver_options)
        model = parse_deck(_optional_path(path, "path"))
        if not steps:
            model.steps = []
        sim = cls.__new__(cls)
        sim.model = model
        sim._output_dir = Path(output) if output is not None else Path(model.output.directory)
        sim._restart = Path(restart) if restart is not None else None
        sim._quiet = quiet
        sim._solver_options = solver_options
        sim._from_deck = True
        sim._shape_ids, sim._boxes, sim._ckpt_steps = {}, [], None
        sim._geometry_hash, sim._wall_args = {}, {}
        sim._failed = None
        sim.solver = Solver(model, output=output, restart=restart, quiet=quiet,
                            **solver_options)
        return sim

    # ------------------------------------------------------------------ value checks
    @staticmethod
    def _number(key: str, value: Any, what: str, positive: bool = False,
                nonnegative: bool = False) -> float:
        try:
            x = float(value)
        except (TypeError, ValueError, OverflowError):
            raise InputError(f"{what}: {key} must be a number, got {_shown(value)}") from None
        if not math.isfinite(x):
            raise InputError(f"{what}: {key} must be a finite number, got {value!r}")
        if positive and not x > 0:
            raise InputError(f"{what}: {key} must be > 0, got {x:g}")
        if nonnegative and x < 0:
            raise InputError(f"{what}: {key} must be >= 0, got {x:g}")
        Simulation._range(key, x, what)
        return x

    @staticmethod
    def _range(key: str, value: Any, what: str) -> None:
        from .io.deck import _DeckError, check_range
        try:
            check_range(key, value, f"{what}: ")
        except _DeckError as exc:
            raise InputError(str(exc)) from None

    @staticmethod
    def _vector(key: str, value: Any, what: str, n: int = 3) -> np.ndarray:
        try:
            v = np.array(value, dtype=float)
        except (TypeError, ValueError, OverflowError):
            raise InputError(f"{what}: {key} must be {n} numbers, got {_shown(value)}") from None
        if v.shape != (n,):
            raise InputError(f"{what}: {key} must be {n} numbers, got {_shown(value)}")
        if not np.isfinite(v).all():
            raise InputError(f"{what}: {key} must be finite numbers, got {value!r}")
        Simulation._range(key, v, what)
        return v

    @staticmethod
    def _id(value: Any, what: str) -> int:
        from .io.deck import ID_MAX
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise InputError(f"{what}: id must be an integer >= 1, got {_shown(value)}")
        if value > ID_MAX:
            raise InputError(f"{what}: id {_shown(value)} is too large: ids are at most {ID_MAX:g} "
                             f"(as in a deck)")
        return int(value)

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
        mid = self._id(id, "add_material")
        if mid in self.model.materials:
            raise InputError(f"add_material: material {mid} is already defined")
        what = f"material {mid}"
        rho = self._number("Density", density, what, positive=True)
        E = (self._number("YoungModulus", young_modulus, what, positive=True)
             if young_modulus is not None else None)
        nu = self._number("PoissonRatio", poisson_ratio, what)
        if not -1.0 < nu < 0.5:
            raise InputError(f"{what}: PoissonRatio must lie in (-1, 0.5), got {nu:g}")
        self.model.materials[mid] = Material(mid, rho, 0, E, nu)
        return mid

    def add_interface(self, normal_penalty: float | None = None,
                      tangential_penalty: float | None = None,
                      normal_damping: float | None = None, tangential_damping: float | None = None,
                      friction: float | None = None, between: str | None = None,
                      materials: Sequence[int] | None = None, id: int | None = None,
                      model: str = "LinearPenalty", restitution: float | None = None,
                      **law_keys: float) -> int:
        """``Interface``: contact law of the pairs it covers.

        ``model="LinearPenalty"`` (paper Eqs. 16-17): normal_penalty, tangential_penalty (N/m),
        normal_damping, tangential_damping (N s/m). ``model="HertzMindlin"``: restitution
        (0 < e <= 1), the stiffness from the materials' young_modulus and poisson_ratio (walls:
        the ``material`` of add_box / add_wall, default rigid). Both: friction (Coulomb, -);
        between: ``None`` (all pairs), ``"particle-particle"`` or ``"particle-wall"``;
        materials: ``(m1, m2)`` or ``(m,)`` as in the deck; a law added at run time takes its
        keys by their Python names (``law_keys``). Later interfaces override earlier ones.
        The rules and messages are the deck's
        (:func:`~nurbsdem.dynamics.laws.interface.build_interface`). Returns the id (default:
        the next free one).
        """
        from .dynamics.laws import LAWS
        from .dynamics.laws.interface import Front, build_interface, python_name
        self._editable("add_interface")
        used = {i.id for i in self.model.interfaces}
        iid = self._id(id, "add_interface") if id is not None else max(used, default=0) + 1
        if iid in used:
            raise InputError(f"add_interface: interface {iid} is already defined")
        what = f"interface {iid}"
        given = dict(normal_penalty=normal_penalty, tangential_penalty=tangential_penalty,
                     normal_damping=normal_damping, tangential_damping=tangential_damping,
                     friction=friction, restitution=restitution, **law_keys)
        deck_key = {python_name(k.deck): k.deck for law in LAWS.values() for k in law.keys}
        values = {}
        for name, value in given.items():
            if value is None:
                continue
            if name not in deck_key:
                raise InputError(f"{what}: unknown key {name!r}")
            values[deck_key[name]] = self._number(python_name(deck_key[name]), value, what)
            self._range(deck_key[name], values[deck_key[name]], what)

        def fail(message: str):
            raise InputError(message)
        mats = None
        if materials is not None:
            mats = tuple(self._id(m, f"{what}: materials") for m in np.ravel(materials).tolist())
        self.model.interfaces.append(build_interface(
            iid, str(model), values, between, mats, Front(what, python_name, fail),
            known_materials=self.model.materials))
        return iid

    def _shape_id(self, shape: Any) -> int:
        """The shape id of a Shape object or a shape file (added on first use)."""
        from .geometry.shape import Shape
        if isinstance(shape, (str, Path)):
            file = Path(shape).expanduser().resolve()
            key: Any = ("file", str(file))
        elif isinstance(shape, Shape):
            key = ("object", id(shape))
        else:
            raise InputError(f"add_particle: shape must be a Shape (e.g. nurbsdem.shapes."
                             f"sphere(r)) or a shape file path, got {type(shape).__name__}")
        if key in self._shape_ids:
            return self._shape_ids[key]
        sid = len(self.model.shapes) + 1
        if key[0] == "file":
            from .io.shapefile import not_a_file
            why = not_a_file(file)
            if why is not None:
                raise InputError(f"add_particle: shape file {shape}: {why}")
            from .io.shapefile import load_shape
            entry = ShapeEntry(sid, "file", load_shape(file), source=str(file), file=file)
        else:
            src = getattr(shape, "source", None)     # load_shape(path) remembers its file
            r = _generated_sphere_radius(shape) if src is None else None
            if src is not None and Path(src).is_file():
                file = Path(src).resolve()
                entry = ShapeEntry(sid, "file", shape, source=str(file), file=file)
            elif r is not None:
                entry = ShapeEntry(sid, "sphere", shape, params=(r,))
            else:
                entry = ShapeEntry(sid, "object", shape)
        self.model.shapes[sid] = entry
        self._shape_ids[key] = sid
        return sid

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
        pid = len(self.model.particles) + 1
        what = f"particle {pid}"
        mid = self._id(material, f"{what}: material")
        if mid not in self.model.materials:
            known = ", ".join(map(str, sorted(self.model.materials))) or "none"
            raise InputError(f"{what}: unknown material {mid} (defined: {known}; "
                             f"add_material first)")
        pos = self._vector("Position", position, what)
        z = np.zeros(3)
        if rotation is not None and np.shape(rotation) == (3, 3):
            rot = _rotvec_of_matrix(np.asarray(rotation, float), what)
        else:
            rot = self._vector("Rotation", rotation, what) if rotation is not None else z.copy()
        vel = self._vector("Velocity", velocity, what) if velocity is not None else z.copy()
        omg = (self._vector("AngularVelocity", angular_velocity, what)
               if angular_velocity is not None else z.copy())
        sid = self._shape_id(shape)
        # line: the id, so that messages name the later of two particles first, as for a deck
        self.model.particles.append(ParticleSpec(pid, sid, mid, pos, rotation=rot, velocity=vel,
                                                 angular_velocity=omg, line=pid))
        return pid

    def _next_wall_id(self) -> int:
        return max((w.id for w in self.model.walls + self.model.curved_walls), default=0) + 1

    def _add_wall_spec(self, w: WallSpec, what: str) -> None:
        if w.name in self.model.wall_names:
            raise InputError(f"{what}: a wall named {w.name!r} exists already")
        self.model.walls.append(w)

    def _wall_material(self, material: int | None, what: str) -> int | None:
        if material is None:
            return None
        mid = self._id(material, f"{what}: material")
        if mid not in self.model.materials:
            raise InputError(f"{what}: unknown material {mid} (add_material first)")
        return mid

    def add_box(self, min: Sequence[float], max: Sequence[float], top: bool = False,
                material: int | None = None) -> list[str]:
        """``Box``: the walls of the box [min, max] (m), normals inwards; returns their names
        (``bottom, x_min, x_max, y_min, y_max`` and ``top`` with ``top=True``). material: the
        walls' material for Hertz–Mindlin interfaces (default rigid)."""
        from .geometry.generators import box_walls
        self._editable("add_box")
        wmat = self._wall_material(material, "add_box")
        lo = self._vector("Min", min, "add_box")
        hi = self._vector("Max", max, "add_box")
        if np.any(hi <= lo):
            raise InputError("add_box: max must exceed min in x, y and z")
        bid = self._next_wall_id()
        names = []
        for k, (name, patch) in enumerate(box_walls(lo, hi, top=bool(top)).items()):
            self._add_wall_spec(WallSpec(bid + k, name, patch, kind="box", material_id=wmat),
                                "add_box")
            names.append(name)
        self._boxes.append((bid, lo, hi, bool(top), wmat))
        return names

    def add_wall(self, name: str, point: Sequence[float], normal: Sequence[float],
                 size: Sequence[float], axis: Sequence[float] | None = None,
                 material: int | None = None) -> str:
        """``Wall``: a flat rectangle centred at ``point`` (m), ``size`` (lu, lv) (m), its
        ``normal`` pointing to the particles; ``axis`` orients the first side; ``material``
        as for :meth:`add_box`. Returns the name."""
        from .geometry.generators import flat_wall
        self._editable("add_wall")
        from .io.deck import SCHEMA
        from .io.wallname import wall_name_problem
        problem = wall_name_problem(name, SCHEMA)
        if problem is not None:        # the deck's rule (Wall ... Name), the same message
            raise InputError(f"add_wall: {problem}")
        what = f"wall {name!r}"
        wmat = self._wall_material(material, what)
        p = self._vector("Point", point, what)
        n = self._vector("Normal", normal, what)
        if not np.linalg.norm(n) > 0:
            raise InputError(f"{what}: normal must not be zero")
        size = self._vector("Size", size, what, n=2)
        if np.any(size <= 0):
            raise InputError(f"{what}: size must be > 0")
        ax = None
        if axis is not None:
            ax = self._vector("Axis", axis, what)
            t = ax - n * (ax @ n) / (n @ n)
            if np.linalg.norm(t) < 1e-12 * np.linalg.norm(ax) or not np.linalg.norm(ax) > 0:
                raise InputError(f"{what}: axis must not be parallel to the normal (or zero)")
        self._add_wall_spec(WallSpec(self._next_wall_id(), name, flat_wall(p, n, size, ax),
                                     kind="wall", material_id=wmat), "add_wall")
        self._wall_args[name] = (p, n, size, ax)
        return name

    def add_mesh_wall(self, name: str, file, scale: float = 1.0, position=(0.0, 0.0, 0.0),
                      rotation=(0.0, 0.0, 0.0), material: int | None = None,
                      one_sided: bool = False) -> str:
        """``Mesh``: a wall of the triangles of an STL, OBJ or PLY ``file``, placed at
        ``x = R(rotation) (scale x_file) + position`` (m; rotation vector, rad); two-sided
        unless ``one_sided``; for exact-sphere particles. Returns the name."""
        return self._add_curved("mesh", name, file, scale, position, rotation, material,
                                one_sided)

    def add_surface_wall(self, name: str, file, position=(0.0, 0.0, 0.0),
                         rotation=(0.0, 0.0, 0.0), material: int | None = None) -> str:
        """``Surface``: a wall of the open NURBS patches of a shape ``file`` (their front
        towards the particles; ``nurbsdem shape cylinder|cone|plane`` writes them), placed
        at ``x = R(rotation) x_file + position``; for exact-sphere particles."""
        return self._add_curved("surface", name, file, 1.0, position, rotation, material,
                                False)

    def _add_curved(self, kind, name, file, scale, position, rotation, material,
                    one_sided) -> str:
        from .io.deck import SCHEMA
        from .io.deck_curved import _read_check
        from .io.wallname import wall_name_problem
        what = f"add_{kind}_wall"
        self._editable(what)
        problem = wall_name_problem(name, SCHEMA)
        if problem is not None:
            raise InputError(f"{what}: {problem}")
        if name in self.model.wall_names:
            raise InputError(f"{what}: a wall named {name!r} exists already")
        if not (np.isfinite(scale) and scale > 0):
            raise InputError(f"{what}: scale must be positive, got {scale!r}")
        self._range("Scale", float(scale), what)
        spec = CurvedWallSpec(self._next_wall_id(), name, kind, str(Path(file).resolve()),
                              path=Path(file).resolve(), scale=float(scale),
                              position=self._vector("Position", position, what),
                              rotation=self._vector("Rotation", rotation, what),
                              material_id=self._wall_material(material, what),
                              one_sided=bool(one_sided), line=None)
        for warning in _read_check(spec, f"{what} {name!r}"):
            logging.getLogger("nurbsdem").warning("%s", warning)
        self.model.curved_walls.append(spec)
        return name

    # ------------------------------------------------------------------ steps
    def run_dynamic(self, duration: float, time_step: float, damping: str = "explicit",
                    accuracy: float | None = None, safety: float | None = None) -> None:
        """``Dynamic``: integrate ``duration`` s with deck time step ``time_step`` s
        (sub-stepped below the stability limit, as ``solve`` does); ``damping`` "explicit" or
        "implicit" (the deck's ``Damping``); ``accuracy`` η of the accuracy control (the
        deck's ``Accuracy``, :mod:`nurbsdem.dynamics.accuracy`; None: off); ``safety`` the
        fraction of the stability limit the sub-step takes (the deck's ``Safety``; None: the
        solver's, 0.5)."""
        sid = self._next_step_id()
        dur, dt = self._timing(sid, duration, time_step)
        self._run(DynamicStep(sid, 0, dur, dt, damping=self._damping(sid, damping),
                              accuracy=self._optional_positive("Accuracy", sid, accuracy),
                              safety=self._optional_positive("Safety", sid, safety)))

    def replicate(self, layers: int, height: float) -> None:
        """``Replicate``: the particles become layer 0 of ``layers`` layers spread over
        ``height`` m upwards (velocities zeroed)."""
        sid = self._next_step_id()
        if isinstance(layers, bool) or not isinstance(layers, (int, np.integer)) or layers < 1:
            raise InputError(f"Step {sid}: layers must be an integer >= 1, got {layers!r}")
        h = self._number("Height", height, f"Step {sid}", positive=True)
        self._run(ReplicateStep(sid, 0, int(layers), h))

    def move_wall(self, name: str, displacement: Sequence[float] | None = None,
                  duration: float | None = None, time_step: float | None = None, *,
                  to_contact: bool = False, gap: float = 0.0,
                  direction: Sequence[float] | None = None, damping: str = "explicit",
                  accuracy: float | None = None, safety: float | None = None,
                  angular_velocity: Sequence[float] | None = None,
                  center: Sequence[float] = (0.0, 0.0, 0.0)) -> None:
        """``MoveWall``: either ``displacement`` (m) at constant velocity over ``duration`` s
        with time step ``time_step`` s (the particles move meanwhile), or ``to_contact=True``:
        translate the wall (along ``direction``, default its normal) until the nearest
        particle is ``gap`` m away (no time passes), or ``angular_velocity`` (rad/s): a mesh
        or surface wall turns about ``center`` (m) over ``duration`` s (``Rotate``).
        ``damping``, ``accuracy``, ``safety``: as for :meth:`run_dynamic`."""
        sid = self._next_step_id()
        what = f"Step {sid}"
        if not isinstance(name, str) or name not in self.model.wall_names:
            names = ", ".join(self.model.wall_names) or "no walls defined"
            raise InputError(f"{what}: no wall named {name!r} (walls: {names})")
        if angular_velocity is not None:
            if name not in {w.name for w in self.model.curved_walls}:
                raise InputError(f"{what}: only mesh and surface walls turn (angular_velocity)")
            if displacement is not None or to_contact or duration is None or time_step is None:
                raise InputError(f"{what}: angular_velocity takes center, duration and "
                                 f"time_step, not displacement or to_contact")
            omega = self._vector("AngularVelocity", angular_velocity, what)
            if not np.linalg.norm(omega) > 0:
                raise InputError(f"{what}: angular_velocity must not be zero")
            dur, dt = self._timing(sid, duration, time_step)
            self._run(MoveWallStep(sid, 0, wall=name, rotate=True, angular_velocity=omega,
                                   center=self._vector("Center", center, what), duration=dur,
                                   time_step=dt, damping=self._damping(sid, damping),
                                   accuracy=self._optional_positive("Accuracy", sid, accuracy),
                                   safety=self._optional_positive("Safety", sid, safety)))
            return
        if name in {w.name for w in self.model.curved_walls}:
            raise InputError(f"{what}: mesh and surface walls turn (angular_velocity); "
                             f"displacement and to_contact move flat walls")
        if to_contact:
            if displacement is not None or duration is not None or time_step is not None:
                raise InputError(f"{what}: to_contact=True takes gap and direction, not "
                                 f"displacement, duration or time_step")
            g = self._number("Gap", gap, what, nonnegative=True)
            d = None
            if direction is not None:
                d = self._vector("Direction", direction, what)
                if not np.linalg.norm(d) > 0:
                    raise InputError(f"{what}: direction must not be zero")
                d = d / np.linalg.norm(d)
            self._run(MoveWallStep(sid, 0, wall=name, to_contact=True, gap=g, direction=d))
            return
        if displacement is None or duration is None or time_step is None:
            raise InputError(f"{what}: move_wall needs displacement, duration and time_step "
                             f"(or to_contact=True)")
        disp = self._vector("Displacement", displacement, what)
        dur, dt = self._timing(sid, duration, time_step)
        self._run(MoveWallStep(sid, 0, wall=name, displacement=disp, duration=dur, time_step=dt,
                               damping=self._damping(sid, damping),
                               accuracy=self._optional_positive("Accuracy", sid, accuracy),
                               safety=self._optional_positive("Safety", sid, safety)))

    @staticmethod
    def _damping(sid: int, damping: Any) -> str:
        if not isinstance(damping, str) or damping.lower() not in DAMPING_SCHEMES:
            raise InputError(f"Step {sid}: damping must be 'explicit' or 'implicit', got "
                             f"{damping!r}")
        return damping.lower()

    @classmethod
    def _optional_positive(cls, key: str, sid: int, value: Any) -> float | None:
        """A step's optional positive number (``Accuracy``, ``Safety``; None: not given)."""
        return None if value is None else cls._number(key, value, f"Step {sid}", positive=True)

    def _next_step_id(self) -> int:
        return max((s.id for s in self.model.steps), default=0) + 1

    def _timing(self, sid: int, duration: Any, time_step: Any) -> tuple[float, float]:
        dur = self._number("Duration", duration, f"Step {sid}", positive=True)
        dt = self._number("TimeStep", time_step, f"Step {sid}", positive=True)
        if dt > dur:
            raise InputError(f"Step {sid}: time_step {dt:g} s exceeds duration {dur:g} s")
        return dur, dt

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
                self._start()
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
        self._failed = exc if not isinstance(exc, InputError) else _strip_location(exc)
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
                raise _strip_location(exc) from None
            raise
        try:
            if not self.solver.started:
                self._start()
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
                raise _strip_location(exc) from None
            self._fail(exc)
            raise _strip_location(exc) from None
        except BaseException as exc:
            self._fail(exc)
            raise

    def _start(self) -> None:
        if self._output_dir is not None and self.solver.write_output:
            from .io.writers import clean_output_directory
            if self._restart is not None and self._restart.parent.is_dir():
                clean_output_directory(self._restart.parent)
        if self._restart is not None and not self._restart.is_file():
            raise InputError(f"{self._restart}: no such checkpoint file")
        self.solver.start()

    def _create_solver(self) -> None:
        """The first step: validate the whole scene (as ``nurbsdem check``), place the bodies
        and make the solver."""
        from .placement import explicit_bodies
        from .solver import Solver
        from .validation import check_model, validate_scene
        m = self.model
        if not m.particles:
            raise InputError("no particles: add_particle(...) before running a step")
        self._check_interfaces()
        check_model(m)
        m.bodies = explicit_bodies(m)
        validate_scene(m)
        self.solver = Solver(m, restart=self._restart, quiet=self._quiet,
                             write_output=self._output_dir is not None,
                             restart_check=self._restart_state, **self._solver_options)

    def _check_interfaces(self) -> None:
        """The deck's check (:func:`~nurbsdem.dynamics.laws.interface.check_coverage`)."""
        from .dynamics.laws.interface import check_coverage, python_name

        def fail(message: str, line: int | None):
            raise InputError(message)
        check_coverage(self.model, fail, lambda material: None, python_name,
                       ": add_interface(...) for them")

    # ------------------------------------------------------------------ restart
    def _restart_state(self, path: Path) -> dict:
        """Read a checkpoint of a scene built in Python and check it was written for this
        scene (its deck text, Output block aside); its steps are compared as they are run."""
        from .io.checkpoint import load_checkpoint
        st = load_checkpoint(path)
        deck = st.get("deck")
        if not isinstance(deck, str) or "time" not in st:
            raise InputError("not a nurbsdem checkpoint of a run (no deck or time in it)",
                             path=str(path))
        old_scene, old_steps = _split_deck(deck)
        new_scene, _ = _split_deck(self.deck_text)
        if old_scene != new_scene:
            here = [x.strip() for x in new_scene if x not in old_scene]
            there = [x.strip() for x in old_scene if x not in new_scene]
            what = (f"here, not in the checkpoint: {here[0]!r}" if here
                    else f"in the checkpoint, not here: {there[0]!r}" if there
                    else "the order of its entries")
            raise InputError(f"the checkpoint was written for a different scene ({what}); "
                             f"build the scene that wrote it", path=str(path))
        self._ckpt_steps = old_steps
        return st

    def _check_restart_step(self, step: Step) -> None:
        """After a restart, a step the checkpoint has run (or started) must be the same."""
        if self._ckpt_steps is None:
            return
        lines = _split_deck(self.deck_text)[1]
        k = len(self.model.steps) - 1
        if self._ckpt_steps and k < len(self._ckpt_steps) and lines[k] != self._ckpt_steps[k]:
            raise InputError(f"Step {step.id} is not the step the checkpoint ran as step "
                             f"{step.id} ({self._ckpt_steps[k].strip()!r}, here "
                             f"{lines[k].strip()!r}): run the same steps to continue it",
                             path=str(self._restart))

    # ------------------------------------------------------------------ the state
    @property
    def bodies(self) -> Bodies:
        """The particles' current state (a copy): ids, shape and material ids, centroids,
        quaternions, velocities."""
        if self.solver is not None:
            return self.solver.bodies.copy()
        from .placement import explicit_bodies
        return explicit_bodies(self.model)

    @property
    def time(self) -> float:
        """Simulated time (s)."""
        return float(self.solver.time) if self.solver is not None else 0.0

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
        off = (self.solver.wall_offset if self.solver is not None
               else np.zeros((len(self.model.walls), 3)))
        return {w.name: np.array(off[k]) for k, w in enumerate(self.model.walls)}

    def energy(self) -> dict[str, float]:
        """The energies of ``monitors/energy.csv`` (J) at the end of the last dynamic step:
        time, kinetic, potential, elastic, dissipated, external_work, mechanical,
        balance_error (dissipated and external work cumulative since the start). Before any
        step: the kinetic and potential energy of the bodies, the rest 0. After a Replicate
        or MoveWall ToContact step (until the next dynamic step): the kinetic and potential
        energy of the bodies, elastic 0 and balance_error NaN (not measured there)."""
        s = self.solver
        e = s.end_energy if s is not None else None
        if e is not None and e["step"] == s.step_index - 1:
            return {k: v for k, v in e.items() if k != "step"}
        kin, pot = self._free_energies()
        off = s.energy_offset if s is not None else {"dissipated": 0.0, "external_work": 0.0}
        return dict(time=self.time, kinetic=kin, potential=pot, elastic=0.0,
                    dissipated=float(off["dissipated"]), external_work=float(off["external_work"]),
                    mechanical=kin + pot,
                    balance_error=0.0 if e is None and s is None else float("nan"))

    def _free_energies(self) -> tuple[float, float]:
        b, m = self.bodies, self.model
        kin = pot = 0.0
        R = b.rotation_matrices()
        for i in range(len(b)):
            entry = m.shapes[int(b.shape_id[i])]
            rho = m.materials[int(b.material_id[i])].density
            mass = entry.mass(rho)
            J = R[i] @ entry.mass_inertia(rho) @ R[i].T
            w = b.angular_velocity[i]
            kin += 0.5 * mass * float(b.velocity[i] @ b.velocity[i]) + 0.5 * float(w @ J @ w)
            pot -= mass * float(m.gravity @ b.position[i])
        return kin, pot

    def contacts(self) -> dict[str, np.ndarray]:
        """The active contacts at the end of the last dynamic step (arrays over K contacts):
        ``pairs`` (K, 2) body indices (rows of :attr:`positions`; N + k is wall k of
        :attr:`wall_names`), ``ids`` (K, 2) particle ids (0 for a wall), ``point`` (K, 3)
        force application points (m), ``normal`` (K, 3) unit, from the first body towards the
        second, ``depth`` (K,) penetration (m), ``force_normal``, ``force_tangential``, ``force``
        (K, 3) on the second body (N). Empty before any dynamic step and after a Replicate or
        MoveWall ToContact step (until the next dynamic step)."""
        s = self.solver
        c = s.end_contacts if s is not None else None
        if c is None or c["step"] != s.step_index - 1:
            z3 = np.zeros((0, 3))
            c = dict(body_a=np.zeros(0, np.int64), body_b=np.zeros(0, np.int64), point=z3,
                     normal=z3, depth=np.zeros(0), force_normal=z3, force_tangential=z3)
        pairs = np.stack([c["body_a"], c["body_b"]], axis=1).reshape(-1, 2)
        ids_all = np.concatenate([self.bodies.id,
                                  np.zeros(len(self.model.wall_names), np.int64)])
        return dict(pairs=pairs, ids=ids_all[pairs] if len(pairs) else pairs.copy(),
                    point=c["point"].copy(), normal=c["normal"].copy(), depth=c["depth"].copy(),
                    force_normal=c["force_normal"].copy(),
                    force_tangential=c["force_tangential"].copy(),
                    force=c["force_normal"] + c["force_tangential"])

    # ------------------------------------------------------------------ the deck
    @property
    def deck_text(self) -> str:
        """The deck of this scene and of the steps run so far (what ``results.h5`` and the
        checkpoint store). Shapes given as Python objects that are not exact generator
        spheres appear as ``File "<python object ...>"`` with a hash of their geometry."""
        from .dynamics.laws.interface import interface_text
        m = self.model
        if self._from_deck:
            return m.text
        out = ["# scene built in Python (nurbsdem.Simulation)", "Environment",
               f"  Gravity {_v(m.gravity)}", "Materials"]
        for k, mat in sorted(m.materials.items()):
            E = getattr(mat, "young_modulus", None)
            out.append(f"  Material {k} Density {_f(mat.density)}" + (
                f" YoungModulus {_f(E)} PoissonRatio {_f(mat.poisson_ratio)}" if E is not None
                else ""))
        out.append("Shapes")
        for sid, e in sorted(m.shapes.items()):
            if e.kind == "sphere":
                out.append(f"  Shape {sid} Sphere Radius {_f(e.params[0])}")
            elif e.kind == "file":
                out.append(f'  Shape {sid} File "{e.file}"')
            else:
                if sid not in self._geometry_hash:
                    self._geometry_hash[sid] = _geometry_hash(e.shape)
                label = "".join(c for c in str(e.shape.name or "shape") if c not in '"#\n')
                out.append(f'  Shape {sid} File "<python object {label}>"  # geometry '
                           f'sha256 {self._geometry_hash[sid]}')
        out.append("Particles")
        for p in m.particles:
            out.append(f"  Particle {p.id} Shape {p.shape_id} Material {p.material_id} Position "
                       f"{_v(p.position)} Rotation {_v(p.rotation)} Velocity {_v(p.velocity)} "
                       f"AngularVelocity {_v(p.angular_velocity)}")
        out.append("Walls")
        boxes = {b[0]: b for b in self._boxes}
        args = self._wall_args
        for w in m.walls:
            if w.id in boxes:
                bid, lo, hi, top, wmat = boxes[w.id]
                mat = f" Material {wmat}" if wmat is not None else ""
                out.append(f"  Box {bid} Min {_v(lo)} Max {_v(hi)} Top {'yes' if top else 'no'}"
                           f"{mat}")
            elif w.kind == "wall":
                p, n, size, ax = args[w.name]
                axis = f" Axis {_v(ax)}" if ax is not None else ""
                mat = (f" Material {w.material_id}"
                       if getattr(w, "material_id", None) is not None else "")
                out.append(f"  Wall {w.id} Name {w.name} Point {_v(p)} Normal {_v(n)} "
                           f"Size {_v(size)}{axis}{mat}")
        out += [_curved_line(w) for w in m.curved_walls]
        out.append("Contact")
        for i in m.interfaces:
            line = "  " + interface_text(i, _f)
            if i.materials:
                line += " Materials " + " ".join(map(str, i.materials))
            elif i.between:
                line += f" Between {i.between}"
            out.append(line)
        out.append("Steps")
        for s in m.steps:
            out.append(_step_line(s))
        o = m.output
        out.append("Output")
        if self._output_dir is not None and o is not None:
            out.append(f'  Directory "{Path(o.directory).resolve()}"')
            out.append(f"  VTK Every {_f(o.vtk_every)} Resolution {o.vtk_resolution}")
            out.append(f"  Monitors Every {_f(o.monitors_every)}")
            if o.results_every is not None:
                out.append(f"  Results Every {_f(o.results_every)}")
            out.append(f"  Checkpoint Every {_f(o.checkpoint_every)}")
        return "\n".join(out) + "\n"

    def write_deck(self, path: str | Path) -> Path:
        """Write :attr:`deck_text` (``nurbsdem solve`` runs it when every shape is a file or
        a generator sphere)."""
        from .io.atomic import atomic_write_text
        atomic_write_text(path, self.deck_text)
        return Path(path)


# ---------------------------------------------------------------------------- helpers


def _step_line(s: Step) -> str:
    damping = " Damping Implicit" if getattr(s, "damping", "explicit") == "implicit" else ""
    if getattr(s, "accuracy", None) is not None:
        damping += f" Accuracy {_f(s.accuracy)}"
    if getattr(s, "safety", None) is not None:
        damping += f" Safety {_f(s.safety)}"
    if isinstance(s, DynamicStep):
        return (f"  Step {s.id} Dynamic Duration {_f(s.duration)} TimeStep {_f(s.time_step)}"
                f"{damping}")
    if isinstance(s, ReplicateStep):
        return f"  Step {s.id} Replicate Layers {s.layers} Height {_f(s.height)}"
    assert isinstance(s, MoveWallStep)
    if s.to_contact:
        d = f" Direction {_v(s.direction)}" if s.direction is not None else ""
        return f"  Step {s.id} MoveWall {s.wall} ToContact Gap {_f(s.gap)}{d}"
    if s.rotate:
        return (f"  Step {s.id} MoveWall {s.wall} Rotate AngularVelocity "
                f"{_v(s.angular_velocity)} Center {_v(s.center)} Duration {_f(s.duration)} "
                f"TimeStep {_f(s.time_step)}{damping}")
    return (f"  Step {s.id} MoveWall {s.wall} Displacement {_v(s.displacement)} Duration "
            f"{_f(s.duration)} TimeStep {_f(s.time_step)}{damping}")


def _split_deck(text: str) -> tuple[list[str], list[str]]:
    """(scene lines, step lines) of a generated deck (Output block left out)."""
    lines = text.splitlines()
    try:
        a = lines.index("Steps")
    except ValueError:
        return lines, []
    b = lines.index("Output", a) if "Output" in lines[a:] else len(lines)
    return lines[:a], lines[a + 1:b]


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


def _rotvec_of_matrix(R: np.ndarray, what: str) -> np.ndarray:
    if not np.isfinite(R).all() or not np.allclose(R @ R.T, np.eye(3), atol=1e-9) \
            or not np.linalg.det(R) > 0:
        raise InputError(f"{what}: rotation must be a rotation vector (3,) or a proper "
                         f"rotation matrix (3, 3)")
    from scipy.spatial.transform import Rotation
    return Rotation.from_matrix(R).as_rotvec()


__all__ = ["Simulation"]

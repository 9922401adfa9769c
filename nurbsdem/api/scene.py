"""The entries of a scene built in Python (:class:`~nurbsdem.simulation.Simulation`'s
``add_*`` methods): each one checked by the deck's rules, with the deck's messages, and added
to the :class:`~nurbsdem.model.Model` as the deck adds it."""
from __future__ import annotations

import logging
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from ..errors import InputError
from ..model import CurvedWallSpec, Material, Model, ParticleSpec, ShapeEntry, WallSpec
from .checks import entity_id, in_range, number, rotvec_of_matrix, vector


class SceneBuilder:
    """Adds materials, interfaces, particles and walls to ``model``.

    sphere_radius: r when a Shape object is exactly ``nurbsdem.shapes.sphere(r)`` (the deck
    writes it as ``Sphere Radius r``), else None. The builder keeps what the deck of the
    scene needs besides the model: the shape id of each shape given (``shape_ids``), the
    boxes as given (``boxes``: first wall id, min, max, top, material) and the arguments of
    each flat wall (``wall_args``: point, normal, size, axis by name).
    """

    def __init__(self, model: Model, sphere_radius: Callable[[Any], float | None]) -> None:
        self.model = model
        self.sphere_radius = sphere_radius
        self.shape_ids: dict[Any, int] = {}
        self.boxes: list[tuple[int, np.ndarray, np.ndarray, bool, int | None]] = []
        self.wall_args: dict[str, tuple] = {}

    # ------------------------------------------------------------------ materials, laws
    def add_material(self, id: int, density: float, young_modulus: float | None,
                     poisson_ratio: float) -> int:
        """``Material``; returns the id."""
        mid = entity_id(id, "add_material")
        if mid in self.model.materials:
            raise InputError(f"add_material: material {mid} is already defined")
        what = f"material {mid}"
        rho = number("Density", density, what, positive=True)
        E = (number("YoungModulus", young_modulus, what, positive=True)
             if young_modulus is not None else None)
        nu = number("PoissonRatio", poisson_ratio, what)
        if not -1.0 < nu < 0.5:
            raise InputError(f"{what}: PoissonRatio must lie in (-1, 0.5), got {nu:g}")
        self.model.materials[mid] = Material(mid, rho, 0, E, nu)
        return mid

    def add_interface(self, given: dict[str, Any], between: str | None,
                      materials: Sequence[int] | None, id: int | None, model: str) -> int:
        """``Interface`` of the law ``model`` with the keys ``given`` by their Python names
        (None: not given); returns the id."""
        from ..dynamics.laws import LAWS
        from ..dynamics.laws.interface import Front, build_interface, python_name
        used = {i.id for i in self.model.interfaces}
        iid = entity_id(id, "add_interface") if id is not None else max(used, default=0) + 1
        if iid in used:
            raise InputError(f"add_interface: interface {iid} is already defined")
        what = f"interface {iid}"
        deck_key = {python_name(k.deck): k.deck for law in LAWS.values() for k in law.keys}
        values = {}
        for name, value in given.items():
            if value is None:
                continue
            if name not in deck_key:
                raise InputError(f"{what}: unknown key {name!r}")
            values[deck_key[name]] = number(python_name(deck_key[name]), value, what)
            in_range(deck_key[name], values[deck_key[name]], what)

        def fail(message: str):
            raise InputError(message)
        mats = None
        if materials is not None:
            mats = tuple(entity_id(m, f"{what}: materials") for m in np.ravel(materials).tolist())
        self.model.interfaces.append(build_interface(
            iid, str(model), values, between, mats, Front(what, python_name, fail),
            known_materials=self.model.materials))
        return iid

    # ------------------------------------------------------------------ shapes, particles
    def shape_id(self, shape: Any) -> int:
        """The shape id of a Shape object or a shape file (added on first use)."""
        from ..geometry.shape import Shape
        if isinstance(shape, (str, Path)):
            file = Path(shape).expanduser().resolve()
            key: Any = ("file", str(file))
        elif isinstance(shape, Shape):
            key = ("object", id(shape))
        else:
            raise InputError(f"add_particle: shape must be a Shape (e.g. nurbsdem.shapes."
                             f"sphere(r)) or a shape file path, got {type(shape).__name__}")
        if key in self.shape_ids:
            return self.shape_ids[key]
        sid = len(self.model.shapes) + 1
        if key[0] == "file":
            from ..io.shapefile import not_a_file
            why = not_a_file(file)
            if why is not None:
                raise InputError(f"add_particle: shape file {shape}: {why}")
            from ..io.shapefile import load_shape
            entry = ShapeEntry(sid, "file", load_shape(file), source=str(file), file=file)
        else:
            src = getattr(shape, "source", None)     # load_shape(path) remembers its file
            r = self.sphere_radius(shape) if src is None else None
            if src is not None and Path(src).is_file():
                file = Path(src).resolve()
                entry = ShapeEntry(sid, "file", shape, source=str(file), file=file)
            elif r is not None:
                entry = ShapeEntry(sid, "sphere", shape, params=(r,))
            else:
                entry = ShapeEntry(sid, "object", shape)
        self.model.shapes[sid] = entry
        self.shape_ids[key] = sid
        return sid

    def add_particle(self, shape: Any, material: int, position: Sequence[float],
                     rotation: Sequence[float] | None, velocity: Sequence[float] | None,
                     angular_velocity: Sequence[float] | None) -> int:
        """``Particle``; returns the particle id (1, 2, ... in the order of the calls)."""
        pid = len(self.model.particles) + 1
        what = f"particle {pid}"
        mid = entity_id(material, f"{what}: material")
        if mid not in self.model.materials:
            known = ", ".join(map(str, sorted(self.model.materials))) or "none"
            raise InputError(f"{what}: unknown material {mid} (defined: {known}; "
                             f"add_material first)")
        pos = vector("Position", position, what)
        z = np.zeros(3)
        if rotation is not None and np.shape(rotation) == (3, 3):
            rot = rotvec_of_matrix(np.asarray(rotation, float), what)
        else:
            rot = vector("Rotation", rotation, what) if rotation is not None else z.copy()
        vel = vector("Velocity", velocity, what) if velocity is not None else z.copy()
        omg = (vector("AngularVelocity", angular_velocity, what)
               if angular_velocity is not None else z.copy())
        sid = self.shape_id(shape)
        # line: the id, so that messages name the later of two particles first, as for a deck
        self.model.particles.append(ParticleSpec(pid, sid, mid, pos, rotation=rot, velocity=vel,
                                                 angular_velocity=omg, line=pid))
        return pid

    # ------------------------------------------------------------------ walls
    def _next_wall_id(self) -> int:
        return max((w.id for w in self.model.walls + self.model.curved_walls), default=0) + 1

    def _add_wall_spec(self, w: WallSpec, what: str) -> None:
        if w.name in self.model.wall_names:
            raise InputError(f"{what}: a wall named {w.name!r} exists already")
        self.model.walls.append(w)

    def _wall_material(self, material: int | None, what: str) -> int | None:
        if material is None:
            return None
        mid = entity_id(material, f"{what}: material")
        if mid not in self.model.materials:
            raise InputError(f"{what}: unknown material {mid} (add_material first)")
        return mid

    def add_box(self, min: Sequence[float], max: Sequence[float], top: bool,
                material: int | None) -> list[str]:
        """``Box``; returns the names of its walls."""
        from ..geometry.generators import box_walls
        wmat = self._wall_material(material, "add_box")
        lo = vector("Min", min, "add_box")
        hi = vector("Max", max, "add_box")
        if np.any(hi <= lo):
            raise InputError("add_box: max must exceed min in x, y and z")
        bid = self._next_wall_id()
        names = []
        for k, (name, patch) in enumerate(box_walls(lo, hi, top=bool(top)).items()):
            self._add_wall_spec(WallSpec(bid + k, name, patch, kind="box", material_id=wmat),
                                "add_box")
            names.append(name)
        self.boxes.append((bid, lo, hi, bool(top), wmat))
        return names

    def add_wall(self, name: str, point: Sequence[float], normal: Sequence[float],
                 size: Sequence[float], axis: Sequence[float] | None,
                 material: int | None) -> str:
        """``Wall``: a flat rectangle; returns the name."""
        from ..geometry.generators import flat_wall
        from ..io.deck import SCHEMA
        from ..io.wallname import wall_name_problem
        problem = wall_name_problem(name, SCHEMA)
        if problem is not None:        # the deck's rule (Wall ... Name), the same message
            raise InputError(f"add_wall: {problem}")
        what = f"wall {name!r}"
        wmat = self._wall_material(material, what)
        p = vector("Point", point, what)
        n = vector("Normal", normal, what)
        if not np.linalg.norm(n) > 0:
            raise InputError(f"{what}: normal must not be zero")
        size = vector("Size", size, what, n=2)
        if np.any(size <= 0):
            raise InputError(f"{what}: size must be > 0")
        ax = None
        if axis is not None:
            ax = vector("Axis", axis, what)
            t = ax - n * (ax @ n) / (n @ n)
            if np.linalg.norm(t) < 1e-12 * np.linalg.norm(ax) or not np.linalg.norm(ax) > 0:
                raise InputError(f"{what}: axis must not be parallel to the normal (or zero)")
        self._add_wall_spec(WallSpec(self._next_wall_id(), name, flat_wall(p, n, size, ax),
                                     kind="wall", material_id=wmat), "add_wall")
        self.wall_args[name] = (p, n, size, ax)
        return name

    def add_curved_wall(self, kind: str, name: str, file: Any, scale: Any, position: Any,
                        rotation: Any, material: int | None, one_sided: bool) -> str:
        """``Mesh`` (``kind`` "mesh") or ``Surface`` ("surface"): a wall read from ``file``,
        its file read and checked now (its warnings logged); returns the name."""
        from ..io.deck import SCHEMA
        from ..io.deck_curved import _read_check
        from ..io.wallname import wall_name_problem
        what = f"add_{kind}_wall"
        problem = wall_name_problem(name, SCHEMA)
        if problem is not None:
            raise InputError(f"{what}: {problem}")
        if name in self.model.wall_names:
            raise InputError(f"{what}: a wall named {name!r} exists already")
        if not (np.isfinite(scale) and scale > 0):
            raise InputError(f"{what}: scale must be positive, got {scale!r}")
        in_range("Scale", float(scale), what)
        spec = CurvedWallSpec(self._next_wall_id(), name, kind, str(Path(file).resolve()),
                              path=Path(file).resolve(), scale=float(scale),
                              position=vector("Position", position, what),
                              rotation=vector("Rotation", rotation, what),
                              material_id=self._wall_material(material, what),
                              one_sided=bool(one_sided), line=None)
        for warning in _read_check(spec, f"{what} {name!r}"):
            logging.getLogger("nurbsdem").warning("%s", warning)
        self.model.curved_walls.append(spec)
        return name

"""Deck entries to a :class:`~nurbsdem.model.Model`: :func:`build_entries` checks each entry's
values and the cross-references between entries (shapes, materials, wall names), and raises
:class:`~nurbsdem.io.deck_schema.LineError` at the line of the first mistake.

The entries come from :func:`nurbsdem.io.deck.lex_deck`; the ``Mesh`` and ``Surface`` walls and
the ``Rotate`` steps are built by :mod:`nurbsdem.io.deck_curved`.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..errors import InputError
from ..model import (DAMPING_SCHEMES, DynamicStep, Material, Model, MoveWallStep, Output,
                     ParticleSpec, PeriodicSpec, RandomGroup, ReplicateStep, ShapeEntry, Step, WallSpec)
from ..ranges import ASPECT_MAX
from .deck_curved import CURVED_WALL_FILES, check_curved_walls, curved_entry, rotate_step
from .deck_moves import (MODES, add_wall_move, check_moves, force_step, table_step,
                         unit_direction)
from .deck_flow import check_inlet, check_outlet, inlet_spec, outlet_spec
from .deck_schema import SCHEMA, Entry, LineError


class DeckBuilder:
    """Turns entries into a :class:`Model`, checking values and cross-references."""

    def __init__(self, path: str, text: str) -> None:
        self.model = Model(path=path, text=text)
        self.base = Path(path).resolve().parent
        self._shape_cache: dict[Path, Any] = {}
        self._settings: dict[str, int] = {}
        self._wall_ids: dict[int, int] = {}
        self._particle_ids: list[tuple[int, int, str, int]] = []  # (first, last, label, line)

    # -- helpers ---------------------------------------------------------------
    def fail(self, msg: str, line: int | None) -> None:
        raise LineError(msg, line)

    def require(self, e: Entry, *keys: str) -> None:
        for k in keys:
            if not e.has(k):
                self.fail(f"{e.keyword} {e.id}: missing {k}" if e.id is not None
                          else f"{e.keyword}: missing {k}", e.line)

    def positive(self, e: Entry, key: str, value: float, strict: bool = True) -> float:
        if (strict and not value > 0) or (not strict and value < 0):
            self.fail(f"{self.label(e)}: {key} must be {'> 0' if strict else '>= 0'}, "
                      f"got {value:g}", e.line)
        return value

    @staticmethod
    def label(e: Entry) -> str:
        return f"{e.keyword} {e.id}" if e.id is not None else e.keyword

    def only(self, e: Entry, allowed: set[str], what: str) -> None:
        for k in e.values:
            if k not in allowed:
                self.fail(f"{self.label(e)}: {k} does not apply to {what}", e.line)

    def unique(self, table: dict, e: Entry, what: str) -> None:
        if e.id in table:
            prev = table[e.id]
            prev_line = prev if isinstance(prev, int) else prev.line
            self.fail(f"duplicate {what} id {e.id} (first at line {prev_line})", e.line)

    # -- blocks ----------------------------------------------------------------
    def setting_once(self, e: Entry) -> None:
        key = f"{e.block}.{e.keyword}"
        if key in self._settings:
            self.fail(f"{e.keyword} given twice (first at line {self._settings[key]})", e.line)
        self._settings[key] = e.line

    def environment(self, e: Entry) -> None:
        self.setting_once(e)
        self.model.gravity = np.asarray(e.head, float)

    def periodic(self, e: Entry) -> None:
        """``Periodic [X lo hi] [Y lo hi] [Z lo hi]``: the periodic cell (lo < hi, m)."""
        self.setting_once(e)
        lo, hi, axes = np.zeros(3), np.zeros(3), np.zeros(3, bool)
        for k, name in enumerate("XYZ"):
            if e.has(name):
                lo[k], hi[k] = e.get(name)
                axes[k] = True
                if not lo[k] < hi[k]:
                    self.fail(f"Periodic: {name} needs lo < hi, got {lo[k]:g} {hi[k]:g}", e.line)
        if not axes.any():
            self.fail("Periodic: give at least one axis (X lo hi, Y lo hi or Z lo hi)", e.line)
        self.model.periodic = PeriodicSpec(lo, hi, axes, e.line)

    def material(self, e: Entry) -> None:
        self.unique(self.model.materials, e, "material")
        self.require(e, "Density")
        rho = self.positive(e, "Density", e.get("Density"))
        E = e.get("YoungModulus")
        if E is not None:
            self.positive(e, "YoungModulus", E)
        nu = e.get("PoissonRatio", 0.0)
        if not -1.0 < nu < 0.5:
            self.fail(f"{self.label(e)}: PoissonRatio must lie in (-1, 0.5), got {nu:g}", e.line)
        self.model.materials[e.id] = Material(e.id, rho, e.line, E, float(nu))

    def shape(self, e: Entry) -> None:
        self.unique(self.model.shapes, e, "shape")
        kinds = [k for k in ("File", "Sphere", "Ellipsoid") if e.has(k)]
        if len(kinds) != 1:
            self.fail(f"Shape {e.id}: give exactly one of File, Sphere, Ellipsoid"
                      + (f" (got {' and '.join(kinds)})" if kinds else ""), e.line)
        kind = kinds[0]
        common = {"Volume", "Inertia"}
        from ..geometry import generators as gen
        from ..geometry.shape import Shape
        if kind == "File":
            self.only(e, common | {"File", "ConvexityTolerance"}, "a File shape")
            source = e.get("File")
            file = (self.base / source) if not Path(source).is_absolute() else Path(source)
            tol = e.get("ConvexityTolerance") if e.has("ConvexityTolerance") else None
            if tol is not None and not tol >= 0:
                self.fail(f"Shape {e.id}: ConvexityTolerance must be >= 0 (a fraction of the "
                          f"particle size), got {tol:g}", e.line)
            shape = self.load_shape_file(file, source, e.line, tol)
            entry = ShapeEntry(e.id, "file", shape, source=source, file=file, line=e.line)
        elif kind == "Sphere":
            self.only(e, common | {"Sphere", "Radius"}, "a Sphere shape")
            self.require(e, "Radius")
            r = self.positive(e, "Radius", e.get("Radius"))
            shape = self.generated(e, lambda: Shape(gen.sphere_patches(r), name=f"sphere r={r:g}"))
            entry = ShapeEntry(e.id, "sphere", shape, params=(r,), line=e.line)
        else:
            self.only(e, common | {"Ellipsoid", "SemiAxes"}, "an Ellipsoid shape")
            self.require(e, "SemiAxes")
            abc = e.get("SemiAxes")
            if np.any(abc <= 0):
                self.fail(f"Shape {e.id}: SemiAxes must be > 0", e.line)
            if abc.max() > ASPECT_MAX * abc.min():
                self.fail(f"Shape {e.id}: SemiAxes {abc.max() / abc.min():.3g} times longer than "
                          f"wide is beyond the {ASPECT_MAX:g} the contact search resolves", e.line)
            shape = self.generated(e, lambda: Shape(
                gen.ellipsoid_patches(*abc), name=f"ellipsoid {abc[0]:g}x{abc[1]:g}x{abc[2]:g}"))
            entry = ShapeEntry(e.id, "ellipsoid", shape, params=tuple(map(float, abc)),
                               line=e.line)
        if e.has("Volume"):
            entry.volume_override = self.positive(e, "Volume", e.get("Volume"))
        if e.has("Inertia"):
            entry.inertia_override = self.inertia_matrix(e, e.get("Inertia"))
        self.model.shapes[e.id] = entry

    def generated(self, e: Entry, make: Callable[[], Any]) -> Any:
        """A shape generated from the deck's numbers; its errors carry this entry's line."""
        try:
            return make()
        except (InputError, ValueError, ArithmeticError) as exc:
            detail = getattr(exc, "detail", None) or str(exc)
            self.fail(f"Shape {e.id}: {detail}", e.line)

    def load_shape_file(self, file: Path, source: str, line: int,
                        convexity_tol: float | None = None):
        from .shapefile import load_shape
        key = (file.resolve(), convexity_tol)
        if key in self._shape_cache:
            return self._shape_cache[key]
        from .shapefile import not_a_file
        why = not_a_file(file)
        if why is not None:
            self.fail(f"shape file {source}: {why}", line)
        try:
            shape = load_shape(file, convexity_tol=convexity_tol)
        except InputError as exc:
            loc = f"shape file {source}"
            if exc.line is not None:
                loc += f":{exc.line}"
            if exc.where:
                loc += f": {exc.where}"
            self.fail(f"{loc}: {exc.detail}", line)
        self._shape_cache[key] = shape
        return shape

    def inertia_matrix(self, e: Entry, j: np.ndarray) -> np.ndarray:
        jxx, jyy, jzz, jxy, jxz, jyz = j
        J = np.array([[jxx, jxy, jxz], [jxy, jyy, jyz], [jxz, jyz, jzz]])
        eig = np.linalg.eigvalsh(J)
        if eig.min() <= 0:
            self.fail(f"Shape {e.id}: Inertia is not positive definite "
                      f"(principal moments {', '.join(f'{x:.4g}' for x in eig)})", e.line)
        if eig[0] + eig[1] < eig[2] * (1 - 1e-9):
            self.fail(f"Shape {e.id}: Inertia violates the triangle inequality of a rigid "
                      f"body's principal moments", e.line)
        return J

    def claim_particle_ids(self, first: int, last: int, label: str, line: int) -> None:
        for a, b, other, oline in self._particle_ids:
            if first <= b and a <= last:
                clash = max(first, a)
                self.fail(f"{label}: particle id {clash} already used by {other} "
                          f"(line {oline})", line)
        self._particle_ids.append((first, last, label, line))

    def random(self, e: Entry) -> None:
        self.require(e, "Shapes", "Counts", "Material", "Region")
        shapes, counts = e.get("Shapes"), e.get("Counts")
        if len(shapes) != len(counts):
            self.fail(f"Random {e.id}: Shapes lists {len(shapes)} shapes but Counts "
                      f"{len(counts)} numbers", e.line)
        if any(c < 0 for c in counts) or sum(counts) == 0:
            self.fail(f"Random {e.id}: Counts must be >= 0 with at least one particle", e.line)
        reg = e.get("Region")
        lo, hi = reg[:3], reg[3:]
        if np.any(hi <= lo):
            self.fail(f"Random {e.id}: Region must be x0 y0 z0 x1 y1 z1 with x1 > x0, "
                      f"y1 > y0, z1 > z0", e.line)
        attempts = e.get("MaxAttempts", 20000)
        if attempts < 1:
            self.fail(f"Random {e.id}: MaxAttempts must be >= 1", e.line)
        g = RandomGroup(e.id, tuple(shapes), tuple(counts), e.get("Material"), lo.copy(),
                        hi.copy(), seed=e.get("Seed", 0), max_attempts=attempts, line=e.line)
        if g.seed < 0:
            self.fail(f"Random {e.id}: Seed must be >= 0", e.line)
        self.claim_particle_ids(g.id, g.id + g.total - 1, f"Random {e.id}", e.line)
        self.model.random_groups.append(g)

    def particle(self, e: Entry) -> None:
        self.require(e, "Shape", "Material", "Position")
        self.claim_particle_ids(e.id, e.id, f"Particle {e.id}", e.line)
        z = np.zeros(3)
        self.model.particles.append(ParticleSpec(
            e.id, e.get("Shape"), e.get("Material"), e.get("Position"),
            rotation=e.get("Rotation", z.copy()), velocity=e.get("Velocity", z.copy()),
            angular_velocity=e.get("AngularVelocity", z.copy()), line=e.line))

    def claim_wall_id(self, wid: int, label: str, line: int) -> None:
        if wid in self._wall_ids:
            self.fail(f"{label}: wall id {wid} already used (line {self._wall_ids[wid]})", line)
        self._wall_ids[wid] = line

    def add_wall(self, w: WallSpec, label: str) -> None:
        from .wallname import wall_name_problem
        problem = wall_name_problem(w.name, SCHEMA)
        if problem is not None:
            self.fail(f"{label}: {problem}", w.line)
        for other in self.model.walls + self.model.curved_walls:
            if other.name == w.name:
                self.fail(f"{label}: duplicate wall name {w.name!r} (first at line "
                          f"{other.line})", w.line)
        self.claim_wall_id(w.id, label, w.line)
        if isinstance(w, WallSpec):
            self.model.walls.append(w)
        else:
            self.model.curved_walls.append(w)

    def add_curved_wall(self, w, label: str) -> None:
        """A Mesh or Surface wall (:mod:`nurbsdem.io.deck_curved`), with the flat walls'
        name and id rules."""
        self.add_wall(w, label)

    def box(self, e: Entry) -> None:
        from ..geometry.generators import box_walls
        self.require(e, "Min", "Max")
        lo, hi = e.get("Min"), e.get("Max")
        if np.any(hi <= lo):
            self.fail(f"Box {e.id}: Max must exceed Min in x, y and z", e.line)
        for k, (name, patch) in enumerate(box_walls(lo, hi, top=e.get("Top", False)).items()):
            self.add_wall(WallSpec(e.id + k, name, patch, kind="box", line=e.line,
                                   material_id=e.get("Material")), f"Box {e.id}")

    def wall(self, e: Entry) -> None:
        from ..geometry.generators import flat_wall
        self.require(e, "Point", "Normal", "Size")
        n = e.get("Normal")
        if not np.linalg.norm(n) > 0:
            self.fail(f"Wall {e.id}: Normal must not be zero", e.line)
        size = e.get("Size")
        if np.any(size <= 0):
            self.fail(f"Wall {e.id}: Size must be > 0", e.line)
        axis = e.get("Axis")
        if axis is not None:
            t = axis - n * (axis @ n) / (n @ n)
            if np.linalg.norm(t) < 1e-12 * max(1.0, np.linalg.norm(axis)):
                self.fail(f"Wall {e.id}: Axis must not be parallel to Normal", e.line)
        patch = flat_wall(e.get("Point"), n, size, axis)
        name = e.get("Name", f"wall{e.id}")
        self.add_wall(WallSpec(e.id, name, patch, kind="wall", line=e.line,
                               material_id=e.get("Material")), f"Wall {e.id}")

    def interface(self, e: Entry) -> None:
        """``Interface``: the one front-end of the laws
        (:func:`~nurbsdem.dynamics.laws.interface.build_interface`), deck spelling, file:line."""
        from ..dynamics.laws.interface import COMMON_KEYS, Front, build_interface
        self.unique({i.id: i for i in self.model.interfaces}, e, "interface")
        front = Front(f"Interface {e.id}", str, lambda msg: self.fail(msg, e.line))
        values = {k: v for k, v in e.values.items() if k not in COMMON_KEYS}
        self.model.interfaces.append(build_interface(
            e.id, e.get("Model"), values, e.get("Between"), e.get("Materials"), front,
            line=e.line))

    def step(self, e: Entry) -> None:
        steps = self.model.steps
        if steps and e.id == steps[-1].id and isinstance(steps[-1], MoveWallStep):
            add_wall_move(self, e, steps[-1])       # one more wall moving in the same step
            return
        self.unique({s.id: s for s in steps}, e, "step")
        if steps and e.id < steps[-1].id:
            self.fail(f"step ids must increase (Step {e.id} after Step {steps[-1].id})", e.line)
        types = [k for k in ("Dynamic", "Replicate", "MoveWall") if e.has(k)]
        if len(types) != 1:
            self.fail(f"Step {e.id}: give exactly one of Dynamic, Replicate, MoveWall"
                      + (f" (got {' and '.join(types)})" if types else ""), e.line)
        kind = types[0]
        if kind == "Dynamic":
            self.only(e, {"Dynamic", "Duration", "TimeStep", "Damping", "Accuracy",
                          "Safety"}, "a Dynamic step")
            self.require(e, "Duration", "TimeStep")
            step: Step = DynamicStep(e.id, e.line, *self.timing(e), damping=self.damping(e),
                                     accuracy=self.optional_positive(e, "Accuracy"),
                                     safety=self.optional_positive(e, "Safety"))
        elif kind == "Replicate":
            self.only(e, {"Replicate", "Layers", "Height"}, "a Replicate step")
            self.require(e, "Layers", "Height")
            if e.get("Layers") < 1:
                self.fail(f"Step {e.id}: Layers must be >= 1, got {e.get('Layers')}", e.line)
            step = ReplicateStep(e.id, e.line, e.get("Layers"),
                                 self.positive(e, "Height", e.get("Height")))
        else:
            step = self.move_wall(e)
        steps.append(step)

    def timing(self, e: Entry) -> tuple[float, float]:
        dur = self.positive(e, "Duration", e.get("Duration"))
        dt = self.positive(e, "TimeStep", e.get("TimeStep"))
        if dt > dur:
            self.fail(f"Step {e.id}: TimeStep {dt:g} s exceeds Duration {dur:g} s", e.line)
        return dur, dt

    def move_wall(self, e: Entry) -> MoveWallStep:
        modes = [k for k in MODES if e.has(k)]
        if e.has("Rotate") and modes == ["Displacement", "Rotate"]:
            modes = ["Rotate"]                       # a turn with a translation
        if len(modes) != 1:
            self.fail(f"Step {e.id}: MoveWall needs exactly one of ToContact, Displacement, "
                      f"Rotate, Table, Force (Rotate may take a Displacement)", e.line)
        name = e.get("MoveWall")
        if modes[0] == "Force":
            return force_step(self, e, name)
        if modes[0] == "Rotate":
            return rotate_step(self, e, name)
        if modes[0] == "Table":
            return table_step(self, e, name)
        if modes[0] == "ToContact":
            self.only(e, {"MoveWall", "ToContact", "Gap", "Direction"}, "MoveWall ToContact")
            gap = self.positive(e, "Gap", e.get("Gap", 0.0), strict=False)
            return MoveWallStep(e.id, e.line, wall=name, to_contact=True, gap=gap,
                                direction=unit_direction(self, e))
        self.only(e, {"MoveWall", "Displacement", "Duration", "TimeStep", "Damping",
                      "Accuracy", "Safety"}, "MoveWall Displacement")
        self.require(e, "Duration", "TimeStep")
        dur, dt = self.timing(e)
        return MoveWallStep(e.id, e.line, wall=name, displacement=e.get("Displacement"),
                            duration=dur, time_step=dt, damping=self.damping(e),
                            accuracy=self.optional_positive(e, "Accuracy"),
                            safety=self.optional_positive(e, "Safety"))

    def damping(self, e: Entry) -> str:
        """The step's ``Damping`` scheme (lower case; default explicit)."""
        value = e.get("Damping", "explicit")
        if value.lower() not in DAMPING_SCHEMES:
            self.fail(f"Step {e.id}: Damping must be Explicit or Implicit, got {value!r}",
                      e.line)
        return value.lower()

    def optional_positive(self, e: Entry, key: str) -> float | None:
        """A step's optional positive number: ``Accuracy`` η (:mod:`nurbsdem.dynamics.accuracy`;
        None: off) or ``Safety`` f, the fraction of the contact network's stability limit the
        sub-step takes (:mod:`nurbsdem.dynamics.stepcontrol`; None: the solver's, 0.5)."""
        value = e.get(key)
        return None if value is None else self.positive(e, key, value)

    def output(self, entries: list[Entry]) -> None:
        out = Output(directory=self.base / "results")
        for e in entries:
            self.setting_once(e)
            if e.keyword == "Directory":
                d = Path(e.head)
                out.directory = d if d.is_absolute() else self.base / d
            elif e.keyword == "VTK":
                if e.has("Every"):
                    out.vtk_every = self.positive(e, "Every", e.get("Every"))
                if e.has("Resolution"):
                    res = e.get("Resolution")
                    if res < 1:
                        self.fail(f"VTK: Resolution must be >= 1, got {res}", e.line)
                    out.vtk_resolution = res
            elif e.has("Every"):
                val = self.positive(e, "Every", e.get("Every"))
                attr = {"Monitors": "monitors_every", "Results": "results_every",
                        "Checkpoint": "checkpoint_every"}[e.keyword]
                setattr(out, attr, val)
        self.model.output = out

    def flow(self, e: Entry) -> None:
        """``Inlet`` or ``Outlet`` (:mod:`nurbsdem.io.deck_flow`)."""
        inlet = e.keyword == "Inlet"
        specs = self.model.inlets if inlet else self.model.outlets
        self.unique({s.id: s for s in specs}, e, e.keyword.lower())
        make = inlet_spec if inlet else outlet_spec
        specs.append(make(e.id, e.values, e.line, lambda msg: self.fail(msg, e.line)))

    # -- cross references ------------------------------------------------------
    def check_references(self) -> None:
        m = self.model
        for g in m.random_groups:
            for sid in g.shape_ids:
                if sid not in m.shapes:
                    self.fail(f"Random {g.id}: unknown shape {sid}{self.known(m.shapes, 'shapes')}", g.line)
            if g.material_id not in m.materials:
                self.fail(f"Random {g.id}: unknown material {g.material_id}"
                          f"{self.known(m.materials, 'materials')}", g.line)
        for p in m.particles:
            if p.shape_id not in m.shapes:
                self.fail(f"Particle {p.id}: unknown shape {p.shape_id}{self.known(m.shapes, 'shapes')}", p.line)
            if p.material_id not in m.materials:
                self.fail(f"Particle {p.id}: unknown material {p.material_id}"
                          f"{self.known(m.materials, 'materials')}", p.line)
        for itf in m.interfaces:
            for mid in itf.materials or ():
                if mid not in m.materials:
                    self.fail(f"Interface {itf.id}: unknown material {mid}", itf.line)
        check_moves(self, m)
        check_curved_walls(self, m)
        for inlet in m.inlets:
            check_inlet(m, inlet, lambda msg: self.fail(msg, inlet.line))
        for outlet in m.outlets:
            check_outlet(m, outlet, lambda msg: self.fail(msg, outlet.line))
        self.check_interfaces()

    @staticmethod
    def known(table: dict, what: str) -> str:
        return f" (defined {what}: {', '.join(map(str, sorted(table)))})" if table else f" (no {what} defined)"

    def check_interfaces(self) -> None:
        """Every pair is covered by an Interface, with the constants its law needs
        (:func:`~nurbsdem.dynamics.laws.interface.check_coverage`)."""
        from ..dynamics.laws.interface import check_coverage
        if not self.model.particle_materials():
            return
        check_coverage(self.model, self.fail, self.first_use)
        self.check_wall_materials()

    def check_wall_materials(self) -> None:
        """Box/Wall ``Material m``: defined, with a YoungModulus (a wall's material matters only
        to Hertz–Mindlin interfaces; walls without one are rigid)."""
        m = self.model
        named = [w for w in m.walls + m.curved_walls if w.material_id is not None]
        for w in named:
            if w.material_id not in m.materials:
                self.fail(f"wall {w.name}: unknown material {w.material_id}"
                          f"{self.known(m.materials, 'materials')}", w.line)
            if m.materials[w.material_id].young_modulus is None:
                self.fail(f"wall {w.name}: Material {w.material_id} needs a YoungModulus to be "
                          f"a wall material", w.line)

    def first_use(self, material: int) -> int:
        """Line of the first particle entry of that material."""
        lines = [g.line for g in self.model.random_groups if g.material_id == material]
        lines += [p.line for p in self.model.particles if p.material_id == material]
        lines += [i.line for i in self.model.inlets if i.material_id == material]
        return min(lines)


_HANDLERS: dict[tuple[str, str], Callable[[DeckBuilder, Entry], None]] = {
    ("Environment", "Gravity"): DeckBuilder.environment,
    ("Environment", "Periodic"): DeckBuilder.periodic,
    ("Materials", "Material"): DeckBuilder.material,
    ("Shapes", "Shape"): DeckBuilder.shape,
    ("Particles", "Random"): DeckBuilder.random,
    ("Particles", "Particle"): DeckBuilder.particle,
    ("Walls", "Box"): DeckBuilder.box,
    ("Walls", "Wall"): DeckBuilder.wall,
    ("Contact", "Interface"): DeckBuilder.interface,
    ("Steps", "Step"): DeckBuilder.step,
    ("Flow", "Inlet"): DeckBuilder.flow,
    ("Flow", "Outlet"): DeckBuilder.flow,
}
#: each curved wall kind's entry (``Mesh``, ``Surface``: :data:`.deck_curved.CURVED_WALL_FILES`)
_HANDLERS.update({("Walls", f.keyword): (lambda b, e, kind=f.name: curved_entry(b, e, kind))
                  for f in CURVED_WALL_FILES.values()})


#: the blocks in the order they are built: definitions before uses, whatever the deck's order
BUILD_ORDER = ("Environment", "Materials", "Shapes", "Particles", "Walls", "Contact", "Steps",
               "Flow")


def build_entries(entries: list[Entry], path: str, text: str) -> Model:
    """The model of a deck's entries (``path`` anchors relative paths, ``text`` is kept as
    ``Model.text``); raises :class:`LineError`."""
    b = DeckBuilder(path, text)
    for block in BUILD_ORDER:
        for e in entries:
            if e.block == block:
                _HANDLERS[(block, e.keyword)](b, e)
    b.output([e for e in entries if e.block == "Output"])
    b.check_references()
    return b.model

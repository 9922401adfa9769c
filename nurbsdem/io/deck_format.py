"""A model written back as deck text: :func:`format_model`.

``build_model(format_model(m), path)`` is ``m`` again for a model ``m`` read from a deck at
``path`` (the same folder: relative files resolve the same): every entry the model holds is
written, numbers by ``repr`` (the shortest text that reads back to the same float), in the
syntax of ``docs/deck-reference.md``.  Each line is an :class:`~nurbsdem.io.deck_schema.Entry`
written by :func:`format_entry`, which takes the number and kind of each key's values from
:data:`~nurbsdem.io.deck_schema.SCHEMA`.

A model keeps its flat walls as patches, not as the ``Box`` and ``Wall`` entries that made
them: :func:`flat_wall_entries` finds the entries that make exactly those patches again (the
shortest decimals first), and a caller that knows the entries (a scene built in Python) passes
them instead.  A shape given as a Python object has no deck spelling; the caller says how to
write it (``shape``).
"""
from __future__ import annotations

import itertools
from typing import Any, Callable, Sequence

import numpy as np

from ..model import (CurvedWallSpec, DynamicStep, Interface, Model, MoveWallStep, ReplicateStep,
                     ShapeEntry, Step, WallSpec)
from .deck import split_tokens, strip_comment
from .deck_curved import CURVED_WALL_FILES
from .deck_flow import inlet_values, outlet_values
from .deck_schema import SCHEMA, Arg, Entry

#: keys whose value is a path: always quoted (a path may hold blanks)
PATH_KEYS = ("File", "Directory", "Table")
#: the names :func:`~nurbsdem.geometry.generators.box_walls` gives a box's walls, in order
BOX_NAMES = ("bottom", "x_min", "x_max", "y_min", "y_max", "top")


# ---------------------------------------------------------------------------- one line


def number(x: Any) -> str:
    """A float as the deck writes it: the shortest text that reads back exactly."""
    return repr(float(x))


def word(text: str, quote: bool = False) -> str:
    """A text value as one deck token: quoted when ``quote`` or when the lexer would not
    read it back as one token; ValueError when no token reads back as ``text``."""
    text = str(text)
    if '"' not in text and "\n" not in text:
        out = f'"{text}"' if quote or split_tokens(strip_comment(text)) != [text] else text
        if split_tokens(strip_comment(out)) == [text]:
            return out
    raise ValueError(f"{text!r} cannot be written as one deck value")


def format_value(arg: Arg, value: Any, key: str = "") -> str:
    """The deck text of the values of ``key`` (a setting's own values: its keyword), by
    their kind in the schema."""
    if arg.kind == "flag":
        return ""
    if arg.kind == "bool":
        return "yes" if value else "no"
    if arg.kind == "str":
        return word(value, quote=key in PATH_KEYS)
    convert = number if arg.kind == "float" else (lambda v: str(int(v)))
    if arg.count == 1:
        return convert(value)
    return " ".join(convert(v) for v in np.ravel(np.asarray(value, dtype=object)))


def format_entry(entry: Entry) -> str:
    """One entry line (no indent): ``Keyword [ID] [head] Key value ...``, then ``# comment``.
    A key the schema does not list is written as numbers (a contact law added at run
    time)."""
    spec = SCHEMA[entry.block][entry.keyword]
    words = [entry.keyword] + ([str(int(entry.id))] if spec.numbered else [])
    if spec.head is not None:
        words.append(format_value(spec.head, entry.head, entry.keyword))
    for key, value in entry.values.items():
        arg = spec.keys.get(key, Arg("float", None if np.ndim(value) else 1))
        text = format_value(arg, value, key)
        words.append(f"{key} {text}" if text else key)
    line = " ".join(words)
    return f"{line}  # {entry.comment}" if entry.comment else line


# ---------------------------------------------------------------------------- the entries


def _entry(block: str, keyword: str, id: int | None = None, head: Any = None,
           comment: str = "", **values: Any) -> Entry:
    return Entry(block, keyword, 0, id, head, dict(values), comment)


def material_entries(model: Model) -> list[Entry]:
    """``Material`` entries; PoissonRatio with a YoungModulus, or when it is not 0."""
    out = []
    for mat in model.materials.values():
        values: dict[str, Any] = {"Density": mat.density}
        if mat.young_modulus is not None:
            values["YoungModulus"] = mat.young_modulus
        if mat.young_modulus is not None or number(mat.poisson_ratio) != "0.0":
            values["PoissonRatio"] = mat.poisson_ratio
        out.append(_entry("Materials", "Material", mat.id, **values))
    return out


def shape_entry(e: ShapeEntry) -> Entry:
    """The ``Shape`` entry of a file, sphere or ellipsoid shape, with its overrides."""
    if e.kind == "sphere":
        values: dict[str, Any] = {"Sphere": True, "Radius": e.params[0]}
    elif e.kind == "ellipsoid":
        values = {"Ellipsoid": True, "SemiAxes": e.params}
    elif e.kind == "file":
        values = {"File": e.source if e.source is not None else str(e.file)}
        tol = getattr(e.shape, "convexity_tol", None)
        if tol is not None:
            values["ConvexityTolerance"] = tol
    else:
        raise ValueError(f"Shape {e.id}: a {e.kind} shape has no deck spelling")
    if e.volume_override is not None:
        values["Volume"] = e.volume_override
    if e.inertia_override is not None:
        J = np.asarray(e.inertia_override, float)
        values["Inertia"] = [J[0, 0], J[1, 1], J[2, 2], J[0, 1], J[0, 2], J[1, 2]]
    return _entry("Shapes", "Shape", e.id, **values)


def particle_entries(model: Model) -> list[Entry]:
    """``Random`` groups, then single ``Particle`` entries."""
    out = [_entry("Particles", "Random", g.id, Shapes=g.shape_ids, Counts=g.counts,
                  Material=g.material_id, Region=np.concatenate([g.region_lo, g.region_hi]),
                  Seed=g.seed, MaxAttempts=g.max_attempts) for g in model.random_groups]
    out += [_entry("Particles", "Particle", p.id, Shape=p.shape_id, Material=p.material_id,
                   Position=p.position, Rotation=p.rotation, Velocity=p.velocity,
                   AngularVelocity=p.angular_velocity) for p in model.particles]
    return out


def box_entry(bid: int, lo, hi, top: bool, material: int | None) -> Entry:
    """A ``Box`` entry: corners (m), a top wall or not, the walls' material."""
    values: dict[str, Any] = {"Min": lo, "Max": hi, "Top": bool(top)}
    if material is not None:
        values["Material"] = material
    return _entry("Walls", "Box", bid, **values)


def wall_entry(wid: int, name: str, point, normal, size, axis, material: int | None) -> Entry:
    """A ``Wall`` entry: centre (m), normal, side lengths (m), first side's axis (None: the
    default), material."""
    values: dict[str, Any] = {"Name": name, "Point": point, "Normal": normal, "Size": size}
    if axis is not None:
        values["Axis"] = axis
    if material is not None:
        values["Material"] = material
    return _entry("Walls", "Wall", wid, **values)


def curved_wall_entry(w: CurvedWallSpec) -> Entry:
    """A ``Mesh`` or ``Surface`` entry (its file as written)."""
    kind = CURVED_WALL_FILES[w.kind]
    values: dict[str, Any] = {"Name": w.name, "File": w.file}
    if "Scale" in kind.keys:
        values["Scale"] = w.scale
    values.update(Position=w.position, Rotation=w.rotation)
    if w.material_id is not None:
        values["Material"] = w.material_id
    if w.one_sided:
        values["OneSided"] = True
    return _entry("Walls", kind.keyword, w.id, **values)


def interface_entry(itf: Interface) -> Entry:
    """An ``Interface`` entry: ``Model`` (but the default law's), every key of its law (an
    optional extra such as ``RollingFriction`` only when it is not its default), then
    ``Materials`` or ``Between``."""
    from ..dynamics.laws import law_named
    from ..dynamics.laws.interface import DEFAULT_LAW
    law = law_named(itf.model)
    values: dict[str, Any] = {} if law.name == DEFAULT_LAW else {"Model": law.name}
    for k in law.keys:
        value = itf.params[k.attr] if k.attr in itf.params else getattr(itf, k.attr)
        if k.written_at_default or value != k.default:
            values[k.deck] = value
    if itf.materials:
        values["Materials"] = itf.materials
    elif itf.between:
        values["Between"] = itf.between
    return _entry("Contact", "Interface", itf.id, **values)


def _timing(s: Step) -> dict[str, Any]:
    """Duration, TimeStep and the step's Damping, Accuracy and Safety when not the default."""
    out: dict[str, Any] = {"Duration": s.duration, "TimeStep": s.time_step}
    if s.damping == "implicit":
        out["Damping"] = "Implicit"
    if s.accuracy is not None:
        out["Accuracy"] = s.accuracy
    if s.safety is not None:
        out["Safety"] = s.safety
    return out


def step_entry(s: Step) -> Entry:
    """A ``Step`` entry of a Dynamic, Replicate or MoveWall step."""
    if isinstance(s, DynamicStep):
        return _entry("Steps", "Step", s.id, Dynamic=True, **_timing(s))
    if isinstance(s, ReplicateStep):
        return _entry("Steps", "Step", s.id, Replicate=True, Layers=s.layers, Height=s.height)
    assert isinstance(s, MoveWallStep)
    if s.to_contact:
        values: dict[str, Any] = {"MoveWall": s.wall, "ToContact": True, "Gap": s.gap}
        if s.direction is not None:
            values["Direction"] = unit_preimage(s.direction)
        return _entry("Steps", "Step", s.id, **values)
    return _entry("Steps", "Step", s.id, **_motion(s), **_timing(s))


def _motion(s: MoveWallStep) -> dict[str, Any]:
    """The keys of one wall's motion in a MoveWall step (no timing)."""
    if s.force is not None:
        axis = {} if s.direction is None else {"Direction": unit_preimage(s.direction)}
        return {"MoveWall": s.wall, "Force": s.force, "MaxSpeed": s.max_speed, "Gain": s.gain,
                **axis}
    if s.table is not None:
        centre = {} if s.center is None else {"Center": s.center}
        return {"MoveWall": s.wall, "Table": s.table.file or f"step{s.id}_{s.wall}.csv",
                **centre}
    if s.rotate:
        shift = {} if s.displacement is None else {"Displacement": s.displacement}
        return {"MoveWall": s.wall, "Rotate": True, "AngularVelocity": s.angular_velocity,
                "Center": s.center, **shift}
    return {"MoveWall": s.wall, "Displacement": s.displacement}


def step_entries(s: Step) -> list[Entry]:
    """The ``Step`` entries of a step: one, and one more for each further wall a MoveWall
    step moves (the same id, no timing)."""
    more = [_entry("Steps", "Step", s.id, **_motion(m)) for m in getattr(s, "also", ())]
    return [step_entry(s), *more]


def output_entries(model: Model) -> list[Entry]:
    """The ``Output`` settings (none when the model has no Output)."""
    o = model.output
    if o is None:
        return []
    out = [_entry("Output", "Directory", head=str(o.directory)),
           _entry("Output", "VTK", Every=o.vtk_every, Resolution=o.vtk_resolution),
           _entry("Output", "Monitors", Every=o.monitors_every)]
    if o.results_every is not None:
        out.append(_entry("Output", "Results", Every=o.results_every))
    return out + [_entry("Output", "Checkpoint", Every=o.checkpoint_every)]


# ---------------------------------------------------------------------------- exact numbers


def variants(v) -> list[np.ndarray]:
    """The array ``v`` rounded to 1, 2, ... 17 significant digits (17: ``v`` itself), each
    distinct one once, the shortest first."""
    out: list[np.ndarray] = []
    for digits in range(1, 18):
        cand = np.array([float(f"{x:.{digits}g}") for x in np.ravel(v)]).reshape(np.shape(v))
        if not any(np.array_equal(cand, o) for o in out):
            out.append(cand)
    return out


def first_making(choices: Sequence[Sequence], makes: Callable[..., bool]) -> tuple | None:
    """The first combination of one value from each of ``choices`` for which ``makes`` holds
    (None when none does); a degenerate combination makes nothing, quietly."""
    with np.errstate(all="ignore"):
        for combo in itertools.product(*choices):
            if makes(*combo):
                return combo
    return None


def unit_preimage(d) -> np.ndarray:
    """A vector the deck's ``Direction`` normalisation (``d / |d|``) turns into ``d`` bit for
    bit: ``d`` itself when it does, else its shortest decimals that do, else ``d``."""
    d = np.asarray(d, float)
    if np.array_equal(d / np.linalg.norm(d), d):
        return d
    found = first_making([variants(d) + variants(d / np.abs(d).max())], lambda c: (
        np.linalg.norm(c) > 0 and np.array_equal(c / np.linalg.norm(c), d)))
    return d if found is None else found[0]


def same_patch(a, b) -> bool:
    """Whether two patches are the same bit for bit (degrees, knots, points, weights)."""
    return (a.degree_u == b.degree_u and a.degree_v == b.degree_v
            and all(np.array_equal(getattr(a, k), getattr(b, k))
                    for k in ("knots_u", "knots_v", "control_points", "weights")))


def _box_from(walls: list[WallSpec]) -> Entry:
    """The Box entry whose walls are ``walls`` (5 or 6, in :data:`BOX_NAMES` order)."""
    from ..geometry.generators import box_walls
    pts = np.concatenate([w.patch.control_points.reshape(-1, 3) for w in walls])
    top = len(walls) == 6

    def makes(lo, hi):
        made = list(box_walls(lo, hi, top=top).values()) if np.all(hi > lo) else []
        return len(made) == len(walls) and all(same_patch(p, w.patch)
                                                for p, w in zip(made, walls))
    found = first_making([variants(pts.min(axis=0)), variants(pts.max(axis=0))], makes)
    if found is None:
        raise ValueError(f"walls {walls[0].id}-{walls[-1].id}: no Box makes them exactly")
    return box_entry(walls[0].id, found[0], found[1], top, walls[0].material_id)


def _axis_choices(t1: np.ndarray, n: np.ndarray) -> list:
    """Axes whose projection onto the wall's plane is along ``t1``: the default (None),
    ``t1``, and those with one zero coordinate (largest coordinate 1), each rounded."""
    out: list = [None] + variants(t1)
    for k in range(3):
        if n[k] != 0:
            a = t1 - n * (t1[k] / n[k])
            a[k] = 0.0
            out += variants(a / np.abs(a).max())
    return out


def _wall_from(w: WallSpec) -> Entry:
    """The Wall entry that makes the flat rectangle ``w`` exactly: its centre, normal, sizes
    and axis recovered from the corners, the shortest decimals that make the same patch."""
    from ..geometry.generators import flat_wall
    P = np.asarray(w.patch.control_points, float)
    if P.shape != (2, 2, 3):
        raise ValueError(f"wall {w.name}: not a flat rectangle a Wall entry makes")
    eu, ev = P[1, 0] - P[0, 0], P[0, 1] - P[0, 0]
    size = np.array([np.linalg.norm(eu), np.linalg.norm(ev)])
    n = np.cross(eu, ev)
    n = n / np.linalg.norm(n)
    choices = [_axis_choices(eu / size[0], n), variants(n) + variants(n / np.abs(n).max()),
               variants(P.mean(axis=(0, 1))), variants(size)]
    found = first_making(choices, lambda a, nn, c, s: same_patch(flat_wall(c, nn, s, a),
                                                                 w.patch))
    if found is None:
        raise ValueError(f"wall {w.name}: no Wall entry makes it exactly")
    axis, normal, point, size = found
    return wall_entry(w.id, w.name, point, normal, size, axis, w.material_id)


def flat_wall_entries(walls: list[WallSpec]) -> list[Entry]:
    """The ``Box`` and ``Wall`` entries that make the flat walls ``walls`` (in order, with
    their ids, names and materials) bit for bit; ValueError for a wall no entry makes."""
    out, i = [], 0
    while i < len(walls):
        group = [walls[i]]
        if walls[i].kind == "box":
            for k, name in enumerate(BOX_NAMES[1:], start=1):
                w = walls[i + k] if i + k < len(walls) else None
                if w is None or w.kind != "box" or w.name != name or w.id != walls[i].id + k:
                    break
                group.append(w)
            out.append(_box_from(group))
        else:
            out.append(_wall_from(walls[i]))
        i += len(group)
    return out


# ---------------------------------------------------------------------------- the deck


def model_entries(model: Model, walls: list[Entry] | None = None,
                  shape: Callable[[ShapeEntry], Entry] | None = None) -> list[Entry]:
    """Every entry of the model, block by block.  ``walls``: the Box and Wall entries of
    ``model.walls`` (default: :func:`flat_wall_entries`); ``shape``: the entry of a shape
    with no deck spelling (default: ValueError)."""
    out = [_entry("Environment", "Gravity", head=model.gravity)]
    if model.periodic is not None:
        p = model.periodic
        out.append(_entry("Environment", "Periodic", **{
            name: np.array([p.lo[k], p.hi[k]]) for k, name in enumerate("XYZ") if p.axes[k]}))
    out += material_entries(model)
    for e in model.shapes.values():
        out.append(shape(e) if shape is not None and e.kind not in
                   ("sphere", "ellipsoid", "file") else shape_entry(e))
    out += particle_entries(model)
    out += flat_wall_entries(model.walls) if walls is None else list(walls)
    out += [curved_wall_entry(w) for w in model.curved_walls]
    out += [interface_entry(i) for i in model.interfaces]
    out += [e for s in model.steps for e in step_entries(s)]
    out += [_entry("Flow", "Inlet", i.id, **inlet_values(i)) for i in model.inlets]
    out += [_entry("Flow", "Outlet", o.id, **outlet_values(o)) for o in model.outlets]
    return out + output_entries(model)


def format_entries(entries: list[Entry], header: str = "") -> str:
    """The deck text of ``entries``: every block's keyword (in :data:`SCHEMA` order, empty
    blocks included), its entries indented below it; ``header`` a first comment line."""
    out = [f"# {header}"] if header else []
    for block in SCHEMA:
        out.append(block)
        out += ["  " + format_entry(e) for e in entries if e.block == block]
    return "\n".join(out) + "\n"


def format_model(model: Model, header: str = "", walls: list[Entry] | None = None,
                 shape: Callable[[ShapeEntry], Entry] | None = None) -> str:
    """The deck text of ``model`` (see the module docstring; arguments as
    :func:`model_entries` and :func:`format_entries`)."""
    return format_entries(model_entries(model, walls, shape), header)

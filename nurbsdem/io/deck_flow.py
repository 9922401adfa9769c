"""The deck's block ``Flow`` (and :meth:`Simulation.add_inlet` / ``add_outlet``, which check
by the same rules with the same messages): ``Inlet`` and ``Outlet`` entries to
:class:`~nurbsdem.flow_spec.InletSpec` and :class:`~nurbsdem.flow_spec.OutletSpec`, and the
checks against the rest of the model (shapes, material, walls, names, outlets that catch an
inlet: the rules of :mod:`nurbsdem.flow_checks`).

Every function takes ``fail(message)``, which raises (the deck: at the entry's line; the
API: an :class:`~nurbsdem.errors.InputError`)."""
from __future__ import annotations

from typing import Any, Callable, Mapping

import numpy as np

from ..flow_checks import outlet_catches_inlet, walls_behind
from ..flow_spec import DEFAULT_EVERY, InletSpec, OutletSpec
from .deck_schema import SCHEMA
from .wallname import wall_name_problem

Fail = Callable[[str], None]

#: how far the fractions of an inlet's mix may sum away from 1 (round-off of decimals)
FRACTION_TOL = 1e-9


def name_problem(name: Any) -> str | None:
    """None for a valid inlet or outlet name (it names ``monitors/inlet_<name>.csv``: the
    wall names' rule, and not a key of the ``Flow`` entries), else what is wrong."""
    problem = wall_name_problem(name, SCHEMA)
    if problem is not None:
        return problem.replace("wall name", "name")
    flow_keys = {k.lower() for spec in SCHEMA["Flow"].values() for k in spec.keys}
    if name.lower() in flow_keys:
        return f"bad name {name!r}: it is a keyword of the Flow entries"
    return None


def _box(label: str, box: np.ndarray, fail: Fail) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = np.array(box[:3], float), np.array(box[3:], float)
    if np.any(hi <= lo):
        fail(f"{label}: Box must be x0 y0 z0 x1 y1 z1 with x1 > x0, y1 > y0, z1 > z0")
    return lo, hi


def _every(label: str, values: Mapping[str, Any], fail: Fail) -> float:
    every = float(values.get("Every", DEFAULT_EVERY))
    if not every > 0:
        fail(f"{label}: Every must be > 0, got {every:g}")
    return every


def _fractions(label: str, shapes: tuple, values: Mapping[str, Any], fail: Fail) -> tuple:
    """The mix's number fractions: given for each shape (>= 0, summing to 1), or 1 for a
    single shape."""
    if "Fractions" not in values:
        if len(shapes) != 1:
            fail(f"{label}: Fractions are required with several Shapes")
        return (1.0,)
    fr = tuple(float(f) for f in np.ravel(values["Fractions"]))
    if len(fr) != len(shapes):
        fail(f"{label}: Shapes lists {len(shapes)} shapes but Fractions {len(fr)} numbers")
    if any(not f >= 0 for f in fr):
        fail(f"{label}: Fractions must be >= 0")
    if abs(sum(fr) - 1.0) > FRACTION_TOL:
        fail(f"{label}: Fractions must sum to 1, got {sum(fr):.12g}")
    return fr


def _normal(label: str, values: Mapping[str, Any], fail: Fail) -> np.ndarray:
    """The entry's ``Normal`` (3,), refused when zero (only its direction is used)."""
    normal = np.array(values["Normal"], float).reshape(3)
    if not np.linalg.norm(normal) > 0:
        fail(f"{label}: Normal must not be zero")
    return normal


def _region(label: str, values: Mapping[str, Any], fail: Fail) -> dict[str, Any]:
    """The inlet's region as :class:`~nurbsdem.flow_spec.InletSpec` fields: ``Box``, or
    ``Disc`` (centre) with ``Normal`` (its axis), ``Radius`` and an optional ``Thickness``
    (m, default 0: the centroids lie in the disc's plane)."""
    disc_keys = ("Normal", "Radius", "Thickness")
    if ("Box" in values) == ("Disc" in values):
        fail(f"{label}: give either Box, or Disc with Normal and Radius")
    if "Box" in values:
        extra = [k for k in disc_keys if k in values]
        if extra:
            fail(f"{label}: {extra[0]} goes with Disc, not with Box")
        lo, hi = _box(label, values["Box"], fail)
        return {"lo": lo, "hi": hi}
    for key in ("Normal", "Radius"):
        if key not in values:
            fail(f"{label}: Disc needs {key}")
    normal = _normal(label, values, fail)
    radius = float(values["Radius"])
    if not radius > 0:
        fail(f"{label}: Radius must be > 0, got {radius:g}")
    thickness = float(values.get("Thickness", 0.0))
    if not thickness >= 0:
        fail(f"{label}: Thickness must be >= 0, got {thickness:g}")
    return {"lo": None, "hi": None, "centre": np.array(values["Disc"], float).reshape(3),
            "normal": normal, "radius": radius, "thickness": thickness}


def inlet_spec(iid: int, values: Mapping[str, Any], line: int | None, fail: Fail) -> InletSpec:
    """An ``Inlet`` entry's spec from its key values (the deck's keys)."""
    label = f"Inlet {iid}"
    for key in ("Shapes", "Material", "Rate", "Count"):
        if key not in values:
            fail(f"{label}: missing {key}")
    shapes = tuple(int(s) for s in np.ravel(values["Shapes"]))
    if not shapes:
        fail(f"{label}: Shapes must list at least one shape")
    if len(set(shapes)) != len(shapes):
        fail(f"{label}: Shapes lists a shape twice")
    fractions = _fractions(label, shapes, values, fail)
    region = _region(label, values, fail)
    rate = float(values["Rate"])
    if not rate > 0:
        fail(f"{label}: Rate must be > 0, got {rate:g}")
    count = int(values["Count"])
    if count < 1:
        fail(f"{label}: Count must be >= 1, got {count}")
    seed = int(values.get("Seed", 0))
    if seed < 0:
        fail(f"{label}: Seed must be >= 0")
    name = values.get("Name", f"inlet{iid}")
    problem = name_problem(name)
    if problem is not None:
        fail(f"{label}: {problem}")
    velocity = np.array(values.get("Velocity", np.zeros(3)), float).reshape(3)
    lo, hi = region.pop("lo"), region.pop("hi")
    return InletSpec(iid, name, shapes, fractions, int(values["Material"]), lo, hi, rate,
                     count, velocity, seed, _every(label, values, fail), line, **region)


def outlet_spec(oid: int, values: Mapping[str, Any], line: int | None,
                fail: Fail) -> OutletSpec:
    """An ``Outlet`` entry's spec: a ``Box``, or a ``Point`` and ``Normal`` (a half-space)."""
    label = f"Outlet {oid}"
    has_box = "Box" in values
    has_plane = "Point" in values or "Normal" in values
    if has_box == has_plane:
        fail(f"{label}: give either Box, or Point and Normal")
    name = values.get("Name", f"outlet{oid}")
    problem = name_problem(name)
    if problem is not None:
        fail(f"{label}: {problem}")
    every = _every(label, values, fail)
    if has_box:
        lo, hi = _box(label, values["Box"], fail)
        return OutletSpec(oid, name, lo=lo, hi=hi, every=every, line=line)
    for key in ("Point", "Normal"):
        if key not in values:
            fail(f"{label}: missing {key}")
    normal = _normal(label, values, fail)
    return OutletSpec(oid, name, point=np.array(values["Point"], float).reshape(3),
                      normal=normal, every=every, line=line)


def check_inlet(model, spec: InletSpec, fail: Fail) -> None:
    """An inlet against the model: its shapes and material are defined, its name is not
    taken, and its region does not lie wholly behind a flat wall
    (:func:`~nurbsdem.flow_checks.walls_behind`).  The outlets are checked against it by
    :func:`check_outlet` (the deck, at the outlet's line) or :func:`check_catch`."""
    label = f"Inlet {spec.id}"
    for sid in spec.shapes:
        if sid not in model.shapes:
            fail(f"{label}: unknown shape {sid}" + _defined(model.shapes, "shapes"))
    if spec.material_id not in model.materials:
        fail(f"{label}: unknown material {spec.material_id}"
             + _defined(model.materials, "materials"))
    _check_name(model, spec, label, fail)
    wall, wholly = walls_behind(model, spec.region())
    if wholly:
        fail(f"{label}: its {spec.region_word} lies wholly outside the walls (behind wall "
             f"{wall!r}): every particle would start outside them")


def check_outlet(model, spec: OutletSpec, fail: Fail) -> None:
    """An outlet against the model: its name is not taken and it catches no inlet present
    (:func:`check_catch`)."""
    _check_name(model, spec, f"Outlet {spec.id}", fail)
    for inlet in model.inlets:
        if all(s in model.shapes for s in inlet.shapes):
            check_catch(model, inlet, spec, fail)


def check_catch(model, inlet: InletSpec, outlet: OutletSpec, fail: Fail) -> None:
    """An outlet must not catch positions where an inlet places particles
    (:func:`~nurbsdem.flow_checks.outlet_catches_inlet`); the same message whichever of the
    two comes first."""
    problem = outlet_catches_inlet(model, inlet, outlet)
    if problem is not None:
        fail(problem)


def _check_name(model, spec, label: str, fail: Fail) -> None:
    for other in model.inlets + model.outlets:
        if other is spec:
            return
        if other.name == spec.name:
            kind = "inlet" if isinstance(other, InletSpec) else "outlet"
            fail(f"{label}: the name {spec.name!r} is taken by {kind} {other.id}")


def _defined(table: dict, what: str) -> str:
    return (f" (defined {what}: {', '.join(map(str, sorted(table)))})" if table
            else f" (no {what} defined)")


def inlet_values(spec: InletSpec) -> dict[str, Any]:
    """The deck keys of an inlet (:mod:`nurbsdem.io.deck_format`), every one written."""
    out: dict[str, Any] = {"Name": spec.name, "Shapes": list(spec.shapes),
                           "Fractions": list(spec.fractions), "Material": spec.material_id}
    if spec.is_disc:
        out.update({"Disc": spec.centre, "Normal": spec.normal, "Radius": spec.radius,
                    "Thickness": spec.thickness})
    else:
        out["Box"] = np.concatenate([spec.lo, spec.hi])
    out.update({"Rate": spec.rate, "Count": spec.count, "Velocity": spec.velocity,
                "Seed": spec.seed, "Every": spec.every})
    return out


def outlet_values(spec: OutletSpec) -> dict[str, Any]:
    """The deck keys of an outlet."""
    out: dict[str, Any] = {"Name": spec.name}
    if spec.normal is None:
        out["Box"] = np.concatenate([spec.lo, spec.hi])
    else:
        out["Point"], out["Normal"] = spec.point, spec.normal
    out["Every"] = spec.every
    return out

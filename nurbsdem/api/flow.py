"""The inlets and outlets of a scene built in Python (:meth:`Simulation.add_inlet
<nurbsdem.simulation.Simulation.add_inlet>`, ``add_outlet``): the arguments checked by the
deck's rules with the deck's messages (:mod:`nurbsdem.io.deck_flow`) and added to the model as
the deck's block ``Flow`` adds them."""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from ..errors import InputError
from ..io.deck_flow import check_catch, check_inlet, check_outlet, inlet_spec, outlet_spec
from .checks import entity_id, number, vector


def _fail(message: str) -> None:
    raise InputError(message)


def _next_id(specs: list) -> int:
    return max((s.id for s in specs), default=0) + 1


def add_inlet(scene, shapes: Sequence[Any], material: int, box: Sequence[float] | None,
              rate: float, count: int, fractions: Sequence[float] | None,
              velocity: Sequence[float], seed: int, every: float, name: str | None,
              disc: Sequence[float] | None = None, normal: Sequence[float] | None = None,
              radius: float | None = None, thickness: float | None = None) -> str:
    """``Inlet`` of ``scene`` (a :class:`~nurbsdem.api.scene.SceneBuilder`): shapes are Shape
    objects, shape files or the ids of shapes already in the scene; the region a ``box``,
    or a ``disc`` centre with its ``normal``, ``radius`` and ``thickness`` (m); returns the
    name."""
    model = scene.model
    iid = _next_id(model.inlets)
    what = f"Inlet {iid}"
    sids = [int(s) if isinstance(s, (int, np.integer)) and not isinstance(s, bool)
            else scene.shape_id(s) for s in shapes]
    values: dict[str, Any] = {
        "Shapes": sids, "Material": entity_id(material, f"{what}: material"),
        "Rate": number("Rate", rate, what),
        "Count": int(number("Count", count, what)), "Velocity": vector("Velocity", velocity, what),
        "Seed": int(number("Seed", seed, what, nonnegative=True)),
        "Every": number("Every", every, what)}
    if box is not None:
        values["Box"] = vector("Box", box, what, n=6)
    if disc is not None:
        values["Disc"] = vector("Disc", disc, what)
    if normal is not None:
        values["Normal"] = vector("Normal", normal, what)
    if radius is not None:
        values["Radius"] = number("Radius", radius, what)
    if thickness is not None:
        values["Thickness"] = number("Thickness", thickness, what)
    if fractions is not None:
        values["Fractions"] = [number("Fractions", f, what) for f in fractions]
    if name is not None:
        values["Name"] = name
    spec = inlet_spec(iid, values, None, _fail)
    check_inlet(model, spec, _fail)
    for outlet in model.outlets:
        check_catch(model, spec, outlet, _fail)
    model.inlets.append(spec)
    return spec.name


def add_outlet(model, box: Sequence[float] | None, point: Sequence[float] | None,
               normal: Sequence[float] | None, every: float, name: str | None) -> str:
    """``Outlet`` of ``model``: a box, or a point and a normal; returns the name."""
    oid = _next_id(model.outlets)
    what = f"Outlet {oid}"
    values: dict[str, Any] = {"Every": number("Every", every, what)}
    if box is not None:
        values["Box"] = vector("Box", box, what, n=6)
    if point is not None:
        values["Point"] = vector("Point", point, what)
    if normal is not None:
        values["Normal"] = vector("Normal", normal, what)
    if name is not None:
        values["Name"] = name
    spec = outlet_spec(oid, values, None, _fail)
    check_outlet(model, spec, _fail)
    model.outlets.append(spec)
    return spec.name


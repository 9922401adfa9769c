"""The rules an inlet's region and the outlets are held to before a run, the same for a deck
(``nurbsdem check``, ``solve``) and for :meth:`Simulation.add_inlet
<nurbsdem.simulation.Simulation.add_inlet>` / ``add_outlet``:

* **walls** (:func:`walls_behind`): a region that lies wholly behind one flat wall (on the
  side away from the particles, within the wall's rectangle) is an error, since every
  particle would start outside the walls; a region that reaches partly behind one is a
  warning (the particles placed there start outside or pressed into that wall);
* **outlets** (:func:`caught_fraction`): an outlet that catches any of the positions where
  an inlet places particle centroids is an error, since the particles inserted there are
  removed at the next segment end;
* **capacity** (:func:`capacity_problem`): a region whose volume cannot hold the particles
  one segment must insert, at the volume fraction that randomly placed bounding spheres
  reach (:data:`LOOSE_FRACTION`), is a warning: the inlet waits, inserting fewer particles
  per second than its rate.

Errors go through ``fail(message)`` (:mod:`nurbsdem.io.deck_flow`); the warnings are issued
once per run by :func:`warn_flow` (from :func:`nurbsdem.validation.validate_scene`).
Units: SI (m, s)."""
from __future__ import annotations

import logging
import math

import numpy as np

from .dynamics.flow import InsertionRegion, Outlet

#: the volume fraction of bounding spheres placed one by one at random (without moving the
#: ones placed) that an inlet's region holds before it has no room: random loose packing of
#: spheres is about 0.55 of their own volume, random sequential placement jams near 0.38,
#: and an inlet that must find room within its draws per particle fills less.
LOOSE_FRACTION = 0.3
#: draws of the outlet rule (:func:`caught_fraction`): positions where an outlet catches
#: less than 1/OUTLET_DRAWS of the inlet's region may go unreported.
OUTLET_DRAWS = 4096


def mix_radii(model, spec) -> np.ndarray:
    """Bounding radii (m) of an inlet's shapes, in the order of ``spec.shapes``."""
    return np.array([model.shapes[s].bounding_radius for s in spec.shapes], float)


def _behind(wall, points: np.ndarray) -> np.ndarray:
    """Bool (n,): the points (n,3) behind the flat ``wall`` (on the side away from the
    particles, by more than round-off) whose foot lies within the wall's rectangle."""
    n, c = wall.normal, wall.center
    pts = np.asarray(wall.patch.control_points, float).reshape(-1, 3)
    tol = 1e-9 * (1.0 + float(np.abs(pts).max()))
    depth = (points - c) @ n
    foot = points - depth[:, None] * n[None]
    inside = np.all((foot >= pts.min(axis=0) - tol) & (foot <= pts.max(axis=0) + tol), axis=1)
    return (depth < -tol) & inside


def _wholly_behind(wall, region: InsertionRegion) -> bool:
    """Whether the whole region lies behind ``wall`` within its rectangle: the set of such
    points is convex (a half-space and a prism over the rectangle's bounding box), so the
    region's support along each of its faces decides it exactly."""
    n, c = np.asarray(wall.normal, float), np.asarray(wall.center, float)
    pts = np.asarray(wall.patch.control_points, float).reshape(-1, 3)
    tol = 1e-9 * (1.0 + float(np.abs(pts).max()))
    if region.support(n) > c @ n - tol:
        return False
    cn = float(c @ n)
    for k in range(3):        # the foot's coordinate k: (e_k - n_k n)·x + (c·n) n_k
        d = np.eye(3)[k] - n[k] * n
        if region.support(d) > pts[:, k].max() - cn * n[k] + tol:
            return False
        if region.support(-d) > -pts[:, k].min() + cn * n[k] + tol:
            return False
    return True


def walls_behind(model, region: InsertionRegion) -> tuple[str | None, bool]:
    """(the name of a flat wall that part of ``region`` lies behind, whether all of it does)
    or (None, False): the wall the whole region lies behind if any, else the first wall a
    point of its outline (:meth:`InsertionRegion.outline`) lies behind."""
    for w in model.walls:
        if _wholly_behind(w, region):
            return w.name, True
    points = region.outline()
    for w in model.walls:
        if np.any(_behind(w, points)):
            return w.name, False
    return None, False


def caught_fraction(region: InsertionRegion, radius: float, outlet: Outlet,
                    seed: int = 0) -> float:
    """The fraction of :data:`OUTLET_DRAWS` centroid positions that ``outlet`` catches,
    drawn as the inlet draws them (:meth:`InsertionRegion.sample`) for its smallest
    particle (bounding radius ``radius`` m, the widest spread of centroids)."""
    rng = np.random.default_rng(seed)
    x = region.sample(rng, OUTLET_DRAWS, np.full(OUTLET_DRAWS, float(radius)))
    return float(np.mean(outlet.catches(x)))


def outlet_catches_inlet(model, inlet_spec, outlet_spec) -> str | None:
    """The error of an outlet that catches positions where an inlet places centroids, or
    None; the message names both."""
    outlet = Outlet(outlet_spec.name, lo=outlet_spec.lo, hi=outlet_spec.hi,
                    point=outlet_spec.point, normal=outlet_spec.normal)
    radius = float(mix_radii(model, inlet_spec).min())
    share = caught_fraction(inlet_spec.region(), radius, outlet)
    if share == 0.0:
        return None
    where = ("its Box" if outlet_spec.normal is None else "the far side of its plane")
    return (f"Outlet {outlet_spec.id}: {where} holds {_percent(share)} of the positions where "
            f"Inlet {inlet_spec.id} ({inlet_spec.name}) places particle centroids: the "
            f"particles inserted there are removed at the next segment end; move the outlet "
            f"or the inlet's {inlet_spec.region_word}")


def _percent(share: float) -> str:
    return "all" if share == 1.0 else f"about {max(100 * share, 0.1):.3g} %"


def segment_length(model) -> float:
    """The length (s) of a segment: the smallest ``Every`` of the inlets and outlets (the
    solver rounds it to a whole number of each step's TimeStep)."""
    return min(s.every for s in model.inlets + model.outlets)


def capacity_problem(model, spec) -> str | None:
    """The warning of an inlet whose region cannot hold the particles one segment must
    insert, or None: ceil(Rate × segment) bounding spheres of the mix's mean volume (by
    number fractions) filling more than :data:`LOOSE_FRACTION` of the volume the region
    offers them (:meth:`InsertionRegion.volume`)."""
    radii = mix_radii(model, spec)
    every = segment_length(model)
    n = min(math.ceil(spec.rate * every - 1e-9), int(spec.count))
    spheres = n * float(np.dot(spec.fractions, 4.0 / 3.0 * math.pi * radii ** 3))
    volume = spec.region().volume(float(radii.max()))
    if spheres <= LOOSE_FRACTION * volume:
        return None
    fill = f"{100 * spheres / volume:.3g} %" if volume > 0 else "more than all"
    return (f"Inlet {spec.id}: its {spec.region_word} ({volume:.3g} m^3) cannot hold the {n} "
            f"particles one segment of {every:g} s must insert at Rate {spec.rate:g} per s: "
            f"their bounding spheres would fill {fill} of it, and spheres placed at random "
            f"fill about {100 * LOOSE_FRACTION:.0f} % (random loose packing): the inlet "
            f"will wait, inserting fewer than Rate particles per second; enlarge the "
            f"{spec.region_word}, lower Rate or shorten Every")


def partly_behind_problem(model, spec) -> str | None:
    """The warning of an inlet whose region reaches partly behind a flat wall, or None."""
    wall, wholly = walls_behind(model, spec.region())
    if wall is None or wholly:
        return None
    return (f"Inlet {spec.id}: its {spec.region_word} lies partly outside the walls (behind "
            f"wall {wall!r}): particles placed there start outside the walls or pressed "
            f"into that wall")


def warn_flow(model) -> None:
    """The warnings of the inlets (:func:`partly_behind_problem`, :func:`capacity_problem`)
    on the ``nurbsdem`` logger, each ``deck:line: message`` (the message alone for a scene
    built in Python)."""
    log = logging.getLogger("nurbsdem")
    for spec in model.inlets:
        if any(s not in model.shapes for s in spec.shapes):
            continue
        for problem in (partly_behind_problem(model, spec), capacity_problem(model, spec)):
            if problem is not None:
                loc = f"{model.path}:{spec.line}: " if model.path and spec.line else ""
                log.warning(f"{loc}{problem}")

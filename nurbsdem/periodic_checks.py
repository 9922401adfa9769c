"""The checks of a periodic cell (``Periodic`` in block Environment, :class:`~nurbsdem.model.
PeriodicSpec`) against the rest of a model: one-line errors naming the deck line.

* The cell is at least twice the contact reach along each periodic axis, the reach being the
  largest sum of two bounding radii plus the default skin (:func:`~nurbsdem.contact.periodic.
  check_cell`): a particle would otherwise touch its own image, or a partner twice.
* A flat wall lies along every periodic axis (its normal has no component along one): a
  wall across a periodic direction would cut the cell, and its images are not modelled.  It
  covers the cell along those axes and, beyond each periodic face, the largest bounding radius
  plus the skin, so that a particle near a face (wrapped into the cell at list builds only,
  it strays up to half the skin out) finds the wall under it.  A floor with normal z under a
  cell periodic in x and y is the usual case.  Checked at the walls' deck positions.
* Each particle starts inside the cell, clear of its periodic faces: the placement does not
  see overlaps through a face (:func:`check_periodic_bodies`).
* An inlet's region lies inside the cell along its periodic axes (a new particle is placed
  clear of the images across the faces of the cell it is in, :mod:`nurbsdem.dynamics.flow`).
* A mesh or surface wall in a periodic cell stays or translates: one that turns is refused
  (the kicks of the images across the faces take the walls' velocities, not their spins).
  Like a flat wall it should cover the cell and its margin along the periodic axes, and its
  shape there repeat with the cell (its own images are not modelled).

Lengths in metres.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .check_rules import wall_plane
from .errors import vector_text

if TYPE_CHECKING:
    from .model import Model


def _radii(model: "Model") -> tuple[float, float]:
    """The largest and smallest bounding radius of the model's shapes (m)."""
    r = [float(e.bounding_radius) for e in model.shapes.values()]
    return (max(r), min(r)) if r else (0.0, 0.0)


def periodic_reach(model: "Model", margin: float = 0.0, skin: float | None = None) -> float:
    """The contact reach of the model's particles: the largest sum of two bounding radii plus
    the margin and the skin (default: the scene's, a fraction of the smallest radius), m."""
    from .contact.scene import SKIN_FRACTION
    rmax, rmin = _radii(model)
    return 2.0 * rmax + margin + (SKIN_FRACTION * rmin if skin is None else skin)


def check_cell_reach(model: "Model", reach: float) -> None:
    """The cell at least twice ``reach`` (m) along each periodic axis."""
    from .contact.periodic import check_cell
    p = model.periodic
    try:
        check_cell(p.cell(), reach)
    except ValueError as exc:
        raise model.error(f"Periodic: {exc}", p.line) from None


def check_periodic(model: "Model") -> None:
    """The module's checks of a model with a periodic cell (nothing without one)."""
    p = model.periodic
    if p is None:
        return
    _check_inlets(model)
    _check_turning_walls(model)
    check_cell_reach(model, periodic_reach(model))
    _check_walls(model)


def _check_turning_walls(model: "Model") -> None:
    """A mesh or surface wall in a periodic cell does not turn (``MoveWall … Rotate``, or a
    table with rotations): the kicks of the particles' images across the faces take the
    walls' velocities, not their spins."""
    curved = {w.name for w in model.curved_walls}
    for step in model.steps:
        for move in (step.moves() if getattr(step, "kind", "") == "movewall" else ()):
            table = move.table
            turns = move.rotate or (table is not None and table.rotation is not None
                                    and bool(np.any(np.asarray(table.rotation) != 0.0)))
            if move.wall in curved and turns:
                raise model.error(f"Step {step.id}: wall {move.wall} turns, and a mesh or "
                                  f"surface wall in a periodic cell (line {model.periodic.line})"
                                  f" can only translate", step.line)


def _check_inlets(model: "Model") -> None:
    """An inlet's region lies inside the cell along its periodic axes: a new particle is
    placed clear of the images across the faces of the cell it is in (there is no other)."""
    p = model.periodic
    for spec in model.inlets:
        lo, hi = spec.region().bounds()
        out = p.axes & ((lo < p.lo) | (hi > p.hi))
        if out.any():
            axis = "XYZ"[int(np.flatnonzero(out)[0])]
            raise model.error(f"Inlet {spec.name}: its region reaches outside the periodic cell "
                              f"along {axis} ({lo[out][0]:.6g} .. {hi[out][0]:.6g} m against "
                              f"{p.lo[out][0]:.6g} .. {p.hi[out][0]:.6g} m, line {p.line})",
                              spec.line)


def _check_walls(model: "Model") -> None:
    """Each flat wall along every periodic axis, covering the cell along it (module
    docstring)."""
    p = model.periodic
    rmax, rmin = _radii(model)
    beyond = periodic_reach(model) - rmax       # the largest bounding radius plus the skin
    for w in model.walls:
        o, a, b, n = wall_plane(w)
        corners = np.array([o, o + a, o + b, o + a + b])
        for k in np.flatnonzero(p.axes):
            axis = "xyz"[k]
            if abs(n[k]) > 1e-9:
                raise model.error(f"wall {w.name}: its normal {vector_text(n)} has a component "
                                  f"along the periodic axis {axis} (Periodic, line {p.line}): "
                                  f"a flat wall must lie along every periodic axis", w.line)
            w_lo, w_hi = corners[:, k].min(), corners[:, k].max()
            if w_lo > p.lo[k] - beyond or w_hi < p.hi[k] + beyond:
                raise model.error(
                    f"wall {w.name} spans {w_lo:.6g} .. {w_hi:.6g} m along the periodic axis "
                    f"{axis}: it must cover the cell ({p.lo[k]:.6g} .. {p.hi[k]:.6g} m, line "
                    f"{p.line}) and {beyond:.6g} m beyond each face (the largest bounding "
                    f"radius plus the skin)", w.line)


def check_periodic_bodies(model: "Model", bodies, support) -> None:
    """Each particle starts inside the cell and clear of its periodic faces (its exact
    extent, to the overlap tolerance of :mod:`nurbsdem.check_rules`): two particles inside it
    cannot then overlap through a face, which the placement does not see.  A ``Random``
    group's Region lies inside the cell, inset by the particles' size.  ``support``: the
    distance from a plane to a body's deepest point
    (:func:`~nurbsdem.validation.plane_support_distance`)."""
    from .check_rules import OVERLAP_TOLERANCE
    p = model.periodic
    if p is None or bodies is None or not len(bodies):
        return
    R = bodies.rotation_matrices()
    for i in range(len(bodies)):
        shape = model.shapes[int(bodies.shape_id[i])].shape
        x, r = bodies.position[i], float(shape.bounding_radius)
        for k in np.flatnonzero(p.axes):
            for face, sign in ((p.lo[k], 1.0), (p.hi[k], -1.0)):
                if sign * (x[k] - face) >= r:
                    continue
                n = np.zeros(3)
                n[k] = sign
                point = np.zeros(3)
                point[k] = face
                sd = support(shape, x, R[i], point, n)
                if sd < -OVERLAP_TOLERANCE * r:
                    raise model.error(
                        f"particle {bodies.id[i]} (centroid {vector_text(x)} m) reaches "
                        f"{-sd:.3g} m across the periodic face {'xyz'[k]} = {face:g} m "
                        f"(Periodic, line {p.line}): particles start inside the cell, clear "
                        f"of its faces", int(bodies.line[i]))

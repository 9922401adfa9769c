"""Exact rational NURBS surfaces for equipment walls: cylinders, cones and planes.

A wall surface is one open patch whose front side (the side S_u × S_v points to) faces the
particles.  The circle is exact: the rational quadratic of nine control points over four
quarter arcs, weights 1 and √2/2 on alternate points (Piegl & Tiller, *The NURBS Book*,
Section 7.5); along the axis the surfaces are ruled (degree 1), so the cylinder and the
(truncated) cone are exact too.  u runs once around the axis from the first radial direction
(u = 0 and u = 1 are the same line, the seam), v from the base (0) to the top (1).

Lengths in metres.  The surfaces are written and read as shape files (patches only: a wall
surface is not a closed particle) by :mod:`nurbsdem.io.shapefile`.
"""
from __future__ import annotations

import numpy as np

from .generators import flat_wall
from .nurbs import Patch

#: knots of the nine-point circle: four rational quadratic quarter arcs
CIRCLE_KNOTS = np.array([0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1], float)
_W = np.sqrt(0.5)
#: (cos, sin) of the circle's control points on the unit square's corners and mid-sides, and
#: their weights
_CIRCLE_2D = np.array([[1, 0], [1, 1], [0, 1], [-1, 1], [-1, 0], [-1, -1], [0, -1], [1, -1],
                       [1, 0]], float)
_CIRCLE_W = np.array([1, _W, 1, _W, 1, _W, 1, _W, 1])


def _frame(axis, first_radial=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit axis e3 and radial directions e1, e2 (e1 × e2 = e3)."""
    e3 = np.asarray(axis, float)
    norm = np.linalg.norm(e3)
    if not norm > 0 or not np.all(np.isfinite(e3)):
        raise ValueError(f"the axis {list(np.ravel(axis))} has no direction")
    e3 = e3 / norm
    if first_radial is None:
        first_radial = np.eye(3)[int(np.argmin(np.abs(e3)))]
    e1 = np.asarray(first_radial, float) - e3 * (np.asarray(first_radial, float) @ e3)
    if not np.linalg.norm(e1) > 1e-12:
        raise ValueError("the first radial direction is along the axis")
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(e3, e1), e3


def _positive(value: float, what: str, allow_zero: bool = False) -> float:
    value = float(value)
    if not (np.isfinite(value) and (value > 0 or (allow_zero and value == 0))):
        raise ValueError(f"{what} must be a positive length, got {value!r}")
    return value


def revolved_patch(r0: float, r1: float, height: float, base=(0.0, 0.0, 0.0),
                   axis=(0.0, 0.0, 1.0), inward: bool = True, first_radial=None) -> Patch:
    """The ruled surface of revolution between the circle of radius r0 at ``base`` and the
    circle of radius r1 at ``base + height * axis`` (a cylinder when r0 = r1, a truncated
    cone otherwise; one of the radii may be 0: a full cone).  ``inward``: the front faces the
    axis (the inside of a drum or a funnel); otherwise away from it."""
    r0 = _positive(r0, "the base radius", allow_zero=True)
    r1 = _positive(r1, "the top radius", allow_zero=True)
    if r0 == 0 and r1 == 0:
        raise ValueError("a surface of revolution needs a radius above zero")
    height = _positive(height, "the height")
    e1, e2, e3 = _frame(axis, first_radial)
    if inward:                          # u clockwise about e3: S_u x S_v = -e1 at u = 0
        e2 = -e2
    c0 = np.asarray(base, float)
    ring = _CIRCLE_2D[:, :1] * e1 + _CIRCLE_2D[:, 1:] * e2          # (9, 3)
    pts = np.stack([c0 + r0 * ring, c0 + height * e3 + r1 * ring], axis=1)   # (9, 2, 3)
    weights = np.repeat(_CIRCLE_W[:, None], 2, axis=1)
    return Patch(2, 1, CIRCLE_KNOTS.copy(), np.array([0, 0, 1, 1], float), pts, weights)


def cylinder_patch(radius: float, length: float, base=(0.0, 0.0, 0.0), axis=(0.0, 0.0, 1.0),
                   inward: bool = True, first_radial=None) -> Patch:
    """An exact cylinder of ``radius`` and ``length`` along ``axis`` from ``base`` (its front
    inward by default: a drum)."""
    return revolved_patch(radius, radius, length, base, axis, inward, first_radial)


def cone_patch(base_radius: float, top_radius: float, height: float, base=(0.0, 0.0, 0.0),
               axis=(0.0, 0.0, 1.0), inward: bool = True, first_radial=None) -> Patch:
    """An exact (truncated) cone between the two radii (its front inward by default: a
    funnel or a hopper)."""
    return revolved_patch(base_radius, top_radius, height, base, axis, inward, first_radial)


def plane_patch(point, normal, size, first_axis=None) -> Patch:
    """A flat rectangle of ``size`` (lu, lv) centred at ``point`` with its front along
    ``normal`` (degree 1, 2 × 2 control points: :func:`nurbsdem.geometry.generators.flat_wall`)."""
    lu, lv = (_positive(s, "a side of the plane") for s in size)
    return flat_wall(point, normal, (lu, lv), first_axis)

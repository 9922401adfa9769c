"""Shapes that are exactly an analytic solid, recognised from their NURBS surfaces.

A shape whose every patch lies on one sphere is an exact sphere: the contact search can then
use closed forms (:mod:`nurbsdem.contact.sphere`) instead of the local contact problem.

Exactness test: on a knot span a rational patch of degrees (p, q) is S = P/w with P, w
polynomials of bidegree (p, q), so |P − c w|² − r² w² is a polynomial of bidegree (2p, 2q).  It
vanishes identically if and only if it vanishes on a tensor grid of (2p + 1) × (2q + 1) distinct
points of the span (tensor-product interpolation is unique).  :func:`exact_sphere` evaluates
that grid in every span of every patch, so a shape it accepts lies on the sphere everywhere, to
round-off — not only at sample points.
"""
from __future__ import annotations

import numpy as np


def _span_grid(knots: np.ndarray, degree: int) -> np.ndarray:
    """(2·degree + 1) distinct parameters inside each non-empty knot span, all spans."""
    k = np.unique(knots[degree:len(knots) - degree])
    t = (np.arange(2 * degree + 1) + 0.5) / (2 * degree + 1)
    return np.concatenate([a + t * (b - a) for a, b in zip(k[:-1], k[1:])])


def exact_sphere(shape, rtol: float = 1e-11) -> tuple[np.ndarray, float] | None:
    """(centre (3,) in the shape's frame, radius) when every patch of ``shape`` lies on one
    sphere to ``rtol`` × radius (module docstring), else None.  The centre is taken from the
    control-point cloud's bounding box and refined by least squares on the grid points."""
    pts = []
    for p in shape.patches:
        u = _span_grid(p.knots_u, p.degree_u)
        v = _span_grid(p.knots_v, p.degree_v)
        U, V = np.meshgrid(u, v, indexing="ij")
        pts.append(p.points(U.ravel(), V.ravel()))
    x = np.concatenate(pts)
    # least-squares sphere: |x|² = 2 c·x + (r² − |c|²), linear in (c, k)
    A = np.hstack([2.0 * x, np.ones((x.shape[0], 1))])
    sol, *_ = np.linalg.lstsq(A, (x * x).sum(axis=1), rcond=None)
    c = sol[:3]
    dist = np.linalg.norm(x - c, axis=1)
    r = float(dist.mean())
    if not (r > 0 and np.isfinite(r)):
        return None
    if float(np.abs(dist - r).max()) > rtol * r:
        return None
    return c, r

"""Whether two placed bodies overlap, by surface samples (the placement's and the scene
check's test, :func:`bodies_overlap`): below both, so that neither imports the other."""
from __future__ import annotations

import weakref
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from .shape import Shape

_SAMPLES_PER_PATCH_DIRECTION = 8
#: Centroids closer than this fraction of the smaller bounding radius: the bodies overlap.
COINCIDENT_FRACTION = 1e-3


@dataclass
class _Sampled:
    """A shape's surface samples and their convex hull, file frame, relative to the centroid."""

    points: np.ndarray      # (M, 3)
    equations: np.ndarray   # (F, 4): n . x + d <= 0 inside
    radius: float           # bounding radius (m)


_SAMPLE_CACHE: "weakref.WeakKeyDictionary[Shape, _Sampled]" = weakref.WeakKeyDictionary()


def sampled_surface(shape: "Shape") -> _Sampled:
    """Surface samples and hull of a shape (cached per Shape object)."""
    hit = _SAMPLE_CACHE.get(shape)
    if hit is not None:
        return hit
    from scipy.spatial import ConvexHull

    try:
        from .tessellate import tessellate_shape
        pts, _, _ = tessellate_shape(shape, _SAMPLES_PER_PATCH_DIRECTION)
    except ImportError:  # pragma: no cover - fallback: uniform parameter grid
        pts = _grid_samples(shape, _SAMPLES_PER_PATCH_DIRECTION)
    pts = np.asarray(pts, float) - np.asarray(shape.centroid, float)
    pts = np.unique(np.round(pts, 15), axis=0)
    hull = ConvexHull(pts)
    out = _Sampled(pts, hull.equations, float(shape.bounding_radius))
    _SAMPLE_CACHE[shape] = out
    return out


def _grid_samples(shape: "Shape", n: int) -> np.ndarray:
    out = []
    for p in shape.patches:
        u0, u1, v0, v1 = p.domain
        U, V = np.meshgrid(np.linspace(u0, u1, n + 1), np.linspace(v0, v1, n + 1), indexing="ij")
        out.append(p.points(U, V).reshape(-1, 3))
    return np.concatenate(out)


def _points_inside(points: np.ndarray, equations: np.ndarray, tol: float) -> bool:
    """Whether any point lies strictly inside the hull (by more than tol)."""
    d = points @ equations[:, :3].T + equations[:, 3]
    return bool(np.any(np.all(d < -tol, axis=1)))


def bodies_overlap(shape_a: "Shape", pos_a, R_a, shape_b: "Shape", pos_b, R_b) -> bool:
    """Whether two bodies overlap, by surface samples: a sampled point of one strictly inside
    the convex hull of the other's samples (that hull lies inside the convex body, so there
    are no false alarms; overlaps shallower than the sampling's chord error may be missed).

    pos_*: centroids in the world (m); R_*: (3, 3) file-to-world rotations. Centroids closer
    than :data:`COINCIDENT_FRACTION` of the smaller bounding radius overlap outright.
    """
    sa, sb = sampled_surface(shape_a), sampled_surface(shape_b)
    pos_a, pos_b = np.asarray(pos_a, float), np.asarray(pos_b, float)
    dist = np.linalg.norm(pos_a - pos_b)
    if dist >= sa.radius + sb.radius:
        return False
    if dist < COINCIDENT_FRACTION * min(sa.radius, sb.radius):
        return True   # a convex body contains its centroid; identical samples are not 'inside'
    tol = 1e-9 * max(sa.radius, sb.radius)
    wa = pos_a + sa.points @ np.asarray(R_a).T
    wb = pos_b + sb.points @ np.asarray(R_b).T
    in_b = (wa - pos_b) @ np.asarray(R_b)   # A's samples in B's centroid frame
    if _points_inside(in_b, sb.equations, tol):
        return True
    in_a = (wb - pos_a) @ np.asarray(R_a)
    return _points_inside(in_a, sa.equations, tol)

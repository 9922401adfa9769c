"""Quad tessellation of NURBS patches and shapes (for ParaView output and plots).

The grid is uniform in parameter space within each knot span: a direction with total
parameter length L gets about n quads, distributed over its non-empty knot spans in
proportion to their lengths (at least one per span), so that every knot line is a grid
line and no quad straddles a knot (where the surface may only be C^0). Quads are ordered
(i, j), (i+1, j), (i+1, j+1), (i, j+1) in (u, v) index, counter-clockwise in the parameter
plane, so their right-hand normals follow S_u x S_v, i.e. point outward on a valid shape.
Points are in metres in the file frame of the patch.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from .nurbs import Patch


def parameter_grid(knots: np.ndarray, degree: int, n: int) -> np.ndarray:
    """Grid parameters along one direction: about n intervals, every distinct knot included."""
    if n < 1:
        raise ValueError("n must be >= 1")
    lo, hi = float(knots[degree]), float(knots[-degree - 1])
    brk = np.unique(knots[(knots >= lo) & (knots <= hi)])
    total = hi - lo
    out = [np.array([lo])]
    for a, b in zip(brk[:-1], brk[1:]):
        k = max(1, int(round(n * (b - a) / total)))
        out.append(np.linspace(a, b, k + 1)[1:])
    t = np.concatenate(out)
    t[-1] = hi
    return t


def tessellate_patch(patch: Patch, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Points and quads of one patch.

    Parameters
    ----------
    patch: the NURBS patch.
    n: quads per parameter direction (about; see module docstring).

    Returns
    -------
    points: (M, 3) with M = (n_u + 1)(n_v + 1), index i * (n_v + 1) + j for grid node (i, j).
    quads: (K, 4) int64 point indices, right-hand normal along S_u x S_v.
    """
    tu = parameter_grid(patch.knots_u, patch.degree_u, n)
    tv = parameter_grid(patch.knots_v, patch.degree_v, n)
    U, V = np.meshgrid(tu, tv, indexing="ij")
    pts = patch.points(U, V).reshape(-1, 3)
    mu, mv = len(tu), len(tv)
    i, j = np.meshgrid(np.arange(mu - 1), np.arange(mv - 1), indexing="ij")
    i, j = i.ravel(), j.ravel()
    quads = np.stack([i * mv + j, (i + 1) * mv + j, (i + 1) * mv + j + 1, i * mv + j + 1],
                     axis=1).astype(np.int64)
    return pts, quads


def tessellate_shape(shape_or_patches, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points, quads and the patch of each quad for a whole shape.

    Points on shared patch edges are duplicated (one copy per patch).

    Returns
    -------
    points (M, 3), quads (K, 4) int64, patch_id (K,) int64.
    """
    patches: Sequence[Patch] = getattr(shape_or_patches, "patches", shape_or_patches)
    P, Q, ids = [], [], []
    off = 0
    for ip, p in enumerate(patches):
        pts, quads = tessellate_patch(p, n)
        P.append(pts)
        Q.append(quads + off)
        ids.append(np.full(len(quads), ip, np.int64))
        off += len(pts)
    if not P:
        return np.zeros((0, 3)), np.zeros((0, 4), np.int64), np.zeros(0, np.int64)
    return np.concatenate(P), np.concatenate(Q), np.concatenate(ids)


def quad_areas_normals(points: np.ndarray, quads: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vector area (1/2 d1 x d2 of the diagonals) of each quad: returns (areas (K,), unit
    normals (K, 3)); degenerate quads (at poles reduced to triangles) are handled exactly."""
    a, b, c, d = (points[quads[:, k]] for k in range(4))
    va = 0.5 * np.cross(c - a, d - b)
    ar = np.linalg.norm(va, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        nrm = va / ar[:, None]
    return ar, nrm

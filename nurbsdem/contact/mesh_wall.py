"""Triangle-mesh walls: an exact sphere against a triangle mesh, per triangle in closed form.

A mesh wall is a set of triangles (an STL, OBJ or PLY surface: open or closed, convex or not,
a thin two-sided shell by default) held in its own frame and placed in the world by a pose
(rotation ``R`` and translation ``t``: ``x_world = R x_mesh + t``).  The particle's centre is
brought into the mesh frame instead of moving the triangles, so that the broad phase (a
uniform grid of the triangles' bounding boxes, built once) stays valid while the wall moves.

Contact of a sphere (centre c, radius r) with one triangle: the triangle's closest point q
to c (face interior, an edge or a vertex: Ericson, *Real-Time Collision Detection*, 5.1.5) and
its distance d = |c − q|; the contact is active when d < r, with

    n = (q − c)/|q − c|  (from the particle towards the wall),   p_A = c + r n,   p_B = q,
    signed distance = d − r,

the row layout of :mod:`nurbsdem.contact.lcp` (the same as the flat wall's closed form of
:mod:`nurbsdem.contact.sphere`).

**One contact per smooth or convex region.**  The surface of the mesh is the union of its
triangles, and a contact is a *local minimum* of the distance from c to that surface.  A
face-interior closest point always is one.  A closest point on an edge or a vertex (a feature
shared by the triangles around it) is one only when no triangle around that feature comes
closer; and where several triangles share the same closest point (c above an internal edge
of a tessellated plane, outside a convex fold) it is one contact, kept once.  So a sphere
sliding over a tessellated plane sees one contact whose distance and normal are those of the
plane (no kick at the internal edges), a sphere outside a convex fold one contact along the
edge's normal cone, and a sphere in a concave fold (the inner corner of a hopper) one contact
per face.  Ties within ``1e-12`` of the mesh's size count as equal.

One-sided meshes ignore the triangles whose front face (the side their vertex order's normal
points to) the centre is behind.

**Kept lists.**  In the step (:func:`mesh_rows_listed`) each sphere keeps the triangles within
r + skin of its centre (mesh frame) between evaluations, like a Verlet list, and asks the grid
again only once it has moved (the wall's motion included) more than skin/2; the candidates
taken from the list are put back in the grid's order, so the rows are those of the grid bit
for bit, whatever the lists hold.  A triangle whose distance from the list's centre exceeds r
by more than the centre's move since, or whose bounding box lies beyond reach, is skipped
without its closest point.

Lengths in metres; triangles are indices into the vertex array (T,3).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ..errors import InputError
from .lcp import F_N, F_PA, F_PB, F_SD, I_ACTIVE, I_PA, I_PB, I_VALID, NF, NI

#: features of a triangle (a, b, c) that hold its closest point to a query point
FACE, EDGE_AB, EDGE_BC, EDGE_CA, VERTEX_A, VERTEX_B, VERTEX_C = 0, 1, 2, 3, 4, 5, 6
#: relative tolerance (of the mesh's bounding-box diagonal) under which two distances or two
#: points are the same: round-off of the closest-point formulas is ~1e-16 of the size
TIE = 1e-12
#: the grid never has more cells than this many per triangle (memory stays O(T))
CELLS_PER_TRIANGLE = 4
#: a triangle whose bounding box lies beyond a sphere's reach by more than this relative
#: margin of the coordinates' size is skipped without its closest point (:func:`_near_point`)
BEYOND = 1e-8
#: the kept lists of nearby triangles (:func:`mesh_rows_listed`): the skin, in radii,
#: and the room (triangles) of each sphere's list; ``NO_LIST``: a sphere without one yet
LIST_SKIN = 0.1
LIST_ROOM = 32
NO_LIST = -2


@dataclass(frozen=True)
class MeshWall:
    """A triangle mesh in its own frame with its broad-phase grid.

    vertices (V,3) m; faces (T,3) vertex indices (counter-clockwise seen from the front);
    normals (T,3) unit front normals; grid_origin (3,) m and grid_cell (m) the grid's corner
    and cell edge; grid_dims (3,) cells per axis; cell_start (C+1,), cell_tris: the triangles
    whose bounding box touches cell k are ``cell_tris[cell_start[k]:cell_start[k+1]]``
    (cells numbered x fastest); two_sided: both faces act; size (m) the bounding-box diagonal;
    tri_cells (T,6) each triangle's cells (lowest x, y, z, highest x, y, z: its bounding
    box's, clipped to the grid).
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    grid_origin: np.ndarray
    grid_cell: float
    grid_dims: np.ndarray
    cell_start: np.ndarray
    cell_tris: np.ndarray
    two_sided: bool
    size: float
    tri_cells: np.ndarray


def _face_normals(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(T,3) unit normals and (T,) areas (m^2) of the triangles."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    cross = np.cross(b - a, c - a)
    twice = np.linalg.norm(cross, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        normals = cross / twice[:, None]
    return normals, 0.5 * twice


def _grid_cell(vertices: np.ndarray, faces: np.ndarray, size: float) -> float:
    """Cell edge (m): the median triangle extent, enlarged where the cells would outnumber
    ``CELLS_PER_TRIANGLE`` per triangle."""
    lo = vertices[faces].min(axis=1)
    hi = vertices[faces].max(axis=1)
    cell = max(float(np.median((hi - lo).max(axis=1))), 1e-9 * size)
    extent = np.maximum(vertices.max(axis=0) - vertices.min(axis=0), cell)
    while np.prod(np.ceil(extent / cell) + 1) > CELLS_PER_TRIANGLE * len(faces) + 8:
        cell *= 1.5
    return cell


def _bin_triangles(vertices: np.ndarray, faces: np.ndarray, origin: np.ndarray, cell: float,
                   dims: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """CSR arrays (cell_start, cell_tris) of the triangles whose bounding box touches each
    cell (each cell's in ascending order), and each triangle's cells (T,6) (lowest and highest
    per axis)."""
    lo = np.floor((vertices[faces].min(axis=1) - origin) / cell).astype(np.int64)
    hi = np.floor((vertices[faces].max(axis=1) - origin) / cell).astype(np.int64)
    lo = np.clip(lo, 0, dims - 1)
    hi = np.clip(hi, 0, dims - 1)
    span = hi - lo + 1                               # cells per axis of each triangle's box
    count = span.prod(axis=1)
    tris_a = np.repeat(np.arange(len(faces), dtype=np.int64), count)
    # the j-th cell of a triangle's box, z fastest, then y, then x
    j = np.arange(tris_a.shape[0], dtype=np.int64) - np.repeat(np.cumsum(count) - count, count)
    nz, ny = span[tris_a, 2], span[tris_a, 1]
    ix = lo[tris_a, 0] + j // (nz * ny)
    iy = lo[tris_a, 1] + (j // nz) % ny
    iz = lo[tris_a, 2] + j % nz
    cells_a = ix + dims[0] * (iy + dims[1] * iz)
    order = np.argsort(cells_a, kind="stable")
    n_cells = int(np.prod(dims))
    start = np.zeros(n_cells + 1, np.int64)
    start[1:] = np.bincount(cells_a, minlength=n_cells)
    return np.cumsum(start), tris_a[order], np.ascontiguousarray(np.hstack([lo, hi]))


def build_mesh_wall(vertices: np.ndarray, faces: np.ndarray, two_sided: bool = True,
                    source: str = "mesh") -> MeshWall:
    """A :class:`MeshWall` of triangles ``faces`` (T,3) over ``vertices`` (V,3) m, with its grid.

    Refuses (:class:`~nurbsdem.errors.InputError`, naming ``source``) an empty mesh, a
    non-finite vertex, a face index out of range and a degenerate triangle (area below
    1e-12 of the bounding box's squared diagonal: its normal is undefined)."""
    vertices = np.ascontiguousarray(vertices, dtype=float)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3:
        raise InputError(f"{source}: a mesh needs (V,3) vertices and (T,3) triangles")
    if len(faces) == 0:
        raise InputError(f"{source}: the mesh has no triangles")
    if not np.all(np.isfinite(vertices)):
        bad = int(np.argwhere(~np.isfinite(vertices).all(axis=1))[0, 0])
        raise InputError(f"{source}: vertex {bad} is not finite ({vertices[bad].tolist()})")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise InputError(f"{source}: a triangle refers to a vertex outside 0..{len(vertices) - 1}")
    size = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))
    normals, area = _face_normals(vertices, faces)
    tiny = np.flatnonzero(~(area > 1e-12 * size * size))
    if len(tiny):
        raise InputError(f"{source}: triangle {int(tiny[0])} is degenerate (area "
                         f"{area[tiny[0]]:.3g} m^2, its vertices are collinear); "
                         f"{len(tiny)} such triangles")
    cell = _grid_cell(vertices, faces, size)
    origin = vertices.min(axis=0) - 1e-9 * size
    dims = (np.floor((vertices.max(axis=0) - origin) / cell).astype(np.int64) + 1)
    start, tris, tri_cells = _bin_triangles(vertices, faces, origin, cell, dims)
    return MeshWall(vertices, faces, np.ascontiguousarray(normals), origin, cell, dims,
                    start, tris, bool(two_sided), size, tri_cells)


# ---------------------------------------------------------------------------- closest points


@njit(cache=True, inline="always")
def _dot(x0, x1, x2, y0, y1, y2):
    return x0 * y0 + x1 * y1 + x2 * y2


@njit(cache=True, inline="always")
def _closest_point(p0, p1, p2, a0, a1, a2, b0, b1, b2, c0, c1, c2):
    """:func:`closest_on_triangle` on coordinates: the point p, the corners a, b, c (m)."""
    ab0, ab1, ab2 = b0 - a0, b1 - a1, b2 - a2
    ac0, ac1, ac2 = c0 - a0, c1 - a1, c2 - a2
    ap0, ap1, ap2 = p0 - a0, p1 - a1, p2 - a2
    d1 = _dot(ab0, ab1, ab2, ap0, ap1, ap2)
    d2 = _dot(ac0, ac1, ac2, ap0, ap1, ap2)
    if d1 <= 0.0 and d2 <= 0.0:
        return a0, a1, a2, VERTEX_A
    bp0, bp1, bp2 = p0 - b0, p1 - b1, p2 - b2
    d3 = _dot(ab0, ab1, ab2, bp0, bp1, bp2)
    d4 = _dot(ac0, ac1, ac2, bp0, bp1, bp2)
    if d3 >= 0.0 and d4 <= d3:
        return b0, b1, b2, VERTEX_B
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return a0 + v * ab0, a1 + v * ab1, a2 + v * ab2, EDGE_AB
    cp0, cp1, cp2 = p0 - c0, p1 - c1, p2 - c2
    d5 = _dot(ab0, ab1, ab2, cp0, cp1, cp2)
    d6 = _dot(ac0, ac1, ac2, cp0, cp1, cp2)
    if d6 >= 0.0 and d5 <= d6:
        return c0, c1, c2, VERTEX_C
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return a0 + w * ac0, a1 + w * ac1, a2 + w * ac2, EDGE_CA
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return b0 + w * (c0 - b0), b1 + w * (c1 - b1), b2 + w * (c2 - b2), EDGE_BC
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return a0 + ab0 * v + ac0 * w, a1 + ab1 * v + ac1 * w, a2 + ab2 * v + ac2 * w, FACE


@njit(cache=True)
def closest_on_triangle(p: np.ndarray, a: np.ndarray, b: np.ndarray,
                        c: np.ndarray) -> tuple[float, float, float, int]:
    """Closest point (x, y, z) of triangle (a, b, c) to p (each (3,), m) and the feature that
    holds it (``FACE``, ``EDGE_AB`` ..., ``VERTEX_A`` ...): the Voronoi regions of the
    vertices, then of the edges, then the face (Ericson 5.1.5)."""
    return _closest_point(p[0], p[1], p[2], a[0], a[1], a[2], b[0], b[1], b[2], c[0], c[1],
                          c[2])


@njit(cache=True, inline="always")
def _axis_gap(x, a, b, c):
    """(gap, magnitude): how far the coordinate x lies outside [min(a,b,c), max(a,b,c)] (0
    inside), and the largest of |x|, |a|, |b|, |c|."""
    lo = min(a, min(b, c))
    hi = max(a, max(b, c))
    gap = max(lo - x, max(x - hi, 0.0))
    return gap, max(abs(x), max(abs(lo), abs(hi)))


@njit(cache=True, inline="always")
def _near_point(x0, x1, x2, reach, a0, a1, a2, b0, b1, b2, c0, c1, c2):
    """(q0, q1, q2, d, feature): the closest point of triangle (a, b, c) to the point x, its
    distance (m) and feature (:func:`closest_on_triangle`); d = inf, without that point,
    where the triangle's bounding box lies farther than ``reach`` (m) from x by more than a
    relative ``BEYOND`` of the coordinates' size (the closest point, which round-off keeps
    within ~1e-15 of that size of the box, is then farther than reach too)."""
    g0, m0 = _axis_gap(x0, a0, b0, c0)
    g1, m1 = _axis_gap(x1, a1, b1, c1)
    g2, m2 = _axis_gap(x2, a2, b2, c2)
    far = reach + BEYOND * (reach + max(m0, max(m1, m2)))
    if g0 * g0 + g1 * g1 + g2 * g2 > far * far:
        return 0.0, 0.0, 0.0, np.inf, FACE
    q0, q1, q2, feat = _closest_point(x0, x1, x2, a0, a1, a2, b0, b1, b2, c0, c1, c2)
    e0, e1, e2 = x0 - q0, x1 - q1, x2 - q2
    return q0, q1, q2, math.sqrt(e0 * e0 + e1 * e1 + e2 * e2), feat


@njit(cache=True, inline="always")
def _feature_vertices(f0, f1, f2, feature):
    """The mesh vertices of a feature of the triangle with vertices (f0, f1, f2): (-1, -1) for
    the face, (i, j) for an edge, (i, -1) for a vertex."""
    if feature == FACE:
        return -1, -1
    if feature == EDGE_AB:
        return f0, f1
    if feature == EDGE_BC:
        return f1, f2
    if feature == EDGE_CA:
        return f2, f0
    if feature == VERTEX_A:
        return f0, -1
    return (f1, -1) if feature == VERTEX_B else (f2, -1)


@njit(cache=True, inline="always")
def _holds(f0, f1, f2, i, j):
    """Whether the triangle with vertices (f0, f1, f2) has the vertex i and (when j >= 0) the
    vertex j."""
    has_i = f0 == i or f1 == i or f2 == i
    if j < 0:
        return has_i
    return has_i and (f0 == j or f1 == j or f2 == j)


# ---------------------------------------------------------------------------- broad phase


@njit(cache=True, inline="always")
def _axis_cells(x, reach, origin, cell, dim):
    """The grid cells (lo, hi) along one axis that x ± reach (m) meets (lo > hi: none)."""
    lo = max(int(math.floor((x - reach - origin) / cell)), 0)
    hi = min(int(math.floor((x + reach - origin) / cell)), dim - 1)
    return lo, hi


@njit(cache=True)
def _near(x0, x1, x2, reach, grid_origin, grid_cell, grid_dims, cell_start, cell_tris, stamp,
          mark, out):
    """:func:`triangles_near` of the point (x0, x1, x2)."""
    lx, hx = _axis_cells(x0, reach, grid_origin[0], grid_cell, grid_dims[0])
    ly, hy = _axis_cells(x1, reach, grid_origin[1], grid_cell, grid_dims[1])
    lz, hz = _axis_cells(x2, reach, grid_origin[2], grid_cell, grid_dims[2])
    if lx > hx or ly > hy or lz > hz:
        return 0
    n = 0
    for iz in range(lz, hz + 1):
        for iy in range(ly, hy + 1):
            for ix in range(lx, hx + 1):
                cell = ix + grid_dims[0] * (iy + grid_dims[1] * iz)
                for m in range(cell_start[cell], cell_start[cell + 1]):
                    t = cell_tris[m]
                    if stamp[t] != mark:
                        stamp[t] = mark
                        if n < out.shape[0]:
                            out[n] = t
                        n += 1
    return n


@njit(cache=True)
def triangles_near(x: np.ndarray, reach: float, grid_origin: np.ndarray, grid_cell: float,
                   grid_dims: np.ndarray, cell_start: np.ndarray, cell_tris: np.ndarray,
                   stamp: np.ndarray, mark: int, out: np.ndarray) -> int:
    """The triangles whose grid cells meet the box x ± reach (mesh frame, m), each once, into
    ``out``; returns their count.  ``stamp`` (T,) int64 holds the last ``mark`` that took each
    triangle (a new ``mark`` per query: no clearing).  Their order: by the first cell of the
    box that holds them (cells numbered x fastest, visited in that order), then by triangle
    number (each cell lists its triangles in ascending order, :func:`_bin_triangles`)."""
    return _near(x[0], x[1], x[2], reach, grid_origin, grid_cell, grid_dims, cell_start,
                 cell_tris, stamp, mark, out)


@njit(cache=True, inline="always")
def _first_cell(c0, c1, c2, c3, c4, c5, lx, hx, ly, hy, lz, hz, d0, d1):
    """The first cell (in :func:`triangles_near`'s order, grid dims d0 × d1 × ...) of the box
    of cells [lx, hx] × [ly, hy] × [lz, hz] that lists a triangle of cells [c0, c3] × [c1, c4]
    × [c2, c5] (``MeshWall.tri_cells``); −1 when none does.  No branches: they are hard to
    predict."""
    f0, f1, f2 = max(c0, lx), max(c1, ly), max(c2, lz)
    inside = (f0 <= min(c3, hx)) & (f1 <= min(c4, hy)) & (f2 <= min(c5, hz))
    cell = f0 + d0 * (f1 + d1 * f2)
    return cell if inside else -1


@njit(cache=True)
def _candidates_of(x0, x1, x2, r, vertices, faces, normals, two_sided, tris, n, cand_q, cand_d,
                   cand_f):
    """:func:`_triangle_candidates` of the point (x0, x1, x2)."""
    k = 0
    for m in range(n):
        t = tris[m]
        a, b, c = faces[t, 0], faces[t, 1], faces[t, 2]
        q0, q1, q2, d, feat = _near_point(x0, x1, x2, r, vertices[a, 0], vertices[a, 1],
                                          vertices[a, 2], vertices[b, 0], vertices[b, 1],
                                          vertices[b, 2], vertices[c, 0], vertices[c, 1],
                                          vertices[c, 2])
        if d >= r:
            continue
        if not two_sided and _dot(x0 - q0, x1 - q1, x2 - q2, normals[t, 0], normals[t, 1],
                                  normals[t, 2]) < 0.0:
            continue
        tris[k] = t
        cand_q[k, 0], cand_q[k, 1], cand_q[k, 2] = q0, q1, q2
        cand_d[k] = d
        cand_f[k] = feat
        k += 1
    return k


@njit(cache=True)
def _triangle_candidates(xm, r, vertices, faces, normals, two_sided, tris, n, cand_q,
                         cand_d, cand_f):
    """Closest point, distance and feature of each listed triangle within r of xm (mesh
    frame); returns how many, compacted to the front of ``tris`` and the ``cand_*`` arrays."""
    return _candidates_of(xm[0], xm[1], xm[2], r, vertices, faces, normals, two_sided, tris, n,
                          cand_q, cand_d, cand_f)


@njit(cache=True)
def _sort_candidates(k, tris, cand_q, cand_d, cand_f, keys):
    """Candidates 0..k-1 sorted by (keys, tris): an insertion sort (a few, nearly in order)."""
    for a in range(1, k):
        b = a
        while b > 0 and (keys[b - 1] > keys[b]
                         or (keys[b - 1] == keys[b] and tris[b - 1] > tris[b])):
            tris[b - 1], tris[b] = tris[b], tris[b - 1]
            keys[b - 1], keys[b] = keys[b], keys[b - 1]
            cand_d[b - 1], cand_d[b] = cand_d[b], cand_d[b - 1]
            cand_f[b - 1], cand_f[b] = cand_f[b], cand_f[b - 1]
            for c in range(3):
                cand_q[b - 1, c], cand_q[b, c] = cand_q[b, c], cand_q[b - 1, c]
            b -= 1


@njit(cache=True, inline="always")
def _first(s, k, fs, fk):
    """Whether candidate s (feature fs) comes before k (feature fk) among contacts that are
    the same: face points first, then by list order (one total order, so that exactly one of
    them is kept)."""
    s_face, k_face = fs == FACE, fk == FACE
    return (s_face and not k_face) or (s_face == k_face and s < k)


@njit(cache=True)
def _is_local_minimum(k, faces, tris, cand_q, cand_d, cand_f, n, tie):
    """Whether candidate k is a local minimum of the distance to the mesh, kept once.  Not
    when another candidate has the same point and comes first (:func:`_first`: two triangles
    of a plane that both take a point of their shared edge as their own); a face point is one
    otherwise; an edge or vertex point is not when a triangle around that feature is closer,
    or as close and comes first (module docstring)."""
    fk = cand_f[k]
    tk = tris[k]
    i, j = _feature_vertices(faces[tk, 0], faces[tk, 1], faces[tk, 2], fk)
    dk = cand_d[k]
    for s in range(n):
        if s == k:
            continue
        e0 = cand_q[s, 0] - cand_q[k, 0]
        e1 = cand_q[s, 1] - cand_q[k, 1]
        e2 = cand_q[s, 2] - cand_q[k, 2]
        if e0 * e0 + e1 * e1 + e2 * e2 <= tie * tie:
            if _first(s, k, cand_f[s], fk):
                return False
        elif fk != FACE and _holds(faces[tris[s], 0], faces[tris[s], 1], faces[tris[s], 2], i,
                                   j):
            ds = cand_d[s]
            if ds < dk - tie or (ds <= dk + tie and _first(s, k, cand_f[s], fk)):
                return False
    return True


@njit(cache=True)
def _to_mesh(y0, y1, y2, R, t):
    """The world point (y0, y1, y2) in the mesh frame of the pose (R, t)."""
    return ((R[0, 0] * (y0 - t[0]) + R[1, 0] * (y1 - t[1]) + R[2, 0] * (y2 - t[2])),
            (R[0, 1] * (y0 - t[0]) + R[1, 1] * (y1 - t[1]) + R[2, 1] * (y2 - t[2])),
            (R[0, 2] * (y0 - t[0]) + R[1, 2] * (y1 - t[1]) + R[2, 2] * (y2 - t[2])))


@njit(cache=True)
def sphere_mesh_rows(x: np.ndarray, r: float, R: np.ndarray, t: np.ndarray,
                     vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray,
                     two_sided: bool, size: float, grid_origin: np.ndarray, grid_cell: float,
                     grid_dims: np.ndarray, cell_start: np.ndarray, cell_tris: np.ndarray,
                     stamp: np.ndarray, mark: int, tris: np.ndarray, cand_q: np.ndarray,
                     cand_d: np.ndarray, cand_f: np.ndarray, rows_f: np.ndarray,
                     rows_i: np.ndarray) -> int:
    """The contacts of a sphere (world centre x (3,), radius r, m) with a mesh wall at pose
    (R (3,3), t (3,): x_world = R x_mesh + t), one row each of rows_f (K,NF) / rows_i (K,NI)
    in the layout of :mod:`nurbsdem.contact.lcp` (``I_PB``: the triangle; ``I_PA`` = −1);
    returns their count (rows beyond the arrays' length are not written: pass K large enough,
    the count says how many there were).  Workspaces of :func:`make_workspace`: ``stamp``
    (with a new ``mark`` per query) for :func:`triangles_near`, ``tris``, ``cand_q``,
    ``cand_d``, ``cand_f`` for the candidate triangles."""
    x0, x1, x2 = _to_mesh(x[0], x[1], x[2], R, t)
    n = _near(x0, x1, x2, r, grid_origin, grid_cell, grid_dims, cell_start, cell_tris, stamp,
              mark, tris)
    n = _candidates_of(x0, x1, x2, r, vertices, faces, normals, two_sided, tris, n, cand_q,
                       cand_d, cand_f)
    return _candidate_rows(x0, x1, x2, r, R, t, vertices, faces, normals, size, tris, n,
                           cand_q, cand_d, cand_f, rows_f, rows_i)


@njit(cache=True)
def _candidate_rows(x0, x1, x2, r, R, t, vertices, faces, normals, size, tris, n, cand_q,
                    cand_d, cand_f, rows_f, rows_i):
    """The rows of the candidates that are local minima (:func:`sphere_mesh_rows`, the sphere
    at (x0, x1, x2) in the mesh frame); returns their count."""
    tie = TIE * size
    out = np.int64(0)
    for k in range(n):
        if not _is_local_minimum(k, faces, tris, cand_q, cand_d, cand_f, n, tie):
            continue
        if out < rows_f.shape[0]:
            tri = tris[k]
            v = faces[tri, 0]
            _contact_row(x0, x1, x2, r, R, t, cand_q[k, 0], cand_q[k, 1], cand_q[k, 2],
                         cand_d[k], normals, tri, vertices[v, 0], vertices[v, 1],
                         vertices[v, 2], rows_f, rows_i, out)
        out += 1
    return out


@njit(cache=True)
def _contact_row(x0, x1, x2, r, R, t, qa, qb, qc, d, normals, tri, c0, c1, c2, rows_f, rows_i,
                 j):
    """Row j: the contact of the sphere at (x0, x1, x2) (mesh frame) with closest point
    (qa, qb, qc) at distance d on triangle ``tri`` (unit normal ``normals[tri]``, a vertex
    (c0, c1, c2)), in world coordinates (module docstring).  Where q lies on the triangle's
    plane straight below x (a face point, or an edge or vertex point of a flat region) the
    normal is the triangle's own and q the projection of x on its plane: the plane's numbers
    to round-off, whichever triangle of the plane holds the contact.  At d = 0 the normal is
    the front normal reversed (the centre on the surface is pushed out of the front)."""
    for k in range(NF):
        rows_f[j, k] = 0.0
    for k in range(NI):
        rows_i[j, k] = 0
    m0, m1, m2 = normals[tri, 0], normals[tri, 1], normals[tri, 2]
    h = (x0 - c0) * m0 + (x1 - c1) * m1 + (x2 - c2) * m2
    if d > 0.0 and abs(h) >= d * (1.0 - 1e-12):
        s = 1.0 if h > 0.0 else -1.0
        n0, n1, n2 = -s * m0, -s * m1, -s * m2
        d = abs(h)
        q0 = x0 - h * m0
        q1 = x1 - h * m1
        q2 = x2 - h * m2
    else:
        q0, q1, q2 = qa, qb, qc
        if d > 0.0:
            n0, n1, n2 = (q0 - x0) / d, (q1 - x1) / d, (q2 - x2) / d
        else:
            n0, n1, n2 = -m0, -m1, -m2
    for k in range(3):
        rows_f[j, F_N + k] = R[k, 0] * n0 + R[k, 1] * n1 + R[k, 2] * n2
        rows_f[j, F_PB + k] = R[k, 0] * q0 + R[k, 1] * q1 + R[k, 2] * q2 + t[k]
        rows_f[j, F_PA + k] = (R[k, 0] * x0 + R[k, 1] * x1 + R[k, 2] * x2 + t[k]
                               + r * rows_f[j, F_N + k])
    rows_f[j, F_SD] = d - r
    rows_i[j, I_PA] = -1
    rows_i[j, I_PB] = tri
    rows_i[j, I_VALID] = 1
    rows_i[j, I_ACTIVE] = 1


# ---------------------------------------------------------------------------- kept lists


@njit(cache=True)
def mesh_rows_listed(idx, x, r, R, t, vertices, faces, normals, two_sided, size, grid_origin,
                     grid_cell, grid_dims, cell_start, cell_tris, tri_cells, stamp, mark0, tris,
                     cand_q, cand_d, cand_f, near_p, near_n, near_t, near_d, keys, most, rows_f,
                     rows_i, owner, rank):
    """The touching rows (signed distance < 0) of spheres ``idx`` (centres x (N,3), radii r
    (N,), m) with a mesh wall at pose (R, t): of each sphere, those of its first ``most``
    rows of :func:`sphere_mesh_rows` that touch, the same bit for bit, in the same order,
    into rows_f / rows_i from row 0, with the sphere in ``owner`` and the row's rank among
    its rows in ``rank``; returns their count (rows beyond the arrays' length are not
    written: call again with that room; those after the count are scratch).  Sphere m's
    grid query takes the mark mark0 + m.

    From each sphere's list of nearby triangles kept between calls (:func:`make_lists`:
    near_p, near_n, near_t, near_d; keys a workspace; tri_cells the mesh's): the triangles
    within r + skin (skin = ``LIST_SKIN`` r) of the centre (mesh frame) where the list was
    made, with their distances from there.  A triangle farther than r + the centre's move
    since then (and a round-off guard) is beyond r now: it is skipped without its closest
    point.  Over a resting floor that leaves the one or two triangles under the sphere.
    It is made again when the centre (mesh frame: the wall's motion counts) has moved more
    than skin/2 from there or the radius differs, so that it holds every triangle within r;
    those of them in the cells of the box x ± r are the grid's candidates, put in the grid's
    order (the first such cell, then the triangle number: :func:`triangles_near`).  Where
    more than the room of ``near_t`` lie within r + skin, the grid answers until the sphere
    has moved that far.  The rows do not depend on the lists' state: lists made anew (a
    restart) give the same rows."""
    tie = TIE * size
    made = tris.reshape((1, tris.size))           # a list being made: the front of tris
    one_f, one_i = np.empty((1, rows_f.shape[1])), np.empty((1, rows_i.shape[1]), np.int64)
    r00, r01, r02, r10, r11, r12 = R[0, 0], R[0, 1], R[0, 2], R[1, 0], R[1, 1], R[1, 2]
    r20, r21, r22, t0, t1, t2 = R[2, 0], R[2, 1], R[2, 2], t[0], t[1], t[2]
    o0, o1, o2 = grid_origin[0], grid_origin[1], grid_origin[2]
    d0, d1, d2 = grid_dims[0], grid_dims[1], grid_dims[2]
    out = 0
    for m in range(idx.shape[0]):
        i = idx[m]
        ri = r[i]
        y0, y1, y2 = x[i, 0] - t0, x[i, 1] - t1, x[i, 2] - t2
        x0 = r00 * y0 + r10 * y1 + r20 * y2               # the centre in the mesh frame
        x1 = r01 * y0 + r11 * y1 + r21 * y2
        x2 = r02 * y0 + r12 * y1 + r22 * y2
        e0, e1, e2 = x0 - near_p[i, 0], x1 - near_p[i, 1], x2 - near_p[i, 2]
        half = 0.5 * near_p[i, 4]
        src, row, n_src, grid = near_t, i, near_n[i], near_n[i] < 0
        kept = True                                   # the list was made at an earlier call
        if (n_src == NO_LIST or near_p[i, 3] != ri
                or e0 * e0 + e1 * e1 + e2 * e2 > half * half):
            n_src = _make_list(i, x0, x1, x2, ri, vertices, faces, normals, grid_origin,
                               grid_cell, grid_dims, cell_start, cell_tris, stamp, mark0 + m,
                               tris, cand_q, cand_d, cand_f, near_p, near_n, near_t,
                               near_d)
            src, row, grid, kept = made, 0, False, False
        if grid:                                      # too many near: the grid
            n = _near(x0, x1, x2, ri, grid_origin, grid_cell, grid_dims, cell_start,
                      cell_tris, stamp, mark0 + m, tris)
            n = _candidates_of(x0, x1, x2, ri, vertices, faces, normals, two_sided, tris, n,
                               cand_q, cand_d, cand_f)
        else:
            lx, hx = _axis_cells(x0, ri, o0, grid_cell, d0)
            ly, hy = _axis_cells(x1, ri, o1, grid_cell, d1)
            lz, hz = _axis_cells(x2, ri, o2, grid_cell, d2)
            if lx > hx or ly > hy or lz > hz:
                n_src = 0
            n = 0
            clear = (ri + BEYOND * (ri + abs(x0) + abs(x1) + abs(x2))
                     + math.sqrt(e0 * e0 + e1 * e1 + e2 * e2))
            for k in range(n_src):
                if kept and near_d[i, k] > clear:     # beyond r: the distance drops by the move
                    continue
                tri = src[row, k]
                a, b, c = faces[tri, 0], faces[tri, 1], faces[tri, 2]
                q0, q1, q2, d, feat = _near_point(x0, x1, x2, ri, vertices[a, 0],
                                                  vertices[a, 1], vertices[a, 2],
                                                  vertices[b, 0], vertices[b, 1],
                                                  vertices[b, 2], vertices[c, 0],
                                                  vertices[c, 1], vertices[c, 2])
                if d >= ri:
                    continue
                if not two_sided and _dot(x0 - q0, x1 - q1, x2 - q2, normals[tri, 0],
                                          normals[tri, 1], normals[tri, 2]) < 0.0:
                    continue
                cell = _first_cell(tri_cells[tri, 0], tri_cells[tri, 1], tri_cells[tri, 2],
                                   tri_cells[tri, 3], tri_cells[tri, 4], tri_cells[tri, 5],
                                   lx, hx, ly, hy, lz, hz, d0, d1)
                if cell < 0:                           # not in the grid's answer
                    continue
                tris[n] = tri
                cand_q[n, 0], cand_q[n, 1], cand_q[n, 2] = q0, q1, q2
                cand_d[n] = d
                cand_f[n] = feat
                keys[n] = cell
                n += 1
            if n > 1:
                _sort_candidates(n, tris, cand_q, cand_d, cand_f, keys)
        j = 0
        for k in range(n):
            if j >= most:
                break
            if not _is_local_minimum(k, faces, tris, cand_q, cand_d, cand_f, n, tie):
                continue
            tri = tris[k]
            v = faces[tri, 0]
            # written in place (the next row overwrites one that does not touch); past the
            # arrays' room, into a spare row, to count it
            room = out < rows_f.shape[0]
            dst_f, dst_i, row = (rows_f, rows_i, out) if room else (one_f, one_i, 0)
            _contact_row(x0, x1, x2, ri, R, t, cand_q[k, 0], cand_q[k, 1], cand_q[k, 2],
                         cand_d[k], normals, tri, vertices[v, 0], vertices[v, 1],
                         vertices[v, 2], dst_f, dst_i, row)
            if dst_f[row, F_SD] < 0.0:
                if room:
                    owner[out] = i
                    rank[out] = j
                out += 1
            j += 1
    return out


@njit(cache=True)
def _make_list(i, x0, x1, x2, r, vertices, faces, normals, grid_origin, grid_cell, grid_dims,
               cell_start, cell_tris, stamp, mark, tris, cand_q, cand_d, cand_f, near_p,
               near_n, near_t, near_d):
    """Sphere i's list made at (x0, x1, x2): the triangles within r + skin and their
    distances (m), also left in ``tris`` and ``cand_d``; returns their count.  The skin has a
    round-off guard of ``BEYOND`` of the coordinates' size on top of ``LIST_SKIN`` r."""
    skin = LIST_SKIN * r + BEYOND * (r + abs(x0) + abs(x1) + abs(x2))
    reach = r + skin
    n = _near(x0, x1, x2, reach, grid_origin, grid_cell, grid_dims, cell_start, cell_tris,
              stamp, mark, tris)
    n = _candidates_of(x0, x1, x2, reach, vertices, faces, normals, True, tris, n, cand_q,
                       cand_d, cand_f)
    near_p[i, 0], near_p[i, 1], near_p[i, 2] = x0, x1, x2
    near_p[i, 3], near_p[i, 4] = r, skin
    if n > near_t.shape[1]:
        near_n[i] = -1
        return n
    for m in range(n):
        near_t[i, m] = tris[m]
        near_d[i, m] = cand_d[m]
    near_n[i] = n
    return n


def make_lists(mesh: MeshWall, n: int, room: int = LIST_ROOM) -> tuple[np.ndarray, ...]:
    """The kept lists of :func:`mesh_rows_listed` for n spheres against ``mesh``: near_p
    (n,5) (the centre (mesh frame, m), radius and skin (m) of each list), near_n (n,) int64
    (its length; ``NO_LIST``: none yet, −1: more than ``room``), near_t (n, room) int64 (its
    triangles), near_d (n, room) (their distances from the list's centre, m) and keys (T,)
    int64 (a workspace)."""
    return (np.zeros((n, 5)), np.full(n, NO_LIST, np.int64), np.zeros((n, room), np.int64),
            np.zeros((n, room)), np.zeros(len(mesh.faces), np.int64))


def make_workspace(mesh: MeshWall) -> tuple[np.ndarray, ...]:
    """The workspaces of :func:`sphere_mesh_rows` for ``mesh`` (one set per thread): stamp
    (T,) int64 at −1, tris (T,) int64, cand_q (T,3), cand_d (T,), cand_f (T,) int64."""
    n = len(mesh.faces)
    return (np.full(n, -1, np.int64), np.empty(n, np.int64), np.empty((n, 3)), np.empty(n),
            np.empty(n, np.int64))


def sphere_contacts(mesh: MeshWall, x: np.ndarray, r: float, R: np.ndarray | None = None,
                    t: np.ndarray | None = None, capacity: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """The contact rows (rows_f (K,NF), rows_i (K,NI)) of a sphere (centre x (3,) m, radius r
    m) with ``mesh`` at pose (R, t) (identity by default): :func:`sphere_mesh_rows` with its
    workspaces, for one query from Python."""
    R = np.eye(3) if R is None else np.ascontiguousarray(R, float)
    t = np.zeros(3) if t is None else np.ascontiguousarray(t, float)
    work = make_workspace(mesh)
    while True:
        rows_f = np.zeros((capacity, NF))
        rows_i = np.zeros((capacity, NI), np.int64)
        n = sphere_mesh_rows(np.ascontiguousarray(x, float), float(r), R, t, mesh.vertices,
                             mesh.faces, mesh.normals, mesh.two_sided, mesh.size,
                             mesh.grid_origin, mesh.grid_cell, mesh.grid_dims, mesh.cell_start,
                             mesh.cell_tris, *work[:1], 0, *work[1:], rows_f, rows_i)
        if n <= capacity:
            return rows_f[:n], rows_i[:n]
        capacity = n
        work[0][:] = -1

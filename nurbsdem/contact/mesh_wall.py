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
:mod:`nurbsdem.contact.analytic`).

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


@dataclass(frozen=True)
class MeshWall:
    """A triangle mesh in its own frame with its broad-phase grid.

    vertices (V,3) m; faces (T,3) vertex indices (counter-clockwise seen from the front);
    normals (T,3) unit front normals; grid_origin (3,) m and grid_cell (m) the grid's corner
    and cell edge; grid_dims (3,) cells per axis; cell_start (C+1,), cell_tris: the triangles
    whose bounding box touches cell k are ``cell_tris[cell_start[k]:cell_start[k+1]]``
    (cells numbered x fastest); two_sided: both faces act; size (m) the bounding-box diagonal.
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
                   dims: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """CSR arrays (cell_start, cell_tris) of the triangles whose bounding box touches each
    cell."""
    lo = np.floor((vertices[faces].min(axis=1) - origin) / cell).astype(np.int64)
    hi = np.floor((vertices[faces].max(axis=1) - origin) / cell).astype(np.int64)
    lo = np.clip(lo, 0, dims - 1)
    hi = np.clip(hi, 0, dims - 1)
    cells, tris = [], []
    for t in range(len(faces)):
        ix, iy, iz = (np.arange(lo[t, k], hi[t, k] + 1) for k in range(3))
        gx, gy, gz = np.meshgrid(ix, iy, iz, indexing="ij")
        ids = (gx + dims[0] * (gy + dims[1] * gz)).ravel()
        cells.append(ids)
        tris.append(np.full(ids.shape, t, np.int64))
    cells_a = np.concatenate(cells)
    tris_a = np.concatenate(tris)
    order = np.argsort(cells_a, kind="stable")
    n_cells = int(np.prod(dims))
    start = np.zeros(n_cells + 1, np.int64)
    np.add.at(start, cells_a + 1, 1)
    return np.cumsum(start), tris_a[order]


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
    start, tris = _bin_triangles(vertices, faces, origin, cell, dims)
    return MeshWall(vertices, faces, np.ascontiguousarray(normals), origin, cell, dims,
                    start, tris, bool(two_sided), size)


# ---------------------------------------------------------------------------- closest points


@njit(cache=True, inline="always")
def _dot(x0, x1, x2, y0, y1, y2):
    return x0 * y0 + x1 * y1 + x2 * y2


@njit(cache=True)
def closest_on_triangle(p: np.ndarray, a: np.ndarray, b: np.ndarray,
                        c: np.ndarray) -> tuple[float, float, float, int]:
    """Closest point (x, y, z) of triangle (a, b, c) to p (each (3,), m) and the feature that
    holds it (``FACE``, ``EDGE_AB`` ..., ``VERTEX_A`` ...): the Voronoi regions of the
    vertices, then of the edges, then the face (Ericson 5.1.5)."""
    ab0, ab1, ab2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    ac0, ac1, ac2 = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    ap0, ap1, ap2 = p[0] - a[0], p[1] - a[1], p[2] - a[2]
    d1 = _dot(ab0, ab1, ab2, ap0, ap1, ap2)
    d2 = _dot(ac0, ac1, ac2, ap0, ap1, ap2)
    if d1 <= 0.0 and d2 <= 0.0:
        return a[0], a[1], a[2], VERTEX_A
    bp0, bp1, bp2 = p[0] - b[0], p[1] - b[1], p[2] - b[2]
    d3 = _dot(ab0, ab1, ab2, bp0, bp1, bp2)
    d4 = _dot(ac0, ac1, ac2, bp0, bp1, bp2)
    if d3 >= 0.0 and d4 <= d3:
        return b[0], b[1], b[2], VERTEX_B
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return a[0] + v * ab0, a[1] + v * ab1, a[2] + v * ab2, EDGE_AB
    cp0, cp1, cp2 = p[0] - c[0], p[1] - c[1], p[2] - c[2]
    d5 = _dot(ab0, ab1, ab2, cp0, cp1, cp2)
    d6 = _dot(ac0, ac1, ac2, cp0, cp1, cp2)
    if d6 >= 0.0 and d5 <= d6:
        return c[0], c[1], c[2], VERTEX_C
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return a[0] + w * ac0, a[1] + w * ac1, a[2] + w * ac2, EDGE_CA
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return (b[0] + w * (c[0] - b[0]), b[1] + w * (c[1] - b[1]), b[2] + w * (c[2] - b[2]),
                EDGE_BC)
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return (a[0] + ab0 * v + ac0 * w, a[1] + ab1 * v + ac1 * w, a[2] + ab2 * v + ac2 * w, FACE)


@njit(cache=True, inline="always")
def _feature_vertices(faces: np.ndarray, t: int, feature: int) -> tuple[int, int]:
    """The mesh vertices of a triangle's feature: (-1, -1) for the face, (i, j) for an edge,
    (i, -1) for a vertex."""
    if feature == FACE:
        return -1, -1
    if feature == EDGE_AB:
        return faces[t, 0], faces[t, 1]
    if feature == EDGE_BC:
        return faces[t, 1], faces[t, 2]
    if feature == EDGE_CA:
        return faces[t, 2], faces[t, 0]
    return faces[t, feature - VERTEX_A], -1


@njit(cache=True, inline="always")
def _holds(faces: np.ndarray, s: int, i: int, j: int) -> bool:
    """Whether triangle s has the vertex i and (when j >= 0) the vertex j."""
    has_i = faces[s, 0] == i or faces[s, 1] == i or faces[s, 2] == i
    if j < 0:
        return has_i
    return has_i and (faces[s, 0] == j or faces[s, 1] == j or faces[s, 2] == j)


# ---------------------------------------------------------------------------- broad phase


@njit(cache=True)
def triangles_near(x: np.ndarray, reach: float, grid_origin: np.ndarray, grid_cell: float,
                   grid_dims: np.ndarray, cell_start: np.ndarray, cell_tris: np.ndarray,
                   stamp: np.ndarray, mark: int, out: np.ndarray) -> int:
    """The triangles whose grid cells meet the box x ± reach (mesh frame, m), each once, into
    ``out``; returns their count.  ``stamp`` (T,) int64 holds the last ``mark`` that took each
    triangle (a new ``mark`` per query: no clearing)."""
    lo = np.empty(3, np.int64)
    hi = np.empty(3, np.int64)
    for k in range(3):
        lo[k] = max(int(math.floor((x[k] - reach - grid_origin[k]) / grid_cell)), 0)
        hi[k] = min(int(math.floor((x[k] + reach - grid_origin[k]) / grid_cell)),
                    grid_dims[k] - 1)
        if lo[k] > hi[k]:
            return 0
    n = 0
    for iz in range(lo[2], hi[2] + 1):
        for iy in range(lo[1], hi[1] + 1):
            for ix in range(lo[0], hi[0] + 1):
                cell = ix + grid_dims[0] * (iy + grid_dims[1] * iz)
                for m in range(cell_start[cell], cell_start[cell + 1]):
                    t = cell_tris[m]
                    if stamp[t] != mark:
                        stamp[t] = mark
                        if n < out.shape[0]:
                            out[n] = t
                        n += 1
    return n


# ---------------------------------------------------------------------------- contacts


@njit(cache=True)
def _triangle_candidates(xm, r, vertices, faces, normals, two_sided, tris, n, cand_q,
                         cand_d, cand_f):
    """Closest point, distance and feature of each listed triangle within r of xm (mesh
    frame); returns how many, compacted to the front of ``tris`` and the ``cand_*`` arrays."""
    k = 0
    for m in range(n):
        t = tris[m]
        q0, q1, q2, feat = closest_on_triangle(xm, vertices[faces[t, 0]], vertices[faces[t, 1]],
                                               vertices[faces[t, 2]])
        e0, e1, e2 = xm[0] - q0, xm[1] - q1, xm[2] - q2
        d = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
        if d >= r:
            continue
        if not two_sided and _dot(e0, e1, e2, normals[t, 0], normals[t, 1], normals[t, 2]) < 0.0:
            continue
        tris[k] = t
        cand_q[k, 0], cand_q[k, 1], cand_q[k, 2] = q0, q1, q2
        cand_d[k] = d
        cand_f[k] = feat
        k += 1
    return k


@njit(cache=True, inline="always")
def _first(s, k, cand_f):
    """Whether candidate s comes before k among contacts that are the same: face points
    first, then by list order (one total order, so that exactly one of them is kept)."""
    fs, fk = cand_f[s] == FACE, cand_f[k] == FACE
    return (fs and not fk) or (fs == fk and s < k)


@njit(cache=True)
def _is_local_minimum(k, faces, tris, cand_q, cand_d, cand_f, n, tie):
    """Whether candidate k is a local minimum of the distance to the mesh, kept once.  Not
    when another candidate has the same point and comes first (:func:`_first`: two triangles
    of a plane that both take a point of their shared edge as their own); a face point is one
    otherwise; an edge or vertex point is not when a triangle around that feature is closer,
    or as close and comes first (module docstring)."""
    fk = cand_f[k]
    i, j = _feature_vertices(faces, tris[k], fk)
    dk = cand_d[k]
    for s in range(n):
        if s == k:
            continue
        e0 = cand_q[s, 0] - cand_q[k, 0]
        e1 = cand_q[s, 1] - cand_q[k, 1]
        e2 = cand_q[s, 2] - cand_q[k, 2]
        if e0 * e0 + e1 * e1 + e2 * e2 <= tie * tie:
            if _first(s, k, cand_f):
                return False
        elif fk != FACE and _holds(faces, tris[s], i, j):
            ds = cand_d[s]
            if ds < dk - tie or (ds <= dk + tie and _first(s, k, cand_f)):
                return False
    return True


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
    xm = np.empty(3)
    for k in range(3):
        xm[k] = (R[0, k] * (x[0] - t[0]) + R[1, k] * (x[1] - t[1]) + R[2, k] * (x[2] - t[2]))
    n = triangles_near(xm, r, grid_origin, grid_cell, grid_dims, cell_start, cell_tris, stamp,
                       mark, tris)
    n = _triangle_candidates(xm, r, vertices, faces, normals, two_sided, tris, n, cand_q,
                             cand_d, cand_f)
    tie = TIE * size
    out = np.int64(0)
    for k in range(n):
        if not _is_local_minimum(k, faces, tris, cand_q, cand_d, cand_f, n, tie):
            continue
        if out < rows_f.shape[0]:
            _contact_row(xm, r, R, t, cand_q[k], cand_d[k], normals[tris[k]],
                         vertices[faces[tris[k], 0]], tris[k], rows_f, rows_i, out)
        out += 1
    return out


@njit(cache=True)
def _contact_row(xm, r, R, t, q, d, face_normal, corner, tri, rows_f, rows_i, j):
    """Row j: the contact of the sphere at xm (mesh frame) with closest point q at distance d
    on the triangle with unit normal ``face_normal`` and a vertex ``corner``, in world
    coordinates (module docstring).  Where q lies on the triangle's plane straight below xm
    (a face point, or an edge or vertex point of a flat region) the normal is the triangle's
    own and q the projection of xm on its plane: the plane's numbers to round-off, whichever
    triangle of the plane holds the contact.  At d = 0 the normal is the front normal
    reversed (the centre on the surface is pushed out of the front)."""
    for k in range(NF):
        rows_f[j, k] = 0.0
    for k in range(NI):
        rows_i[j, k] = 0
    h = ((xm[0] - corner[0]) * face_normal[0] + (xm[1] - corner[1]) * face_normal[1]
         + (xm[2] - corner[2]) * face_normal[2])
    if d > 0.0 and abs(h) >= d * (1.0 - 1e-12):
        s = 1.0 if h > 0.0 else -1.0
        n0, n1, n2 = -s * face_normal[0], -s * face_normal[1], -s * face_normal[2]
        d = abs(h)
        q0 = xm[0] - h * face_normal[0]
        q1 = xm[1] - h * face_normal[1]
        q2 = xm[2] - h * face_normal[2]
    else:
        q0, q1, q2 = q[0], q[1], q[2]
        if d > 0.0:
            n0, n1, n2 = (q0 - xm[0]) / d, (q1 - xm[1]) / d, (q2 - xm[2]) / d
        else:
            n0, n1, n2 = -face_normal[0], -face_normal[1], -face_normal[2]
    for k in range(3):
        rows_f[j, F_N + k] = R[k, 0] * n0 + R[k, 1] * n1 + R[k, 2] * n2
        rows_f[j, F_PB + k] = R[k, 0] * q0 + R[k, 1] * q1 + R[k, 2] * q2 + t[k]
        rows_f[j, F_PA + k] = (R[k, 0] * xm[0] + R[k, 1] * xm[1] + R[k, 2] * xm[2] + t[k]
                               + r * rows_f[j, F_N + k])
    rows_f[j, F_SD] = d - r
    rows_i[j, I_PA] = -1
    rows_i[j, I_PB] = tri
    rows_i[j, I_VALID] = 1
    rows_i[j, I_ACTIVE] = 1


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

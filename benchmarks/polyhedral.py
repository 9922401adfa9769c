"""Polyhedral particles: the standard alternative to exact NURBS contact, for comparison.

A reference for the benchmarks (``bench_facets.py``, ``report.py``) and the tests
(``tests/test_polyhedral.py``), not part of the package: import it as ``polyhedral`` with
``benchmarks/`` on ``sys.path`` (the benchmark scripts run from there; ``tests/conftest.py``
adds it for pytest).

Each particle is replaced by the convex hull of points tessellated from its NURBS surface
(vertices lie *on* the exact surface, so the polyhedron is inscribed: penetrations come out
too small and distances too large, by O(h²) with h the facet size). Contact between two
convex polyhedra is computed by

* **GJK** (Gilbert–Johnson–Keerthi, with van den Bergen's termination test) for the distance
  of separated bodies — closest point of the configuration-space obstacle (CSO, the Minkowski
  difference A − B) to the origin, simplex reduction by Voronoi regions (Ericson, *Real-Time
  Collision Detection*, 5.1.5);
* **EPA** (expanding polytope algorithm) for overlapping bodies — the distance from the origin
  to the CSO boundary, i.e. the maximum penetration depth ``min_{|d|=1} hA(d) + hB(−d)`` (the
  same quantity as the NURBS contact). The polytope
  is expanded by a flood fill of the faces visible from the new support point, starting at the
  face being refined, so the horizon is one closed loop (checked; on a broken horizon the
  best face so far is returned and the status says so).

Support mappings: brute-force maximum over all vertices when the vertex set is given as a
plain array; **hill climbing** over the hull's vertex graph (CSR adjacency from the Qhull
triangulation; a local maximum of a linear function on the edge graph of a convex polytope is
global) when a :class:`Polyhedron` is given, warm-started from the previous support vertex of
the same query. Both are exact for the polytope.

Sign conventions as the NURBS contact result (``docs/conventions.md``): ``signed_distance`` < 0
is minus the penetration depth, > 0 the separation (m); ``normal`` is a unit vector from A
towards B (force on A along −normal); ``point_a``, ``point_b`` are world points (m) on the
two hulls with ``normal · (point_a − point_b) = −signed_distance``.

All iteration counts are bounded (GJK ≤ :data:`GJK_MAX_IT`, EPA ≤ :data:`EPA_MAX_IT`); a
query never loops forever. Tolerances are relative to the bodies' size (``scale``, m).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

GJK_MAX_IT = 128
EPA_MAX_IT = 512

#: status codes returned by the kernel
ST_SEPARATED = 0
ST_PENETRATING = 1
ST_APPROX = 2  # iteration cap hit, broken horizon or degenerate CSO: best estimate returned


# =========================================================================== construction
def polyhedron_from_shape(shape, n: int) -> np.ndarray:
    """Vertices of the polyhedron tessellated from a NURBS shape.

    Each patch is tessellated with
    :func:`nurbsdem.geometry.tessellate.tessellate_patch` (about ``n`` quads per parameter
    direction); points shared by neighbouring patches (edges, corners, poles) are merged.

    Parameters
    ----------
    shape: :class:`~nurbsdem.geometry.shape.Shape` or a sequence of patches.
    n: quads per parameter direction per patch (>= 1).

    Returns
    -------
    vertices: (M, 3) float array, file frame, m (all tessellation points, duplicates removed;
        interior points of flat faces are kept — the hull drops them, see
        :func:`facet_count` and :class:`Polyhedron`).
    """
    from nurbsdem.geometry.tessellate import tessellate_patch

    patches = getattr(shape, "patches", shape)
    pts = np.concatenate([tessellate_patch(p, int(n))[0] for p in patches])
    return dedupe_points(pts)


def dedupe_points(pts: np.ndarray, rel_tol: float = 1e-10) -> np.ndarray:
    """Merge points closer than ``rel_tol`` × (bounding-box diagonal) (first copy kept)."""
    pts = np.asarray(pts, dtype=float).reshape(-1, 3)
    if len(pts) == 0:
        return pts
    from scipy.spatial import cKDTree

    diag = float(np.linalg.norm(pts.max(0) - pts.min(0))) or 1.0
    pairs = cKDTree(pts).query_pairs(rel_tol * diag, output_type="ndarray")
    keep = np.ones(len(pts), bool)
    if len(pairs):
        # drop the later point of each close pair (union of near-duplicates keeps one)
        keep[np.maximum(pairs[:, 0], pairs[:, 1])] = False
    return np.ascontiguousarray(pts[keep])


def facet_count(vertices: np.ndarray) -> int:
    """Number of triangular facets of the convex hull of ``vertices`` (scipy ConvexHull)."""
    from scipy.spatial import ConvexHull

    return int(len(ConvexHull(np.asarray(vertices, float)).simplices))


@dataclass
class Polyhedron:
    """A convex polyhedron prepared for fast support mappings.

    Attributes
    ----------
    vertices: (M, 3) hull vertices only, file frame (m), C-contiguous.
    adj_ptr, adj: CSR vertex adjacency of the hull triangulation (int64 (M+1,), (E,)):
        neighbours of vertex i are ``adj[adj_ptr[i]:adj_ptr[i+1]]``.
    n_facets: number of triangular hull facets.
    centroid: mean of the hull vertices (m), used for the initial GJK direction.
    scale: max distance of a vertex from ``centroid`` (m), sets the tolerances.
    """

    vertices: np.ndarray
    adj_ptr: np.ndarray
    adj: np.ndarray
    n_facets: int
    centroid: np.ndarray
    scale: float

    @classmethod
    def from_vertices(cls, vertices: np.ndarray) -> "Polyhedron":
        """Convex hull of the points (scipy/Qhull, triangulated) and its vertex graph."""
        from scipy.spatial import ConvexHull

        pts = np.asarray(vertices, dtype=float).reshape(-1, 3)
        hull = ConvexHull(pts)
        hv = np.asarray(hull.vertices, np.int64)
        remap = -np.ones(len(pts), np.int64)
        remap[hv] = np.arange(len(hv))
        tri = remap[hull.simplices]
        e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
        e = np.concatenate([e, e[:, ::-1]])
        e = np.unique(e, axis=0)  # sorted by first column
        ptr = np.zeros(len(hv) + 1, np.int64)
        np.add.at(ptr, e[:, 0] + 1, 1)
        ptr = np.cumsum(ptr)
        v = np.ascontiguousarray(pts[hv])
        c = v.mean(0)
        return cls(v, ptr, np.ascontiguousarray(e[:, 1]), int(len(tri)), c,
                   float(np.linalg.norm(v - c, axis=1).max()))

    @classmethod
    def from_shape(cls, shape, n: int) -> "Polyhedron":
        """Tessellate a NURBS shape (:func:`polyhedron_from_shape`) and build the hull."""
        return cls.from_vertices(polyhedron_from_shape(shape, n))

    @property
    def n_vertices(self) -> int:
        return int(len(self.vertices))


# =========================================================================== kernels
@njit(cache=True)
def _support_vertex(verts, ptr, adj, dx, dy, dz, hint):
    """Index of a vertex maximising d·v (file-frame d). Brute force when ``ptr`` is empty,
    otherwise steepest-ascent hill climbing from ``hint`` over the hull's vertex graph."""
    M = verts.shape[0]
    if ptr.shape[0] == 0:
        best = -np.inf
        bi = 0
        for i in range(M):
            s = verts[i, 0] * dx + verts[i, 1] * dy + verts[i, 2] * dz
            if s > best:
                best = s
                bi = i
        return bi
    cur = hint if 0 <= hint < M else 0
    best = verts[cur, 0] * dx + verts[cur, 1] * dy + verts[cur, 2] * dz
    for _ in range(M):
        nxt = -1
        nb = best
        for k in range(ptr[cur], ptr[cur + 1]):
            j = adj[k]
            s = verts[j, 0] * dx + verts[j, 1] * dy + verts[j, 2] * dz
            if s > nb:
                nb = s
                nxt = j
        if nxt < 0:
            break
        cur = nxt
        best = nb
    return cur


@njit(cache=True)
def _cso_support(va, pa_ptr, pa_adj, pos_a, Ra, vb, pb_ptr, pb_adj, pos_b, Rb,
                 dx, dy, dz, hints, out_a, out_b):
    """Support point of A − B in world direction d: writes s_A(d) into out_a and s_B(−d)
    into out_b (world, m); returns the vertex indices (ia, ib). ``hints`` (2,) is updated."""
    # file-frame directions: R^T d and -R^T d
    ax = Ra[0, 0] * dx + Ra[1, 0] * dy + Ra[2, 0] * dz
    ay = Ra[0, 1] * dx + Ra[1, 1] * dy + Ra[2, 1] * dz
    az = Ra[0, 2] * dx + Ra[1, 2] * dy + Ra[2, 2] * dz
    bx = -(Rb[0, 0] * dx + Rb[1, 0] * dy + Rb[2, 0] * dz)
    by = -(Rb[0, 1] * dx + Rb[1, 1] * dy + Rb[2, 1] * dz)
    bz = -(Rb[0, 2] * dx + Rb[1, 2] * dy + Rb[2, 2] * dz)
    ia = _support_vertex(va, pa_ptr, pa_adj, ax, ay, az, hints[0])
    ib = _support_vertex(vb, pb_ptr, pb_adj, bx, by, bz, hints[1])
    hints[0] = ia
    hints[1] = ib
    for r in range(3):
        out_a[r] = pos_a[r] + Ra[r, 0] * va[ia, 0] + Ra[r, 1] * va[ia, 1] + Ra[r, 2] * va[ia, 2]
        out_b[r] = pos_b[r] + Rb[r, 0] * vb[ib, 0] + Rb[r, 1] * vb[ib, 1] + Rb[r, 2] * vb[ib, 2]
    return ia, ib


@njit(cache=True)
def _seg(W, i, j):
    """Barycentric weights (li, lj) of the point of segment W[i]W[j] closest to the origin."""
    ex = W[j, 0] - W[i, 0]
    ey = W[j, 1] - W[i, 1]
    ez = W[j, 2] - W[i, 2]
    ee = ex * ex + ey * ey + ez * ez
    if ee <= 0.0:
        return 1.0, 0.0
    t = -(W[i, 0] * ex + W[i, 1] * ey + W[i, 2] * ez) / ee
    if t <= 0.0:
        return 1.0, 0.0
    if t >= 1.0:
        return 0.0, 1.0
    return 1.0 - t, t


@njit(cache=True)
def _d2(W, i, li, j, lj, k, lk):
    x = li * W[i, 0] + lj * W[j, 0] + lk * W[k, 0]
    y = li * W[i, 1] + lj * W[j, 1] + lk * W[k, 1]
    z = li * W[i, 2] + lj * W[j, 2] + lk * W[k, 2]
    return x * x + y * y + z * z


@njit(cache=True)
def _tri(W, i, j, k):
    """Barycentric weights of the point of triangle W[i]W[j]W[k] closest to the origin
    (Ericson 5.1.5 with p = 0; a degenerate triangle falls back to its best edge)."""
    abx = W[j, 0] - W[i, 0]
    aby = W[j, 1] - W[i, 1]
    abz = W[j, 2] - W[i, 2]
    acx = W[k, 0] - W[i, 0]
    acy = W[k, 1] - W[i, 1]
    acz = W[k, 2] - W[i, 2]
    d1 = -(abx * W[i, 0] + aby * W[i, 1] + abz * W[i, 2])
    d2 = -(acx * W[i, 0] + acy * W[i, 1] + acz * W[i, 2])
    if d1 <= 0.0 and d2 <= 0.0:
        return 1.0, 0.0, 0.0
    d3 = -(abx * W[j, 0] + aby * W[j, 1] + abz * W[j, 2])
    d4 = -(acx * W[j, 0] + acy * W[j, 1] + acz * W[j, 2])
    if d3 >= 0.0 and d4 <= d3:
        return 0.0, 1.0, 0.0
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        den = d1 - d3
        v = d1 / den if den > 0.0 else 0.0
        return 1.0 - v, v, 0.0
    d5 = -(abx * W[k, 0] + aby * W[k, 1] + abz * W[k, 2])
    d6 = -(acx * W[k, 0] + acy * W[k, 1] + acz * W[k, 2])
    if d6 >= 0.0 and d5 <= d6:
        return 0.0, 0.0, 1.0
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        den = d2 - d6
        w = d2 / den if den > 0.0 else 0.0
        return 1.0 - w, 0.0, w
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        den = (d4 - d3) + (d5 - d6)
        w = (d4 - d3) / den if den > 0.0 else 0.0
        return 0.0, 1.0 - w, w
    den = va + vb + vc
    ab2 = abx * abx + aby * aby + abz * abz
    ac2 = acx * acx + acy * acy + acz * acz
    if den <= 1e-14 * ab2 * ac2:  # collinear: best of the three edges
        a0, a1 = _seg(W, i, j)
        b0, b1 = _seg(W, j, k)
        c0, c1 = _seg(W, i, k)
        da = _d2(W, i, a0, j, a1, k, 0.0)
        db = _d2(W, i, 0.0, j, b0, k, b1)
        dc = _d2(W, i, c0, j, 0.0, k, c1)
        if da <= db and da <= dc:
            return a0, a1, 0.0
        if db <= dc:
            return 0.0, b0, b1
        return c0, 0.0, c1
    v = vb / den
    w = vc / den
    return 1.0 - v - w, v, w


@njit(cache=True)
def _tet(W, lam, scale):
    """Closest point of tetrahedron W[0..3] to the origin: fills ``lam`` (4,), returns True
    when the origin is inside (or on the boundary of) a non-degenerate tetrahedron."""
    faces = ((0, 1, 2, 3), (0, 1, 3, 2), (0, 2, 3, 1), (1, 2, 3, 0))
    # degenerate (flat) tetrahedron: only the faces count
    e1x = W[1, 0] - W[0, 0]
    e1y = W[1, 1] - W[0, 1]
    e1z = W[1, 2] - W[0, 2]
    e2x = W[2, 0] - W[0, 0]
    e2y = W[2, 1] - W[0, 1]
    e2z = W[2, 2] - W[0, 2]
    e3x = W[3, 0] - W[0, 0]
    e3y = W[3, 1] - W[0, 1]
    e3z = W[3, 2] - W[0, 2]
    vol = (e1y * e2z - e1z * e2y) * e3x + (e1z * e2x - e1x * e2z) * e3y + \
        (e1x * e2y - e1y * e2x) * e3z
    flat = abs(vol) <= 1e-13 * scale * scale * scale
    best = np.inf
    for f in range(4):
        i, j, k, m = faces[f]
        abx = W[j, 0] - W[i, 0]
        aby = W[j, 1] - W[i, 1]
        abz = W[j, 2] - W[i, 2]
        acx = W[k, 0] - W[i, 0]
        acy = W[k, 1] - W[i, 1]
        acz = W[k, 2] - W[i, 2]
        nx = aby * acz - abz * acy
        ny = abz * acx - abx * acz
        nz = abx * acy - aby * acx
        sp = -(nx * W[i, 0] + ny * W[i, 1] + nz * W[i, 2])
        sm = nx * (W[m, 0] - W[i, 0]) + ny * (W[m, 1] - W[i, 1]) + nz * (W[m, 2] - W[i, 2])
        if flat or sp * sm < 0.0:
            li, lj, lk = _tri(W, i, j, k)
            d = _d2(W, i, li, j, lj, k, lk)
            if d < best:
                best = d
                for r in range(4):
                    lam[r] = 0.0
                lam[i] = li
                lam[j] = lj
                lam[k] = lk
    if best == np.inf:  # origin inside (no face separates it)
        for r in range(4):
            lam[r] = 0.25
        return True
    return False


@njit(cache=True)
def _bary_face(V, i, j, k, px, py, pz):
    """Barycentric weights of the point of triangle V[i]V[j]V[k] closest to p."""
    T = np.empty((3, 3))
    for r in range(3):
        T[0, r] = V[i, r]
        T[1, r] = V[j, r]
        T[2, r] = V[k, r]
    T[0, 0] -= px
    T[1, 0] -= px
    T[2, 0] -= px
    T[0, 1] -= py
    T[1, 1] -= py
    T[2, 1] -= py
    T[0, 2] -= pz
    T[1, 2] -= pz
    T[2, 2] -= pz
    return _tri(T, 0, 1, 2)


@njit(cache=True)
def _face_plane(V, a, b, c, nrm, dist, f, tiny):
    """Outward unit normal and origin distance of face (a, b, c) (counter-clockwise)."""
    abx = V[b, 0] - V[a, 0]
    aby = V[b, 1] - V[a, 1]
    abz = V[b, 2] - V[a, 2]
    acx = V[c, 0] - V[a, 0]
    acy = V[c, 1] - V[a, 1]
    acz = V[c, 2] - V[a, 2]
    nx = aby * acz - abz * acy
    ny = abz * acx - abx * acz
    nz = abx * acy - aby * acx
    ln = math.sqrt(nx * nx + ny * ny + nz * nz)
    if ln <= tiny:
        nrm[f, 0] = 0.0
        nrm[f, 1] = 0.0
        nrm[f, 2] = 0.0
        dist[f] = np.inf  # never chosen, never visible
        return
    nx /= ln
    ny /= ln
    nz /= ln
    nrm[f, 0] = nx
    nrm[f, 1] = ny
    nrm[f, 2] = nz
    dist[f] = (nx * (V[a, 0] + V[b, 0] + V[c, 0]) + ny * (V[a, 1] + V[b, 1] + V[c, 1])
               + nz * (V[a, 2] + V[b, 2] + V[c, 2])) / 3.0


@njit(cache=True)
def contact_kernel(va, pa_ptr, pa_adj, ca, pos_a, Ra, vb, pb_ptr, pb_adj, cb, pos_b, Rb,
                   scale, out):
    """GJK distance + EPA penetration of two convex vertex sets in world poses.

    Parameters
    ----------
    va, vb: (M, 3) vertices, file frames (m). pa_ptr/pa_adj, pb_ptr/pb_adj: CSR vertex
        adjacency for hill climbing, or empty arrays for brute-force support.
    ca, cb: a point inside each body (file frame, m), for the first search direction.
    pos_a, Ra, pos_b, Rb: poses, x_world = pos + R @ x_file.
    scale: body size (m) for the tolerances.
    out: (10,) float, filled with signed distance (m), normal (3), point_a (3), point_b (3).

    Returns
    -------
    (iterations (GJK + EPA), status) — status :data:`ST_SEPARATED`, :data:`ST_PENETRATING`
    or :data:`ST_APPROX`.
    """
    hints = np.zeros(2, np.int64)
    sa = np.empty(3)
    sb = np.empty(3)
    W = np.empty((4, 3))
    PA = np.empty((4, 3))
    PB = np.empty((4, 3))
    IA = np.empty(4, np.int64)
    IB = np.empty(4, np.int64)
    lam = np.zeros(4)
    # ---------------------------------------------------------------- GJK
    dx = dy = dz = 0.0
    for r in range(3):
        wa = pos_a[r] + Ra[r, 0] * ca[0] + Ra[r, 1] * ca[1] + Ra[r, 2] * ca[2]
        wb = pos_b[r] + Rb[r, 0] * cb[0] + Rb[r, 1] * cb[1] + Rb[r, 2] * cb[2]
        if r == 0:
            dx = wb - wa
        elif r == 1:
            dy = wb - wa
        else:
            dz = wb - wa
    if dx * dx + dy * dy + dz * dz <= (1e-12 * scale) ** 2:
        dx, dy, dz = 1.0, 0.0, 0.0
    ia, ib = _cso_support(va, pa_ptr, pa_adj, pos_a, Ra, vb, pb_ptr, pb_adj, pos_b, Rb,
                          dx, dy, dz, hints, sa, sb)
    k = 1
    for r in range(3):
        PA[0, r] = sa[r]
        PB[0, r] = sb[r]
        W[0, r] = sa[r] - sb[r]
    IA[0] = ia
    IB[0] = ib
    vx, vy, vz = W[0, 0], W[0, 1], W[0, 2]
    wpa = PA[0].copy()
    wpb = PB[0].copy()
    touch = 1e-10 * scale
    overlap = False
    status = ST_SEPARATED
    it = 0
    while it < GJK_MAX_IT:
        it += 1
        vv = vx * vx + vy * vy + vz * vz
        if vv <= touch * touch:
            overlap = True
            break
        ia, ib = _cso_support(va, pa_ptr, pa_adj, pos_a, Ra, vb, pb_ptr, pb_adj, pos_b, Rb,
                              -vx, -vy, -vz, hints, sa, sb)
        wx = sa[0] - sb[0]
        wy = sa[1] - sb[1]
        wz = sa[2] - sb[2]
        vw = vx * wx + vy * wy + vz * wz
        if vv - vw <= 1e-12 * vv + 1e-14 * scale * math.sqrt(vv):
            break  # |v| is the distance to within tolerance
        dup = False
        for q in range(k):
            if IA[q] == ia and IB[q] == ib:
                dup = True
        if dup:
            break
        PA[k, 0] = sa[0]
        PA[k, 1] = sa[1]
        PA[k, 2] = sa[2]
        PB[k, 0] = sb[0]
        PB[k, 1] = sb[1]
        PB[k, 2] = sb[2]
        W[k, 0] = wx
        W[k, 1] = wy
        W[k, 2] = wz
        IA[k] = ia
        IB[k] = ib
        k += 1
        # closest point of the simplex, barycentric weights
        for q in range(4):
            lam[q] = 0.0
        if k == 2:
            lam[0], lam[1] = _seg(W, 0, 1)
        elif k == 3:
            lam[0], lam[1], lam[2] = _tri(W, 0, 1, 2)
        else:
            if _tet(W, lam, scale):
                overlap = True
                break
        # compact the simplex to the vertices with non-zero weight
        m = 0
        nvx = nvy = nvz = 0.0
        for q in range(k):
            if lam[q] > 0.0:
                for r in range(3):
                    W[m, r] = W[q, r]
                    PA[m, r] = PA[q, r]
                    PB[m, r] = PB[q, r]
                IA[m] = IA[q]
                IB[m] = IB[q]
                lam[m] = lam[q]
                nvx += lam[q] * W[q, 0]
                nvy += lam[q] * W[q, 1]
                nvz += lam[q] * W[q, 2]
                m += 1
        k = m
        nvv = nvx * nvx + nvy * nvy + nvz * nvz
        if nvv >= vv:
            break  # no progress (rounding): keep the previous estimate
        vx, vy, vz = nvx, nvy, nvz
        for r in range(3):
            wpa[r] = 0.0
            wpb[r] = 0.0
            for q in range(k):
                wpa[r] += lam[q] * PA[q, r]
                wpb[r] += lam[q] * PB[q, r]
    if not overlap:
        d = math.sqrt(vx * vx + vy * vy + vz * vz)
        out[0] = d
        out[1] = -vx / d
        out[2] = -vy / d
        out[3] = -vz / d
        for r in range(3):
            out[4 + r] = wpa[r]
            out[7 + r] = wpb[r]
        if it >= GJK_MAX_IT:
            status = ST_APPROX
        return it, status
    # ---------------------------------------------------------------- EPA
    capv = EPA_MAX_IT + 8
    capf = 2 * EPA_MAX_IT + 16
    V = np.empty((capv, 3))
    VA = np.empty((capv, 3))
    VB = np.empty((capv, 3))
    VIA = np.empty(capv, np.int64)
    VIB = np.empty(capv, np.int64)
    for q in range(k):
        for r in range(3):
            V[q, r] = W[q, r]
            VA[q, r] = PA[q, r]
            VB[q, r] = PB[q, r]
        VIA[q] = IA[q]
        VIB[q] = IB[q]
    nv = k
    # blow a lower-dimensional simplex (touching contact) up to a tetrahedron
    eps_aff = 1e-9 * scale
    cand = np.empty((8, 3))
    tries = 0
    while nv < 4 and tries < 4:
        tries += 1
        nc = 0
        if nv == 1:
            for ax in range(3):
                cand[2 * ax, 0] = 0.0
                cand[2 * ax, 1] = 0.0
                cand[2 * ax, 2] = 0.0
                cand[2 * ax, ax] = 1.0
                cand[2 * ax + 1, 0] = 0.0
                cand[2 * ax + 1, 1] = 0.0
                cand[2 * ax + 1, 2] = 0.0
                cand[2 * ax + 1, ax] = -1.0
            nc = 6
        elif nv == 2:
            ex = V[1, 0] - V[0, 0]
            ey = V[1, 1] - V[0, 1]
            ez = V[1, 2] - V[0, 2]
            ax = 0
            if abs(ey) <= abs(ex) and abs(ey) <= abs(ez):
                ax = 1
            elif abs(ez) <= abs(ex) and abs(ez) <= abs(ey):
                ax = 2
            ux, uy, uz = 0.0, 0.0, 0.0
            if ax == 0:
                ux, uy, uz = 0.0, ez, -ey      # e x (1,0,0)
            elif ax == 1:
                ux, uy, uz = -ez, 0.0, ex      # e x (0,1,0)
            else:
                ux, uy, uz = ey, -ex, 0.0      # e x (0,0,1)
            tx = ey * uz - ez * uy
            ty = ez * ux - ex * uz
            tz = ex * uy - ey * ux
            cand[0, 0], cand[0, 1], cand[0, 2] = ux, uy, uz
            cand[1, 0], cand[1, 1], cand[1, 2] = -ux, -uy, -uz
            cand[2, 0], cand[2, 1], cand[2, 2] = tx, ty, tz
            cand[3, 0], cand[3, 1], cand[3, 2] = -tx, -ty, -tz
            nc = 4
        else:
            e1x = V[1, 0] - V[0, 0]
            e1y = V[1, 1] - V[0, 1]
            e1z = V[1, 2] - V[0, 2]
            e2x = V[2, 0] - V[0, 0]
            e2y = V[2, 1] - V[0, 1]
            e2z = V[2, 2] - V[0, 2]
            cand[0, 0] = e1y * e2z - e1z * e2y
            cand[0, 1] = e1z * e2x - e1x * e2z
            cand[0, 2] = e1x * e2y - e1y * e2x
            cand[1, 0] = -cand[0, 0]
            cand[1, 1] = -cand[0, 1]
            cand[1, 2] = -cand[0, 2]
            nc = 2
        added = False
        for c in range(nc):
            ia, ib = _cso_support(va, pa_ptr, pa_adj, pos_a, Ra, vb, pb_ptr, pb_adj,
                                  pos_b, Rb, cand[c, 0], cand[c, 1], cand[c, 2], hints, sa, sb)
            wx = sa[0] - sb[0]
            wy = sa[1] - sb[1]
            wz = sa[2] - sb[2]
            # distance of w from the affine hull of the current points
            if nv == 1:
                ddx = wx - V[0, 0]
                ddy = wy - V[0, 1]
                ddz = wz - V[0, 2]
                off = math.sqrt(ddx * ddx + ddy * ddy + ddz * ddz)
            elif nv == 2:
                ex = V[1, 0] - V[0, 0]
                ey = V[1, 1] - V[0, 1]
                ez = V[1, 2] - V[0, 2]
                ddx = wx - V[0, 0]
                ddy = wy - V[0, 1]
                ddz = wz - V[0, 2]
                cx = ey * ddz - ez * ddy
                cy = ez * ddx - ex * ddz
                cz = ex * ddy - ey * ddx
                off = math.sqrt(cx * cx + cy * cy + cz * cz) / max(
                    math.sqrt(ex * ex + ey * ey + ez * ez), 1e-300)
            else:
                nn = math.sqrt(cand[0, 0] ** 2 + cand[0, 1] ** 2 + cand[0, 2] ** 2)
                off = abs(cand[0, 0] * (wx - V[0, 0]) + cand[0, 1] * (wy - V[0, 1])
                          + cand[0, 2] * (wz - V[0, 2])) / max(nn, 1e-300)
            if off > eps_aff:
                for r in range(3):
                    VA[nv, r] = sa[r]
                    VB[nv, r] = sb[r]
                V[nv, 0] = wx
                V[nv, 1] = wy
                V[nv, 2] = wz
                VIA[nv] = ia
                VIB[nv] = ib
                nv += 1
                added = True
                break
        if not added:
            break
    if nv < 4:  # flat CSO (degenerate bodies): touching, no usable normal
        out[0] = 0.0
        dn = math.sqrt(dx * dx + dy * dy + dz * dz)
        out[1] = dx / dn
        out[2] = dy / dn
        out[3] = dz / dn
        for r in range(3):
            out[4 + r] = VA[0, r]
            out[7 + r] = VB[0, r]
        return it, ST_APPROX
    # orient the tetrahedron: face (0,1,2) must have its normal away from vertex 3
    e1x = V[1, 0] - V[0, 0]
    e1y = V[1, 1] - V[0, 1]
    e1z = V[1, 2] - V[0, 2]
    e2x = V[2, 0] - V[0, 0]
    e2y = V[2, 1] - V[0, 1]
    e2z = V[2, 2] - V[0, 2]
    s3 = (e1y * e2z - e1z * e2y) * (V[3, 0] - V[0, 0]) + \
        (e1z * e2x - e1x * e2z) * (V[3, 1] - V[0, 1]) + (e1x * e2y - e1y * e2x) * (V[3, 2] - V[0, 2])
    if s3 > 0.0:
        for r in range(3):
            t = V[1, r]
            V[1, r] = V[2, r]
            V[2, r] = t
            t = VA[1, r]
            VA[1, r] = VA[2, r]
            VA[2, r] = t
            t = VB[1, r]
            VB[1, r] = VB[2, r]
            VB[2, r] = t
        ti = VIA[1]
        VIA[1] = VIA[2]
        VIA[2] = ti
        ti = VIB[1]
        VIB[1] = VIB[2]
        VIB[2] = ti
    F = np.empty((capf, 3), np.int64)
    ADJ = np.empty((capf, 3), np.int64)
    NRM = np.empty((capf, 3))
    DIST = np.empty(capf)
    ALIVE = np.zeros(capf, np.bool_)
    MARK = np.zeros(capf, np.int64)  # +stamp visible, -stamp tested not visible
    init = ((0, 1, 2), (0, 3, 1), (0, 2, 3), (1, 3, 2))
    tiny = 1e-300
    for f in range(4):
        F[f, 0], F[f, 1], F[f, 2] = init[f]
        ALIVE[f] = True
        _face_plane(V, F[f, 0], F[f, 1], F[f, 2], NRM, DIST, f, tiny)
    for f in range(4):
        for e in range(3):
            a = F[f, e]
            b = F[f, (e + 1) % 3]
            for g in range(4):
                if g != f:
                    for e2 in range(3):
                        if F[g, e2] == b and F[g, (e2 + 1) % 3] == a:
                            ADJ[f, e] = g
    nf = 4
    free = np.empty(capf, np.int64)
    nfree = 0
    hor_f = np.empty(capf, np.int64)   # visible face of each horizon edge
    hor_a = np.empty(capf, np.int64)   # edge start / end vertex
    hor_b = np.empty(capf, np.int64)
    hor_h = np.empty(capf, np.int64)   # the hidden face across the edge
    hor_new = np.empty(capf, np.int64)
    stack = np.empty(capf, np.int64)
    vis_list = np.empty(capf, np.int64)
    tol = 1e-11 * scale
    eps_vis = 1e-13 * scale
    best = 0
    status = ST_PENETRATING
    epa_it = 0
    converged = False
    while epa_it < EPA_MAX_IT:
        epa_it += 1
        best = -1
        bd = np.inf
        for f in range(nf):
            if ALIVE[f] and DIST[f] < bd:
                bd = DIST[f]
                best = f
        if best < 0:
            break
        nx, ny, nz = NRM[best, 0], NRM[best, 1], NRM[best, 2]
        ia, ib = _cso_support(va, pa_ptr, pa_adj, pos_a, Ra, vb, pb_ptr, pb_adj, pos_b, Rb,
                              nx, ny, nz, hints, sa, sb)
        wx = sa[0] - sb[0]
        wy = sa[1] - sb[1]
        wz = sa[2] - sb[2]
        if nx * wx + ny * wy + nz * wz - bd <= tol:
            converged = True
            break
        dup = False
        for q in range(nv):
            if VIA[q] == ia and VIB[q] == ib:
                dup = True
                break
        if dup:
            converged = True  # w is already a vertex: the face lies on the CSO boundary
            break
        if nv >= capv:
            break
        # flood fill of the faces visible from w, starting at the face being refined
        stamp = epa_it
        MARK[best] = stamp
        ns = 1
        stack[0] = best
        nvis = 0
        nh = 0
        while ns > 0:
            ns -= 1
            g = stack[ns]
            vis_list[nvis] = g
            nvis += 1
            for e in range(3):
                h = ADJ[g, e]
                if MARK[h] == stamp:
                    continue
                if MARK[h] != -stamp:
                    p0 = F[h, 0]
                    s = NRM[h, 0] * (wx - V[p0, 0]) + NRM[h, 1] * (wy - V[p0, 1]) + \
                        NRM[h, 2] * (wz - V[p0, 2])
                    if s > eps_vis:
                        MARK[h] = stamp
                        stack[ns] = h
                        ns += 1
                        continue
                    MARK[h] = -stamp
                hor_f[nh] = g
                hor_a[nh] = F[g, e]
                hor_b[nh] = F[g, (e + 1) % 3]
                hor_h[nh] = h
                nh += 1
        # the horizon must be one closed loop: each edge end starts exactly one other edge
        ok = nh >= 3
        if ok:
            for q in range(nh):
                cnt = 0
                for p in range(nh):
                    if hor_a[p] == hor_b[q]:
                        cnt += 1
                if cnt != 1:
                    ok = False
                    break
        if not ok or nh > nfree + nvis + (capf - nf):
            break  # broken horizon (rounding) or out of room: keep the best face so far
        # new vertex
        for r in range(3):
            VA[nv, r] = sa[r]
            VB[nv, r] = sb[r]
        V[nv, 0] = wx
        V[nv, 1] = wy
        V[nv, 2] = wz
        VIA[nv] = ia
        VIB[nv] = ib
        wi = nv
        nv += 1
        # retire visible faces
        for q in range(nvis):
            ALIVE[vis_list[q]] = False
            free[nfree] = vis_list[q]
            nfree += 1
        # one new face per horizon edge
        full = False
        for q in range(nh):
            if nfree > 0:
                nfree -= 1
                fn = free[nfree]
            else:
                if nf >= capf:
                    full = True
                    break
                fn = nf
                nf += 1
            g = hor_f[q]
            a = hor_a[q]
            b = hor_b[q]
            h = hor_h[q]
            F[fn, 0] = a
            F[fn, 1] = b
            F[fn, 2] = wi
            ALIVE[fn] = True
            MARK[fn] = 0
            _face_plane(V, a, b, wi, NRM, DIST, fn, tiny)
            ADJ[fn, 0] = h
            for e2 in range(3):
                if ADJ[h, e2] == g and F[h, e2] == b:
                    ADJ[h, e2] = fn
            hor_new[q] = fn
        if full:  # cannot happen (room checked above); stop with the best face
            break
        # link the new faces around the apex: edge 1 (b, w) meets edge 2 (w, b) of the next
        for q in range(nh):
            fq = hor_new[q]
            b = F[fq, 1]
            for p in range(nh):
                fp = hor_new[p]
                if F[fp, 0] == b:
                    ADJ[fq, 1] = fp
                    ADJ[fp, 2] = fq
                    break
    if not converged:
        status = ST_APPROX
        # pick the best live face
        best = -1
        bd = np.inf
        for f in range(nf):
            if ALIVE[f] and DIST[f] < bd:
                bd = DIST[f]
                best = f
    d = DIST[best]
    nx, ny, nz = NRM[best, 0], NRM[best, 1], NRM[best, 2]
    i0, i1, i2 = F[best, 0], F[best, 1], F[best, 2]
    l0, l1, l2 = _bary_face(V, i0, i1, i2, nx * d, ny * d, nz * d)
    out[0] = -d
    out[1] = nx
    out[2] = ny
    out[3] = nz
    for r in range(3):
        out[4 + r] = l0 * VA[i0, r] + l1 * VA[i1, r] + l2 * VA[i2, r]
        out[7 + r] = l0 * VB[i0, r] + l1 * VB[i1, r] + l2 * VB[i2, r]
    return it + epa_it, status


# =========================================================================== public API
_EMPTY = np.zeros(0, np.int64)


def _prep(v) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    if isinstance(v, Polyhedron):
        return v.vertices, v.adj_ptr, v.adj, v.centroid, v.scale
    arr = np.ascontiguousarray(np.asarray(v, dtype=float).reshape(-1, 3))
    if len(arr) == 0:
        raise ValueError("empty vertex set")
    c = arr.mean(0)
    return arr, _EMPTY, _EMPTY, c, float(np.linalg.norm(arr - c, axis=1).max())


def _pose(pose) -> tuple[np.ndarray, np.ndarray]:
    pos, R = pose
    return (np.ascontiguousarray(np.asarray(pos, dtype=float).reshape(3)),
            np.ascontiguousarray(np.asarray(R, dtype=float).reshape(3, 3)))


def polyhedral_contact(verts_a: "np.ndarray | Polyhedron", pose_a, verts_b: "np.ndarray | Polyhedron",
                       pose_b, return_status: bool = False):
    """Contact of two convex polyhedra by GJK (distance) and EPA (penetration).

    Parameters
    ----------
    verts_a, verts_b: (M, 3) vertex arrays in the file frames (m) — brute-force support over
        all vertices — or :class:`Polyhedron` objects (hull vertices, hill-climbing support).
    pose_a, pose_b: (position (3,) m, rotation (3, 3)); x_world = position + R @ x_file.
    return_status: also return the status code (:data:`ST_SEPARATED`, :data:`ST_PENETRATING`,
        :data:`ST_APPROX`).

    Returns
    -------
    (signed_distance, normal, point_a, point_b, iterations[, status]):
    signed_distance (m): < 0 minus the penetration depth (distance from the origin to the
    boundary of the Minkowski difference), > 0 the separation; normal: unit (3,), from A
    towards B; point_a, point_b: world points (m) on the hulls of A and B with
    ``normal · (point_a − point_b) = −signed_distance``; iterations: GJK + EPA iterations.
    """
    va, pa_ptr, pa_adj, ca, sca = _prep(verts_a)
    vb, pb_ptr, pb_adj, cb, scb = _prep(verts_b)
    pos_a, Ra = _pose(pose_a)
    pos_b, Rb = _pose(pose_b)
    out = np.empty(10)
    it, st = contact_kernel(va, pa_ptr, pa_adj, ca, pos_a, Ra, vb, pb_ptr, pb_adj, cb, pos_b, Rb,
                            max(sca, scb, 1e-300), out)
    res = (float(out[0]), out[1:4].copy(), out[4:7].copy(), out[7:10].copy(), int(it))
    return res + (int(st),) if return_status else res


@njit(cache=True)
def _batch(va, pa_ptr, pa_adj, ca, vb, pb_ptr, pb_adj, cb, pos_a, rot_a, pos_b, rot_b, scale,
           out, its, sts):
    for q in range(pos_a.shape[0]):
        it, st = contact_kernel(va, pa_ptr, pa_adj, ca, pos_a[q], rot_a[q], vb, pb_ptr, pb_adj,
                                cb, pos_b[q], rot_b[q], scale, out[q])
        its[q] = it
        sts[q] = st


def polyhedral_contact_batch(poly_a: "np.ndarray | Polyhedron", pos_a: np.ndarray,
                             rot_a: np.ndarray, poly_b: "np.ndarray | Polyhedron",
                             pos_b: np.ndarray, rot_b: np.ndarray):
    """K queries of the same two polyhedra in compiled code (serial; for timing the kernel
    without Python overhead).

    Parameters: pos_a, pos_b (K, 3) m; rot_a, rot_b (K, 3, 3).

    Returns
    -------
    (out (K, 10): signed distance, normal (3), point_a (3), point_b (3);
     iterations (K,) int64; status (K,) int64).
    """
    va, pa_ptr, pa_adj, ca, sca = _prep(poly_a)
    vb, pb_ptr, pb_adj, cb, scb = _prep(poly_b)
    K = len(pos_a)
    pos_a = np.ascontiguousarray(pos_a, float).reshape(K, 3)
    pos_b = np.ascontiguousarray(pos_b, float).reshape(K, 3)
    rot_a = np.ascontiguousarray(rot_a, float).reshape(K, 3, 3)
    rot_b = np.ascontiguousarray(rot_b, float).reshape(K, 3, 3)
    out = np.empty((K, 10))
    its = np.empty(K, np.int64)
    sts = np.empty(K, np.int64)
    _batch(va, pa_ptr, pa_adj, ca, vb, pb_ptr, pb_adj, cb, pos_a, rot_a, pos_b, rot_b,
           max(sca, scb, 1e-300), out, its, sts)
    return out, its, sts

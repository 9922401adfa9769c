"""A convex NURBS particle against a triangle-mesh wall, compiled: the contacts of
:func:`~nurbsdem.contact.mesh_particle.particle_mesh_contacts` (its module docstring states
the problem: one contact per face, edge and vertex region, their normal cones and the ties)
in one kernel per particle and mesh.

The support point p_A(d) and dp/dd (paper Eq. 8–9, 14–15) come from the flat-wall kernel
exactly as the surface-wall kernel asks it
(:func:`~nurbsdem.contact.surface_particle_compiled._support`: the plane through the
centroid with normal −d, each query warm-started from the previous converged one); a face
contact is the flat-wall kernel against the triangle's own plane.  The queries come in the
reference's order (the distinct face normals in sorted order, the faces, the edges, the
vertices), so the rows agree with the Python solve to round-off.

The mesh's edges and vertices that are not flat (those whose normal cone has an interior)
are packed once per mesh as *features*
(:func:`~nurbsdem.contact.mesh_topology.pack_topology`): ``feat`` (F, 4) int64 rows (v0,
v1, start, end), an edge (v0 < v1) or a vertex (v1 = −1) and the range of its triangles in
``feat_tris``; ``tri_feat_range`` (T, 2) the range in ``tri_feat`` of each triangle's
features (its edges, then its vertices).

:func:`particle_mesh_into` solves one particle against one mesh in three parts: the start
(the pose in the mesh frame, :func:`_near`: the triangles within reach, :func:`_may_hold`:
the faces that may hold the contact), the iterations of each feature (:func:`_face`,
:func:`_edge`, :func:`_vertex`, in :func:`_features`'s order) and the result
(:func:`_distinct`, :func:`_rows`), over one tuple of named workspaces
(:data:`MeshParticleWork`).  :func:`particle_mesh_rows` runs the particles of one mesh
in one call (the Python provider and the compiled deck steps).  Lengths in metres.
"""
from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
from numba import njit

from ..jit import PointerKernel, kernel
from .lcp import F_N, F_PA, F_PAR, F_PB, F_SD, I_ACTIVE, I_FAIL, I_IT, I_PA, I_PB, I_VALID, NF, NI
from .mesh_particle import (ARC_SAMPLES, DEEPER, ITERATED_TIE, MAX_IT, MAX_TURN, MIN_ARC,
                            TOL)
from .mesh_topology import (crosses_beyond_border, deepest_of_a_border_edge, inward_normal,
                            pack_topology)
from .mesh_wall import EDGE_AB, FACE, TIE, VERTEX_A, MeshWall, _triangle_candidates, triangles_near
from .surface_particle_compiled import (_C, _D, _M, _P, _POS, _start as _pose_start, _support,
                                        make_surface_work)
from .flat_wall import solve_wall_ptr

#: columns of a candidate's float row: sd, the particle's point p, the wall's point q, the
#: normal d (particle to wall), all in the mesh frame
_SD, _CP, _CQ, _CD = 0, 1, 4, 7
CF_COLS = 10
#: columns of a candidate's int row: feature kind (FACE, EDGE_AB, VERTEX_A), triangle,
#: iterations
_FEAT, _TRI, _IT = 0, 1, 2
#: rows of the vector workspace ``mv``: a face query's origin and edges; an edge's basis e1,
#: e2, direction t and the derivative direction dd; a vertex's tangent basis u1, u2; sums of
#: facing normals
_O, _EA, _EB, _E1, _E2, _T, _DD, _U1, _U2, _S = range(10)
MV_ROWS = 10


#: the workspaces of :func:`particle_mesh_into` (T triangles, F features, C = T + F): the
#: support mapping's sv (:func:`make_surface_work`); the broad phase's stamp (T,) (−1),
#: query mark (1,), tris (T,), cand_q (T,3), cand_d (T,), cand_f (T,); per near triangle its
#: facing normal facing (T,3), whether it may hold the contact hold (T,) and its distinct
#: normal's index key (T,); the distinct normals' keys dkey (T,3), first triangle drep (T,),
#: order dord (T,) and support points dp (T,3); the features' stamp fstamp (F,) (−1) and
#: list flist (F,); the candidates' rows cf (C,10), ci (C,3) and keep (C,); the in-plane
#: inward normals of an edge's triangles inward (T,3); vectors mv (10,3)
MeshParticleWork = namedtuple("MeshParticleWork", "sv stamp mark tris cand_q cand_d cand_f "
                              "facing hold key dkey drep dord dp fstamp flist cf ci keep "
                              "inward mv")


@njit(cache=True)
def make_mesh_particle_work(n_tris, n_feat):
    """The :data:`MeshParticleWork` of :func:`particle_mesh_into` for a mesh of ``n_tris``
    triangles and ``n_feat`` features (one per thread)."""
    T, F = n_tris, n_feat
    C = T + F
    i8 = np.int64
    return MeshParticleWork(
        make_surface_work(0), np.full(T, -1, i8), np.zeros(1, i8), np.empty(T, i8),
        np.empty((T, 3)), np.empty(T), np.empty(T, i8), np.empty((T, 3)), np.empty(T, np.bool_),
        np.empty(T, i8), np.empty((T, 3)), np.empty(T, i8), np.empty(T, i8), np.empty((T, 3)),
        np.full(F, -1, i8), np.empty(F, i8), np.empty((C, CF_COLS)), np.empty((C, 3), i8),
        np.empty(C, np.bool_), np.empty((T, 3)), np.zeros((MV_ROWS, 3)))


# --------------------------------------------------------------------------- small helpers
@kernel(inline="always")
def _dot(x, y):
    return x[0] * y[0] + x[1] * y[1] + x[2] * y[2]


@kernel(inline="always")
def _dot_diff(d, x, y):
    """d · (x − y)."""
    return d[0] * (x[0] - y[0]) + d[1] * (x[1] - y[1]) + d[2] * (x[2] - y[2])


@kernel(inline="always")
def _quad(M, x):
    """xᵀ M x."""
    s = 0.0
    for r in range(3):
        s += x[r] * (M[r, 0] * x[0] + M[r, 1] * x[1] + M[r, 2] * x[2])
    return s


@kernel(inline="always")
def _bilinear(M, x, y):
    """xᵀ M y."""
    s = 0.0
    for r in range(3):
        s += x[r] * (M[r, 0] * y[0] + M[r, 1] * y[1] + M[r, 2] * y[2])
    return s


@kernel
def _point(tab, info, cen, rad, seeds, sv, d0, d1, d2):
    """The support point along the unit (d0, d1, d2) (mesh frame) into sw[_P], dp/dd into
    sw[_M:_M+3]; whether it converged (:func:`_support`)."""
    sw = sv[5]
    sw[_D, 0], sw[_D, 1], sw[_D, 2] = d0, d1, d2
    return _support(tab, info, cen, rad, seeds, sv)


@kernel
def _separated(tab, info, cen, rad, seeds, sv, d0, d1, d2, x, y):
    """Whether the support plane along the unit d has the points x and y beyond it (pass x
    twice for one point)."""
    ok = _point(tab, info, cen, rad, seeds, sv, d0, d1, d2)
    sw = sv[5]
    h = d0 * sw[_P, 0] + d1 * sw[_P, 1] + d2 * sw[_P, 2]
    return (ok and d0 * x[0] + d1 * x[1] + d2 * x[2] > h
            and d0 * y[0] + d1 * y[1] + d2 * y[2] > h)


@kernel(inline="always")
def _facing_into(c, vertices, faces, normals, tri, out):
    """The unit normal of triangle ``tri`` on the side of the point c into out."""
    a = vertices[faces[tri, 0]]
    s = 1.0 if _dot_diff(normals[tri], c, a) >= 0.0 else -1.0
    for k in range(3):
        out[k] = s * normals[tri, k]


@kernel(inline="always")
def _facing_sum(c, vertices, faces, normals, feat_tris, t0, t1, out):
    """The sum of the facing normals of triangles feat_tris[t0:t1] into out."""
    out[0] = out[1] = out[2] = 0.0
    for m in range(t0, t1):
        tri = feat_tris[m]
        a = vertices[faces[tri, 0]]
        s = 1.0 if _dot_diff(normals[tri], c, a) >= 0.0 else -1.0
        for k in range(3):
            out[k] += s * normals[tri, k]


@kernel(inline="always")
def _put(cf, ci, n, sd, p, q, d0, d1, d2, feat, tri, it):
    """Candidate n: (sd, p, q, d, feat, tri, it)."""
    cf[n, _SD] = sd
    for k in range(3):
        cf[n, _CP + k] = p[k]
        cf[n, _CQ + k] = q[k]
    cf[n, _CD], cf[n, _CD + 1], cf[n, _CD + 2] = d0, d1, d2
    ci[n, _FEAT], ci[n, _TRI], ci[n, _IT] = feat, tri, it


# --------------------------------------------------------------------------- start
@kernel
def _near(rad, vertices, faces, normals, two_sided, grid_origin, grid_cell, grid_dims,
          cell_start, cell_tris, work):
    """The triangles within ``rad`` of the centroid (the reference's ``_near_triangles``)
    compacted to the front of work's tris; returns their count."""
    sv, stamp, mark, tris = work.sv, work.stamp, work.mark, work.tris
    c = sv[5][_C]
    mark[0] += 1
    n = triangles_near(c, rad, grid_origin, grid_cell, grid_dims, cell_start, cell_tris, stamp,
                       mark[0], tris)
    n = _triangle_candidates(c, rad, vertices, faces, normals, True, tris, min(n, tris.shape[0]),
                             work.cand_q, work.cand_d, work.cand_f)
    if two_sided:
        return n
    k = 0
    for m in range(n):
        tri = tris[m]
        if _dot_diff(normals[tri], c, vertices[faces[tri, 0]]) >= 0.0:
            tris[k] = tri
            k += 1
    return k


@kernel(inline="always")
def _key_less(dkey, a, b):
    """Whether distinct key a sorts before b (lexicographic)."""
    for k in range(3):
        if dkey[a, k] != dkey[b, k]:
            return dkey[a, k] < dkey[b, k]
    return False


@kernel
def _may_hold(tab, info, cen, rad, seeds, vertices, faces, normals, size, n, work):
    """Per near triangle m < n, whether the deepest point below its plane may project into
    it (the reference's ``_may_hold``): the support point along each distinct facing normal
    (rounded to 1e-9, asked in sorted order), projected within 1e-8 of the mesh size."""
    sv, tris, facing, hold, key = work.sv, work.tris, work.facing, work.hold, work.key
    dkey, drep, dord, dp = work.dkey, work.drep, work.dord, work.dp
    c = sv[5][_C]
    nd = 0
    for m in range(n):
        _facing_into(c, vertices, faces, normals, tris[m], facing[m])
        j = 0
        while j < nd:
            if (dkey[j, 0] == np.rint(facing[m, 0] * 1e9)
                    and dkey[j, 1] == np.rint(facing[m, 1] * 1e9)
                    and dkey[j, 2] == np.rint(facing[m, 2] * 1e9)):
                break
            j += 1
        if j == nd:
            for k in range(3):
                dkey[nd, k] = np.rint(facing[m, k] * 1e9)
            drep[nd] = m
            dord[nd] = nd
            nd += 1
        key[m] = j
    for a in range(1, nd):                        # insertion sort of the keys
        b = a
        while b > 0 and _key_less(dkey, dord[b], dord[b - 1]):
            dord[b - 1], dord[b] = dord[b], dord[b - 1]
            b -= 1
    sw = sv[5]
    for r in range(nd):
        j = dord[r]
        f = facing[drep[j]]
        _point(tab, info, cen, rad, seeds, sv, -f[0], -f[1], -f[2])
        for k in range(3):
            dp[j, k] = sw[_P, k]
    margin = 1e-8 * size
    for m in range(n):
        tri = tris[m]
        p, f = dp[key[m]], facing[m]
        ok = True
        for k in range(3):
            x = vertices[faces[tri, k]]
            y = vertices[faces[tri, (k + 1) % 3]]
            z = vertices[faces[tri, (k + 2) % 3]]
            e0, e1, e2 = y[0] - x[0], y[1] - x[1], y[2] - x[2]
            w0 = f[1] * e2 - f[2] * e1                 # in-plane, normal to edge (x, y)
            w1 = f[2] * e0 - f[0] * e2
            w2 = f[0] * e1 - f[1] * e0
            s = 1.0 if w0 * (z[0] - x[0]) + w1 * (z[1] - x[1]) + w2 * (z[2] - x[2]) > 0.0 else -1.0
            w0, w1, w2 = s * w0, s * w1, s * w2
            lhs = (p[0] - x[0]) * w0 + (p[1] - x[1]) * w1 + (p[2] - x[2]) * w2
            ok = ok and lhs >= -margin * math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
        hold[m] = ok


# --------------------------------------------------------------------------- iterations
@kernel
def _face(tab, info, cen, rad, seeds, vertices, faces, normals, feat, tri_feat_range,
          tri_feat, tri, work, nc):
    """The face contact of triangle ``tri`` (the reference's ``_face``: the flat-wall kernel
    against its plane, normal towards the particle, and its border test) as candidate nc;
    returns the new count."""
    sv, mv, cf, ci = work.sv, work.mv, work.cf, work.ci
    ws, wf, wi, wfs, no_mask, sw, rw, wdom, _, prev_f, prev_i, qf, qi, _, _ = sv
    a, b, c = vertices[faces[tri, 0]], vertices[faces[tri, 1]], vertices[faces[tri, 2]]
    front = _dot_diff(normals[tri], sw[_C], a) >= 0.0
    for k in range(3):
        mv[_O, k] = a[k]
        mv[_EA, k] = (b[k] if front else c[k]) - a[k]
        mv[_EB, k] = (c[k] if front else b[k]) - a[k]
    solve_wall_ptr(tab, info, cen, rad, seeds, sw[_POS], rw, mv[_O], mv[_EA], mv[_EB], wdom,
                   prev_f, prev_i, ws, wf, wi, wfs, no_mask, qf, qi)
    if qi[I_VALID] == 1 and qi[I_FAIL] == 0:      # the next query's warm start
        for k in range(qf.shape[0]):
            prev_f[k] = qf[k]
        for k in range(qi.shape[0]):
            prev_i[k] = qi[k]
    al, be = qf[F_PAR + 2], qf[F_PAR + 3]
    if not (qi[I_VALID] == 1 and al >= 0.0 and be >= 0.0 and al + be <= 1.0):
        return nc
    if crosses_beyond_border(vertices, faces, normals, feat, tri_feat_range, tri_feat, tri,
                             sw[_C], qf[F_PA:F_PA + 3]):
        return nc
    _put(cf, ci, nc, qf[F_SD], qf[F_PA:F_PA + 3], qf[F_PB:F_PB + 3], qf[F_N], qf[F_N + 1],
         qf[F_N + 2], FACE, tri, 1)
    return nc + 1


@kernel
def _edge_slope(tab, info, cen, rad, seeds, sv, mv, p0, th):
    """(g, h, ok) of the edge's f(θ) = h_A(d(θ)) − d(θ) · P0: f' = (p − P0) · d',
    f'' = d'ᵀ (dp/dd) d' − (p − P0) · d, with d(θ) = cos θ e1 + sin θ e2 (in sw[_D]) and p
    in sw[_P]."""
    cs, sn = math.cos(th), math.sin(th)
    for k in range(3):
        mv[_DD, k] = -sn * mv[_E1, k] + cs * mv[_E2, k]
    ok = _point(tab, info, cen, rad, seeds, sv, cs * mv[_E1, 0] + sn * mv[_E2, 0],
                cs * mv[_E1, 1] + sn * mv[_E2, 1], cs * mv[_E1, 2] + sn * mv[_E2, 2])
    sw = sv[5]
    p, d, dd = sw[_P], sw[_D], mv[_DD]
    g = _dot_diff(dd, p, p0)
    h = _quad(sw[_M:_M + 3], dd) - _dot_diff(d, p, p0)
    return g, h, ok


@kernel(inline="always")
def _least_in_arc(tab, info, cen, rad, seeds, sv, mv, p0, lo, hi):
    """(found, lo, hi, f): the samples around the least f over ARC_SAMPLES intervals of
    [lo, hi] and that f (the reference's sampling in ``_edge``), found where f' changes sign
    across them."""
    sw = sv[5]
    best, kbest, g_before, g_after, g_prev = math.inf, -1, 0.0, 0.0, 0.0
    for k in range(ARC_SAMPLES + 1):
        g = _edge_slope(tab, info, cen, rad, seeds, sv, mv, p0,
                        lo + k * (hi - lo) / ARC_SAMPLES)[0]
        f = _dot_diff(sw[_D], sw[_P], p0)
        if k == kbest + 1:
            g_after = g
        if f < best:
            best, kbest = f, k
            g_before = g_prev if k > 0 else g
            g_after = g                       # k the last sample: its own
        g_prev = g
    a, b = max(kbest - 1, 0), min(kbest + 1, ARC_SAMPLES)
    if not g_before < 0.0 < g_after:
        return False, lo, hi, best
    return True, lo + a * (hi - lo) / ARC_SAMPLES, lo + b * (hi - lo) / ARC_SAMPLES, best


@kernel(inline="always")
def _edge_newton(tab, info, cen, rad, seeds, sv, mv, p0, lo, hi, tol):
    """(converged, iterations) of the safeguarded Newton on f'(θ) = 0 in [lo, hi] (the
    reference's ``_edge_root``); the root's p and d are left in the support workspace."""
    th = 0.5 * (lo + hi)
    it = 0
    for it in range(MAX_IT):
        g, h, ok = _edge_slope(tab, info, cen, rad, seeds, sv, mv, p0, th)
        if not ok:
            return False, it
        if abs(g) <= tol:
            return True, it
        if g < 0.0:
            lo = th
        else:
            hi = th
        step = th - g / h if h > 0.0 else 0.5 * (lo + hi)
        th = step if lo < step < hi else 0.5 * (lo + hi)
        if hi - lo < 1e-15:
            return True, it
    return False, it


@kernel(inline="always")
def _keep_root(sw, mv, p0):
    """Keep an edge root's p and d (in the support workspace) in mv's rows U1, U2 (free while
    an edge is solved); returns its f = d · (p − P0)."""
    for k in range(3):
        mv[_U1, k] = sw[_P, k]
        mv[_U2, k] = sw[_D, k]
    return _dot_diff(sw[_D], sw[_P], p0)


@kernel
def _edge_arc(vertices, faces, feat_tris, t0, t1, i, j, work):
    """(L, lo, hi): the length (m) of edge (i, j), its direction t and a basis e1, e2 of the
    plane normal to it (mv), and the arc [lo, hi] (rad) of its normal cone (the reference's
    ``_edge_arc``, from the in-plane inward normals of its triangles feat_tris[t0:t1])."""
    mv, inward = work.mv, work.inward
    p0, p1 = vertices[i], vertices[j]
    L = math.sqrt((p1[0] - p0[0]) ** 2 + (p1[1] - p0[1]) ** 2 + (p1[2] - p0[2]) ** 2)
    t = mv[_T]
    for k in range(3):
        t[k] = (p1[k] - p0[k]) / L
    for m in range(t0, t1):                  # the edge's inward normal in each triangle
        tri = feat_tris[m]
        o = faces[tri, 0]
        for k in range(3):                   # the vertex that is neither end
            if faces[tri, k] != i and faces[tri, k] != j:
                o = faces[tri, k]
        w = inward[m - t0]
        w[0], w[1], w[2] = inward_normal(p0, t[0], t[1], t[2], vertices[o])
    e1, e2 = mv[_E1], mv[_E2]
    for k in range(3):
        e1[k] = inward[0, k]
    e2[0] = t[1] * e1[2] - t[2] * e1[1]
    e2[1] = t[2] * e1[0] - t[0] * e1[2]
    e2[2] = t[0] * e1[1] - t[1] * e1[0]
    lo, hi = -0.5 * math.pi, 0.5 * math.pi
    for m in range(1, t1 - t0):
        phi = math.atan2(_dot(inward[m], e2), _dot(inward[m], e1))
        lo, hi = max(lo, phi - 0.5 * math.pi), min(hi, phi + 0.5 * math.pi)
    return L, lo, hi


@kernel
def _edge(tab, info, cen, rad, seeds, vertices, faces, normals, feat_tris, t0, t1, i, j,
          active_only, work, nc):
    """The contact of edge (i, j) with triangles feat_tris[t0:t1] (the reference's ``_edge``
    and its side test: a safeguarded Newton on f'(θ) = 0 inside the normal arc) as candidate
    nc; returns the new count."""
    sv, mv, cf, ci = work.sv, work.mv, work.cf, work.ci
    sw = sv[5]
    L, lo, hi = _edge_arc(vertices, faces, feat_tris, t0, t1, i, j, work)
    if hi - lo < MIN_ARC:
        return nc
    p0, p1 = vertices[i], vertices[j]
    e1, e2 = mv[_E1], mv[_E2]
    if active_only:
        cm, sm = math.cos(0.5 * (lo + hi)), math.sin(0.5 * (lo + hi))
        if _separated(tab, info, cen, rad, seeds, sv, cm * e1[0] + sm * e2[0],
                      cm * e1[1] + sm * e2[1], cm * e1[2] + sm * e2[2], p0, p1):
            return nc
    g_lo = _edge_slope(tab, info, cen, rad, seeds, sv, mv, p0, lo)[0]
    f_lo = _dot_diff(sw[_D], sw[_P], p0)
    g_hi = _edge_slope(tab, info, cen, rad, seeds, sv, mv, p0, hi)[0]
    f_hi = _dot_diff(sw[_D], sw[_P], p0)
    tol = TOL * rad
    found, it, f_root = False, 0, math.inf
    if g_lo < 0.0 and g_hi > 0.0:
        found, it = _edge_newton(tab, info, cen, rad, seeds, sv, mv, p0, lo, hi, tol)
        if found:
            f_root = _keep_root(sw, mv, p0)
    if f_lo > 0.0 and f_hi > 0.0:                  # the particle may reach over the line
        other, a_lo, a_hi, f_least = _least_in_arc(tab, info, cen, rad, seeds, sv, mv, p0,
                                                   lo, hi)
        if other and (not found or f_least < f_root - DEEPER * rad):
            other, it2 = _edge_newton(tab, info, cen, rad, seeds, sv, mv, p0, a_lo, a_hi, tol)
            if other and (not found or _dot_diff(sw[_D], sw[_P], p0) < f_root):
                found, it = True, it2
                f_root = _keep_root(sw, mv, p0)
    if not found:
        return nc
    p, d, q = mv[_U1], mv[_U2], mv[_O]
    s = _dot_diff(mv[_T], p, p0)
    if s < 0.0 or s > L:
        return nc
    for k in range(3):
        q[k] = p0[k] + s * mv[_T, k]
    _facing_sum(sw[_C], vertices, faces, normals, feat_tris, t0, t1, mv[_S])
    if t1 - t0 > 1 and not _dot(d, mv[_S]) < 0.0:
        return nc
    _put(cf, ci, nc, _dot_diff(d, q, p), p, q, d[0], d[1], d[2], EDGE_AB, feat_tris[t0], it)
    return nc + 1


@kernel(inline="always")
def _tangent_basis(d0, d1, d2, u1, u2):
    """u1, u2 completing the unit d to an orthonormal basis (the reference's)."""
    ad = (abs(d0), abs(d1), abs(d2))
    k = 0
    if ad[1] < ad[k]:
        k = 1
    if ad[2] < ad[k]:
        k = 2
    dk = (d0, d1, d2)[k]
    u1[0], u1[1], u1[2] = -d0 * dk, -d1 * dk, -d2 * dk
    u1[k] += 1.0
    nu = math.sqrt(u1[0] * u1[0] + u1[1] * u1[1] + u1[2] * u1[2])
    u1[0], u1[1], u1[2] = u1[0] / nu, u1[1] / nu, u1[2] / nu
    u2[0] = d1 * u1[2] - d2 * u1[1]
    u2[1] = d2 * u1[0] - d0 * u1[2]
    u2[2] = d0 * u1[1] - d1 * u1[0]


@kernel
def _vertex_newton(tab, info, cen, rad, seeds, V, d0, d1, d2, work):
    """(found, λ, iterations) of the point V against the particle (the reference's
    ``_vertex``): a Newton on the tangent components of p_A(d) − V from the unit d, with the
    Jacobian (dp/dd)_t − λ I, steepest-descent turns where that is not positive definite;
    found: converged to a minimum, with p in sw[_P], d in sw[_D]."""
    sv, mv = work.sv, work.mv
    sw = sv[5]
    u1, u2 = mv[_U1], mv[_U2]
    tol = TOL * rad
    for it in range(MAX_IT):
        if not _point(tab, info, cen, rad, seeds, sv, d0, d1, d2):
            return False, 0.0, it
        p, M = sw[_P], sw[_M:_M + 3]
        r0, r1, r2 = p[0] - V[0], p[1] - V[1], p[2] - V[2]
        lam = d0 * r0 + d1 * r1 + d2 * r2
        _tangent_basis(d0, d1, d2, u1, u2)
        f0 = u1[0] * r0 + u1[1] * r1 + u1[2] * r2
        f1 = u2[0] * r0 + u2[1] * r1 + u2[2] * r2
        a = _quad(M, u1) - lam
        c = _quad(M, u2) - lam
        b = 0.5 * (_bilinear(M, u1, u2) + _bilinear(M, u2, u1))
        convex = 0.5 * (a + c) - math.sqrt(0.25 * (a - c) ** 2 + b * b) > 0.0
        if abs(f0) <= tol and abs(f1) <= tol:
            return convex, lam, it                # not convex: a saddle of h_A(d) − d · V
        if convex:
            det = a * c - b * b
            s0 = -(c * f0 - b * f1) / det
            s1 = -(a * f1 - b * f0) / det
        else:                                     # the reference's steepest-descent turn
            g = max(abs(lam), tol)
            s0, s1 = -f0 / g, -f1 / g
        size = math.sqrt(s0 * s0 + s1 * s1)
        if size > MAX_TURN:
            s0, s1 = s0 * MAX_TURN / size, s1 * MAX_TURN / size
        d0, d1, d2 = d0 + s0 * u1[0] + s1 * u2[0], d1 + s0 * u1[1] + s1 * u2[1], \
            d2 + s0 * u1[2] + s1 * u2[2]
        nd = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        d0, d1, d2 = d0 / nd, d1 / nd, d2 / nd
    return False, 0.0, MAX_IT


@kernel(inline="always")
def _in_cone_on_side(vertices, faces, normals, size, feat_tris, t0, t1, v, d, c, s):
    """Whether the contact normal d of vertex v lies in its normal cone over the triangles
    feat_tris[t0:t1] on the side of the particle's centroid c (the reference's
    ``_in_vertex_cone`` and ``_on_particle_side``; s: a 3-vector workspace)."""
    V = vertices[v]
    tol = 1e-12 * size
    for m in range(t0, t1):
        for k in range(3):
            x = faces[feat_tris[m], k]
            if x != v and _dot_diff(d, vertices[x], V) < -tol:
                return False
    _facing_sum(c, vertices, faces, normals, feat_tris, t0, t1, s)
    return _dot(d, s) < 0.0


@kernel
def _vertex(tab, info, cen, rad, seeds, vertices, faces, normals, size, feat, feat_tris,
            tri_feat_range, tri_feat, t0, t1, v, active_only, work, nc):
    """The contact of vertex v with triangles feat_tris[t0:t1] (the reference's vertex
    branch: Newton from minus the sum of their facing normals, kept in the vertex's normal
    cone on the particle's side, or where v is the deepest point of a boundary edge) as
    candidate nc; returns the new count."""
    sv, mv, cf, ci = work.sv, work.mv, work.cf, work.ci
    sw = sv[5]
    V = vertices[v]
    s = mv[_S]
    _facing_sum(sw[_C], vertices, faces, normals, feat_tris, t0, t1, s)
    ns = math.sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2])
    if not ns > 1e-9:
        return nc
    d0, d1, d2 = -s[0] / ns, -s[1] / ns, -s[2] / ns
    if active_only and _separated(tab, info, cen, rad, seeds, sv, d0, d1, d2, V, V):
        return nc
    nd = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    found, lam, it = _vertex_newton(tab, info, cen, rad, seeds, V, d0 / nd, d1 / nd, d2 / nd,
                                    work)
    if not found:
        return nc
    d = sw[_D]
    if not _in_cone_on_side(vertices, faces, normals, size, feat_tris, t0, t1, v, d, sw[_C], s):
        if not deepest_of_a_border_edge(vertices, faces, feat, tri_feat_range, tri_feat,
                                         feat_tris, t0, t1, v, d):
            return nc
    _put(cf, ci, nc, -lam, sw[_P], V, d[0], d[1], d[2], VERTEX_A, feat_tris[t0], it)
    return nc + 1


@kernel
def _features(tab, info, cen, rad, seeds, vertices, faces, normals, size, feat, feat_tris,
              tri_feat_range, tri_feat, n, active_only, work, nc):
    """The edge, then the vertex contacts of the features of the near triangles (first-seen
    order, the reference's ``_features``) within the particle's reach, appended from
    candidate nc; returns the new count."""
    sv, mark, tris, fstamp, flist = work.sv, work.mark, work.tris, work.fstamp, work.flist
    c = sv[5][_C]
    nf = 0
    for edges in (True, False):
        for m in range(n):
            tri = tris[m]
            for r in range(tri_feat_range[tri, 0], tri_feat_range[tri, 1]):
                f = tri_feat[r]
                if (feat[f, 1] >= 0) == edges and fstamp[f] != mark[0]:
                    fstamp[f] = mark[0]
                    flist[nf] = f
                    nf += 1
    for r in range(nf):
        f = flist[r]
        i, j, t0, t1 = feat[f, 0], feat[f, 1], feat[f, 2], feat[f, 3]
        if j >= 0:
            p0, p1 = vertices[i], vertices[j]
            e0, e1, e2 = p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]
            s = min(max(_dot_diff((e0, e1, e2), c, p0) / (e0 * e0 + e1 * e1 + e2 * e2), 0.0),
                    1.0)
            g0, g1, g2 = c[0] - p0[0] - s * e0, c[1] - p0[1] - s * e1, c[2] - p0[2] - s * e2
            if math.sqrt(g0 * g0 + g1 * g1 + g2 * g2) > rad:
                continue
            nc = _edge(tab, info, cen, rad, seeds, vertices, faces, normals, feat_tris, t0, t1,
                       i, j, active_only, work, nc)
        else:
            V = vertices[i]
            g0, g1, g2 = V[0] - c[0], V[1] - c[1], V[2] - c[2]
            if math.sqrt(g0 * g0 + g1 * g1 + g2 * g2) > rad:
                continue
            nc = _vertex(tab, info, cen, rad, seeds, vertices, faces, normals, size, feat,
                         feat_tris, tri_feat_range, tri_feat, t0, t1, i, active_only, work, nc)
    return nc


# --------------------------------------------------------------------------- result
@kernel
def _distinct(cf, ci, keep, nc, size):
    """keep[k]: candidate k is not at the point of an earlier kept one, faces first (the
    reference's ``_distinct``: within 1e-12 of the mesh size between faces, 1e-9 else)."""
    for k in range(nc):
        keep[k] = False
    for faces_first in (True, False):
        for k in range(nc):
            face = ci[k, _FEAT] == FACE
            if face != faces_first:
                continue
            same = False
            for m in range(nc):
                if not keep[m]:
                    continue
                tie = (TIE if face and ci[m, _FEAT] == FACE else ITERATED_TIE) * size
                e0 = cf[m, _CQ] - cf[k, _CQ]
                e1 = cf[m, _CQ + 1] - cf[k, _CQ + 1]
                e2 = cf[m, _CQ + 2] - cf[k, _CQ + 2]
                if math.sqrt(e0 * e0 + e1 * e1 + e2 * e2) <= tie:
                    same = True
                    break
            keep[k] = not same


@kernel
def _rows(cf, ci, keep, nc, R, t, active_only, rows_f, rows_i):
    """The kept candidates (touching only with ``active_only``) as rows (world frame, normal
    from the particle to the wall), at most rows_f.shape[0]; returns how many there are."""
    n = 0
    for k in range(nc):
        sd = cf[k, _SD]
        if not keep[k] or (active_only and not sd < 0.0):
            continue
        if n < rows_f.shape[0]:
            rf, ri = rows_f[n], rows_i[n]
            for c in range(rf.shape[0]):
                rf[c] = 0.0
            for c in range(ri.shape[0]):
                ri[c] = 0
            rf[F_SD] = sd
            for a in range(3):
                rf[F_N + a] = (R[a, 0] * cf[k, _CD] + R[a, 1] * cf[k, _CD + 1]
                               + R[a, 2] * cf[k, _CD + 2])
                rf[F_PA + a] = (R[a, 0] * cf[k, _CP] + R[a, 1] * cf[k, _CP + 1]
                                + R[a, 2] * cf[k, _CP + 2] + t[a])
                rf[F_PB + a] = (R[a, 0] * cf[k, _CQ] + R[a, 1] * cf[k, _CQ + 1]
                                + R[a, 2] * cf[k, _CQ + 2] + t[a])
            ri[I_PA] = -1
            ri[I_PB] = ci[k, _TRI]
            ri[I_IT] = ci[k, _IT]
            ri[I_VALID] = 1
            ri[I_ACTIVE] = 1 if sd < 0.0 else 0
        n += 1
    return n


@kernel
def particle_mesh_into(tab, info, cen, rad, seeds, pos, Rb, R, t, vertices, faces, normals,
                       two_sided, size, grid_origin, grid_cell, grid_dims, cell_start,
                       cell_tris, feat, feat_tris, tri_feat_range, tri_feat, active_only, work,
                       rows_f, rows_i):
    """The contact rows (rows_f (K,NF), rows_i (K,NI), at most K written) of the NURBS
    particle of table ``tab`` with shape ``info`` (one row of ContactTable.info), centroid
    ``cen`` (3,) m and bounding radius ``rad`` m, at the pose (pos (3,) m, Rb (3,3); world),
    against the mesh of the arrays ``vertices`` … ``cell_tris``
    (:class:`~nurbsdem.contact.mesh_wall.MeshWall`) and ``feat`` … ``tri_feat``
    (:func:`~nurbsdem.contact.mesh_topology.pack_topology`) at (R, t) (``x_world = R x_mesh
    + t``): the rows of :func:`~nurbsdem.contact.mesh_particle.particle_mesh_contacts`, in its
    order (only those with sd < 0 with ``active_only``).  ``work``:
    :func:`make_mesh_particle_work`.  Returns the count of rows (written or not)."""
    sv, cf, ci, keep = work.sv, work.cf, work.ci, work.keep
    _pose_start(pos, Rb, R, t, cen, sv[5], sv[6], sv[10], sv[11], sv[12])
    n = _near(rad, vertices, faces, normals, two_sided, grid_origin, grid_cell, grid_dims,
              cell_start, cell_tris, work)
    if n == 0:
        return 0
    _may_hold(tab, info, cen, rad, seeds, vertices, faces, normals, size, n, work)
    nc = 0
    tris, hold = work.tris, work.hold
    for m in range(n):
        if hold[m]:
            nc = _face(tab, info, cen, rad, seeds, vertices, faces, normals, feat,
                       tri_feat_range, tri_feat, tris[m], work, nc)
    nc = _features(tab, info, cen, rad, seeds, vertices, faces, normals, size, feat, feat_tris,
                   tri_feat_range, tri_feat, n, active_only, work, nc)
    _distinct(cf, ci, keep, nc, size)
    return _rows(cf, ci, keep, nc, R, t, active_only, rows_f, rows_i)


@njit(cache=True)
def particle_mesh_rows(idx, body_shape, pos, rot, R, t, tab, info, cen, rad, seeds, vertices,
                       faces, normals, two_sided, size, grid_origin, grid_cell, grid_dims,
                       cell_start, cell_tris, feat, feat_tris, tri_feat_range, tri_feat, per,
                       work, rows_f, rows_i, owner, rank, count):
    """The touching rows of the NURBS particles ``idx`` (K,) (shapes ``body_shape`` (N,),
    poses pos (N,3) m, rot (N,3,3); the arrays tab … seeds of a
    :class:`~nurbsdem.contact.detect.ContactTable`) against one mesh at (R, t):
    :func:`particle_mesh_into` for each, its first ``per`` rows appended to rows_f (≥ K·per,
    NF), rows_i with their particle in ``owner`` and rank among its rows in ``rank``; their
    count in count[0].  ``work``: a :data:`MeshParticleWork` for at least this mesh's
    triangles and features (kept between calls and meshes: its marks only grow)."""
    n = 0
    for m in range(idx.shape[0]):
        i = idx[m]
        s = body_shape[i]
        k = particle_mesh_into(tab, info[s], cen[s], rad[s], seeds, pos[i], rot[i], R, t,
                               vertices, faces, normals, two_sided, size, grid_origin,
                               grid_cell, grid_dims, cell_start, cell_tris, feat, feat_tris,
                               tri_feat_range, tri_feat, np.bool_(True), work, rows_f[n:n + per],
                               rows_i[n:n + per])
        for j in range(min(k, per)):
            owner[n + j] = i
            rank[n + j] = j
        n += min(k, per)
    count[0] = n


#: :func:`particle_mesh_rows` through a lazy pointer (group "mesh_particles",
#: :func:`~nurbsdem.jit.fill_lazy_kernels`): the compiled deck steps call it for a scene with
#: NURBS particles and mesh walls only
particle_mesh_rows_ptr = PointerKernel(particle_mesh_rows, "particle_mesh_rows",
                                       lazy="mesh_particles").call


def mesh_work(mesh: MeshWall):
    """A :data:`MeshParticleWork` for ``mesh``."""
    return make_mesh_particle_work(len(mesh.faces), len(pack_topology(mesh)[0]))


def mesh_rows(table, mesh: MeshWall, idx: np.ndarray, body_shape: np.ndarray, pos: np.ndarray,
              rot: np.ndarray, R: np.ndarray, t: np.ndarray, per: int,
              work=None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(rows_f, rows_i, owner, rank) of the touching contacts of the NURBS particles ``idx``
    (shapes ``body_shape`` in ``table``, poses pos (N,3) m, rot (N,3,3)) with ``mesh`` at
    (R, t), at most ``per`` each: :func:`particle_mesh_rows` from Python (``work``: the
    mesh's :func:`mesh_work`, made when None)."""
    c = np.ascontiguousarray
    work = mesh_work(mesh) if work is None else work
    K = len(idx)
    rows_f, rows_i = np.zeros((K * per, NF)), np.zeros((K * per, NI), np.int64)
    owner, rank, count = (np.zeros(K * per, np.int64), np.zeros(K * per, np.int64),
                          np.zeros(1, np.int64))
    particle_mesh_rows(c(idx, np.int64), c(body_shape, np.int64), c(pos, float), c(rot, float),
                       c(R, float), c(t, float), table.tab, table.info, table.centroid,
                       table.radius, table.seeds, mesh.vertices, mesh.faces, mesh.normals,
                       mesh.two_sided, float(mesh.size), mesh.grid_origin, mesh.grid_cell,
                       mesh.grid_dims, mesh.cell_start, mesh.cell_tris, *pack_topology(mesh),
                       int(per), work, rows_f, rows_i, owner, rank, count)
    n = int(count[0])
    return rows_f[:n], rows_i[:n], owner[:n], rank[:n]

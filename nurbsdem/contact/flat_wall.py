"""The flat wall kind: a rectangle (a degree-1 NURBS patch with 2×2 control points), its
frame, its test in the broad phase and its pair solvers.

* **Frame** (:func:`wall_geometry`, :func:`wall_frame`): the corner o, the edge vectors a, b
  along u and v, the unit normal n = a × b / |a × b| toward the side where the particles are;
  the rectangle is o + α a + β b, 0 ≤ α, β ≤ 1 (:func:`parallelogram_coordinates`).
* **Broad phase** (:func:`sphere_wall_pairs`, paper Eq. 3 with a wall): body i is near the
  wall when its bounding sphere reaches the rectangle (widened by the skin).
* **An exact sphere** (centre x, radius r; :func:`sphere_wall_row`, the closed form the
  scene's dispatch runs with the sphere–sphere one, :mod:`nurbsdem.contact.sphere`):
  p_A = x − r n, p_B its projection on the plane, signed distance n·(p_A − o).
* **A NURBS particle** (:func:`solve_wall`, :func:`solve_wall_rows`): the deepest point of
  body A below the plane is its support point along −n (paper Eq. 8 with d = −n): one
  support mapping, no direction search; signed_distance = n · (p_A − o), point_b the
  projection of p_A onto the plane.  A warm start begins at the previous support point moved
  to first order by the body's turn since (its du/de and body-frame direction are kept in the
  row: ``lcp._predicted_params``), so that the support mapping usually ends after one
  evaluation.

Either contact is active only where point_b falls inside the rectangle; its normal (from A
towards the wall, docs/conventions.md) is −n, and gap = point_a − point_b satisfies
normal · gap = −signed_distance.  The pair solvers are named in :mod:`nurbsdem.contact.kinds`
(``CLOSED_FORM`` and ``WALL_SUPPORT`` with ``FLAT_WALL``); the wall's ParaView output is the
walls' (:meth:`nurbsdem.io.paraview.ParaViewWriter.write_walls`).

Curved walls: a triangle mesh takes the NURBS particle's kernel per face
(:mod:`nurbsdem.contact.mesh_particle`), an open NURBS surface wall its support mapping along
the wall's normal (:mod:`nurbsdem.contact.surface_particle`).

Lengths in metres. Result rows use the column constants of :mod:`nurbsdem.contact.lcp`;
``I_BROAD`` = 1 when the bounding sphere does not reach the plane, 2 when the deepest point
projects outside the wall rectangle.
"""
from __future__ import annotations

import math

import numpy as np
import numba
from numba import njit, prange

from ..geometry.kernel import make_workspace
from ..jit import PointerKernel, kernel
from .broadphase import _as_centers_radii, _push
from .detect import (PARALLEL_MIN_PAIRS, ContactResult, _pose, _prev_rows, _work,
                     kept_on_failure, next_chunk, table_of)
from .lcp import (F_N, F_PA, F_PAR, F_PB, F_SD, I_ACTIVE, I_BROAD, I_DEG, I_FAIL, I_IT, I_NEV,
                  I_PA, I_PB, I_VALID, NF, NI, clear_row, full_rows, make_work,
                  _predicted_params, _store_prediction)
from .stage2 import _EA, _EV, _EV2, _GA, _H, _MA, _PA, _TMP, _rot_t, _to_world
from .support import CREASE, seed_start, support_map


# --------------------------------------------------------------------------- geometry and a sphere
@njit(cache=True)
def _parallelogram(r0: float, r1: float, r2: float, a0: float, a1: float, a2: float, b0: float,
                   b1: float, b2: float) -> tuple[float, float]:
    """:func:`parallelogram_coordinates` of edge vectors given by their components."""
    aa = a0 * a0 + a1 * a1 + a2 * a2
    ab = a0 * b0 + a1 * b1 + a2 * b2
    bb = b0 * b0 + b1 * b1 + b2 * b2
    ar = a0 * r0 + a1 * r1 + a2 * r2
    br = b0 * r0 + b1 * r1 + b2 * r2
    det = aa * bb - ab * ab
    return (bb * ar - ab * br) / det, (aa * br - ab * ar) / det


@njit(cache=True)
def parallelogram_coordinates(r0: float, r1: float, r2: float, a: np.ndarray,
                              b: np.ndarray) -> tuple[float, float]:
    """Coordinates (α, β) of the in-plane offset r (m) from a wall's corner on its edge
    vectors a, b (3,): r = α a + β b (the 2×2 normal equations); inside when both are in
    [0, 1]."""
    return _parallelogram(r0, r1, r2, a[0], a[1], a[2], b[0], b[1], b[2])


@njit(cache=True)
def sphere_wall_row(x0: float, x1: float, x2: float, r: float, w: int, wall_d: np.ndarray,
                     wall_origin: np.ndarray, wall_a: np.ndarray, wall_b: np.ndarray,
                     wall_dom: np.ndarray, rows_f: np.ndarray, rows_i: np.ndarray,
                     j: int) -> None:
    """One sphere (centre x m, radius r m) against flat wall w (corner wall_origin[w] +
    wall_d[w], edge vectors wall_a[w], wall_b[w], parameter rectangle wall_dom[w]) into row j
    of rows_f, rows_i (zeroed first), in the convention of
    :func:`solve_wall`."""
    clear_row(rows_f, rows_i, j)
    a0, a1, a2 = wall_a[w, 0], wall_a[w, 1], wall_a[w, 2]
    b0, b1, b2 = wall_b[w, 0], wall_b[w, 1], wall_b[w, 2]
    o0 = wall_origin[w, 0] + wall_d[w, 0]
    o1 = wall_origin[w, 1] + wall_d[w, 1]
    o2 = wall_origin[w, 2] + wall_d[w, 2]
    m0 = a1 * b2 - a2 * b1
    m1 = a2 * b0 - a0 * b2
    m2 = a0 * b1 - a1 * b0
    mm = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
    m0, m1, m2 = m0 / mm, m1 / mm, m2 / mm
    rows_f[j, F_N], rows_f[j, F_N + 1], rows_f[j, F_N + 2] = -m0, -m1, -m2
    p0, p1, p2 = x0 - r * m0, x1 - r * m1, x2 - r * m2
    rows_f[j, F_PA], rows_f[j, F_PA + 1], rows_f[j, F_PA + 2] = p0, p1, p2
    sd = m0 * (p0 - o0) + m1 * (p1 - o1) + m2 * (p2 - o2)
    rows_f[j, F_SD] = sd
    q0, q1, q2 = p0 - sd * m0, p1 - sd * m1, p2 - sd * m2
    rows_f[j, F_PB], rows_f[j, F_PB + 1], rows_f[j, F_PB + 2] = q0, q1, q2
    al, be = _parallelogram(q0 - o0, q1 - o1, q2 - o2, a0, a1, a2, b0, b1, b2)
    rows_f[j, F_PAR + 2] = wall_dom[w, 0] + al * (wall_dom[w, 1] - wall_dom[w, 0])
    rows_f[j, F_PAR + 3] = wall_dom[w, 2] + be * (wall_dom[w, 3] - wall_dom[w, 2])
    rows_i[j, I_PA] = -1
    rows_i[j, I_PB] = 0
    rows_i[j, I_VALID] = 1
    inside = al >= 0.0 and al <= 1.0 and be >= 0.0 and be <= 1.0
    if not inside:
        rows_i[j, I_BROAD] = 2
    rows_i[j, I_ACTIVE] = 1 if (inside and sd < 0.0) else 0


# --------------------------------------------------------------------------- a NURBS particle


@kernel
def solve_wall(tab, info, cen, rad, seeds, pos, R, origin, a, b, wdom, prevF, prevI,
               ws, wf, wi, wfs, no_mask, resF, resI):
    """One body against one flat wall (module docstring); writes ``resF``/``resI`` rows.

    ``origin`` (3,) wall corner (u_min, v_min), ``a``/``b`` (3,) edge vectors along u and v
    (a × b along the wall normal, towards the particles), ``wdom`` the wall's parameter
    rectangle (u_min, u_max, v_min, v_max); ``no_mask`` an empty bool array (every patch may
    seed a cold start)."""
    for k in range(resF.shape[0]):
        resF[k] = 0.0
    for k in range(resI.shape[0]):
        resI[k] = 0
    n0 = a[1] * b[2] - a[2] * b[1]
    n1 = a[2] * b[0] - a[0] * b[2]
    n2 = a[0] * b[1] - a[1] * b[0]
    nn = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    n0 /= nn
    n1 /= nn
    n2 /= nn
    c = wf[_EV2]
    _to_world(pos, R, cen, c)
    sc = n0 * (c[0] - origin[0]) + n1 * (c[1] - origin[1]) + n2 * (c[2] - origin[2])
    resF[F_N] = -n0
    resF[F_N + 1] = -n1
    resF[F_N + 2] = -n2
    if sc > rad:
        resF[F_SD] = sc - rad
        resI[I_BROAD] = 1
        resI[I_PA] = -1
        resI[I_PB] = -1
        return
    p0 = info[0]
    d = wf[_H]
    d[0] = -n0
    d[1] = -n1
    d[2] = -n2
    e = wf[_EA]
    _rot_t(R, d, 1.0, e)
    if prevI[I_VALID] == 1:
        wi[0, 0] = p0 + prevI[I_PA]
        _predicted_params(prevF, np.int64(0), e, wfs[0])
    else:
        k = seed_start(seeds[0], seeds[1], seeds[2], info[2], info[3], no_mask, p0, e)
        wi[0, 0] = seeds[1][k]
        wfs[0, 0] = seeds[2][k, 0]
        wfs[0, 1] = seeds[2][k, 1]
    wfs[0, 2] = 0.0
    ok, nev = support_map(tab, e, wi[0], wfs[0], rad, ws, wf[_EV:_EV + 6], wf[_EV2:_EV2 + 6],
                          wf[_TMP], wf[_PA], wf[_MA:_MA + 3], wf[_GA:_GA + 2])
    _store_prediction(resF, np.int64(0), e, wf[_GA:_GA + 2])
    pa = resF[F_PA:F_PA + 3]
    _to_world(pos, R, wf[_PA], pa)
    sd = n0 * (pa[0] - origin[0]) + n1 * (pa[1] - origin[1]) + n2 * (pa[2] - origin[2])
    resF[F_SD] = sd
    resF[F_PB] = pa[0] - sd * n0
    resF[F_PB + 1] = pa[1] - sd * n1
    resF[F_PB + 2] = pa[2] - sd * n2
    # position in the wall parallelogram
    al, be = parallelogram_coordinates(resF[F_PB] - origin[0], resF[F_PB + 1] - origin[1],
                                       resF[F_PB + 2] - origin[2], a, b)
    resF[F_PAR] = wfs[0, 0]
    resF[F_PAR + 1] = wfs[0, 1]
    resF[F_PAR + 2] = wdom[0] + al * (wdom[1] - wdom[0])
    resF[F_PAR + 3] = wdom[2] + be * (wdom[3] - wdom[2])
    resI[I_PA] = wi[0, 0] - p0
    resI[I_PB] = 0
    deg = 0
    if wi[0, 1] == CREASE:
        deg += 1
    if wi[0, 2] == CREASE:
        deg += 1
    resI[I_DEG] = deg
    resI[I_IT] = 1
    resI[I_NEV] = nev
    finite = sd == sd and abs(sd) < np.inf
    resI[I_FAIL] = 0 if (ok and finite) else 1
    resI[I_VALID] = 1 if finite else 0
    inside = al >= 0.0 and al <= 1.0 and be >= 0.0 and be <= 1.0
    if not inside:
        resI[I_BROAD] = 2
    resI[I_ACTIVE] = 1 if (finite and inside and sd < 0.0) else 0



#: :func:`solve_wall` compiled once and called by the batch kernels through a pointer
#: (:class:`~nurbsdem.jit.PointerKernel`)
solve_wall_ptr = PointerKernel(solve_wall, "solve_wall", lazy=True).call


def wall_frame(wall) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(origin, a, b, dom) of a flat wall patch (degree 1, 2×2 control points, world frame)."""
    cp = np.asarray(wall.control_points, float)
    if cp.shape[:2] != (2, 2):
        raise ValueError("detect_wall needs a flat wall patch with 2×2 control points")
    o = cp[0, 0].copy()
    return o, cp[1, 0] - o, cp[0, 1] - o, np.asarray(wall.domain, float)


def detect_wall(shape, pose, wall, previous: ContactResult | None = None) -> ContactResult:
    """Contact of a convex body (A) with a flat wall (B).

    Parameters
    ----------
    shape: the body's :class:`~nurbsdem.geometry.shape.Shape`; pose: (position, R).
    wall: a flat wall :class:`~nurbsdem.geometry.nurbs.Patch` in world coordinates (degree 1,
        2×2 control points, S_u × S_v pointing to the particles' side), e.g. from
        :func:`nurbsdem.shapes.flat_wall`; or a tuple (origin, a, b) of its corner and edge
        vectors.
    previous: the last result of the same body/wall (warm start).

    Returns
    -------
    :class:`ContactResult` with A = the body, B = the wall (patch_b = 0; params zB, θB the
    wall parameters of point_b); normal from the body to the wall.
    """
    if isinstance(wall, tuple):
        o, a, b = (np.asarray(x, float) for x in wall)
        wdom = np.array([0.0, 1.0, 0.0, 1.0])
    else:
        o, a, b, wdom = wall_frame(wall)
    t = table_of(shape)
    pos, R = _pose(pose)
    pf, pi = _prev_rows(previous)
    rf = np.zeros(NF)
    ri = np.zeros(NI, np.int64)
    ws, (wf, wi, wfs, w4) = _work()
    try:
        solve_wall(t.tab, t.info[0], t.centroid[0], float(t.radius[0]), t.seeds, pos, R,
                   np.ascontiguousarray(o), np.ascontiguousarray(a), np.ascontiguousarray(b),
                   wdom, pf, pi, ws, wf, wi, wfs, np.zeros(0, np.bool_), rf, ri)
    except Exception:  # pragma: no cover - never abort the simulation
        ri[I_FAIL] = 1
        ri[I_VALID] = 0
    return ContactResult.from_rows(rf, ri)


@kernel
def _wall_range(tab, info, cen, rad, seeds, shape, pos, rot, body, wall, wall_base, rows,
                origin, wa, wb, wdom, res_f, res_i, k0, k1, ws, wf, wi, wfs, no_mask, prev_f,
                prev_i):
    """The loop of :func:`_wall_chunk`: contact j = rows[k] for k in k0..k1-1 of body
    body[j] (shape[·], pos[·], rot[·]) against wall w = wall[j] − wall_base (origin[w],
    wa[w], wb[w], wdom[w]); its rows res_f[j], res_i[j] hold the previous solution and
    receive the new one in place (the previous one copied into prev_f, prev_i first, and kept
    by a contact that fails: :func:`~nurbsdem.contact.detect.kept_on_failure`).  Without
    reference counting (see :func:`nurbsdem.contact.detect._solve_range`)."""
    for k in range(k0, k1):
        j = rows[k]
        i = body[j]
        w = wall[j] - wall_base
        s = shape[i]
        for c in range(prev_f.shape[0]):
            prev_f[c] = res_f[j, c]
        for c in range(prev_i.shape[0]):
            prev_i[c] = res_i[j, c]
        solve_wall_ptr(tab, info[s], cen[s], rad[s], seeds, pos[i], rot[i], origin[w], wa[w],
                       wb[w], wdom[w], prev_f, prev_i, ws, wf, wi, wfs, no_mask, res_f[j],
                       res_i[j])
        kept_on_failure(res_f, res_i, j, prev_f, prev_i, 0.0)


@njit(cache=True, inline="always")
def _wall_chunk(tab, info, cen, rad, seeds, shape, pos, rot, body, wall, wall_base, rows,
                origin, wa, wb, wdom, res_f, res_i, k0, k1):
    """Body/wall contacts rows[k0:k1] (:func:`_wall_range`) with one set of workspaces (one
    thread)."""
    ws = make_workspace()
    wf, wi, wfs, _ = make_work()
    _wall_range(tab, info, cen, rad, seeds, shape, pos, rot, body, wall, wall_base, rows,
                origin, wa, wb, wdom, res_f, res_i, k0, k1, ws, wf, wi, wfs,
                np.zeros(0, np.bool_), np.empty(NF), np.empty(NI, np.int64))


@njit(cache=True, inline="always")
def _wall_chunks(tab, info, cen, rad, seeds, shape, pos, rot, body, wall, wall_base, rows,
                 origin, wa, wb, wdom, res_f, res_i, taken):
    """:func:`_wall_chunk` of the chunks :func:`~nurbsdem.contact.detect.next_chunk` hands
    this thread, with one set of workspaces."""
    ws = make_workspace()
    wf, wi, wfs, _ = make_work()
    no_mask = np.zeros(0, np.bool_)
    prev_f, prev_i = np.empty(NF), np.empty(NI, np.int64)
    k0, k1 = next_chunk(taken, rows.shape[0])
    while k0 < k1:
        _wall_range(tab, info, cen, rad, seeds, shape, pos, rot, body, wall, wall_base, rows,
                    origin, wa, wb, wdom, res_f, res_i, k0, k1, ws, wf, wi, wfs, no_mask,
                    prev_f, prev_i)
        k0, k1 = next_chunk(taken, rows.shape[0])


@njit(cache=True, parallel=True)
def _wall_batch_kernel(tab, info, cen, rad, seeds, shape, pos, rot, body, wall, wall_base,
                       rows, origin, wa, wb, wdom, res_f, res_i, nt):
    """The body/wall contacts ``rows`` (in place) on nt threads, which take chunks as they
    go."""
    K = rows.shape[0]
    if nt > K:
        nt = max(K, 1)
    taken = np.zeros(1, np.int64)
    for t in prange(nt):
        _wall_chunks(tab, info, cen, rad, seeds, shape, pos, rot, body, wall, wall_base, rows,
                     origin, wa, wb, wdom, res_f, res_i, taken)


@njit(cache=True, inline="always")
def solve_wall_rows(tab, info, cen, rad, seeds, shape, pos, rot, body, wall, wall_base, rows,
                    origin, wa, wb, wdom, res_f, res_i, nt) -> None:
    """The body/wall contacts ``rows`` in place (:func:`_wall_range`): on nt threads from
    :data:`~nurbsdem.contact.detect.PARALLEL_MIN_PAIRS` contacts, else on this one."""
    K = rows.shape[0]
    if K >= PARALLEL_MIN_PAIRS:
        _wall_batch_kernel(tab, info, cen, rad, seeds, shape, pos, rot, body, wall, wall_base,
                           rows, origin, wa, wb, wdom, res_f, res_i, nt)
    elif K:
        _wall_chunk(tab, info, cen, rad, seeds, shape, pos, rot, body, wall, wall_base, rows,
                    origin, wa, wb, wdom, res_f, res_i, np.int64(0), K)


def detect_wall_batch(table, shape_id, pos, rot, origin, a, b, dom=None, prev_f=None, prev_i=None):
    """K body/flat-wall contacts in compiled code (parallel).

    ``table``: :class:`~nurbsdem.contact.detect.ContactTable`; ``shape_id`` (K,) shapes of the
    bodies, ``pos`` (K, 3), ``rot`` (K, 3, 3) their poses; ``origin``, ``a``, ``b`` (K, 3) the
    walls' corners and edge vectors (:func:`wall_frame`), ``dom`` (K, 4) their parameter
    rectangles (default unit square). Returns (res_f (K, NF), res_i (K, NI))."""
    K = len(shape_id)
    f = lambda x, shp: np.ascontiguousarray(np.asarray(x, float).reshape(shp))  # noqa: E731
    if dom is None:
        dom = np.tile([0.0, 1.0, 0.0, 1.0], (K, 1))
    if prev_f is None or prev_i is None:
        prev_f = np.zeros((K, NF))
        prev_i = np.zeros((K, NI), np.int64)
    res_f = full_rows(prev_f).copy()        # solved in place from the previous rows
    res_i = np.array(prev_i, dtype=np.int64).reshape(K, NI)
    k = np.arange(K, dtype=np.int64)        # contact k: body k against wall k, row k
    solve_wall_rows(table.tab, table.info, table.centroid, table.radius, table.seeds,
                    np.ascontiguousarray(shape_id, dtype=np.int64), f(pos, (K, 3)),
                    f(rot, (K, 3, 3)), k, k, 0, k, f(origin, (K, 3)), f(a, (K, 3)),
                    f(b, (K, 3)), f(dom, (K, 4)), res_f, res_i, numba.get_num_threads())
    return res_f, res_i


# --------------------------------------------------------------------------- broad phase
def wall_geometry(patch) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centre, frame and half sizes of a flat rectangular wall patch (degree 1, 2x2 points,
    as made by :func:`nurbsdem.shapes.flat_wall`).

    Returns
    -------
    center: (3,) m.  axes: (3, 3) with columns (t1, t2, n): t1 along u, t2 in plane with
    t1 x t2 = n, n the unit normal ``S_u x S_v`` (the wall's active side).
    half: (2,) half lengths along t1 and t2 (m).
    """
    P = np.asarray(patch.control_points, dtype=float)
    if P.shape[:2] != (2, 2):
        raise ValueError("a flat wall must have 2 x 2 control points")
    center = P.reshape(-1, 3).mean(0)
    eu = 0.5 * ((P[1, 0] - P[0, 0]) + (P[1, 1] - P[0, 1]))
    ev = 0.5 * ((P[0, 1] - P[0, 0]) + (P[1, 1] - P[1, 0]))
    n = np.cross(eu, ev)
    n /= np.linalg.norm(n)
    t1 = eu / np.linalg.norm(eu)
    t2 = np.cross(n, t1)
    half = np.array([0.5 * np.linalg.norm(eu), 0.5 * abs(ev @ t2)])
    return center, np.stack([t1, t2, n], axis=1), half


@njit(cache=True)
def sphere_wall_pairs_jit(centers, radii, wall_centers, wall_axes, wall_half, margin):
    """Compiled core of :func:`sphere_wall_pairs` (no input checks). Returns int64 (K, 2)."""
    n = centers.shape[0]
    nw = wall_centers.shape[0]
    buf = np.empty((max(16, 2 * n), 2), dtype=np.int64)
    npair = np.int64(0)         # not a literal: one specialisation of _push
    for i in range(n):
        for k in range(nw):
            du = 0.0
            dv = 0.0
            dn = 0.0
            for d in range(3):
                x = centers[i, d] - wall_centers[k, d]
                du += x * wall_axes[k, d, 0]
                dv += x * wall_axes[k, d, 1]
                dn += x * wall_axes[k, d, 2]
            eu = max(abs(du) - wall_half[k, 0], 0.0)
            ev = max(abs(dv) - wall_half[k, 1], 0.0)
            s = radii[i] + margin
            if s > 0.0 and dn * dn + eu * eu + ev * ev < s * s:
                buf = _push(buf, npair, i, k)
                npair += 1
    return buf[:npair].copy()


def sphere_wall_pairs(centers: np.ndarray, radii: np.ndarray, wall_centers: np.ndarray,
                      wall_axes: np.ndarray, wall_half: np.ndarray,
                      margin: float = 0.0) -> np.ndarray:
    """Body-vs-flat-wall candidates of the first global level (paper Eq. 3 with a wall).

    Body i is near wall k when its bounding sphere reaches the wall rectangle (inflated by
    ``margin``): the distance from ``c_i`` to the rectangle (exact closest point, both sides
    of the plane) is ``< r_i + margin``.

    Parameters
    ----------
    centers: (N, 3) m.  radii: (N,) m.
    wall_centers: (W, 3) rectangle centres (m).
    wall_axes: (W, 3, 3), columns (t1, t2, n) orthonormal (see :func:`wall_geometry`).
    wall_half: (W, 2) half lengths along t1, t2 (m); a third column (thickness) is ignored.
    margin: skin (m), >= 0.

    Returns
    -------
    int64 (K, 2) of (body i, wall k), sorted by i then k (wall index local, 0..W-1).
    """
    c, r = _as_centers_radii(centers, radii)
    wc = np.ascontiguousarray(wall_centers, dtype=np.float64).reshape(-1, 3)
    wa = np.ascontiguousarray(wall_axes, dtype=np.float64).reshape(-1, 3, 3)
    wh = np.ascontiguousarray(
        np.asarray(wall_half, dtype=np.float64).reshape(wc.shape[0], -1)[:, :2])
    if wa.shape[0] != wc.shape[0] or wh.shape[1] != 2:
        raise ValueError("wall_centers (W,3), wall_axes (W,3,3), wall_half (W,2) disagree")
    margin = float(margin)
    if not (np.isfinite(margin) and margin >= 0):
        raise ValueError("margin must be finite and >= 0")
    return sphere_wall_pairs_jit(c, r, wc, wa, wh, margin)

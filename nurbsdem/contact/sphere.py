"""The exact sphere kind: its pair solvers (the flat wall's against a sphere lives in the flat
wall's module, :func:`~nurbsdem.contact.flat_wall.sphere_wall_row`, and is dispatched here
with the sphere–sphere one: :func:`closed_form_into`).

**Sphere against sphere** (centres x_A, x_B, radii r_A, r_B): the local contact problem of
paper Section 3 has the closed-form solution that the LCP converges to,

    n = (x_B − x_A)/|x_B − x_A|,   p_A = x_A + r_A n,   p_B = x_B − r_B n,
    signed distance = (p_B − p_A)·n = |x_B − x_A| − r_A − r_B

(the closest points when apart, the support points of the deepest penetration — Eq. 6–9 —
when they intersect).  Rows use the column layout of :mod:`nurbsdem.contact.lcp` (``I_PA`` =
−1: no patch is involved; ``I_IT`` = 0 iterations) so that everything after the contact
search is unchanged.

**Sphere against a convex NURBS particle**: a point-to-surface problem in 2 parameters.  For a
sphere of centre c and radius r outside a convex body B, the contact problem reduces to the
closest point p of B's surface to c:

    minimise ½ |S(u, v) − c|²  over (u, v) on B's patches,

whose stationary point has S − c along B's normal.  Then, with n the unit normal from the
sphere towards B (n = (p − c)/|p − c|, i.e. minus B's outward normal at p):

    point on the sphere  c + r n,   point on B  p,   signed distance |p − c| − r

(negative: the penetration depth, as long as c stays outside B, which holds for any overlap
smaller than the sphere's radius).  This is what the 4-parameter LCP converges to on the same
geometry (tested against it), at the cost of a 2 × 2 Newton iteration.

Newton on (u, v) in B's file frame, warm-started from the pair's previous row (B's patch and
parameters) or, cold, from B's nearest tabulated surface sample.  A solve that does not
converge on its patch within ``MAX_IT`` iterations, would have to migrate to a neighbouring
patch, meets a singular parametrisation (a pole) or finds c inside B returns ``ok = False``:
the caller then solves the pair with the full LCP.  The sphere's side has patch −1 (a closed
form), ``I_STAGE`` = :data:`~nurbsdem.contact.lcp.STAGE_POINT` (the LCP starts cold from
such a row: :func:`~nurbsdem.contact.lcp.warm_start`).

Which shapes are exact spheres is decided in :mod:`nurbsdem.geometry.analytic`.  Lengths in
metres.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..geometry.kernel import MAX_DEGREE, _WS_ROWS
from ..jit import kernel
from .flat_wall import sphere_wall_row
from .lcp import (F_N, F_PA, F_PAR, F_PB, F_SD, I_ACTIVE, I_IT, I_NEV, I_PA, I_PB, I_STAGE,
                  I_VALID, NF, NI, STAGE_POINT, clear_row)
from .point_distance import distance_gradient, distance_hessian
from .support import evaluate

#: Newton iterations before the pair is handed to the LCP
MAX_IT = 12
#: convergence: |S − c| × sin(angle to the normal) below this × the body's bounding radius
TOL = 1e-12


@kernel
def _local(pos, R, x, out):
    """out = Rᵀ (x − pos): a world point in the body's file frame."""
    for a in range(3):
        out[a] = (R[0, a] * (x[0] - pos[0]) + R[1, a] * (x[1] - pos[1])
                  + R[2, a] * (x[2] - pos[2]))


@kernel
def _nearest_seed(seed_x, seed_p, seed_uv, s0, ns, c):
    """Index of the tabulated surface sample nearest to c (file frame)."""
    best, ib = 1e300, s0
    for k in range(s0, s0 + ns):
        d = ((seed_x[k, 0] - c[0]) ** 2 + (seed_x[k, 1] - c[1]) ** 2
             + (seed_x[k, 2] - c[2]) ** 2)
        if d < best:
            best, ib = d, k
    return ib


@kernel
def closest_point(tab, ip, u, v, c, scale, ws, ev):
    """Newton for the point of patch ``ip`` nearest to c (file frame), from (u, v).

    Returns (ok, u, v, iterations, evaluations); ``ev`` holds S and its derivatives at the
    result.  ok = False when it leaves the patch, meets a singular Hessian or does not
    converge."""
    dom = tab[6][ip]
    nev = 0
    for it in range(MAX_IT):
        evaluate(tab, ip, u, v, 2, ws, ev)
        nev += 1
        d0, d1, d2, gu, gv, su2, sv2 = distance_gradient(ev, c)
        if not (su2 > 0.0 and sv2 > 0.0):
            return False, u, v, it, nev
        # tangential offset of c from the normal line at S, relative to the body scale
        if abs(gu) <= TOL * scale * math.sqrt(su2) and abs(gv) <= TOL * scale * math.sqrt(sv2):
            return True, u, v, it, nev
        huu, huv, hvv = distance_hessian(ev, d0, d1, d2, su2, sv2)
        det = huu * hvv - huv * huv
        if not (huu > 0.0 and det > 1e-14 * su2 * sv2):
            return False, u, v, it, nev
        du = -(hvv * gu - huv * gv) / det
        dv = -(huu * gv - huv * gu) / det
        u += du
        v += dv
        if u < dom[0] or u > dom[1] or v < dom[2] or v > dom[3]:
            return False, u, v, it, nev          # the nearest point is on another patch
    return False, u, v, MAX_IT, nev


@njit(cache=True)
def sphere_nurbs_row(tab, info, cen, rad, seeds, c, r, pos, R, sphere_is_a, prev_f, prev_i,
                     ws, ev, res_f, res_i) -> bool:
    """Row of one pair: an exact sphere (centre c, radius r, world) and a NURBS body (shape
    ``info``/``cen``/``rad`` of the table, pose pos, R).  ``sphere_is_a``: the sphere is body
    A of the pair (the normal points from A to B).  Returns False when the LCP must solve it
    (module docstring)."""
    for k in range(NF):
        res_f[k] = 0.0
    for k in range(NI):
        res_i[k] = 0
    p0 = info[0]
    cl = np.empty(3)
    _local(pos, R, c, cl)
    # warm start: the body's side of the previous row; cold: the nearest surface sample
    side = 1 if sphere_is_a else 0
    if prev_i[I_VALID] == 1 and prev_i[I_PB if sphere_is_a else I_PA] >= 0:
        ip = p0 + prev_i[I_PB if sphere_is_a else I_PA]
        u, v = prev_f[F_PAR + 2 * side], prev_f[F_PAR + 2 * side + 1]
    else:
        k = _nearest_seed(seeds[0], seeds[1], seeds[2], info[2], info[3], cl)
        ip, u, v = seeds[1][k], seeds[2][k, 0], seeds[2][k, 1]
    ok, u, v, it, nev = closest_point(tab, ip, u, v, cl, rad, ws, ev)
    if not ok:
        return False
    # world point and B's outward normal there (away from the centroid)
    p = np.empty(3)
    nb = np.empty(3)
    for a in range(3):
        p[a] = pos[a] + R[a, 0] * ev[0, 0] + R[a, 1] * ev[0, 1] + R[a, 2] * ev[0, 2]
    t0 = ev[1, 1] * ev[2, 2] - ev[1, 2] * ev[2, 1]
    t1 = ev[1, 2] * ev[2, 0] - ev[1, 0] * ev[2, 2]
    t2 = ev[1, 0] * ev[2, 1] - ev[1, 1] * ev[2, 0]
    sg = 1.0 if (t0 * (ev[0, 0] - cen[0]) + t1 * (ev[0, 1] - cen[1])
                 + t2 * (ev[0, 2] - cen[2])) > 0.0 else -1.0
    for a in range(3):
        nb[a] = sg * (R[a, 0] * t0 + R[a, 1] * t1 + R[a, 2] * t2)
    dist = math.sqrt((c[0] - p[0]) ** 2 + (c[1] - p[1]) ** 2 + (c[2] - p[2]) ** 2)
    out = (c[0] - p[0]) * nb[0] + (c[1] - p[1]) * nb[1] + (c[2] - p[2]) * nb[2]
    if not (dist > 0.0 and out > 0.0):
        return False                              # c on or inside B: the LCP's case
    # n from the sphere towards B: (p − c)/|p − c|
    n0, n1, n2 = (p[0] - c[0]) / dist, (p[1] - c[1]) / dist, (p[2] - c[2]) / dist
    sd = dist - r
    sgn = 1.0 if sphere_is_a else -1.0            # the row's normal points from A to B
    res_f[F_SD] = sd
    res_f[F_N], res_f[F_N + 1], res_f[F_N + 2] = sgn * n0, sgn * n1, sgn * n2
    q = F_PA if sphere_is_a else F_PB             # the sphere's point
    s = F_PB if sphere_is_a else F_PA             # B's point
    res_f[q], res_f[q + 1], res_f[q + 2] = c[0] + r * n0, c[1] + r * n1, c[2] + r * n2
    res_f[s], res_f[s + 1], res_f[s + 2] = p[0], p[1], p[2]
    res_f[F_PAR + 2 * side] = u
    res_f[F_PAR + 2 * side + 1] = v
    res_i[I_PA if sphere_is_a else I_PB] = -1
    res_i[I_PB if sphere_is_a else I_PA] = ip - p0
    res_i[I_IT] = it
    res_i[I_NEV] = nev
    res_i[I_STAGE] = STAGE_POINT
    res_i[I_VALID] = 1
    res_i[I_ACTIVE] = 1 if sd < 0.0 else 0
    return True


@njit(cache=True)
def sphere_nurbs_rows(tab, info, cen, rad, seeds, shape_b, c, r, pos, R, sphere_is_a,
                      prev_f, prev_i, res_f, res_i):
    """:func:`sphere_nurbs_row` for K pairs (NURBS bodies of shapes ``shape_b`` (K,), poses
    pos (K,3), R (K,3,3); sphere centres c (K,3), radii r (K,)); returns ok (K,) bool."""
    K = c.shape[0]
    ok = np.zeros(K, np.bool_)
    ws = np.zeros((_WS_ROWS, MAX_DEGREE + 1))
    ev = np.zeros((6, 3))
    for k in range(K):
        s = shape_b[k]
        ok[k] = sphere_nurbs_row(tab, info[s], cen[s], rad[s], seeds, c[k], r[k], pos[k], R[k],
                                 sphere_is_a[k], prev_f[k], prev_i[k], ws, ev, res_f[k],
                                 res_i[k])
    return ok


@njit(cache=True)
def _sphere_sphere_row(xa0: float, xa1: float, xa2: float, ra: float, xb0: float, xb1: float,
                       xb2: float, rb: float, rows_f: np.ndarray, rows_i: np.ndarray,
                       j: int) -> None:
    """One sphere pair (centres xa, xb m, radii ra, rb m) into row j of rows_f (P,NF), rows_i
    (P,NI) (zeroed first).  Coincident centres take the normal +x."""
    clear_row(rows_f, rows_i, j)
    d0, d1, d2 = xb0 - xa0, xb1 - xa1, xb2 - xa2
    dist = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    if dist > 0.0:
        n0, n1, n2 = d0 / dist, d1 / dist, d2 / dist
    else:
        n0, n1, n2 = 1.0, 0.0, 0.0
    rows_f[j, F_N], rows_f[j, F_N + 1], rows_f[j, F_N + 2] = n0, n1, n2
    rows_f[j, F_PA], rows_f[j, F_PA + 1], rows_f[j, F_PA + 2] = (xa0 + ra * n0, xa1 + ra * n1,
                                                                 xa2 + ra * n2)
    rows_f[j, F_PB], rows_f[j, F_PB + 1], rows_f[j, F_PB + 2] = (xb0 - rb * n0, xb1 - rb * n1,
                                                                 xb2 - rb * n2)
    sd = dist - ra - rb
    rows_f[j, F_SD] = sd
    rows_i[j, I_PA] = -1
    rows_i[j, I_PB] = -1
    rows_i[j, I_VALID] = 1
    rows_i[j, I_ACTIVE] = 1 if sd < 0.0 else 0


@njit(cache=True)
def _centre(i: int, pos: np.ndarray, R: np.ndarray, body_shape: np.ndarray,
            centre: np.ndarray) -> tuple[float, float, float]:
    """World centre pos + R c (m) of the exact-sphere body i (c: its sphere's centre in its
    shape's frame)."""
    s = body_shape[i]
    c0, c1, c2 = centre[s, 0], centre[s, 1], centre[s, 2]
    return (pos[i, 0] + R[i, 0, 0] * c0 + R[i, 0, 1] * c1 + R[i, 0, 2] * c2,
            pos[i, 1] + R[i, 1, 0] * c0 + R[i, 1, 1] * c1 + R[i, 1, 2] * c2,
            pos[i, 2] + R[i, 2, 0] * c0 + R[i, 2, 1] * c1 + R[i, 2, 2] * c2)


@njit(cache=True)
def sphere_centres(idx: np.ndarray, pos: np.ndarray, R: np.ndarray, body_shape: np.ndarray,
                   centre: np.ndarray) -> np.ndarray:
    """(K,3) world centres pos + R c of the exact-sphere bodies idx (c: the sphere's centre in
    its shape's frame, per shape)."""
    out = np.empty((idx.shape[0], 3))
    for k in range(idx.shape[0]):
        out[k, 0], out[k, 1], out[k, 2] = _centre(idx[k], pos, R, body_shape, centre)
    return out


@njit(cache=True)
def closed_form_into(rows_f: np.ndarray, rows_i: np.ndarray, idx: np.ndarray, a: np.ndarray,
                     b: np.ndarray, n_particles: int, pos: np.ndarray, R: np.ndarray,
                     wall_d: np.ndarray, body_shape: np.ndarray, sphere_center: np.ndarray,
                     sphere_radius: np.ndarray, wall_origin: np.ndarray, wall_a: np.ndarray,
                     wall_b: np.ndarray, wall_dom: np.ndarray) -> None:
    """Rows rows_f[j], rows_i[j] (in place, j in ``idx``) of the listed pairs (a[j], b[j]) of
    exact spheres: sphere–sphere where b < n_particles, sphere–flat wall b − n_particles
    otherwise.  pos (N,3), R (N,3,3): the bodies' poses; wall_d (W,3) the walls'
    displacements; sphere_center (S,3), sphere_radius (S,) per shape; wall_origin, wall_a,
    wall_b (W,3), wall_dom (W,4) the walls' frames."""
    for r in range(idx.shape[0]):
        j = idx[r]
        ia, ib = a[j], b[j]
        xa0, xa1, xa2 = _centre(ia, pos, R, body_shape, sphere_center)
        ra = sphere_radius[body_shape[ia]]
        if ib < n_particles:
            xb0, xb1, xb2 = _centre(ib, pos, R, body_shape, sphere_center)
            _sphere_sphere_row(xa0, xa1, xa2, ra, xb0, xb1, xb2,
                               sphere_radius[body_shape[ib]], rows_f, rows_i, j)
        else:
            sphere_wall_row(xa0, xa1, xa2, ra, ib - n_particles, wall_d, wall_origin, wall_a,
                            wall_b, wall_dom, rows_f, rows_i, j)

"""Closed-form contacts for exact spheres: sphere–sphere and sphere–flat wall.

The local contact problem of two exact spheres (centres x_A, x_B, radii r_A, r_B) has the
closed-form solution that the LCP of paper Section 3 converges to:

    n = (x_B − x_A)/|x_B − x_A|,   p_A = x_A + r_A n,   p_B = x_B − r_B n,
    signed distance = (p_B − p_A)·n = |x_B − x_A| − r_A − r_B

(the closest points when apart, the support points of the deepest penetration — Eq. 6–9 —
when they intersect).  Against a flat wall with unit normal m towards the particles, corner o
and edges a, b (the fast path of :mod:`nurbsdem.contact.wall`): p_A = x − r m, p_B its
projection on the plane, signed distance m·(p_A − o), normal −m, active only where p_B falls
inside the wall's parallelogram.

Rows use the column layout of :mod:`nurbsdem.contact.lcp` (``I_PA`` = −1: no patch is
involved; ``I_IT`` = 0 iterations) so that everything after the contact search is unchanged.
Lengths in metres.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from .lcp import F_N, F_PA, F_PAR, F_PB, F_SD, I_ACTIVE, I_BROAD, I_PA, I_PB, I_VALID


@njit(cache=True)
def _sphere_sphere_row(xa0: float, xa1: float, xa2: float, ra: float, xb0: float, xb1: float,
                       xb2: float, rb: float, row_f: np.ndarray, row_i: np.ndarray) -> None:
    """One sphere pair (centres xa, xb m, radii ra, rb m) into row_f (NF,), row_i (NI,)
    (zeroed first).  Coincident centres take the normal +x."""
    row_f[:] = 0.0
    row_i[:] = 0
    d0, d1, d2 = xb0 - xa0, xb1 - xa1, xb2 - xa2
    dist = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    if dist > 0.0:
        n0, n1, n2 = d0 / dist, d1 / dist, d2 / dist
    else:
        n0, n1, n2 = 1.0, 0.0, 0.0
    row_f[F_N], row_f[F_N + 1], row_f[F_N + 2] = n0, n1, n2
    row_f[F_PA], row_f[F_PA + 1], row_f[F_PA + 2] = xa0 + ra * n0, xa1 + ra * n1, xa2 + ra * n2
    row_f[F_PB], row_f[F_PB + 1], row_f[F_PB + 2] = xb0 - rb * n0, xb1 - rb * n1, xb2 - rb * n2
    sd = dist - ra - rb
    row_f[F_SD] = sd
    row_i[I_PA] = -1
    row_i[I_PB] = -1
    row_i[I_VALID] = 1
    row_i[I_ACTIVE] = 1 if sd < 0.0 else 0


@njit(cache=True)
def parallelogram_coordinates(r0: float, r1: float, r2: float, a: np.ndarray,
                              b: np.ndarray) -> tuple[float, float]:
    """Coordinates (α, β) of the in-plane offset r (m) from a wall's corner on its edge
    vectors a, b (3,): r = α a + β b (the 2×2 normal equations); inside when both are in
    [0, 1]."""
    aa = a[0] * a[0] + a[1] * a[1] + a[2] * a[2]
    ab = a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    bb = b[0] * b[0] + b[1] * b[1] + b[2] * b[2]
    ar = a[0] * r0 + a[1] * r1 + a[2] * r2
    br = b[0] * r0 + b[1] * r1 + b[2] * r2
    det = aa * bb - ab * ab
    return (bb * ar - ab * br) / det, (aa * br - ab * ar) / det


@njit(cache=True)
def _sphere_wall_row(x0: float, x1: float, x2: float, r: float, origin: np.ndarray,
                     a: np.ndarray, b: np.ndarray, wdom: np.ndarray, row_f: np.ndarray,
                     row_i: np.ndarray) -> None:
    """One sphere (centre x m, radius r m) against a flat wall (corner ``origin`` (3,), edge
    vectors ``a``, ``b`` (3,), parameter rectangle ``wdom`` (4,)) into row_f, row_i (zeroed
    first), in the convention of :func:`nurbsdem.contact.wall.solve_wall`."""
    row_f[:] = 0.0
    row_i[:] = 0
    m0 = a[1] * b[2] - a[2] * b[1]
    m1 = a[2] * b[0] - a[0] * b[2]
    m2 = a[0] * b[1] - a[1] * b[0]
    mm = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
    m0, m1, m2 = m0 / mm, m1 / mm, m2 / mm
    row_f[F_N], row_f[F_N + 1], row_f[F_N + 2] = -m0, -m1, -m2
    p0, p1, p2 = x0 - r * m0, x1 - r * m1, x2 - r * m2
    row_f[F_PA], row_f[F_PA + 1], row_f[F_PA + 2] = p0, p1, p2
    sd = m0 * (p0 - origin[0]) + m1 * (p1 - origin[1]) + m2 * (p2 - origin[2])
    row_f[F_SD] = sd
    q0, q1, q2 = p0 - sd * m0, p1 - sd * m1, p2 - sd * m2
    row_f[F_PB], row_f[F_PB + 1], row_f[F_PB + 2] = q0, q1, q2
    al, be = parallelogram_coordinates(q0 - origin[0], q1 - origin[1], q2 - origin[2], a, b)
    row_f[F_PAR + 2] = wdom[0] + al * (wdom[1] - wdom[0])
    row_f[F_PAR + 3] = wdom[2] + be * (wdom[3] - wdom[2])
    row_i[I_PA] = -1
    row_i[I_PB] = 0
    row_i[I_VALID] = 1
    inside = al >= 0.0 and al <= 1.0 and be >= 0.0 and be <= 1.0
    if not inside:
        row_i[I_BROAD] = 2
    row_i[I_ACTIVE] = 1 if (inside and sd < 0.0) else 0


@njit(cache=True)
def _centre(i: int, pos: np.ndarray, R: np.ndarray, body_shape: np.ndarray,
            centre: np.ndarray) -> tuple[float, float, float]:
    """World centre pos + R c (m) of the exact-sphere body i (c: its sphere's centre in its
    shape's frame)."""
    c = centre[body_shape[i]]
    return (pos[i, 0] + R[i, 0, 0] * c[0] + R[i, 0, 1] * c[1] + R[i, 0, 2] * c[2],
            pos[i, 1] + R[i, 1, 0] * c[0] + R[i, 1, 1] * c[1] + R[i, 1, 2] * c[2],
            pos[i, 2] + R[i, 2, 0] * c[0] + R[i, 2, 1] * c[1] + R[i, 2, 2] * c[2])


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
    o = np.empty(3)
    for r in range(idx.shape[0]):
        j = idx[r]
        ia, ib = a[j], b[j]
        xa0, xa1, xa2 = _centre(ia, pos, R, body_shape, sphere_center)
        ra = sphere_radius[body_shape[ia]]
        if ib < n_particles:
            xb0, xb1, xb2 = _centre(ib, pos, R, body_shape, sphere_center)
            _sphere_sphere_row(xa0, xa1, xa2, ra, xb0, xb1, xb2,
                               sphere_radius[body_shape[ib]], rows_f[j], rows_i[j])
        else:
            w = ib - n_particles
            for k in range(3):
                o[k] = wall_origin[w, k] + wall_d[w, k]
            _sphere_wall_row(xa0, xa1, xa2, ra, o, wall_a[w], wall_b[w], wall_dom[w],
                             rows_f[j], rows_i[j])

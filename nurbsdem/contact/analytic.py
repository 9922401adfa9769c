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

from .lcp import (F_N, F_PA, F_PAR, F_PB, F_SD, I_ACTIVE, I_BROAD, I_PA, I_PB, I_VALID, NF,
                  NI)


@njit(cache=True)
def sphere_sphere_rows(xa: np.ndarray, ra: np.ndarray, xb: np.ndarray, rb: np.ndarray,
                       res_f: np.ndarray, res_i: np.ndarray) -> None:
    """K sphere pairs: centres xa, xb (K,3), radii ra, rb (K,); rows written to res_f (K,NF),
    res_i (K,NI) (zeroed first).  Coincident centres take the normal +x."""
    for k in range(xa.shape[0]):
        res_f[k, :] = 0.0
        res_i[k, :] = 0
        d0, d1, d2 = xb[k, 0] - xa[k, 0], xb[k, 1] - xa[k, 1], xb[k, 2] - xa[k, 2]
        dist = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        if dist > 0.0:
            n0, n1, n2 = d0 / dist, d1 / dist, d2 / dist
        else:
            n0, n1, n2 = 1.0, 0.0, 0.0
        res_f[k, F_N], res_f[k, F_N + 1], res_f[k, F_N + 2] = n0, n1, n2
        res_f[k, F_PA] = xa[k, 0] + ra[k] * n0
        res_f[k, F_PA + 1] = xa[k, 1] + ra[k] * n1
        res_f[k, F_PA + 2] = xa[k, 2] + ra[k] * n2
        res_f[k, F_PB] = xb[k, 0] - rb[k] * n0
        res_f[k, F_PB + 1] = xb[k, 1] - rb[k] * n1
        res_f[k, F_PB + 2] = xb[k, 2] - rb[k] * n2
        sd = dist - ra[k] - rb[k]
        res_f[k, F_SD] = sd
        res_i[k, I_PA] = -1
        res_i[k, I_PB] = -1
        res_i[k, I_VALID] = 1
        res_i[k, I_ACTIVE] = 1 if sd < 0.0 else 0


@njit(cache=True)
def sphere_wall_rows(x: np.ndarray, r: np.ndarray, origin: np.ndarray, a: np.ndarray,
                     b: np.ndarray, wdom: np.ndarray, res_f: np.ndarray, res_i: np.ndarray) -> None:
    """K sphere/flat-wall pairs: centres x (K,3), radii r (K,); walls' corners ``origin``,
    edge vectors ``a``, ``b`` (K,3) and parameter rectangles ``wdom`` (K,4); rows written to
    res_f, res_i (zeroed first), in the convention of :func:`nurbsdem.contact.wall.solve_wall`."""
    for k in range(x.shape[0]):
        res_f[k, :] = 0.0
        res_i[k, :] = 0
        m0 = a[k, 1] * b[k, 2] - a[k, 2] * b[k, 1]
        m1 = a[k, 2] * b[k, 0] - a[k, 0] * b[k, 2]
        m2 = a[k, 0] * b[k, 1] - a[k, 1] * b[k, 0]
        mm = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
        m0, m1, m2 = m0 / mm, m1 / mm, m2 / mm
        res_f[k, F_N], res_f[k, F_N + 1], res_f[k, F_N + 2] = -m0, -m1, -m2
        p0, p1, p2 = x[k, 0] - r[k] * m0, x[k, 1] - r[k] * m1, x[k, 2] - r[k] * m2
        res_f[k, F_PA], res_f[k, F_PA + 1], res_f[k, F_PA + 2] = p0, p1, p2
        sd = m0 * (p0 - origin[k, 0]) + m1 * (p1 - origin[k, 1]) + m2 * (p2 - origin[k, 2])
        res_f[k, F_SD] = sd
        q0, q1, q2 = p0 - sd * m0, p1 - sd * m1, p2 - sd * m2
        res_f[k, F_PB], res_f[k, F_PB + 1], res_f[k, F_PB + 2] = q0, q1, q2
        r0, r1, r2 = q0 - origin[k, 0], q1 - origin[k, 1], q2 - origin[k, 2]
        aa = a[k, 0] * a[k, 0] + a[k, 1] * a[k, 1] + a[k, 2] * a[k, 2]
        ab = a[k, 0] * b[k, 0] + a[k, 1] * b[k, 1] + a[k, 2] * b[k, 2]
        bb = b[k, 0] * b[k, 0] + b[k, 1] * b[k, 1] + b[k, 2] * b[k, 2]
        ar = a[k, 0] * r0 + a[k, 1] * r1 + a[k, 2] * r2
        br = b[k, 0] * r0 + b[k, 1] * r1 + b[k, 2] * r2
        det = aa * bb - ab * ab
        al = (bb * ar - ab * br) / det
        be = (aa * br - ab * ar) / det
        res_f[k, F_PAR + 2] = wdom[k, 0] + al * (wdom[k, 1] - wdom[k, 0])
        res_f[k, F_PAR + 3] = wdom[k, 2] + be * (wdom[k, 3] - wdom[k, 2])
        res_i[k, I_PA] = -1
        res_i[k, I_PB] = 0
        res_i[k, I_VALID] = 1
        inside = al >= 0.0 and al <= 1.0 and be >= 0.0 and be <= 1.0
        if not inside:
            res_i[k, I_BROAD] = 2
        res_i[k, I_ACTIVE] = 1 if (inside and sd < 0.0) else 0


@njit(cache=True)
def sphere_centres(idx: np.ndarray, pos: np.ndarray, R: np.ndarray, body_shape: np.ndarray,
                   centre: np.ndarray) -> np.ndarray:
    """(K,3) world centres pos + R c of the exact-sphere bodies idx (c: the sphere's centre in
    its shape's frame, per shape)."""
    out = np.empty((idx.shape[0], 3))
    for k in range(idx.shape[0]):
        i = idx[k]
        c = centre[body_shape[i]]
        for j in range(3):
            out[k, j] = pos[i, j] + R[i, j, 0] * c[0] + R[i, j, 1] * c[1] + R[i, j, 2] * c[2]
    return out


@njit(cache=True)
def scatter_rows(rows_f: np.ndarray, rows_i: np.ndarray, idx: np.ndarray, f: np.ndarray,
             i: np.ndarray) -> None:
    """rows_f[idx] = f, rows_i[idx] = i."""
    for r in range(idx.shape[0]):
        rows_f[idx[r]] = f[r]
        rows_i[idx[r]] = i[r]


@njit(cache=True)
def closed_form_rows(a: np.ndarray, b: np.ndarray, n_particles: int, pos: np.ndarray,
                     R: np.ndarray, wall_d: np.ndarray, body_shape: np.ndarray,
                     sphere_center: np.ndarray, sphere_radius: np.ndarray,
                     wall_origin: np.ndarray, wall_a: np.ndarray, wall_b: np.ndarray,
                     wall_dom: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows (K,NF), (K,NI) of K pairs of exact spheres (a, b): sphere–sphere where
    b < n_particles, sphere–flat wall b − n_particles otherwise.  pos (N,3), R (N,3,3): the
    bodies' poses; wall_d (W,3) the walls' displacements; sphere_center (S,3), sphere_radius
    (S,) per shape; wall_origin, wall_a, wall_b (W,3), wall_dom (W,4) the walls' frames."""
    K = a.shape[0]
    N = n_particles
    rf = np.zeros((K, NF))
    ri = np.zeros((K, NI), np.int64)
    rad = sphere_radius[body_shape]
    pp = np.nonzero(b < N)[0]
    pw = np.nonzero(b >= N)[0]
    if pp.shape[0]:
        ia, ib = a[pp], b[pp]
        f, i = np.empty((pp.shape[0], NF)), np.empty((pp.shape[0], NI), np.int64)
        sphere_sphere_rows(sphere_centres(ia, pos, R, body_shape, sphere_center), rad[ia],
                           sphere_centres(ib, pos, R, body_shape, sphere_center), rad[ib], f, i)
        scatter_rows(rf, ri, pp, f, i)
    if pw.shape[0]:
        ia, w = a[pw], b[pw] - N
        f, i = np.empty((pw.shape[0], NF)), np.empty((pw.shape[0], NI), np.int64)
        sphere_wall_rows(sphere_centres(ia, pos, R, body_shape, sphere_center), rad[ia],
                         wall_origin[w] + wall_d[w], wall_a[w], wall_b[w], wall_dom[w], f, i)
        scatter_rows(rf, ri, pw, f, i)
    return rf, ri

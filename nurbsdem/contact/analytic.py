"""Closed-form contacts for exact spheres: sphere–sphere here, sphere–flat wall in the flat
wall's module (:func:`~nurbsdem.contact.flat_wall.sphere_wall_row`), dispatched together
(:func:`closed_form_into`).

The local contact problem of two exact spheres (centres x_A, x_B, radii r_A, r_B) has the
closed-form solution that the LCP of paper Section 3 converges to:

    n = (x_B − x_A)/|x_B − x_A|,   p_A = x_A + r_A n,   p_B = x_B − r_B n,
    signed distance = (p_B − p_A)·n = |x_B − x_A| − r_A − r_B

(the closest points when apart, the support points of the deepest penetration — Eq. 6–9 —
when they intersect).

Rows use the column layout of :mod:`nurbsdem.contact.lcp` (``I_PA`` = −1: no patch is
involved; ``I_IT`` = 0 iterations) so that everything after the contact search is unchanged.
Lengths in metres.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from .flat_wall import sphere_wall_row
from .lcp import F_N, F_PA, F_PB, F_SD, I_ACTIVE, I_PA, I_PB, I_VALID, clear_row


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

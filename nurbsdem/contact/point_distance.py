"""The squared distance from a point to a surface point and its derivatives in the surface's
parameters: what a Newton iteration for the point of a patch nearest to a given point needs
(the point-to-surface problem of an exact sphere against a NURBS particle,
:func:`nurbsdem.contact.sphere.closest_point`, and against a surface wall,
:func:`nurbsdem.contact.surface_wall.closest_on_patch`).

For f(u, v) = ½ |S(u, v) − c|² with d = S − c: the gradient (d·S_u, d·S_v) and the Hessian
(S_u·S_u + d·S_uu, S_u·S_v + d·S_uv, S_v·S_v + d·S_vv).  Units: those of S and c (m).
"""
from __future__ import annotations

from numba import njit


@njit(cache=True, inline="always")
def distance_gradient(ev, c):
    """From ``ev`` (6,3) (S, S_u, S_v, S_uu, S_uv, S_vv at (u, v)) and the point c (3,):
    (d0, d1, d2, gu, gv, su2, sv2), d = S − c, (gu, gv) the gradient of ½|d|², su2 = |S_u|²
    and sv2 = |S_v|² (zero where the parametrisation degenerates)."""
    d0, d1, d2 = ev[0, 0] - c[0], ev[0, 1] - c[1], ev[0, 2] - c[2]
    gu = d0 * ev[1, 0] + d1 * ev[1, 1] + d2 * ev[1, 2]
    gv = d0 * ev[2, 0] + d1 * ev[2, 1] + d2 * ev[2, 2]
    su2 = ev[1, 0] ** 2 + ev[1, 1] ** 2 + ev[1, 2] ** 2
    sv2 = ev[2, 0] ** 2 + ev[2, 1] ** 2 + ev[2, 2] ** 2
    return d0, d1, d2, gu, gv, su2, sv2


@njit(cache=True, inline="always")
def distance_hessian(ev, d0, d1, d2, su2, sv2):
    """The Hessian (huu, huv, hvv) of ½|S − c|² from ``ev`` (6,3) and what
    :func:`distance_gradient` returned (d = S − c, su2, sv2)."""
    huu = su2 + d0 * ev[3, 0] + d1 * ev[3, 1] + d2 * ev[3, 2]
    huv = (ev[1, 0] * ev[2, 0] + ev[1, 1] * ev[2, 1] + ev[1, 2] * ev[2, 2]
           + d0 * ev[4, 0] + d1 * ev[4, 1] + d2 * ev[4, 2])
    hvv = sv2 + d0 * ev[5, 0] + d1 * ev[5, 1] + d2 * ev[5, 2]
    return huu, huv, hvv

"""NURBS surface walls: an exact sphere against open NURBS patches (the wall as body B).

A surface wall is a set of open patches (a drum's mantle, a funnel, a chute: the patches of
:mod:`nurbsdem.geometry.surfaces`, a shape file, a Rhino or Giraffe CAD record) whose front
side (S_u × S_v) faces the particles.  It is not a closed convex body, so the support
mappings of paper Section 3 apply to the particle only; for an exact sphere (centre c,
radius r) the local contact problem reduces to the closest point of the wall to c,

    minimise ½ |S(u, v) − c|²  over (u, v) in each patch's parameter rectangle,

the point-surface problem of the paper's Eq. 4 with body A shrunk to its centre.  Then

    n = (p − c)/|p − c|  (from the sphere towards the wall),   p_A = c + r n,   p_B = p,
    signed distance = |p − c| − r,

the row layout of :mod:`nurbsdem.contact.lcp`.  The minimiser is unique where the wall's
radius of curvature at the contact exceeds the sphere's distance to it (in particular a
concave wall — the inside of a drum — whose radius exceeds the particle's): the distance
function is then strictly convex near p.  The iteration is a projected Newton method on the
rectangle: a parameter at its bound whose gradient pushes outward is held there and the
other is solved in one dimension, so that a sphere beyond the wall's rim touches the rim.
It starts from the nearest of a tabulated grid of surface samples (:func:`build_surface_wall`).

The wall is one-sided: only a centre in front of the surface (``(c − p)·(S_u × S_v) > 0``)
makes a contact, so a particle that slipped behind the wall is not pulled through it.

Evaluations are those of the contact kernels (power form, :mod:`nurbsdem.geometry.kernel`).
Lengths in metres.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numba import njit

from ..geometry.kernel import PatchPool, power_derivs, power_form
from ..geometry.nurbs import Patch
from .lcp import F_N, F_PA, F_PAR, F_PB, F_SD, I_ACTIVE, I_IT, I_PA, I_PB, I_VALID, NF, NI
from .point_distance import distance_gradient, distance_hessian

#: projected Newton iterations before a solve counts as not converged
MAX_IT = 60
#: convergence: the projected gradient below this × the wall's size × |S_u| (and |S_v|)
TOL = 1e-13
#: surface samples per patch and direction for the cold start
SAMPLES = 24


@dataclass(frozen=True)
class SurfaceWall:
    """Open NURBS patches with their power form and start samples.

    deg, ncp, koff, knots, dom: the :class:`~nurbsdem.geometry.kernel.PatchPool` arrays; pw,
    poff: its power form; seed_x (K,3) m, seed_p (K,), seed_uv (K,2): surface samples;
    periodic (P,2) bool: the patch closes on itself along u / v (a full cylinder's seam: u
    wraps there instead of stopping); spacing (m): the largest distance between neighbouring
    samples; size (m): the diagonal of the control points' bounding box."""

    deg: np.ndarray
    ncp: np.ndarray
    koff: np.ndarray
    knots: np.ndarray
    dom: np.ndarray
    pw: np.ndarray
    poff: np.ndarray
    seed_x: np.ndarray
    seed_p: np.ndarray
    seed_uv: np.ndarray
    periodic: np.ndarray
    spacing: float
    size: float


def build_surface_wall(patches: Sequence[Patch], samples: int = SAMPLES) -> SurfaceWall:
    """A :class:`SurfaceWall` of ``patches`` (validated beforehand), with ``samples`` ×
    ``samples`` start points per patch, spaced evenly in parameter space."""
    pool = PatchPool.from_patches(list(patches))
    pw, poff = power_form(pool)
    xs, ps, uvs = [], [], []
    spacing = 0.0
    for ip, patch in enumerate(patches):
        u0, u1, v0, v1 = patch.domain
        uu, vv = np.meshgrid(np.linspace(u0, u1, samples), np.linspace(v0, v1, samples),
                             indexing="ij")
        grid = patch.points(uu, vv)
        spacing = max(spacing, float(np.linalg.norm(np.diff(grid, axis=0), axis=-1).max()),
                      float(np.linalg.norm(np.diff(grid, axis=1), axis=-1).max()))
        xs.append(grid.reshape(-1, 3))
        ps.append(np.full(uu.size, ip, np.int64))
        uvs.append(np.column_stack([uu.ravel(), vv.ravel()]))
    cps = np.concatenate([p.control_points.reshape(-1, 3) for p in patches])
    size = float(np.linalg.norm(cps.max(axis=0) - cps.min(axis=0)))
    periodic = np.array([_closes(p, 1e-12 * size) for p in patches], dtype=np.bool_)
    return SurfaceWall(pool.deg, pool.ncp, pool.koff, pool.knots, pool.dom, pw, poff,
                       np.concatenate(xs), np.concatenate(ps), np.concatenate(uvs),
                       periodic.reshape(-1, 2), spacing, size)


def _closes(patch: Patch, tol: float) -> tuple[bool, bool]:
    """Whether the patch's boundary curves u = u_min and u = u_max (v = v_min and v_max)
    coincide, within ``tol`` m at 33 points."""
    u0, u1, v0, v1 = patch.domain
    t = np.linspace(0, 1, 33)
    us, vs = u0 + (u1 - u0) * t, v0 + (v1 - v0) * t
    along_u = np.abs(patch.points(np.full(33, u0), vs) - patch.points(np.full(33, u1), vs)).max()
    along_v = np.abs(patch.points(us, np.full(33, v0)) - patch.points(us, np.full(33, v1))).max()
    return bool(along_u <= tol), bool(along_v <= tol)


@njit(cache=True, inline="always")
def _projected(g, x, lo, hi):
    """Whether a bound holds the parameter x: at lo with the gradient g pushing below, or at
    hi with g pushing above."""
    return (x <= lo and g > 0.0) or (x >= hi and g < 0.0)


@njit(cache=True, inline="always")
def _wrap(x, lo, hi):
    """x brought into [lo, hi) along a periodic direction."""
    span = hi - lo
    return x - span * math.floor((x - lo) / span)


@njit(cache=True)
def closest_on_patch(deg, ncp, koff, knots, pw, poff, dom, periodic, ip, u, v, c, scale, ev):
    """Projected Newton for the point of patch ``ip`` nearest to c (3,), from (u, v) (module
    docstring; a periodic direction wraps instead of holding at its bound).  Returns (ok, u,
    v, iterations); ``ev`` (6,3) holds S and its derivatives at the result.  ``scale`` (m)
    sets the tolerance."""
    u0, u1, v0, v1 = dom[ip, 0], dom[ip, 1], dom[ip, 2], dom[ip, 3]
    wrap_u, wrap_v = periodic[ip, 0], periodic[ip, 1]
    for it in range(MAX_IT):
        power_derivs(deg, ncp, koff, knots, pw, poff, ip, u, v, 2, ev)
        d0, d1, d2, gu, gv, su2, sv2 = distance_gradient(ev, c)
        if not (su2 > 0.0 and sv2 > 0.0):
            return False, u, v, it
        fix_u = not wrap_u and _projected(gu, u, u0, u1)
        fix_v = not wrap_v and _projected(gv, v, v0, v1)
        pgu = 0.0 if fix_u else gu
        pgv = 0.0 if fix_v else gv
        if abs(pgu) <= TOL * scale * math.sqrt(su2) and abs(pgv) <= TOL * scale * math.sqrt(sv2):
            return True, u, v, it
        huu, huv, hvv = distance_hessian(ev, d0, d1, d2, su2, sv2)
        du, dv = _newton_step(pgu, pgv, huu, huv, hvv, su2, sv2, fix_u, fix_v)
        u = _wrap(u + du, u0, u1) if wrap_u else min(max(u + du, u0), u1)
        v = _wrap(v + dv, v0, v1) if wrap_v else min(max(v + dv, v0), v1)
    return False, u, v, MAX_IT


@njit(cache=True, inline="always")
def _newton_step(gu, gv, huu, huv, hvv, su2, sv2, fix_u, fix_v):
    """Step (du, dv) on the free parameters: Newton where the (reduced) Hessian is positive,
    else the Gauss–Newton step (first-order terms only, always a descent direction)."""
    if fix_u and fix_v:
        return 0.0, 0.0
    if fix_u:
        return 0.0, -gv / (hvv if hvv > 0.0 else sv2)
    if fix_v:
        return -gu / (huu if huu > 0.0 else su2), 0.0
    det = huu * hvv - huv * huv
    if huu > 0.0 and det > 1e-14 * su2 * sv2:
        return -(hvv * gu - huv * gv) / det, -(huu * gv - huv * gu) / det
    return -gu / su2, -gv / sv2


@njit(cache=True)
def _nearest_seeds(seed_x, seed_p, n_patches, c, best_k, best_d):
    """Per patch, the index ``best_k`` and squared distance ``best_d`` of its sample nearest
    to c."""
    for ip in range(n_patches):
        best_d[ip] = 1e300
        best_k[ip] = -1
    for k in range(seed_x.shape[0]):
        d = (seed_x[k, 0] - c[0]) ** 2 + (seed_x[k, 1] - c[1]) ** 2 + (seed_x[k, 2] - c[2]) ** 2
        ip = seed_p[k]
        if d < best_d[ip]:
            best_d[ip] = d
            best_k[ip] = k


@njit(cache=True)
def sphere_surface_row(x, r, R, t, deg, ncp, koff, knots, pw, poff, dom, periodic, seed_x,
                       seed_p, seed_uv, spacing, size, ev, res_f, res_i) -> bool:
    """Row (res_f (NF,), res_i (NI,)) of a sphere (world centre x (3,), radius r m) against a
    surface wall at pose (R (3,3), t (3,): x_world = R x_wall + t): its closest point over the
    patches (module docstring).  Each patch whose nearest sample lies within ``spacing`` (m,
    the samples' largest gap) of the nearest sample overall is solved from that sample; the
    nearest converged point wins.  ``I_PB``: the patch; ``F_PAR + 2:4``: its (u, v).  Returns
    False when no patch gave a converged closest point."""
    for k in range(NF):
        res_f[k] = 0.0
    for k in range(NI):
        res_i[k] = 0
    c = np.empty(3)
    for a in range(3):
        c[a] = R[0, a] * (x[0] - t[0]) + R[1, a] * (x[1] - t[1]) + R[2, a] * (x[2] - t[2])
    n_patches = dom.shape[0]
    best_k = np.empty(n_patches, np.int64)
    best_d = np.empty(n_patches)
    _nearest_seeds(seed_x, seed_p, n_patches, c, best_k, best_d)
    reach = math.sqrt(best_d.min()) + spacing
    found, found_d = False, 1e300
    ev_try = np.empty((6, 3))
    for ip in range(n_patches):
        if best_k[ip] < 0 or math.sqrt(best_d[ip]) > reach:
            continue
        k = best_k[ip]
        ok, u, v, it = closest_on_patch(deg, ncp, koff, knots, pw, poff, dom, periodic, ip,
                                        seed_uv[k, 0], seed_uv[k, 1], c, size, ev_try)
        if not ok:
            continue
        d = ((ev_try[0, 0] - c[0]) ** 2 + (ev_try[0, 1] - c[1]) ** 2
             + (ev_try[0, 2] - c[2]) ** 2)
        if d < found_d:
            found, found_d = True, d
            ev[:, :] = ev_try
            _surface_row(c, r, R, t, ev, ip, u, v, it, res_f, res_i)
    return found


@njit(cache=True)
def _surface_row(c, r, R, t, ev, ip, u, v, it, res_f, res_i):
    """The row of a converged closest point ev[0] (wall frame) of patch ip at (u, v)."""
    p0, p1, p2 = ev[0, 0], ev[0, 1], ev[0, 2]
    e0, e1, e2 = p0 - c[0], p1 - c[1], p2 - c[2]
    dist = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    m0 = ev[1, 1] * ev[2, 2] - ev[1, 2] * ev[2, 1]
    m1 = ev[1, 2] * ev[2, 0] - ev[1, 0] * ev[2, 2]
    m2 = ev[1, 0] * ev[2, 1] - ev[1, 1] * ev[2, 0]
    front = -(e0 * m0 + e1 * m1 + e2 * m2) > 0.0
    if dist > 0.0:
        n0, n1, n2 = e0 / dist, e1 / dist, e2 / dist
    else:
        mm = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
        n0, n1, n2 = -m0 / mm, -m1 / mm, -m2 / mm
    for a in range(3):
        res_f[F_N + a] = R[a, 0] * n0 + R[a, 1] * n1 + R[a, 2] * n2
        res_f[F_PB + a] = R[a, 0] * p0 + R[a, 1] * p1 + R[a, 2] * p2 + t[a]
        res_f[F_PA + a] = (R[a, 0] * c[0] + R[a, 1] * c[1] + R[a, 2] * c[2] + t[a]
                           + r * res_f[F_N + a])
    sd = dist - r
    res_f[F_SD] = sd
    res_f[F_PAR + 2] = u
    res_f[F_PAR + 3] = v
    res_i[I_PA] = -1
    res_i[I_PB] = ip
    res_i[I_IT] = it
    res_i[I_VALID] = 1
    res_i[I_ACTIVE] = 1 if (sd < 0.0 and (front or dist == 0.0)) else 0


def sphere_contact(wall: SurfaceWall, x, r: float, R=None, t=None) -> tuple[np.ndarray,
                                                                             np.ndarray, bool]:
    """(res_f, res_i, ok) of one sphere (centre x m, radius r m) against ``wall`` at pose
    (R, t) (identity by default): :func:`sphere_surface_row` from Python."""
    R = np.eye(3) if R is None else np.ascontiguousarray(R, float)
    t = np.zeros(3) if t is None else np.ascontiguousarray(t, float)
    res_f, res_i = np.zeros(NF), np.zeros(NI, np.int64)
    ok = sphere_surface_row(np.ascontiguousarray(x, float), float(r), R, t, wall.deg, wall.ncp,
                            wall.koff, wall.knots, wall.pw, wall.poff, wall.dom, wall.periodic,
                            wall.seed_x, wall.seed_p, wall.seed_uv, wall.spacing, wall.size,
                            np.zeros((6, 3)), res_f, res_i)
    return res_f, res_i, bool(ok)

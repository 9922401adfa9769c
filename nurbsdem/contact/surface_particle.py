"""A convex NURBS particle against an open NURBS surface wall (the wall as body B).

The wall is not a closed convex body, so the support mapping of paper Section 3 applies to
the particle A only (paper Eq. 8–9, through
:class:`~nurbsdem.contact.support_oracle.SupportOracle`).  For the wall point S(u, v) with
unit normal n(u, v) = S_u × S_v / |S_u × S_v| (towards the particles), the particle's deepest
point below the wall's tangent plane there is its support point p = p_A(−n); the contact is
the wall point where p lies on the wall's normal line,

    F(u, v) = [ S_u · (p − S),  S_v · (p − S) ] = 0,      signed distance  sd = n · (p − S),

normal from A to the wall −n, points p (on A) and S (on the wall): the flat wall's contact
(:mod:`nurbsdem.contact.flat_wall`) on the wall's tangent plane at the solution, which is where
that tangent plane is the wall's.  It is solved by Newton on (u, v) with the exact Jacobian

    ∂F_i/∂u_j = S_ij · (p − S) + S_i · (dp/du_j − S_j),   dp/du_j = −(dp/dd) n_j,

n_j = (I − n nᵀ) ∂(S_u × S_v)/∂u_j / |S_u × S_v| (dp/dd: the Hessian of the support function,
paper Eq. 14–15), projected on the parameter rectangle as the sphere kernel does
(:mod:`nurbsdem.contact.surface_wall`: a parameter at its bound whose step leaves the
rectangle is held there; a closed direction wraps), from the nearest samples of the wall to
the particle's centroid.

**Uniqueness.**  At the solution, in an orthonormal tangent frame, the Jacobian is
J = (M_t + sd I) W − I, with M_t the particle's radii of curvature at p (dp/dd on the
tangent plane) and W the wall's shape operator (positive where the wall curves towards the
particles, as the inside of a drum).  The contact is an isolated, unique solution when J is
negative definite (its eigenvalues negative): on every convex or flat wall, and on a concave
wall whose radius of curvature exceeds the particle's (a particle inside a drum wider than
it).  Where the wall curves more tightly than the particle (a pocket narrower than the
particle: two contact points, or a ring) the formulation has no unique solution: the solve
reports it (:class:`ContactNotUnique`) for a particle that crosses the wall, as it reports a
Newton that does not converge there.

The wall is one-sided: a particle whose centroid is behind the surface makes no contact.
The solve runs compiled (:mod:`nurbsdem.contact.surface_particle_compiled`: one kernel per
particle and wall, one call per wall); the Python one here is its reference.
Lengths in metres; rows in the layout of :mod:`nurbsdem.contact.lcp` (``I_PB``: the wall's
patch, ``F_PAR + 2:4``: its (u, v); ``I_PA``: −1).
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import NurbsdemError
from ..geometry.kernel import power_derivs
from .lcp import F_N, F_PA, F_PAR, F_PB, F_SD, I_ACTIVE, I_IT, I_PA, I_PB, I_VALID, NF, NI
from .support_oracle import SupportOracle
from .surface_particle_compiled import (CONTACT, MAX_IT, MAX_STEP, NOT_CONVERGED, NOT_UNIQUE,
                                        TOL, particle_surface_rows)
from .surface_wall import SurfaceWall, _nearest_seeds


class ContactNotUnique(NurbsdemError):
    """A particle's contact with a surface wall has no unique solution (module docstring)."""


def refusal(where: str, centroid: np.ndarray, patch: int, status: int) -> ContactNotUnique:
    """The error of a refused contact (status NOT_CONVERGED or NOT_UNIQUE of
    :mod:`~nurbsdem.contact.surface_particle_compiled`) of the particle with world centroid
    ``centroid`` (m) with ``patch`` of the wall named by ``where``."""
    head = (f"{where}: the contact of a particle (centroid "
            f"{np.round(np.asarray(centroid, float), 6).tolist()} m) with patch {patch}")
    if status == NOT_CONVERGED:
        return ContactNotUnique(f"{head} did not converge")
    return ContactNotUnique(f"{head} is not unique: the wall curves more tightly than the "
                            f"particle there")


def particle_surface_row(table, shape: int, pos: np.ndarray, Rb: np.ndarray,
                         wall: SurfaceWall, R: np.ndarray | None = None,
                         t: np.ndarray | None = None, where: str = "surface wall"
                         ) -> tuple[np.ndarray, np.ndarray, bool]:
    """(res_f (NF,), res_i (NI,), found) of the NURBS particle of shape ``shape`` of
    ``table`` (a :class:`~nurbsdem.contact.detect.ContactTable`) at the pose (pos (3,) m, Rb
    (3,3)) against ``wall`` at (R, t) (``x_world = R x_wall + t``; identity by default),
    world frame, normal from the particle to the wall.  Each patch whose sample nearest to
    the centroid lies within the samples' spacing of the nearest overall is solved; the
    deepest converged contact wins.  Raises :class:`ContactNotUnique` (naming ``where``)
    when the particle crosses a patch (sd < 0) whose contact does not converge or is not
    unique (module docstring); apart from the wall, neither matters.  Compiled
    (:func:`surface_rows`); :func:`particle_surface_row_reference` is the same solve in
    Python."""
    R = np.eye(3) if R is None else np.asarray(R, float)
    t = np.zeros(3) if t is None else np.asarray(t, float)
    s = np.array([int(shape)], np.int64)
    f, i, status = surface_rows(table, wall, np.zeros(1, np.int64), s,
                                np.asarray(pos, float)[None], np.asarray(Rb, float)[None], R, t)
    if status[0, 0] == NOT_CONVERGED or status[0, 0] == NOT_UNIQUE:
        raise refusal(where, np.asarray(pos, float) + np.asarray(Rb, float)
                      @ table.centroid[s[0]], int(status[0, 1]), int(status[0, 0]))
    return f[0], i[0], bool(status[0, 0] == CONTACT)


def surface_rows(table, wall: SurfaceWall, idx: np.ndarray, body_shape: np.ndarray,
                 pos: np.ndarray, rot: np.ndarray, R: np.ndarray, t: np.ndarray):
    """(rows_f (K,NF), rows_i (K,NI), status (K,2)) of the NURBS particles ``idx`` (K,)
    (shapes ``body_shape`` (N,) in ``table``, poses pos (N,3) m, rot (N,3,3)) against
    ``wall`` at (R, t): :func:`~nurbsdem.contact.surface_particle_compiled.particle_surface_rows`
    (status: CONTACT, NO_CONTACT, or a refusal with its patch)."""
    K = len(idx)
    rows_f, rows_i = np.zeros((K, NF)), np.zeros((K, NI), np.int64)
    status = np.zeros((K, 2), np.int64)
    c = np.ascontiguousarray
    particle_surface_rows(c(idx, np.int64), c(body_shape, np.int64), c(pos, float),
                          c(rot, float), c(R, float), c(t, float), table.tab, table.info,
                          table.centroid, table.radius, table.seeds, wall.deg, wall.ncp,
                          wall.koff, wall.knots, wall.pw, wall.poff, wall.dom, wall.periodic,
                          wall.seed_x, wall.seed_p, wall.seed_uv, float(wall.spacing),
                          float(wall.size), rows_f, rows_i, status)
    return rows_f, rows_i, status


def _derivs(wall: SurfaceWall, ip: int, u: float, v: float, ev: np.ndarray) -> None:
    """S and its first and second derivatives at (u, v) of patch ip into ev (6,3)."""
    power_derivs(wall.deg, wall.ncp, wall.koff, wall.knots, wall.pw, wall.poff, ip, u, v, 2,
                 ev)


def _normal_derivatives(ev: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(n, n_u, n_v): the unit normal S_u × S_v / |·| and its derivatives."""
    su, sv, suu, suv, svv = ev[1], ev[2], ev[3], ev[4], ev[5]
    m = np.cross(su, sv)
    mm = float(np.linalg.norm(m))
    n = m / mm
    P = np.eye(3) - np.outer(n, n)
    nu = P @ (np.cross(suu, sv) + np.cross(su, suv)) / mm
    nv = P @ (np.cross(suv, sv) + np.cross(su, svv)) / mm
    return n, nu, nv


def _residual(oracle: SupportOracle, ev: np.ndarray):
    """(F (2,), J (2,2), p, n, sd, ok) at the wall point of ev (module docstring)."""
    n, nu, nv = _normal_derivatives(ev)
    p, M, ok = oracle.point(-n)
    r = p - ev[0]
    tang = (ev[1], ev[2])
    dp = (-(M @ nu), -(M @ nv))
    second = ((ev[3], ev[4]), (ev[4], ev[5]))
    F = np.array([tang[0] @ r, tang[1] @ r])
    J = np.array([[second[i][j] @ r + tang[i] @ (dp[j] - tang[j]) for j in range(2)]
                  for i in range(2)])
    return F, J, p, n, float(n @ r), ok


def _unique(J: np.ndarray, ev: np.ndarray) -> bool:
    """Whether the Jacobian's operator on the tangent plane (G⁻¹ J, G the metric) has
    negative eigenvalues (module docstring: the contact is unique)."""
    G = np.array([[ev[1] @ ev[1], ev[1] @ ev[2]], [ev[1] @ ev[2], ev[2] @ ev[2]]])
    Y = np.linalg.solve(G, J)
    return bool(np.linalg.det(Y) > 0.0 and np.trace(Y) < 0.0)


def _step_in(x: float, dx: float, lo: float, hi: float, wrap: bool) -> float:
    """x + dx kept in [lo, hi] (wrapped along a closed direction)."""
    if wrap:
        span = hi - lo
        y = x + dx
        return y - span * math.floor((y - lo) / span)
    return min(max(x + dx, lo), hi)


def _solve_patch(oracle: SupportOracle, wall: SurfaceWall, ip: int, u: float, v: float):
    """Projected Newton on patch ip from (u, v): (sd, p, S, n, u, v, iterations, unique),
    or (sd,) of the last iterate when it does not converge (None: no support point)."""
    u0, u1, v0, v1 = wall.dom[ip]
    wrap_u, wrap_v = bool(wall.periodic[ip, 0]), bool(wall.periodic[ip, 1])
    ev = np.zeros((6, 3))
    for it in range(MAX_IT):
        _derivs(wall, ip, u, v, ev)
        F, J, p, n, sd, ok = _residual(oracle, ev)
        if not ok:
            return None
        su, sv = float(np.linalg.norm(ev[1])), float(np.linalg.norm(ev[2]))
        try:
            step = -np.linalg.solve(J, F)
        except np.linalg.LinAlgError:
            return (sd,)
        fix_u = not wrap_u and ((u <= u0 and step[0] < 0.0) or (u >= u1 and step[0] > 0.0))
        fix_v = not wrap_v and ((v <= v0 and step[1] < 0.0) or (v >= v1 and step[1] > 0.0))
        if fix_u and fix_v:
            step[:] = 0.0
        elif fix_u:
            step = np.array([0.0, -F[1] / J[1, 1]])
        elif fix_v:
            step = np.array([-F[0] / J[0, 0], 0.0])
        gu = 0.0 if fix_u else F[0]
        gv = 0.0 if fix_v else F[1]
        if abs(gu) <= TOL * wall.size * su and abs(gv) <= TOL * wall.size * sv:
            return sd, p, ev[0].copy(), n, u, v, it, _unique(J, ev)
        step[0] = max(min(step[0], MAX_STEP * (u1 - u0)), -MAX_STEP * (u1 - u0))
        step[1] = max(min(step[1], MAX_STEP * (v1 - v0)), -MAX_STEP * (v1 - v0))
        u = _step_in(u, step[0], u0, u1, wrap_u)
        v = _step_in(v, step[1], v0, v1, wrap_v)
    return (sd,)


def particle_surface_row_reference(table, shape: int, pos: np.ndarray, Rb: np.ndarray,
                                   wall: SurfaceWall, R: np.ndarray | None = None,
                                   t: np.ndarray | None = None, where: str = "surface wall",
                                   reach: float | None = None
                                   ) -> tuple[np.ndarray, np.ndarray, bool]:
    """:func:`particle_surface_row` (the same arguments, result and refusals) solved in
    Python through :class:`~nurbsdem.contact.support_oracle.SupportOracle`: the reference of
    the compiled kernel (tests).  ``reach`` (m): the patches within it (and the samples'
    spacing) of the centroid are solved (None: the bounding radius; a larger one gives a
    separated particle's exact distance, ``MoveWall … ToContact``)."""
    R = np.eye(3) if R is None else np.asarray(R, float)
    t = np.zeros(3) if t is None else np.asarray(t, float)
    oracle = SupportOracle(table, shape, R.T @ (np.asarray(pos, float) - t),
                           R.T @ np.asarray(Rb, float))
    if reach is not None and reach > oracle.radius:
        oracle.radius = float(reach)        # the flat-wall solve's early exit beyond it too
    c = oracle.centroid
    n_patches = wall.dom.shape[0]
    best_k = np.empty(n_patches, np.int64)
    best_d = np.empty(n_patches)
    _nearest_seeds(wall.seed_x, wall.seed_p, n_patches, c, best_k, best_d)
    reach = math.sqrt(best_d.min()) + wall.spacing
    res_f, res_i = np.zeros(NF), np.zeros(NI, np.int64)
    found = None
    for ip in range(n_patches):
        if best_k[ip] < 0 or math.sqrt(best_d[ip]) > reach:
            continue
        if math.sqrt(best_d[ip]) > oracle.radius + wall.spacing:
            continue                         # the particle does not reach this patch
        k = best_k[ip]
        hit = _solve_patch(oracle, wall, ip, wall.seed_uv[k, 0], wall.seed_uv[k, 1])
        if hit is None or (len(hit) == 1 and not hit[0] < 0.0):
            continue                         # no support point, or clear of the wall
        if len(hit) == 1:
            raise refusal(where, R @ c + t, ip, NOT_CONVERGED)
        if not hit[7] and hit[0] < 0.0:
            raise refusal(where, R @ c + t, ip, NOT_UNIQUE)
        if found is None or hit[0] < found[0]:
            found = hit + (ip,)
    if found is None:
        return res_f, res_i, False
    sd, p, S, n, u, v, it, _, ip = found
    res_f[F_SD] = sd
    res_f[F_N:F_N + 3] = -(R @ n)
    res_f[F_PA:F_PA + 3] = R @ p + t
    res_f[F_PB:F_PB + 3] = R @ S + t
    res_f[F_PAR + 2], res_f[F_PAR + 3] = u, v
    res_i[I_PA] = -1
    res_i[I_PB] = ip
    res_i[I_IT] = it
    res_i[I_VALID] = 1
    front = float(n @ (c - S)) > 0.0
    res_i[I_ACTIVE] = 1 if (sd < 0.0 and front) else 0
    return res_f, res_i, True

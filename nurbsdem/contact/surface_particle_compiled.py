"""A convex NURBS particle against an open NURBS surface wall, compiled: the contact of
:mod:`nurbsdem.contact.surface_particle` (its module docstring states the problem, the Newton
iteration over the wall's (u, v) and the uniqueness test) in one kernel per particle and wall.

The support point p_A(d) along the wall's normal d = −n and its derivative dp/dd (paper Eq.
8–9, 14–15) come from the flat-wall kernel (:func:`~nurbsdem.contact.flat_wall.solve_wall`,
through its pointer, compiled once for this caller and the flat walls' batches) against the
plane through the centroid with normal −d, each query warm-started from the previous
converged one (the parameters moved to first order to the new direction), exactly as the
Python :class:`~nurbsdem.contact.support_oracle.SupportOracle` asks it: the rows agree with
the Python solve (:func:`~nurbsdem.contact.surface_particle.particle_surface_row_reference`)
to round-off.

:func:`particle_surface_into` solves one particle against one wall and returns a status:
:data:`CONTACT` (a row), :data:`NO_CONTACT` (no patch within reach gave one, or all are
clear), or a refusal (:data:`NOT_CONVERGED`, :data:`NOT_UNIQUE`) with the patch, which the
Python side turns into :class:`~nurbsdem.contact.surface_particle.ContactNotUnique` naming
the wall.  :func:`particle_surface_rows` runs the particles of one wall in one call (the
Python provider, the compiled deck steps and, for one particle,
:func:`~nurbsdem.contact.surface_particle.particle_surface_row`).

Its pieces (start, the iteration's support query, normal, residual and step, the result
row) are plain kernels over one tuple of named workspaces (:func:`make_surface_work`).
Lengths in metres.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..geometry.kernel import make_workspace, power_derivs
from ..jit import PointerKernel, kernel
from .lcp import (F_N, F_PA, F_PAR, F_PB, F_SD, I_ACTIVE, I_FAIL, I_IT, I_PA, I_PB, I_VALID,
                  NF, NI, make_work)
from .stage2 import _MA, _to_world
from .flat_wall import solve_wall_ptr

#: Newton iterations before a solve counts as not converged
MAX_IT = 50
#: convergence: |F| below this × the wall's size × |S_u| (and |S_v|)
TOL = 1e-13
#: the largest Newton step, as a fraction of the parameter rectangle's side
MAX_STEP = 0.25

#: statuses of :func:`particle_surface_into`: a contact row; none; the Newton of a patch the
#: particle crosses did not converge; its contact there is not unique
NO_CONTACT, CONTACT, NOT_CONVERGED, NOT_UNIQUE = 0, 1, 2, 3
#: statuses of one patch's solve (:func:`_solve_patch`): converged; not converged; no support
#: point
_CONVERGED, _OPEN, _NO_SUPPORT = 0, 1, 2

#: rows of the workspace ``sw``: the centroid and the body's position in the wall's frame;
#: the support point and dp/dd (3 rows, wall frame); the wall's unit normal n and its
#: derivatives n_u, n_v; the query direction d and the query plane's edges a, b
_C, _POS, _P, _M, _N, _NU, _NV, _D, _A, _B = 0, 1, 2, 3, 6, 7, 8, 9, 10, 11
SW_ROWS = 12
#: the query planes' parameter rectangle (u_min, u_max, v_min, v_max)
UNIT_DOMAIN = np.array([0.0, 1.0, 0.0, 1.0])


@njit(cache=True)
def make_surface_work(n_patches):
    """The workspaces of :func:`particle_surface_into` for a wall of ``n_patches`` patches
    (one set per thread), one tuple: the support mapping's (ws, wf, wi, wfs, no_mask), sw
    (rows above), the body's rotation in the wall's frame rw (3,3), the query planes'
    rectangle wdom (4,), the wall's evaluation ev (6,3), the warm start's rows prev_f (NF,),
    prev_i (NI,), a query's rows qf (NF,), qi (NI,), and per patch the nearest sample best_k
    (P,) and its squared distance best_d (P,)."""
    wf, wi, wfs, _ = make_work()
    return (make_workspace(), wf, wi, wfs, np.zeros(0, np.bool_), np.zeros((SW_ROWS, 3)),
            np.zeros((3, 3)), UNIT_DOMAIN.copy(), np.zeros((6, 3)), np.zeros(NF),
            np.zeros(NI, np.int64), np.zeros(NF), np.zeros(NI, np.int64),
            np.empty(n_patches, np.int64), np.empty(n_patches))


# --------------------------------------------------------------------------- start
@kernel(inline="always")
def _start(pos, Rb, R, t, cen, sw, rw, prev_i, res_f, res_i):
    """The particle's pose (pos, Rb; world) in the frame of the wall at (R, t) into sw[_POS]
    and rw, its centroid there into sw[_C]; no warm start yet; the result rows cleared."""
    for a in range(3):
        sw[_POS, a] = (R[0, a] * (pos[0] - t[0]) + R[1, a] * (pos[1] - t[1])
                       + R[2, a] * (pos[2] - t[2]))
        for b in range(3):
            rw[a, b] = R[0, a] * Rb[0, b] + R[1, a] * Rb[1, b] + R[2, a] * Rb[2, b]
    _to_world(sw[_POS], rw, cen, sw[_C])
    prev_i[I_VALID] = 0
    for k in range(res_f.shape[0]):
        res_f[k] = 0.0
    for k in range(res_i.shape[0]):
        res_i[k] = 0


@kernel(inline="always")
def _nearest(seed_x, seed_p, c, best_k, best_d):
    """Per patch, the index ``best_k`` and squared distance ``best_d`` of its sample nearest
    to c (−1 and 1e300 for a patch without samples); returns the smallest distance (m)."""
    for ip in range(best_k.shape[0]):
        best_d[ip] = 1e300
        best_k[ip] = -1
    low = 1e300
    for k in range(seed_x.shape[0]):
        d = (seed_x[k, 0] - c[0]) ** 2 + (seed_x[k, 1] - c[1]) ** 2 + (seed_x[k, 2] - c[2]) ** 2
        ip = seed_p[k]
        if d < best_d[ip]:
            best_d[ip] = d
            best_k[ip] = k
        low = min(low, d)
    return math.sqrt(low)


# --------------------------------------------------------------------------- iteration
@kernel(inline="always")
def _support(tab, info, cen, rad, seeds, work):
    """The support point of the particle along the unit direction sw[_D] (wall frame) into
    sw[_P] and its dp/dd into sw[_M:_M+3] (wall frame): the flat-wall kernel
    (:func:`~nurbsdem.contact.flat_wall.solve_wall`, its rows in qf, qi) against the plane
    through the centroid with normal −d, spanned by a ⊥ d and b = a × d, warm-started from
    the previous converged query's rows (prev_f, prev_i), which a converged query replaces,
    as :class:`~nurbsdem.contact.support_oracle.SupportOracle` asks it.  Returns whether it
    converged to a finite point."""
    ws, wf, wi, wfs, no_mask, sw, rw, wdom, _, prev_f, prev_i, qf, qi, _, _ = work
    d, a, b = sw[_D], sw[_A], sw[_B]
    k = 0                                # a: the unit axis least along d, made ⊥ d
    if abs(d[1]) < abs(d[k]):
        k = 1
    if abs(d[2]) < abs(d[k]):
        k = 2
    for c in range(3):
        a[c] = -d[c] * d[k]
    a[k] += 1.0
    na = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    a[0], a[1], a[2] = a[0] / na, a[1] / na, a[2] / na
    b[0] = a[1] * d[2] - a[2] * d[1]     # a × b = −d: the plane's normal is −d
    b[1] = a[2] * d[0] - a[0] * d[2]
    b[2] = a[0] * d[1] - a[1] * d[0]
    solve_wall_ptr(tab, info, cen, rad, seeds, sw[_POS], rw, sw[_C], a, b, wdom, prev_f,
                   prev_i, ws, wf, wi, wfs, no_mask, qf, qi)
    for c in range(3):
        sw[_P, c] = qf[F_PA + c]
    Mb = wf[_MA:_MA + 3]
    for r in range(3):                  # M = Rw Mb Rwᵀ
        for c in range(3):
            m = 0.0
            for k in range(3):
                m += rw[r, k] * (Mb[k, 0] * rw[c, 0] + Mb[k, 1] * rw[c, 1] + Mb[k, 2] * rw[c, 2])
            sw[_M + r, c] = m
    ok = qi[I_FAIL] == 0 and qi[I_VALID] == 1
    if ok:
        for c in range(qf.shape[0]):
            prev_f[c] = qf[c]
        for c in range(qi.shape[0]):
            prev_i[c] = qi[c]
    return ok


@kernel(inline="always")
def _normal(ev, sw):
    """The wall's unit normal n = S_u × S_v / |·| at ev into sw[_N], its derivatives
    (I − n nᵀ) ∂(S_u × S_v)/∂u_j / |S_u × S_v| into sw[_NU], sw[_NV], and d = −n into
    sw[_D]."""
    m0 = ev[1, 1] * ev[2, 2] - ev[1, 2] * ev[2, 1]
    m1 = ev[1, 2] * ev[2, 0] - ev[1, 0] * ev[2, 2]
    m2 = ev[1, 0] * ev[2, 1] - ev[1, 1] * ev[2, 0]
    mm = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
    n = sw[_N]
    n[0], n[1], n[2] = m0 / mm, m1 / mm, m2 / mm
    for j in range(2):
        # ∂(S_u × S_v)/∂u_j = S_uj × S_v + S_u × S_vj   (S_uu, S_uv | S_uv, S_vv)
        a = ev[3 + j]
        b = ev[4 + j]
        x0 = (a[1] * ev[2, 2] - a[2] * ev[2, 1]) + (ev[1, 1] * b[2] - ev[1, 2] * b[1])
        x1 = (a[2] * ev[2, 0] - a[0] * ev[2, 2]) + (ev[1, 2] * b[0] - ev[1, 0] * b[2])
        x2 = (a[0] * ev[2, 1] - a[1] * ev[2, 0]) + (ev[1, 0] * b[1] - ev[1, 1] * b[0])
        nx = n[0] * x0 + n[1] * x1 + n[2] * x2
        out = sw[_NU + j]
        out[0] = (x0 - n[0] * nx) / mm
        out[1] = (x1 - n[1] * nx) / mm
        out[2] = (x2 - n[2] * nx) / mm
    sw[_D, 0], sw[_D, 1], sw[_D, 2] = -n[0], -n[1], -n[2]


@kernel(inline="always")
def _residual(ev, sw):
    """(F_u, F_v, J_uu, J_uv, J_vu, J_vv, sd) at the wall point of ev with the support point
    sw[_P] and its dp/dd sw[_M:_M+3] (the module docstring of
    :mod:`~nurbsdem.contact.surface_particle`): F_i = S_i · r, J_ij = S_ij · r + S_i · (dp/du_j
    − S_j), dp/du_j = −M n_j, r = p − S, sd = n · r."""
    p, M, n = sw[_P], sw[_M:_M + 3], sw[_N]
    r0, r1, r2 = p[0] - ev[0, 0], p[1] - ev[0, 1], p[2] - ev[0, 2]
    Fu = ev[1, 0] * r0 + ev[1, 1] * r1 + ev[1, 2] * r2
    Fv = ev[2, 0] * r0 + ev[2, 1] * r1 + ev[2, 2] * r2
    Juu = Juv = Jvu = Jvv = 0.0
    for j in range(2):
        nj = sw[_NU + j]
        q0 = -(M[0, 0] * nj[0] + M[0, 1] * nj[1] + M[0, 2] * nj[2]) - ev[1 + j, 0]
        q1 = -(M[1, 0] * nj[0] + M[1, 1] * nj[1] + M[1, 2] * nj[2]) - ev[1 + j, 1]
        q2 = -(M[2, 0] * nj[0] + M[2, 1] * nj[1] + M[2, 2] * nj[2]) - ev[1 + j, 2]
        su = ev[3 + j]                  # S_u,j: S_uu, S_uv
        sv = ev[4 + j]                  # S_v,j: S_uv, S_vv
        ju = (su[0] * r0 + su[1] * r1 + su[2] * r2
              + ev[1, 0] * q0 + ev[1, 1] * q1 + ev[1, 2] * q2)
        jv = (sv[0] * r0 + sv[1] * r1 + sv[2] * r2
              + ev[2, 0] * q0 + ev[2, 1] * q1 + ev[2, 2] * q2)
        if j == 0:
            Juu, Jvu = ju, jv
        else:
            Juv, Jvv = ju, jv
    sd = n[0] * r0 + n[1] * r1 + n[2] * r2
    return Fu, Fv, Juu, Juv, Jvu, Jvv, sd


@kernel(inline="always")
def _solve2(a00, a01, a10, a11, b0, b1):
    """(ok, x0, x1): A x = b by Gauss elimination with partial pivoting (LAPACK's order);
    not ok where a pivot is exactly zero (a singular A)."""
    if abs(a10) > abs(a00):
        a00, a01, a10, a11 = a10, a11, a00, a01
        b0, b1 = b1, b0
    if a00 == 0.0:
        return False, 0.0, 0.0
    l = a10 / a00
    piv = a11 - l * a01
    if piv == 0.0:
        return False, 0.0, 0.0
    x1 = (b1 - l * b0) / piv
    return True, (b0 - a01 * x1) / a00, x1


@kernel(inline="always")
def _unique(ev, Juu, Juv, Jvu, Jvv):
    """Whether the Jacobian's operator on the tangent plane (G⁻¹ J, G the metric) has
    negative eigenvalues: a positive determinant and a negative trace."""
    g00 = ev[1, 0] * ev[1, 0] + ev[1, 1] * ev[1, 1] + ev[1, 2] * ev[1, 2]
    g01 = ev[1, 0] * ev[2, 0] + ev[1, 1] * ev[2, 1] + ev[1, 2] * ev[2, 2]
    g11 = ev[2, 0] * ev[2, 0] + ev[2, 1] * ev[2, 1] + ev[2, 2] * ev[2, 2]
    det = g00 * g11 - g01 * g01
    y00 = (g11 * Juu - g01 * Jvu) / det
    y01 = (g11 * Juv - g01 * Jvv) / det
    y10 = (g00 * Jvu - g01 * Juu) / det
    y11 = (g00 * Jvv - g01 * Juv) / det
    return y00 * y11 - y01 * y10 > 0.0 and y00 + y11 < 0.0


@kernel(inline="always")
def _step_in(x, dx, lo, hi, wrap):
    """x + dx kept in [lo, hi] (wrapped along a closed direction)."""
    if wrap:
        span = hi - lo
        y = x + dx
        return y - span * math.floor((y - lo) / span)
    return min(max(x + dx, lo), hi)


@kernel(inline="always")
def _solve_patch(tab, info, cen, rad, seeds, deg, ncp, koff, knots, pw, poff, dom, periodic,
                 size, ip, u, v, work):
    """Projected Newton on patch ip of the wall from (u, v) (the Python ``_solve_patch``):
    (status, sd, u, v, iterations, unique).  Converged: ev holds the wall point S and its
    derivatives, sw[_P] the support point and sw[_N] the normal; not converged: sd of the
    last iterate; no support point: nothing."""
    sw, ev = work[5], work[8]
    u0, u1, v0, v1 = dom[ip, 0], dom[ip, 1], dom[ip, 2], dom[ip, 3]
    wrap_u, wrap_v = periodic[ip, 0], periodic[ip, 1]
    sd = 0.0
    for it in range(MAX_IT):
        power_derivs(deg, ncp, koff, knots, pw, poff, ip, u, v, 2, ev)
        _normal(ev, sw)
        if not _support(tab, info, cen, rad, seeds, work):
            return _NO_SUPPORT, sd, u, v, it, False
        Fu, Fv, Juu, Juv, Jvu, Jvv, sd = _residual(ev, sw)
        su = math.sqrt(ev[1, 0] ** 2 + ev[1, 1] ** 2 + ev[1, 2] ** 2)
        sv = math.sqrt(ev[2, 0] ** 2 + ev[2, 1] ** 2 + ev[2, 2] ** 2)
        ok, du, dv = _solve2(Juu, Juv, Jvu, Jvv, -Fu, -Fv)
        if not ok:
            return _OPEN, sd, u, v, it, False
        fix_u = not wrap_u and ((u <= u0 and du < 0.0) or (u >= u1 and du > 0.0))
        fix_v = not wrap_v and ((v <= v0 and dv < 0.0) or (v >= v1 and dv > 0.0))
        if fix_u and fix_v:
            du = dv = 0.0
        elif fix_u:                       # a zero diagonal: no step (Python: ±inf, clipped)
            du, dv = 0.0, (-Fv / Jvv if Jvv != 0.0 else 0.0)
        elif fix_v:
            du, dv = (-Fu / Juu if Juu != 0.0 else 0.0), 0.0
        gu = 0.0 if fix_u else Fu
        gv = 0.0 if fix_v else Fv
        if abs(gu) <= TOL * size * su and abs(gv) <= TOL * size * sv:
            return _CONVERGED, sd, u, v, it, _unique(ev, Juu, Juv, Jvu, Jvv)
        du = max(min(du, MAX_STEP * (u1 - u0)), -MAX_STEP * (u1 - u0))
        dv = max(min(dv, MAX_STEP * (v1 - v0)), -MAX_STEP * (v1 - v0))
        u = _step_in(u, du, u0, u1, wrap_u)
        v = _step_in(v, dv, v0, v1, wrap_v)
    return _OPEN, sd, u, v, MAX_IT, False


# --------------------------------------------------------------------------- result
@kernel(inline="always")
def _result(R, t, sw, ev, ip, u, v, it, sd, res_f, res_i):
    """The row (world frame, normal from the particle to the wall, −R n) of the converged
    contact of patch ip at (u, v): S = ev[0], p = sw[_P], n = sw[_N] (wall frame)."""
    n, p, c = sw[_N], sw[_P], sw[_C]
    for a in range(3):
        res_f[F_N + a] = -(R[a, 0] * n[0] + R[a, 1] * n[1] + R[a, 2] * n[2])
        res_f[F_PA + a] = R[a, 0] * p[0] + R[a, 1] * p[1] + R[a, 2] * p[2] + t[a]
        res_f[F_PB + a] = R[a, 0] * ev[0, 0] + R[a, 1] * ev[0, 1] + R[a, 2] * ev[0, 2] + t[a]
    res_f[F_SD] = sd
    res_f[F_PAR + 2] = u
    res_f[F_PAR + 3] = v
    res_i[I_PA] = -1
    res_i[I_PB] = ip
    res_i[I_IT] = it
    res_i[I_VALID] = 1
    front = (n[0] * (c[0] - ev[0, 0]) + n[1] * (c[1] - ev[0, 1])
             + n[2] * (c[2] - ev[0, 2])) > 0.0
    res_i[I_ACTIVE] = 1 if (sd < 0.0 and front) else 0


@kernel
def particle_surface_into(tab, info, cen, rad, seeds, pos, Rb, R, t, deg, ncp, koff, knots,
                          pw, poff, dom, periodic, seed_x, seed_p, seed_uv, spacing, size, work,
                          res_f, res_i):
    """The row (res_f (NF,), res_i (NI,)) of the NURBS particle of table ``tab`` with shape
    ``info`` (one row of ContactTable.info), centroid ``cen`` (3,) m and bounding radius
    ``rad`` m, at the pose (pos (3,) m, Rb (3,3); world), against the surface wall of the
    arrays ``deg`` … ``size`` (:class:`~nurbsdem.contact.surface_wall.SurfaceWall`) at (R,
    t) (``x_world = R x_wall + t``): each patch whose sample nearest to the centroid lies
    within the samples' spacing of the nearest overall and within the particle's reach is
    solved from that sample; the deepest converged contact wins.  ``work``: the workspaces
    of :func:`make_surface_work`.  Returns (status, patch):
    CONTACT or NO_CONTACT with −1, or NOT_CONVERGED / NOT_UNIQUE with the patch where the
    particle crosses the wall (sd < 0) and the solve there did not converge or is not unique
    (the Python side raises; the rows are then undefined)."""
    sw, rw, ev, prev_i, best_k, best_d = work[5], work[6], work[8], work[10], work[13], work[14]
    _start(pos, Rb, R, t, cen, sw, rw, prev_i, res_f, res_i)
    reach = _nearest(seed_x, seed_p, sw[_C], best_k, best_d) + spacing
    found = False
    found_sd = 0.0
    for ip in range(dom.shape[0]):
        if best_k[ip] < 0:
            continue
        dist = math.sqrt(best_d[ip])
        if dist > reach or dist > rad + spacing:
            continue                          # the particle does not reach this patch
        k = best_k[ip]
        status, sd, u, v, it, unique = _solve_patch(
            tab, info, cen, rad, seeds, deg, ncp, koff, knots, pw, poff, dom, periodic, size,
            ip, seed_uv[k, 0], seed_uv[k, 1], work)
        if status == _NO_SUPPORT or (status == _OPEN and not sd < 0.0):
            continue                          # no support point, or clear of the wall
        if status == _OPEN:
            return NOT_CONVERGED, ip
        if not unique and sd < 0.0:
            return NOT_UNIQUE, ip
        if not found or sd < found_sd:
            found = True
            found_sd = sd
            _result(R, t, sw, ev, ip, u, v, it, sd, res_f, res_i)
    return (CONTACT if found else NO_CONTACT), np.int64(-1)


@njit(cache=True)
def particle_surface_rows(idx, body_shape, pos, rot, R, t, tab, info, cen, rad, seeds, deg,
                          ncp, koff, knots, pw, poff, dom, periodic, seed_x, seed_p, seed_uv,
                          spacing, size, rows_f, rows_i, status):
    """Rows m (rows_f (K,NF), rows_i (K,NI)) of the NURBS particles ``idx`` (K,) (shapes
    ``body_shape`` (N,), poses pos (N,3) m, rot (N,3,3); the arrays tab … seeds of a
    :class:`~nurbsdem.contact.detect.ContactTable`) against one surface wall at (R, t):
    :func:`particle_surface_into` for each, its (status, patch) in ``status`` (K,2).  One
    set of workspaces for all (the Python provider's and the compiled deck steps' call)."""
    work = make_surface_work(dom.shape[0])
    for m in range(idx.shape[0]):
        i = idx[m]
        s = body_shape[i]
        status[m, 0], status[m, 1] = particle_surface_into(
            tab, info[s], cen[s], rad[s], seeds, pos[i], rot[i], R, t, deg, ncp, koff, knots,
            pw, poff, dom, periodic, seed_x, seed_p, seed_uv, spacing, size, work, rows_f[m],
            rows_i[m])


#: :func:`particle_surface_rows` through a lazy pointer (group "surface_particles",
#: :func:`~nurbsdem.jit.fill_lazy_kernels`): the compiled deck steps call it for a scene with
#: NURBS particles and surface walls only
particle_surface_rows_ptr = PointerKernel(particle_surface_rows, "particle_surface_rows",
                                          lazy="surface_particles").call

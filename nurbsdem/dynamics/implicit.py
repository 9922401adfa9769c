"""Implicit normal dashpots: the paper's damping without its explicit stability limit.

Why
---
The explicit scheme (:mod:`nurbsdem.dynamics.integrator`) evaluates the dashpot of Eq. 16,
``fn = εn g + cn ġn``, with the half-step velocities.  Its stability limit is the damped spring's
Δt_cr = (2/ω)(√(1+ζ²) − ζ) (:mod:`nurbsdem.dynamics.stepcontrol`, Eq. 1): strong damping
shortens the step.  In the paper's dense pack the network's damping rate γ ≈ 8400 1/s against
ω ≈ 3000 rad/s (ζ ≈ 1.4) makes the limit 3.2× shorter than the undamped 2/ω.  The paper's
solver is implicit (Newmark); ``Damping Implicit`` on a step makes only the dashpots implicit.

The scheme
----------
In the kick–drift–kick step the force of an evaluation at x(n+1) acts through two half kicks:
the closing one of step n and the opening one of step n+1, together an impulse h F.  Its
normal dashpot part is taken at the velocity *after* both, v⁺ = v(n+3/2), instead of the
half-step velocity v(n+1/2) of the explicit scheme:

    f_c = max(−f_el,c , −cn_c w_c(v⁺))                    (Eq. 16, clipped so that fn ≥ 0)
    M v⁺ = M v(n+1/2) + h (F₀ + Σ_c N_cᵀ f_c)

with w_c = n_c·(relative velocity of B w.r.t. A at the contact point), N_c the map of a unit
normal force at c to the bodies' generalised forces, F₀ all other loads (elastic normal force,
tangential force, gravity).  Eliminating v⁺ gives a bound-constrained, strictly convex
quadratic programme in the K dashpot forces (the damping analogue of a Delassus problem):

    min ½ fᵀ A f + fᵀ w₀   s.t.  f ≥ −f_el ,   A = diag(1/cn) + h G ,  G = N M⁻¹ Nᵀ          (D1)

w₀ the normal velocities that v⁺ would have without dashpots.  Its KKT conditions are exactly
the clipped law above (a contact at its bound is one whose dashpot would pull).  A is SPD with
eigenvalues in [1/cn_max, 1/cn_min + h λmax(G)], so conjugate gradients on the free contacts
converge in a few iterations (condition number about 1 + γh); the bound is handled by an
active set (:func:`solve_dashpots`).

Stability: for a linear spring–dashpot this is Störmer–Verlet in the stiffness and backward
Euler in the damping, stable for h < 2/ω whatever the damping (the spectral radius of the
step is ≤ 1 for all hω < 2, γh ≥ 0), and L-stable in the damping: a dashpot much faster than
the step brings the relative velocity to rest instead of reversing it (the trapezoidal rule
would make an overdamped contact bounce back with (γh/2 − 1)/(γh/2 + 1) of its speed).  The
time-step control then leaves the normal dashpots out of γ in Eq. 1.  The scheme stays a
kick–drift–kick splitting, and the energy ledger (exact work of the impulses actually applied)
is unchanged.  Accuracy: first order in the damping (test_implicit: the restitution of a
ζ = 0.3 impact converges at first order, as the explicit scheme's, whose error comes from the
contact starting and ending between two samples).  The dashpots are solved with the tangential
loads of the explicit evaluation; the Coulomb limit then takes the implicit f_n.

The operator G works in the mass-scaled coordinates of :mod:`nurbsdem.dynamics.stepcontrol`
(y = M^{1/2}(v, ω in the principal frame)) with the rows of N M^{-1/2} formed once per solve
(:func:`normal_rows`), so that a CG iteration is 24 multiply–adds per contact.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..jit import ROW_CHUNK, THREADED_ROWS, n_chunks
from .forces import contact_loads
from .images import fold_images, image_rows
from .integrator import _relative_point_velocities
from .rigid import omega_world

#: relative residual of the conjugate gradients: |A f + w₀|₂ on the free set ≤ this × scale √K
#: (scale: the largest |w₀| or f_el/cn, m/s): the velocities after the step 1e-10 of the
#: scale from the law's, far below what the contact geometry resolves; 1e-12 costs about a
#: fifth more CG iterations per solve for nothing the balance sees (the energy ledger takes
#: the work of the forces applied, so its balance does not see the residual)
CG_TOLERANCE = 1e-10
#: conjugate-gradient iterations per active-set round (a safeguard; a few tens suffice)
CG_MAX_ITERATIONS = 500
#: active-set rounds (contacts moving between free and clipped)
MAX_ROUNDS = 50


@njit(cache=True)
def _lever_arms_range(body_a, body_b, point, x, r_a, r_b, lo: int, hi: int) -> None:
    """:func:`lever_arms` of contacts lo .. hi-1."""
    n_part = x.shape[0]
    for c in range(lo, hi):
        for k in range(3):
            r_a[c, k] = point[c, k] - x[body_a[c], k] if body_a[c] < n_part else 0.0
            r_b[c, k] = point[c, k] - x[body_b[c], k] if body_b[c] < n_part else 0.0


@njit(cache=True, parallel=True)
def _lever_arms_threads(body_a, body_b, point, x, r_a, r_b) -> None:
    n = body_a.shape[0]
    for t in prange(n_chunks(n)):
        _lever_arms_range(body_a, body_b, point, x, r_a, r_b, t * ROW_CHUNK,
                          min(n, (t + 1) * ROW_CHUNK))


@njit(cache=True)
def lever_arms(body_a: np.ndarray, body_b: np.ndarray, point: np.ndarray, x: np.ndarray,
               r_a: np.ndarray, r_b: np.ndarray) -> None:
    """r_a, r_b (K,3) = contact point − centroid (m) of A and B (walls, index ≥ N: 0); on
    threads from :data:`~nurbsdem.jit.THREADED_ROWS` contacts (the same bits)."""
    if body_a.shape[0] >= THREADED_ROWS:
        _lever_arms_threads(body_a, body_b, point, x, r_a, r_b)
    else:
        _lever_arms_range(body_a, body_b, point, x, r_a, r_b, np.int64(0), body_a.shape[0])


@njit(cache=True)
def _normal_rows_range(body_a, body_b, r_a, r_b, normal, Q, sq_m, sq_I, rows, lo: int,
                       hi: int) -> None:
    """:func:`normal_rows` of contacts lo .. hi-1."""
    n_part = sq_m.shape[0]
    for c in range(lo, hi):
        for side in range(2):
            i = body_b[c] if side == 0 else body_a[c]
            if i >= n_part:
                rows[c, side, :] = 0.0
                continue
            sign = 1.0 if side == 0 else -1.0
            r0, r1, r2 = ((r_b[c, 0], r_b[c, 1], r_b[c, 2]) if side == 0
                          else (r_a[c, 0], r_a[c, 1], r_a[c, 2]))
            n0, n1, n2 = normal[c, 0], normal[c, 1], normal[c, 2]
            x0, x1, x2 = r1 * n2 - r2 * n1, r2 * n0 - r0 * n2, r0 * n1 - r1 * n0
            for k in range(3):
                rows[c, side, k] = sign * normal[c, k] / sq_m[i]
                rows[c, side, 3 + k] = sign * (Q[i, 0, k] * x0 + Q[i, 1, k] * x1
                                               + Q[i, 2, k] * x2) / sq_I[i, k]


@njit(cache=True, parallel=True)
def _normal_rows_threads(body_a, body_b, r_a, r_b, normal, Q, sq_m, sq_I, rows) -> None:
    n = body_a.shape[0]
    for t in prange(n_chunks(n)):
        _normal_rows_range(body_a, body_b, r_a, r_b, normal, Q, sq_m, sq_I, rows,
                           t * ROW_CHUNK, min(n, (t + 1) * ROW_CHUNK))


@njit(cache=True)
def normal_rows(body_a: np.ndarray, body_b: np.ndarray, r_a: np.ndarray, r_b: np.ndarray,
                normal: np.ndarray, Q: np.ndarray, sq_m: np.ndarray, sq_I: np.ndarray,
                rows: np.ndarray) -> None:
    """rows (K,2,6): the rows of N M^{-1/2}, a unit normal force at each contact as mass-scaled
    generalised forces of B (side 0, +n) and A (side 1, −n): (±n/√m, ±Qᵀ(r × n)/√I) in the
    coordinates of :mod:`nurbsdem.dynamics.stepcontrol` (walls, index ≥ N: zero rows); on
    threads from :data:`~nurbsdem.jit.THREADED_ROWS` contacts (the same bits)."""
    if body_a.shape[0] >= THREADED_ROWS:
        _normal_rows_threads(body_a, body_b, r_a, r_b, normal, Q, sq_m, sq_I, rows)
    else:
        _normal_rows_range(body_a, body_b, r_a, r_b, normal, Q, sq_m, sq_I, rows, np.int64(0),
                           body_a.shape[0])


@njit(cache=True)
def _velocities_range(body_a: np.ndarray, body_b: np.ndarray, rows: np.ndarray, y: np.ndarray,
                      out: np.ndarray, lo: int, hi: int) -> None:
    """out[c] = Σ rows[c, side] · y of its particles, for the contacts lo .. hi-1."""
    n_part = y.shape[0] // 6
    for c in range(lo, hi):
        g = 0.0
        for side in range(2):
            i = body_b[c] if side == 0 else body_a[c]
            if i < n_part:
                for k in range(6):
                    g += rows[c, side, k] * y[6 * i + k]
        out[c] = g


@njit(cache=True, parallel=True)
def _velocities_threads(body_a, body_b, rows, y, out) -> None:
    n = body_a.shape[0]
    for t in prange(n_chunks(n)):
        _velocities_range(body_a, body_b, rows, y, out, t * ROW_CHUNK,
                          min(n, (t + 1) * ROW_CHUNK))


@njit(cache=True)
def delassus_apply(f: np.ndarray, use: np.ndarray, body_a: np.ndarray, body_b: np.ndarray,
                   rows: np.ndarray, y: np.ndarray, out: np.ndarray) -> None:
    """out (K,) = G f: the normal relative velocity (m/s) at every contact from the impulse
    of the normal forces f (N, × 1 s) of the contacts with ``use``; workspace y (6N,).  The
    impulses are summed in contact order on the calling thread (split into ranges of bodies,
    each from the contacts that touch it, it was slower: the contacts' rows read out of
    order); the velocities run on threads from :data:`~nurbsdem.jit.THREADED_ROWS` contacts
    (the same bits)."""
    n_part = y.shape[0] // 6
    y[:] = 0.0
    for c in range(body_a.shape[0]):
        if not use[c] or f[c] == 0.0:
            continue
        for side in range(2):
            i = body_b[c] if side == 0 else body_a[c]
            if i < n_part:
                for k in range(6):
                    y[6 * i + k] += f[c] * rows[c, side, k]
    if body_a.shape[0] >= THREADED_ROWS:
        _velocities_threads(body_a, body_b, rows, y, out)
    else:
        _velocities_range(body_a, body_b, rows, y, out, np.int64(0), body_a.shape[0])


@njit(cache=True)
def _residual(f: np.ndarray, inv_cn: np.ndarray, w0: np.ndarray, h: float,
              all_on: np.ndarray, body_a, body_b, rows, y, gf: np.ndarray,
              res: np.ndarray) -> None:
    """res = A f + w₀ of Eq. (D1) over all contacts (gf: workspace for G f)."""
    delassus_apply(f, all_on, body_a, body_b, rows, y, gf)
    for c in range(f.shape[0]):
        res[c] = inv_cn[c] * f[c] + h * gf[c] + w0[c]


@njit(cache=True)
def _masked_dot(a: np.ndarray, b: np.ndarray, free: np.ndarray) -> float:
    s = 0.0
    for c in range(a.shape[0]):
        if free[c]:
            s += a[c] * b[c]
    return s


@njit(cache=True)
def _cg_free(f: np.ndarray, free: np.ndarray, inv_cn: np.ndarray, h: float,
             precond: np.ndarray, tol: float, body_a, body_b, rows, y: np.ndarray,
             res: np.ndarray) -> int:
    """Conjugate gradients, Jacobi-preconditioned (``precond`` = 1 / diag A), for
    A_FF f_F = −(w₀ + A_FC f_C) on the free contacts (the others fixed at their bound), from
    the present f, whose residual A f + w₀ over all contacts is ``res`` (:func:`_residual`);
    stops when |residual|₂ <= tol.  Returns the iterations."""
    K = f.shape[0]
    r = np.empty(K)
    gf = np.empty(K)
    z = np.zeros(K)
    for c in range(K):
        r[c] = -res[c] if free[c] else 0.0
        z[c] = precond[c] * r[c]
    p = z.copy()
    ap = np.empty(K)
    rz = _masked_dot(r, z, free)
    rr = _masked_dot(r, r, free)
    it = 0
    while it < CG_MAX_ITERATIONS and np.sqrt(rr) > tol:
        delassus_apply(p, free, body_a, body_b, rows, y, gf)
        for c in range(K):
            ap[c] = inv_cn[c] * p[c] + h * gf[c] if free[c] else 0.0
        alpha = rz / _masked_dot(p, ap, free)
        for c in range(K):
            if free[c]:
                f[c] += alpha * p[c]
                r[c] -= alpha * ap[c]
                z[c] = precond[c] * r[c]
        rz_new = _masked_dot(r, z, free)
        rr = _masked_dot(r, r, free)
        beta = rz_new / rz
        rz = rz_new
        for c in range(K):
            p[c] = z[c] + beta * p[c] if free[c] else 0.0
        it += 1
    return it


@njit(cache=True)
def _update_active_set(f: np.ndarray, free: np.ndarray, damped: np.ndarray, lower: np.ndarray,
                       res: np.ndarray) -> tuple[bool, bool]:
    """Free contacts below their bound are clipped; clipped (damped) ones whose multiplier
    (A f + w₀)_c is negative are freed.  Returns (whether the set changed, whether a force
    was clipped: f changed, so its residual must be taken again)."""
    changed = clipped = False
    for c in range(f.shape[0]):
        if not damped[c]:
            continue
        if free[c] and f[c] < lower[c]:
            free[c] = False
            f[c] = lower[c]
            changed = clipped = True
        elif not free[c] and res[c] < 0.0:
            free[c] = True
            changed = True
    return changed, clipped


@njit(cache=True)
def solve_dashpots(body_a: np.ndarray, body_b: np.ndarray, rows: np.ndarray, n_particles: int,
                   cn: np.ndarray, f_el: np.ndarray, w0: np.ndarray, h: float,
                   f: np.ndarray) -> tuple[int, int]:
    """Solve Eq. (D1): the normal dashpot forces f (K,) N (in place, started from its values)
    of contacts with damping cn (K,) N s/m, elastic normal forces f_el (K,) N and dashpot-free
    normal velocities w₀ (K,) m/s, for the two half kicks (h s in all) of an internal step h;
    ``rows`` from :func:`normal_rows`.  Contacts with cn = 0 get f = 0.  Returns (active-set
    rounds, CG iterations)."""
    return solve_dashpots_from(body_a, body_b, rows, n_particles, cn, f_el, w0, h, f,
                               np.empty(0))


@njit(cache=True)
def solve_dashpots_from(body_a: np.ndarray, body_b: np.ndarray, rows: np.ndarray,
                        n_particles: int, cn: np.ndarray, f_el: np.ndarray, w0: np.ndarray,
                        h: float, f: np.ndarray, gf0: np.ndarray) -> tuple[int, int]:
    """:func:`solve_dashpots` given gf0 (K,) = G f of the starting f (m/s per N s, from
    :func:`delassus_apply` over all contacts), which saves the product of the first residual
    when no starting force is moved to its bound (the same bits: the same product); an
    empty gf0 when not known."""
    K = f.shape[0]
    inv_cn = np.zeros(K)
    lower = np.empty(K)
    free = np.zeros(K, np.bool_)
    precond = np.zeros(K)
    scale = 0.0
    moved = gf0.shape[0] != K            # the starting f's G f unknown, or f moved below
    for c in range(K):
        lower[c] = -f_el[c]
        if cn[c] > 0.0:
            inv_cn[c] = 1.0 / cn[c]
            if f[c] < lower[c]:
                f[c] = lower[c]
                moved = True
            free[c] = f[c] > lower[c]
            g = 0.0                               # G_cc, the contact's own compliance
            for side in range(2):
                for k in range(6):
                    g += rows[c, side, k] * rows[c, side, k]
            precond[c] = 1.0 / (inv_cn[c] + h * g)
        else:
            moved = moved or f[c] != 0.0
            f[c] = 0.0
            lower[c] = 0.0
        scale = max(scale, abs(w0[c]), abs(f_el[c]) * inv_cn[c])
    tol = CG_TOLERANCE * max(scale, 1e-300) * np.sqrt(K)
    y = np.empty(6 * n_particles)
    res = np.empty(K)
    gf = np.empty(K)
    all_on = np.ones(K, np.bool_)
    damped = cn > 0.0
    if moved:
        _residual(f, inv_cn, w0, h, all_on, body_a, body_b, rows, y, gf, res)
    else:                            # _residual's arithmetic on the given product
        for c in range(K):
            res[c] = inv_cn[c] * f[c] + h * gf0[c] + w0[c]
    rounds, iterations = 0, 0
    while rounds < MAX_ROUNDS:
        rounds += 1
        iterations += _cg_free(f, free, inv_cn, h, precond, tol, body_a, body_b, rows, y, res)
        _residual(f, inv_cn, w0, h, all_on, body_a, body_b, rows, y, gf, res)
        changed, clipped = _update_active_set(f, free, damped, lower, res)
        if not changed:
            break
        if clipped:                  # else f is unchanged and so is its residual
            _residual(f, inv_cn, w0, h, all_on, body_a, body_b, rows, y, gf, res)
    for c in range(K):          # an unfinished active set still gives forces within the law
        if f[c] < lower[c]:
            f[c] = lower[c]
    return rounds, iterations


@njit(cache=True)
def _owners(body: np.ndarray, own: np.ndarray, n: int) -> np.ndarray:
    """The bodies (K,) with each image n + g replaced by its owner own[g]."""
    out = body.copy()
    for c in range(body.shape[0]):
        if n <= body[c] < n + own.shape[0]:
            out[c] = own[body[c] - n]
    return out


@njit(cache=True)
def implicit_dashpots(body_a: np.ndarray, body_b: np.ndarray, point: np.ndarray,
                      normal: np.ndarray, fn: np.ndarray, f_damp_n: np.ndarray, cn: np.ndarray,
                      force: np.ndarray, torque: np.ndarray, x: np.ndarray, v: np.ndarray,
                      q: np.ndarray, L: np.ndarray, inv_I: np.ndarray, inv_mass: np.ndarray,
                      wall_d: np.ndarray, wall_u: np.ndarray, Q: np.ndarray, sq_m: np.ndarray,
                      sq_I: np.ndarray, h: float, own: np.ndarray) -> tuple[np.ndarray, int, int]:
    """The implicit normal dashpot forces (K,) N of one force evaluation at the end of an
    internal step h (s), acting through its closing and the next opening half kick, from the
    explicit evaluation of the same contacts (``fn`` (K,) N, ``f_damp_n`` (K,3) its normal
    dashpot vector, ``force``/``torque`` (B,3) its loads, gravity included,
    :func:`~nurbsdem.dynamics.forces.contact_loads`) and the half-step state (v, q, L of the N
    particles; walls at wall_d moving at wall_u).  In a periodic cell the last G of the N
    particles are images of the particles ``own`` (G,) (empty: none,
    :mod:`nurbsdem.dynamics.periodic_steps`): each contact keeps its image's lever arm, while
    the loads, the predicted velocities and the solve take an image as its owner, one body.
    Returns (f, active-set rounds, CG iterations); pass f to contact_loads as the given
    dashpots."""
    K = body_a.shape[0]
    N = x.shape[0]
    G = own.shape[0]
    n = N - G
    if G:
        # a particle and its images are one body: each takes the summed loads
        force = image_rows(fold_images(force, own, n), own, n)
        torque = image_rows(fold_images(torque, own, n), own, n)
    f = np.empty(K)
    f_el = np.empty(K)
    for c in range(K):
        f[c] = (f_damp_n[c, 0] * normal[c, 0] + f_damp_n[c, 1] * normal[c, 1]
                + f_damp_n[c, 2] * normal[c, 2])
        f_el[c] = fn[c] - f[c]
    # the velocities after the two half kicks with the explicit loads ...
    v_pred = np.empty((N, 3))
    L_pred = np.empty((N, 3))
    for i in range(N):
        for k in range(3):
            v_pred[i, k] = v[i, k] + h * inv_mass[i] * force[i, k]
            L_pred[i, k] = L[i, k] + h * torque[i, k]
    w3 = np.empty((K, 3))
    _relative_point_velocities(body_a, body_b, point, x, wall_d, v_pred,
                               omega_world(q, L_pred, inv_I), wall_u, w3)
    # ... less the explicit dashpots' share: w₀ of Eq. (D1)
    r_a = np.empty((K, 3))
    r_b = np.empty((K, 3))
    lever_arms(body_a, body_b, point, x, r_a, r_b)
    rows = np.empty((K, 2, 6))
    normal_rows(body_a, body_b, r_a, r_b, normal, Q, sq_m, sq_I, rows)
    sa, sb = body_a, body_b
    if G:
        sa, sb = _owners(body_a, own, n), _owners(body_b, own, n)
    gf = np.empty(K)
    delassus_apply(f, np.ones(K, np.bool_), sa, sb, rows, np.empty(6 * n), gf)
    w0 = np.empty(K)
    for c in range(K):
        w0[c] = (w3[c, 0] * normal[c, 0] + w3[c, 1] * normal[c, 1] + w3[c, 2] * normal[c, 2]
                 - h * gf[c])
    rounds, iterations = solve_dashpots_from(sa, sb, rows, n, cn, f_el, w0, h, f, gf)
    return f, rounds, iterations


@njit(cache=True)
def dashpots_of_evaluation(body_a, body_b, point_a, point_b, normal, depth, pos, vel, omg,
                           material, table, spring, h, inv_mass_all, radius, mass, gravity,
                           q: np.ndarray, L: np.ndarray, inv_I: np.ndarray, Q: np.ndarray,
                           sq_m: np.ndarray, sq_I: np.ndarray,
                           own: np.ndarray) -> tuple[np.ndarray, int, int]:
    """The implicit normal dashpot forces (K,) N of a force evaluation given by the arguments
    of :func:`~nurbsdem.dynamics.forces.contact_loads` (pos, vel (B,3): the N particles then
    the walls): its explicit evaluation on a copy of the tangential springs, then
    :func:`implicit_dashpots` with the particles' q, L (N,4), (N,3), 1/I, Q (principal frames)
    and √m, √I (the last G of them images of the particles ``own`` (G,), empty: none).
    Returns (f, active-set rounds, CG iterations).  The one entry of the Python path and the
    compiled loop, so that both give the same bits."""
    N = mass.shape[0]
    force, torque, point, _, fdn, _, _, fn, _, _, coeffs, _ = contact_loads(
        body_a, body_b, point_a, point_b, normal, depth, pos, vel, omg, material, table,
        spring.copy(), h, inv_mass_all, radius, mass, gravity, np.bool_(False), np.zeros(0))
    return implicit_dashpots(body_a, body_b, point, normal, fn, fdn,
                             np.ascontiguousarray(coeffs[:, 1]), force, torque, pos[:N],
                             vel[:N], q, L, inv_I, inv_mass_all[:N], pos[N:], vel[N:], Q, sq_m,
                             sq_I, h, own)

"""Stage 1 of the local contact problem: the distance between two NURBS surfaces
(paper Sec. 3.2.1, Eq. 4–5).

Minimise over the four surface parameters x = (ζA, θA, ζB, θB) (patch pA of body A, patch pB
of body B, world poses)

    f1(x) = ½ |g|²,      g = ΓA(ζA, θA) − ΓB(ζB, θB)       (paper Eq. 4–5; m², g in m)

with the exact derivatives from the compiled kernel's first and second surface derivatives
(:func:`nurbsdem.geometry.kernel.patch_derivs`):

    J = [ΓA,ζ  ΓA,θ  −ΓB,ζ  −ΓB,θ]  (3×4, world),     ∇f1 = Jᵀ g,
    ∇²f1 = JᵀJ + diag-blocks( g·ΓA,ζζ  g·ΓA,ζθ  g·ΓA,θθ ;  −g·ΓB,ζζ  −g·ΓB,ζθ  −g·ΓB,θθ ).

**Trust-region Newton** (as in the authors' Giraffe code, Δ0 = 0.1, Δmax = 1e4, η = 0.15, at
most 50 iterations). The variables are scaled by
each patch's parameter width, so the radius is in patch widths. The step is the exact
trust-region step (:func:`.trust_region.tr_step_eig`, shared with the support mapping and
the direction search) in the eigenbasis of the (reduced) Hessian (4×4 cyclic Jacobi): the
Newton step when the Hessian is positive definite and the step fits, otherwise the
eigenvalues are shifted by μ ≥ max(0, −λmin) until the step has length Δ (the Moré–Sorensen
refinement of Giraffe's "shifted eigenvalues / dogleg"; along the lowest eigenvector in the
hard case, which is how a start exactly at a saddle of f1 is left). A ratio
ρ = actual / predicted decrease > η accepts the step; ρ > 0.75 on the boundary doubles Δ,
ρ < 0.25 shrinks it to ¼ of the step.

**Bounds and patch change** (paper 3.2.2, the mechanism of the support mapping,
:mod:`.support`): a parameter at its bound whose descent direction points out of the
rectangle is clamped, and the point is moved across the edge onto the neighbour patch when
f1 decreases into it (:func:`.support.try_migrate` with the descent direction of that point:
−g for A, +g for B); the ζ neighbour first, then θ. Across a C0 crease (the neighbour's inward
derivative points back), at a pole that no meridian leaves, or after 8 migrations, the
parameter is *fixed* (degeneration, paper Eq. 10–13: reduced gradient P_sᵀ∇f1 and Hessian
P_sᵀ∇²f1 P_s); fixed creases are re-tested at the final point.

**Stopping** (Giraffe): |∇f1| < 1e-12 λmax(∇²f1) with no negative curvature, and (added)
|∇f1| <= 1e-6 |J| |g| or at the rounding floor 1e-14 |J| × (position scale) — near an
intersection the absolute test alone passes while f1 is still above its threshold, which
would classify an intersecting pair as a (tiny) strict minimum; or a world step below
1e-13 × scale; a last Newton step below 1e-6 patch widths is taken by a second-order
Taylor update of the points (no new evaluation; error ~ step² ≈ 1e-12 widths).

**Classification** (Giraffe, λ the eigenvalues of the reduced scaled Hessian at the end):

* f1 < 1e-24 λmax                 → :data:`S1_INTERSECTING` (the surfaces cross: stage 2);
* all λ ≥ 1e-12 λmax              → :data:`S1_SEPARATED` (strict minimum, distance |g|);
* some λ ≤ −1e-12 λmax            → :data:`S1_SADDLE`;
* otherwise (a weak minimum)      → :data:`S1_DEGENERATE`; not converged → :data:`S1_NONE`.

A strict positive minimum of f1 is the distance of two *convex bodies* only when the points
face each other (outward normal of A along −g, of B along +g); for convex surfaces another
strict local minimum (a point on the far side of a flat body) is possible. The pipeline
(:func:`nurbsdem.contact.lcp.solve_pair`) therefore certifies a stage-1 result with one
support mapping per body along ±n (stage-2 machinery), see the ``lcp`` module docstring.

The state uses the support mapping's layout: ``ist`` rows (patch (global), fix_u, fix_v,
migrations), ``fst`` rows (ζ, θ, –) for A (row 0) and B (row 1). Work rows live in the LCP's
float work array ``wf`` from row :data:`S1_ROW` and in a (24, 8) array ``w4``.
Units: metres, parameters dimensionless.
"""
from __future__ import annotations

import math

import numpy as np

from ..jit import kernel
from .support import (CREASE, FREE, OPEN_FIX, POLE_FIX, dot3, evaluate, pole_escape, rt_times,
                      try_migrate)
from .trust_region import jacobi_eig, tr_step_eig

#: classification codes
S1_NONE = 0
S1_SEPARATED = 1
S1_INTERSECTING = 2
S1_SADDLE = 3
S1_DEGENERATE = 4
CLASS_NAMES = {S1_NONE: "not converged", S1_SEPARATED: "separated",
               S1_INTERSECTING: "intersecting", S1_SADDLE: "saddle",
               S1_DEGENERATE: "degenerate"}

#: Giraffe's trust-region constants (radius in patch widths)
DELTA0 = 0.1
DELTA_MAX = 1e4
ETA = 0.15
MAX_IT = 50
GRAD_TOL = 1e-12      # |∇f1| < GRAD_TOL λmax
F_TOL = 1e-24         # f1 < F_TOL λmax: intersecting
EIG_TOL = 1e-12       # λ >= EIG_TOL λmax: strictly positive
REL_TOL = 1e-6        # |∇f1| <= REL_TOL |J| |g|: g normal to both surfaces
TAYLOR_STEP1 = 1e-6   # last Newton step (patch widths) taken by a Taylor update
MAX_MIG = 8

#: first row of stage 1 in the LCP float work array (rows of 3), rows used
S1_ROW = 48
S1_ROWS = 41
W4_ROWS = 24
W4_COLS = 8
#: entries of the float summary ``out``
O_F1, O_LREF, O_LMIN, O_GN, O_GL = 0, 1, 2, 3, 4
N_OUT = 8

# offsets inside the stage-1 rows
_EVA, _EVB, _TEA, _TEB = 0, 6, 12, 18
_PAW, _PBW, _G, _C = 24, 25, 26, 27          # _C: 4 rows, world columns of J
_E, _TMP, _EV2, _TPA, _TPB = 31, 32, 33, 39, 40
#: public row offsets (relative to S1_ROW) of the final points, gap and world tangents
S1_PAW, S1_PBW, S1_G, S1_C = _PAW, _PBW, _G, _C
# rows of w4
_HS, _Q, _LAM, _GR, _X, _XN, _WD, _ST, _HR, _GS, _Y, _IDX, _DIAG = 0, 4, 8, 9, 10, 11, 12, 13, 14, 18, 19, 20, 21


def make_w4() -> np.ndarray:
    """The (24, 8) float work array of :func:`stage1`."""
    return np.zeros((W4_ROWS, W4_COLS))


# --------------------------------------------------------------------------- geometry
@kernel
def _world(pos, R, ev, sign, p, c0, c1):
    """p = pos + R ev[0]; c0 = sign R ev[1]; c1 = sign R ev[2] (world)."""
    for a in range(3):
        p[a] = pos[a] + R[a, 0] * ev[0, 0] + R[a, 1] * ev[0, 1] + R[a, 2] * ev[0, 2]
        c0[a] = sign * (R[a, 0] * ev[1, 0] + R[a, 1] * ev[1, 1] + R[a, 2] * ev[1, 2])
        c1[a] = sign * (R[a, 0] * ev[2, 0] + R[a, 1] * ev[2, 1] + R[a, 2] * ev[2, 2])


@kernel
def outward_normal(c0, c1, p, centre, out):
    """Unit outward normal from two world tangents c0, c1 at p (sign chosen so that it points
    away from the body's centroid ``centre``; p − centre where the tangents are degenerate,
    e.g. at a pole)."""
    out[0] = c0[1] * c1[2] - c0[2] * c1[1]
    out[1] = c0[2] * c1[0] - c0[0] * c1[2]
    out[2] = c0[0] * c1[1] - c0[1] * c1[0]
    nn = math.sqrt(out[0] * out[0] + out[1] * out[1] + out[2] * out[2])
    l0 = math.sqrt(dot3(c0, c0))
    l1 = math.sqrt(dot3(c1, c1))
    if not nn > 1e-8 * l0 * l1:
        for a in range(3):
            out[a] = p[a] - centre[a]
        nn = math.sqrt(out[0] * out[0] + out[1] * out[1] + out[2] * out[2])
        if not nn > 0.0:
            return False
    sg = 1.0
    if (out[0] * (p[0] - centre[0]) + out[1] * (p[1] - centre[1])
            + out[2] * (p[2] - centre[2])) < 0.0:
        sg = -1.0
    for a in range(3):
        out[a] *= sg / nn
    return True


@kernel
def _clamp_state(tab, ist, fst):
    dom = tab[6]
    ip = ist[0]
    fst[0] = min(max(fst[0], dom[ip, 0]), dom[ip, 1])
    fst[1] = min(max(fst[1], dom[ip, 2]), dom[ip, 3])


@kernel
def _bounds(tab, ist, fst, gu, gv, gl, g, pos, R, sign, ws, ev, e, ev2, tmp):
    """Bound handling of one body's point (paper 3.2.2; module docstring). ``gu, gv``: the
    gradient of f1 w.r.t. this body's (ζ, θ); the point's descent direction is −sign·g.
    Returns (moved, evaluations)."""
    dom = tab[6]
    ip = ist[0]
    u = fst[0]
    v = fst[1]
    tol = 1e-13 * gl * (math.sqrt(dot3(ev[1], ev[1])) + math.sqrt(dot3(ev[2], ev[2])))
    out_u = (u <= dom[ip, 0] and gu > tol) or (u >= dom[ip, 1] and gu < -tol)
    out_v = (v <= dom[ip, 2] and gv > tol) or (v >= dom[ip, 3] and gv < -tol)
    if not out_u:
        ist[1] = FREE
    if not out_v:
        ist[2] = FREE
    nev = 0
    if not ((out_u and ist[1] == FREE) or (out_v and ist[2] == FREE)):
        return False, nev
    # descent direction of this point in its file frame: −sign Rᵀ g / |g|
    for a in range(3):
        e[a] = -sign * (R[0, a] * g[0] + R[1, a] * g[1] + R[2, a] * g[2]) / gl
    for k in range(2):
        if k == 0 and not (out_u and ist[1] == FREE):
            continue
        if k == 1 and not (out_v and ist[2] == FREE):
            continue
        if k == 0:
            edge = 0 if u <= dom[ip, 0] else 1
        else:
            edge = 2 if v <= dom[ip, 2] else 3
        code, j, uj, vj = try_migrate(tab, ip, u, v, edge, e, ws, ev2, tmp)
        nev += 1 if code <= 1 else 0
        if code == 0 and ist[3] < MAX_MIG:
            ist[0] = j
            ist[1] = FREE
            ist[2] = FREE
            ist[3] += 1
            fst[0] = uj
            fst[1] = vj
            return True, nev
        if code == 2:
            if ist[3] < MAX_MIG:
                ist[3] += 1
                ok, uu, vv = pole_escape(tab, ip, u, v, edge, e, ws, ev2, tmp)
                nev += 18
                if ok:
                    fst[0] = uu
                    fst[1] = vv
                    ist[1] = FREE
                    ist[2] = FREE
                    return True, nev
            fx = POLE_FIX
        elif code == 3:
            fx = OPEN_FIX
        else:
            fx = CREASE
        ist[1 + k] = fx
    return False, nev


@kernel
def _retest_creases(tab, ist, fst, g, gl, R, sign, ws, e, ev2, tmp):
    """Re-test parameters fixed at a crease at the final point (the crease decision was taken
    where the point first reached the edge). Returns (moved, evaluations)."""
    if not (ist[1] == CREASE or ist[2] == CREASE) or ist[3] >= MAX_MIG or not gl > 0.0:
        return False, 0
    dom = tab[6]
    ip = ist[0]
    u = fst[0]
    v = fst[1]
    for a in range(3):
        e[a] = -sign * (R[0, a] * g[0] + R[1, a] * g[1] + R[2, a] * g[2]) / gl
    nev = 0
    for k in range(2):
        if ist[1 + k] != CREASE:
            continue
        if k == 0:
            edge = 0 if u <= dom[ip, 0] else 1
        else:
            edge = 2 if v <= dom[ip, 2] else 3
        code, j, uj, vj = try_migrate(tab, ip, u, v, edge, e, ws, ev2, tmp)
        nev += 1
        if code == 0:
            ist[0] = j
            ist[1] = FREE
            ist[2] = FREE
            ist[3] += 1
            fst[0] = uj
            fst[1] = vj
            return True, nev
    return False, nev


@kernel
def _taylor(ev, du, dv):
    """Second-order Taylor update of the point ev[0] (file frame) by (du, dv)."""
    for c in range(3):
        ev[0, c] += (ev[1, c] * du + ev[2, c] * dv
                     + 0.5 * (ev[3, c] * du * du + 2.0 * ev[4, c] * du * dv + ev[5, c] * dv * dv))


# --------------------------------------------------------------------------- the solver
#: what a trust-region pass of :func:`stage1` leads to: the next pass, the end of the
#: iteration (no progress within rounding), or the stationary point's tests
_NEXT, _STOP, _STATIONARY = 0, 1, 2


@kernel(inline="always")
def _gap(pA, pB, g):
    """g = pA − pB (m, world) and f1 = |g|²/2 (m², paper Eq. 5)."""
    f = 0.0
    for a in range(3):
        g[a] = pA[a] - pB[a]
        f += g[a] * g[a]
    return 0.5 * f


@kernel(inline="always")
def _start(tabA, posA, RA, tabB, posB, RB, ist, fst, ws, evA, evB, pA, pB, C, g, out):
    """The start of :func:`stage1`: the state clamped to its patches with every parameter free,
    both points evaluated (world points pA, pB, tangents C).  Returns f1 (m²)."""
    for k in range(N_OUT):
        out[k] = 0.0
    _clamp_state(tabA, ist[0], fst[0])
    _clamp_state(tabB, ist[1], fst[1])
    ist[0, 1] = FREE
    ist[0, 2] = FREE
    ist[1, 1] = FREE
    ist[1, 2] = FREE
    evaluate(tabA, ist[0, 0], fst[0, 0], fst[0, 1], 2, ws, evA)
    evaluate(tabB, ist[1, 0], fst[1, 0], fst[1, 1], 2, ws, evB)
    _world(posA, RA, evA, 1.0, pA, C[0], C[1])
    _world(posB, RB, evB, -1.0, pB, C[2], C[3])
    return _gap(pA, pB, g)


@kernel(inline="always")
def _bounds_pass(tabA, posA, RA, tabB, posB, RB, ist, fst, gr, gl, g, ws, evA, evB, pA, pB, C,
                 e, ev2, tmp):
    """The bounds of A, then (if A's point stays) of B: clamp, migrate or fix (paper 3.2.2,
    3.2.3); a moved point is evaluated again.  Returns (moved, patch evaluations)."""
    mv, nev = _bounds(tabA, ist[0], fst[0], gr[0], gr[1], gl, g, posA, RA, 1.0, ws, evA, e,
                      ev2, tmp)
    if mv:
        evaluate(tabA, ist[0, 0], fst[0, 0], fst[0, 1], 2, ws, evA)
        nev += 1
        _world(posA, RA, evA, 1.0, pA, C[0], C[1])
    else:
        mv, ne = _bounds(tabB, ist[1], fst[1], gr[2], gr[3], gl, g, posB, RB, -1.0, ws, evB, e,
                         ev2, tmp)
        nev += ne
        if mv:
            evaluate(tabB, ist[1, 0], fst[1, 0], fst[1, 1], 2, ws, evB)
            nev += 1
            _world(posB, RB, evB, -1.0, pB, C[2], C[3])
    return mv, nev


@kernel(inline="always")
def _reduced_hessian(domA, domB, ist, RA, RB, g, C, evA, evB, gr, wd, Hs, gs, idx, sr, Hr, Q,
                     lam):
    """The scaled Hessian Hs and gradient gs of f1 (paper Eq. 5 differentiated twice, each
    parameter scaled by its patch's width wd), and the reduced problem on the free parameters
    (P_s, Eq. 12–13: Hr, sr over the indices idx) with its eigen-decomposition (Q, lam).
    Returns (free parameters n, |reduced gradient|, λref = max(|λ|, max diag), λmin)."""
    wd[0] = domA[ist[0, 0], 1] - domA[ist[0, 0], 0]
    wd[1] = domA[ist[0, 0], 3] - domA[ist[0, 0], 2]
    wd[2] = domB[ist[1, 0], 1] - domB[ist[1, 0], 0]
    wd[3] = domB[ist[1, 0], 3] - domB[ist[1, 0], 2]
    for i in range(4):
        for j in range(i, 4):
            Hs[i, j] = dot3(C[i], C[j])
    # curvature terms: g · Γ'' (file frame: Rᵀ g)
    gA0, gA1, gA2 = rt_times(RA, g[0], g[1], g[2])
    gB0, gB1, gB2 = rt_times(RB, g[0], g[1], g[2])
    Hs[0, 0] += gA0 * evA[3, 0] + gA1 * evA[3, 1] + gA2 * evA[3, 2]
    Hs[0, 1] += gA0 * evA[4, 0] + gA1 * evA[4, 1] + gA2 * evA[4, 2]
    Hs[1, 1] += gA0 * evA[5, 0] + gA1 * evA[5, 1] + gA2 * evA[5, 2]
    Hs[2, 2] -= gB0 * evB[3, 0] + gB1 * evB[3, 1] + gB2 * evB[3, 2]
    Hs[2, 3] -= gB0 * evB[4, 0] + gB1 * evB[4, 1] + gB2 * evB[4, 2]
    Hs[3, 3] -= gB0 * evB[5, 0] + gB1 * evB[5, 1] + gB2 * evB[5, 2]
    dmax = 0.0
    for i in range(4):
        for j in range(i, 4):
            Hs[i, j] *= wd[i] * wd[j]
            Hs[j, i] = Hs[i, j]
        gs[i] = gr[i] * wd[i]
        dmax = max(dmax, abs(Hs[i, i]))
    n = np.int64(0)         # not a literal: one specialisation of jacobi_eig
    for k in range(4):
        fx = ist[k // 2, 1 + k % 2]
        if fx == FREE:
            idx[n] = k
            n += 1
    gn = 0.0
    for i in range(n):
        ki = int(idx[i])
        sr[i] = gs[ki]
        gn += gs[ki] * gs[ki]
        for j in range(n):
            Hr[i, j] = Hs[ki, int(idx[j])]
    gn = math.sqrt(gn)
    jacobi_eig(Hr, n, Q, lam)
    lref = dmax
    lmin = 1e300
    for i in range(n):
        lref = max(lref, abs(lam[i]))
        lmin = min(lmin, lam[i])
    return n, gn, lref, lmin


@kernel(inline="always")
def _trust_step(tabA, posA, RA, tabB, posB, RB, ist, fst, ws, wf, w4, n, delta, xtol, f, gl,
                pscale, gn, lref):
    """One trust-region pass of :func:`stage1` (radius delta in scaled parameters; the
    workspaces' named rows as there): the step clamped to the patches' rectangles, then a
    snap onto a bound, a last second-order Taylor update in the quadratic-convergence region,
    or a trial point accepted on its ratio of actual to predicted decrease.  Returns (_NEXT,
    _STOP or _STATIONARY, f1 (m²), delta, |reduced gradient|, patch evaluations)."""
    r0 = S1_ROW
    evA, evB = wf[r0 + _EVA:r0 + _EVA + 6], wf[r0 + _EVB:r0 + _EVB + 6]
    teA, teB = wf[r0 + _TEA:r0 + _TEA + 6], wf[r0 + _TEB:r0 + _TEB + 6]
    pA, pB, g, tpA, tpB = wf[r0 + _PAW], wf[r0 + _PBW], wf[r0 + _G], wf[r0 + _TPA], wf[r0 + _TPB]
    C = wf[r0 + _C:r0 + _C + 4]
    Hs, Q = w4[_HS:_HS + 4], w4[_Q:_Q + 4]
    lam, xn, wd, st, gs, y, idx, sr = (w4[_LAM], w4[_XN], w4[_WD], w4[_ST], w4[_GS], w4[_Y],
                                       w4[_IDX], w4[_DIAG])
    domA, domB = tabA[6], tabB[6]
    newton = tr_step_eig(lam, Q, sr, n, delta, y, xn, w4[22])
    for k in range(4):
        st[k] = 0.0
    for i in range(n):
        ki = int(idx[i])
        st[ki] = xn[i] * wd[ki]
    # clamp to the rectangles
    uA = min(max(fst[0, 0] + st[0], domA[ist[0, 0], 0]), domA[ist[0, 0], 1])
    vA = min(max(fst[0, 1] + st[1], domA[ist[0, 0], 2]), domA[ist[0, 0], 3])
    uB = min(max(fst[1, 0] + st[2], domB[ist[1, 0], 0]), domB[ist[1, 0], 1])
    vB = min(max(fst[1, 1] + st[3], domB[ist[1, 0], 2]), domB[ist[1, 0], 3])
    clamped = (uA != fst[0, 0] + st[0] or vA != fst[0, 1] + st[1]
               or uB != fst[1, 0] + st[2] or vB != fst[1, 1] + st[3])
    st[0] = uA - fst[0, 0]
    st[1] = vA - fst[0, 1]
    st[2] = uB - fst[1, 0]
    st[3] = vB - fst[1, 1]
    lx = 0.0
    for a in range(3):
        t = C[0, a] * st[0] + C[1, a] * st[1] + C[2, a] * st[2] + C[3, a] * st[3]
        lx += t * t
    lx = math.sqrt(lx)
    xs = 0.0
    for k in range(4):
        xs += (st[k] / wd[k]) ** 2
    xs = math.sqrt(xs)
    if clamped and lx <= xtol:
        # a tiny step cut by a bound: snap onto the bound, the next pass sees the edge
        fst[0, 0] = uA
        fst[0, 1] = vA
        fst[1, 0] = uB
        fst[1, 1] = vB
        return _NEXT, f, delta, gn, 0
    if newton and not clamped and (xs <= TAYLOR_STEP1 or lx <= xtol):
        # quadratic-convergence region: last step by a second-order Taylor update
        _taylor(evA, st[0], st[1])
        _taylor(evB, st[2], st[3])
        fst[0, 0] = uA
        fst[0, 1] = vA
        fst[1, 0] = uB
        fst[1, 1] = vB
        for a in range(3):
            pA[a] = posA[a] + RA[a, 0] * evA[0, 0] + RA[a, 1] * evA[0, 1] + RA[a, 2] * evA[0, 2]
            pB[a] = posB[a] + RB[a, 0] * evB[0, 0] + RB[a, 1] * evB[0, 1] + RB[a, 2] * evB[0, 2]
        # the gradient after the Newton step is second order
        return _STATIONARY, _gap(pA, pB, g), delta, 0.0, 0
    # predicted decrease of the (clamped) step on the scaled model
    pred = 0.0
    for i in range(4):
        si = st[i] / wd[i]
        pred -= gs[i] * si
        for j in range(4):
            pred -= 0.5 * si * Hs[i, j] * st[j] / wd[j]
    evaluate(tabA, ist[0, 0], uA, vA, 2, ws, teA)
    evaluate(tabB, ist[1, 0], uB, vB, 2, ws, teB)
    fn = 0.0
    for a in range(3):
        tpA[a] = posA[a] + RA[a, 0] * teA[0, 0] + RA[a, 1] * teA[0, 1] + RA[a, 2] * teA[0, 2]
        tpB[a] = posB[a] + RB[a, 0] * teB[0, 0] + RB[a, 1] * teB[0, 1] + RB[a, 2] * teB[0, 2]
        fn += (tpA[a] - tpB[a]) ** 2
    fn *= 0.5
    actual = f - fn
    noise = 4e-16 * pscale * (gl + 1e-16 * pscale)
    if pred > noise:
        rho = actual / pred
    else:
        rho = 1.0 if actual >= -noise else -1.0
    if rho > ETA and fn == fn:
        fst[0, 0] = uA
        fst[0, 1] = vA
        fst[1, 0] = uB
        fst[1, 1] = vB
        for r in range(6):
            for a in range(3):
                evA[r, a] = teA[r, a]
                evB[r, a] = teB[r, a]
        _world(posA, RA, evA, 1.0, pA, C[0], C[1])
        _world(posB, RB, evB, -1.0, pB, C[2], C[3])
        f = _gap(pA, pB, g)
        if rho > 0.75 and xs >= 0.9 * delta:
            delta = min(2.0 * delta, DELTA_MAX)
    if rho < 0.25:
        delta = 0.25 * xs
        if delta < 1e-15:
            # no further progress within rounding: stationary if the gradient is small on
            # the scale of the rounding, otherwise not converged
            if gn < 1e-8 * lref:
                return _STATIONARY, f, delta, gn, 2
            return _STOP, f, delta, gn, 2
    return _NEXT, f, delta, gn, 2


@kernel(inline="always")
def _retest(tabA, posA, RA, tabB, posB, RB, ist, fst, g, gl, ws, e, ev2, tmp, evA, evB, pA, pB,
            C):
    """At a stationary point: the creases of A, then (if A's point stays) of B, tested again;
    a moved point is evaluated again.  Returns (moved, patch evaluations)."""
    mv, ne = _retest_creases(tabA, ist[0], fst[0], g, gl, RA, 1.0, ws, e, ev2, tmp)
    if not mv:
        mv, ne2 = _retest_creases(tabB, ist[1], fst[1], g, gl, RB, -1.0, ws, e, ev2, tmp)
        ne += ne2
        if mv:
            evaluate(tabB, ist[1, 0], fst[1, 0], fst[1, 1], 2, ws, evB)
            _world(posB, RB, evB, -1.0, pB, C[2], C[3])
    else:
        evaluate(tabA, ist[0, 0], fst[0, 0], fst[0, 1], 2, ws, evA)
        _world(posA, RA, evA, 1.0, pA, C[0], C[1])
    return mv, ne


@kernel(inline="always")
def _classify(f, lref, lmin, gn, n, pscale):
    """The class of a stationary point of f1 (m²): intersecting, degenerate (the gradient not
    small relative to |g|), separated (a minimum) or a saddle, from the reduced Hessian's
    λref, λmin and the reduced gradient's norm gn."""
    gl = math.sqrt(2.0 * f)
    rel = gn <= math.sqrt(lref) * max(1e2 * REL_TOL * gl, 1e-13 * pscale)
    if f < F_TOL * lref:
        return S1_INTERSECTING
    if not rel and n > 0:
        return S1_DEGENERATE
    if n == 0 or lmin >= EIG_TOL * lref:
        return S1_SEPARATED
    if lmin <= -EIG_TOL * lref:
        return S1_SADDLE
    return S1_DEGENERATE


@kernel
def stage1(tabA, posA, RA, tabB, posB, RB, scale, ist, fst, max_it, delta0, ws, wf, w4, out):
    """Minimise f1 (paper Eq. 5) from the state in ``ist``/``fst`` rows 0 (A) and 1 (B)
    (module docstring). ``scale`` (m): length scale of the pair (sum of bounding radii).

    On return the state holds the final patches/parameters, ``wf[S1_ROW + 24]`` /
    ``wf[S1_ROW + 25]`` the world points on A / B, ``wf[S1_ROW + 26]`` the gap g (m),
    ``wf[S1_ROW + 27:31]`` the world tangents (columns of J) and ``out`` the summary
    (f1 (m²), λmax, λmin of the reduced scaled Hessian, scaled gradient norm, |g| (m)).
    Returns (classification, iterations, patch evaluations)."""
    r0 = S1_ROW                 # the named rows of the workspaces
    evA, evB = wf[r0 + _EVA:r0 + _EVA + 6], wf[r0 + _EVB:r0 + _EVB + 6]
    pA, pB, g = wf[r0 + _PAW], wf[r0 + _PBW], wf[r0 + _G]
    C = wf[r0 + _C:r0 + _C + 4]
    e, tmp, ev2 = wf[r0 + _E], wf[r0 + _TMP], wf[r0 + _EV2:r0 + _EV2 + 6]
    Hs, Q, Hr = w4[_HS:_HS + 4], w4[_Q:_Q + 4], w4[_HR:_HR + 4]
    lam, gr, wd, gs, idx, sr = w4[_LAM], w4[_GR], w4[_WD], w4[_GS], w4[_IDX], w4[_DIAG]
    domA, domB = tabA[6], tabB[6]
    f = _start(tabA, posA, RA, tabB, posB, RB, ist, fst, ws, evA, evB, pA, pB, C, g, out)
    nev = 2
    pscale = max(scale, math.sqrt(dot3(pA, pA)))
    xtol = 1e-13 * scale
    delta = delta0
    it = 0
    cls = S1_NONE
    nretest = 0
    lref = 0.0
    lmin = 0.0
    gn = 0.0
    n = np.int64(0)
    for _pass in range(max_it + 40):
        gl = math.sqrt(2.0 * f)
        for k in range(4):
            gr[k] = dot3(C[k], g)
        if gl > 0.0:                # bounds: clamp / migrate / fix (paper 3.2.2, 3.2.3)
            mv, ne = _bounds_pass(tabA, posA, RA, tabB, posB, RB, ist, fst, gr, gl, g, ws,
                                  evA, evB, pA, pB, C, e, ev2, tmp)
            nev += ne
            if mv:
                f = _gap(pA, pB, g)
                continue
        n, gn, lref, lmin = _reduced_hessian(domA, domB, ist, RA, RB, g, C, evA, evB, gr, wd,
                                             Hs, gs, idx, sr, Hr, Q, lam)
        if f < F_TOL * lref:
            cls = S1_INTERSECTING
            break
        # Giraffe's test, plus: the reduced gradient small relative to |g| (g normal to both
        # surfaces) or at the rounding floor — near an intersection |∇f1| ~ |J||g| passes
        # the absolute test before f1 passes F_TOL
        rel = gn <= math.sqrt(lref) * max(REL_TOL * gl, 1e-14 * pscale)
        stationary = n == 0 or (gn < GRAD_TOL * lref and rel and lmin >= -EIG_TOL * lref)
        if not stationary and it < max_it:
            it += 1
            step, f, delta, gn, ne = _trust_step(tabA, posA, RA, tabB, posB, RB, ist, fst, ws,
                                                 wf, w4, n, delta, xtol, f, gl, pscale, gn,
                                                 lref)
            nev += ne
            if step == _NEXT:
                continue
            if step == _STOP:
                break
        elif not stationary:
            break      # iteration limit
        if nretest < 4:             # stationary: re-test creases, then classify
            mv, ne = _retest(tabA, posA, RA, tabB, posB, RB, ist, fst, g, math.sqrt(2.0 * f),
                             ws, e, ev2, tmp, evA, evB, pA, pB, C)
            nev += ne
            if mv:
                nretest += 1
                nev += 1
                f = _gap(pA, pB, g)
                continue
        cls = _classify(f, lref, lmin, gn, n, pscale)
        break
    out[O_F1] = f
    out[O_LREF] = lref
    out[O_LMIN] = lmin if n > 0 else 0.0
    out[O_GN] = gn
    out[O_GL] = math.sqrt(2.0 * f)
    return cls, it, nev


# --------------------------------------------------------------------------- cold seeds
@kernel
def nearest_seed(seed_x, seed_p, s0, ns, mask, p0, pos, R, q):
    """Index of the seed (file-frame surface sample of a body in pose (pos, R)) nearest to
    the world point q, among seeds s0..s0+ns-1 allowed by ``mask`` (empty: all)."""
    q0 = q[0] - pos[0]
    q1 = q[1] - pos[1]
    q2 = q[2] - pos[2]
    f0, f1, f2 = rt_times(R, q0, q1, q2)
    best = 1e300
    ib = s0
    use_mask = mask.shape[0] > 0
    for k in range(s0, s0 + ns):
        if use_mask and not mask[seed_p[k] - p0]:
            continue
        d0 = seed_x[k, 0] - f0
        d1 = seed_x[k, 1] - f1
        d2 = seed_x[k, 2] - f2
        dd = d0 * d0 + d1 * d1 + d2 * d2
        if dd < best:
            best = dd
            ib = k
    return ib

"""Stage 2 of the local contact problem: the search over unit directions d (world frame) for
the minimum of phi(d) = h_A(d) + h_B(−d), the support function of the configuration space
obstacle A − B (paper Eq. 6–9; the pipeline and the equivalence with the paper's f2:
:mod:`.lcp`).

**Newton on the sphere.** Each iteration uses a *local chart re-centred on the current
direction*, d(a, b) = normalize(d0 + a t1 + b t2) with (t1, t2) an orthonormal tangent
basis: no pole singularity. In that chart

    grad = Tᵀ (p_A − p_B),      Hess = Tᵀ (H_A + H_B) T − phi I,

with H_A = R_A M_A R_Aᵀ, H_B = R_B M_B R_Bᵀ the Hessians of the support functions, from the
implicit differentiation of the support conditions (the paper's A x = b, reduced by P_s for
degenerated parameters, Eq. 14–15; see :mod:`.support`), and −phi I the curvature of the unit
sphere. The step is the exact trust-region step (eigen-decomposition of the 2×2 Hessian,
shift when indefinite), trust radius in radians, ratio test with eta = 0.1. The support
points for the trial direction start from the first-order prediction
u + (du/de) (e' − e), so each support mapping takes 1–2 Newton iterations near convergence.
Stopping: Newton step < 1e-11 rad, or tangential gradient < 1e-15 × scale; a last Newton step
below 1e-7 rad is taken by a Taylor update (points moved by dp/de, depth by the quadratic
model) instead of two more support mappings — its error is second order (~1e-14).

**Saddle stall** (nearly convex shapes only, a non-convexity height ``tol_nc`` = h_A + h_B
> 0; convex shapes never take this path). At a saddle (a CAD patch corner) e·x can have
several local maxima on one body, about its non-convexity height h apart (the higher point
rises above the lower one's supporting plane; h is measured on samples and refined to its
local maximum, and at a crease that plane is no tangent plane, so the gap can exceed h a
little), and the support mapping, a local Newton method, may return the lower one: the
computed phi is then too small and not smooth. The search notices it when it has stalled
(trust radius <= ``SADDLE_STALL_ANGLE``) and a trial a vanishing angle xn away lands on a
maximum higher by J > 2·scale·xn — more than the support function of bodies within their
bounding spheres can change (|grad phi| = |p_A − p_B| <= 2 scale):

1. the current support point was not the maximum: the search goes on from the higher one
   (trust radius ``SADDLE_DELTA``, ``SADDLE_EXTRA_IT`` more iterations), at most
   ``SADDLE_MAX_MOVES`` times;
2. after that, a search that stalls again is accepted (not failed) when J <= ``tol_nc``,
   phi has converged (within ``SADDLE_PHI_TOL`` × scale of one value over the last
   ``SADDLE_PHI_IT`` iterations or more: a search still creeping down the lower branch by
   ever smaller steps counts once the steps add up to less than that) and the support pair
   jumped by at least the remaining tangential gradient (the residual is of the size of the
   support set, not a descent the search missed). Both support pairs are J-support points
   of the CSO; the contact points are their convex combination with the smallest
   tangential gap (the point of the support set nearest to stationarity), so
   (p_A − p_B)·n = phi stays the reported depth and lies between the two maxima (within
   J <= tol_nc of either). Parameters and patches stay those of the current support point
   (the warm-start state). The search keeps the world support points of the last jump
   (rows ``_JUMP``); :func:`nurbsdem.contact.lcp.solve_pair` applies the rule.

The work arrays are the LCP's (:func:`nurbsdem.contact.lcp.make_work`): float rows ``wf``
(rows of 3, the layout below), support-mapping states ``wi`` / ``wfs`` (rows 0, 1: current
A, B; rows 2, 3: trial A, B). Lengths in metres, angles in radians.
"""
from __future__ import annotations

import math

import numpy as np

from ..jit import kernel
from .stage1 import S1_ROW, S1_ROWS
from .support import dot3, norm3, support_map
from .trust_region import tr_step2

MAX_OUTER_IT = 60
ANGLE_TOL = 1e-11
#: A final Newton step on the sphere shorter than this (rad) is taken by a Taylor update.
TAYLOR_ANGLE = 1e-7
#: saddle stall of a nearly convex pair (``tol_nc`` > 0, module docstring): the trust
#: radius (rad) below which a search that cannot move counts as stalled; phi has converged
#: when it stayed within this change (× scale) of one value over the last SADDLE_PHI_IT
#: iterations or more; how often the search may move to a higher local maximum of the
#: support problem, the iterations each such move adds and the trust radius (rad) it
#: restarts with
SADDLE_STALL_ANGLE = 1e-8
SADDLE_PHI_TOL = 1e-10
SADDLE_PHI_IT = 10
SADDLE_MAX_MOVES = 2
SADDLE_EXTRA_IT = 40
SADDLE_DELTA = 1e-3

# rows of the float work array (rows of 3): support point, dp/de (3 rows) and du/de (2 rows)
# of A and of B (current, and the same at _TRIAL for the trial direction), scratch of the
# support mappings (_EV, _EV2, _TMP), the body-frame directions, the direction d, the
# tangent basis, the trial direction, the bounding spheres' centres (_H, 2 rows) and the
# trust-region step's scratch (_TR, 3 rows); stage 1 uses S1_ROWS rows from S1_ROW
_PA, _MA, _GA, _PB, _MB, _GB = 0, 1, 4, 6, 7, 10
_TRIAL = 12
_EV, _EV2, _TMP, _EA, _EB, _D, _T1, _T2, _DT, _H = 24, 30, 36, 37, 38, 39, 40, 41, 42, 43
_TR = 45
#: 2 rows: the world support points of A and B at the last saddle-stall jump
_JUMP = S1_ROW + S1_ROWS
#: rows of the float work array
WORK_ROWS = 96


@kernel
def _tangent_basis(d, t1, t2):
    """Orthonormal t1, t2 with t1 × t2 = d (d unit)."""
    ax = abs(d[0])
    ay = abs(d[1])
    az = abs(d[2])
    if ax <= ay and ax <= az:
        a0, a1, a2 = 1.0, 0.0, 0.0
    elif ay <= az:
        a0, a1, a2 = 0.0, 1.0, 0.0
    else:
        a0, a1, a2 = 0.0, 0.0, 1.0
    # t1 = normalize(a - (a.d) d)
    ad = a0 * d[0] + a1 * d[1] + a2 * d[2]
    t1[0] = a0 - ad * d[0]
    t1[1] = a1 - ad * d[1]
    t1[2] = a2 - ad * d[2]
    n = norm3(t1)
    for c in range(3):
        t1[c] /= n
    t2[0] = d[1] * t1[2] - d[2] * t1[1]
    t2[1] = d[2] * t1[0] - d[0] * t1[2]
    t2[2] = d[0] * t1[1] - d[1] * t1[0]


@kernel
def _rot_t(R, d, sign, out):
    """out = sign * Rᵀ d (world direction to file frame)."""
    for a in range(3):
        out[a] = sign * (R[0, a] * d[0] + R[1, a] * d[1] + R[2, a] * d[2])


@kernel
def _to_world(pos, R, p, out):
    """out = pos + R p."""
    for a in range(3):
        out[a] = pos[a] + R[a, 0] * p[0] + R[a, 1] * p[1] + R[a, 2] * p[2]


@kernel
def _quad_world(R, M, x, y):
    """xᵀ (R M Rᵀ) y."""
    s = 0.0
    for a in range(3):
        rx = R[0, a] * x[0] + R[1, a] * x[1] + R[2, a] * x[2]
        for b in range(3):
            ry = R[0, b] * y[0] + R[1, b] * y[1] + R[2, b] * y[2]
            s += rx * M[a, b] * ry
    return s


@kernel
def _eval_supports(tabA, tabB, posA, RA, scA, posB, RB, scB, d, wf, wi, wfs, base, ws, sA, sB):
    """Both support mappings for the world direction d into rows ``base`` (0: current,
    _TRIAL: trial) of the work arrays; states in wi/wfs rows sA, sB. Returns (phi, nev, ok)."""
    ev = wf[_EV:_EV + 6]
    ev2 = wf[_EV2:_EV2 + 6]
    tmp = wf[_TMP]
    eA = wf[_EA]
    eB = wf[_EB]
    _rot_t(RA, d, 1.0, eA)
    _rot_t(RB, d, -1.0, eB)
    okA, nA = support_map(tabA, eA, wi[sA], wfs[sA], scA, ws, ev, ev2, tmp,
                          wf[base + _PA], wf[base + _MA:base + _MA + 3], wf[base + _GA:base + _GA + 2])
    okB, nB = support_map(tabB, eB, wi[sB], wfs[sB], scB, ws, ev, ev2, tmp,
                          wf[base + _PB], wf[base + _MB:base + _MB + 3], wf[base + _GB:base + _GB + 2])
    # phi = d . (posA + RA pA) - d . (posB + RB pB), with the positions' difference taken
    # first: d . posA alone carries a rounding error of eps |posA| (4e-16 m at 2 m from the
    # origin), more than the decrease a last Newton step predicts (~|grad|^2 / curvature,
    # 1e-16 m for |grad| = 1e-9 m); the ratio test would then reject it for ever (the
    # stalls of tests/test_lcp_stalls.py). The difference is exact for nearby bodies.
    pA = wf[base + _PA]
    pB = wf[base + _PB]
    phi = (d[0] * (posA[0] - posB[0]) + d[1] * (posA[1] - posB[1]) + d[2] * (posA[2] - posB[2])
           + dot3(eA, pA) + dot3(eB, pB))
    return phi, nA + nB, okA and okB


@kernel
def _predict(wf, wfs, base, sA, sB, tA, tB, RA, RB, dnew):
    """First-order prediction of the trial parameters: u' = u + G (e' − e)."""
    eA = wf[_EA]
    eB = wf[_EB]
    GA = wf[base + _GA:base + _GA + 2]
    GB = wf[base + _GB:base + _GB + 2]
    for a in range(2):
        sa = 0.0
        sb = 0.0
        for c in range(3):
            ea = RA[0, c] * dnew[0] + RA[1, c] * dnew[1] + RA[2, c] * dnew[2]
            eb = -(RB[0, c] * dnew[0] + RB[1, c] * dnew[1] + RB[2, c] * dnew[2])
            sa += GA[a, c] * (ea - eA[c])
            sb += GB[a, c] * (eb - eB[c])
        wfs[tA, a] = wfs[sA, a] + sa
        wfs[tB, a] = wfs[sB, a] + sb
    wfs[tA, 2] = wfs[sA, 2]
    wfs[tB, 2] = wfs[sB, 2]


@kernel
def _taylor_finish(wf, wfs, RA, RB, d, x1, x2):
    """Take a final Newton step of angle <= TAYLOR_ANGLE without new support mappings:
    d' = normalize(d + x1 t1 + x2 t2), p' = p + M (e' − e), u' = u + G (e' − e).
    The remaining errors are second order in the step (<= 1e-14 relative)."""
    t1 = wf[_T1]
    t2 = wf[_T2]
    dt = wf[_DT]
    nd = 0.0
    for c in range(3):
        dt[c] = d[c] + x1 * t1[c] + x2 * t2[c]
        nd += dt[c] * dt[c]
    nd = math.sqrt(nd)
    for c in range(3):
        dt[c] = dt[c] / nd - d[c]          # delta d
    for body in range(2):
        R = RA if body == 0 else RB
        sg = 1.0 if body == 0 else -1.0
        P = _PA if body == 0 else _PB
        Mr = _MA if body == 0 else _MB
        Gr = _GA if body == 0 else _GB
        de0 = sg * (R[0, 0] * dt[0] + R[1, 0] * dt[1] + R[2, 0] * dt[2])
        de1 = sg * (R[0, 1] * dt[0] + R[1, 1] * dt[1] + R[2, 1] * dt[2])
        de2 = sg * (R[0, 2] * dt[0] + R[1, 2] * dt[1] + R[2, 2] * dt[2])
        for a in range(3):
            wf[P, a] += wf[Mr + a, 0] * de0 + wf[Mr + a, 1] * de1 + wf[Mr + a, 2] * de2
        for a in range(2):
            wfs[body, a] += wf[Gr + a, 0] * de0 + wf[Gr + a, 1] * de1 + wf[Gr + a, 2] * de2
    for c in range(3):
        d[c] += dt[c]


@kernel
def _copy_trial(wf, wi, wfs):
    """Make the trial rows/states current."""
    for r in range(12):
        for c in range(3):
            wf[r, c] = wf[_TRIAL + r, c]
    for c in range(4):
        wi[0, c] = wi[2, c]
        wi[1, c] = wi[3, c]
    for c in range(3):
        wfs[0, c] = wfs[2, c]
        wfs[1, c] = wfs[3, c]


@kernel(inline="always")
def _tangential_gradient(posA, RA, posB, RB, wf, t1, t2):
    """The tangential components (g1, g2) of grad phi = p_A − p_B (world, m) in the chart's
    basis t1, t2 (translation invariant like phi: the positions' difference first)."""
    g1 = 0.0
    g2 = 0.0
    for c in range(3):
        pa = RA[c, 0] * wf[_PA, 0] + RA[c, 1] * wf[_PA, 1] + RA[c, 2] * wf[_PA, 2]
        pb = RB[c, 0] * wf[_PB, 0] + RB[c, 1] * wf[_PB, 1] + RB[c, 2] * wf[_PB, 2]
        gc = (posA[c] - posB[c]) + (pa - pb)
        g1 += t1[c] * gc
        g2 += t2[c] * gc
    return g1, g2


@kernel(inline="always")
def _chart_hessian(RA, RB, wf, t1, t2, phi):
    """The chart's Hessian Tᵀ (H_A + H_B) T − phi I (module docstring) as (k11, k12, k22)."""
    MA = wf[_MA:_MA + 3]
    MB = wf[_MB:_MB + 3]
    k11 = _quad_world(RA, MA, t1, t1) + _quad_world(RB, MB, t1, t1) - phi
    k12 = _quad_world(RA, MA, t1, t2) + _quad_world(RB, MB, t1, t2)
    k22 = _quad_world(RA, MA, t2, t2) + _quad_world(RB, MB, t2, t2) - phi
    return k11, k12, k22


@kernel(inline="always")
def _chart_point(d, t1, t2, x1, x2, out):
    """out = normalize(d + x1 t1 + x2 t2): the direction at chart coordinates (x1, x2)."""
    nd = 0.0
    for c in range(3):
        out[c] = d[c] + x1 * t1[c] + x2 * t2[c]
        nd += out[c] * out[c]
    nd = math.sqrt(nd)
    for c in range(3):
        out[c] /= nd


@kernel(inline="always")
def _take_trial(wf, wi, wfs, d, dt):
    """The trial direction dt, its support points and states become the current ones."""
    _copy_trial(wf, wi, wfs)
    for c in range(3):
        d[c] = dt[c]


@kernel(inline="always")
def _ratio(phi, phin, mval, scale):
    """Ratio of the actual to the predicted decrease of phi (the model's value ``mval`` at
    the step); within the rounding of ``scale`` (m) a decrease counts as 1 and a rise as -1."""
    actual = phi - phin
    pred = -mval
    noise = 1e-15 * scale
    if pred > noise:
        return actual / pred
    return 1.0 if actual >= -4.0 * noise else -1.0


@kernel(inline="always")
def direction_search(tabA, tabB, posA, RA, scA, posB, RB, scB, d, delta, tol_nc, ws, wf, wi,
                     wfs):
    """Minimise phi over unit directions from ``d`` (3,, in place; the start states in
    ``wi``/``wfs`` rows 0, 1) with the trust radius ``delta`` (rad): the support mappings
    at d, then Newton on the sphere (module docstring). ``tol_nc`` (m): h_A + h_B, 0 for
    convex shapes (no saddle-stall moves).

    Returns (phi (m), iterations, patch evaluations, |tangential gradient| (m), converged,
    trust radius, the last saddle-stall jump J (m; < 0: none since the search last moved),
    the value phi stayed near and the iteration since which it did); the current support
    points, their derivatives and states stay in rows ``_PA`` .. ``_GB`` and ``wi``/``wfs``
    rows 0, 1."""
    scale = scA + scB
    t1 = wf[_T1]
    t2 = wf[_T2]
    dt = wf[_DT]
    phi, nev, _ = _eval_supports(tabA, tabB, posA, RA, scA, posB, RB, scB, d, wf, wi, wfs,
                                 np.int64(0), ws, np.int64(0), np.int64(1))
    converged = False
    it = 0
    gnorm = 0.0
    # saddle stall (tol_nc > 0): the last support jump at a vanishing step and the value phi
    # has stayed within SADDLE_PHI_TOL × scale of since iteration it_ref
    jump = -1.0
    phi_ref = np.inf
    it_ref = 0
    nadopt = 0
    while it < MAX_OUTER_IT + SADDLE_EXTRA_IT * nadopt:
        it += 1
        if tol_nc > 0.0 and not abs(phi - phi_ref) <= SADDLE_PHI_TOL * scale:
            phi_ref = phi
            it_ref = it
        _tangent_basis(d, t1, t2)
        g1, g2 = _tangential_gradient(posA, RA, posB, RB, wf, t1, t2)
        gnorm = math.sqrt(g1 * g1 + g2 * g2)
        if gnorm <= 1e-15 * scale:
            converged = True
            break
        k11, k12, k22 = _chart_hessian(RA, RB, wf, t1, t2, phi)
        x1, x2, mval = tr_step2(k11, k12, k22, g1, g2, delta, wf[_TR:_TR + 3])
        xn = math.sqrt(x1 * x1 + x2 * x2)
        newton = xn < 0.99 * delta          # the step is the (positive definite) Newton step
        if newton and xn <= ANGLE_TOL:
            converged = True
            break
        if newton and xn <= TAYLOR_ANGLE:
            _taylor_finish(wf, wfs, RA, RB, d, x1, x2)
            phi += mval
            converged = True
            break
        _chart_point(d, t1, t2, x1, x2, dt)
        # trial states: same patches, predicted parameters
        for c in range(4):
            wi[2, c] = wi[0, c]
            wi[3, c] = wi[1, c]
        _predict(wf, wfs, 0, 0, 1, 2, 3, RA, RB, dt)
        phin, ne, _ = _eval_supports(tabA, tabB, posA, RA, scA, posB, RB, scB, dt, wf, wi, wfs,
                                     np.int64(_TRIAL), ws, np.int64(2), np.int64(3))
        nev += ne
        rho = _ratio(phi, phin, mval, scale)
        if rho > 0.1 and phin == phin:
            _take_trial(wf, wi, wfs, d, dt)
            phi = phin
            if rho > 0.75 and xn >= 0.9 * delta:
                delta = min(2.0 * delta, 1.0)
            if xn > SADDLE_STALL_ANGLE:
                jump = -1.0
        elif (tol_nc > 0.0 and xn <= SADDLE_STALL_ANGLE
              and phin - phi > 2.0 * scale * xn + 4.0 * (1e-15 * scale)):
            # the support jumped to a higher local maximum (module docstring: saddle stall)
            jump = phin - phi
            if nadopt < SADDLE_MAX_MOVES:
                # the current support point is not the maximum: go on from the higher one
                nadopt += 1
                _take_trial(wf, wi, wfs, d, dt)
                phi = phin
                delta = SADDLE_DELTA
                jump = -1.0
                phi_ref = np.inf
                continue
            _to_world(posA, RA, wf[_TRIAL + _PA], wf[_JUMP])
            _to_world(posB, RB, wf[_TRIAL + _PB], wf[_JUMP + 1])
        if rho < 0.25:
            delta = 0.25 * xn
            if delta < 1e-14:
                break
    return phi, it, nev, gnorm, converged, delta, jump, phi_ref, it_ref

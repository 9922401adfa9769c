"""Compiled local contact problem (LCP) of two convex multi-patch NURBS bodies (paper 3.2),
in the paper's two stages.

**Stage 1** (paper Eq. 4–5, :mod:`.stage1`): minimise f1 = ½|ΓA − ΓB|² over the four surface
parameters by trust-region Newton with the exact Hessian. A strict positive minimum means
separated: the distance |g| and the closest points. f1 ≈ 0 means the surfaces intersect.

**Stage 2** (paper Eq. 6–9): one minimisation over unit directions ``d`` (world frame) of

    phi(d) = h_A(d) + h_B(-d),        h_X(d) = max_{x in X} d · x   (support functions)

i.e. the support function of the configuration space obstacle CSO = A − B (paper Eq. 7–8).
Overlapping bodies: min phi = maximum penetration depth (> 0), attained at the normal d*.
(Separated bodies: min phi = −distance < 0 with the closest points as support points — the
same first-order condition as the minimum of f1 — which is what makes phi the certificate
and fallback of stage 1.)

**Pipeline** (:func:`solve_pair`):

* cold start (no valid previous row): stage 1 from the nearest pair of surface samples;
  - separated (strict minimum, f1 > 0): *certificate* — the stage-2 iteration is started at
    d = −g/|g| with the support mappings warm-started at the stage-1 parameters. For convex
    bodies the stage-1 points are the answer iff they are the support points along ±d
    (a separating slab of width |g|); the support mappings confirm this in 1–2 patch
    evaluations each and the first direction step (usually a Taylor update of < 1e-7 rad)
    polishes the normal, which |g|'s direction alone fixes poorly for tiny gaps. Certified
    (≤ 3 direction iterations, h_A(d) + h_B(−d) = −|g| to 1e-9 × scale, points unchanged
    to 1e-6 × scale): ``I_STAGE`` = 1. Otherwise the stage-2 iteration simply continues
    (stage-1 fallback, ``I_STAGE`` = 2) — never an abort;
  - intersecting (or a weak minimum within 1e-8 × scale): stage 2 from d = nA − nB, the
    outward normals at the intersection point (Giraffe's recipe), supports from the samples;
  - stage 1 not converged / saddle: stage 2 from the centroid direction.
* warm start, previous result separated: stage 1 from the previous parameters (1–3 Newton
  steps), then as above; if it finds an intersection, stage 2 warm from the previous normal.
* warm start, previous result penetrating: stage 2 from the previous normal and parameters
  (if it ends separated, the next call starts with stage 1).

``I_IT`` counts the iterations of both stages, ``F_IT1`` those of stage 1.

So ``signed_distance = −min phi`` and the gap (Eq. 4) is ``g = p_A − p_B = phi · d``.

**Equivalence with the paper's f2** (Eq. 6): f2(d) = ½ |p_A(d) − p_B(−d)|² with the support
points of Eq. 8–9. By Danskin's theorem grad phi = p_A(d) − p_B(−d) = map_CSO(d) (Eq. 7);
its tangential part vanishes exactly when map_CSO(d) is parallel to d, i.e. when map_CSO(d) is
the boundary point of the CSO whose outward normal points back at the origin — the
stationarity condition of f2 as well (the CSO point nearest to / deepest from the origin,
where |map_CSO| = |phi|). Both functions have the same minimiser; phi has the simpler
derivatives (first derivative: the support points; second: the support Hessians).

**Newton on the sphere** (:mod:`.stage2`): a trust-region Newton search over unit
directions in a chart re-centred on the current direction, with the exact Hessian from the
support mappings' dp/de; the support points of a trial direction start from the first-order
prediction u + (du/de) (e' − e). A warm start predicts its start parameters the same way for
the bodies' turn since the previous solve (that solve's du/de and body-frame directions are
kept in its result row, columns ``F_EA`` .. ``F_GB``): at the small turns of a sub-step each
support mapping then ends after one evaluation, by the search's Taylor step.  The warm start
of a penetrating pair also moves its start direction: the previous solve's support points
and dp/de (columns ``F_QA`` .. ``F_SB``) give the support points, gradient and Hessian of the
outer problem at the new poses to first order, and the start is the previous normal moved
by that model's Newton step (:func:`_predicted_direction`).  The first outer iteration then
lands within the Taylor step's reach of the solution: one support mapping per body instead
of two (a captured compaction batch at 1e-4 rad turns: 4.4 -> 2.5 patch evaluations per
pair). Nearly convex shapes (a non-convexity height h > 0): a search that stalls at a
saddle, where the support mapping can return a lower local maximum, moves to the higher one
or is accepted within h_A + h_B (:mod:`.stage2`, "saddle stall"); convex shapes never take
that path.

Result rows (``resF`` float, ``resI`` int) use the column constants below. Lengths in metres.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..jit import PointerKernel, kernel
from .stage1 import (MAX_IT as S1_MAX_IT, DELTA0 as S1_DELTA0, O_GL,
                     S1_C, S1_G, S1_INTERSECTING, S1_NONE, S1_PAW, S1_PBW, S1_ROW, S1_ROWS,
                     S1_SEPARATED, W4_COLS, W4_ROWS, nearest_seed, outward_normal, stage1)
from .stage2 import (SADDLE_PHI_IT, SADDLE_PHI_TOL, SADDLE_STALL_ANGLE, WORK_ROWS, _D, _DT, _EA,
                     _EB, _GA, _GB, _H, _JUMP, _MA, _MB, _PA, _PB, _T1, _T2, _TMP,
                     _rot_t, _tangent_basis, _to_world, direction_search)
from .support import CREASE, norm3, rt_times, seed_start

# float result columns
F_SD = 0          # signed distance (m): < 0 penetration depth, > 0 separation
F_N = 1           # 1:4 unit normal (world), outward from A towards B
F_PA = 4          # 4:7 point on A (world, m)
F_PB = 7          # 7:10 point on B (world, m)
F_PAR = 10        # 10:14 params (uA, vA, uB, vB)
F_GRAD = 14       # tangential gradient norm at exit (m)
F_IT1 = 15        # stage-1 trust-region iterations (a count, stored as float)
F_EA = 16         # 16:19 direction of A's support mapping at exit, A's file frame (R_A^T n)
F_EB = 19         # 19:22 direction of B's support mapping at exit, B's file frame (-R_B^T n)
F_GA = 22         # 22:28 du/de of A's support point (2 x 3, row-major; zeros: no prediction)
F_GB = 28         # 28:34 du/de of B's support point
F_QA = 34         # 34:37 A's support point at exit, A's file frame (m; the model of a warm start)
F_QB = 37         # 37:40 B's support point at exit, B's file frame
F_SA = 40         # 40:46 dp/de of A's support point, symmetric part (xx, xy, xz, yy, yz, zz; m)
F_SB = 46         # 46:52 dp/de of B's support point
NF = 52
# int result columns
I_ACTIVE = 0
I_PA = 1          # patch of A (local index in its shape)
I_PB = 2          # patch of B
I_DEG = 3         # degeneration level (number of fixed parameters)
I_IT = 4          # outer Newton iterations
I_FAIL = 5        # 1 = not converged / fallback
I_VALID = 6       # 1 = holds a solution usable as warm start
I_NEV = 7         # patch evaluations spent
I_BROAD = 8       # 1 = rejected by the bounding spheres (Eq. 3), no LCP solved
I_STAGE = 9       # stage that produced the result: 1 = f1 (Eq. 5), 2 = f2/phi (Eq. 6-9), 0 none
NI = 10
#: I_STAGE of a row the point-to-surface solver of a sphere and a NURBS particle gave
#: (:mod:`nurbsdem.contact.sphere`)
STAGE_POINT = 3


@njit(cache=True)
def clear_row(rows_f: np.ndarray, rows_i: np.ndarray, j: int) -> None:
    """Zero row j of rows_f (P,NF), rows_i (P,NI), in place (a view of the row in a loop over
    pairs would cost numba's atomic reference counts: more than the closed form)."""
    for k in range(rows_f.shape[1]):
        rows_f[j, k] = 0.0
    for k in range(rows_i.shape[1]):
        rows_i[j, k] = 0


def full_rows(rows_f) -> np.ndarray:
    """Float result rows (..., NF), C-contiguous: rows of an older layout with fewer columns
    (a checkpoint, stored data) are padded with zeros, which :func:`solve_pair` reads as
    "no warm prediction"."""
    rows_f = np.asarray(rows_f, dtype=float)
    if rows_f.shape[-1] < NF:
        padded = np.zeros(rows_f.shape[:-1] + (NF,))
        padded[..., :rows_f.shape[-1]] = rows_f
        return padded
    return np.ascontiguousarray(rows_f)


#: a warm start of a penetrating pair moves the previous direction by the Newton step of the
#: previous solve's model at the new poses when that step is shorter than this (rad)
PREDICT_ANGLE = 1e-2
#: row of the (W4_ROWS, 4) work array holding the stage-1 summary
W4_OUT = 23
#: stage-2 start modes
MODE_COLD, MODE_WARM, MODE_S1, MODE_NORMALS = 0, 1, 2, 3
#: a stage-1 solution counts as certified when the phi polish ends within this many
#: iterations, at the same distance (relative to the scale) and the same points
S1_CERT_IT = 3
S1_CERT_TOL = 1e-9


@njit(cache=True)
def make_work() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per-thread work arrays of :func:`solve_pair`: (float rows (96, 3), int states (4, 4),
    float states (4, 3), stage-1 float rows (24, 8); compiled: the threads of a parallel batch
    make theirs)."""
    return (np.zeros((WORK_ROWS, 3)), np.zeros((4, 4), np.int64), np.zeros((4, 3)),
            np.zeros((W4_ROWS, W4_COLS)))


@kernel
def _seed_pair(RA, posA, RB, posB, d, infoA, infoB, maskA, maskB, seedsA, seedsB, wf, wi, wfs):
    """Cold start of stage 1: the nearest pair of surface samples, approximately — A's sample
    farthest along the centroid direction d, then alternately the nearest sample of B and of
    A (three passes over the samples). Writes patches/parameters into wi/wfs rows 0, 1."""
    eA = wf[_EA]
    q = wf[_EB]
    _rot_t(RA, d, 1.0, eA)
    pA0 = infoA[0]
    pB0 = infoB[0]
    ka = seed_start(seedsA[0], seedsA[1], seedsA[2], infoA[2], infoA[3], maskA, pA0, eA)
    kb = infoB[2]
    for rep in range(2):
        _to_world(posA, RA, seedsA[0][ka], q)
        kb = nearest_seed(seedsB[0], seedsB[1], infoB[2], infoB[3], maskB, pB0, posB, RB, q)
        if rep == 1:
            break
        _to_world(posB, RB, seedsB[0][kb], q)
        ka = nearest_seed(seedsA[0], seedsA[1], infoA[2], infoA[3], maskA, pA0, posA, RA, q)
    wi[0, 0] = seedsA[1][ka]
    wfs[0, 0] = seedsA[2][ka, 0]
    wfs[0, 1] = seedsA[2][ka, 1]
    wi[1, 0] = seedsB[1][kb]
    wfs[1, 0] = seedsB[2][kb, 0]
    wfs[1, 1] = seedsB[2][kb, 1]


@kernel
def _predicted_params(prevF, body, e, out):
    """Start parameters of body 0 (A) or 1 (B) of a warm solve: the previous support point's
    parameters moved to first order to the body-frame direction e (3,),
    u = u_prev + G (e − e_prev) (the module docstring's prediction, as for a trial
    direction; a row without G, zeros, gives u_prev).  Writes out[0:2]."""
    fe = F_EA if body == 0 else F_EB
    fg = F_GA if body == 0 else F_GB
    pu = F_PAR + 2 * body
    for a in range(2):
        g = fg + 3 * a
        out[a] = (prevF[pu + a] + prevF[g] * (e[0] - prevF[fe])
                  + prevF[g + 1] * (e[1] - prevF[fe + 1]) + prevF[g + 2] * (e[2] - prevF[fe + 2]))


@kernel
def _store_prediction(resF, body, e, G):
    """Columns F_EA.. (body 0) or F_EB.. (body 1) of a result row: the body-frame direction
    e (3,) of the final support point and its du/de G (2, 3), for :func:`_predicted_params`
    at the next solve."""
    fe = F_EA if body == 0 else F_EB
    fg = F_GA if body == 0 else F_GB
    for c in range(3):
        resF[fe + c] = e[c]
        resF[fg + c] = G[0, c]
        resF[fg + 3 + c] = G[1, c]


@kernel
def _store_model(resF, body, p, M):
    """Columns F_QA, F_SA (body 0) or F_QB, F_SB (body 1) of a result row: the body-frame
    support point p (3,) at exit and the symmetric part of its dp/de M (3, 3), the model of
    :func:`_predicted_direction` at the next solve."""
    fq = F_QA if body == 0 else F_QB
    fs = F_SA if body == 0 else F_SB
    k = 0
    for a in range(3):
        resF[fq + a] = p[a]
        for b in range(a, 3):
            resF[fs + k] = 0.5 * (M[a, b] + M[b, a])
            k += 1


@kernel
def _model_point(prevF, body, e, out):
    """out (3,) = the body-frame support point of the previous solve moved to the direction
    e (3, body frame) to first order: q + S (e − e_prev) (columns of :func:`_store_model`)."""
    fq = F_QA if body == 0 else F_QB
    fs = F_SA if body == 0 else F_SB
    fe = F_EA if body == 0 else F_EB
    de0, de1, de2 = e[0] - prevF[fe], e[1] - prevF[fe + 1], e[2] - prevF[fe + 2]
    out[0] = prevF[fq] + prevF[fs] * de0 + prevF[fs + 1] * de1 + prevF[fs + 2] * de2
    out[1] = prevF[fq + 1] + prevF[fs + 1] * de0 + prevF[fs + 3] * de1 + prevF[fs + 4] * de2
    out[2] = prevF[fq + 2] + prevF[fs + 2] * de0 + prevF[fs + 4] * de1 + prevF[fs + 5] * de2


@kernel
def _model_quad(prevF, body, R, x, y):
    """(Rᵀx)ᵀ S (Rᵀy): the stored symmetric dp/de S of body 0/1 as a form on world vectors."""
    fs = F_SA if body == 0 else F_SB
    x0, x1, x2 = rt_times(R, x[0], x[1], x[2])
    y0, y1, y2 = rt_times(R, y[0], y[1], y[2])
    return (x0 * (prevF[fs] * y0 + prevF[fs + 1] * y1 + prevF[fs + 2] * y2)
            + x1 * (prevF[fs + 1] * y0 + prevF[fs + 3] * y1 + prevF[fs + 4] * y2)
            + x2 * (prevF[fs + 2] * y0 + prevF[fs + 4] * y1 + prevF[fs + 5] * y2))


@kernel
def _predicted_direction(prevF, posA, RA, posB, RB, d, wf):
    """The start direction d (3,, in place: the previous normal) of a warm solve of a
    penetrating pair moved by one Newton step (the outer iteration below) of the previous
    solve's model at the new poses: support points q + S (e − e_prev), Hessian from S, so
    that the first support mappings are taken near the new solution (the step the bodies'
    motion since the previous solve asks for, without evaluating a patch).  Nothing is moved
    when the model is not positive definite (a row without one: zeros) or the step exceeds
    PREDICT_ANGLE.  Scratch rows of wf: _EA, _EB, _TMP, _DT, _T1, _T2."""
    eA = wf[_EA]
    eB = wf[_EB]
    pa = wf[_TMP]
    pb = wf[_DT]
    t1 = wf[_T1]
    t2 = wf[_T2]
    _rot_t(RA, d, 1.0, eA)
    _rot_t(RB, d, -1.0, eB)
    _model_point(prevF, np.int64(0), eA, pa)
    _model_point(prevF, np.int64(1), eB, pb)
    _tangent_basis(d, t1, t2)
    phi = 0.0
    g1 = 0.0
    g2 = 0.0
    for c in range(3):
        gc = ((posA[c] - posB[c]) + (RA[c, 0] * pa[0] + RA[c, 1] * pa[1] + RA[c, 2] * pa[2])
              - (RB[c, 0] * pb[0] + RB[c, 1] * pb[1] + RB[c, 2] * pb[2]))
        phi += d[c] * gc
        g1 += t1[c] * gc
        g2 += t2[c] * gc
    a, b = np.int64(0), np.int64(1)         # body rows of the stored models (not literals)
    k11 = _model_quad(prevF, a, RA, t1, t1) + _model_quad(prevF, b, RB, t1, t1) - phi
    k12 = _model_quad(prevF, a, RA, t1, t2) + _model_quad(prevF, b, RB, t1, t2)
    k22 = _model_quad(prevF, a, RA, t2, t2) + _model_quad(prevF, b, RB, t2, t2) - phi
    det = k11 * k22 - k12 * k12
    if not (k11 > 0.0 and det > 0.0):
        return
    x1 = -(k22 * g1 - k12 * g2) / det
    x2 = -(k11 * g2 - k12 * g1) / det
    if not x1 * x1 + x2 * x2 <= PREDICT_ANGLE * PREDICT_ANGLE:
        return
    nd = 0.0
    for c in range(3):
        d[c] += x1 * t1[c] + x2 * t2[c]
        nd += d[c] * d[c]
    nd = math.sqrt(nd)
    for c in range(3):
        d[c] /= nd


@kernel
def _unit_direction(cA, cB, d):
    """d (3,) = the unit vector from cA to cB (+z when they coincide); returns |cB − cA|."""
    dist = 0.0
    for c in range(3):
        d[c] = cB[c] - cA[c]
        dist += d[c] * d[c]
    dist = math.sqrt(dist)
    if dist > 0.0:
        for c in range(3):
            d[c] /= dist
    else:
        d[0] = 0.0
        d[1] = 0.0
        d[2] = 1.0
    return dist


@kernel
def bounding_spheres_apart(posA, RA, cenA, scA, posB, RB, cenB, scB, cA, cB, d, resF, resI):
    """Level 1 of the search (paper Eq. 3) for one pair: the bounding spheres' world centres
    cA, cB (3,) and the unit direction d (3,) from A's to B's; when the spheres are apart,
    the row of the pair (resF, resI zeroed before) is their gap, direction and the points on
    them (``I_BROAD``) and True is returned.  Every kind of pair that the LCP could solve
    answers this case so (the LCP, the point-to-surface problem), so that the rows agree."""
    _to_world(posA, RA, cenA, cA)
    _to_world(posB, RB, cenB, cB)
    dist = _unit_direction(cA, cB, d)
    if not dist > scA + scB:
        return False
    resF[F_SD] = dist - scA - scB
    for c in range(3):
        resF[F_N + c] = d[c]
        resF[F_PA + c] = cA[c] + scA * d[c]
        resF[F_PB + c] = cB[c] - scB * d[c]
    resI[I_PA] = -1
    resI[I_PB] = -1
    resI[I_BROAD] = 1
    return True


@kernel(inline="always")
def warm_start(prevI) -> bool:
    """Whether a previous row (NI,) warm-starts the LCP: a valid row the LCP gave.  A row of
    the point-to-surface solver (``STAGE_POINT``) names no patch of the sphere, so the LCP
    starts cold from it (and a failed pair keeps it: :func:`~nurbsdem.contact.detect.
    kept_on_failure`)."""
    return prevI[I_VALID] == 1 and prevI[I_STAGE] != STAGE_POINT


@kernel(inline="always")
def _warm_normal(prevF, prevI):
    """Whether the previous row is a warm start (:func:`warm_start`, with a nonzero normal)
    and the length of its normal. Returns (warm, |n|)."""
    if not warm_start(prevI):
        return False, 0.0
    nn = norm3(prevF[F_N:F_N + 3])
    return nn > 0.0, nn


@kernel(inline="always")
def _run_stage1(tabA, posA, RA, tabB, posB, RB, infoA, infoB, maskA, maskB, seedsA, seedsB,
                prevF, prevI, warm, scale, d, ws, wf, wi, wfs, w4):
    """Stage 1 (paper Eq. 5) of a cold start (from the nearest samples, ``d`` the centres'
    direction) or of a pair that was separated (from its previous parameters), and the start
    mode of stage 2 it gives (module docstring). Returns (mode, stage-1 iterations, patch
    evaluations, |g| (m))."""
    if warm:
        wi[0, 0] = infoA[0] + prevI[I_PA]
        wi[1, 0] = infoB[0] + prevI[I_PB]
        wfs[0, 0] = prevF[F_PAR]
        wfs[0, 1] = prevF[F_PAR + 1]
        wfs[1, 0] = prevF[F_PAR + 2]
        wfs[1, 1] = prevF[F_PAR + 3]
    else:
        _seed_pair(RA, posA, RB, posB, d, infoA, infoB, maskA, maskB, seedsA, seedsB,
                   wf, wi, wfs)
    for r in range(2):
        wi[r, 1] = 0
        wi[r, 2] = 0
        wi[r, 3] = 0
    s1out = w4[W4_OUT]
    cls, it1, ne1 = stage1(tabA, posA, RA, tabB, posB, RB, scale, wi, wfs, np.int64(S1_MAX_IT),
                           S1_DELTA0, ws, wf, w4, s1out)
    gl = s1out[O_GL]
    fin = gl == gl and abs(gl) < np.inf
    if fin and cls == S1_SEPARATED and gl > 0.0:
        mode = MODE_S1
    elif warm:
        mode = MODE_WARM
    elif fin and (cls == S1_INTERSECTING or (cls != S1_NONE and gl <= 1e-8 * scale)):
        mode = MODE_NORMALS
    else:
        mode = MODE_COLD
    return mode, it1, ne1, gl


@kernel(inline="always")
def _normals_direction(wf, cA, cB, d):
    """Giraffe's recipe after an intersection: d = nA − nB, the outward normals at stage 1's
    intersection point (normalised). Returns False (d unchanged) where a normal is undefined
    or the two nearly cancel."""
    s1 = wf[S1_ROW:S1_ROW + S1_ROWS]
    nA = wf[_TMP]
    nB = wf[_DT]
    dt = wf[_DT]
    okA = outward_normal(s1[S1_C], s1[S1_C + 1], s1[S1_PAW], cA, nA)
    okB = outward_normal(s1[S1_C + 2], s1[S1_C + 3], s1[S1_PBW], cB, nB)
    nd = 0.0
    for c in range(3):
        dt[c] = nA[c] - nB[c]
        nd += dt[c] * dt[c]
    nd = math.sqrt(nd)
    if okA and okB and nd > 0.1:
        for c in range(3):
            d[c] = dt[c] / nd
        return True
    return False


@kernel(inline="always")
def _stage2_start(mode, gl, nn, prev_sep, prevF, prevI, posA, RA, posB, RB, cA, cB, infoA,
                  infoB, maskA, maskB, seedsA, seedsB, d, wf, wi, wfs):
    """The start direction ``d`` and support states (``wi``/``wfs`` rows 0, 1) of stage 2
    for a start mode (module docstring): along the stage-1 gap (``MODE_S1``), the previous
    normal and parameters (``MODE_WARM``), the normals at an intersection
    (``MODE_NORMALS``) or the centres' direction with the samples farthest along it.
    Returns (mode, trust radius (rad))."""
    if mode == MODE_NORMALS and not _normals_direction(wf, cA, cB, d):
        mode = MODE_COLD
    if mode == MODE_S1:
        # d along the stage-1 gap (from A towards B), supports from the stage-1 points
        for c in range(3):
            d[c] = -wf[S1_ROW + S1_G, c] / gl
        delta = 0.1
    elif mode == MODE_WARM:
        for c in range(3):
            d[c] = prevF[F_N + c] / nn
        if not prev_sep:
            _predicted_direction(prevF, posA, RA, posB, RB, d, wf)
        wi[0, 0] = infoA[0] + prevI[I_PA]
        wi[1, 0] = infoB[0] + prevI[I_PB]
        _rot_t(RA, d, 1.0, wf[_EA])
        _rot_t(RB, d, -1.0, wf[_EB])
        _predicted_params(prevF, np.int64(0), wf[_EA], wfs[0])
        _predicted_params(prevF, np.int64(1), wf[_EB], wfs[1])
        delta = 0.1
    else:
        if mode == MODE_COLD:
            _unit_direction(cA, cB, d)        # the centres' direction again
        eA = wf[_EA]
        eB = wf[_EB]
        _rot_t(RA, d, 1.0, eA)
        _rot_t(RB, d, -1.0, eB)
        ka = seed_start(seedsA[0], seedsA[1], seedsA[2], infoA[2], infoA[3], maskA, infoA[0], eA)
        kb = seed_start(seedsB[0], seedsB[1], seedsB[2], infoB[2], infoB[3], maskB, infoB[0], eB)
        wi[0, 0] = seedsA[1][ka]
        wfs[0, 0] = seedsA[2][ka, 0]
        wfs[0, 1] = seedsA[2][ka, 1]
        wi[1, 0] = seedsB[1][kb]
        wfs[1, 0] = seedsB[2][kb, 0]
        wfs[1, 1] = seedsB[2][kb, 1]
        delta = 0.5
    for r in range(2):
        wi[r, 1] = 0
        wi[r, 2] = 0
        wi[r, 3] = 0
        wfs[r, 2] = 0.0
    return mode, delta


@kernel(inline="always")
def _write_solution(resF, d, phi, gnorm, posA, RA, posB, RB, wf, wfs):
    """The float row of the search's end: normal, world points, signed distance −phi,
    parameters, tangential gradient, and the warm-start prediction and model columns."""
    for c in range(3):
        resF[F_N + c] = d[c]
    _to_world(posA, RA, wf[_PA], resF[F_PA:F_PA + 3])
    _to_world(posB, RB, wf[_PB], resF[F_PB:F_PB + 3])
    resF[F_SD] = -phi
    resF[F_PAR] = wfs[0, 0]
    resF[F_PAR + 1] = wfs[0, 1]
    resF[F_PAR + 2] = wfs[1, 0]
    resF[F_PAR + 3] = wfs[1, 1]
    resF[F_GRAD] = gnorm
    _rot_t(RA, d, 1.0, wf[_EA])
    _rot_t(RB, d, -1.0, wf[_EB])
    _store_prediction(resF, np.int64(0), wf[_EA], wf[_GA:_GA + 2])
    _store_prediction(resF, np.int64(1), wf[_EB], wf[_GB:_GB + 2])
    _store_model(resF, np.int64(0), wf[_PA], wf[_MA:_MA + 3])
    _store_model(resF, np.int64(1), wf[_PB], wf[_MB:_MB + 3])


@kernel(inline="always")
def _accept_saddle_stall(resF, d, phi, wf):
    """Rule 2 of a saddle stall (:mod:`.stage2`): when the support pair jumped (to the
    world points in rows ``_JUMP``) by at least the remaining tangential gap, the contact
    points become the convex combination of the two pairs with the smallest tangential gap,
    and the row's depth and gradient follow. Returns (accepted, phi (m))."""
    ja = wf[_JUMP]              # the jump of the support pair (world)
    jb = wf[_JUMP + 1]
    for c in range(3):
        ja[c] = ja[c] - resF[F_PA + c]
        jb[c] = jb[c] - resF[F_PB + c]
    t1 = wf[_T1]
    t2 = wf[_T2]
    _tangent_basis(d, t1, t2)
    r1 = r2 = s1_ = s2_ = 0.0      # tangential gap now, and its change to the other pair
    for c in range(3):
        r1 += t1[c] * (resF[F_PA + c] - resF[F_PB + c])
        r2 += t2[c] * (resF[F_PA + c] - resF[F_PB + c])
        s1_ += t1[c] * (ja[c] - jb[c])
        s2_ += t2[c] * (ja[c] - jb[c])
    if not norm3(ja) + norm3(jb) >= math.sqrt(r1 * r1 + r2 * r2):
        return False, phi
    ss = s1_ * s1_ + s2_ * s2_
    lam = 0.0
    if ss > 0.0:
        lam = min(max(-(r1 * s1_ + r2 * s2_) / ss, 0.0), 1.0)
    phi = 0.0
    for c in range(3):
        resF[F_PA + c] += lam * ja[c]
        resF[F_PB + c] += lam * jb[c]
        phi += d[c] * (resF[F_PA + c] - resF[F_PB + c])
    resF[F_SD] = -phi
    r1 += lam * s1_
    r2 += lam * s2_
    resF[F_GRAD] = math.sqrt(r1 * r1 + r2 * r2)
    return True, phi


@kernel(inline="always")
def _write_counts(resF, resI, wi, infoA, infoB, it, it1, nev):
    """Patches, degeneration level and counts of the int row (stage-1 iterations also in
    the float row)."""
    resI[I_PA] = wi[0, 0] - infoA[0]
    resI[I_PB] = wi[1, 0] - infoB[0]
    deg = 0
    for r in range(2):
        if wi[r, 1] == CREASE:
            deg += 1
        if wi[r, 2] == CREASE:
            deg += 1
    resI[I_DEG] = deg
    resI[I_IT] = it + it1
    resI[I_NEV] = nev
    resF[F_IT1] = it1


@kernel(inline="always")
def _stage_of(mode, converged, it, phi, gl, scale, resF, wf):
    """The stage that produced the row: 1 when it certifies the stage-1 minimum (the support
    points along ±n are the stage-1 points and h_A(n) + h_B(−n) = −|g|, a separating slab
    of width |g|), else 2."""
    if mode == MODE_S1 and converged and it <= S1_CERT_IT and phi < 0.0:
        tol = S1_CERT_TOL * scale
        dp = 0.0
        for c in range(3):
            dp = max(dp, abs(resF[F_PA + c] - wf[S1_ROW + S1_PAW, c]),
                     abs(resF[F_PB + c] - wf[S1_ROW + S1_PBW, c]))
        if abs(phi + gl) <= tol and dp <= 1e3 * tol:
            return 1
    return 2


@kernel(inline="always")
def _finish_flags(resF, resI, prevF, prevI, converged, phi, cA, cB, scA, scB):
    """The row's flags; a row that is not finite is replaced by the previous valid row, or
    else by the bounding spheres' gap and direction, and marked failed."""
    finite = True
    for k in range(14):
        if not (resF[k] == resF[k]) or abs(resF[k]) == np.inf:
            finite = False
    if finite:
        resI[I_FAIL] = 0 if converged else 1
        resI[I_VALID] = 1
        resI[I_ACTIVE] = 1 if phi > 0.0 else 0
        return
    if prevI[I_VALID] == 1:
        for k in range(resF.shape[0]):
            resF[k] = prevF[k]
        for k in range(resI.shape[0]):
            resI[k] = prevI[k]
    else:
        dist = math.sqrt((cB[0] - cA[0]) ** 2 + (cB[1] - cA[1]) ** 2 + (cB[2] - cA[2]) ** 2)
        resF[F_SD] = dist - scA - scB
        for k in range(1, 14):
            resF[k] = 0.0
        for c in range(3):
            resF[F_N + c] = (cB[c] - cA[c]) / dist if dist > 0.0 else 0.0
    resI[I_FAIL] = 1
    resI[I_VALID] = 0
    resI[I_ACTIVE] = 0


@kernel
def solve_pair(tabA, infoA, cenA, scA, tabB, infoB, cenB, scB,
               posA, RA, posB, RB, prevF, prevI, maskA, maskB, seedsA, seedsB,
               ws, wf, wi, wfs, w4, resF, resI, tol_nc):
    """Solve the LCP of one body pair (module docstring); writes ``resF``/``resI`` rows.

    Parameters
    ----------
    tabA, tabB: (deg, ncp, koff, coff, knots, cpw, dom, nbr) packed tables.
    infoA, infoB: int64 (4,) (first patch, patch count, first seed, seed count) in the tables.
    cenA, cenB: centroid (file frame, m) and scA, scB bounding radius (m, paper Eq. 3).
    posA, RA, posB, RB: poses (x_world = pos + R x_file).
    prevF, prevI: previous result rows (a warm start: :func:`warm_start`).
    maskA, maskB: bool per patch, allowed starting patches (empty: all).
    seedsA, seedsB: (x (S, 3), patch (S,), uv (S, 2)) surface samples for cold starts.
    ws, wf, wi, wfs, w4: per-thread workspaces (kernel.make_workspace, make_work()).
    tol_nc: h_A + h_B, the two shapes' non-convexity heights (m; 0 for convex shapes, which
        turns the saddle-stall rule of :mod:`.stage2` off: their results do not depend on it).
    """
    for k in range(resF.shape[0]):
        resF[k] = 0.0
    for k in range(resI.shape[0]):
        resI[k] = 0
    d = wf[_D]
    # ---- global level 1: bounding spheres (paper Eq. 3)
    cA = wf[_H]
    cB = wf[_H + 1]
    if bounding_spheres_apart(posA, RA, cenA, scA, posB, RB, cenB, scB, cA, cB, d, resF, resI):
        return
    scale = scA + scB
    warm, nn = _warm_normal(prevF, prevI)
    prev_sep = warm and prevF[F_SD] > 0.0
    # ---- stage 1 (paper Eq. 5): cold starts and pairs that were separated
    nev = 0
    it1 = 0
    gl = 0.0
    mode = MODE_WARM if warm else MODE_COLD
    if not warm or prev_sep:
        mode, it1, nev, gl = _run_stage1(tabA, posA, RA, tabB, posB, RB, infoA, infoB, maskA,
                                         maskB, seedsA, seedsB, prevF, prevI, warm, scale, d,
                                         ws, wf, wi, wfs, w4)
    # ---- stage 2 (paper Eq. 6-9), or the stage-1 certificate (module docstring)
    mode, delta = _stage2_start(mode, gl, nn, prev_sep, prevF, prevI, posA, RA, posB, RB, cA,
                                cB, infoA, infoB, maskA, maskB, seedsA, seedsB, d, wf, wi, wfs)
    phi, it, ne2, gnorm, converged, delta, jump, phi_ref, it_ref = direction_search(
        tabA, tabB, posA, RA, scA, posB, RB, scB, d, delta, tol_nc, ws, wf, wi, wfs)
    nev += ne2
    # ---- result
    _write_solution(resF, d, phi, gnorm, posA, RA, posB, RB, wf, wfs)
    if (not converged and tol_nc > 0.0 and 0.0 <= jump <= tol_nc and delta <= SADDLE_STALL_ANGLE
            and abs(phi - phi_ref) <= SADDLE_PHI_TOL * scale and it - it_ref >= SADDLE_PHI_IT):
        converged, phi = _accept_saddle_stall(resF, d, phi, wf)
    _write_counts(resF, resI, wi, infoA, infoB, it, it1, nev)
    resI[I_STAGE] = _stage_of(mode, converged, it, phi, gl, scale, resF, wf)
    _finish_flags(resF, resI, prevF, prevI, converged, phi, cA, cB, scA, scB)


#: :func:`solve_pair` compiled once and called by the batch kernels through a pointer
#: (:class:`~nurbsdem.jit.PointerKernel`): its callers do not compile the LCP again
solve_pair_ptr = PointerKernel(solve_pair, "solve_pair", lazy=True).call

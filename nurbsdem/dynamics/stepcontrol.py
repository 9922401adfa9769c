"""Time-step control that sees the whole contact network, and a guard against period-2 motion.

Why a network and not a pair
----------------------------
The explicit scheme (:mod:`nurbsdem.dynamics.integrator`) is stable while the internal step h
satisfies, for every mode of the linearised contact network,

    h < Δt_cr = 2 / (γ/2 + √(ω² + γ²/4))  =  (2/ω)(√(1+ζ²) − ζ),   ζ = γ / (2ω)        (1)

(the damped spring's limit with the damping rate γ = 2ζω, which makes plain that Δt_cr falls
when either ω² or γ grows).  For one pair, ω² = k/m* and γ = c/m*.  A body with n contacts has a
stiffer mode than any of its pairs (in a face-centred cubic block of spheres ω² reaches about
8× the pair value), so a step chosen from the stiffest pair can be unstable in a dense pack.

The network's operators
-----------------------
With the generalised coordinates of the N particles scaled by the mass matrix,
y = M^{1/2} (u, θ) (θ in each body's principal frame), the linearised contact stiffness is the
symmetric positive semi-definite operator

    A_K = Σ_c J_cᵀ D_c J_c ,   D_c = εn n nᵀ + εt (1 − n nᵀ)                             (2)

where J_c y is the relative displacement of body B with respect to body A at the contact point
p (translation plus rotation × lever arm r = p − x, so an off-centre contact on a flat body
counts with its true, smaller effective mass), and walls have no degrees of freedom.  The
damping operator A_C is the same with (cn, ct).  ω² = λmax(A_K), γ = λmax(A_C) in (1) (for
damping proportional to stiffness, as in every interface of the paper, the two maxima belong to
the same mode and (1) is exact; otherwise it is conservative).

λmax is computed matrix-free by Lanczos iteration (:func:`network_lanczos`, a few tens of
products, each O(K)) from a fixed start vector, so the result is deterministic and a restart
reproduces it bit for bit.  The operator includes, besides the active contacts, the separated
pairs that can close within the next deck step ("near" pairs), so the sub-step count rises
*before* the contact appears.  The a-priori estimate for contacts that are not yet near uses
each shape's worst point compliance (:func:`surface_compliance`): the largest
1/m + (r × n)ᵀ I⁻¹ (r × n) over its surface.

Period-2 guard
--------------
An explicit step beyond the limit of the highest mode shows as motion that reverses at every
internal step.  Its full-step velocities are ~0, so the kinetic energy of the monitors cannot
see it.  :func:`alternation_update` watches the half-step velocities (the drift of each internal
step) instead: a body whose translational or angular half-step velocity reverses at every step
(cosine < −0.9) without decaying (ratio ≥ 0.9), above a round-off floor, for
:data:`ALTERNATION_STEPS` consecutive steps, is in period-2 motion.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

#: consecutive reversing internal steps that make period-2 motion
ALTERNATION_STEPS = 10
#: a reversal: cos(angle between successive half-step velocities) below this
ALTERNATION_COS = -0.9
#: not decaying: |v_{n+1/2}| >= this × |v_{n-1/2}|
ALTERNATION_RATIO = 0.9
#: Lanczos steps of the network estimate, and the relative change of its largest Ritz value
#: that ends it earlier
LANCZOS_STEPS = 30
LANCZOS_RTOL = 1e-4
#: quiet deck steps after which a refinement of the step (period-2 or energy guard) is halved
REFINE_DECAY_STEPS = 200
#: from this many sub-steps per deck step on, a warning says what limits the step
HEAVY_SUBSTEPS = 20
#: deck steps between exact (Lanczos) network estimates when the Gershgorin bound calls for no
#: more sub-steps (a fall of the count is noticed at these steps)
NETWORK_RECHECK_STEPS = 20
#: the exact estimate is repeated when the Gershgorin bound of the network's critical step has
#: fallen by more than this fraction since the last exact estimate
NETWORK_BOUND_SLACK = 0.05
#: the sub-step count falls only when the need is below this fraction of the current count
FALL_HYSTERESIS = 0.8


def critical_step(k: float, c: float, m: float) -> tuple[float, float, float]:
    """(ω rad/s, ζ, Δt_cr s) of a spring k (N/m) – dashpot c (N s/m) – mass m (kg) for the
    explicit scheme: Δt_cr = (2/ω)(√(1+ζ²) − ζ).  Δt_cr = inf when k = 0."""
    if k <= 0 or not math.isfinite(m):
        return 0.0, 0.0, math.inf
    omega = math.sqrt(k / m)
    zeta = c / (2.0 * math.sqrt(k * m))
    return omega, zeta, (2.0 / omega) * (math.sqrt(1.0 + zeta * zeta) - zeta)


@njit(cache=True)
def critical_step_from_rates(omega2: float, gamma: float) -> float:
    """Eq. (1): Δt_cr (s) from the largest squared frequency ω² (1/s²) and damping rate γ (1/s)."""
    if omega2 <= 0 and gamma <= 0:
        return math.inf
    return 2.0 / (0.5 * gamma + math.sqrt(max(omega2, 0.0) + 0.25 * gamma * gamma))


# --------------------------------------------------------------------------- a priori
def surface_compliance(points: np.ndarray, normals: np.ndarray, mass: float,
                       inertia: np.ndarray) -> tuple[float, float]:
    """Worst point compliances of a body (1/kg) over sampled surface points.

    points (S,3) relative to the centroid and normals (S,3), in the body frame; inertia (3,3)
    about the centroid in that frame (kg m²).  Returns (g_n, g_t): the largest
    1/m + (r×n)ᵀ I⁻¹ (r×n) (normal direction) and the largest eigenvalue of the compliance
    G = 1/m + [r]ₓᵀ I⁻¹ [r]ₓ restricted to the tangent plane.  An effective mass of a contact
    at that point is 1/g.  For a sphere (r ∥ n): g_n = 1/m, g_t = 1/m + r²/I = 3.5/m.
    """
    inv_I = np.linalg.inv(0.5 * (inertia + inertia.T))
    rxn = np.cross(points, normals)
    g_n = 1.0 / mass + np.einsum("si,ij,sj->s", rxn, inv_I, rxn)
    # G = 1/m + [r]x^T I^-1 [r]x ; [r]x w = r x w
    rx = np.zeros((points.shape[0], 3, 3))
    rx[:, 0, 1], rx[:, 0, 2] = -points[:, 2], points[:, 1]
    rx[:, 1, 0], rx[:, 1, 2] = points[:, 2], -points[:, 0]
    rx[:, 2, 0], rx[:, 2, 1] = -points[:, 1], points[:, 0]
    G = np.einsum("sji,jk,skl->sil", rx, inv_I, rx) + np.eye(3)[None] / mass
    P = np.eye(3)[None] - np.einsum("si,sj->sij", normals, normals)
    g_t = np.linalg.eigvalsh(np.einsum("sij,sjk,skl->sil", P, G, P))[:, -1]
    return float(g_n.max()), float(g_t.max())


def shape_compliance(shape, mass: float, inertia: np.ndarray, centroid: np.ndarray,
                     n: int = 16) -> tuple[float, float]:
    """:func:`surface_compliance` of a NURBS shape sampled on a (2n+1)² grid of parameters per
    patch, edges and mid-lines included (exact points and normals; file frame; inertia (3,3)
    about ``centroid``).  Points where the normal is undefined (poles) are skipped."""
    pts, nrm = [], []
    for patch in shape.patches:
        u0, u1, v0, v1 = patch.domain
        t = np.linspace(0.0, 1.0, 2 * n + 1)
        U, V = np.meshgrid(u0 + t * (u1 - u0), v0 + t * (v1 - v0), indexing="ij")
        d = patch.evaluate(U.ravel(), V.ravel(), 1)
        cr = np.cross(d[:, 1], d[:, 2])
        ln = np.linalg.norm(cr, axis=1)
        ok = ln > 1e-12 * max(float(ln.max()), 1e-300)
        pts.append(d[ok, 0])
        nrm.append(cr[ok] / ln[ok, None])
    return surface_compliance(np.concatenate(pts) - np.asarray(centroid, float)[None],
                              np.concatenate(nrm), mass, inertia)


# --------------------------------------------------------------------------- network operator
@njit(cache=True)
def network_blocks(body_a: np.ndarray, body_b: np.ndarray, point: np.ndarray, x: np.ndarray,
                   Q: np.ndarray, sq_m: np.ndarray, sq_I: np.ndarray,
                   image=None) -> tuple[np.ndarray, np.ndarray]:
    """The contacts' rows of J in Eq. (2), formed once per estimate so that each product
    :func:`apply_blocks` is multiply–adds only: s (K,2) 1/√m and C (K,2,3,3) the map
    −[r]× Q diag(1/√I) of a body's scaled rotation to the displacement of the contact point
    (both 1/√kg: metres per unit of the scaled coordinates), for B (side 0) and A (side 1);
    walls (index ≥ N) get zeros.  The relative displacement of B w.r.t. A is
    J_c y = Σ_side ±(s y_trans + C y_rot).  ``image`` (K,3) m: the translation of the
    periodic image of B each contact touches (:mod:`nurbsdem.contact.periodic`; None: none),
    B's lever arm taken from that image."""
    K, n_part = body_a.shape[0], x.shape[0]
    s = np.zeros((K, 2))
    C = np.zeros((K, 2, 3, 3))
    for c in range(K):
        for side in range(2):
            i = body_b[c] if side == 0 else body_a[c]
            if i >= n_part:
                continue
            r0, r1, r2 = point[c, 0] - x[i, 0], point[c, 1] - x[i, 1], point[c, 2] - x[i, 2]
            if image is not None and side == 0:
                r0, r1, r2 = r0 - image[c, 0], r1 - image[c, 1], r2 - image[c, 2]
            s[c, side] = 1.0 / sq_m[i]
            for j in range(3):      # column j: the displacement Q e_j / √I_j × r
                w0, w1, w2 = (Q[i, 0, j] / sq_I[i, j], Q[i, 1, j] / sq_I[i, j],
                              Q[i, 2, j] / sq_I[i, j])
                C[c, side, 0, j] = w1 * r2 - w2 * r1
                C[c, side, 1, j] = w2 * r0 - w0 * r2
                C[c, side, 2, j] = w0 * r1 - w1 * r0
    return s, C


@njit(cache=True, inline="always")
def _side_displacement(y, c, side, o, s, C):
    """s y_trans + C y_rot (3 floats) of the body whose coordinates start at y[o], on side
    ``side`` of contact c: the displacement of the contact point by that body's motion."""
    sc = s[c, side]
    y3, y4, y5 = y[o + 3], y[o + 4], y[o + 5]
    e0 = sc * y[o] + C[c, side, 0, 0] * y3 + C[c, side, 0, 1] * y4 + C[c, side, 0, 2] * y5
    e1 = sc * y[o + 1] + C[c, side, 1, 0] * y3 + C[c, side, 1, 1] * y4 + C[c, side, 1, 2] * y5
    e2 = sc * y[o + 2] + C[c, side, 2, 0] * y3 + C[c, side, 2, 1] * y4 + C[c, side, 2, 2] * y5
    return e0, e1, e2


@njit(cache=True, inline="always")
def _side_force(c, side, s, C, f0, f1, f2):
    """(s f, Cᵀ f) (6 floats): the force f on the body of side ``side`` of contact c as scaled
    generalised forces."""
    sc = s[c, side]
    return (sc * f0, sc * f1, sc * f2,
            C[c, side, 0, 0] * f0 + C[c, side, 1, 0] * f1 + C[c, side, 2, 0] * f2,
            C[c, side, 0, 1] * f0 + C[c, side, 1, 1] * f1 + C[c, side, 2, 1] * f2,
            C[c, side, 0, 2] * f0 + C[c, side, 1, 2] * f1 + C[c, side, 2, 2] * f2)


@njit(cache=True)
def apply_blocks(y: np.ndarray, body_a: np.ndarray, body_b: np.ndarray, normal: np.ndarray,
                 k_n: np.ndarray, k_t: np.ndarray, s: np.ndarray, C: np.ndarray,
                 z: np.ndarray) -> None:
    """z (6N,) = A y of Eq. (2) (in place) with the blocks of :func:`network_blocks` and
    per-contact normal/tangential coefficients k_n, k_t (N/m, or N s/m).  Per contact, the
    relative displacement d = J_c y of B w.r.t. A (B's part added to 0, then A's
    subtracted), the force f = k_n (d·n) n + k_t (d − (d·n) n), and ±(s f, Cᵀ f) added to B
    and subtracted from A; each in scalars (no per-contact arrays)."""
    n_part = y.shape[0] // 6
    z[:] = 0.0
    for c in range(body_a.shape[0]):
        ib, ia = body_b[c], body_a[c]
        d0 = d1 = d2 = 0.0
        if ib < n_part:
            e0, e1, e2 = _side_displacement(y, c, 0, 6 * ib, s, C)
            d0 += e0
            d1 += e1
            d2 += e2
        if ia < n_part:
            e0, e1, e2 = _side_displacement(y, c, 1, 6 * ia, s, C)
            d0 -= e0
            d1 -= e1
            d2 -= e2
        n0, n1, n2 = normal[c, 0], normal[c, 1], normal[c, 2]
        dn = d0 * n0 + d1 * n1 + d2 * n2
        kn, kt = k_n[c], k_t[c]
        f0 = kn * dn * n0 + kt * (d0 - dn * n0)
        f1 = kn * dn * n1 + kt * (d1 - dn * n1)
        f2 = kn * dn * n2 + kt * (d2 - dn * n2)
        if ib < n_part:
            g = _side_force(c, 0, s, C, f0, f1, f2)
            o = 6 * ib
            for k in range(6):
                z[o + k] += g[k]
        if ia < n_part:
            g = _side_force(c, 1, s, C, f0, f1, f2)
            o = 6 * ia
            for k in range(6):
                z[o + k] -= g[k]

@njit(cache=True)
def network_apply(y: np.ndarray, body_a: np.ndarray, body_b: np.ndarray, point: np.ndarray,
                  normal: np.ndarray, k_n: np.ndarray, k_t: np.ndarray, x: np.ndarray,
                  Q: np.ndarray, sq_m: np.ndarray, sq_I: np.ndarray) -> np.ndarray:
    """z = A y for the operator of Eq. (2) with per-contact normal/tangential coefficients
    k_n, k_t (stiffness N/m, or damping N s/m).  y, z (6N,); x (N,3) centroids; Q (N,3,3)
    principal→world; sq_m (N,) √m; sq_I (N,3) √(principal moments).  Walls: index ≥ N."""
    s, C = network_blocks(body_a, body_b, point, x, Q, sq_m, sq_I)
    z = np.empty(y.shape[0])
    apply_blocks(y, body_a, body_b, normal, k_n, k_t, s, C, z)
    return z


@njit(cache=True)
def _compliance_row(i, r, d, Q, inv_I):
    """c = Qᵀ (r × d) of body i, and Σ_k c_k² / I_k."""
    x0 = r[1] * d[2] - r[2] * d[1]
    x1 = r[2] * d[0] - r[0] * d[2]
    x2 = r[0] * d[1] - r[1] * d[0]
    c0 = Q[i, 0, 0] * x0 + Q[i, 1, 0] * x1 + Q[i, 2, 0] * x2
    c1 = Q[i, 0, 1] * x0 + Q[i, 1, 1] * x1 + Q[i, 2, 1] * x2
    c2 = Q[i, 0, 2] * x0 + Q[i, 1, 2] * x1 + Q[i, 2, 2] * x2
    g = 0.0 + c0 * c0 * inv_I[i, 0]
    g += c1 * c1 * inv_I[i, 1]
    g += c2 * c2 * inv_I[i, 2]
    return c0, c1, c2, g


@njit(cache=True)
def _side_norms(i, n_part, r, n, Q, inv_m, inv_I, t1, t2):
    """(|ĵ_n|, ||ĵ_t||) of one side of a contact: the square roots of the normal and the
    largest tangential point compliance n·G n, λmax(Tᵀ G T), G = 1/m + [r]ₓᵀ I⁻¹ [r]ₓ.
    With c = Qᵀ (r × d) for d = n, t1, t2: d·G d' = (1/m) d·d' + Σ_k c_k c'_k / I_k."""
    if i >= n_part:
        return 0.0, 0.0
    _, _, _, g0 = _compliance_row(i, r, n, Q, inv_I)
    a0, a1, a2, g1 = _compliance_row(i, r, t1, Q, inv_I)
    b0, b1, b2, g2 = _compliance_row(i, r, t2, Q, inv_I)
    g12 = 0.0 + a0 * b0 * inv_I[i, 0]
    g12 += a1 * b1 * inv_I[i, 1]
    g12 += a2 * b2 * inv_I[i, 2]
    a11, a22 = inv_m[i] + g1, inv_m[i] + g2
    lam = 0.5 * (a11 + a22) + math.sqrt(0.25 * (a11 - a22) ** 2 + g12 * g12)
    return math.sqrt(inv_m[i] + g0), math.sqrt(lam)


@njit(cache=True)
def _side_norms_coarse(i, n_part, r, n, inv_m, inv_I):
    """Upper bounds of :func:`_side_norms` from the largest inverse moment alone:
    n·G n <= 1/m + |r × n|² max(1/I_k) and λmax(Tᵀ G T) <= 1/m + |r|² max(1/I_k) (since
    |r × t| <= |r| for a unit t); equal to them for a body with equal moments (a sphere)."""
    if i >= n_part:
        return 0.0, 0.0
    x0 = r[1] * n[2] - r[2] * n[1]
    x1 = r[2] * n[0] - r[0] * n[2]
    x2 = r[0] * n[1] - r[1] * n[0]
    big = max(inv_I[i, 0], inv_I[i, 1], inv_I[i, 2])
    rn2 = x0 * x0 + x1 * x1 + x2 * x2
    r2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
    return math.sqrt(inv_m[i] + rn2 * big), math.sqrt(inv_m[i] + r2 * big)


@njit(cache=True)
def _tangent_basis(n, t1, t2) -> None:
    """Unit tangents t1, t2 (3,) of the unit normal n (in place)."""
    if abs(n[0]) < 0.9:
        t1[0], t1[1], t1[2] = 0.0, n[2], -n[1]
    else:
        t1[0], t1[1], t1[2] = -n[2], 0.0, n[0]
    ln = math.sqrt(t1[0] ** 2 + t1[1] ** 2 + t1[2] ** 2)
    for k in range(3):
        t1[k] /= ln
    t2[0] = n[1] * t1[2] - n[2] * t1[1]
    t2[1] = n[2] * t1[0] - n[0] * t1[2]
    t2[2] = n[0] * t1[1] - n[1] * t1[0]


#: the coarse bounds are raised by this factor so that round-off cannot make them smaller
#: than the exact ones (the gate's decision from a coarse bound is then the exact one's)
COARSE_INFLATION = 1.0 + 1e-9


@njit(cache=True)
def network_gershgorin(body_a: np.ndarray, body_b: np.ndarray, point: np.ndarray,
                       normal: np.ndarray, coeffs: np.ndarray, x: np.ndarray, Q: np.ndarray,
                       inv_m: np.ndarray, inv_I: np.ndarray,
                       coarse: bool = False, image=None) -> tuple[float, float]:
    """Upper bounds (ω² 1/s², γ 1/s) of λmax of Eq. (2)'s stiffness and damping operators:
    the largest block-Gershgorin row sum Σ_c k_c |ĵ_c,i| (|ĵ_c,i| + |ĵ_c,j|) over the bodies,
    normal and tangential parts with their own point compliances.  O(K), no iteration: cheap
    enough for every deck step (the Lanczos value is needed only when this bound calls for
    more sub-steps).  coeffs (K,4): εn, cn, εt, ct.  ``coarse``: the point compliances bounded
    by :func:`_side_norms_coarse` (no body frames; larger bounds, by COARSE_INFLATION at least,
    equal to round-off for spheres), about three times cheaper.  ``image``: as
    :func:`network_blocks`."""
    n_part = x.shape[0]
    rk = np.zeros(n_part)
    rc = np.zeros(n_part)
    r = np.zeros(3)
    t1 = np.empty(3)
    t2 = np.empty(3)
    norms = np.empty((2, 2))          # |ĵ| of side A / B, normal / tangential
    n = np.empty(3)                   # the contact's normal (a copy: no view per contact)
    for c in range(body_a.shape[0]):
        n[0], n[1], n[2] = normal[c, 0], normal[c, 1], normal[c, 2]
        if not coarse:
            _tangent_basis(n, t1, t2)
        for side in range(2):
            i = body_a[c] if side == 0 else body_b[c]
            if i < n_part:
                for k in range(3):
                    r[k] = point[c, k] - x[i, k]
                    if image is not None and side == 1:
                        r[k] -= image[c, k]
            if coarse:
                jn, jt = _side_norms_coarse(i, n_part, r, n, inv_m, inv_I)
            else:
                jn, jt = _side_norms(i, n_part, r, n, Q, inv_m, inv_I, t1, t2)
            norms[side, 0], norms[side, 1] = jn, jt
        for side in range(2):
            i = body_a[c] if side == 0 else body_b[c]
            if i >= n_part:
                continue
            jn, jt = norms[side, 0], norms[side, 1]
            sn = jn * (jn + norms[1 - side, 0])
            st = jt * (jt + norms[1 - side, 1])
            rk[i] += coeffs[c, 0] * sn + coeffs[c, 2] * st
            rc[i] += coeffs[c, 1] * sn + coeffs[c, 3] * st
    wk, wc = 0.0, 0.0
    for i in range(n_part):
        wk = max(wk, rk[i])
        wc = max(wc, rc[i])
    if coarse:
        wk, wc = wk * COARSE_INFLATION, wc * COARSE_INFLATION
    return wk, wc


@njit(cache=True)
def needed_substeps(dt: float, dt_safe: float) -> int:
    """Sub-steps that keep the internal step of a deck step dt (s) within dt_safe (s)."""
    if not math.isfinite(dt_safe):
        return 1
    return max(1, math.ceil(dt / dt_safe * (1 - 1e-12)))


@njit(cache=True)
def periodic_recheck(step_count: int, every: int, refine: int, fall: float,
                     substeps: int) -> bool:
    """Whether deck step ``step_count`` is one of the regular exact (Lanczos) estimates: every
    ``every`` deck steps, when the count could fall (it is above the guard's refinement by
    more than the hysteresis factor ``fall``)."""
    return step_count % every == 0 and refine < fall * substeps


@njit(cache=True)
def count_stands(bound: float, dt_bound: float, slack: float, need: int, refine: int,
                 substeps: int) -> bool:
    """The gate of the time-step control: whether the present sub-step count stands without
    an exact estimate, given the network's Gershgorin bound (s) now and at the last exact
    estimate (dt_bound): the network is no stiffer than then (within ``slack``), or even the
    count ``need`` that the rigorous bound asks for (× the guard's refinement) is no more."""
    return bound >= (1.0 - slack) * dt_bound or need * refine <= substeps


@njit(cache=True)
def network_count_stands(body_a: np.ndarray, body_b: np.ndarray, point: np.ndarray,
                         normal: np.ndarray, coeffs: np.ndarray, x: np.ndarray, Q: np.ndarray,
                         inv_m: np.ndarray, inv_I: np.ndarray, dt: float, safety: float,
                         dt_apriori: float, dt_bound: float, slack: float, refine: int,
                         substeps: int, image=None) -> bool:
    """:func:`count_stands` for the network (a, b, point, normal, coeffs) of a deck step dt
    (s): decided by the coarse Gershgorin bound when that suffices (a coarse bound is never
    below the exact one, so where it lets the count stand the exact one does too), else by the
    exact bound; the decision is the exact bound's either way."""
    for coarse in (True, False):
        wk, wc = network_gershgorin(body_a, body_b, point, normal, coeffs, x, Q, inv_m, inv_I,
                                    coarse, image)
        bound = critical_step_from_rates(wk, wc) if body_a.shape[0] else math.inf
        need = needed_substeps(dt, safety * min(dt_apriori, bound))
        if count_stands(bound, dt_bound, slack, need, refine, substeps):
            return True
    return False


@njit(cache=True)
def body_speeds(v: np.ndarray, omega: np.ndarray, ell: np.ndarray, wall_u: np.ndarray) -> np.ndarray:
    """(N+W,) the largest speed of any point of each body (m/s): |v| + ℓ|ω| for particles
    (ℓ its size), |u| for walls."""
    n = v.shape[0]
    out = np.empty(n + wall_u.shape[0])
    for i in range(n):
        out[i] = (math.sqrt(v[i, 0] ** 2 + v[i, 1] ** 2 + v[i, 2] ** 2)
                  + ell[i] * math.sqrt(omega[i, 0] ** 2 + omega[i, 1] ** 2 + omega[i, 2] ** 2))
    for w in range(wall_u.shape[0]):
        out[n + w] = math.sqrt(wall_u[w, 0] ** 2 + wall_u[w, 1] ** 2 + wall_u[w, 2] ** 2)
    return out


@njit(cache=True)
def contact_network(c_a: np.ndarray, c_b: np.ndarray, c_point: np.ndarray, c_normal: np.ndarray,
                    c_coeffs: np.ndarray, near_a: np.ndarray, near_b: np.ndarray,
                    near_point: np.ndarray, near_normal: np.ndarray, near_gap: np.ndarray,
                    speed: np.ndarray, dt: float, g: float, table: np.ndarray,
                    material: np.ndarray):
    """The linearised network of the time-step control: the K contacts of the last evaluation
    (their own tangent coefficients c_coeffs (K,4): εn, cn, εt, ct) and the separated pairs
    whose gap (m) can close within one deck step dt (s): gap ≤ 2 (s_a + s_b) dt + g dt² with
    s the bodies' point speeds (:func:`body_speeds`, m/s) and g = |gravity| (m/s²); those take
    the coefficients of their interface (table (M,M,≥4) by material).  Returns (a, b, point,
    normal, coeffs) arrays."""
    K = c_a.shape[0]
    take = np.empty(near_a.shape[0], np.int64)
    m = 0
    for r in range(near_a.shape[0]):
        if near_gap[r] <= 2.0 * (speed[near_a[r]] + speed[near_b[r]]) * dt + g * dt * dt:
            take[m] = r
            m += 1
    a = np.empty(K + m, np.int64)
    b = np.empty(K + m, np.int64)
    p = np.empty((K + m, 3))
    n = np.empty((K + m, 3))
    coeffs = np.empty((K + m, 4))
    for c in range(K):
        a[c], b[c] = c_a[c], c_b[c]
        for k in range(3):
            p[c, k], n[c, k] = c_point[c, k], c_normal[c, k]
        for k in range(4):
            coeffs[c, k] = c_coeffs[c, k]
    for s in range(m):
        r = take[s]
        c = K + s
        a[c], b[c] = near_a[r], near_b[r]
        for k in range(3):
            p[c, k], n[c, k] = near_point[r, k], near_normal[r, k]
        for k in range(4):
            coeffs[c, k] = table[material[a[c]], material[b[c]], k]
    return a, b, p, n, coeffs


@njit(cache=True)
def _largest_ritz(alpha: np.ndarray, beta: np.ndarray, m: int) -> tuple[float, np.ndarray]:
    """Largest eigenpair of the m×m symmetric tridiagonal matrix (diagonal alpha[:m],
    off-diagonal beta[:m-1])."""
    T = np.zeros((m, m))
    for i in range(m):
        T[i, i] = alpha[i]
        if i + 1 < m:
            T[i, i + 1] = T[i + 1, i] = beta[i]
    w, y = np.linalg.eigh(T)
    return w[m - 1], np.ascontiguousarray(y[:, m - 1])


@njit(cache=True)
def _dot(a: np.ndarray, b: np.ndarray) -> float:
    """a · b in a fixed order (four interleaved partial sums, then their sum: the same bits
    whatever BLAS and its threads, and not held to one addition's latency per term)."""
    n = a.shape[0]
    s0 = s1 = s2 = s3 = 0.0
    m = n - n % 4
    for i in range(0, m, 4):
        s0 += a[i] * b[i]
        s1 += a[i + 1] * b[i + 1]
        s2 += a[i + 2] * b[i + 2]
        s3 += a[i + 3] * b[i + 3]
    for i in range(m, n):
        s0 += a[i] * b[i]
    return (s0 + s1) + (s2 + s3)


@njit(cache=True)
def _orthogonalise(w: np.ndarray, basis: np.ndarray) -> None:
    """w −= (basis_j · w) basis_j for each row j in turn, in place (modified Gram–Schmidt: each
    coefficient taken from the w already orthogonal to the rows before it).  One pass over w
    per row: the subtraction of row j − 1 and the dot product of row j with the updated w
    together, the dot's terms summed in :func:`_dot`'s order (the same bits)."""
    rows, n = basis.shape[0], w.shape[0]
    if rows == 0:
        return
    m = n - n % 4
    c = _dot(basis[0], w)
    for j in range(1, rows):
        s0 = s1 = s2 = s3 = 0.0
        for i in range(0, m, 4):
            w[i] -= c * basis[j - 1, i]
            w[i + 1] -= c * basis[j - 1, i + 1]
            w[i + 2] -= c * basis[j - 1, i + 2]
            w[i + 3] -= c * basis[j - 1, i + 3]
            s0 += basis[j, i] * w[i]
            s1 += basis[j, i + 1] * w[i + 1]
            s2 += basis[j, i + 2] * w[i + 2]
            s3 += basis[j, i + 3] * w[i + 3]
        for i in range(m, n):
            w[i] -= c * basis[j - 1, i]
            s0 += basis[j, i] * w[i]
        c = (s0 + s1) + (s2 + s3)
    for i in range(n):
        w[i] -= c * basis[rows - 1, i]


@njit(cache=True)
def network_lanczos(body_a: np.ndarray, body_b: np.ndarray, point: np.ndarray,
                    normal: np.ndarray, k_n: np.ndarray, k_t: np.ndarray, x: np.ndarray,
                    Q: np.ndarray, sq_m: np.ndarray, sq_I: np.ndarray, steps: int = LANCZOS_STEPS,
                    rtol: float = LANCZOS_RTOL) -> tuple[float, np.ndarray]:
    """Largest eigenvalue and Ritz vector (6N,) of the network operator of
    :func:`network_apply` (symmetric positive semi-definite): :func:`lanczos_blocks` on the
    blocks of :func:`network_blocks`."""
    s, C = network_blocks(body_a, body_b, point, x, Q, sq_m, sq_I)
    return lanczos_blocks(body_a, body_b, normal, k_n, k_t, s, C, 6 * x.shape[0], steps, rtol)


@njit(cache=True)
def lanczos_blocks(body_a: np.ndarray, body_b: np.ndarray, normal: np.ndarray,
                   k_n: np.ndarray, k_t: np.ndarray, s: np.ndarray, C: np.ndarray, dim: int,
                   steps: int = LANCZOS_STEPS,
                   rtol: float = LANCZOS_RTOL) -> tuple[float, np.ndarray]:
    """Largest eigenvalue and Ritz vector (dim = 6N,) of the operator of :func:`apply_blocks`.

    Lanczos with full re-orthogonalisation (one modified Gram–Schmidt pass against every
    earlier vector: in ``benchmarks/bench_estimate.py`` the same λmax errors against LAPACK as
    two classical passes, in 2/3 of the time) from a fixed start vector (deterministic), at
    most ``steps`` products, stopping early when the largest Ritz value changes by less than
    ``rtol`` over 5 steps.  The Ritz value is a lower bound of λmax that converges from below
    (to round-off within a few tens of steps here).  Vector products are loops in a fixed
    order (:func:`_dot`), not BLAS, whose threaded reductions would make the bits depend on
    the thread count."""
    if dim == 0:
        return 0.0, np.zeros(0)
    v = 1.0 + 0.5 * np.sin(np.arange(dim) * 1.2345 + 0.1)
    v /= math.sqrt(_dot(v, v))
    m = min(steps, dim)
    V = np.zeros((m, dim))
    alpha = np.zeros(m)
    beta = np.zeros(m)
    w = np.empty(dim)
    last = -1.0
    size = 0
    for k in range(m):
        size = k + 1
        V[k] = v
        apply_blocks(v, body_a, body_b, normal, k_n, k_t, s, C, w)
        alpha[k] = _dot(v, w)
        _orthogonalise(w, V[:size])                 # full re-orthogonalisation
        nb = math.sqrt(_dot(w, w))
        beta[k] = nb
        if nb <= 1e-12 * max(np.abs(alpha[:size]).max(), 1e-300):
            break
        if k % 5 == 4:
            ritz = _largest_ritz(alpha, beta, size)[0]
            if abs(ritz - last) <= rtol * ritz:
                break
            last = ritz
        v = w / nb
    lam, y = _largest_ritz(alpha, beta, size)
    vec = np.zeros(dim)
    for j in range(size):
        for i in range(dim):
            vec[i] += V[j, i] * y[j]
    return max(lam, 0.0), vec


def network_rates(body_a: np.ndarray, body_b: np.ndarray, point: np.ndarray,
                  normal: np.ndarray, coeffs: np.ndarray, x: np.ndarray, Q: np.ndarray,
                  mass: np.ndarray, I: np.ndarray, image=None) -> tuple[float, float, int]:
    """(ω² 1/s², γ 1/s, dominant body) of the contact network: λmax of Eq. (2)'s stiffness and
    damping operators, and the particle with the largest share of the stiffest mode (−1 when
    there is no contact).  coeffs (K,4): εn, cn, εt, ct of each contact; mass (N,) kg, I (N,3)
    principal inertias kg m² (:func:`network_rates_scaled` with their square roots); image
    (K,3) m: as :func:`network_blocks` (the time-step control always gives it, zeros without
    a periodic cell, as the compiled loop does: both call the same compiled kernels)."""
    extra = () if image is None else (image,)
    omega2, gamma, body = network_rates_scaled(body_a, body_b, point, normal,
                                               np.ascontiguousarray(coeffs, float), x, Q,
                                               np.sqrt(mass), np.sqrt(I), *extra)
    return float(omega2), float(gamma), int(body)


@njit(cache=True)
def network_rates_scaled(body_a: np.ndarray, body_b: np.ndarray, point: np.ndarray,
                         normal: np.ndarray, coeffs: np.ndarray, x: np.ndarray, Q: np.ndarray,
                         sq_m: np.ndarray, sq_I: np.ndarray,
                         image=None) -> tuple[float, float, int]:
    """:func:`network_rates` given sq_m (N,) = √mass (√kg) and sq_I (N,3) = √I (√(kg m²)):
    compiled, so that the deck steps' loop takes the exact estimate without returning to
    Python (:mod:`nurbsdem.dynamics.deck_steps`)."""
    N = x.shape[0]
    if body_a.shape[0] == 0 or N == 0:
        return 0.0, 0.0, -1
    kn, cn = coeffs[:, 0].copy(), coeffs[:, 1].copy()
    kt, ct = coeffs[:, 2].copy(), coeffs[:, 3].copy()
    s, C = network_blocks(body_a, body_b, point, x, Q, sq_m, sq_I, image)
    steps = np.int64(LANCZOS_STEPS)     # the types of network_lanczos' call: one compilation
    omega2, vec = lanczos_blocks(body_a, body_b, normal, kn, kt, s, C, 6 * N, steps, LANCZOS_RTOL)
    gamma = 0.0
    if cn.any() or ct.any():
        gamma = lanczos_blocks(body_a, body_b, normal, cn, ct, s, C, 6 * N, steps, LANCZOS_RTOL)[0]
    return omega2, gamma, _dominant_body(vec, N)


@njit(cache=True)
def _dominant_body(vec: np.ndarray, N: int) -> int:
    """The body with the largest share Σ vec[6i:6i+6]² of a mode vector (6N,) (the first of
    equal ones)."""
    best, body = -1.0, 0
    for i in range(N):
        share = 0.0
        for k in range(6):
            share += vec[6 * i + k] ** 2
        if share > best:
            best, body = share, i
    return body


# --------------------------------------------------------------------------- period-2 guard
def period2_amplitude(trace, last: int = 40) -> float:
    """Largest period-2 component (m) of the centroids' increments over the ``last`` internal
    steps of ``trace`` (a list of (N,3) centroid arrays, one per internal step):
    max over bodies of |mean of (−1)ⁿ (x_{n+1} − x_n)|; ≈ 0 for motion the step resolves, the
    half amplitude of the flip for period-2 motion.  A diagnostic for tests and benchmarks."""
    x = np.array(trace[-(last + 1):])
    inc = np.diff(x, axis=0)
    sign = (-1.0) ** np.arange(inc.shape[0])
    return float(np.abs(np.einsum("n,nij->ij", sign, inc)).max() / inc.shape[0])


@njit(cache=True)
def _reversed(arr: np.ndarray, prev: np.ndarray, i: int, floor: float) -> bool:
    """Whether row i of arr reverses row i of prev without decaying (prev updated to arr)."""
    dot = arr[i, 0] * prev[i, 0] + arr[i, 1] * prev[i, 1] + arr[i, 2] * prev[i, 2]
    n1 = math.sqrt(arr[i, 0] ** 2 + arr[i, 1] ** 2 + arr[i, 2] ** 2)
    n0 = math.sqrt(prev[i, 0] ** 2 + prev[i, 1] ** 2 + prev[i, 2] ** 2)
    for k in range(3):
        prev[i, k] = arr[i, k]
    return (n1 > floor and n0 > floor and dot < ALTERNATION_COS * n1 * n0
            and n1 >= ALTERNATION_RATIO * n0)


@njit(cache=True)
def alternation_update(v: np.ndarray, L: np.ndarray, prev_v: np.ndarray, prev_L: np.ndarray,
                       count: np.ndarray, floor_x: np.ndarray, floor_L: np.ndarray,
                       inv_h: float) -> int:
    """Count, per body, consecutive internal steps whose half-step velocity v (N,3) or angular
    momentum L (N,3) reversed with respect to the previous step's (prev_v, prev_L, updated in
    place) without decaying; reset on any other step or below the round-off floors:
    floor_x (N,) m of displacement and floor_L (N,) kg m² of angular momentum × step, both
    divided by the step h (inv_h = 1/h, 1/s).  Returns the body with the longest run (its count
    in ``count``), −1 when there is none."""
    worst, best = -1, 0
    for i in range(v.shape[0]):
        flip_v = _reversed(v, prev_v, i, floor_x[i] * inv_h)
        flip_L = _reversed(L, prev_L, i, floor_L[i] * inv_h)
        count[i] = count[i] + 1 if (flip_v or flip_L) else 0
        if count[i] > best:
            best, worst = count[i], i
    return worst

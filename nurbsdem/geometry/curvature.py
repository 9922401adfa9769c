"""Differential geometry at contact points, and the equivalent radius of elliptical Hertz contact.

Principal curvatures (do Carmo, ch. 3; The NURBS Book's derivatives)
--------------------------------------------------------------------
At a point S(u, v) of a patch with the derivatives S_u, S_v, S_uu, S_uv, S_vv of the compiled
kernel (:func:`nurbsdem.geometry.kernel.patch_derivs`), the first and second fundamental forms are

    I  = [[S_u·S_u, S_u·S_v], [S_u·S_v, S_v·S_v]]
    II = [[S_uu·m,  S_uv·m ], [S_uv·m,  S_vv·m ]]      m: the unit **inward** normal

and the shape operator W = I⁻¹ II has the principal curvatures κ1, κ2 (1/m) as eigenvalues,
its eigenvectors (α, β) give the principal directions α S_u + β S_v.  With the inward normal,
a convex surface has κ >= 0.  The inward normal is taken from the contact normal (outward of A,
``-n`` for B), so a patch's orientation does not matter.  The curvature tensor of the surface
in 3-D is C = κ1 t1 t1ᵀ + κ2 t2 t2ᵀ (t1, t2 unit principal directions in the tangent plane).

At a pole (collapsed edge, |S_u × S_v| -> 0) the forms are singular: the point is moved into
the patch by 1e-5 of its parameter range, where they are regular (the curvature is continuous
there on a smooth surface).  A seam or a patch connection uses the patch the LCP ended on.

Relative curvature and the equivalent radius (Johnson, *Contact Mechanics*, §4.1–4.2)
--------------------------------------------------------------------------------------
Near the contact the gap between two convex bodies is h = A x² + B y² with A <= B the
half-eigenvalues of C_A + C_B projected on the common tangent plane (the same as Johnson's
(4.2)–(4.3) with the angle between the principal directions).  The Hertz pressure
p = p0 √(1 − x²/a² − y²/b²) on an ellipse with b/a = √(1 − e²) solves it when (Johnson (3.xx),
E(e), K(e) complete elliptic integrals of modulus e, here of parameter m = e²)

    B/A = [E/(1−e²) − K] / (K − E),     a² = (K − E) δ / (e² A K),     P = 2π a E* δ / (3K).

Hence P = (4/3) E* √R_eff δ^{3/2} with the **force-equivalent radius**

    R_eff = (π / 2K)² (K − E) / (e² K A)        (-> 1/(2A) = R for a sphere, e -> 0),

a function of the curvatures only.  :func:`hertz_radius` solves the first relation for e by
regula falsi (K and E from the arithmetic–geometric mean, with K − E from the AGM's own series,
so there is no cancellation near e = 0) and returns R_eff and b/a.  Johnson's approximation
R_e = √(R'R'') F(e) is not used: the exact relation costs a few µs per contact.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from .kernel import MAX_DEGREE, _WS_ROWS, patch_derivs

#: surface kinds of one side of a contact
KIND_PATCH, KIND_SPHERE, KIND_FLAT = 0, 1, 2
#: status of a contact's equivalent radius
OK, DEGENERATED = 0, 1


@njit(cache=True)
def agm_elliptic(m: float) -> tuple[float, float]:
    """Complete elliptic integrals (K(m), K(m) − E(m)) of parameter m = e² in [0, 1)."""
    a = 1.0
    b = math.sqrt(1.0 - m)
    c2 = m                  # c_0² = m
    s = 0.5 * m             # Σ 2^(n−1) c_n², n = 0..
    w = 0.5
    for _ in range(40):
        an = 0.5 * (a + b)
        cn = 0.5 * (a - b)
        b = math.sqrt(a * b)
        a = an
        w *= 2.0
        c2 = cn * cn
        s += w * c2
        if c2 < 1e-34:
            break
    k = 0.5 * math.pi / a
    return k, k * s


@njit(cache=True)
def _log_ratio(t: float) -> float:
    """ln g(m) at b/a = e^t (m = 1 − e^{2t}): the log of B/A of the Hertz ellipse."""
    kp = math.exp(t)
    m = 1.0 - kp * kp
    k, kme = agm_elliptic(m)
    s = kme / k
    return math.log((m - s) / ((1.0 - m) * s))


@njit(cache=True)
def hertz_radius(A: float, B: float) -> tuple[float, float]:
    """Force-equivalent radius R_eff (m) and axis ratio b/a of the Hertz contact of a gap
    h = A x² + B y² (A, B in 1/m, any order).  (nan, nan) when not positive definite."""
    if A > B:
        A, B = B, A
    if not (A > 0.0) or not (B < math.inf):
        return math.nan, math.nan
    lam = B / A
    if lam < 1.0 + 1e-12:
        return 1.0 / (A + B), 1.0
    # root of f(t) = ln g(m) − ln λ in t = ln(b/a) (m = 1 − e^{2t}); g(m) = (m − S)/((1 − m) S)
    # grows with m, so f falls with t.  Illinois regula falsi in a bracket around Johnson's
    # estimate b/a ≈ (A/B)^{2/3}: about 8 evaluations to round-off.
    llam = math.log(lam)
    t0 = (2.0 / 3.0) * math.log(A / B)
    lo = t0 - 0.5
    flo = _log_ratio(lo) - llam
    while flo <= 0.0:
        lo -= 1.0
        flo = _log_ratio(lo) - llam
    hi = min(t0 + 0.5, -1e-14)
    fhi = _log_ratio(hi) - llam
    while fhi > 0.0:
        hi = min(hi + 1.0, -1e-14)
        fhi = _log_ratio(hi) - llam
    side = 0
    t = hi
    for _ in range(100):
        t = (lo * fhi - hi * flo) / (fhi - flo)
        ft = _log_ratio(t) - llam
        if ft > 0.0:
            lo, flo = t, ft
            if side == 1:
                fhi *= 0.5
            side = 1
        else:
            hi, fhi = t, ft
            if side == -1:
                flo *= 0.5
            side = -1
        if abs(ft) < 1e-15 or hi - lo < 1e-15 * (1.0 + abs(t)):
            break
    kp = math.exp(t)
    m = 1.0 - kp * kp
    k, kme = agm_elliptic(m)
    s = kme / k
    r = (0.5 * math.pi / k) ** 2 * (s / m) / A
    return r, kp


@njit(cache=True)
def _surface_tensor(d, inward, C):
    """Add the curvature tensor (3×3, 1/m) of the surface with derivatives d (6,3) (file frame)
    to C, measured against its unit normal on the side of ``inward`` (file frame).  Returns
    False if the metric is singular."""
    su0, su1, su2 = d[1, 0], d[1, 1], d[1, 2]
    sv0, sv1, sv2 = d[2, 0], d[2, 1], d[2, 2]
    E = su0 * su0 + su1 * su1 + su2 * su2
    F = su0 * sv0 + su1 * sv1 + su2 * sv2
    G = sv0 * sv0 + sv1 * sv1 + sv2 * sv2
    det = E * G - F * F
    if not (det > 1e-14 * (E + G) * (E + G)):      # a pole (a collapsed edge) or worse
        return False
    # the surface's own unit normal at the point, turned to agree with ``inward`` (the contact
    # normal: at a pole the point was moved, and the normal moved with it)
    m0 = su1 * sv2 - su2 * sv1
    m1 = su2 * sv0 - su0 * sv2
    m2 = su0 * sv1 - su1 * sv0
    mm = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
    if m0 * inward[0] + m1 * inward[1] + m2 * inward[2] < 0.0:
        mm = -mm
    m0, m1, m2 = m0 / mm, m1 / mm, m2 / mm
    L = d[3, 0] * m0 + d[3, 1] * m1 + d[3, 2] * m2
    M = d[4, 0] * m0 + d[4, 1] * m1 + d[4, 2] * m2
    N = d[5, 0] * m0 + d[5, 1] * m1 + d[5, 2] * m2
    # the curvature tensor in 3-D: C = J I⁻¹ II I⁻¹ Jᵀ with J = [S_u S_v] (3×2) (symmetric;
    # its eigenvalues in the tangent plane are the principal curvatures)
    i00, i01, i11 = G / det, -F / det, E / det
    # T = I⁻¹ II I⁻¹
    a00 = i00 * L + i01 * M
    a01 = i00 * M + i01 * N
    a10 = i01 * L + i11 * M
    a11 = i01 * M + i11 * N
    t00 = a00 * i00 + a01 * i01
    t01 = a00 * i01 + a01 * i11
    t11 = a10 * i01 + a11 * i11
    su = (su0, su1, su2)
    sv = (sv0, sv1, sv2)
    for r in range(3):
        for c in range(3):
            C[r, c] += (t00 * su[r] * su[c] + t01 * (su[r] * sv[c] + sv[r] * su[c])
                        + t11 * sv[r] * sv[c])
    return True


@njit(cache=True)
def _side_tensor(tab_deg, tab_ncp, tab_koff, tab_coff, tab_knots, tab_cpw, tab_dom,
                 ip, u, v, Rm, inward_world, ws, d, C, Cw):
    """Curvature tensor (world) of patch ip at (u, v) of a body with rotation Rm, added to Cw."""
    inward = np.empty(3)
    for r in range(3):      # file frame: Rᵀ n
        inward[r] = Rm[0, r] * inward_world[0] + Rm[1, r] * inward_world[1] + Rm[2, r] * inward_world[2]
    u0, u1, v0, v1 = tab_dom[ip, 0], tab_dom[ip, 1], tab_dom[ip, 2], tab_dom[ip, 3]
    good = False
    for attempt in range(3):
        patch_derivs(tab_deg, tab_ncp, tab_koff, tab_coff, tab_knots, tab_cpw, ip, u, v, 2, ws, d)
        C[:, :] = 0.0
        if _surface_tensor(d, inward, C):
            good = True
            break
        # a pole: move into the patch
        eps = 1e-5 * 10.0 ** (2 * attempt)
        u = u + eps * (0.5 * (u0 + u1) - u)
        v = v + eps * (0.5 * (v0 + v1) - v)
    if not good:
        return False
    # world: R C Rᵀ
    for r in range(3):
        for c in range(3):
            acc = 0.0
            for i in range(3):
                for j in range(3):
                    acc += Rm[r, i] * C[i, j] * Rm[c, j]
            Cw[r, c] += acc
    return True


@njit(cache=True)
def _one_radius(tab_deg, tab_ncp, tab_koff, tab_coff, tab_knots, tab_cpw, tab_dom, ka, kb, pa, pb,
                ua, va, ub, vb, rot_a, rot_b, sa, sb, n0, n1, n2, ws, d, C, Cw, nin):
    """One contact of :func:`contact_radii`: (R_eff, b/a, A, B, ok)."""
    Cw[:, :] = 0.0
    for side in range(2):
        kind = ka if side == 0 else kb
        sg = -1.0 if side == 0 else 1.0      # inward normal of A is -n, of B is +n
        if kind == KIND_FLAT:
            continue
        if kind == KIND_SPHERE:
            k = 1.0 / (sa if side == 0 else sb)
            nn = (n0, n1, n2)
            for r in range(3):
                for q in range(3):
                    Cw[r, q] += k * ((1.0 if r == q else 0.0) - nn[r] * nn[q])
            continue
        nin[0], nin[1], nin[2] = sg * n0, sg * n1, sg * n2
        if side == 0:
            ok = _side_tensor(tab_deg, tab_ncp, tab_koff, tab_coff, tab_knots, tab_cpw, tab_dom,
                              pa, ua, va, rot_a, nin, ws, d, C, Cw)
        else:
            ok = _side_tensor(tab_deg, tab_ncp, tab_koff, tab_coff, tab_knots, tab_cpw, tab_dom,
                              pb, ub, vb, rot_b, nin, ws, d, C, Cw)
        if not ok:
            return math.nan, 1.0, math.nan, math.nan, False
    # tangent basis e, f of n; the 2×2 projection of Cw and its eigenvalues
    if abs(n0) < 0.9:
        e0, e1_, e2 = 0.0, -n2, n1
    else:
        e0, e1_, e2 = n2, 0.0, -n0
    en = math.sqrt(e0 * e0 + e1_ * e1_ + e2 * e2)
    e0, e1_, e2 = e0 / en, e1_ / en, e2 / en
    f0, f1, f2 = n1 * e2 - n2 * e1_, n2 * e0 - n0 * e2, n0 * e1_ - n1 * e0
    ev = (e0, e1_, e2)
    fv = (f0, f1, f2)
    p00 = 0.0
    p01 = 0.0
    p11 = 0.0
    for r in range(3):
        for q in range(3):
            p00 += ev[r] * Cw[r, q] * ev[q]
            p01 += ev[r] * Cw[r, q] * fv[q]
            p11 += fv[r] * Cw[r, q] * fv[q]
    tr = 0.5 * (p00 + p11)
    dis = math.sqrt(0.25 * (p00 - p11) ** 2 + p01 * p01)
    A = 0.5 * (tr - dis)
    B = 0.5 * (tr + dis)
    r, q = hertz_radius(A, B)
    # a flat or ruled contact (A -> 0, a line contact): Hertz does not apply
    return r, q, A, B, bool(math.isfinite(r) and A > 1e-9 * B)


@njit(cache=True)
def contact_radii(tab_deg, tab_ncp, tab_koff, tab_coff, tab_knots, tab_cpw, tab_dom,
                  kind_a, kind_b, patch_a, patch_b, params, rot_a, rot_b, sphere_a, sphere_b,
                  normal, fallback, r_eff, axis_ratio, curv, status):
    """Force-equivalent Hertz radius of K contacts (module docstring).

    kind_a/kind_b (K,) :data:`KIND_PATCH` | :data:`KIND_SPHERE` | :data:`KIND_FLAT`;
    patch_a/patch_b (K,) global patch index in the pool ``tab_*`` (KIND_PATCH);
    params (K,4) (uA, vA, uB, vB); rot_a/rot_b (K,3,3) file->world rotations; sphere_a/_b (K,)
    radii (KIND_SPHERE); normal (K,3) unit, from A towards B; fallback (K,) radius used where the
    curvature is degenerate (status DEGENERATED; the caller also passes the LCP's degenerated
    contacts as ``status`` 1 on input).  Outputs r_eff (K,) m, axis_ratio (K,) b/a, curv (K,2)
    A, B (1/m), status (K,) 0 | 1.
    """
    K = kind_a.shape[0]
    ws = np.zeros((_WS_ROWS, MAX_DEGREE + 1))
    d = np.zeros((6, 3))
    C = np.zeros((3, 3))
    Cw = np.zeros((3, 3))
    nin = np.empty(3)
    for c in range(K):
        curv[c, 0] = math.nan
        curv[c, 1] = math.nan
        if status[c] == OK:
            r, q, A, B, ok = _one_radius(
                tab_deg, tab_ncp, tab_koff, tab_coff, tab_knots, tab_cpw, tab_dom, kind_a[c],
                kind_b[c], patch_a[c], patch_b[c], params[c, 0], params[c, 1], params[c, 2],
                params[c, 3], rot_a[c], rot_b[c], sphere_a[c], sphere_b[c], normal[c, 0],
                normal[c, 1], normal[c, 2], ws, d, C, Cw, nin)
            curv[c, 0] = A
            curv[c, 1] = B
            if ok:
                r_eff[c] = r
                axis_ratio[c] = q
                continue
        status[c] = DEGENERATED
        r_eff[c] = fallback[c]
        axis_ratio[c] = 1.0


@njit(cache=True)
def scene_contact_radii(tab_deg, tab_ncp, tab_koff, tab_coff, tab_knots, tab_cpw, tab_dom,
                        first_patch, body_shape, sphere_radius, bound_radius, R, body_a, body_b,
                        patch_a, patch_b, params, normal, degenerated, r_eff):
    """:func:`contact_radii` for the contacts of a scene in one compiled call (what
    the scene needs): bodies b >= N are flat walls, patch −1 a closed-form sphere
    (radius ``sphere_radius[shape]``); fallback r_A r_B/(r_A + r_B) (r_A on a wall) of the
    bounding radii.  Writes r_eff (K,); returns the number of fallbacks."""
    K = body_a.shape[0]
    N = body_shape.shape[0]
    ws = np.zeros((_WS_ROWS, MAX_DEGREE + 1))
    d = np.zeros((6, 3))
    C = np.zeros((3, 3))
    Cw = np.zeros((3, 3))
    nin = np.empty(3)
    eye = np.eye(3)
    n_fall = 0
    for c in range(K):
        a = body_a[c]
        b = body_b[c]
        sa = body_shape[a]
        wall = b >= N
        ka = KIND_PATCH if patch_a[c] >= 0 else KIND_SPHERE
        ga = first_patch[sa] + patch_a[c] if ka == KIND_PATCH else 0
        if wall:
            kb = KIND_FLAT
            gb = 0
            srb = 1.0
            fall = bound_radius[a]
            rot_b = eye
        else:
            sb = body_shape[b]
            kb = KIND_PATCH if patch_b[c] >= 0 else KIND_SPHERE
            gb = first_patch[sb] + patch_b[c] if kb == KIND_PATCH else 0
            srb = sphere_radius[sb]
            fall = bound_radius[a] * bound_radius[b] / (bound_radius[a] + bound_radius[b])
            rot_b = R[b]
        ok = False
        if degenerated[c] == 0:
            r, q, A, B, ok = _one_radius(
                tab_deg, tab_ncp, tab_koff, tab_coff, tab_knots, tab_cpw, tab_dom, ka, kb, ga,
                gb, params[c, 0], params[c, 1], params[c, 2], params[c, 3], R[a], rot_b,
                sphere_radius[sa], srb, normal[c, 0], normal[c, 1], normal[c, 2], ws, d, C, Cw,
                nin)
        if ok:
            r_eff[c] = r
        else:
            r_eff[c] = fall
            n_fall += 1
    return n_fall


def principal_curvatures(patch, u: float, v: float, inward: np.ndarray | None = None
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Principal curvatures (2,) (1/m, ascending) and unit principal directions (2,3) of a
    :class:`~nurbsdem.geometry.nurbs.Patch` at (u, v), with the vectorised kernel (tests and
    reports).  ``inward``: the normal the curvatures are measured against (default
    −S_u × S_v normalised, i.e. the inward normal of an outward-oriented patch)."""
    d = np.asarray(patch.evaluate(np.array([u]), np.array([v]), order=2), float).reshape(6, 3)
    nrm = np.cross(d[1], d[2])
    nrm /= np.linalg.norm(nrm)
    m = -nrm if inward is None else np.asarray(inward, float) / np.linalg.norm(inward)
    I = np.array([[d[1] @ d[1], d[1] @ d[2]], [d[1] @ d[2], d[2] @ d[2]]])
    II = np.array([[d[3] @ m, d[4] @ m], [d[4] @ m, d[5] @ m]])
    w, vec = np.linalg.eig(np.linalg.solve(I, II))
    order = np.argsort(w.real)
    dirs = (np.column_stack([d[1], d[2]]) @ vec.real[:, order]).T
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    return w.real[order], dirs


def equivalent_radii(table, rows_a_shape: np.ndarray, kind_a, kind_b, patch_a, patch_b, params,
                     rot_a, rot_b, sphere_a, sphere_b, normal, fallback, degenerated
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Python front of :func:`contact_radii` over a :class:`~nurbsdem.contact.detect.ContactTable`:
    patch_a/patch_b are **local** patch indices of the shapes ``rows_a_shape`` (K,2) (shape of
    A, shape of B; -1 where not a patch).  Returns r_eff, axis_ratio, curv (K,2), status."""
    K = kind_a.shape[0]
    deg, ncp, koff, coff, knots, cpw, dom = table.tab[:7]
    first = table.info[:, 0]
    ga = np.where(kind_a == KIND_PATCH, first[np.maximum(rows_a_shape[:, 0], 0)] + patch_a, 0)
    gb = np.where(kind_b == KIND_PATCH, first[np.maximum(rows_a_shape[:, 1], 0)] + patch_b, 0)
    r_eff, ratio = np.empty(K), np.empty(K)
    curv = np.empty((K, 2))
    status = (np.asarray(degenerated) != 0).astype(np.int64)
    contact_radii(deg, ncp, koff, coff, knots, cpw, dom, np.ascontiguousarray(kind_a, np.int64),
                  np.ascontiguousarray(kind_b, np.int64), np.ascontiguousarray(ga, np.int64),
                  np.ascontiguousarray(gb, np.int64), np.ascontiguousarray(params, float),
                  np.ascontiguousarray(rot_a, float), np.ascontiguousarray(rot_b, float),
                  np.ascontiguousarray(sphere_a, float), np.ascontiguousarray(sphere_b, float),
                  np.ascontiguousarray(normal, float), np.ascontiguousarray(fallback, float),
                  r_eff, ratio, curv, status)
    return r_eff, ratio, curv, status


def contact_radii_for(provider, cs, bodies, K: int) -> tuple[np.ndarray, int]:
    """Equivalent Hertz radius (K,) of each contact of ``cs`` and the number that fell back to
    the bounding-sphere radius: a ContactSet with its own ``radius`` (test providers) gives it;
    a :class:`~nurbsdem.contact.scene.SceneContacts` provider the exact curvature
    (:func:`scene_contact_radii`; its ContactSet carries ``params``, ``patch_a``, ``patch_b``);
    any other provider the bounding-sphere radii (all counted)."""
    if K == 0:
        return np.zeros(0), 0
    own = getattr(cs, "radius", None)
    if own is not None:
        return np.ascontiguousarray(own, float), 0
    N = bodies.n
    if hasattr(provider, "body_shape") and hasattr(provider, "table"):
        deg, ncp, koff, coff, knots, cpw, dom = provider.table.tab[:7]
        r = np.empty(K)
        k = min(K, np.asarray(cs.params).shape[0])
        n_fall = scene_contact_radii(
            deg, ncp, koff, coff, knots, cpw, dom, np.ascontiguousarray(provider.table.info[:, 0]),
            provider.body_shape, provider.sphere_radius, provider.radius, bodies.rotations(),
            np.asarray(cs.body_a, np.int64), np.asarray(cs.body_b, np.int64),
            np.asarray(cs.patch_a, np.int64), np.asarray(cs.patch_b, np.int64),
            np.ascontiguousarray(cs.params, float), np.ascontiguousarray(cs.normal, float),
            np.asarray(cs.degenerated, np.int64), r) if k == K else None
        if n_fall is None:
            raise ValueError("the ContactSet lacks params/patch_a/patch_b for the Hertz curvature")
        return r, int(n_fall)
    a = np.asarray(cs.body_a, np.int64)
    b = np.asarray(cs.body_b, np.int64)
    ra = bodies.radius[a]
    rb = np.where(b >= N, np.inf, bodies.radius[np.minimum(b, N - 1)])
    return np.where(b >= N, ra, ra * rb / (ra + np.where(b >= N, 1.0, rb))), K

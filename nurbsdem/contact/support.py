"""Support mapping of a convex multi-patch NURBS body (paper Eq. 8–9, Sec. 3.2.2–3.2.3).

For a unit direction ``e`` (body file frame) the support point is the point of the closed
surface that maximises ``e · s(u, v)`` (paper Eq. 8–9, ``f_sup = e · Γ(ζ, θ)``). It is found
by a trust-region Newton method (the step of :mod:`.trust_region`) on one patch at a time
with the exact 2×2 Hessian
``H = [[e·s_uu, e·s_uv], [e·s_uv, e·s_vv]]`` (bound-constrained to the parameter rectangle):

* **patch migration** (paper 3.2.2): a parameter that reaches its bound with the gradient
  pointing out of the rectangle is clamped and the point is mapped to the neighbour patch
  through the connectivity ``nbr[i, e] = (j, f, rev)``. When both parameters are out, the
  ζ (u) neighbour is tried first, then θ (v). The move is taken only when ``e · s`` keeps
  increasing into the neighbour (its inward derivative is positive);
* **degeneration** (paper 3.2.3, Eq. 10–15): when the neighbour's inward derivative points
  back (a C0 crease between patches) — or after too many migrations (cycling) — the
  parameter across the edge is *fixed* at its bound; the Newton step then acts on the
  free parameters only (``P_sᵀ ∇f``, ``P_sᵀ H P_s``, Eq. 12–13): a search along the edge curve
  (one fixed parameter) or nothing at a 3-patch node (two fixed). The number of fixed
  parameters is the body's degeneration level;
* **poles** (an edge collapsed to a point, ``j = -2``): at the pole ``e · s`` does not depend
  on the along-edge parameter, so the best meridian is chosen by sampling the inward
  derivative along the collapsed edge; when none increases ``e · s`` the pole is the support
  point. **Seams** (``j = i``) are ordinary migrations onto the same patch.

At the solution the kernel also returns the derivative of the support point with respect to
the direction (implicit differentiation of the stationarity condition ``Jᵀ e = 0``, the
paper's ``A x = b``, reduced by ``P_s`` as in Eq. 14–15):

    dp/de = M = J_F (−H_F)^(-1) J_Fᵀ      (3×3, metres; the Hessian of the support function)
    du/de = G = (−H_F)^(-1) J_Fᵀ          (2×3, parameter per unit direction)

with ``J_F`` the tangent columns of the free parameters. ``G`` predicts the parameters for
the next direction (warm start of the next support mapping).

Units: lengths in metres, parameters dimensionless. All functions are numba
compiled by :func:`nurbsdem.jit.kernel`; the table ``tab`` is the tuple
``(deg, ncp, koff, coff, knots, cpw, dom, nbr, pw, poff)`` of a packed pool (global patch
indices; :class:`nurbsdem.contact.detect.ContactTable`), evaluated in its power form
(patches with a pole by A2.3).
"""
from __future__ import annotations

import math

import numpy as np

from ..geometry.connectivity import edge_uv_nb, map_to_neighbour_nb
from ..geometry.kernel import patch_derivs, power_derivs
from ..jit import kernel
from .trust_region import sym2_eig, tr_step1, tr_step2

#: Parameter status codes.
FREE = 0
CREASE = 1      # fixed by degeneration (counts in the degeneration level)
POLE_FIX = 2    # at a pole: the across-edge parameter sits on the collapsed edge
OPEN_FIX = 3    # at an open edge (single open patch)

#: Newton iterations of one support mapping, patch migrations per mapping.
MAX_SUPPORT_IT = 60
MAX_MIGRATIONS = 8
#: Cosine below which a directional derivative counts as zero.
COS_TOL = 1e-13
#: Largest radius of curvature (relative to the body scale) used in dp/de (flat regions).
MAX_CURVATURE_RADIUS = 1e6
#: Samples along a collapsed edge when looking for the meridian out of a pole.
POLE_SAMPLES = 16
#: Newton steps shorter than this (relative to the parameter range) are taken without a new
#: evaluation (second-order Taylor update; the remaining error is ~ step^2).
TAYLOR_STEP = 1e-6


@kernel
def evaluate(tab, ip, u, v, order, ws, out):
    """Point and derivatives of patch ``ip`` of the table at (u, v) into ``out`` (6, 3), from
    the patches' power form (:func:`nurbsdem.geometry.kernel.power_derivs`), or by A2.3
    (:func:`~nurbsdem.geometry.kernel.patch_derivs`, workspace ``ws``) for a patch with a
    pole (``poff`` -1)."""
    if tab[9][ip] < 0:
        patch_derivs(tab[0], tab[1], tab[2], tab[3], tab[4], tab[5], ip, u, v, order, ws, out)
    else:
        power_derivs(tab[0], tab[1], tab[2], tab[4], tab[8], tab[9], ip, u, v, order, out)


@kernel
def dot3(a, b):
    """a · b for 3-vectors."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@kernel(inline="always")
def rt_times(R, x0, x1, x2):
    """Rᵀ x for the rotation R (body to world) and the world vector (x0, x1, x2): its file
    (body) frame components."""
    return (R[0, 0] * x0 + R[1, 0] * x1 + R[2, 0] * x2,
            R[0, 1] * x0 + R[1, 1] * x1 + R[2, 1] * x2,
            R[0, 2] * x0 + R[1, 2] * x1 + R[2, 2] * x2)


@kernel
def norm3(a):
    """|a| for a 3-vector."""
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


# --------------------------------------------------------------------------- edges
@kernel
def edge_param(dom, ip, edge, u, v):
    """Edge parameter s in [0, 1] of (u, v) on edge ``edge`` of patch ip (docs/conventions.md)."""
    if edge < 2:
        w = dom[ip, 3] - dom[ip, 2]
        return (v - dom[ip, 2]) / w if w > 0.0 else 0.0
    w = dom[ip, 1] - dom[ip, 0]
    return (u - dom[ip, 0]) / w if w > 0.0 else 0.0


@kernel
def inward_derivative(ev, edge, out):
    """Derivative pointing into the patch across edge ``edge`` (from an order >= 1 ``ev``)."""
    k = 1 if edge < 2 else 2
    sg = 1.0 if edge % 2 == 0 else -1.0
    for c in range(3):
        out[c] = sg * ev[k, c]


@kernel
def try_migrate(tab, ip, u, v, edge, e, ws, ev2, tmp):
    """Patch change across edge ``edge`` of patch ip at (u, v) (paper 3.2.2).

    Returns (code, j, uj, vj): code 0 = move to patch j at (uj, vj); 1 = crease (the
    neighbour's inward derivative does not increase e·s: fix the parameter); 2 = pole;
    3 = open edge.
    """
    nbr = tab[7]
    dom = tab[6]
    j = nbr[ip, edge, 0]
    if j == -1:
        return 3, ip, u, v
    if j == -2:
        return 2, ip, u, v
    s = edge_param(dom, ip, edge, u, v)
    j, uj, vj = map_to_neighbour_nb(nbr, dom, ip, edge, s)
    f = nbr[ip, edge, 1]
    evaluate(tab, j, uj, vj, 1, ws, ev2)
    inward_derivative(ev2, f, tmp)
    gin = dot3(e, tmp)
    if gin > COS_TOL * norm3(tmp):
        return 0, j, uj, vj
    return 1, ip, u, v


@kernel
def pole_escape(tab, ip, u, v, edge, e, ws, ev2, tmp):
    """At a pole (edge ``edge`` of patch ip collapsed to a point): the meridian along which
    ``e · s`` increases fastest. Returns (moved, u, v): moved = False means the pole is the
    support point."""
    dom = tab[6]
    best = -1e300
    bt = 0.0
    for k in range(POLE_SAMPLES + 1):
        t = (k + 0.5) / POLE_SAMPLES if k < POLE_SAMPLES else edge_param(dom, ip, edge, u, v)
        uu, vv = edge_uv_nb(dom, ip, edge, t)
        evaluate(tab, ip, uu, vv, 1, ws, ev2)
        inward_derivative(ev2, edge, tmp)
        nt = norm3(tmp)
        if nt > 0.0:
            g = dot3(e, tmp) / nt
            if g > best:
                best = g
                bt = t
    if best <= COS_TOL:
        return False, u, v
    uu, vv = edge_uv_nb(dom, ip, edge, bt)
    evaluate(tab, ip, uu, vv, 2, ws, ev2)
    inward_derivative(ev2, edge, tmp)
    g = dot3(e, tmp)
    k2 = 3 if edge < 2 else 5
    h = dot3(e, ev2[k2])
    w = (dom[ip, 1] - dom[ip, 0]) if edge < 2 else (dom[ip, 3] - dom[ip, 2])
    step = g / (-h) if h < 0.0 else 0.25 * w
    step = min(max(step, 1e-9 * w), 0.25 * w)
    if edge == 0:
        return True, uu + step, vv
    if edge == 1:
        return True, uu - step, vv
    if edge == 2:
        return True, uu, vv + step
    return True, uu, vv - step


# --------------------------------------------------------------------------- support map
@kernel
def support_derivatives(tab, ip, u, v, e, fixu, fixv, scale, ws, ev, ev2, out_M, out_G):
    """dp/de (``out_M``, 3×3) and du/de (``out_G``, 2×3) at a support point (module doc).

    ``ev`` holds the order-2 derivatives at (u, v). Fixed parameters (creases, Eq. 14–15)
    drop out. At a pole the parametrisation is singular, so the derivatives are taken at a
    point nudged off the pole along the current meridian (the shape operator is continuous).
    """
    dom = tab[6]
    src = ev
    fu = fixu == FREE
    fv = fixv == FREE
    if fixu == POLE_FIX or fixv == POLE_FIX:
        uu = u
        vv = v
        if fixu == POLE_FIX:
            w = dom[ip, 1] - dom[ip, 0]
            uu = u + 1e-6 * w if u <= dom[ip, 0] else u - 1e-6 * w
        if fixv == POLE_FIX:
            w = dom[ip, 3] - dom[ip, 2]
            vv = v + 1e-6 * w if v <= dom[ip, 2] else v - 1e-6 * w
        evaluate(tab, ip, uu, vv, 2, ws, ev2)
        src = ev2
        fu = fixu != CREASE and fixu != OPEN_FIX
        fv = fixv != CREASE and fixv != OPEN_FIX
    for a in range(3):
        for b in range(3):
            out_M[a, b] = 0.0
        out_G[0, a] = 0.0
        out_G[1, a] = 0.0
    rmax = MAX_CURVATURE_RADIUS * scale
    if fu and fv:
        b11 = -dot3(e, src[3])
        b12 = -dot3(e, src[4])
        b22 = -dot3(e, src[5])
        l1, l2, c, s = sym2_eig(b11, b12, b22)
        # curvature floor per eigen-direction q: radius |J q|^2 / l <= rmax (invariant under
        # reparametrisation; near a pole one tangent is tiny and a global floor would swamp it)
        j1 = 0.0
        j2 = 0.0
        for a in range(3):
            t1 = -s * src[1, a] + c * src[2, a]
            t2 = c * src[1, a] + s * src[2, a]
            j1 += t1 * t1
            j2 += t2 * t2
        fl1 = j1 / rmax + 1e-300
        fl2 = j2 / rmax + 1e-300
        if l1 < fl1:
            l1 = fl1
        if l2 < fl2:
            l2 = fl2
        # B^-1 = q1 q1^T / l1 + q2 q2^T / l2, q1 = (-s, c), q2 = (c, s)
        i11 = s * s / l1 + c * c / l2
        i12 = -s * c / l1 + c * s / l2
        i22 = c * c / l1 + s * s / l2
        for a in range(3):
            out_G[0, a] = i11 * src[1, a] + i12 * src[2, a]
            out_G[1, a] = i12 * src[1, a] + i22 * src[2, a]
        for a in range(3):
            for b in range(3):
                out_M[a, b] = src[1, a] * out_G[0, b] + src[2, a] * out_G[1, b]
    elif fu or fv:
        k = 1 if fu else 2
        kk = 3 if fu else 5
        row = 0 if fu else 1
        b = -dot3(e, src[kk])
        jj = dot3(src[k], src[k])
        floor = jj / rmax
        if b < floor:
            b = floor
        for a in range(3):
            out_G[row, a] = src[k, a] / b
        for a in range(3):
            for c2 in range(3):
                out_M[a, c2] = src[k, a] * out_G[row, c2]


#: what the Newton part of an iteration of :func:`support_map` leads to: a step snapped
#: onto a bound (the next iteration sees the edge), the final point, or a trial point
_SNAP, _FINISH, _TRIAL = 0, 1, 2


@kernel(inline="always")
def _start_point(tab, ip, fst, ws, ev):
    """The start of :func:`support_map`: (u, v) clamped to patch ``ip``'s rectangle, the trust
    radius (fst[2]; a quarter of the patch's width by default, at least 5 % of it) and the
    point evaluated into ev.  Returns (u, v, the patch's width, the trust radius)."""
    dom = tab[6]
    u = min(max(fst[0], dom[ip, 0]), dom[ip, 1])
    v = min(max(fst[1], dom[ip, 2]), dom[ip, 3])
    width = max(dom[ip, 1] - dom[ip, 0], dom[ip, 3] - dom[ip, 2])
    delta = fst[2]
    if not delta > 0.0:
        delta = 0.25 * width
    elif delta < 0.05 * width:
        delta = 0.05 * width
    evaluate(tab, ip, u, v, 2, ws, ev)
    return u, v, width, delta


@kernel(inline="always")
def _escape(tab, ip, pu, pv, edge, e, u, v, ws, ev2, tmp):
    """A pole escape (:func:`pole_escape`) from (pu, pv) on the collapsed edge ``edge`` of
    patch ip.  Returns (moved, u, v, evaluations): the meridian's point, or (u, v) as given
    when the pole is the support point."""
    ok, uu, vv = pole_escape(tab, ip, pu, pv, edge, e, ws, ev2, tmp)
    if ok:
        u = uu
        v = vv
    return ok, u, v, POLE_SAMPLES + 2


@kernel(inline="always")
def _boundary(tab, ip, u, v, e, out_u, out_v, fixu, fixv, nmig, npole, ws, ev2, tmp):
    """At a rectangle's edge with the gradient pointing out (``out_u``, ``out_v``): the u
    (zeta) neighbour first, then v (theta): migrate to the neighbour patch, escape a pole, or
    fix the parameter (crease, pole, open edge; paper 3.2.2, 3.2.3).  Returns (moved, patch,
    u, v, fixu, fixv, migrations, pole escapes, evaluations)."""
    dom = tab[6]
    nev = 0
    moved = False
    for k in range(2):
        if k == 0 and not (out_u and fixu == FREE):
            continue
        if k == 1 and not (out_v and fixv == FREE):
            continue
        if k == 0:
            edge = 0 if u <= dom[ip, 0] else 1
        else:
            edge = 2 if v <= dom[ip, 2] else 3
        code, j, uj, vj = try_migrate(tab, ip, u, v, edge, e, ws, ev2, tmp)
        nev += 1 if code == 0 or code == 1 else 0
        if code == 0 and nmig < MAX_MIGRATIONS:
            nmig += 1
            ip = j
            u = uj
            v = vj
            moved = True
            break
        if code == 2:
            if npole < 3:
                npole += 1
                moved, u, v, n = _escape(tab, ip, u, v, edge, e, u, v, ws, ev2, tmp)
                nev += n
                if moved:
                    break
            fx = POLE_FIX
        elif code == 3:
            fx = OPEN_FIX
        else:
            fx = CREASE
        if k == 0:
            fixu = fx
        else:
            fixv = fx
    return moved, ip, u, v, fixu, fixv, nmig, npole, nev


@kernel(inline="always")
def _pole_restart(tab, ip, u, v, e, npole, ws, ev2, tmp):
    """Near a pole the (u, v) parametrisation is singular and Newton is slow: a restart from
    the pole along the best meridian.  Returns (moved, u, v, pole escapes, evaluations)."""
    dom = tab[6]
    moved = False
    nev = 0
    for edge in range(4):
        if tab[7][ip, edge, 0] != -2:
            continue
        lo = dom[ip, 0] if edge == 0 else dom[ip, 1]
        w = dom[ip, 1] - dom[ip, 0]
        pv = u
        if edge >= 2:
            lo = dom[ip, 2] if edge == 2 else dom[ip, 3]
            w = dom[ip, 3] - dom[ip, 2]
            pv = v
        if abs(pv - lo) < 0.02 * w:
            npole += 1
            pu, pv = (lo, v) if edge < 2 else (u, lo)
            moved, u, v, n = _escape(tab, ip, pu, pv, edge, e, u, v, ws, ev2, tmp)
            nev += n
            break
    return moved, u, v, npole, nev


@kernel(inline="always")
def _newton_step(tab, ip, u, v, e, gu, gv, fixu, fixv, delta, width, xtol, f, ev, ev2):
    """The trust-region Newton step on the free parameters (reduced by P_s, Eq. 12-13),
    clamped to the rectangle.  Returns (_SNAP, _FINISH or _TRIAL, u, v, the step's end un,
    vn, its parts xu, xv and length xn (parameter units), f): a tiny step cut by a bound
    snaps onto it; a step below xtol (m), none (both parameters fixed) or one in the
    quadratic-convergence region (taken by a second-order Taylor update of the point, without
    a new evaluation) finishes."""
    dom = tab[6]
    u0, u1, v0, v1 = dom[ip, 0], dom[ip, 1], dom[ip, 2], dom[ip, 3]
    hu = dot3(e, ev[3])
    huv = dot3(e, ev[4])
    hv = dot3(e, ev[5])
    xu = 0.0
    xv = 0.0
    if fixu == FREE and fixv == FREE:
        xu, xv, _ = tr_step2(-hu, -huv, -hv, -gu, -gv, delta, ev2)  # ev2: free here
    elif fixu == FREE:
        xu, _ = tr_step1(-hu, -gu, delta)
    elif fixv == FREE:
        xv, _ = tr_step1(-hv, -gv, delta)
    else:
        return _FINISH, u, v, u, v, 0.0, 0.0, 0.0, f
    un = min(max(u + xu, u0), u1)
    vn = min(max(v + xv, v0), v1)
    clamped = un != u + xu or vn != v + xv
    xu = un - u
    xv = vn - v
    lx = 0.0
    for c in range(3):
        t = ev[1, c] * xu + ev[2, c] * xv
        lx += t * t
    xn = math.sqrt(xu * xu + xv * xv)
    if math.sqrt(lx) <= xtol and clamped:
        # a tiny step cut by the bound: snap onto the bound (no new evaluation) so that the
        # next iteration sees the edge (migration / degeneration)
        return _SNAP, un, vn, un, vn, xu, xv, xn, f
    if math.sqrt(lx) <= xtol:
        return _FINISH, u, v, un, vn, xu, xv, xn, f
    if (xn <= TAYLOR_STEP * width and xn < 0.99 * delta and not clamped
            and hu * hv - huv * huv > 0.0 and hu < 0.0):
        # quadratic-convergence region: the Newton step leaves an error ~|x|^2; take it
        # without re-evaluating (second-order Taylor for the point)
        for c in range(3):
            ev[0, c] += (ev[1, c] * xu + ev[2, c] * xv
                         + 0.5 * (ev[3, c] * xu * xu + 2.0 * ev[4, c] * xu * xv
                                  + ev[5, c] * xv * xv))
        return _FINISH, un, vn, un, vn, xu, xv, xn, dot3(e, ev[0])
    return _TRIAL, u, v, un, vn, xu, xv, xn, f


@kernel(inline="always")
def _retest_crease(tab, ip, u, v, e, fixu, fixv, ws, ev2, tmp):
    """A parameter fixed at a crease, tested again at the final point (the crease decision
    was taken where the point first reached the edge): the migration's (code, patch, u, v)
    (code 0: migrate) and the evaluations."""
    dom = tab[6]
    if fixu == CREASE:
        edge = 0 if u <= dom[ip, 0] else 1
        code, j, uj, vj = try_migrate(tab, ip, u, v, edge, e, ws, ev2, tmp)
        nev = 1
        if code != 0 and fixv == CREASE:
            edge = 2 if v <= dom[ip, 2] else 3
            code, j, uj, vj = try_migrate(tab, ip, u, v, edge, e, ws, ev2, tmp)
            nev += 1
        return code, j, uj, vj, nev
    edge = 2 if v <= dom[ip, 2] else 3
    code, j, uj, vj = try_migrate(tab, ip, u, v, edge, e, ws, ev2, tmp)
    return code, j, uj, vj, 1


@kernel(inline="always")
def _trial(tab, ip, e, u, v, un, vn, xu, xv, xn, gu, gv, f, delta, scale, ws, ev, ev2):
    """The trial point (un, vn) accepted or not on its ratio of actual to predicted ascent,
    the trust radius updated.  Returns (u, v, f, delta, stop: no improvement is possible
    within rounding, not converged)."""
    dom = tab[6]
    hu = dot3(e, ev[3])
    huv = dot3(e, ev[4])
    hv = dot3(e, ev[5])
    pred = gu * xu + gv * xv + 0.5 * (hu * xu * xu + 2.0 * huv * xu * xv + hv * xv * xv)
    evaluate(tab, ip, un, vn, 2, ws, ev2)
    fn = dot3(e, ev2[0])
    actual = fn - f
    noise = 1e-15 * scale
    if pred > noise:
        rho = actual / pred
    else:
        rho = 1.0 if actual >= -4.0 * noise else -1.0
    if rho > 0.1:
        u = un
        v = vn
        f = fn
        for a in range(6):
            for c in range(3):
                ev[a, c] = ev2[a, c]
        if rho > 0.75 and xn >= 0.9 * delta:
            delta = 2.0 * delta
    stop = False
    if rho < 0.25:
        delta = 0.25 * xn
        stop = delta < 1e-14 * max(dom[ip, 1] - dom[ip, 0], dom[ip, 3] - dom[ip, 2])
    return u, v, f, delta, stop


@kernel
def support_map(tab, e, ist, fst, scale, ws, ev, ev2, tmp, out_p, out_M, out_G):
    """Support point of a closed multi-patch body along the unit direction ``e`` (file frame).

    Parameters
    ----------
    tab: packed table (module docstring).
    e: (3,) unit direction, file frame.
    ist: int64 (4,) state in/out: (patch (global index), fix_u, fix_v, migrations).
    fst: float (3,) state in/out: (u, v, trust radius in parameter units; <= 0: default).
    scale: body length scale (m), for tolerances.
    ws, ev, ev2, tmp: workspaces (kernel workspace, (6, 3), (6, 3), (3,)).
    out_p: (3,) support point (file frame, m); out_M (3, 3) dp/de; out_G (2, 3) du/de.

    Returns (converged, evaluations). Never raises; the state always holds the best point.
    """
    dom = tab[6]
    ip = ist[0]
    u, v, width, delta = _start_point(tab, ip, fst, ws, ev)
    fixu = np.int64(FREE)       # not literals: one specialisation of support_derivatives
    fixv = np.int64(FREE)
    nmig = 0
    npole = 0
    nretest = 0
    nev = 1
    f = dot3(e, ev[0])
    xtol = 1e-13 * scale
    converged = False
    for it in range(MAX_SUPPORT_IT):
        gu = dot3(e, ev[1])
        gv = dot3(e, ev[2])
        # zero thresholds relative to the longer tangent (at a pole one tangent vanishes)
        tu = COS_TOL * max(norm3(ev[1]), norm3(ev[2]))
        out_u = (u <= dom[ip, 0] and gu < -tu) or (u >= dom[ip, 1] and gu > tu)
        out_v = (v <= dom[ip, 2] and gv < -tu) or (v >= dom[ip, 3] and gv > tu)
        if not out_u:
            fixu = FREE
        if not out_v:
            fixv = FREE
        moved, ip, u, v, fixu, fixv, nmig, npole, ne = _boundary(
            tab, ip, u, v, e, out_u, out_v, fixu, fixv, nmig, npole, ws, ev2, tmp)
        nev += ne
        if moved:
            fixu = FREE
            fixv = FREE
            evaluate(tab, ip, u, v, 2, ws, ev)
            nev += 1
            f = dot3(e, ev[0])
            delta = max(delta, 0.05 * max(dom[ip, 1] - dom[ip, 0], dom[ip, 3] - dom[ip, 2]))
            continue
        if it == 8 and npole < 3:
            moved, u, v, npole, ne = _pole_restart(tab, ip, u, v, e, npole, ws, ev2, tmp)
            nev += ne
            if moved:
                evaluate(tab, ip, u, v, 2, ws, ev)
                nev += 1
                f = dot3(e, ev[0])
                continue
        step, u, v, un, vn, xu, xv, xn, f = _newton_step(tab, ip, u, v, e, gu, gv, fixu, fixv,
                                                         delta, width, xtol, f, ev, ev2)
        if step == _SNAP:
            continue
        if step == _FINISH:
            if (fixu == CREASE or fixv == CREASE) and nmig < MAX_MIGRATIONS and nretest < 4:
                nretest += 1
                code, j, uj, vj, ne = _retest_crease(tab, ip, u, v, e, fixu, fixv, ws, ev2, tmp)
                nev += ne
                if code == 0:
                    nmig += 1
                    ip = j
                    u = uj
                    v = vj
                    fixu = FREE
                    fixv = FREE
                    evaluate(tab, ip, u, v, 2, ws, ev)
                    nev += 1
                    f = dot3(e, ev[0])
                    continue
            converged = True
            break
        u, v, f, delta, stop = _trial(tab, ip, e, u, v, un, vn, xu, xv, xn, gu, gv, f, delta,
                                      scale, ws, ev, ev2)
        nev += 1
        if stop:
            break   # cannot improve any further within rounding: not converged
    ist[0] = ip
    ist[1] = fixu
    ist[2] = fixv
    ist[3] = nmig
    fst[0] = u
    fst[1] = v
    fst[2] = delta
    for c in range(3):
        out_p[c] = ev[0, c]
    support_derivatives(tab, ip, u, v, e, fixu, fixv, scale, ws, ev, ev2, out_M, out_G)
    return converged, nev


@kernel
def seed_start(seed_x, seed_p, seed_uv, s0, ns, mask, p0, e):
    """Index of the seed (tabulated surface sample, file frame) with the largest e · x among
    seeds s0..s0+ns-1 whose patch is allowed by ``mask`` (mask empty: all allowed)."""
    best = -1e300
    ib = s0
    use_mask = mask.shape[0] > 0
    for k in range(s0, s0 + ns):
        if use_mask and not mask[seed_p[k] - p0]:
            continue
        val = e[0] * seed_x[k, 0] + e[1] * seed_x[k, 1] + e[2] * seed_x[k, 2]
        if val > best:
            best = val
            ib = k
    return ib


def make_seeds(shape, n: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Surface samples used for cold starts: an n×n grid of cell centres per patch
    (n chosen for ~200 samples per body). Returns (x (S, 3) file frame, patch (S,), uv (S, 2))."""
    P = len(shape.patches)
    if n is None:
        n = max(4, int(round(math.sqrt(216.0 / max(P, 1)))))
    xs, ps, uvs = [], [], []
    t = (np.arange(n) + 0.5) / n
    for i, pt in enumerate(shape.patches):
        u0, u1, v0, v1 = pt.domain
        U, V = np.meshgrid(u0 + t * (u1 - u0), v0 + t * (v1 - v0), indexing="ij")
        pts = pt.evaluate(U.ravel(), V.ravel(), 0)[:, 0]
        xs.append(pts)
        ps.append(np.full(U.size, i, np.int64))
        uvs.append(np.stack([U.ravel(), V.ravel()], axis=1))
    return (np.ascontiguousarray(np.concatenate(xs)), np.concatenate(ps),
            np.ascontiguousarray(np.concatenate(uvs)))

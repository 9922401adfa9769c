"""The trust-region step shared by the local contact search: the support mapping (2 surface
parameters, :mod:`.support`), the direction search on the unit sphere (2 chart
coordinates, :mod:`.lcp`) and stage 1 (up to 4 surface parameters, :mod:`.stage1`).

Subproblem (Nocedal & Wright, *Numerical Optimization*, Sec. 4.3; Moré & Sorensen 1983):

    minimise  m(x) = gᵀx + ½ xᵀ H x     subject to  |x| <= Δ

solved exactly in the eigenbasis of the symmetric H = Q diag(λ) Qᵀ by :func:`tr_solve`:
the Newton step x = −H⁻¹g when H is positive definite and the step fits; otherwise
x(μ) = −(H + μI)⁻¹g with the shift μ >= max(0, −λmin) for which |x(μ)| = Δ (safeguarded
Newton on the secular equation 1/|x(μ)| = 1/Δ, bisection when Newton leaves the bracket);
in the *hard case* (λmin <= 0 and the shifted step at μ = −λmin + 1e-12 max|λ| is still
shorter than Δ: g has no component along the lowest eigenvector) the step is completed along
that eigenvector to length Δ — which is how a start exactly at a saddle is left.

The eigen-decompositions: closed form for 2×2 (:func:`sym2_eig`), cyclic Jacobi up to 4×4
(:func:`jacobi_eig`). The callers' coordinates: :func:`tr_step2` (2-D, returns the model
value too) and :func:`tr_step_eig` (n-D, H already decomposed). One free parameter in the
support mapping is the closed-form :func:`tr_step1`.

All functions are compiled by :func:`nurbsdem.jit.kernel`; the callers pass the scratch arrays.
"""
from __future__ import annotations

import math

from ..jit import kernel

#: Iterations of the secular equation (it converges in a few; bisection bounds the rest).
SECULAR_IT = 80


# --------------------------------------------------------------------------- eigen-decompositions
@kernel
def sym2_eig(b11, b12, b22):
    """Eigen-decomposition of a symmetric 2×2 matrix: (l1, l2, c, s) with l1 <= l2,
    q1 = (−s, c) the eigenvector of l1 and q2 = (c, s) the eigenvector of l2."""
    half = 0.5 * (b11 - b22)
    r = math.sqrt(half * half + b12 * b12)
    m = 0.5 * (b11 + b22)
    th = 0.5 * math.atan2(b12, half) if r > 0.0 else 0.0
    return m - r, m + r, math.cos(th), math.sin(th)


@kernel
def jacobi_eig(A, n, Q, lam):
    """Eigen-decomposition of the leading n×n block (n <= 4) of the symmetric ``A`` by cyclic
    Jacobi rotations: A = Q diag(lam) Qᵀ (eigenvectors in the columns of Q). ``A`` is
    overwritten."""
    for i in range(n):
        for j in range(n):
            Q[i, j] = 1.0 if i == j else 0.0
    for sweep in range(40):
        off = 0.0
        dg = 0.0
        for i in range(n):
            dg += A[i, i] * A[i, i]
            for j in range(i + 1, n):
                off += A[i, j] * A[i, j]
        if off <= 1e-34 * dg or off == 0.0:
            break
        for p in range(n - 1):
            for q in range(p + 1, n):
                apq = A[p, q]
                if apq == 0.0:
                    continue
                theta = (A[q, q] - A[p, p]) / (2.0 * apq)
                t = 1.0 / (abs(theta) + math.sqrt(theta * theta + 1.0))
                if theta < 0.0:
                    t = -t
                c = 1.0 / math.sqrt(t * t + 1.0)
                s = t * c
                for k in range(n):
                    akp = A[k, p]
                    akq = A[k, q]
                    A[k, p] = c * akp - s * akq
                    A[k, q] = s * akp + c * akq
                for k in range(n):
                    apk = A[p, k]
                    aqk = A[q, k]
                    A[p, k] = c * apk - s * aqk
                    A[q, k] = s * apk + c * aqk
                for k in range(n):
                    qkp = Q[k, p]
                    qkq = Q[k, q]
                    Q[k, p] = c * qkp - s * qkq
                    Q[k, q] = s * qkp + c * qkq
    for i in range(n):
        lam[i] = A[i, i]


# --------------------------------------------------------------------------- the step
@kernel(inline="always")   # hot: the 2-D callers run it with n = 2
def tr_solve(lam, a, n, delta, y):
    """The trust-region step in the eigenbasis (module docstring): minimise
    Σ a_i y_i + ½ λ_i y_i² subject to |y| <= delta, for n <= 4 components. Writes ``y``;
    returns whether it is the (unconstrained) Newton step."""
    lmin = 1e300
    imin = 0
    lmax = 0.0
    for i in range(n):
        if lam[i] < lmin:
            lmin = lam[i]
            imin = i
        if abs(lam[i]) > lmax:
            lmax = abs(lam[i])
    scale = max(lmax, 1e-300)
    if lmin > 1e-14 * scale:
        nn = 0.0
        for i in range(n):
            y[i] = -a[i] / lam[i]
            nn += y[i] * y[i]
        if nn <= delta * delta:
            return True
    lo = max(0.0, -lmin)
    gn = 0.0
    for i in range(n):
        gn += a[i] * a[i]
    gn = math.sqrt(gn)
    eps = 1e-12 * scale + 1e-300
    # hard case: no gradient component along the lowest eigenvector(s) and the step at
    # mu -> lo (those components dropped) shorter than delta: complete it along the lowest
    nn = 0.0
    hard = lmin <= 0.0
    for i in range(n):
        den = lam[i] + lo
        if den > eps:
            y[i] = -a[i] / den
            nn += y[i] * y[i]
        elif abs(a[i]) <= 1e-12 * (gn + 1e-300):
            y[i] = 0.0
        else:
            y[i] = 0.0
            hard = False
    hi = lo + gn / delta + 1e-300
    if (hard and nn <= delta * delta) or not hi > lo:
        # (hi == lo: the gradient is below the rounding of lo, the secular equation has no
        # room and would divide by zero: the hard-case step instead; y[imin] is 0 here)
        rest = delta * delta - (nn - y[imin] * y[imin])
        y[imin] = math.sqrt(rest) if rest > 0.0 else 0.0
        if a[imin] > 0.0:
            y[imin] = -y[imin]
        return False
    mu = hi
    for _ in range(SECULAR_IT):
        nn = 0.0
        s3 = 0.0
        for i in range(n):
            d = lam[i] + mu
            y[i] = -a[i] / d
            nn += y[i] * y[i]
            s3 += a[i] * a[i] / (d * d * d)
        nn = math.sqrt(nn)
        if abs(nn - delta) <= 1e-6 * delta:
            break
        if nn > delta:
            lo = mu
        else:
            hi = mu
        step = (nn / delta - 1.0) * nn * nn / s3 if s3 > 0.0 else 0.0
        mnew = mu + step
        if not (mnew > lo and mnew < hi):
            mnew = 0.5 * (lo + hi)
        if not lam[imin] + mnew > 0.0:
            break   # the bracket is down to rounding at mu = -lmin: keep this step
        mu = mnew
    return False


@kernel
def tr_step_eig(lam, Q, gv, n, delta, y, s, a):
    """Trust-region step for H = Q diag(lam) Qᵀ (n×n, n <= 4) and gradient ``gv``: writes
    s (and y = Qᵀ s); returns whether it is the Newton step. ``a`` (n,): scratch."""
    for i in range(n):
        acc = 0.0
        for k in range(n):
            acc += Q[k, i] * gv[k]
        a[i] = acc
    newton = tr_solve(lam, a, n, delta, y)
    for k in range(n):
        acc = 0.0
        for i in range(n):
            acc += Q[k, i] * y[i]
        s[k] = acc
    return newton


@kernel(inline="always")
def tr_step2(b11, b12, b22, c1, c2, delta, w):
    """Trust-region step in 2-D: minimise m(x) = c·x + ½ xᵀBx subject to |x| <= delta,
    B = [[b11, b12], [b12, b22]]. ``w``: scratch, 3 rows of >= 2. Returns (x1, x2, m(x))."""
    l1, l2, c, s = sym2_eig(b11, b12, b22)
    lam = w[0]
    a = w[1]
    y = w[2]
    lam[0] = l1
    lam[1] = l2
    a[0] = -s * c1 + c * c2     # q1 · c
    a[1] = c * c1 + s * c2      # q2 · c
    tr_solve(lam, a, 2, delta, y)
    y1 = y[0]
    y2 = y[1]
    x1 = c * y2 - s * y1
    x2 = s * y2 + c * y1
    mval = c1 * x1 + c2 * x2 + 0.5 * (b11 * x1 * x1 + 2.0 * b12 * x1 * x2 + b22 * x2 * x2)
    return x1, x2, mval


@kernel
def tr_step1(b, cg, delta):
    """Trust-region step in 1-D: minimise cg x + ½ b x² with |x| <= delta; returns (x, m(x))."""
    if b > 0.0 and abs(cg) <= b * delta:
        x = -cg / b
    elif cg > 0.0:
        x = -delta
    elif cg < 0.0:
        x = delta
    else:
        x = delta if b < 0.0 else 0.0
    return x, cg * x + 0.5 * b * x * x

"""The shared trust-region step (nurbsdem.contact.trust_region) against the optimality
conditions of the subproblem (Moré–Sorensen): x* minimises g·x + ½ xᵀHx over |x| <= Δ iff
(H + μI) x* = −g, H + μI positive semi-definite, μ >= 0 and μ (Δ − |x*|) = 0."""
from __future__ import annotations

import numpy as np
import pytest

from nurbsdem.contact.trust_region import tr_step2, tr_step_eig


def _check_optimal(H, g, delta, x, tol=1e-6):
    n = len(g)
    lmin = np.linalg.eigvalsh(H)[0]
    nx = np.linalg.norm(x)
    assert nx <= delta * (1 + tol)
    if nx < delta * (1 - tol):           # interior: the Newton step of a convex model
        assert lmin > -tol * max(1.0, abs(lmin))
        np.testing.assert_allclose(H @ x, -g, atol=tol * (np.abs(g).max() + np.abs(H).max() * nx))
        return
    # on the boundary: the multiplier from the stationarity condition
    r = -g - H @ x
    mu = float(r @ x) / float(x @ x)
    scale = np.abs(H).max() + np.abs(g).max() / delta
    assert mu >= -tol * scale
    assert lmin + mu >= -1e-5 * scale
    np.testing.assert_allclose(r, mu * x, atol=1e-5 * scale * delta)
    # and it is no worse than a dense sample of the boundary and the interior Newton point
    m = lambda y: g @ y + 0.5 * y @ H @ y  # noqa: E731
    rng = np.random.default_rng(0)
    u = rng.normal(size=(4000, n))
    u *= delta / np.linalg.norm(u, axis=1)[:, None]
    assert m(x) <= np.min(np.einsum("ki,i->k", u, g) + 0.5 * np.einsum("ki,ij,kj->k", u, H, u)) \
        + 1e-6 * scale * delta ** 2


@pytest.mark.parametrize("seed", range(40))
def test_tr_step2_is_optimal(seed):
    rng = np.random.default_rng(seed)
    B = rng.normal(size=(2, 2))
    B = 0.5 * (B + B.T)
    c = rng.normal(size=2) * 10 ** rng.uniform(-2, 1)
    delta = 10 ** rng.uniform(-2, 1)
    x1, x2, mval = tr_step2(B[0, 0], B[0, 1], B[1, 1], c[0], c[1], delta, np.zeros((3, 3)))
    x = np.array([x1, x2])
    assert mval == pytest.approx(c @ x + 0.5 * x @ B @ x, rel=1e-12, abs=1e-15)
    _check_optimal(B, c, delta, x)


@pytest.mark.parametrize("seed", range(40))
def test_tr_step_eig_is_optimal(seed):
    rng = np.random.default_rng(100 + seed)
    n = int(rng.integers(1, 5))
    Q = np.linalg.qr(rng.normal(size=(n, n)))[0]
    lam = rng.normal(size=n)
    g = rng.normal(size=n) * 10 ** rng.uniform(-2, 1)
    delta = 10 ** rng.uniform(-2, 1)
    Qp = np.zeros((4, 4))
    Qp[:n, :n] = Q
    gp = np.zeros(4)
    gp[:n] = g
    s, y, a = np.zeros(4), np.zeros(4), np.zeros(4)
    tr_step_eig(np.r_[lam, np.zeros(4 - n)], Qp, gp, n, delta, y, s, a)
    _check_optimal(Q @ np.diag(lam) @ Q.T, g, delta, s[:n])


def test_hard_case_and_tiny_gradients_leave_a_saddle():
    """A start exactly at a saddle (zero gradient) steps along the negative curvature to the
    boundary; gradients far below rounding of the curvature do not divide by zero."""
    w = np.zeros((3, 3))
    for g in (0.0, 1e-300, 1e-200, 1e-30):
        x1, x2, _ = tr_step2(-1.0, 0.0, 2.0, g, 0.0, 0.5, w)
        assert np.hypot(x1, x2) == pytest.approx(0.5, rel=1e-9) and abs(x1) == pytest.approx(0.5)
    lam = np.array([-1.0, 2.0, 3.0, 0.0])
    for g in (0.0, 1e-300, 1e-30):
        s, y, a = np.zeros(4), np.zeros(4), np.zeros(4)
        tr_step_eig(lam.copy(), np.eye(4), np.array([g, 0.0, 0.0, 0.0]), 3, 0.5, y, s, a)
        assert np.linalg.norm(s[:3]) == pytest.approx(0.5, rel=1e-9) and abs(s[0]) == pytest.approx(0.5)


def test_sym2_eig_against_numpy_and_the_angle():
    """The closed-form 2x2 eigen-decomposition: B q = λ q to round-off, q1 = (−s, c),
    q2 = (c, s) orthonormal, and (c, s) the rotation by θ = ½ atan2(b12, (b11 − b22)/2) —
    including the diagonal cases (b12 = ±0, either order)."""
    from nurbsdem.contact.trust_region import sym2_eig
    rng = np.random.default_rng(5)
    cases = [tuple(rng.normal(size=3) * 10.0 ** rng.integers(-6, 6)) for _ in range(2000)]
    cases += [(1.0, 0.0, 2.0), (2.0, 0.0, 1.0), (2.0, -0.0, 1.0), (1.0, -0.0, 2.0),
              (1.0, 1e-300, 1.0), (3.0, 0.0, 3.0), (0.0, 1.0, 0.0), (1.0, -1e-12, 1.0 + 1e-9)]
    for b11, b12, b22 in cases:
        l1, l2, c, s = sym2_eig(b11, b12, b22)
        B = np.array([[b11, b12], [b12, b22]])
        scale = np.abs(B).max()
        np.testing.assert_allclose([l1, l2], np.linalg.eigvalsh(B), atol=1e-14 * scale)
        q1, q2 = np.array([-s, c]), np.array([c, s])
        assert abs(c * c + s * s - 1.0) <= 4e-16
        np.testing.assert_allclose(B @ q1, l1 * q1, atol=1e-14 * scale)
        np.testing.assert_allclose(B @ q2, l2 * q2, atol=1e-14 * scale)
        half = 0.5 * (b11 - b22)
        if np.sqrt(half * half + b12 * b12) > 0.0:     # else any basis: sym2_eig's (1, 0)
            th = 0.5 * np.arctan2(b12, half)
            assert abs(c - np.cos(th)) <= 1e-15 and abs(s - np.sin(th)) <= 1e-15

"""Rational tensor-product B-spline (NURBS) patches: data, validation, vectorised evaluation.

A patch (paper Eq. 2) is

    s(u, v) = sum_ij N_i,p(u) N_j,q(v) w_ij P_ij / sum_ij N_i,p(u) N_j,q(v) w_ij

with clamped knot vectors. Lengths are in metres; parameters are dimensionless.

This module is the *vectorised* face of the kernel (many (u, v) points at once, used for
tessellation, mass properties and tests). The compiled scalar face used in the contact hot
loop is :mod:`nurbsdem.geometry.kernel`; both implement The NURBS Book's algorithms A2.1
(span), A2.3 (basis functions with derivatives) and the quotient rule of Eq. (4.20) for the
rational derivatives, and the tests check them against each other.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import GeometryError

#: Order of the derivative slots returned by the evaluators.
DERIVS = ("S", "S_u", "S_v", "S_uu", "S_uv", "S_vv")


@dataclass(eq=False)
class Patch:
    """One NURBS surface patch.

    Attributes
    ----------
    degree_u, degree_v: polynomial degrees p, q (>= 1).
    knots_u, knots_v: clamped, non-decreasing knot vectors (lengths n_u + p + 1, n_v + q + 1).
    control_points: array (n_u, n_v, 3), metres; row index i goes with u, column j with v.
    weights: array (n_u, n_v), all > 0.
    """

    degree_u: int
    degree_v: int
    knots_u: np.ndarray
    knots_v: np.ndarray
    control_points: np.ndarray
    weights: np.ndarray = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        self.knots_u = np.asarray(self.knots_u, dtype=float)
        self.knots_v = np.asarray(self.knots_v, dtype=float)
        self.control_points = np.asarray(self.control_points, dtype=float)
        if self.weights is None:
            self.weights = np.ones(self.control_points.shape[:2])
        self.weights = np.asarray(self.weights, dtype=float)

    # ------------------------------------------------------------------ properties
    @property
    def shape(self) -> tuple[int, int]:
        """(n_u, n_v): control points along u and v."""
        return self.control_points.shape[0], self.control_points.shape[1]

    @property
    def domain(self) -> tuple[float, float, float, float]:
        """(u_min, u_max, v_min, v_max) of the parameter rectangle."""
        p, q = self.degree_u, self.degree_v
        return (float(self.knots_u[p]), float(self.knots_u[-p - 1]),
                float(self.knots_v[q]), float(self.knots_v[-q - 1]))

    @property
    def homogeneous(self) -> np.ndarray:
        """Weighted control points (w x, w y, w z, w), array (n_u, n_v, 4)."""
        return np.concatenate([self.control_points * self.weights[..., None],
                               self.weights[..., None]], axis=-1)

    def transformed(self, matrix: np.ndarray, offset: np.ndarray | None = None) -> "Patch":
        """The patch under x -> matrix @ x + offset (NURBS are affine invariant)."""
        pts = self.control_points @ np.asarray(matrix, float).T
        if offset is not None:
            pts = pts + np.asarray(offset, float)
        return Patch(self.degree_u, self.degree_v, self.knots_u.copy(), self.knots_v.copy(),
                     pts, self.weights.copy())

    # ------------------------------------------------------------------ validation
    def validate(self, path: str | None = None, index: int | None = None) -> None:
        """Raise :class:`GeometryError` naming the file and patch if the data are not a NURBS patch."""
        where = f"patch {index}" if index is not None else "patch"

        def fail(msg: str) -> None:
            raise GeometryError(msg, path=path, where=where)

        for name, deg in (("degree_u", self.degree_u), ("degree_v", self.degree_v)):
            if int(deg) != deg or deg < 1:
                fail(f"{name} must be an integer >= 1, got {deg}")
        cp = self.control_points
        if cp.ndim != 3 or cp.shape[2] != 3:
            fail(f"control_points must be n_u rows of n_v [x, y, z] points, got array of shape {cp.shape}")
        nu, nv = cp.shape[:2]
        if self.weights.shape != (nu, nv):
            fail(f"weights must have shape {(nu, nv)} like control_points, got {self.weights.shape}")
        for name, arr in (("control_points", cp), ("weights", self.weights),
                          ("knots_u", self.knots_u), ("knots_v", self.knots_v)):
            if not np.all(np.isfinite(arr)):
                fail(f"{name} contains a non-finite number")
        if np.any(self.weights <= 0.0):
            i, j = np.argwhere(self.weights <= 0.0)[0]
            fail(f"weight [{i}][{j}] = {self.weights[i, j]} is not > 0")
        for name, knots, deg, n in (("knots_u", self.knots_u, self.degree_u, nu),
                                    ("knots_v", self.knots_v, self.degree_v, nv)):
            if knots.ndim != 1:
                fail(f"{name} must be a list of numbers")
            if n < deg + 1:
                fail(f"{name}: degree {deg} needs at least {deg + 1} control points, got {n}")
            if len(knots) != n + deg + 1:
                fail(f"{name} has {len(knots)} knots, expected n + degree + 1 = {n + deg + 1}")
            if np.any(np.diff(knots) < 0):
                k = int(np.argmax(np.diff(knots) < 0))
                fail(f"{name} is not non-decreasing at index {k + 1}")
            if not (np.all(knots[: deg + 1] == knots[0]) and np.all(knots[-deg - 1:] == knots[-1])):
                fail(f"{name} is not clamped: the first and last {deg + 1} knots must repeat")
            if knots[-1] <= knots[0]:
                fail(f"{name} spans an empty parameter range")
            interior = knots[deg + 1: -deg - 1]
            if interior.size:
                _, counts = np.unique(interior, return_counts=True)
                if counts.max() > deg:
                    fail(f"{name} has an interior knot of multiplicity > degree {deg}")

    # ------------------------------------------------------------------ evaluation
    def evaluate(self, u, v, order: int = 2) -> np.ndarray:
        """Points and partial derivatives at many parameter pairs.

        Parameters
        ----------
        u, v: arrays of the same shape (any), inside the domain.
        order: 0 (points), 1 (with S_u, S_v) or 2 (with S_uu, S_uv, S_vv).

        Returns
        -------
        Array ``(..., k, 3)`` with k = 1, 3 or 6 slots in the order of :data:`DERIVS`.
        """
        return evaluate_patch(self, u, v, order)

    def points(self, u, v) -> np.ndarray:
        """Surface points at (u, v), array (..., 3)."""
        return evaluate_patch(self, u, v, 0)[..., 0, :]

    def normals(self, u, v) -> np.ndarray:
        """Unit normals S_u x S_v / |S_u x S_v| at (u, v), array (..., 3)."""
        d = evaluate_patch(self, u, v, 1)
        n = np.cross(d[..., 1, :], d[..., 2, :])
        return n / np.linalg.norm(n, axis=-1, keepdims=True)


# ---------------------------------------------------------------------- basis functions
def find_spans(knots: np.ndarray, degree: int, t: np.ndarray) -> np.ndarray:
    """Knot span index of each parameter (The NURBS Book A2.1, vectorised).

    Returns k with knots[k] <= t < knots[k+1], clamped so that t = t_max maps to the last
    non-empty span.
    """
    n = len(knots) - degree - 1  # number of control points
    t = np.clip(t, knots[degree], knots[n])
    k = np.searchsorted(knots, t, side="right") - 1
    return np.clip(k, degree, n - 1)


def basis_functions_derivs(knots: np.ndarray, degree: int, t: np.ndarray, nderiv: int,
                           spans: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Non-zero B-spline basis functions and their derivatives (The NURBS Book A2.3, vectorised).

    Returns
    -------
    spans: array (m,).
    ders: array (m, nderiv + 1, degree + 1); ders[:, k, r] is the k-th derivative of
        N_{span - degree + r, degree} at t.
    """
    t = np.atleast_1d(np.asarray(t, dtype=float)).ravel()
    p = degree
    if spans is None:
        spans = find_spans(knots, p, t)
    m = t.size
    ndu = np.zeros((m, p + 1, p + 1))
    left = np.zeros((m, p + 1))
    right = np.zeros((m, p + 1))
    ndu[:, 0, 0] = 1.0
    for j in range(1, p + 1):
        left[:, j] = t - knots[spans + 1 - j]
        right[:, j] = knots[spans + j] - t
        saved = np.zeros(m)
        for r in range(j):
            ndu[:, j, r] = right[:, r + 1] + left[:, j - r]
            temp = ndu[:, r, j - 1] / ndu[:, j, r]
            ndu[:, r, j] = saved + right[:, r + 1] * temp
            saved = left[:, j - r] * temp
        ndu[:, j, j] = saved
    ders = np.zeros((m, nderiv + 1, p + 1))
    for j in range(p + 1):
        ders[:, 0, j] = ndu[:, j, p]
    a = np.zeros((m, 2, p + 1))
    for r in range(p + 1):
        s1, s2 = 0, 1
        a[:] = 0.0
        a[:, 0, 0] = 1.0
        for k in range(1, nderiv + 1):
            d = np.zeros(m)
            rk = r - k
            pk = p - k
            if r >= k:
                a[:, s2, 0] = a[:, s1, 0] / ndu[:, pk + 1, rk]
                d = a[:, s2, 0] * ndu[:, rk, pk]
            j1 = 1 if rk >= -1 else -rk
            j2 = k - 1 if r - 1 <= pk else p - r
            for j in range(j1, j2 + 1):
                a[:, s2, j] = (a[:, s1, j] - a[:, s1, j - 1]) / ndu[:, pk + 1, rk + j]
                d = d + a[:, s2, j] * ndu[:, rk + j, pk]
            if r <= pk:
                a[:, s2, k] = -a[:, s1, k - 1] / ndu[:, pk + 1, r]
                d = d + a[:, s2, k] * ndu[:, r, pk]
            ders[:, k, r] = d
            s1, s2 = s2, s1
    fac = p
    for k in range(1, nderiv + 1):
        ders[:, k, :] *= fac
        fac *= p - k
    return spans, ders


def evaluate_patch(patch: Patch, u, v, order: int = 2) -> np.ndarray:
    """Vectorised points and derivatives of a NURBS patch; see :meth:`Patch.evaluate`."""
    u = np.asarray(u, dtype=float)
    v = np.asarray(v, dtype=float)
    out_shape = np.broadcast(u, v).shape
    u = np.broadcast_to(u, out_shape).ravel()
    v = np.broadcast_to(v, out_shape).ravel()
    p, q = patch.degree_u, patch.degree_v
    su, Nu = basis_functions_derivs(patch.knots_u, p, u, min(order, p))
    sv, Nv = basis_functions_derivs(patch.knots_v, q, v, min(order, q))
    if Nu.shape[1] < order + 1:  # degree-1 directions have zero second derivatives
        Nu = np.concatenate([Nu, np.zeros((Nu.shape[0], order + 1 - Nu.shape[1], p + 1))], axis=1)
    if Nv.shape[1] < order + 1:
        Nv = np.concatenate([Nv, np.zeros((Nv.shape[0], order + 1 - Nv.shape[1], q + 1))], axis=1)
    Pw = patch.homogeneous
    iu = su[:, None] - p + np.arange(p + 1)[None, :]  # (m, p+1)
    iv = sv[:, None] - q + np.arange(q + 1)[None, :]  # (m, q+1)
    local = Pw[iu[:, :, None], iv[:, None, :]]  # (m, p+1, q+1, 4)
    # homogeneous derivatives A^(k,l) = sum_ij N_i^(k) N_j^(l) Pw_ij
    pairs = [(0, 0)] if order == 0 else [(0, 0), (1, 0), (0, 1)] if order == 1 else \
        [(0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2)]
    H = {kl: np.einsum("mi,mj,mijc->mc", Nu[:, kl[0]], Nv[:, kl[1]], local) for kl in pairs}
    w = H[(0, 0)][:, 3:4]
    S = H[(0, 0)][:, :3] / w
    out = [S]
    if order >= 1:
        wu, wv = H[(1, 0)][:, 3:4], H[(0, 1)][:, 3:4]
        Su = (H[(1, 0)][:, :3] - wu * S) / w
        Sv = (H[(0, 1)][:, :3] - wv * S) / w
        out += [Su, Sv]
    if order >= 2:
        wuu, wuv, wvv = H[(2, 0)][:, 3:4], H[(1, 1)][:, 3:4], H[(0, 2)][:, 3:4]
        Suu = (H[(2, 0)][:, :3] - 2 * wu * Su - wuu * S) / w
        Suv = (H[(1, 1)][:, :3] - wu * Sv - wv * Su - wuv * S) / w
        Svv = (H[(0, 2)][:, :3] - 2 * wv * Sv - wvv * S) / w
        out += [Suu, Suv, Svv]
    res = np.stack(out, axis=1)
    return res.reshape(out_shape + (len(out), 3))

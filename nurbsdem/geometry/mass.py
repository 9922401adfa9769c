"""Mass properties of a closed NURBS surface from its boundary (divergence theorem).

For a closed surface with outward normal n, the divergence theorem turns the volume
integrals of a homogeneous solid into surface integrals. With r = x - x0 (x0 a reference
point) and the identities

    div(r)            = 3               ->  V        = 1/3 ∮ (r·n) dA
    div(r_k r)        = 4 r_k           ->  ∫ r_k dV = 1/4 ∮ r_k (r·n) dA
    div(r_i r_j r)    = 5 r_i r_j       ->  ∫ r_i r_j dV = 1/5 ∮ r_i r_j (r·n) dA

(all rotation-equivariant, so the error does not depend on the orientation of the body),
the centroid is c = x0 + ∫ r dV / V and the second moment about the centroid follows from
the parallel-axis theorem M2_c = M2_x0 - V d dᵀ with d = c - x0. The volume inertia tensor is
J = tr(M2_c) I - M2_c (m^5; times the density it is the mass inertia tensor, kg m^2).

On a patch, n dA = (S_u × S_v) du dv, outward when the patch is outward oriented. Each
non-empty knot span (rectangle of the parameter domain) is integrated with an n × n
Gauss–Legendre rule. For a polynomial (non-rational) patch of degrees (p, q) the integrand
r_i r_j (r·(S_u × S_v)) is a polynomial of degree 5p - 1 in u and 5q - 1 in v on each span, so
n_u = ceil(5p/2), n_v = ceil(5q/2) points integrate it exactly. A rational patch's integrand
is a rational function, analytic on the span, for which Gauss rules converge geometrically:
there the rule starts 2 points above the polynomial-exact order and is raised by 4 per
step until two successive orders agree to ``rtol`` relative to the size of the body
(V ~ R^3, first moments ~ R^4, second ~ R^5, with R the largest distance of a control point
from x0, the centre of the control points' bounding box). Degenerate edges (poles, where
S_u × S_v = 0) need no special care: the Gauss points are interior and the integrand is bounded.
"""
from __future__ import annotations

import math
import warnings
from functools import lru_cache
from typing import Sequence

import numpy as np

from .nurbs import Patch

#: Largest Gauss order per direction and span tried for rational patches.
MAX_ORDER = 64
#: Extra Gauss points (per direction) of the first rule tried on a rational patch, above
#: the order that would be exact for a polynomial patch of the same degrees.
RATIONAL_EXTRA = 2
#: Order increment between the successive rules compared for rational patches.
ORDER_STEP = 4


@lru_cache(maxsize=128)
def _gauss(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Legendre nodes and weights on [0, 1] (read-only arrays)."""
    x, w = np.polynomial.legendre.leggauss(n)
    x = 0.5 * (x + 1.0)
    w = 0.5 * w
    x.setflags(write=False)
    w.setflags(write=False)
    return x, w


def _span_rule(knots: np.ndarray, degree: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and weights of an n-point Gauss rule on every non-empty span of the domain."""
    breaks = np.unique(knots[degree: len(knots) - degree])
    a, b = breaks[:-1], breaks[1:]
    x, w = _gauss(n)
    h = b - a
    nodes = (a[:, None] + h[:, None] * x[None, :]).ravel()
    weights = (h[:, None] * w[None, :]).ravel()
    return nodes, weights


def _is_rational(patch: Patch) -> bool:
    w = patch.weights
    return bool(np.any(w != w.flat[0]))


def _exact_orders(patch: Patch) -> tuple[int, int]:
    """Gauss orders integrating a polynomial patch's moment integrands exactly."""
    return math.ceil(5 * patch.degree_u / 2), math.ceil(5 * patch.degree_v / 2)


def patch_moments(patch: Patch, x0: np.ndarray, n_u: int, n_v: int) -> np.ndarray:
    """Boundary contribution of one patch to the volume moments about x0.

    Returns the vector ``(V, ∫r dV (3), ∫r rᵀ dV (xx, yy, zz, xy, xz, yz))`` (m^3, m^4, m^5)
    of the patch's flux, computed with n_u × n_v Gauss points per non-empty knot span.
    """
    u, wu = _span_rule(patch.knots_u, patch.degree_u, n_u)
    v, wv = _span_rule(patch.knots_v, patch.degree_v, n_v)
    U, V = np.meshgrid(u, v, indexing="ij")
    W = wu[:, None] * wv[None, :]
    d = patch.evaluate(U, V, order=1).reshape(-1, 3, 3)
    r = d[:, 0, :] - x0
    nda = np.cross(d[:, 1, :], d[:, 2, :]) * W.reshape(-1, 1)  # n dA (m^2)
    flux = np.einsum("mk,mk->m", r, nda)  # (r·n) dA
    out = np.empty(10)
    out[0] = flux.sum() / 3.0
    out[1:4] = (r * flux[:, None]).sum(0) / 4.0
    x, y, z = r[:, 0], r[:, 1], r[:, 2]
    out[4:10] = np.stack([x * x, y * y, z * z, x * y, x * z, y * z]) @ flux / 5.0
    return out


def _scales(R: float) -> np.ndarray:
    return np.array([R ** 3] + [R ** 4] * 3 + [R ** 5] * 6)


def _patch_moments_adaptive(patch: Patch, x0: np.ndarray, R: float, rtol: float) -> np.ndarray:
    n_u, n_v = _exact_orders(patch)
    if not _is_rational(patch):
        return patch_moments(patch, x0, n_u, n_v)
    n_u, n_v = n_u + RATIONAL_EXTRA, n_v + RATIONAL_EXTRA
    m = patch_moments(patch, x0, n_u, n_v)
    scale = _scales(R)
    while max(n_u, n_v) < MAX_ORDER:
        n_u = min(n_u + ORDER_STEP, MAX_ORDER)
        n_v = min(n_v + ORDER_STEP, MAX_ORDER)
        m_new = patch_moments(patch, x0, n_u, n_v)
        converged = np.all(np.abs(m_new - m) <= rtol * scale)
        m = m_new
        if converged:
            return m
    warnings.warn(f"mass properties: Gauss order {MAX_ORDER} did not reach rtol={rtol:g} on a "
                  "rational patch (extreme weights?)", RuntimeWarning, stacklevel=3)
    return m


def inertia_from_second_moment(m2: np.ndarray) -> np.ndarray:
    """Inertia tensor J = tr(M2) I - M2 from the second-moment matrix M2 = ∫ x xᵀ dV."""
    return np.trace(m2) * np.eye(3) - m2


def second_moment_from_inertia(j: np.ndarray) -> np.ndarray:
    """Inverse of :func:`inertia_from_second_moment`: M2 = ½ tr(J) I - J."""
    return 0.5 * np.trace(j) * np.eye(3) - j


def mass_properties(patches: Sequence[Patch], rtol: float = 1e-13
                    ) -> tuple[float, np.ndarray, np.ndarray]:
    """Volume, centroid and volume inertia tensor of the solid bounded by closed patches.

    Parameters
    ----------
    patches: outward-oriented patches (S_u × S_v points out) forming a closed surface, m.
    rtol: convergence tolerance of the Gauss order for rational patches, relative to the
        body's size (see the module docstring). Polynomial patches are integrated exactly.

    Returns
    -------
    volume: m^3 (negative if the patches are inward oriented).
    centroid: array (3,), m, file frame.
    inertia: array (3, 3), m^5, ∫ (|r|² I - r rᵀ) dV about the centroid, r = x - centroid;
        multiply by the density (kg/m^3) for the mass inertia tensor (kg m^2).
    """
    pts = np.concatenate([p.control_points.reshape(-1, 3) for p in patches])
    x0 = 0.5 * (pts.min(0) + pts.max(0))
    R = float(np.linalg.norm(pts - x0, axis=1).max())
    if R == 0.0:
        return 0.0, x0, np.zeros((3, 3))
    m = sum(_patch_moments_adaptive(p, x0, R, rtol) for p in patches)
    vol = float(m[0])
    if vol == 0.0:
        return 0.0, x0, np.zeros((3, 3))
    d = m[1:4] / vol
    xx, yy, zz, xy, xz, yz = m[4:10]
    m2 = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]) - vol * np.outer(d, d)
    return vol, x0 + d, inertia_from_second_moment(m2)

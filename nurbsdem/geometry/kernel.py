"""Compiled scalar NURBS kernel for the contact hot loop.

Patches of any number of shapes are packed into flat arrays (a :class:`PatchPool`) so that
compiled code — and later a GPU kernel — can evaluate any patch with no Python object in
the loop. The algorithms are those of :mod:`nurbsdem.geometry.nurbs` (The NURBS Book A2.1,
A2.3 and the rational quotient rule), written once more as scalar loops over a caller-owned
workspace so that an evaluation allocates nothing.

Units: control points in metres, parameters dimensionless.

Pool layout (P patches):

* ``deg[P, 2]``   degrees (p, q)
* ``ncp[P, 2]``   control-point counts (n_u, n_v)
* ``koff[P, 2]``  offsets of each patch's u and v knot vectors in ``knots``
* ``coff[P]``     offset of each patch's control net in ``cpw`` (row-major, index i * n_v + j)
* ``knots[K]``    all knot vectors, concatenated
* ``cpw[C, 4]``   homogeneous control points (w x, w y, w z, w)
* ``dom[P, 4]``   parameter rectangles (u_min, u_max, v_min, v_max)
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numba import njit

from ..jit import kernel
from ._basis_unrolled import (basis_ders_2_0, basis_ders_2_1, basis_ders_2_2, basis_ders_3_0,
                              basis_ders_3_1, basis_ders_3_2)
from .nurbs import Patch

#: Highest degree the compiled kernel supports (workspace size).
MAX_DEGREE = 9
_WS_ROWS = (MAX_DEGREE + 1) + 16


def make_workspace() -> np.ndarray:
    """A workspace for :func:`patch_derivs` (one per thread)."""
    return np.zeros((_WS_ROWS, MAX_DEGREE + 1))


@kernel
def find_span(knots, k0, n, p, t):
    """Span index (relative to the patch's knot vector at offset k0) with n control points.

    The NURBS Book A2.1: knots[k] <= t < knots[k+1]; t at or beyond the end maps to n - 1.
    """
    if t >= knots[k0 + n]:
        return n - 1
    if t <= knots[k0 + p]:
        return p
    low = p
    high = n
    mid = (low + high) // 2
    while t < knots[k0 + mid] or t >= knots[k0 + mid + 1]:
        if t < knots[k0 + mid]:
            high = mid
        else:
            low = mid
        mid = (low + high) // 2
    return mid


@kernel
def basis_ders(knots, k0, span, p, t, nd, ndu, a, left, right, ders):
    """Non-zero basis functions and derivatives up to ``nd`` (The NURBS Book A2.3).

    Writes ders[k, r] = d^k/dt^k N_{span-p+r, p}(t) for k <= nd; rows k > p are zero.
    ``ndu`` (p+1, p+1), ``a`` (2, p+1), ``left``/``right`` (p+1,) are scratch.
    """
    ndu[0, 0] = 1.0
    for j in range(1, p + 1):
        left[j] = t - knots[k0 + span + 1 - j]
        right[j] = knots[k0 + span + j] - t
        saved = 0.0
        for r in range(j):
            ndu[j, r] = right[r + 1] + left[j - r]
            temp = ndu[r, j - 1] / ndu[j, r]
            ndu[r, j] = saved + right[r + 1] * temp
            saved = left[j - r] * temp
        ndu[j, j] = saved
    for j in range(p + 1):
        ders[0, j] = ndu[j, p]
    for k in range(1, nd + 1):
        for j in range(p + 1):
            ders[k, j] = 0.0
    ndmax = nd if nd < p else p
    for r in range(p + 1):
        s1 = 0
        s2 = 1
        a[0, 0] = 1.0
        for k in range(1, ndmax + 1):
            d = 0.0
            rk = r - k
            pk = p - k
            if r >= k:
                a[s2, 0] = a[s1, 0] / ndu[pk + 1, rk]
                d = a[s2, 0] * ndu[rk, pk]
            j1 = 1 if rk >= -1 else -rk
            j2 = k - 1 if r - 1 <= pk else p - r
            for j in range(j1, j2 + 1):
                a[s2, j] = (a[s1, j] - a[s1, j - 1]) / ndu[pk + 1, rk + j]
                d += a[s2, j] * ndu[rk + j, pk]
            if r <= pk:
                a[s2, k] = -a[s1, k - 1] / ndu[pk + 1, r]
                d += a[s2, k] * ndu[r, pk]
            ders[k, r] = d
            s1, s2 = s2, s1
    fac = p
    for k in range(1, ndmax + 1):
        for j in range(p + 1):
            ders[k, j] *= fac
        fac *= p - k


@kernel(inline="always")
def _basis(knots, k0, span, p, t, nd, ndu, a, left, right, ders):
    """:func:`basis_ders`, unrolled for degrees 2 and 3 (same operations, same bits)."""
    if p == 3:
        if nd == 2:
            basis_ders_3_2(knots, k0, span, t, ders)
        elif nd == 1:
            basis_ders_3_1(knots, k0, span, t, ders)
        else:
            basis_ders_3_0(knots, k0, span, t, ders)
    elif p == 2:
        if nd == 2:
            basis_ders_2_2(knots, k0, span, t, ders)
        elif nd == 1:
            basis_ders_2_1(knots, k0, span, t, ders)
        else:
            basis_ders_2_0(knots, k0, span, t, ders)
    else:
        basis_ders(knots, k0, span, p, t, nd, ndu, a, left, right, ders)


@kernel
def patch_derivs(deg, ncp, koff, coff, knots, cpw, ip, u, v, order, ws, out):
    """Point and partial derivatives of patch ``ip`` of a pool at (u, v).

    Writes ``out[0:k]`` (k = 1, 3, 6 for order 0, 1, 2) in the order
    S, S_u, S_v, S_uu, S_uv, S_vv (metres per unit parameter^k). ``ws`` from
    :func:`make_workspace`. Parameters outside the domain are clamped to it.
    """
    p = deg[ip, 0]
    q = deg[ip, 1]
    nu = ncp[ip, 0]
    nv = ncp[ip, 1]
    ku = koff[ip, 0]
    kv = koff[ip, 1]
    c0 = coff[ip]
    m = MAX_DEGREE + 1
    ndu = ws[0:m]
    a = ws[m:m + 2]
    left = ws[m + 2]
    right = ws[m + 3]
    Nu = ws[m + 4:m + 7]
    Nv = ws[m + 7:m + 10]
    umin = knots[ku + p]
    umax = knots[ku + nu]
    vmin = knots[kv + q]
    vmax = knots[kv + nv]
    if u < umin:
        u = umin
    elif u > umax:
        u = umax
    if v < vmin:
        v = vmin
    elif v > vmax:
        v = vmax
    su = find_span(knots, ku, nu, p, u)
    sv = find_span(knots, kv, nv, q, v)
    _basis(knots, ku, su, p, u, order, ndu, a, left, right, Nu)
    _basis(knots, kv, sv, q, v, order, ndu, a, left, right, Nv)
    # homogeneous sums A_kl (x, y, z, w) for (k,l) in (0,0),(1,0),(0,1),(2,0),(1,1),(0,2):
    # scalar accumulators, summed in the same order as rows of a workspace would be (same
    # bits) but kept in registers (a row of ``ws`` may alias ``cpw`` for the compiler)
    x00 = y00 = z00 = w00 = 0.0
    x10 = y10 = z10 = w10 = 0.0
    x01 = y01 = z01 = w01 = 0.0
    x20 = y20 = z20 = w20 = 0.0
    x11 = y11 = z11 = w11 = 0.0
    x02 = y02 = z02 = w02 = 0.0
    for i in range(p + 1):
        row = c0 + (su - p + i) * nv + (sv - q)
        for j in range(q + 1):
            idx = row + j
            cx = cpw[idx, 0]
            cy = cpw[idx, 1]
            cz = cpw[idx, 2]
            cw = cpw[idx, 3]
            n00 = Nu[0, i] * Nv[0, j]
            x00 += n00 * cx
            y00 += n00 * cy
            z00 += n00 * cz
            w00 += n00 * cw
            if order >= 1:
                n10 = Nu[1, i] * Nv[0, j]
                n01 = Nu[0, i] * Nv[1, j]
                x10 += n10 * cx
                y10 += n10 * cy
                z10 += n10 * cz
                w10 += n10 * cw
                x01 += n01 * cx
                y01 += n01 * cy
                z01 += n01 * cz
                w01 += n01 * cw
            if order >= 2:
                n20 = Nu[2, i] * Nv[0, j]
                n11 = Nu[1, i] * Nv[1, j]
                n02 = Nu[0, i] * Nv[2, j]
                x20 += n20 * cx
                y20 += n20 * cy
                z20 += n20 * cz
                w20 += n20 * cw
                x11 += n11 * cx
                y11 += n11 * cy
                z11 += n11 * cz
                w11 += n11 * cw
                x02 += n02 * cx
                y02 += n02 * cy
                z02 += n02 * cz
                w02 += n02 * cw
    _rational_derivs(order, x00, y00, z00, w00, x10, y10, z10, w10, x01, y01, z01, w01,
                     x20, y20, z20, w20, x11, y11, z11, w11, x02, y02, z02, w02, out)


@kernel
def _rational_derivs(order, x00, y00, z00, w00, x10, y10, z10, w10, x01, y01, z01, w01,
                     x20, y20, z20, w20, x11, y11, z11, w11, x02, y02, z02, w02, out):
    """S, S_u, S_v, S_uu, S_uv, S_vv (rows of ``out``) from the homogeneous sums A_kl =
    (x, y, z, w)_kl (quotient rule, The NURBS Book Eq. 4.8)."""
    out[0, 0] = x00 / w00
    out[0, 1] = y00 / w00
    out[0, 2] = z00 / w00
    if order < 1:
        return
    for c in range(3):
        a10 = x10 if c == 0 else (y10 if c == 1 else z10)
        a01 = x01 if c == 0 else (y01 if c == 1 else z01)
        out[1, c] = (a10 - w10 * out[0, c]) / w00
        out[2, c] = (a01 - w01 * out[0, c]) / w00
    if order < 2:
        return
    for c in range(3):
        a20 = x20 if c == 0 else (y20 if c == 1 else z20)
        a11 = x11 if c == 0 else (y11 if c == 1 else z11)
        a02 = x02 if c == 0 else (y02 if c == 1 else z02)
        out[3, c] = (a20 - 2.0 * w10 * out[1, c] - w20 * out[0, c]) / w00
        out[4, c] = (a11 - w10 * out[2, c] - w01 * out[1, c] - w11 * out[0, c]) / w00
        out[5, c] = (a02 - 2.0 * w01 * out[2, c] - w02 * out[0, c]) / w00


@njit(cache=True)
def patch_derivs_many(deg, ncp, koff, coff, knots, cpw, ip, u, v, order, out):
    """Loop of :func:`patch_derivs` over arrays u, v (for benchmarks and tests); out (m, 6, 3)."""
    ws = np.zeros((_WS_ROWS, MAX_DEGREE + 1))
    for k in range(u.shape[0]):
        patch_derivs(deg, ncp, koff, coff, knots, cpw, ip, u[k], v[k], order, ws, out[k])


@dataclass
class PatchPool:
    """Flat-array storage of many patches (see module docstring for the layout)."""

    deg: np.ndarray
    ncp: np.ndarray
    koff: np.ndarray
    coff: np.ndarray
    knots: np.ndarray
    cpw: np.ndarray
    dom: np.ndarray

    @classmethod
    def from_patches(cls, patches: Sequence[Patch]) -> "PatchPool":
        """Pack patches (validated beforehand) into flat arrays, in the given order."""
        for pt in patches:
            if max(pt.degree_u, pt.degree_v) > MAX_DEGREE:
                raise ValueError(f"degree above {MAX_DEGREE} is not supported by the compiled kernel")
        P = len(patches)
        deg = np.zeros((P, 2), np.int64)
        ncp = np.zeros((P, 2), np.int64)
        koff = np.zeros((P, 2), np.int64)
        coff = np.zeros(P, np.int64)
        dom = np.zeros((P, 4))
        knots, cpw = [], []
        k = c = 0
        for i, pt in enumerate(patches):
            deg[i] = pt.degree_u, pt.degree_v
            ncp[i] = pt.shape
            koff[i] = k, k + len(pt.knots_u)
            knots += [pt.knots_u, pt.knots_v]
            k += len(pt.knots_u) + len(pt.knots_v)
            coff[i] = c
            cpw.append(pt.homogeneous.reshape(-1, 4))
            c += pt.shape[0] * pt.shape[1]
            dom[i] = pt.domain
        return cls(deg, ncp, koff, coff, np.concatenate(knots) if knots else np.zeros(0),
                   np.concatenate(cpw) if cpw else np.zeros((0, 4)), dom)

    @property
    def arrays(self) -> tuple:
        """(deg, ncp, koff, coff, knots, cpw): the leading arguments of :func:`patch_derivs`."""
        return self.deg, self.ncp, self.koff, self.coff, self.knots, self.cpw

    def evaluate(self, ip: int, u, v, order: int = 2) -> np.ndarray:
        """Compiled evaluation at many points of patch ``ip``: array (m, 6, 3) (unused slots zero)."""
        u = np.ascontiguousarray(np.atleast_1d(u), dtype=float)
        v = np.ascontiguousarray(np.atleast_1d(v), dtype=float)
        out = np.zeros((u.size, 6, 3))
        patch_derivs_many(*self.arrays, ip, u, v, order, out)
        return out

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

The contact hot loop evaluates patches in **power (Taylor) form** instead
(:func:`power_form`, :func:`power_derivs`): each non-empty knot span of a patch is one
polynomial in homogeneous coordinates, stored as its Taylor coefficients about the span's
centre, ``Pw(u, v) = sum_ab C_ab (u - u_c)^a (v - v_c)^b`` (The NURBS Book Sec. 6.6, the
B-spline to power-basis conversion, here by A2.3's derivatives at the centre). An
evaluation is then two Horner schemes with derivatives (no basis recursion, no division
before the rational quotient rule): 1.5 x faster for the paper's bicubic patches, 2.9 x for
the sphere's rational biquartic ones (``benchmarks/bench_kernel.py``), equal to A2.3's path
within 1e-14 relative (``tests/test_kernel.py``; centring keeps ``|u - u_c|`` at half a span,
so even degree 9 stays there). Table layout (R rows):

* ``pw[R, 4]``    coefficients C_ab (w x, w y, w z, w) per span, row
  ``poff[ip] + ((su - p) * (n_v - q) + (sv - q)) * (p + 1) * (q + 1) + a * (q + 1) + b``
  for the span (su, sv) of :func:`find_span` (empty spans keep zero rows; never selected)
* ``poff[P]``     first row of each patch
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numba import njit

from ..jit import kernel
from ._basis_unrolled import (basis_ders_2_0, basis_ders_2_1, basis_ders_2_2, basis_ders_3_0,
                              basis_ders_3_1, basis_ders_3_2)
from .nurbs import Patch, basis_functions_derivs

#: Highest degree the compiled kernel supports (workspace size).
MAX_DEGREE = 9
_WS_ROWS = (MAX_DEGREE + 1) + 16


@njit(cache=True)
def make_workspace() -> np.ndarray:
    """A workspace for :func:`patch_derivs` (one per thread; compiled: the threads of a
    parallel batch make theirs)."""
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
    p, q, nu, nv, ku, kv = _patch_dims(deg, ncp, koff, ip)
    c0 = coff[ip]
    m = MAX_DEGREE + 1
    ndu = ws[0:m]
    a = ws[m:m + 2]
    left = ws[m + 2]
    right = ws[m + 3]
    Nu = ws[m + 4:m + 7]
    Nv = ws[m + 7:m + 10]
    u = _clamp(u, knots[ku + p], knots[ku + nu])
    v = _clamp(v, knots[kv + q], knots[kv + nv])
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


@kernel
def power_derivs(deg, ncp, koff, knots, pw, poff, ip, u, v, order, out):
    """:func:`patch_derivs` from the power form of the patch (module docstring): the same
    rows S, S_u, S_v, S_uu, S_uv, S_vv of ``out`` (metres per unit parameter^k) within
    round-off. Parameters outside the domain are clamped to it."""
    p, q, nu, nv, ku, kv = _patch_dims(deg, ncp, koff, ip)
    u = _clamp(u, knots[ku + p], knots[ku + nu])
    v = _clamp(v, knots[kv + q], knots[kv + nv])
    su = find_span(knots, ku, nu, p, u)
    sv = find_span(knots, kv, nv, q, v)
    s = u - 0.5 * (knots[ku + su] + knots[ku + su + 1])
    t = v - 0.5 * (knots[kv + sv] + knots[kv + sv + 1])
    first = poff[ip] + ((su - p) * (nv - q) + (sv - q)) * (p + 1) * (q + 1)
    # Horner in u over the rows a of Horner sums in v: A_kl (x, y, z, w) accumulate the
    # k-th u- and l-th v-derivative divided by k! l! (the Taylor coefficients' scaling)
    x00 = y00 = z00 = w00 = 0.0
    x10 = y10 = z10 = w10 = 0.0
    x01 = y01 = z01 = w01 = 0.0
    x20 = y20 = z20 = w20 = 0.0
    x11 = y11 = z11 = w11 = 0.0
    x02 = y02 = z02 = w02 = 0.0
    for a in range(p, -1, -1):
        row = first + a * (q + 1)
        # the row's polynomial in v and its first two derivatives (the second halved)
        fx0 = fy0 = fz0 = fw0 = 0.0
        fx1 = fy1 = fz1 = fw1 = 0.0
        fx2 = fy2 = fz2 = fw2 = 0.0
        for b in range(q, -1, -1):
            fx2 = fx2 * t + fx1
            fy2 = fy2 * t + fy1
            fz2 = fz2 * t + fz1
            fw2 = fw2 * t + fw1
            fx1 = fx1 * t + fx0
            fy1 = fy1 * t + fy0
            fz1 = fz1 * t + fz0
            fw1 = fw1 * t + fw0
            fx0 = fx0 * t + pw[row + b, 0]
            fy0 = fy0 * t + pw[row + b, 1]
            fz0 = fz0 * t + pw[row + b, 2]
            fw0 = fw0 * t + pw[row + b, 3]
        x20 = x20 * s + x10
        y20 = y20 * s + y10
        z20 = z20 * s + z10
        w20 = w20 * s + w10
        x10 = x10 * s + x00
        y10 = y10 * s + y00
        z10 = z10 * s + z00
        w10 = w10 * s + w00
        x00 = x00 * s + fx0
        y00 = y00 * s + fy0
        z00 = z00 * s + fz0
        w00 = w00 * s + fw0
        x11 = x11 * s + x01
        y11 = y11 * s + y01
        z11 = z11 * s + z01
        w11 = w11 * s + w01
        x01 = x01 * s + fx1
        y01 = y01 * s + fy1
        z01 = z01 * s + fz1
        w01 = w01 * s + fw1
        x02 = x02 * s + fx2
        y02 = y02 * s + fy2
        z02 = z02 * s + fz2
        w02 = w02 * s + fw2
    _rational_derivs(order, x00, y00, z00, w00, x10, y10, z10, w10, x01, y01, z01, w01,
                     2.0 * x20, 2.0 * y20, 2.0 * z20, 2.0 * w20, x11, y11, z11, w11,
                     2.0 * x02, 2.0 * y02, 2.0 * z02, 2.0 * w02, out)


@kernel(inline="always")
def _patch_dims(deg, ncp, koff, ip):
    """(p, q, n_u, n_v, u-knot offset, v-knot offset) of patch ``ip`` of a pool."""
    return deg[ip, 0], deg[ip, 1], ncp[ip, 0], ncp[ip, 1], koff[ip, 0], koff[ip, 1]


@kernel(inline="always")
def _clamp(x, lo, hi):
    """x clamped to [lo, hi]."""
    if x < lo:
        return lo
    if x > hi:
        return hi
    return x


def power_form(pool: "PatchPool") -> tuple[np.ndarray, np.ndarray]:
    """The power-form table ``(pw, poff)`` of a pool (module docstring): for each span, the
    Taylor coefficients about its centre, ``C_ab = sum_ij N_i^(a)(u_c) / a! N_j^(b)(v_c) / b!
    Pw_ij`` (A2.3's derivatives up to the degree; exact for the span's polynomial)."""
    blocks, poff = [], np.zeros(pool.deg.shape[0], np.int64)
    rows = 0
    for ip in range(pool.deg.shape[0]):
        (p, q), (nu, nv) = pool.deg[ip], pool.ncp[ip]
        U = pool.knots[pool.koff[ip, 0]:pool.koff[ip, 0] + nu + p + 1]
        V = pool.knots[pool.koff[ip, 1]:pool.koff[ip, 1] + nv + q + 1]
        net = pool.cpw[pool.coff[ip]:pool.coff[ip] + nu * nv].reshape(nu, nv, 4)
        poff[ip] = rows
        taylor_v_of = [_span_taylor(V, q, sv) for sv in range(q, nv)]
        for su in range(p, nu):
            taylor_u = _span_taylor(U, p, su)
            for sv, taylor_v in zip(range(q, nv), taylor_v_of):
                c = np.zeros((p + 1, q + 1, 4))
                if taylor_u is not None and taylor_v is not None:
                    c = np.einsum("ai,bj,ijc->abc", taylor_u, taylor_v,
                                  net[su - p:su + 1, sv - q:sv + 1])
                blocks.append(c.reshape(-1, 4))
                rows += (p + 1) * (q + 1)
    pw = np.concatenate(blocks) if blocks else np.zeros((0, 4))
    return np.ascontiguousarray(pw), poff


def _span_taylor(knots: np.ndarray, p: int, span: int) -> np.ndarray | None:
    """(p+1, p+1): row a holds N_{span-p+r}^(a)(t_c) / a! at the span's centre t_c (the
    Taylor coefficients of the span's basis polynomials), or None for an empty span."""
    if not knots[span + 1] > knots[span]:
        return None
    centre = 0.5 * (knots[span] + knots[span + 1])
    _, ders = basis_functions_derivs(knots, p, centre, p, np.array([span]))
    return ders[0] / np.array([math.factorial(a) for a in range(p + 1)])[:, None]


@njit(cache=True)
def patch_derivs_many(deg, ncp, koff, coff, knots, cpw, ip, u, v, order, out):
    """Loop of :func:`patch_derivs` over arrays u, v (for benchmarks and tests); out (m, 6, 3)."""
    ws = np.zeros((_WS_ROWS, MAX_DEGREE + 1))
    for k in range(u.shape[0]):
        patch_derivs(deg, ncp, koff, coff, knots, cpw, ip, u[k], v[k], order, ws, out[k])


@njit(cache=True)
def power_derivs_many(deg, ncp, koff, knots, pw, poff, ip, u, v, order, out):
    """Loop of :func:`power_derivs` over arrays u, v (for benchmarks and tests); out (m, 6, 3)."""
    for k in range(u.shape[0]):
        power_derivs(deg, ncp, koff, knots, pw, poff, ip, u[k], v[k], order, out[k])


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

    def evaluate(self, ip: int, u, v, order: int = 2, power: bool = False) -> np.ndarray:
        """Compiled evaluation at many points of patch ``ip``: array (m, 6, 3) (unused slots
        zero); by A2.3 (:func:`patch_derivs`) or, with ``power``, from the power form
        (:func:`power_derivs`, what the contact kernels evaluate)."""
        u = np.ascontiguousarray(np.atleast_1d(u), dtype=float)
        v = np.ascontiguousarray(np.atleast_1d(v), dtype=float)
        out = np.zeros((u.size, 6, 3))
        if power:
            pw, poff = power_form(self)
            power_derivs_many(self.deg, self.ncp, self.koff, self.knots, pw, poff, ip, u, v,
                              order, out)
        else:
            patch_derivs_many(*self.arrays, ip, u, v, order, out)
        return out

"""Benchmark of the global contact search (paper Section 3.1).

1. Level 1, :func:`nurbsdem.contact.broadphase.sphere_pairs` (bounding spheres, Eq. 3) on N
   random polydisperse spheres at ~30 % volume fraction, N = 1e2 ... 1e5: time per call,
   pairs found, mismatches against scipy's cKDTree (all N) and against brute force
   (N <= 1e4), and time per particle to show the ~linear scaling.
2. A rebuild that renews few bodies: :func:`~nurbsdem.contact.broadphase.sphere_pairs_of`
   (the pairs with a renewed body only) at 1 ... 30 % of the bodies renewed, against the
   full search: time per call and mismatches against the full search's pairs that hold a
   renewed body (must be 0).
3. Level 2: cost of one oriented-box separating-axis test, and of the candidate patch pairs
   of one body pair (6 x 6 patch boxes of exact spheres) through the batch kernel.

Run: ``.venv/bin/python benchmarks/bench_broadphase.py [--quick]``
"""
from __future__ import annotations

import argparse
import time

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from nurbsdem.contact.boxes import (_relative, _sat, candidate_patch_pairs_batch,
                                    pack_boxes)
from nurbsdem.contact.broadphase import sphere_pairs, sphere_pairs_brute, sphere_pairs_of


def make_spheres(n: int, phi: float = 0.3, ratio: float = 3.0, seed: int = 0):
    """n spheres, radii uniform in [r0, ratio r0] (r0 = 1 mm), in a cube sized for volume
    fraction phi (overlaps allowed: random positions)."""
    rng = np.random.default_rng(seed)
    r = 1e-3 * rng.uniform(1.0, ratio, n)
    L = (4.0 / 3.0 * np.pi * np.sum(r ** 3) / phi) ** (1.0 / 3.0)
    return rng.uniform(0.0, L, (n, 3)), r


def kdtree_pairs(c: np.ndarray, r: np.ndarray, margin: float) -> np.ndarray:
    """Reference pairs by cKDTree (candidate radius 2 r_max + margin, then exact Eq. 3)."""
    t = cKDTree(c)
    p = t.query_pairs(2 * r.max() + margin, output_type="ndarray").astype(np.int64)
    p.sort(axis=1)
    d = np.linalg.norm(c[p[:, 0]] - c[p[:, 1]], axis=1)
    s = r[p[:, 0]] + r[p[:, 1]] + margin
    p = p[d * d < s * s]
    return p[np.lexsort((p[:, 1], p[:, 0]))]


def brute_chunked(c: np.ndarray, r: np.ndarray, margin: float) -> np.ndarray:
    """O(N^2) reference in row blocks (same comparison as sphere_pairs)."""
    n = len(c)
    if n <= 2000:
        return sphere_pairs_brute(c, r, margin)
    out = []
    for i0 in range(0, n, 500):
        i1 = min(n, i0 + 500)
        d = c[i0:i1, None, :] - c[None, :, :]
        d2 = np.einsum("ijk,ijk->ij", d, d)
        s = r[i0:i1, None] + r[None, :] + margin
        ii, jj = np.nonzero((d2 < s * s) & (np.arange(n)[None, :] > np.arange(i0, i1)[:, None]))
        out.append(np.stack([ii + i0, jj], 1))
    return np.concatenate(out).astype(np.int64)


def mismatches(a: np.ndarray, b: np.ndarray) -> int:
    sa = {tuple(x) for x in a}
    sb = {tuple(x) for x in b}
    return len(sa ^ sb)


def timeit(f, repeat: int) -> float:
    """Best of ``repeat`` calls, in CPU seconds of this process (time.process_time: the
    kernels are single-threaded, and CPU time is robust to other jobs sharing the cores)."""
    best = np.inf
    for _ in range(repeat):
        t0 = time.process_time()
        f()
        best = min(best, time.process_time() - t0)
    return best


def bench_level1(sizes, ratio: float, margin_rel: float = 0.1) -> None:
    print(f"\nLevel 1: sphere_pairs, volume fraction 0.30, radii uniform in [1, {ratio:g}] mm, "
          f"margin = {margin_rel:g} * r_min")
    print(f"{'N':>8} {'pairs':>9} {'t/call ms':>10} {'ns/particle':>12} "
          f"{'cKDTree ms':>11} {'err vs kd':>9} {'brute ms':>9} {'err vs brute':>12}")
    sphere_pairs(*make_spheres(10, ratio=ratio))  # compile
    for n in sizes:
        c, r = make_spheres(n, ratio=ratio, seed=n)
        m = margin_rel * r.min()
        rep = 5 if n <= 10_000 else 3
        t = timeit(lambda: sphere_pairs(c, r, m), rep)
        got = sphere_pairs(c, r, m)
        tk = timeit(lambda: kdtree_pairs(c, r, m), rep)
        ek = mismatches(got, kdtree_pairs(c, r, m))
        if n <= 10_000:
            tb = timeit(lambda: brute_chunked(c, r, m), 1)
            eb = f"{mismatches(got, brute_chunked(c, r, m)):12d}"
            tbs = f"{tb * 1e3:9.1f}"
        else:
            tbs, eb = f"{'-':>9}", f"{'-':>12}"
        print(f"{n:8d} {len(got):9d} {t * 1e3:10.3f} {t / n * 1e9:12.0f} {tk * 1e3:11.2f} "
              f"{ek:9d} {tbs} {eb}")


def bench_renewed(n: int, ratio: float = 3.0, margin_rel: float = 0.1) -> None:
    """sphere_pairs_of at a few fractions of renewed bodies against the full search."""
    c, r = make_spheres(n, ratio=ratio, seed=n)
    m = margin_rel * r.min()
    every = sphere_pairs(c, r, m)
    t_all = timeit(lambda: sphere_pairs(c, r, m), 3)
    rng = np.random.default_rng(3)
    print(f"\nA rebuild renewing few of N = {n} bodies: sphere_pairs_of against the full "
          f"search ({t_all * 1e3:.2f} ms, {len(every)} pairs)")
    print(f"{'renewed':>8} {'pairs':>8} {'t/call ms':>10} {'x full':>7} {'mismatches':>11}")
    for frac in (0.01, 0.05, 0.1, 0.3):
        fresh = rng.random(n) < frac
        want = every[fresh[every[:, 0]] | fresh[every[:, 1]]]
        t = timeit(lambda: sphere_pairs_of(c, r, m, fresh), 3)
        got = sphere_pairs_of(c, r, m, fresh)
        print(f"{frac:8.0%} {len(got):8d} {t * 1e3:10.2f} {t / t_all:7.2f} "
              f"{mismatches(got, want):11d}")


@njit(cache=True)
def _sat_loop(axes_a, axes_b, t, ha, hb):
    """Full OBB test (relative rotation + 15 axes) for each of M box pairs."""
    R = np.empty((3, 3))
    AbsR = np.empty((3, 3))
    hits = 0
    for m in range(t.shape[0]):
        _relative(axes_a[m], axes_b[m], R, AbsR)
        if _sat(t[m], R, AbsR, ha[m], hb[m]):
            hits += 1
    return hits


def bench_level2(quick: bool) -> None:
    from scipy.spatial.transform import Rotation
    from nurbsdem.shapes import sphere

    rng = np.random.default_rng(1)
    M = 200_000 if quick else 1_000_000
    A = Rotation.random(M, random_state=rng).as_matrix()
    B = Rotation.random(M, random_state=rng).as_matrix()
    ha = rng.uniform(0.2, 1.0, (M, 3))
    hb = rng.uniform(0.2, 1.0, (M, 3))
    t = rng.normal(size=(M, 3)) * 1.2
    _sat_loop(A[:10], B[:10], t[:10], ha[:10], hb[:10])
    tt = timeit(lambda: _sat_loop(A, B, t, ha, hb), 3)
    hits = _sat_loop(A, B, t, ha, hb)
    print(f"\nLevel 2: OBB separating-axis test (incl. R = A^T B): {tt / M * 1e9:.1f} ns per box "
          f"pair ({M} random pairs, {hits / M:.0%} overlapping)")

    # candidate patch pairs of body pairs: exact spheres (6 patches), touching pairs
    r = 0.01
    boxes, off = pack_boxes([sphere(r)])
    K = 20_000 if quick else 100_000
    pos = np.zeros((2 * K, 3))
    d = rng.normal(size=(K, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    pos[1::2] = d * (2 * r - 1e-4)
    rot = Rotation.random(2 * K, random_state=rng).as_matrix()
    pairs = np.arange(2 * K).reshape(K, 2)
    shp = np.zeros(2 * K, np.int64)
    candidate_patch_pairs_batch(boxes, off, shp, pos[:4], rot[:4], pairs[:2], 1e-4)
    tb = timeit(lambda: candidate_patch_pairs_batch(boxes, off, shp, pos, rot, pairs, 1e-4), 3)
    got = candidate_patch_pairs_batch(boxes, off, shp, pos, rot, pairs, 1e-4)
    print(f"candidate_patch_pairs_batch, touching sphere pairs (6x6 boxes): "
          f"{tb / K * 1e6:.2f} us per body pair, {len(got) / K:.2f} candidate patch pairs "
          f"per body pair (of 36)")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="N up to 1e4 only")
    a = ap.parse_args()
    sizes = [100, 1_000, 10_000] if a.quick else [100, 1_000, 10_000, 100_000]
    bench_level1(sizes, ratio=3.0)
    bench_level1(sizes[-2:], ratio=30.0)
    bench_renewed(sizes[-1])
    bench_level2(a.quick)


if __name__ == "__main__":
    main()

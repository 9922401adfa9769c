"""NURBS kernel cost and accuracy: one point with second derivatives.

Prints, for a bicubic 6x6 patch (the paper's particles) and the rational biquartic sphere
face, the time per evaluation of (S, S_u, S_v, S_uu, S_uv, S_vv) in the compiled scalar path
by A2.3 (one core), in the power form the contact kernels evaluate
(:func:`nurbsdem.geometry.kernel.power_derivs`) and in the vectorised path, with the error of
each against an independent value: the compiled paths against the vectorised one, and the
sphere's points against the exact radius.  Then the cost of the shape check of a deck's shape (``check_shape``: connectivity
of the patches, convexity) on the exact NURBS sphere, with the connectivity it finds.

Run: ``.venv/bin/python benchmarks/bench_kernel.py``
"""
from __future__ import annotations

import time

import numpy as np

from nurbsdem.geometry.generators import sphere_patches
from nurbsdem.geometry.kernel import (PatchPool, patch_derivs_many, power_derivs_many,
                                      power_form)
from nurbsdem.geometry.nurbs import Patch


def bicubic_patch() -> Patch:
    rng = np.random.default_rng(0)
    knots = np.array([0, 0, 0, 0, 2 / 3, 4 / 3, 2, 2, 2, 2], float)
    return Patch(3, 3, knots, knots, rng.normal(size=(6, 6, 3)))


def time_compiled(pool: PatchPool, u, v, repeats: int = 5,
                  power: bool = False) -> tuple[float, np.ndarray]:
    out = np.zeros((u.size, 6, 3))
    if power:
        pw, poff = power_form(pool)
        args = (pool.deg, pool.ncp, pool.koff, pool.knots, pw, poff)
        run = power_derivs_many
    else:
        args, run = pool.arrays, patch_derivs_many
    run(*args, 0, u[:10], v[:10], 2, out[:10])  # compile / load cache
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        run(*args, 0, u, v, 2, out)
        best = min(best, time.perf_counter() - t0)
    return best / u.size, out


def time_vectorised(patch: Patch, u, v, repeats: int = 3) -> tuple[float, np.ndarray]:
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        res = patch.evaluate(u, v, 2)
        best = min(best, time.perf_counter() - t0)
    return best / u.size, res


def main() -> None:
    rng = np.random.default_rng(1)
    rows = []
    for label, patch in (("bicubic 6x6 (paper particle)", bicubic_patch()),
                         ("rational biquartic (sphere face)", sphere_patches(1.0)[0])):
        u0, u1, v0, v1 = patch.domain
        n = 200_000
        u, v = rng.uniform(u0, u1, n), rng.uniform(v0, v1, n)
        pool = PatchPool.from_patches([patch])
        tc, comp = time_compiled(pool, u, v)
        tp, powr = time_compiled(pool, u, v, power=True)
        tv, vec = time_vectorised(patch, u, v)
        scale = np.abs(vec).max()
        diff, pdiff = np.abs(comp - vec).max() / scale, np.abs(powr - vec).max() / scale
        extra = ""
        if "sphere" in label:
            extra = "  max | |S| - 1 |: A2.3 {:.1e}, power {:.1e}".format(
                *(np.abs(np.linalg.norm(x[:, 0], axis=1) - 1).max() for x in (comp, powr)))
        rows.append((label, tc * 1e9, tp * 1e9, tv * 1e9, diff, pdiff, extra))
    print(f"{'patch':34s} {'A2.3 ns/pt':>11s} {'power ns/pt':>12s} {'vectorised':>11s} "
          f"{'A2.3 diff':>10s} {'power diff':>11s}")
    for label, tc, tp, tv, diff, pdiff, extra in rows:
        print(f"{label:34s} {tc:11.0f} {tp:12.0f} {tv:11.0f} {diff:10.1e} {pdiff:11.1e}{extra}")
    time_shape_check()


def time_shape_check(repeats: int = 5) -> None:
    """Time of check_shape + find_connectivity of the exact sphere (6 rational patches): what a
    deck pays per shape before anything runs."""
    from nurbsdem.geometry.connectivity import check_shape, find_connectivity
    from nurbsdem.geometry.generators import sphere
    sh = sphere(0.5)
    check_shape(sh)
    t0 = time.perf_counter()
    for _ in range(repeats):
        check_shape(sh)
        conn = find_connectivity(sh.patches)
    per = (time.perf_counter() - t0) / repeats
    print(f"shape check of the exact sphere (6 patches): {per * 1e3:.1f} ms "
          f"(closed: {conn.closed}, {len(conn.corners)} corners)")


if __name__ == "__main__":
    main()

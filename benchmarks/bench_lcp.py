"""Benchmark of the compiled LCP (``nurbsdem.contact``): speed and accuracy side by side.

For three pair types — exact 6-patch spheres, exact ellipsoids, the paper's particle A
against A — it prints, on one thread:

* the median µs per LCP, cold (no previous solution) and warm-started (previous solution of
  the same pair one "time step" earlier: displacement 1e-4 × size, rotation 2e-3 rad),
* per regime: the share of results produced by stage 1 (f1, separated pairs) and by stage 2
  (directions, penetrating pairs and stage-1 fallbacks), the stage-1 iterations, and the
  median µs of the timed pairs of each kind (cold and warm),
* the median (max) Newton iterations on the direction sphere and patch evaluations,
* the error of the signed distance (relative to the radius) and of the normal (rad)
  against the independent references of :mod:`nurbsdem.contact.reference` (analytic for
  spheres and ellipsoids, dense sampling + SciPy for the particle).

Run: ``.venv/bin/python benchmarks/bench_lcp.py [--pairs N] [--ref M] [--threads T]
[--range LO HI]``.
"""
from __future__ import annotations

import argparse
import time

import numpy as np
import numba
from scipy.spatial.transform import Rotation

from nurbsdem.contact import ContactTable, detect_batch
from nurbsdem.contact.lcp import F_IT1, F_N, F_SD, I_FAIL, I_IT, I_NEV, I_DEG, I_STAGE, NF, NI
from nurbsdem.contact import reference as ref
from nurbsdem.geometry.generators import ellipsoid, sphere


def _configs(table, sid_a, sid_b, n, rng, depth_range):
    """n poses of two bodies with target signed distances (placed by translating B along
    the contact normal, two corrections)."""
    ra = table.radius[sid_a]
    rb = table.radius[sid_b]
    Ra = Rotation.random(n, random_state=rng).as_matrix()
    Rb = Rotation.random(n, random_state=rng).as_matrix()
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    ca = table.centroid[sid_a]
    cb = table.centroid[sid_b]
    pa = -np.einsum("kij,j->ki", Ra, ca)
    pb = 0.9 * (ra + rb) * u - np.einsum("kij,j->ki", Rb, cb)
    target = rng.uniform(*depth_range, size=n) * min(ra, rb)
    sa = np.full(n, sid_a)
    sb = np.full(n, sid_b)
    for _ in range(3):
        f, i = detect_batch(table, sa, pa, Ra, sb, pb, Rb)
        pb = pb + (target - f[:, F_SD])[:, None] * f[:, F_N:F_N + 3]
    return sa, pa, Ra, sb, pb, Rb


def _step(rng, pa, Ra, pb, Rb, size):
    """The same poses one time step earlier (small displacement and rotation)."""
    n = len(pa)
    dr = lambda: Rotation.from_rotvec(rng.normal(size=(n, 3)) * 2e-3).as_matrix()  # noqa: E731
    return (pa + rng.normal(size=(n, 3)) * 1e-4 * size, np.einsum("kij,kjl->kil", dr(), Ra),
            pb + rng.normal(size=(n, 3)) * 1e-4 * size, np.einsum("kij,kjl->kil", dr(), Rb))


def _times_us(table, cfg, prev, n_time, repeats):
    """µs per LCP of each of the first n_time pairs (each solved ``repeats`` times)."""
    sa, pa, Ra, sb, pb, Rb = cfg
    times = []
    for k in range(min(n_time, len(sa))):
        idx = np.full(repeats, k)
        args = (table, sa[idx], pa[idx], Ra[idx], sb[idx], pb[idx], Rb[idx])
        pf = pi = None
        if prev is not None:
            pf, pi = prev[0][idx], prev[1][idx]
        out = (np.zeros((repeats, NF)), np.zeros((repeats, NI), np.int64))
        detect_batch(*args, pf, pi, out=out)
        t = time.perf_counter()
        detect_batch(*args, pf, pi, out=out)
        times.append((time.perf_counter() - t) / repeats * 1e6)
    return np.array(times)


def run(n_pairs: int, n_ref: int, n_time: int, repeats: int, seed: int = 0,
        depth_range: tuple[float, float] = (-0.05, 0.01)) -> None:
    from nurbsdem.geometry.particles import paper_particle_shape

    rng = np.random.default_rng(seed)
    r = 0.02
    axes = (0.03, 0.02, 0.012)
    shapes = [sphere(r), ellipsoid(*axes), paper_particle_shape("A")]
    table = ContactTable(shapes)
    print(f"threads: {numba.get_num_threads()}; pairs per type: {n_pairs}; signed distances {100 * depth_range[0]:g} % .. {100 * depth_range[1]:g} % of the radius")
    print(f"{'pair':10s} {'cold µs':>8s} {'warm µs':>8s} {'it cold':>8s} {'it warm':>8s} "
          f"{'ev cold':>8s} {'ev warm':>8s} {'|Δsd|/r':>9s} {'normal rad':>10s} {'deg %':>6s} {'fail':>5s}")
    for name, s in (("sphere", 0), ("ellipsoid", 1), ("A-A", 2)):
        cfg = _configs(table, s, s, n_pairs, rng, depth_range)
        sa, pa, Ra, sb, pb, Rb = cfg
        size = float(table.radius[s])
        prev_pose = _step(rng, pa, Ra, pb, Rb, size)
        prev = detect_batch(table, sa, prev_pose[0], prev_pose[1], sb, prev_pose[2], prev_pose[3])
        cold = detect_batch(table, *cfg[:])
        warm = detect_batch(table, *cfg, prev[0], prev[1])
        t_cold = _times_us(table, cfg, None, n_time, repeats)
        t_warm = _times_us(table, cfg, prev, n_time, repeats)
        us_cold = float(np.median(t_cold))
        us_warm = float(np.median(t_warm))
        # accuracy against the references
        errs, angs = [], []
        for k in range(min(n_ref, n_pairs)):
            pose_a = (pa[k], Ra[k])
            pose_b = (pb[k], Rb[k])
            if name == "sphere":
                dc = pb[k] - pa[k]
                dist = np.linalg.norm(dc)
                sd_ref, n_ref_ = dist - 2 * r, dc / dist
            elif name == "ellipsoid":
                sd_ref, n_ref_, _, _ = ref.ellipsoid_pair(axes, pose_a, axes, pose_b)
            else:
                sd_ref, n_ref_, _, _ = ref.nurbs_pair(shapes[2], pose_a, shapes[2], pose_b)
            errs.append(abs(warm[0][k, F_SD] - sd_ref) / size)
            angs.append(np.linalg.norm(np.cross(warm[0][k, F_N:F_N + 3], n_ref_)))
        ic, iw = cold[1][:, I_IT], warm[1][:, I_IT]
        print(f"{name:10s} {us_cold:8.1f} {us_warm:8.1f} {np.median(ic):4.0f}({ic.max():2d}) "
              f"{np.median(iw):4.0f}({iw.max():2d}) {np.median(cold[1][:, I_NEV]):8.0f} "
              f"{np.median(warm[1][:, I_NEV]):8.0f} {max(errs):9.1e} {max(angs):10.1e} "
              f"{100 * np.mean(warm[1][:, I_DEG] > 0):6.2f} {int(cold[1][:, I_FAIL].sum() + warm[1][:, I_FAIL].sum()):5d}")
        same = np.abs(cold[0][:, F_SD] - warm[0][:, F_SD]).max() / size
        print(f"{'':10s} cold vs warm max |Δsd|/r = {same:.1e}")
        nt = len(t_cold)
        for lab, res, tt in (("cold", cold, t_cold), ("warm", warm, t_warm)):
            st = res[1][:, I_STAGE]
            sep = res[0][:, F_SD] > 0
            it1 = res[0][:, F_IT1]
            s1 = st[:nt] == 1
            med = lambda m: f"{np.median(tt[m]):6.1f}" if m.any() else "     -"  # noqa: E731
            print(f"{'':10s} {lab}: separated {100 * np.mean(sep):5.1f} %, by stage 1 "
                  f"{100 * np.mean(st == 1):5.1f} %, by stage 2 {100 * np.mean(st == 2):5.1f} %; "
                  f"stage-1 it median (max) {np.median(it1[it1 > 0]) if (it1 > 0).any() else 0:.0f}"
                  f"({it1.max():.0f}); µs: stage-1 results {med(s1)}, stage-2 results {med(~s1)}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=2000)
    ap.add_argument("--ref", type=int, default=20, help="pairs checked against the reference")
    ap.add_argument("--time", type=int, default=200, help="pairs timed individually")
    ap.add_argument("--repeats", type=int, default=50)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--range", type=float, nargs=2, default=(-0.05, 0.01), metavar=("LO", "HI"),
                    help="signed distances relative to the radius (default -0.05 0.01)")
    a = ap.parse_args()
    numba.set_num_threads(a.threads)
    run(a.pairs, a.ref, a.time, a.repeats, depth_range=tuple(a.range))


if __name__ == "__main__":
    main()

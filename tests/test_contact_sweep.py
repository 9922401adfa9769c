"""Randomised sweep of the batch LCP over shapes, poses and depths (seeded).

Every pair: no exception, finite output, and
* spheres (6-patch and single-patch): exact answer, |Δsd| <= 1e-9 r, normal <= 1e-7 rad;
* ellipsoids: analytic support-function reference, |Δsd| <= 1e-8 × size;
* particles A/B/C: optimality certificates from dense surface samples (no sample of A lies
  beyond the support plane at p_A, none of B beyond the one at p_B; the gap is parallel to
  the normal) and agreement of cold and warm-started solves.
The shares of degenerated and failed LCPs are printed. ~500 poses in the normal suite, 10⁴
in the slow one."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from nurbsdem.contact import ContactTable, detect_batch
from nurbsdem.contact.lcp import F_N, F_PA, F_PB, F_SD, I_DEG, I_FAIL
from nurbsdem.contact.reference import SampledBody, ellipsoid_pair, random_pair_poses
from nurbsdem.geometry.generators import ellipsoid, single_patch_sphere_patches, sphere
from nurbsdem.geometry.particles import paper_particle_shape
from nurbsdem.geometry.shape import Shape

R = 0.01
AX = (0.03, 0.02, 0.012)


@pytest.fixture(scope="module")
def table():
    shapes = [sphere(R), Shape(single_patch_sphere_patches(R), check=False), ellipsoid(*AX),
              paper_particle_shape("A"), paper_particle_shape("B"), paper_particle_shape("C")]
    return ContactTable(shapes)


def run_sweep(table, n, seed):
    rng = np.random.default_rng(seed)
    sa = rng.integers(0, len(table), n)
    sb = rng.integers(0, len(table), n)
    pa, ra, pb, rb = random_pair_poses(table, sa, sb, rng, -0.15, 0.03)
    f, i = detect_batch(table, sa, pa, ra, sb, pb, rb)
    assert np.all(np.isfinite(f))
    # warm start from a pose one step earlier
    dr = Rotation.from_rotvec(rng.normal(size=(n, 3)) * 1e-3).as_matrix()
    fp, ip = detect_batch(table, sa, pa + 1e-5, np.einsum("kij,kjl->kil", dr, ra), sb, pb, rb)
    fw, iw = detect_batch(table, sa, pa, ra, sb, pb, rb, fp, ip)
    assert np.all(np.isfinite(fw))
    ok = (i[:, I_FAIL] == 0) & (iw[:, I_FAIL] == 0)
    scale = table.radius[sa] + table.radius[sb]
    # cold and warm agree (same local minimum)
    assert np.all(np.abs(f[ok, F_SD] - fw[ok, F_SD]) <= 1e-9 * scale[ok])
    nerr = 0
    for k in range(n):
        a, b = sa[k], sb[k]
        if not ok[k]:
            continue
        n_k = f[k, F_N:F_N + 3]
        sd = f[k, F_SD]
        if a in (0, 1) and b in (0, 1):
            ca = pa[k] + ra[k] @ table.centroid[a]
            cb = pb[k] + rb[k] @ table.centroid[b]
            dist = np.linalg.norm(cb - ca)
            assert abs(sd - (dist - 2 * R)) <= 1e-9 * R
            assert np.linalg.norm(np.cross(n_k, (cb - ca) / dist)) <= 1e-7
        elif a == 2 and b == 2 and k % 5 == 0:     # a subset (the reference costs ~5 ms)
            ref = ellipsoid_pair(AX, (pa[k], ra[k]), AX, (pb[k], rb[k]), n_dirs=1500)
            assert abs(sd - ref[0]) <= 1e-8 * max(AX)
        elif a >= 3 and b >= 3 and k % 3 == 0:
            # optimality certificate from dense samples
            for s, pose, p, sign in ((a, (pa[k], ra[k]), f[k, F_PA:F_PA + 3], 1.0),
                                     (b, (pb[k], rb[k]), f[k, F_PB:F_PB + 3], -1.0)):
                body = SampledBody(table.shapes[s], pose, n=24)
                smax = np.max(body.x @ (sign * n_k))
                if smax > sign * (n_k @ p) + 1e-12 * scale[k]:
                    nerr += 1
            gap = f[k, F_PA:F_PA + 3] - f[k, F_PB:F_PB + 3]
            assert np.linalg.norm(gap + sd * n_k) <= 1e-9 * scale[k]
    assert nerr == 0
    share_deg = float(np.mean(i[:, I_DEG] > 0))
    share_fail = float(np.mean(~ok))
    print(f"sweep n={n}: degenerated {100 * share_deg:.2f} %, failed {100 * share_fail:.3f} %")
    return share_deg, share_fail


def test_sweep_short(table):
    deg, fail = run_sweep(table, 500, seed=0)
    assert fail <= 0.002


@pytest.mark.slow
def test_sweep_long(table):
    deg, fail = run_sweep(table, 10000, seed=1)
    assert fail <= 0.001

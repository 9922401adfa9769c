"""LCP on exact NURBS ellipsoids in random relative poses against the independent
support-function reference (h(d) = c·d + sqrt(dᵀ M d), dense start + SciPy refinement, see
:mod:`nurbsdem.contact.reference`): signed distance to 1e-8 relative, normals to 1e-7 rad."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from nurbsdem.contact import ContactTable, detect, detect_batch
from nurbsdem.contact.lcp import F_SD, I_FAIL
from nurbsdem.contact.reference import ellipsoid_pair
from nurbsdem.geometry.generators import ellipsoid

AX_A = (0.03, 0.02, 0.012)
AX_B = (0.025, 0.015, 0.01)
EA = ellipsoid(*AX_A)
EB = ellipsoid(*AX_B)


def random_case(rng, lo, hi):
    """Poses with a target signed distance in [lo, hi] × the smaller axis (placed by moving B
    along the centre line, bisection on the reference)."""
    ra, rb = Rotation.random(2, random_state=rng).as_matrix()
    u = rng.normal(size=3)
    u /= np.linalg.norm(u)
    target = rng.uniform(lo, hi) * min(AX_B)
    a, b = 0.0, 0.1
    for _ in range(40):
        t = 0.5 * (a + b)
        sd = ellipsoid_pair(AX_A, (np.zeros(3), ra), AX_B, (t * u, rb), n_dirs=400)[0]
        a, b = (t, b) if sd < target else (a, t)
    return (np.zeros(3), ra), (t * u, rb)


@pytest.mark.parametrize("seed", range(4))
def test_ellipsoids_random_poses(seed):
    rng = np.random.default_rng(seed)
    for _ in range(6):
        pa, pb = random_case(rng, -0.4, 0.2)
        sd, n, qa, qb = ellipsoid_pair(AX_A, pa, AX_B, pb)
        res = detect(EA, pa, EB, pb)
        assert not res.failed
        scale = max(AX_A)
        assert abs(res.signed_distance - sd) <= 1e-8 * scale, (res.signed_distance, sd)
        assert np.linalg.norm(np.cross(res.normal, n)) <= 1e-7
        assert np.linalg.norm(res.point_a - qa) <= 1e-6 * scale
        assert np.linalg.norm(res.point_b - qb) <= 1e-6 * scale
        # warm start from a slightly earlier pose gives the same answer, fast
        prev = detect(EA, (pa[0] + 1e-5, pa[1]), EB, pb)
        res2 = detect(EA, pa, EB, pb, previous=prev)
        assert abs(res2.signed_distance - sd) <= 1e-8 * scale
        assert res2.iterations <= 4


def test_ellipsoids_grazing_and_deep():
    rng = np.random.default_rng(42)
    for lo, hi in ((-1e-6, 1e-6), (-0.6, -0.5)):
        for _ in range(4):
            pa, pb = random_case(rng, lo, hi)
            sd = ellipsoid_pair(AX_A, pa, AX_B, pb)[0]
            res = detect(EA, pa, EB, pb)
            assert abs(res.signed_distance - sd) <= 1e-8 * max(AX_A)


def test_ellipsoid_batch_parallel_equals_single():
    rng = np.random.default_rng(9)
    table = ContactTable([EA, EB])
    cases = [random_case(rng, -0.3, 0.1) for _ in range(8)]
    f, i = detect_batch(table, np.zeros(8, int), np.array([c[0][0] for c in cases]),
                        np.array([c[0][1] for c in cases]), np.ones(8, int),
                        np.array([c[1][0] for c in cases]), np.array([c[1][1] for c in cases]))
    for k, (pa, pb) in enumerate(cases):
        assert f[k, F_SD] == pytest.approx(detect(EA, pa, EB, pb).signed_distance, abs=1e-15)
    assert not i[:, I_FAIL].any()

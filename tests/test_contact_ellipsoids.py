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


def _ellipsoid_batch_poses(rng, K):
    """K pairs (A, B) of the two ellipsoids, B at 0.6-1.6 x the sum of the largest axes from
    A in a random direction (touching, overlapping and apart), both turned at random."""
    ra, rb = Rotation.random(2 * K, random_state=rng).as_matrix().reshape(2, K, 3, 3)
    u = rng.normal(size=(K, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    xb = u * rng.uniform(0.6, 1.6, (K, 1)) * (max(AX_A) + max(AX_B))
    return np.zeros((K, 3)), ra, xb, rb


@pytest.mark.parametrize("threads", [1, 2])
def test_batch_results_do_not_depend_on_how_the_threads_share_it(threads):
    """The threads of a parallel batch take chunks of pairs as they go (a slowed thread leaves
    its share to the others): every pair's result, cold and warm-started, is the same to the
    bit on one thread, on two, and solved alone (a batch of one pair); flat walls too."""
    import numba

    from nurbsdem.contact.flat_wall import detect_wall_batch
    rng = np.random.default_rng(21)
    K = 300
    table = ContactTable([EA, EB])
    xa, ra, xb, rb = _ellipsoid_batch_poses(rng, K)
    sa, sb = np.zeros(K, np.int64), np.ones(K, np.int64)
    moved = xb + rng.normal(size=(K, 3)) * 1e-4
    o, a, b = np.array([-0.1, -0.1, 0.0]), np.array([0.2, 0, 0]), np.array([0, 0.2, 0])
    xw = rng.uniform(-0.08, 0.08, (K, 3)) * [1, 1, 0] + [0, 0, 1] * rng.uniform(0.0, 0.04, (K, 1))
    tile = lambda v: np.tile(v, (K, 1))  # noqa: E731

    def solve(select):
        cold = detect_batch(table, sa[select], xa[select], ra[select], sb[select], xb[select],
                            rb[select])
        warm = detect_batch(table, sa[select], xa[select], ra[select], sb[select],
                            moved[select], rb[select], prev_f=cold[0], prev_i=cold[1])
        wall = detect_wall_batch(table, sa[select], xw[select], ra[select], tile(o)[select],
                                 tile(a)[select], tile(b)[select])
        return cold + warm + wall
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
        together = solve(np.arange(K))
        alone = [solve(np.array([k])) for k in range(0, K, 7)]
    finally:
        numba.set_num_threads(before)
    for j, k in enumerate(range(0, K, 7)):
        for whole, one in zip(together, alone[j]):
            np.testing.assert_array_equal(whole[k], one[0])          # bit for bit
    assert not together[1][:, I_FAIL].any() and not together[3][:, I_FAIL].any()
    assert (together[0][:, F_SD] < 0).sum() > 20 and (together[0][:, F_SD] > 0).sum() > 20

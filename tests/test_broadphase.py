"""Level-1 broad phase (bounding spheres, paper Eq. 3) against brute force."""
from __future__ import annotations

import numpy as np
import pytest

from nurbsdem.contact.broadphase import sphere_pairs, sphere_pairs_brute
from nurbsdem.contact.flat_wall import sphere_wall_pairs, wall_geometry


def _check(c, r, margin=0.0):
    got = sphere_pairs(c, r, margin)
    ref = sphere_pairs_brute(c, r, margin)
    assert got.dtype == np.int64 and got.shape[1] == 2
    np.testing.assert_array_equal(got, ref)
    return got


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("margin", [0.0, 0.05])
def test_random_monodisperse(seed, margin):
    rng = np.random.default_rng(seed)
    n = 400
    c = rng.uniform(0, 3, (n, 3))
    r = np.full(n, 0.1)
    _check(c, r, margin)


@pytest.mark.parametrize("seed", range(5))
def test_random_polydisperse(seed):
    rng = np.random.default_rng(100 + seed)
    n = 500
    c = rng.uniform(-2, 2, (n, 3))
    r = 10 ** rng.uniform(-3, -0.5, n)  # radii over 2.5 decades
    r[:3] = [0.8, 1.1, 0.0]  # a few giants and a point
    got = _check(c, r, 0.01)
    assert len(got) > 0


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("fraction", [0.0, 0.02, 0.3, 1.0])
def test_the_pairs_of_some_bodies_are_those_of_all_that_hold_one(seed, fraction):
    """sphere_pairs_of (a rebuild's search from the renewed bodies only) gives exactly the
    pairs of sphere_pairs that hold a fresh body, in the same order: monodisperse and over
    2.5 decades of radii (several size levels, each queried from either member), with a
    margin; the brute force agrees with sphere_pairs."""
    from nurbsdem.contact.broadphase import sphere_pairs_of
    rng = np.random.default_rng(200 + seed)
    n = 600
    c = rng.uniform(-2, 2, (n, 3))
    found = 0
    for r in (np.full(n, 0.15), 10 ** rng.uniform(-3, -0.5, n)):
        every = _check(c, r, 0.02)
        fresh = rng.random(n) < fraction
        got = sphere_pairs_of(c, r, 0.02, fresh)
        np.testing.assert_array_equal(got, every[fresh[every[:, 0]] | fresh[every[:, 1]]])
        found += len(got)
    assert (found > 0) == (fraction > 0.0)


def test_clustered_and_spread():
    rng = np.random.default_rng(7)
    clusters = rng.uniform(-1e6, 1e6, (6, 3))  # very spread-out domain: hashed cells
    c = np.concatenate([k + rng.normal(0, 0.05, (60, 3)) for k in clusters])
    r = rng.uniform(0.01, 0.04, len(c))
    got = _check(c, r)
    assert len(got) > 0


def test_small_and_degenerate_sets():
    assert sphere_pairs(np.zeros((0, 3)), np.zeros(0)).shape == (0, 2)
    assert sphere_pairs([[0.0, 0, 0]], [1.0]).shape == (0, 2)
    # all in one cell, all overlapping
    rng = np.random.default_rng(3)
    c = rng.uniform(0, 0.01, (30, 3))
    got = _check(c, np.full(30, 1.0))
    assert len(got) == 30 * 29 // 2
    # coincident centres, zero radii: never a pair (strict inequality), with margin: all
    c = np.zeros((5, 3))
    assert len(_check(c, np.zeros(5))) == 0
    assert len(_check(c, np.zeros(5), 1e-3)) == 10


def test_strict_inequality_and_order():
    c = np.array([[0.0, 0, 0], [2.0, 0, 0], [4.0, 0, 0], [1.0, 0, 0]])
    r = np.ones(4)
    got = sphere_pairs(c, r)
    # touching (distance == r_i + r_j) is not a pair; sorted lexicographically
    np.testing.assert_array_equal(got, [[0, 3], [1, 3]])
    # permuting the input permutes the indices only
    perm = np.array([2, 0, 3, 1])
    got2 = sphere_pairs(c[perm], r[perm])
    back = np.sort(perm[got2], axis=1)
    np.testing.assert_array_equal(back[np.lexsort(back.T[::-1])], got)


def test_bad_input():
    with pytest.raises(ValueError):
        sphere_pairs(np.zeros((2, 3)), np.ones(3))
    with pytest.raises(ValueError):
        sphere_pairs([[0, 0, np.nan], [0, 0, 0]], [1, 1])
    with pytest.raises(ValueError):
        sphere_pairs(np.zeros((2, 3)), [1, -1])
    with pytest.raises(ValueError):
        sphere_pairs(np.zeros((2, 3)), [1, 1], margin=-1)


def _wall_brute(c, r, wc, wa, wh, margin):
    out = []
    for i in range(len(c)):
        for k in range(len(wc)):
            # dense sampling of the rectangle
            s = np.linspace(-1, 1, 201)
            U, V = np.meshgrid(s * wh[k, 0], s * wh[k, 1])
            pts = wc[k] + U[..., None] * wa[k][:, 0] + V[..., None] * wa[k][:, 1]
            d = np.linalg.norm(pts - c[i], axis=-1).min()
            out.append(d)
    return np.array(out).reshape(len(c), len(wc))


def test_sphere_wall_pairs():
    from nurbsdem.shapes import box_walls
    walls = list(box_walls([0, 0, 0], [1, 2, 3], top=True).values())
    geo = [wall_geometry(w) for w in walls]
    wc = np.array([g[0] for g in geo])
    wa = np.array([g[1] for g in geo])
    wh = np.array([g[2] for g in geo])
    # the normals point into the box
    assert np.allclose(wa[0][:, 2], [0, 0, 1]) and np.allclose(wh[0], [0.5, 1.0])
    rng = np.random.default_rng(11)
    c = rng.uniform(-0.5, 3.5, (60, 3))
    r = rng.uniform(0.05, 0.6, 60)
    got = sphere_wall_pairs(c, r, wc, wa, wh, margin=0.02)
    d = _wall_brute(c, r, wc, wa, wh, 0.02)
    lim = (r + 0.02)[:, None]
    sure_in = {(i, k) for i, k in zip(*np.nonzero(d < lim - 0.02))}
    sure_out = {(i, k) for i, k in zip(*np.nonzero(d > lim))}
    gs = {tuple(p) for p in got}
    assert sure_in <= gs
    assert not (sure_out & gs)
    assert np.all(np.diff(got[:, 0] * 10 + got[:, 1]) > 0)

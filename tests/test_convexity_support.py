"""The convexity measure's height on the samples' convex hull.

:func:`nurbsdem.geometry.connectivity.measure_convexity` finds max_ab n_a . (x_b - x_a) with
the support function of the samples (:mod:`nurbsdem.geometry.support`: Qhull, then a walk
uphill on the hull) instead of all pairs. Checked here:

* the support function equals the all-pairs maximum on random sets (with duplicates, a
  flat set, a tiny and a far-off set);
* measure_convexity gives the figures and verdicts of the all-pairs measure on small nets
  (exact convex shapes, dents, the near-convex projected cube);
* the work per query does not grow with the number of samples (the walk's step count), and
  a 78 x 78 control net per patch (the paper's particle A refined by knot insertion) is
  measured convex.
"""
from __future__ import annotations

import numpy as np
import pytest

from nurbsdem.geometry import connectivity
from nurbsdem.geometry import generators as gen
from nurbsdem.geometry.connectivity import measure_convexity
from nurbsdem.geometry.fit import projected_cube_sphere
from nurbsdem.geometry.nurbs import Patch
from nurbsdem.geometry.particles import paper_particle
from nurbsdem.geometry.support import Support, max_height


def all_pairs_height(Xa, Na, support, extra=None):
    """The former measure: every tangent plane against every point."""
    Xb = support.X + support.centre
    if extra is not None and len(extra):
        Xb = np.concatenate([extra, Xb])
    D = np.einsum("rk,rmk->rm", Na, Xb[None, :, :] - Xa[:, None, :])
    r, m = np.unravel_index(int(np.argmax(D)), D.shape)
    return float(D[r, m]), int(r), int(m)


def insert_knot(H: np.ndarray, knots: np.ndarray, p: int, t: float):
    """Boehm's knot insertion of t into the curves H (n, ..., 4) (homogeneous) of degree p."""
    k = int(np.searchsorted(knots, t, side="right")) - 1
    Q = np.empty((H.shape[0] + 1,) + H.shape[1:])
    Q[:k - p + 1] = H[:k - p + 1]
    Q[k + 1:] = H[k:]
    for i in range(k - p + 1, k + 1):
        a = (t - knots[i]) / (knots[i + p] - knots[i])
        Q[i] = a * H[i] + (1 - a) * H[i - 1]
    return Q, np.insert(knots, k + 1, t)


def refined(patch: Patch, n: int) -> Patch:
    """The same surface with n x n control points (knots inserted mid-span, widest first)."""
    H, ku, kv = patch.homogeneous, patch.knots_u.copy(), patch.knots_v.copy()
    while H.shape[0] < n:
        i = int(np.argmax(np.diff(ku)))
        H, ku = insert_knot(H, ku, patch.degree_u, 0.5 * (ku[i] + ku[i + 1]))
    H = np.swapaxes(H, 0, 1)
    while H.shape[0] < n:
        i = int(np.argmax(np.diff(kv)))
        H, kv = insert_knot(H, kv, patch.degree_v, 0.5 * (kv[i] + kv[i + 1]))
    H = np.swapaxes(H, 0, 1)
    return Patch(patch.degree_u, patch.degree_v, ku, kv, H[..., :3] / H[..., 3:], H[..., 3])


# ---------------------------------------------------------------------- the support function
@pytest.mark.parametrize("case", ["sphere", "cube", "duplicates", "flat", "tiny", "far"])
def test_support_equals_all_pairs(case):
    rng = np.random.default_rng(7)
    X = rng.normal(size=(800, 3))
    if case == "sphere":
        X /= np.linalg.norm(X, axis=1, keepdims=True)
    elif case == "cube":
        X = rng.uniform(-1, 1, size=(800, 3))
    elif case == "duplicates":
        X = np.concatenate([X, X[:300], X[:10]])
    elif case == "flat":
        X[:, 2] = 0.0
    elif case == "tiny":
        X *= 1e-9
    else:
        X = X * 1e-3 + 1e3
    N = rng.normal(size=(500, 3))
    N[:20] = 0.0
    sup = Support(X)
    h, idx = sup.query(N)
    ref = (N @ (X - sup.centre).T).max(axis=1)
    scale = np.abs(X - sup.centre).max()
    assert np.allclose(h, ref, rtol=0, atol=1e-12 * scale)
    assert np.allclose(np.einsum("kj,kj->k", N, X[idx] - sup.centre), ref, atol=1e-12 * scale)
    if case == "flat":
        assert sup.vertices is None          # Qhull refuses a flat set: all pairs


def test_max_height_with_extra_points():
    rng = np.random.default_rng(3)
    X = rng.normal(size=(400, 3))
    extra = rng.normal(size=(30, 3)) * 1.5
    Xa = rng.normal(size=(50, 3))
    Na = rng.normal(size=(50, 3))
    sup = Support(X)
    got = max_height(Xa, Na, sup, extra=extra)
    ref = all_pairs_height(Xa, Na, sup, extra=extra)
    assert got[0] == pytest.approx(ref[0], abs=1e-12)
    assert got[1] == ref[1] and got[2] == ref[2]


# ---------------------------------------------------------------------- the measure
def _dented(depth: float) -> list[Patch]:
    patches = gen.sphere_patches(1.0)
    p = patches[2]
    cp = p.control_points.copy()
    cp[2, 2] *= 1.0 - depth
    patches[2] = Patch(4, 4, p.knots_u, p.knots_v, cp, p.weights)
    return patches


@pytest.mark.parametrize("name", ["sphere", "ellipsoid", "A", "dent 2%", "dent 20%",
                                  "projected cube"])
def test_same_figures_and_verdicts_as_all_pairs(name, monkeypatch):
    patches = {"sphere": lambda: gen.sphere_patches(0.01),
               "ellipsoid": lambda: gen.ellipsoid_patches(0.03, 0.02, 0.012),
               "A": lambda: paper_particle("A"),
               "dent 2%": lambda: _dented(0.02), "dent 20%": lambda: _dented(0.2),
               "projected cube": lambda: projected_cube_sphere(0.025)}[name]()
    new = measure_convexity(patches)
    monkeypatch.setattr(connectivity, "max_height", all_pairs_height)
    old = measure_convexity(patches)
    assert new.convex == old.convex
    assert new.height == pytest.approx(old.height, rel=1e-9, abs=1e-15 * old.size)
    assert new.curvature == old.curvature


def test_walk_work_does_not_grow_with_the_samples():
    """Steps per query stay bounded from 2 000 to 50 000 samples of a sphere (the all-pairs
    measure's work grows with the square)."""
    rng = np.random.default_rng(1)
    per_query = []
    for n in (2000, 50000):
        X = rng.normal(size=(n, 3))
        X /= np.linalg.norm(X, axis=1, keepdims=True)
        sup = Support(X)
        sup.query(X)                        # the outward normals of the samples
        per_query.append(sup.walk_steps / n)
    assert per_query[1] < 1.0 and per_query[1] <= 2 * per_query[0]


def test_dense_net_78x78_is_measured_convex():
    patches = [refined(p, 78) for p in paper_particle("A")]
    assert patches[0].shape == (78, 78)
    u = np.linspace(0.0, 2.0, 9)
    assert np.allclose(patches[0].points(u, u), paper_particle("A")[0].points(u, u),
                       atol=1e-15)
    cv = measure_convexity(patches)
    assert cv.convex and cv.height == 0.0

"""Gap certificates of spheres against a surface wall (nurbsdem.contact.wall_skin): over a
random walk of spheres inside a turning and shifting drum, the rows found with the
certificates equal those of solving every sphere at every evaluation, and most spheres are
skipped."""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from nurbsdem.contact.surface_kind import _surface_rows_of
from nurbsdem.contact.lcp import NF
from nurbsdem.contact.surface_wall import build_surface_wall
from nurbsdem.contact.wall_skin import WallSkin
from nurbsdem.geometry.surfaces import cylinder_patch


def _rows(g, idx, x, r, R, t):
    rf, owner, gap = np.zeros((len(idx), NF)), np.zeros(len(idx), np.int64), np.zeros(len(idx))
    n = _surface_rows_of(idx, x, r, R, t, g.deg, g.ncp, g.koff, g.knots, g.pw, g.poff, g.dom,
                         g.periodic, g.seed_x, g.seed_p, g.seed_uv, g.spacing, g.size, rf,
                         owner, gap)
    return rf[:n], owner[:n], gap


def test_certified_spheres_are_apart_and_the_rows_are_unchanged():
    g = build_surface_wall([cylinder_patch(0.1, 0.1, axis=(0, 0, 1))])
    rng = np.random.default_rng(4)
    n = 300
    rho = 0.1 * np.sqrt(rng.uniform(0.6, 1.0, n))
    phi = rng.uniform(0.0, 2.0 * np.pi, n)
    x = np.column_stack([rho * np.cos(phi), rho * np.sin(phi), rng.uniform(0.03, 0.07, n)])
    r = np.full(n, 0.004)
    every = np.arange(n, dtype=np.int64)
    skin = WallSkin(n, g.seed_x, g.spacing)
    solved = touched = 0
    for k in range(150):
        R = Rotation.from_rotvec([0.1, 0.05, 0.002 * k]).as_matrix()
        t = np.array([0.0001 * k, 0.0, 0.0])
        x = x + rng.normal(0.0, 0.0003, x.shape)
        ref_f, ref_owner, _ = _rows(g, every, x, r, R, t)
        skin.advance(R, t)
        due = skin.due(every, x)
        f, owner, gap = _rows(g, due, x, r, R, t)
        skin.certify(due, x, gap)
        solved += len(due)
        touched += len(ref_owner)
        np.testing.assert_array_equal(owner, ref_owner)
        np.testing.assert_array_equal(f, ref_f)
    assert touched > 500                            # spheres touch the mantle
    assert solved < 0.5 * 150 * n                   # most evaluations are skipped

"""Closed-form contacts of exact spheres (sphere–sphere, sphere–flat wall) against the NURBS
LCP on the same geometry, and the recognition of exact spheres from their NURBS surfaces."""
from __future__ import annotations

import numpy as np
import pytest

from nurbsdem.contact.detect import ContactTable, detect_batch
from nurbsdem.contact.flat_wall import detect_wall_batch, wall_frame
from nurbsdem.contact.lcp import F_N, F_PA, F_PB, F_SD, I_ACTIVE, I_BROAD, I_VALID, NF, NI
from nurbsdem.contact.sphere import closed_form_into
from nurbsdem.contact.stage2 import ANGLE_TOL
from nurbsdem.geometry.analytic import exact_sphere
from nurbsdem.geometry.rotation import quats_to_matrices, random_quaternions
from nurbsdem.shapes import ellipsoid, flat_wall, single_patch_sphere, sphere


def test_exact_spheres_are_recognised_and_nothing_else():
    for shape, r in ((sphere(0.02), 0.02), (single_patch_sphere(0.031), 0.031)):
        c, got = exact_sphere(shape)
        assert got == pytest.approx(r, rel=1e-14) and np.abs(c).max() < 1e-15
    R = quats_to_matrices(random_quaternions(np.random.default_rng(0), 1))[0]
    moved = sphere(0.01).transformed(R, offset=[0.3, -0.2, 0.1])
    c, r = exact_sphere(moved)
    assert r == pytest.approx(0.01, rel=1e-13)
    np.testing.assert_allclose(c, [0.3, -0.2, 0.1], atol=1e-15)
    assert exact_sphere(ellipsoid(0.02, 0.02, 0.02 * (1 + 1e-7))) is None
    assert exact_sphere(ellipsoid(0.03, 0.02, 0.01)) is None


def poses(rng, K, r_a, r_b, sd):
    """K random pairs at signed distances sd (K,): random orientations and directions."""
    Ra = quats_to_matrices(random_quaternions(rng, K))
    Rb = quats_to_matrices(random_quaternions(rng, K))
    xa = rng.uniform(-0.1, 0.1, (K, 3))
    n = rng.normal(size=(K, 3))
    n /= np.linalg.norm(n, axis=1)[:, None]
    xb = xa + (r_a + r_b + sd)[:, None] * n
    return xa, Ra, xb, Rb


def test_sphere_pairs_agree_with_the_nurbs_lcp_to_round_off():
    rng = np.random.default_rng(7)
    ra, rb = 0.02, 0.013
    K = 200
    sd = np.concatenate([rng.uniform(-0.3, -1e-9, K // 2), rng.uniform(1e-9, 0.5, K // 2)]) * rb
    xa, Ra, xb, Rb = poses(rng, K, ra, rb, sd)
    table = ContactTable([sphere(ra), sphere(rb)])
    lf, li = detect_batch(table, np.zeros(K, np.int64), xa, Ra, np.ones(K, np.int64), xb, Rb)
    # the scene's closed form: bodies 0..K-1 (shape 0) against K..2K-1 (shape 1), no walls
    cf, ci = np.full((K, NF), np.nan), np.full((K, NI), -9, np.int64)
    no_walls = np.zeros((0, 3))
    closed_form_into(cf, ci, np.arange(K), np.arange(K), K + np.arange(K), 2 * K,
                     np.concatenate([xa, xb]), np.concatenate([Ra, Rb]), no_walls,
                     np.repeat([0, 1], K), np.zeros((2, 3)), np.array([ra, rb]), no_walls,
                     no_walls, no_walls, np.zeros((0, 4)))
    assert (li[:, I_VALID] == 1).all() and (ci[:, I_ACTIVE] == li[:, I_ACTIVE]).all()
    np.testing.assert_allclose(cf[:, F_SD], sd, atol=1e-14 * ra)
    # the LCP stops when its direction moves less than ANGLE_TOL (1e-11 rad): normals and
    # points agree to that, the distance to its square
    ang = 5 * ANGLE_TOL
    for cols, tol in ((slice(F_SD, F_SD + 1), 1e-13 * ra), (slice(F_N, F_N + 3), ang),
                      (slice(F_PA, F_PA + 3), ang * ra), (slice(F_PB, F_PB + 3), ang * ra)):
        np.testing.assert_allclose(cf[:, cols], lf[:, cols], rtol=0, atol=tol)


def test_sphere_on_a_flat_wall_agrees_with_the_nurbs_wall_path():
    rng = np.random.default_rng(8)
    r = 0.02
    K = 200
    wall = flat_wall([0.1, 0.1, 0.0], [0.3, 0.2, 1.0], [0.3, 0.3])
    o, a, b, dom = wall_frame(wall)
    m = np.cross(a, b)
    m /= np.linalg.norm(m)
    # centres over the wall (and some beyond its edges) at heights giving sd in [-0.3 r, 0.5 r]
    al, be = rng.uniform(-0.2, 1.2, K), rng.uniform(-0.2, 1.2, K)
    sd = rng.uniform(-0.3, 0.5, K) * r
    x = o + al[:, None] * a + be[:, None] * b + (r + sd)[:, None] * m
    R = quats_to_matrices(random_quaternions(rng, K))
    table = ContactTable([sphere(r)])
    tile = lambda v: np.tile(v, (K, 1))  # noqa: E731
    lf, li = detect_wall_batch(table, np.zeros(K, np.int64), x, R, tile(o), tile(a), tile(b),
                               tile(dom))
    # the scene's closed form: particles 0..K-1 against the wall (body K)
    cf, ci = np.full((K, NF), np.nan), np.full((K, NI), -9, np.int64)
    closed_form_into(cf, ci, np.arange(K), np.arange(K), np.full(K, K), K, x, R,
                     np.zeros((1, 3)), np.zeros(K, np.int64), np.zeros((1, 3)), np.array([r]),
                     o[None], a[None], b[None], np.asarray(dom, float)[None])
    assert (ci[:, I_ACTIVE] == li[:, I_ACTIVE]).all() and ci[:, I_ACTIVE].any()
    np.testing.assert_allclose(cf[:, F_SD], sd, atol=1e-14)
    # where the bounding sphere (radius: farthest control point) does not reach the plane the
    # wall path stops with that lower bound of the distance
    far = li[:, I_BROAD] == 1
    assert (cf[far, F_SD] > lf[far, F_SD]).all() and (~far).sum() > K // 2
    cf, lf = cf[~far], lf[~far]
    ang = 5 * ANGLE_TOL
    for cols, tol in ((slice(F_SD, F_SD + 1), 1e-13 * r), (slice(F_N, F_N + 3), 1e-14),
                      (slice(F_PA, F_PA + 3), ang * r), (slice(F_PB, F_PB + 3), ang * r)):
        np.testing.assert_allclose(cf[:, cols], lf[:, cols], rtol=0, atol=tol)

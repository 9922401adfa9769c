"""Level-2 broad phase: oriented patch boxes (separating-axis test) against independent checks."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linprog
from scipy.spatial.transform import Rotation

from nurbsdem.contact.boxes import (MASK_CHUNK, candidate_patch_masks_batch_jit,
                                    candidate_patch_pairs, candidate_patch_pairs_batch,
                                    candidate_patches_wall, candidate_patches_wall_batch,
                                    obb_overlap, pack_boxes)
from nurbsdem.contact.flat_wall import wall_geometry
from nurbsdem.shapes import ellipsoid, flat_wall, sphere


def _halfspaces(c, A, h):
    """Box {x : |A_k . (x - c)| <= h_k} as G x <= g (6 rows)."""
    G = np.concatenate([A.T, -A.T])
    g = np.concatenate([A.T @ c + h, -(A.T @ c) + h])
    return G, g


def _lp_slack(ca, Aa, ha, cb, Ab, hb):
    """max s s.t. x in both boxes shrunk by s: s > 0 overlap with interior, s < 0 apart.

    Independent of the SAT: an LP over (x, s) on the 12 half-spaces."""
    G1, g1 = _halfspaces(ca, Aa, ha)
    G2, g2 = _halfspaces(cb, Ab, hb)
    G = np.concatenate([G1, G2])
    g = np.concatenate([g1, g2])
    A_ub = np.concatenate([G, np.ones((12, 1))], axis=1)
    res = linprog([0, 0, 0, -1], A_ub=A_ub, b_ub=g, bounds=[(None, None)] * 3 + [(-1e3, 1e3)],
                  method="highs")
    assert res.status == 0
    return res.x[3]


def _rand_rot(rng):
    return Rotation.random(random_state=rng).as_matrix()


def test_sat_vs_lp_random():
    rng = np.random.default_rng(0)
    tol = 1e-7
    n_over = n_apart = 0
    for _ in range(1500):
        ha = rng.uniform(0.05, 1.0, 3)
        hb = rng.uniform(0.05, 1.0, 3)
        Aa, Ab = _rand_rot(rng), _rand_rot(rng)
        ca = rng.uniform(-0.5, 0.5, 3)
        cb = ca + rng.normal(size=3) * rng.uniform(0.2, 2.5)
        s = _lp_slack(ca, Aa, ha, cb, Ab, hb)
        got = obb_overlap(ca, Aa, ha, cb, Ab, hb)
        if s > tol:
            assert got
            n_over += 1
        elif s < -tol:
            assert not got, s
            n_apart += 1
    assert n_over > 200 and n_apart > 200


def _touching_cases(rng):
    """Boxes touching exactly: face-face, parallel (same axes), edge-edge, vertex-face."""
    I = np.eye(3)
    yield np.zeros(3), I, np.array([1, 1, 1.]), np.array([2.0, 0.3, -0.2]), I, np.array([1, .5, .5])
    # same rotation, touching along a face
    R = _rand_rot(rng)
    ha, hb = np.array([0.3, 0.7, 0.2]), np.array([0.5, 0.1, 0.4])
    yield np.zeros(3), R, ha, R @ np.array([0.8, 0.2, 0.1]), R, hb
    # edge-edge: crossed edges, B rotated 45 deg about x and about z
    Rb = Rotation.from_euler("xz", [45, 45], degrees=True).as_matrix()
    hb = np.array([1.0, 1.0, 1.0])
    # B's extreme point along -z: a vertex/edge; place it on A's top face
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    low = (corners @ (Rb * hb).T)[:, 2].min()
    yield np.zeros(3), I, np.ones(3), np.array([0.3, 0.2, 1.0 - low]), Rb, hb
    # edge-edge with parallel edges (rotation about a shared axis direction)
    Rz = Rotation.from_euler("z", 45, degrees=True).as_matrix()
    yield np.zeros(3), I, np.ones(3), np.array([1 + np.sqrt(2), 0.0, 0.5]), Rz, np.ones(3)


def test_sat_touching_and_parallel():
    rng = np.random.default_rng(1)
    for ca, Aa, ha, cb, Ab, hb in _touching_cases(rng):
        assert abs(_lp_slack(ca, Aa, ha, cb, Ab, hb)) < 1e-7
        assert obb_overlap(ca, Aa, ha, cb, Ab, hb)  # touching counts (conservative)
        assert obb_overlap(cb, Ab, hb, ca, Aa, ha)
        # pull apart by 1e-6 along the centre line: separated
        d = (cb - ca) / np.linalg.norm(cb - ca)
        assert not obb_overlap(ca, Aa, ha, cb + 1e-5 * d, Ab, hb)
    # identical boxes, parallel axes, edge-edge axes all degenerate
    R = _rand_rot(rng)
    h = np.array([0.2, 0.3, 0.4])
    assert obb_overlap(np.zeros(3), R, h, np.zeros(3), R, h)
    assert not obb_overlap(np.zeros(3), R, h, R @ np.array([0.0, 0.0, 0.8001]), R, h)
    assert obb_overlap(np.zeros(3), R, h, R @ np.array([0.0, 0.0, 0.7999]), R, h)


def test_sat_edge_edge_only_separation():
    """Two square rods crossing, each turned 45 deg about its own axis so that ridges face
    each other: only the edge-edge axis z = A_x x B_y separates them."""
    A = Rotation.from_euler("x", 45, degrees=True).as_matrix()
    B = Rotation.from_euler("z", 90, degrees=True).as_matrix() @ \
        Rotation.from_euler("x", 45, degrees=True).as_matrix()  # rod along y
    h = np.array([2.0, 0.05, 0.05])
    contact = 2 * 0.05 * np.sqrt(2)  # ridge to ridge
    R0 = _rand_rot(np.random.default_rng(9))  # whole scene in a random orientation
    for gap, want in [(1e-3, False), (-1e-3, True), (1e-7, False)]:
        cb = np.array([0.3, -0.2, contact + gap])
        got = obb_overlap(np.zeros(3), R0 @ A, h, R0 @ cb, R0 @ B, h)
        assert got == want
        if abs(gap) > 1e-6:
            s = _lp_slack(np.zeros(3), R0 @ A, h, R0 @ cb, R0 @ B, h)
            assert (s > 0) == want
        # no face axis separates them
        for ax in np.concatenate([(R0 @ A).T, (R0 @ B).T]):
            ra = np.abs((R0 @ A).T @ ax) @ h
            rb = np.abs((R0 @ B).T @ ax) @ h
            assert abs((R0 @ cb) @ ax) <= ra + rb


# --------------------------------------------------------------------------- patches
def _samples(shape, pose, n=25):
    pos, R = pose
    u = np.linspace(0, 1, n)
    out = []
    for p in shape.patches:
        d0, d1, e0, e1 = p.domain if not callable(p.domain) else p.domain()
        U, V = np.meshgrid(d0 + (d1 - d0) * u, e0 + (e1 - e0) * u, indexing="ij")
        pts = p.points(U.ravel(), V.ravel()).reshape(-1, 3)
        out.append(pts @ R.T + pos)
    return out


def _nearest_patch(samples, x):
    return int(np.argmin([np.linalg.norm(s - x, axis=1).min() for s in samples]))


@pytest.mark.parametrize("seed", range(6))
def test_spheres_true_contact_patch_pair(seed):
    rng = np.random.default_rng(seed)
    ra, rb = 0.02, 0.015
    A, B = sphere(ra), sphere(rb)
    Ra, Rb = _rand_rot(rng), _rand_rot(rng)
    d = rng.normal(size=3)
    d /= np.linalg.norm(d)
    pa = rng.uniform(-1, 1, 3)
    for dist in (ra + rb - 1e-3, ra + rb, ra + rb + 5e-4):
        pb = pa + d * dist
        pose_a, pose_b = (pa, Ra), (pb, Rb)
        margin = 1e-3
        got = candidate_patch_pairs(A, pose_a, B, pose_b, margin=margin)
        sa, sb = _samples(A, pose_a), _samples(B, pose_b)
        xa, xb = pa + ra * d, pb - rb * d  # the closest / deepest points
        assert (_nearest_patch(sa, xa), _nearest_patch(sb, xb)) in {tuple(p) for p in got}
    # far apart: nothing
    assert len(candidate_patch_pairs(A, (pa, Ra), B, (pa + d * 3 * (ra + rb), Rb))) == 0


@pytest.mark.parametrize("seed", range(4))
def test_ellipsoids_conservative(seed):
    """Every patch pair with sampled points closer than the margin is a candidate."""
    rng = np.random.default_rng(10 + seed)
    A = ellipsoid(0.03, 0.02, 0.012)
    B = ellipsoid(0.025, 0.01, 0.015)
    margin = 2e-3
    for _ in range(5):
        pa = np.zeros(3)
        d = rng.normal(size=3)
        pb = d / np.linalg.norm(d) * rng.uniform(0.01, 0.05)
        pose_a, pose_b = (pa, _rand_rot(rng)), (pb, _rand_rot(rng))
        got = {tuple(p) for p in candidate_patch_pairs(A, pose_a, B, pose_b, margin=margin)}
        sa, sb = _samples(A, pose_a, 15), _samples(B, pose_b, 15)
        for i, x in enumerate(sa):
            for j, y in enumerate(sb):
                dmin = np.sqrt(((x[:, None] - y[None]) ** 2).sum(-1).min())
                if dmin < margin:
                    assert (i, j) in got, (i, j, dmin)


def test_batch_matches_single():
    rng = np.random.default_rng(5)
    shapes = [sphere(0.02), ellipsoid(0.03, 0.02, 0.012)]
    boxes, off = pack_boxes(shapes)
    n = 12
    body_shape = rng.integers(0, 2, n)
    pos = rng.uniform(0, 0.08, (n, 3))
    rot = np.array([_rand_rot(rng) for _ in range(n)])
    pairs = np.array([(i, j) for i in range(n) for j in range(i + 1, n)])
    got = candidate_patch_pairs_batch(boxes, off, body_shape, pos, rot, pairs, margin=1e-3)
    assert got.shape[1] == 3 and len(got) > 0
    for k, (a, b) in enumerate(pairs):
        ref = candidate_patch_pairs(shapes[body_shape[a]], (pos[a], rot[a]),
                                    shapes[body_shape[b]], (pos[b], rot[b]), margin=1e-3)
        np.testing.assert_array_equal(got[got[:, 0] == k, 1:], ref)
    assert len(candidate_patch_pairs_batch(boxes, off, body_shape, pos, rot,
                                           np.zeros((0, 2), np.int64))) == 0


def _paper_shapes():
    from nurbsdem.geometry.particles import paper_particle_shape
    return [paper_particle_shape(k) for k in "ABC"]


@pytest.mark.parametrize("n, paper", [(6, False), (30, False), (30, True), (60, True)])
def test_masks_mark_the_patches_of_the_overlapping_box_pairs(n, paper):
    """The neighbour list's masks (boxes skipped where both patches are marked already,
    shares on the threads for more than MASK_CHUNK pairs) mark exactly the patches of the
    rows of candidate_patch_pairs_batch, which tests every pair of boxes; also the paper's
    particles (six patches each), packed densely."""
    rng = np.random.default_rng(n)
    shapes = _paper_shapes() if paper else [sphere(0.02), ellipsoid(0.03, 0.02, 0.012)]
    boxes, off = pack_boxes(shapes)
    P = int(np.diff(off).max())
    body_shape = rng.integers(0, len(shapes), n)
    pos = rng.uniform(0, (0.03 if paper else 0.05) * n ** (1 / 3), (n, 3))
    rot = np.array([_rand_rot(rng) for _ in range(n)])
    pairs = np.array([(i, j) for i in range(n) for j in range(i + 1, n)], np.int64)
    assert (len(pairs) > 2 * MASK_CHUNK) == (n >= 30)
    for margin in (0.0, 1e-3, 1e-2):
        keep, mask_a, mask_b = candidate_patch_masks_batch_jit(boxes, off, body_shape, pos, rot,
                                                               pairs, margin, P)
        rows = candidate_patch_pairs_batch(boxes, off, body_shape, pos, rot, pairs, margin)
        want_a, want_b = np.zeros_like(mask_a), np.zeros_like(mask_b)
        want_a[rows[:, 0], rows[:, 1]] = True
        want_b[rows[:, 0], rows[:, 2]] = True
        np.testing.assert_array_equal(keep, np.isin(np.arange(len(pairs)), rows[:, 0]))
        np.testing.assert_array_equal(mask_a, want_a)
        np.testing.assert_array_equal(mask_b, want_b)
        assert 0 < keep.sum() < len(pairs)


def test_wall_candidates():
    r = 0.02
    S = sphere(r)
    wall = flat_wall([0.0, 0.0, 0.0], [0, 0, 1], (0.2, 0.3))
    wc, wa, wh = wall_geometry(wall)
    rng = np.random.default_rng(2)
    for _ in range(10):
        R = _rand_rot(rng)
        x = np.array([rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05), r - 1e-3])
        pos = x - R @ S.centroid
        got = candidate_patches_wall(S, (pos, R), wc, wa, wh)
        samples = _samples(S, (pos, R))
        low = _nearest_patch(samples, x - np.array([0, 0, r]))
        assert low in set(got)
        assert np.all(np.diff(got) > 0)
        # above the wall by 3 radii: nothing; with a big margin: something
        pos_up = pos + np.array([0, 0, 3 * r])
        assert len(candidate_patches_wall(S, (pos_up, R), wc, wa, wh)) == 0
        assert len(candidate_patches_wall(S, (pos_up, R), wc, wa, wh, margin=4 * r)) > 0
        # sunk entirely below the plane: only found with depth
        pos_dn = pos - np.array([0, 0, 3 * r])
        assert len(candidate_patches_wall(S, (pos_dn, R), wc, wa, wh)) == 0
        assert len(candidate_patches_wall(S, (pos_dn, R), wc, wa, wh, depth=5 * r)) > 0
        # outside the rectangle: nothing
        pos_out = pos + np.array([0.2, 0, 0])
        assert len(candidate_patches_wall(S, (pos_out, R), wc, wa, wh)) == 0
    # batch
    boxes, off = pack_boxes([S])
    pos = np.array([[0, 0, r - 1e-3], [0, 0, 1.0]]) - S.centroid
    rot = np.array([np.eye(3), np.eye(3)])
    got = candidate_patches_wall_batch(boxes, off, np.zeros(2, np.int64), pos, rot,
                                       wc[None], wa[None], wh[None], np.array([[0, 0], [1, 0]]))
    ref = candidate_patches_wall(S, (pos[0], rot[0]), wc, wa, wh)
    np.testing.assert_array_equal(got[:, 0], 0)
    np.testing.assert_array_equal(got[:, 1], ref)

"""Stage 1 of the LCP (paper Eq. 5): trust-region Newton on f1 = ½|ΓA − ΓB|² over the four
surface parameters (:mod:`nurbsdem.contact.stage1`), alone and inside the pipeline
(:func:`nurbsdem.contact.detect`): exact spheres (analytic distance and closest points,
touching, intersecting), ellipsoids against the support-function reference, starts at a
saddle and at the far sides, the cold pipeline on particle A against the stage-2-only
solution, warm starts, stage switching and the batch column ``I_STAGE``."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from nurbsdem.contact import ContactResult, ContactTable, detect, detect_batch
from nurbsdem.contact.lcp import F_N, F_SD, I_FAIL, I_STAGE, NF, NI, I_VALID, I_PA, I_PB, F_PAR
from nurbsdem.contact.reference import ellipsoid_pair
from nurbsdem.contact.detect import closest_points
from nurbsdem.contact.trust_region import jacobi_eig
from nurbsdem.geometry.generators import ellipsoid, sphere
from nurbsdem.geometry.particles import paper_particle_shape

R = 0.01
SPH = sphere(R)
I3 = np.eye(3)
DIRS = [np.array(v, float) / np.linalg.norm(v) for v in
        ([0.3, -0.2, 0.9], [1.0, 1.0, 0.0], [1.0, 1.0, 1.0], [-0.7, 0.1, 0.2])]
AX_A = (0.03, 0.02, 0.012)
AX_B = (0.025, 0.015, 0.01)
EA = ellipsoid(*AX_A)
EB = ellipsoid(*AX_B)
PA = paper_particle_shape("A")


def _cross(a, b) -> float:
    return float(np.linalg.norm(np.cross(a, b)))


def test_jacobi_eig_matches_numpy():
    rng = np.random.default_rng(0)
    for n in (1, 2, 3, 4):
        for _ in range(20):
            M = rng.normal(size=(n, n))
            M = M + M.T
            A = np.zeros((4, 8))
            A[:n, :n] = M
            Q = np.zeros((4, 8))
            lam = np.zeros(8)
            jacobi_eig(A, n, Q, lam)
            assert np.allclose(np.sort(lam[:n]), np.linalg.eigvalsh(M), atol=1e-13)
            V = Q[:n, :n]
            assert np.allclose(V @ np.diag(lam[:n]) @ V.T, M, atol=1e-12)


@pytest.mark.parametrize("d", DIRS)
@pytest.mark.parametrize("gap", [0.5, 0.1, 1e-3])
def test_spheres_separated_exact(d, gap):
    """Distance analytic to 1e-12 r, closest points on the line of centres."""
    res = closest_points(SPH, (np.zeros(3), I3), SPH, ((2 + gap) * R * d, I3))
    assert res.classification == "separated"
    assert abs(res.distance - gap * R) <= 1e-12 * R, (res.distance, gap * R)
    assert np.linalg.norm(res.point_a - R * d) <= 1e-9 * R
    assert np.linalg.norm(res.point_b - (1 + gap) * R * d) <= 1e-9 * R
    assert _cross(res.gap, d) <= 1e-9 * R
    assert res.iterations <= 50


def test_spheres_touching_and_intersecting():
    d = DIRS[0]
    # touching: f1 has a degenerate minimum (zero); stage 1 gets within 1e-9 r
    res = closest_points(SPH, (np.zeros(3), I3), SPH, (2 * R * d, I3))
    assert res.distance <= 1e-9 * R
    assert res.classification in ("intersecting", "separated", "degenerate")
    full = detect(SPH, (np.zeros(3), I3), SPH, (2 * R * d, I3))
    assert abs(full.signed_distance) <= 1e-12 * R and not full.failed
    for gap in (-1e-3, -0.05, -0.3):
        res = closest_points(SPH, (np.zeros(3), I3), SPH, ((2 + gap) * R * d, I3))
        assert res.classification == "intersecting", (gap, res)
        assert res.f1 < 1e-24 * res.lambda_max
        # the point lies on both spheres: on the intersection circle
        assert abs(np.linalg.norm(res.point_a) - R) <= 1e-12 * R


def test_ellipsoids_separated_against_reference():
    rng = np.random.default_rng(3)
    n_done = 0
    while n_done < 8:
        ra, rb = Rotation.random(2, random_state=rng).as_matrix()
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        pa, pb = (np.zeros(3), ra), (0.06 * u, rb)
        sd, n, qa, qb = ellipsoid_pair(AX_A, pa, AX_B, pb)
        if sd <= 1e-4:
            continue
        n_done += 1
        res = closest_points(EA, pa, EB, pb)
        assert res.classification == "separated"
        assert abs(res.distance - sd) <= 1e-12 * max(AX_A), (res.distance, sd)
        assert np.linalg.norm(res.point_a - qa) <= 1e-6 * max(AX_A)
        assert np.linalg.norm(res.point_b - qb) <= 1e-6 * max(AX_A)
        assert _cross(-res.gap / res.distance, n) <= 1e-7


def test_start_at_saddle_and_far_side():
    """Start exactly at the maximum-penetration points of intersecting spheres (a stationary
    saddle of f1, zero gradient) and at the far sides of separated spheres (a maximum): the
    trust region leaves along negative curvature and migrates across patches."""
    d = DIRS[2]
    pose_b = ((2 - 0.1) * R * d, I3)
    deep = detect(SPH, (np.zeros(3), I3), SPH, pose_b)       # stage 2: support points along ±d
    start = (deep.patch_a, *deep.params[:2], deep.patch_b, *deep.params[2:])
    res = closest_points(SPH, (np.zeros(3), I3), SPH, pose_b, start=start)
    assert res.classification == "intersecting"
    assert res.iterations >= 1
    # far sides: A's point at −d, B's point at c_B + R d (both stationary, f1 maximal)
    d = DIRS[0]
    pose_b = ((2.2) * R * d, I3)
    far_a = detect(SPH, (np.zeros(3), I3), SPH, (-1.9 * R * d, I3))   # support along −d
    far_b = detect(SPH, (np.zeros(3), I3), SPH, (1.9 * R * d, I3))    # support along +d
    start = (far_a.patch_a, *far_a.params[:2], far_b.patch_a, *far_b.params[:2])
    res = closest_points(SPH, (np.zeros(3), I3), SPH, pose_b, start=start)
    assert res.classification == "separated"
    assert abs(res.distance - 0.2 * R) <= 1e-12 * R
    assert np.linalg.norm(res.point_a - R * d) <= 1e-9 * R


def test_far_start_ellipsoids():
    rng = np.random.default_rng(8)
    ra, rb = Rotation.random(2, random_state=rng).as_matrix()
    u = np.array([0.2, 0.9, -0.3])
    u /= np.linalg.norm(u)
    pa, pb = (np.zeros(3), ra), (0.05 * u, rb)
    sd = ellipsoid_pair(AX_A, pa, AX_B, pb)[0]
    assert sd > 0
    for k in range(6):
        start = (k, 0.3, 0.7, (k + 3) % 6, 0.6, 0.2)
        res = closest_points(EA, pa, EB, pb, start=start)
        assert res.classification == "separated"
        assert abs(res.distance - sd) <= 1e-12 * max(AX_A)


def _stage2_only(shape_a, pose_a, shape_b, pose_b):
    """The previous pipeline (one minimisation over directions from the centroid
    direction): a fake 'previous penetrating' row makes detect skip stage 1."""
    ca = pose_a[0] + pose_a[1] @ shape_a.centroid
    cb = pose_b[0] + pose_b[1] @ shape_b.centroid
    seed = detect(shape_a, pose_a, shape_b, pose_b)
    rf = np.zeros(NF)
    ri = np.zeros(NI, np.int64)
    n = (cb - ca) / np.linalg.norm(cb - ca)
    rf[F_N:F_N + 3] = n
    rf[F_SD] = -1.0
    rf[F_PAR:F_PAR + 4] = seed.params
    ri[I_VALID] = 1
    ri[I_PA] = seed.patch_a
    ri[I_PB] = seed.patch_b
    return detect(shape_a, pose_a, shape_b, pose_b, previous=ContactResult.from_rows(rf, ri))


def _place(rng, target):
    ra, rb = Rotation.random(2, random_state=rng).as_matrix()
    u = rng.normal(size=3)
    u /= np.linalg.norm(u)
    pa = (-ra @ PA.centroid, ra)
    pos_b = 1.8 * PA.bounding_radius * u - rb @ PA.centroid
    for _ in range(4):
        r = detect(PA, pa, PA, (pos_b, rb))
        pos_b = pos_b + (target - r.signed_distance) * r.normal
    return pa, (pos_b, rb)


def test_cold_pipeline_particle_a_agrees_with_stage2():
    rng = np.random.default_rng(21)
    scale = 2 * PA.bounding_radius
    stages = {1: 0, 2: 0}
    for k in range(16):
        target = (0.02 if k % 2 == 0 else -0.01) * rng.uniform(0.01, 1.0) * PA.bounding_radius
        pa, pb = _place(rng, target)
        res = detect(PA, pa, PA, pb)
        ref = _stage2_only(PA, pa, PA, pb)
        assert not res.failed and not ref.failed
        assert abs(res.signed_distance - ref.signed_distance) <= 1e-12 * scale
        assert _cross(res.normal, ref.normal) <= 1e-9
        assert np.linalg.norm(res.point_a - ref.point_a) <= 1e-7 * scale
        assert res.active == (res.signed_distance < 0)
        stages[res.stage] += 1
        if res.signed_distance < 0:
            assert res.stage == 2
        assert res.iterations >= res.stage1_iterations >= 1
    assert stages[1] >= 7      # the separated pairs come from stage 1


def test_warm_stage1_is_cheap():
    """Previous result separated and a small pose change: stage 1 warm, <= 2 iterations."""
    rng = np.random.default_rng(5)
    for k in range(6):
        pa, pb = _place(rng, rng.uniform(0.002, 0.03) * PA.bounding_radius)
        prev = detect(PA, pa, PA, pb)
        assert prev.stage == 1
        dr = Rotation.from_rotvec(rng.normal(size=3) * 1e-5).as_matrix()
        pb2 = (pb[0] + rng.normal(size=3) * 1e-7, dr @ pb[1])
        res = detect(PA, pa, PA, pb2, previous=prev)
        cold = detect(PA, pa, PA, pb2)
        assert res.stage == 1 and res.stage1_iterations <= 2, res
        assert abs(res.signed_distance - cold.signed_distance) <= 1e-12 * PA.bounding_radius
    # ellipsoids
    for k in range(4):
        ra, rb = Rotation.random(2, random_state=rng).as_matrix()
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        pa, pb = (np.zeros(3), ra), (0.055 * u, rb)
        prev = detect(EA, pa, EB, pb)
        if prev.signed_distance <= 0:
            continue
        res = detect(EA, (pa[0] + 1e-7, pa[1]), EB, pb, previous=prev)
        assert res.stage == 1 and res.stage1_iterations <= 2


def test_stage_switching_through_contact():
    """Separated -> penetrating -> separated, each warm-started from the last result."""
    d = DIRS[1]
    prev = None
    for gap in (0.02, 0.005, -0.003, -0.01, 0.004, 0.01):
        res = detect(SPH, (np.zeros(3), I3), SPH, ((2 + gap) * R * d, I3), previous=prev)
        assert abs(res.signed_distance - gap * R) <= 1e-12 * R
        assert _cross(res.normal, d) <= 1e-9
        if prev is not None and prev.signed_distance > 0 and gap > 0:
            assert res.stage == 1
        if gap < 0:
            assert res.stage == 2 and res.active
        prev = res


def test_batch_stage_column():
    rng = np.random.default_rng(2)
    table = ContactTable([SPH, EA])
    K = 30
    d = rng.normal(size=(K, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    gap = rng.uniform(-0.1, 0.1, K) * R
    ra = Rotation.random(K, random_state=rng).as_matrix()
    rb = Rotation.random(K, random_state=rng).as_matrix()
    sa = np.zeros(K, np.int64)
    f, i = detect_batch(table, sa, np.zeros((K, 3)), ra, sa, (2 * R + gap)[:, None] * d, rb)
    assert not i[:, I_FAIL].any()
    assert np.abs(f[:, F_SD] - gap).max() <= 1e-12 * R
    assert np.all(i[gap > 0, I_STAGE] == 1)
    assert np.all(i[gap < 0, I_STAGE] == 2)

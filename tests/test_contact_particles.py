"""LCP on the paper's particles A, B, C (6 bicubic patches with slight C0 kinks along the
cube edges) against each other and against flat walls, compared with the independent
reference of :mod:`nurbsdem.contact.reference` (dense sampling of the support functions +
SciPy refinement on the NURBS). Configurations: face-on, edge-on, corner-on (the support
points at a patch interior, on a patch edge, at a 3-patch node of both bodies), generic,
grazing; walls: face-on, edge-on, corner-on, nearly parallel."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from nurbsdem.contact import detect, detect_wall
from nurbsdem.contact.reference import nurbs_pair, wall_reference
from nurbsdem.geometry.generators import flat_wall
from nurbsdem.geometry.particles import paper_particle_shape

SH = {k: paper_particle_shape(k) for k in "ABC"}
I3 = np.eye(3)
FEATURES = {"face": (1.0, 0.0, 0.0), "edge": (1.0, 1.0, 0.0), "corner": (1.0, 1.0, 1.0),
            "generic": (0.7, -0.3, 0.5)}


def place(a, b, d, depth, ra=I3, rb=I3):
    """Poses with A at its centroid frame origin and B along d with signed distance -depth
    (placed by translating B along the computed normal; checked against the reference)."""
    A, B = SH[a], SH[b]
    d = np.asarray(d, float) / np.linalg.norm(d)
    pa = (-ra @ A.centroid, ra)
    pos_b = 0.9 * (A.bounding_radius + B.bounding_radius) * d - rb @ B.centroid
    for _ in range(4):
        r = detect(A, pa, B, (pos_b, rb))
        pos_b = pos_b + (-depth - r.signed_distance) * r.normal
    return pa, (pos_b, rb)


def compare(a, pa, b, pb, tol_sd=1e-9, tol_n=1e-6):
    A, B = SH[a], SH[b]
    res = detect(A, pa, B, pb)
    sd, n, qa, qb = nurbs_pair(A, pa, B, pb, n=30, n_dirs=2000)
    assert not res.failed
    assert np.all(np.isfinite(res.row_f))
    assert abs(res.signed_distance - sd) <= tol_sd * A.bounding_radius, (res.signed_distance, sd)
    assert np.linalg.norm(np.cross(res.normal, n)) <= tol_n
    return res


@pytest.mark.parametrize("feature", ["face", "edge", "corner"])
def test_particle_pairs_features(feature):
    """Both bodies meet with the same feature type (identity rotations: −d has the same type)."""
    pa, pb = place("A", "B", FEATURES[feature], 1e-3)
    res = compare("A", pa, "B", pb)
    assert res.active


def test_particle_pair_generic_and_grazing():
    rng = np.random.default_rng(4)
    ra, rb = Rotation.random(2, random_state=rng).as_matrix()
    pa, pb = place("A", "C", FEATURES["generic"], 2e-3, ra, rb)
    compare("A", pa, "C", pb)
    pa, pb = place("B", "C", (0.1, 0.9, -0.4), -1e-7, ra, rb)   # grazing, separated
    res = compare("B", pa, "C", pb)
    assert not res.active and res.signed_distance > 0


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(6))
def test_particle_pairs_random_slow(seed):
    rng = np.random.default_rng(100 + seed)
    for _ in range(4):
        a, b = rng.choice(list("ABC"), 2)
        ra, rb = Rotation.random(2, random_state=rng).as_matrix()
        d = rng.normal(size=3)
        pa, pb = place(a, b, d, rng.uniform(-1e-3, 4e-3), ra, rb)
        compare(a, pa, b, pb)


WALL = flat_wall([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], (0.25, 0.25), [1.0, 0.0, 0.0])


def _rotation_to(v):
    """A rotation taking the file-frame direction v to -z (the feature v faces the floor)."""
    v = np.asarray(v, float) / np.linalg.norm(v)
    rot, _ = Rotation.align_vectors([[0.0, 0.0, -1.0]], [v])
    return rot.as_matrix()


@pytest.mark.parametrize("feature", ["face", "edge", "corner", "generic", "nearly_parallel"])
@pytest.mark.parametrize("kind", ["A", "C"])
def test_particle_on_flat_wall(feature, kind):
    S = SH[kind]
    if feature == "nearly_parallel":
        R = Rotation.from_rotvec([1e-4, -2e-4, 0.0]).as_matrix() @ _rotation_to((0, 0, -1))
    else:
        R = _rotation_to(FEATURES[feature])
    base = np.array([0.01, -0.02, 0.0]) - R @ S.centroid
    lowest = detect_wall(S, (base, R), WALL)
    pos = base + np.array([0.0, 0.0, -lowest.signed_distance - 1e-3])   # depth 1 mm
    res = detect_wall(S, (pos, R), WALL)
    sd, p = wall_reference(S, (pos, R), [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], n=30)
    assert res.active and not res.failed
    assert abs(res.signed_distance - sd) <= 1e-10 * S.bounding_radius
    assert res.signed_distance == pytest.approx(-1e-3, abs=1e-12)
    assert np.allclose(res.normal, [0, 0, -1])
    assert np.allclose(res.gap, -res.signed_distance * res.normal, atol=1e-14)
    # warm start: one support mapping from the previous parameters
    res2 = detect_wall(S, (pos + [0, 0, 1e-6], R), WALL, previous=res)
    assert res2.signed_distance == pytest.approx(res.signed_distance + 1e-6, abs=1e-12)


def test_wall_rectangle_and_far():
    S = SH["C"]
    far = detect_wall(S, (np.array([0.0, 0.0, 0.2]), I3), WALL)
    assert far.broad_rejected and not far.active
    outside = detect_wall(S, (np.array([0.2, 0.0, 0.0]), I3), WALL)
    assert not outside.active

"""Mass properties from the boundary (nurbsdem.geometry.mass) against analytic values and an
independent polyhedral method."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import ConvexHull
from scipy.spatial.transform import Rotation

from nurbsdem.geometry.generators import (ellipsoid_patches, single_patch_sphere_patches,
                                          sphere_patches)
from nurbsdem.geometry.mass import (inertia_from_second_moment, mass_properties,
                                    second_moment_from_inertia)
from nurbsdem.geometry.nurbs import Patch

TIGHT = 1e-10


def rel(a, b) -> float:
    return float(np.linalg.norm(np.asarray(a) - np.asarray(b)) / np.linalg.norm(b))


def ellipsoid_inertia(a: float, b: float, c: float) -> tuple[float, np.ndarray]:
    v = 4.0 / 3.0 * np.pi * a * b * c
    return v, v / 5.0 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])


def box_patches(lo, hi) -> list[Patch]:
    """Closed box from six degree-1 patches with outward S_u x S_v."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    k = np.array([0.0, 0.0, 1.0, 1.0])
    out = []
    faces = [((1, 0, 0), 1, 2), ((-1, 0, 0), 2, 1), ((0, 1, 0), 2, 0), ((0, -1, 0), 0, 2),
             ((0, 0, 1), 0, 1), ((0, 0, -1), 1, 0)]
    for n, a, b in faces:
        ax = int(np.flatnonzero(n)[0])
        pts = np.zeros((2, 2, 3))
        for i in range(2):
            for j in range(2):
                x = lo.copy()
                x[ax] = hi[ax] if sum(n) > 0 else lo[ax]
                x[a] = (lo, hi)[i][a]
                x[b] = (lo, hi)[j][b]
                pts[i, j] = x
        out.append(Patch(1, 1, k, k.copy(), pts))
    return out


@pytest.mark.parametrize("r", [1.0, 0.0137])
def test_sphere_exact(r):
    v, c, j = mass_properties(sphere_patches(r))
    V = 4.0 / 3.0 * np.pi * r ** 3
    assert abs(v / V - 1) < TIGHT
    assert np.linalg.norm(c) < TIGHT * r
    assert rel(j, 0.4 * r * r * V * np.eye(3)) < TIGHT


def test_ellipsoid_exact():
    a, b, c_ = 0.03, 0.02, 0.012
    v, c, j = mass_properties(ellipsoid_patches(a, b, c_))
    V, J = ellipsoid_inertia(a, b, c_)
    assert abs(v / V - 1) < TIGHT
    assert np.linalg.norm(c) < TIGHT * a
    assert rel(j, J) < TIGHT


def test_rotated_translated_ellipsoid_full_tensor():
    a, b, c_ = 2.0, 1.3, 0.7
    R = Rotation.from_rotvec([0.3, -1.1, 0.7]).as_matrix()
    off = np.array([5.0, -3.0, 2.5])
    v, c, j = mass_properties([p.transformed(R, off) for p in ellipsoid_patches(a, b, c_)])
    V, J0 = ellipsoid_inertia(a, b, c_)
    J = R @ J0 @ R.T
    assert np.abs(J[np.triu_indices(3, 1)]).min() > 0.03 * np.abs(J).max()  # genuinely full
    assert abs(v / V - 1) < TIGHT
    assert np.linalg.norm(c - off) < TIGHT * a
    assert rel(j, J) < TIGHT
    assert np.allclose(j, j.T, rtol=0, atol=1e-14 * np.abs(J).max())


def test_single_patch_sphere_with_poles_and_seam():
    r = 0.25
    v, c, j = mass_properties(single_patch_sphere_patches(r))
    V = 4.0 / 3.0 * np.pi * r ** 3
    assert abs(v / V - 1) < TIGHT
    assert np.linalg.norm(c) < TIGHT * r
    assert rel(j, 0.4 * r * r * V * np.eye(3)) < TIGHT


def test_box_of_flat_patches():
    lo, hi = np.array([-0.1, 0.2, 1.0]), np.array([0.3, 0.25, 1.7])
    R = Rotation.from_rotvec([0.4, 0.2, -0.9]).as_matrix()
    v, c, j = mass_properties([p.transformed(R) for p in box_patches(lo, hi)])
    a, b, cc = hi - lo
    V = a * b * cc
    J0 = V / 12.0 * np.diag([b * b + cc * cc, a * a + cc * cc, a * a + b * b])
    assert abs(v / V - 1) < 1e-13
    assert np.linalg.norm(c - R @ (0.5 * (lo + hi))) < 1e-13
    assert rel(j, R @ J0 @ R.T) < 1e-12


def test_inward_orientation_gives_negative_volume():
    flipped = [Patch(p.degree_v, p.degree_u, p.knots_v, p.knots_u,
                     p.control_points.transpose(1, 0, 2), p.weights.T)
               for p in sphere_patches(1.0)]
    v, _, _ = mass_properties(flipped)
    assert abs(v + 4.0 / 3.0 * np.pi) < 1e-10


def polyhedron_mass_properties(points: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Volume, centroid and inertia of the convex hull of points (tetrahedra from the centre)."""
    hull = ConvexHull(points)
    o = points[hull.vertices].mean(0)
    tri = points[hull.simplices] - o  # (T, 3, 3)
    vol_t = np.abs(np.einsum("ti,ti->t", tri[:, 0], np.cross(tri[:, 1], tri[:, 2]))) / 6.0
    V = vol_t.sum()
    cen = (vol_t[:, None] * tri.sum(1) / 4.0).sum(0) / V
    # second moment of a tetrahedron (0, a, b, c): V/20 (sum_k v_k v_kᵀ + s sᵀ), s = a + b + c
    s = tri.sum(1)
    m2 = np.einsum("t,tki,tkj->ij", vol_t, tri, tri) + np.einsum("t,ti,tj->ij", vol_t, s, s)
    m2 = m2 / 20.0 - V * np.outer(cen, cen)
    return V, o + cen, inertia_from_second_moment(m2)


def test_random_convex_body_against_convex_hull():
    """Random affine image of the paper's particle A vs a dense polyhedral tessellation."""
    from nurbsdem.geometry.particles import paper_particle

    rng = np.random.default_rng(7)
    L = np.eye(3) + 0.4 * rng.standard_normal((3, 3))
    if np.linalg.det(L) < 0:
        L[:, 0] *= -1
    offset = rng.standard_normal(3) * 0.05
    patches = [p.transformed(L, offset) for p in paper_particle("A")]
    v, c, j = mass_properties(patches)
    t = np.linspace(0.0, 2.0, 61)
    U, W = np.meshgrid(t, t, indexing="ij")
    pts = np.concatenate([p.points(U, W).reshape(-1, 3) for p in patches])
    V, C, J = polyhedron_mass_properties(pts)
    size = np.linalg.norm(pts.max(0) - pts.min(0))
    assert abs(v / V - 1) < 1e-3
    assert np.linalg.norm(c - C) < 1e-3 * size
    assert rel(j, J) < 2e-3
    assert v > V  # the inscribed polyhedron is smaller


def test_second_moment_inertia_round_trip():
    m2 = np.array([[3.0, 0.2, -0.1], [0.2, 2.0, 0.05], [-0.1, 0.05, 1.0]])
    assert np.allclose(second_moment_from_inertia(inertia_from_second_moment(m2)), m2)

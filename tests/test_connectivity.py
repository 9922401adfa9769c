"""Connectivity found from the geometry, and the closed / oriented / convex shape checks."""
from __future__ import annotations


import numpy as np
import pytest

from nurbsdem.errors import GeometryError
from nurbsdem.geometry import generators as gen
from nurbsdem.geometry.connectivity import (EDGE_SENSE, Connectivity, edge_uv,
                                            map_to_neighbour_nb)
from nurbsdem.geometry.nurbs import Patch
from nurbsdem.geometry.shape import Shape
from nurbsdem.io.shapefile import load_shape, save_shape


def _transposed(p: Patch) -> Patch:
    return Patch(p.degree_v, p.degree_u, p.knots_v, p.knots_u,
                 p.control_points.transpose(1, 0, 2), p.weights.T)


@pytest.fixture(scope="module")
def sphere():
    return gen.sphere(0.5)


def _edge_points(patch: Patch, e: int, s):
    u, v = edge_uv(patch.domain, e, s)
    return patch.points(u, v)


def _assert_neighbours_coincide(shape, s=np.linspace(0, 1, 13)):
    conn = shape.connectivity
    for i, p in enumerate(shape.patches):
        for e in range(4):
            j, f, r = conn.neighbours[i, e]
            if j < 0:
                continue
            here = _edge_points(p, e, s)
            there = np.array([shape.patches[jj].points(u, v) for jj, u, v in
                              (conn.map_to_neighbour(i, e, t) for t in s)])
            assert np.abs(here - there).max() < 1e-12 * shape.size
            # symmetric
            assert tuple(conn.neighbours[j, f]) == (i, e, r)
            # consistently oriented: the shared edge is run in opposite directions
            assert EDGE_SENSE[e] * EDGE_SENSE[f] * (-1 if r else 1) == -1


def test_six_patch_sphere_connectivity(sphere):
    conn = sphere.connectivity
    assert isinstance(conn, Connectivity)
    assert conn.neighbours.shape == (6, 4, 3) and conn.neighbours.dtype == np.int64
    assert conn.closed and np.all(conn.neighbours[:, :, 0] >= 0)
    assert np.all(conn.neighbours[:, :, 0] != np.arange(6)[:, None])  # no seams
    _assert_neighbours_coincide(sphere)


def test_six_patch_sphere_corners(sphere):
    conn = sphere.connectivity
    assert len(conn.corners) == 8
    for c in conn.corners:
        assert sorted(c.patches) == sorted(set(c.patches)) and len(c.patches) == 3
        assert np.isclose(np.linalg.norm(c.position), 0.5)
        for ip, u, v in c.members:
            assert np.abs(sphere.patches[ip].points(u, v) - c.position).max() < 1e-12
    # packed arrays agree with the list, every patch corner is a 3-patch node
    assert np.all(conn.corner_index >= 0)
    assert conn.corner_patch.shape == (8, 3) and conn.corner_pos.shape == (8, 3)
    for i in range(6):
        for k in range(4):
            assert i in conn.corners[conn.corner_index[i, k]].patches


def test_single_patch_sphere_poles_and_seam():
    sh = gen.single_patch_sphere(2.0)
    nbr = sh.connectivity.neighbours
    assert tuple(nbr[0, 0]) == (0, 1, 0)      # seam: u_min is u_max, same direction
    assert tuple(nbr[0, 1]) == (0, 0, 0)
    assert tuple(nbr[0, 2]) == (-2, -1, -1)   # poles
    assert tuple(nbr[0, 3]) == (-2, -1, -1)
    assert sh.connectivity.corners == []
    _assert_neighbours_coincide(sh)
    j, u, v = sh.connectivity.map_to_neighbour(0, 0, 0.3)
    assert (j, u) == (0, 1.0) and np.isclose(v, 0.3)
    j, u, v = sh.connectivity.map_to_neighbour(0, 2, 0.4)   # a pole: own parameters
    assert j == -2 and (u, v) == (0.4, 0.0)


def test_ellipsoid_and_paper_particle_closed():
    _assert_neighbours_coincide(gen.ellipsoid(0.03, 0.02, 0.01))
    particles = pytest.importorskip("nurbsdem.geometry.particles")
    sh = Shape(particles.paper_particle("A"))
    assert sh.connectivity.closed and len(sh.connectivity.corners) == 8
    _assert_neighbours_coincide(sh)


def test_compiled_map_matches(sphere):
    nbr, dom = sphere.connectivity.arrays
    for i in range(6):
        for e in range(4):
            for s in (0.0, 0.25, 1.0):
                assert map_to_neighbour_nb(nbr, dom, i, e, s) == \
                    sphere.connectivity.map_to_neighbour(i, e, s)


def test_tolerance_is_relative_to_size():
    for r in (1e-4, 1.0, 1e3):
        sh = gen.sphere(r)
        assert sh.connectivity.closed
        assert np.isclose(sh.connectivity.tol, 1e-6 * sh.size)


# ---------------------------------------------------------------------- rejections
def test_gap_names_patch_and_edge():
    patches = gen.sphere_patches(1.0)[:5]
    with pytest.raises(GeometryError, match=r"^shape\.yaml: patch \d, edge \d \(\w+\): the "
                                            r"surface is not closed"):
        Shape(patches, source="shape.yaml")
    sh = Shape(patches, check=False)          # allowed without the check: open edges = -1
    assert not sh.connectivity.closed
    assert np.sum(sh.connectivity.neighbours[:, :, 0] == -1) == 4


def test_overlap_is_rejected():
    patches = gen.sphere_patches(1.0)
    with pytest.raises(GeometryError, match="overlapping or non-manifold"):
        Shape(patches + [patches[0]], source="x.yaml")


def test_parametrisation_mismatch_is_named():
    """Edges that share their end points but not the points in between are named."""
    patches = gen.sphere_patches(1.0)
    p = patches[0]
    w = p.weights.copy()
    w[0, 2] *= 1.5             # changes the interior of edge u_min, not its end points
    patches[0] = Patch(4, 4, p.knots_u, p.knots_v, p.control_points, w)
    with pytest.raises(GeometryError, match=r"patch 0, edge 0 \(u_min\): edge has the end points"):
        Shape(patches, source="x.yaml")


def test_inconsistent_orientation_is_rejected():
    patches = gen.sphere_patches(1.0)
    patches[3] = _transposed(patches[3])
    with pytest.raises(GeometryError, match=r"inconsistent orientation") as ei:
        Shape(patches, source="x.yaml")
    assert "3" in str(ei.value)


def test_inward_normals_are_rejected():
    patches = [_transposed(p) for p in gen.sphere_patches(1.0)]
    with pytest.raises(GeometryError, match=r"^x\.yaml: patch 0: normals S_u x S_v point into"):
        Shape(patches, source="x.yaml")


def test_nonconvex_is_rejected_with_location(tmp_path):
    patches = gen.sphere_patches(1.0)
    p = patches[2]
    cp = p.control_points.copy()
    cp[2, 2] *= -0.5           # push the middle control point through the centre: a dent
    patches[2] = Patch(4, 4, p.knots_u, p.knots_v, cp, p.weights)
    f = tmp_path / "dent.yaml"
    save_shape(f, patches)
    with pytest.raises(GeometryError) as ei:
        load_shape(f)
    msg = str(ei.value)
    assert msg.startswith(f"{f}: patch 2") and "not convex" in msg and "(u, v) = (" in msg
    assert "\n" not in msg


def test_slightly_concave_face_is_rejected():
    """A face whose middle is only slightly concave (flattening the face with the middle
    control point at the centre of the sphere): refused with tolerance 0, accepted with a
    warning under the default tolerance."""
    patches = gen.sphere_patches(1.0)
    p = patches[4]
    cp = p.control_points.copy()
    cp[2, 2] = 0.0
    patches[4] = Patch(4, 4, p.knots_u, p.knots_v, cp, p.weights)
    with pytest.raises(GeometryError, match=r"patch 4: not convex: the surface rises .* m "
                       r"\(1\.4\d?e-06 of the particle size 4\.34 m\).*outward normal curvature"):
        Shape(patches, convexity_tol=0.0)               # strict: any non-convexity refused
    sh = Shape(patches)                                  # 1.4e-6 of the size: accepted, warned
    assert sh.warnings and "patch 4: nearly convex" in sh.warnings[0]
    cp[2, 2] = 0.5 * p.control_points[2, 2]          # flatter but still convex: accepted
    patches[4] = Patch(4, 4, p.knots_u, p.knots_v, cp, p.weights)
    assert not Shape(patches, convexity_tol=0.0).warnings

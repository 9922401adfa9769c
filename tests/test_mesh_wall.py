"""Triangle-mesh walls (nurbsdem.contact.mesh_wall): closest points against trimesh's own,
a tessellated plane against the flat wall's closed form, one contact per flat or convex region,
one per face in a concave fold, the grid against all triangles, poses and bad meshes."""
import math

import numpy as np
import pytest
import trimesh

from nurbsdem.contact.flat_wall import sphere_wall_row
from nurbsdem.contact.lcp import F_N, F_PA, F_PB, F_SD, I_ACTIVE, I_PB, NF, NI
from nurbsdem.contact.mesh_wall import (FACE, build_mesh_wall, closest_on_triangle,
                                        make_workspace, sphere_contacts, triangles_near)
from nurbsdem.errors import InputError


def plane_mesh(n, half=1.0, z=0.0):
    """n x n squares over [-half, half]^2 at height z, each split in two triangles, normals +z."""
    s = np.linspace(-half, half, n + 1)
    gx, gy = np.meshgrid(s, s, indexing="ij")
    verts = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, z)])
    faces = []
    for i in range(n):
        for j in range(n):
            a, b = i * (n + 1) + j, (i + 1) * (n + 1) + j
            faces += [(a, b, b + 1), (a, b + 1, a + 1)]
    return verts, np.array(faces)


def test_closest_point_equals_trimesh():
    rng = np.random.default_rng(1)
    for _ in range(300):
        tri = rng.normal(size=(3, 3))
        p = rng.normal(size=3) * 2.0
        q0, q1, q2, _ = closest_on_triangle(p, tri[0], tri[1], tri[2])
        ref = trimesh.triangles.closest_point(tri[None], p[None])[0]
        assert np.allclose([q0, q1, q2], ref, atol=1e-12)


def test_two_triangle_floor_equals_the_flat_wall():
    mesh = build_mesh_wall(*plane_mesh(1, half=0.5))
    wall_origin = np.array([[-0.5, -0.5, 0.0]])
    wall_a, wall_b = np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]])
    rng = np.random.default_rng(2)
    for _ in range(50):
        x = np.array([*rng.uniform(-0.45, 0.45, 2), rng.uniform(0.005, 0.0099)])
        rf, ri = sphere_contacts(mesh, x, 0.01)
        assert len(rf) == 1
        ref_f, ref_i = np.zeros((1, NF)), np.zeros((1, NI), np.int64)
        sphere_wall_row(x[0], x[1], x[2], 0.01, 0, np.zeros((1, 3)), wall_origin, wall_a,
                        wall_b, np.array([[0, 1.0, 0, 1.0]]), ref_f, ref_i, 0)
        for col in (F_SD, F_N, F_N + 1, F_N + 2, *range(F_PA, F_PA + 3), *range(F_PB, F_PB + 3)):
            assert rf[0, col] == pytest.approx(ref_f[0, col], abs=1e-17)
        assert ri[0, I_ACTIVE] == ref_i[0, I_ACTIVE] == 1


def test_sliding_over_a_tessellated_plane_sees_one_contact_of_the_plane():
    """Every centre of a path over a 40 x 40 plane, through the internal edges and vertices:
    one contact, the plane's distance and normal to round-off."""
    mesh = build_mesh_wall(*plane_mesh(40))
    h, r = 0.05, 0.0501
    xs = np.linspace(-0.9, 0.9, 721)          # hits grid lines (spacing 0.05) exactly
    for x in xs:
        for y in (0.0, 0.025, x, 0.3 * x + 0.01):
            rf, ri = sphere_contacts(mesh, np.array([x, y, h]), r)
            assert len(rf) == 1, (x, y, len(rf))
            assert rf[0, F_SD] == pytest.approx(h - r, abs=1e-16)
            assert np.allclose(rf[0, F_N:F_N + 3], [0, 0, -1], atol=1e-15)
            assert np.allclose(rf[0, F_PB:F_PB + 3], [x, y, 0], atol=1e-15)


def test_convex_fold_gives_one_contact_along_the_edge_normal_cone():
    mesh = build_mesh_wall(trimesh.creation.box(extents=(1, 1, 1)).vertices,
                           trimesh.creation.box(extents=(1, 1, 1)).faces)
    r = 0.1
    # outside the edge x = 0.5, z = 0.5 (along y), at 45 degrees
    c = np.array([0.5 + 0.06, 0.1, 0.5 + 0.06])
    rf, _ = sphere_contacts(mesh, c, r)
    assert len(rf) == 1
    assert rf[0, F_SD] == pytest.approx(math.hypot(0.06, 0.06) - r, abs=1e-15)
    assert np.allclose(rf[0, F_N:F_N + 3], [-1 / math.sqrt(2), 0, -1 / math.sqrt(2)], atol=1e-15)
    # outside a corner
    c = np.array([0.55, 0.55, 0.55])
    rf, _ = sphere_contacts(mesh, c, r)
    assert len(rf) == 1
    assert rf[0, F_SD] == pytest.approx(math.sqrt(3) * 0.05 - r, abs=1e-15)
    # above a face, next to the edge: the face's contact only
    c = np.array([0.45, 0.0, 0.55])
    rf, _ = sphere_contacts(mesh, c, r)
    assert len(rf) == 1 and rf[0, F_SD] == pytest.approx(0.05 - r, abs=1e-15)


def test_concave_fold_gives_one_contact_per_face():
    """A V of two planes at +-45 degrees (the inner corner of a hopper): a sphere resting in it
    touches both faces, each along its own normal."""
    v = np.array([[-1, -1, 1], [-1, 1, 1], [0, -1, 0], [0, 1, 0], [1, -1, 1], [1, 1, 1.0]])
    f = np.array([[0, 2, 3], [0, 3, 1], [2, 4, 5], [2, 5, 3]])
    mesh = build_mesh_wall(v, f)
    r = 0.2
    c = np.array([0.0, 0.1, 0.25])
    rf, _ = sphere_contacts(mesh, c, r)
    assert len(rf) == 2
    d = 0.25 / math.sqrt(2)
    assert np.allclose(sorted(rf[:, F_SD]), [d - r, d - r], atol=1e-15)
    normals = sorted(map(tuple, np.round(rf[:, F_N:F_N + 3], 12)))
    s = 1 / math.sqrt(2)
    assert np.allclose(normals, [(-s, 0, -s), (s, 0, -s)], atol=1e-12)


def test_grid_finds_every_triangle_within_reach():
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    mesh = build_mesh_wall(sphere.vertices, sphere.faces)
    stamp, tris = make_workspace(mesh)[:2]
    rng = np.random.default_rng(3)
    a, b, c = (mesh.vertices[mesh.faces[:, k]] for k in range(3))
    for mark in range(100):
        x = rng.uniform(-1.3, 1.3, 3)
        reach = rng.uniform(0.01, 0.3)
        n = triangles_near(x, reach, mesh.grid_origin, mesh.grid_cell, mesh.grid_dims,
                           mesh.cell_start, mesh.cell_tris, stamp, mark, tris)
        found = set(tris[:n].tolist())
        assert len(found) == n
        near = {t for t in range(len(mesh.faces))
                if np.linalg.norm(x - closest_on_triangle(x, a[t], b[t], c[t])[:3]) < reach}
        assert near <= found


def test_grid_lists_each_triangle_in_every_cell_its_box_touches():
    """The grid's CSR arrays against binning triangle by triangle: each cell lists the
    triangles whose bounding box touches it, in ascending order; each triangle's cell range."""
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    verts = sphere.vertices * np.array([1.0, 0.6, 0.3])      # cells spanned differ per axis
    mesh = build_mesh_wall(verts, sphere.faces)
    lo, hi = mesh.tri_cells[:, :3], mesh.tri_cells[:, 3:]
    corners = verts[sphere.faces]
    assert np.array_equal(lo, np.floor((corners.min(axis=1) - mesh.grid_origin)
                                       / mesh.grid_cell).astype(np.int64))
    assert np.array_equal(hi, np.floor((corners.max(axis=1) - mesh.grid_origin)
                                       / mesh.grid_cell).astype(np.int64))
    dims = mesh.grid_dims
    expected = [[] for _ in range(int(np.prod(dims)))]
    for t in range(len(sphere.faces)):
        for ix in range(lo[t, 0], hi[t, 0] + 1):
            for iy in range(lo[t, 1], hi[t, 1] + 1):
                for iz in range(lo[t, 2], hi[t, 2] + 1):
                    expected[ix + dims[0] * (iy + dims[1] * iz)].append(t)
    assert (hi - lo).max() >= 1                               # triangles spanning cells
    for cell, tris in enumerate(expected):
        got = mesh.cell_tris[mesh.cell_start[cell]:mesh.cell_start[cell + 1]]
        assert got.tolist() == tris, cell


def test_contacts_of_a_rotated_moved_mesh_equal_those_of_the_moved_sphere():
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.5)
    mesh = build_mesh_wall(sphere.vertices, sphere.faces)
    rng = np.random.default_rng(4)
    R, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    R *= np.sign(np.linalg.det(R))
    t = rng.normal(size=3)
    x_mesh = np.array([0.3, 0.2, 0.45])
    ref_f, ref_i = sphere_contacts(mesh, x_mesh, 0.1)
    got_f, got_i = sphere_contacts(mesh, R @ x_mesh + t, 0.1, R, t)
    assert len(ref_f) == len(got_f) >= 1
    assert np.array_equal(ref_i[:, I_PB], got_i[:, I_PB])
    assert np.allclose(got_f[:, F_SD], ref_f[:, F_SD], atol=1e-15)
    assert np.allclose(got_f[:, F_N:F_N + 3], ref_f[:, F_N:F_N + 3] @ R.T, atol=1e-14)
    assert np.allclose(got_f[:, F_PB:F_PB + 3], ref_f[:, F_PB:F_PB + 3] @ R.T + t, atol=1e-14)


def test_one_sided_mesh_ignores_the_back_face():
    verts, faces = plane_mesh(2)
    one = build_mesh_wall(verts, faces, two_sided=False)
    two = build_mesh_wall(verts, faces, two_sided=True)
    below = np.array([0.1, 0.2, -0.05])
    assert len(sphere_contacts(one, below, 0.1)[0]) == 0
    rf, _ = sphere_contacts(two, below, 0.1)
    assert len(rf) == 1 and np.allclose(rf[0, F_N:F_N + 3], [0, 0, 1])
    assert len(sphere_contacts(one, -below, 0.1)[0]) == 1


def test_bad_meshes_are_refused_with_the_reason():
    verts, faces = plane_mesh(1)
    with pytest.raises(InputError, match="drum.stl: triangle 1 is degenerate"):
        build_mesh_wall(verts, np.array([[0, 1, 2], [0, 0, 3]]), source="drum.stl")
    bad = verts.copy()
    bad[2, 1] = np.nan
    with pytest.raises(InputError, match="vertex 2 is not finite"):
        build_mesh_wall(bad, faces)
    with pytest.raises(InputError, match="outside 0..3"):
        build_mesh_wall(verts, np.array([[0, 1, 7]]))


def test_face_feature_constant():
    q = closest_on_triangle(np.array([0.2, 0.2, 1.0]), np.zeros(3), np.array([1.0, 0, 0]),
                            np.array([0, 1.0, 0]))
    assert q[3] == FACE and np.allclose(q[:3], [0.2, 0.2, 0])

"""NURBS particles against mesh and NURBS-surface walls (nurbsdem.contact.mesh_particle,
nurbsdem.contact.surface_particle): an exact ellipsoid on a two-triangle floor and over a
tessellated plane against the flat wall's kernel, edge and vertex contacts against the
ellipsoid's analytic support function, convex and concave folds, the ellipsoid inside an
exact cylinder against the analytic contact and the same cylinder as a mesh (chord error), a
wall pocket narrower than the particle refused, moved walls, and the compiled surface-wall
solve against its Python reference in the drum and the cone of inputs/, and the compiled
mesh solve against its Python reference over a cube and a bumped plane.  (Runs:
test_mesh_walls_deck, test_wall_checks.)"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq, minimize, minimize_scalar

from nurbsdem import shapes
from nurbsdem.contact.detect import table_of
from nurbsdem.contact.lcp import F_N, F_PA, F_PB, F_SD, I_ACTIVE
from nurbsdem.contact.mesh_particle import particle_mesh_contacts
from nurbsdem.contact.mesh_wall import build_mesh_wall
from nurbsdem.contact.surface_particle import (ContactNotUnique, particle_surface_row,
                                               particle_surface_row_reference)
from nurbsdem.contact.surface_wall import build_surface_wall
from nurbsdem.contact.flat_wall import detect_wall
from nurbsdem.geometry.rotation import quat_from_rotvec, quat_to_matrix
from nurbsdem.geometry.surfaces import cylinder_patch
from nurbsdem.io.shapefile import read_patches

sys.path.insert(0, str(Path(__file__).parent))
from test_mesh_wall import plane_mesh  # noqa: E402
from test_surface_wall import _tessellated_cylinder, LENGTH, RADIUS  # noqa: E402

AXES = (0.03, 0.02, 0.015)
ELLIPSOID = shapes.ellipsoid(*AXES)
TABLE = table_of(ELLIPSOID)
FLOOR = shapes.flat_wall([0, 0, 0], [0, 0, 1], (1.0, 1.0))


def _rotation(rv) -> np.ndarray:
    return quat_to_matrix(quat_from_rotvec(np.asarray(rv, float)))


def _support_matrix(R: np.ndarray) -> np.ndarray:
    """M = R diag(a², b², c²) Rᵀ: the ellipsoid's support function is h(d) = c·d + √(dᵀMd)."""
    return R @ np.diag(np.square(AXES)) @ R.T


def _pose(c, R):
    return np.asarray(c, float) - R @ ELLIPSOID.centroid, R


def _same_as_flat(rf, pos, R, atol=1e-16):
    ref = detect_wall(ELLIPSOID, (pos, R), FLOOR)
    assert rf[F_SD] == pytest.approx(ref.signed_distance, abs=atol)
    np.testing.assert_allclose(rf[F_PA:F_PA + 3], ref.point_a, rtol=0, atol=atol)
    np.testing.assert_allclose(rf[F_PB:F_PB + 3], ref.point_b, rtol=0, atol=atol)
    np.testing.assert_allclose(rf[F_N:F_N + 3], ref.normal, rtol=0, atol=atol)


def test_ellipsoid_on_a_two_triangle_floor_equals_the_flat_wall():
    """At several orientations and places (on either triangle and on the diagonal), one
    contact whose depth, points and normal are the flat wall's to round-off (1e-16 m: the
    support mapping's convergence from a different start)."""
    mesh = build_mesh_wall(*plane_mesh(1, half=0.5))
    rng = np.random.default_rng(0)
    for k in range(6):
        R = _rotation(rng.normal(size=3))
        xy = (0.1, 0.1) if k == 0 else rng.uniform(-0.3, 0.3, 2)
        c = np.array([*xy, math.sqrt(_support_matrix(R)[2, 2]) - 1e-4])
        pos, R = _pose(c, R)
        rf, ri = particle_mesh_contacts(TABLE, 0, pos, R, mesh)
        assert len(rf) == 1 and ri[0, I_ACTIVE] == 1
        _same_as_flat(rf[0], pos, R)


def test_ellipsoid_across_the_internal_edges_of_a_tessellated_plane():
    """A path over a 20 x 20 plane of 1 cm squares (the ellipsoid's contact crosses edges
    and vertices): always one contact, the flat wall's to round-off (no kick)."""
    mesh = build_mesh_wall(*plane_mesh(20, half=0.1))
    R = _rotation([0.4, 0.2, -0.3])
    h = math.sqrt(_support_matrix(R)[2, 2]) - 2e-4
    for x in np.linspace(-0.02, 0.02, 17):
        pos, R = _pose([x, 0.37 * x + 0.001, h], R)
        rf, _ = particle_mesh_contacts(TABLE, 0, pos, R, mesh)
        assert len(rf) == 1
        _same_as_flat(rf[0], pos, R)


def _edge_reference(c, M, p0, p1):
    """sd of the ellipsoid (centre c, support matrix M) against the line through p0, p1:
    −min over d ⊥ t of h(d) − d·p0, with the analytic h (1-D, dense start then Brent)."""
    t = (p1 - p0) / np.linalg.norm(p1 - p0)
    e1 = np.cross(t, [0.3, 0.5, 0.8])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(t, e1)

    def f(th):
        d = math.cos(th) * e1 + math.sin(th) * e2
        return c @ d + math.sqrt(d @ M @ d) - d @ p0
    ths = np.linspace(0, 2 * math.pi, 721)
    k = int(np.argmin([f(th) for th in ths]))
    r = minimize_scalar(f, bracket=(ths[k - 1], ths[k], ths[k + 1]), tol=1e-14)
    return -r.fun


def _vertex_reference(c, M, V):
    """sd of the point V against the ellipsoid: −min over unit d of h(d) − d·V."""
    def f(a):
        d = np.array([math.sin(a[0]) * math.cos(a[1]), math.sin(a[0]) * math.sin(a[1]),
                      math.cos(a[0])])
        return c @ d + math.sqrt(d @ M @ d) - d @ V
    best = min((minimize(f, [a, b], method="Nelder-Mead",
                         options=dict(xatol=1e-13, fatol=1e-17, maxiter=4000))
                for a in np.linspace(0.3, 2.8, 3) for b in np.linspace(0, 5, 3)),
               key=lambda r: r.fun)
    return -best.fun


def test_edge_and_vertex_contacts_of_one_triangle_against_the_support_function():
    """Beside an edge (penetrating and apart) and beyond a vertex of a tilted triangle: one
    contact, of that feature, with the analytic support function's signed distance."""
    tri = np.array([[0.0, 0, 0], [0.1, 0, 0], [0.0, 0.1, 0.02]])
    one = build_mesh_wall(tri, np.array([[0, 1, 2]]))
    R = _rotation([0.4, 0.2, -0.3])
    M = _support_matrix(R)
    cases = [([0.05, -0.012, 0.0], "edge"), ([0.05, -0.02, 0.005], "edge"),
             ([-0.012, -0.012, 0.0], 0), ([0.12, -0.01, 0.0], 1)]
    for c, feature in cases:
        c = np.array(c)
        rf, _ = particle_mesh_contacts(TABLE, 0, *_pose(c, R), one, active_only=False)
        assert len(rf) == 1
        if feature == "edge":
            ref = _edge_reference(c, M, tri[0], tri[1])
            assert rf[0, F_PB + 1] == pytest.approx(0.0, abs=1e-15)      # on edge AB
        else:
            ref = _vertex_reference(c, M, tri[feature])
            np.testing.assert_allclose(rf[0, F_PB:F_PB + 3], tri[feature], atol=1e-15)
        assert rf[0, F_SD] == pytest.approx(ref, abs=1e-11 * max(AXES))
        gap = rf[0, F_PB:F_PB + 3] - rf[0, F_PA:F_PA + 3]     # along the normal, length |sd|
        np.testing.assert_allclose(gap, rf[0, F_SD] * rf[0, F_N:F_N + 3], atol=1e-14)


def _cylinder_reference(c, M):
    """(sd, p) of the ellipsoid inside the cylinder of radius RADIUS about z: the angle φ
    where the support point p(e_φ) lies on the radial line of e_φ, sd = RADIUS − e_φ·p."""
    def p_of(phi):
        d = np.array([math.cos(phi), math.sin(phi), 0.0])
        return c + M @ d / math.sqrt(d @ M @ d)

    def g(phi):
        p = p_of(phi)
        return math.cos(phi) * p[1] - math.sin(phi) * p[0]
    best = None
    phis = np.linspace(0, 2 * math.pi, 361)
    for a, b in zip(phis[:-1], phis[1:]):
        if g(a) * g(b) < 0:
            ph = brentq(g, a, b, xtol=1e-15, rtol=1e-15)
            p = p_of(ph)
            sd = RADIUS - (math.cos(ph) * p[0] + math.sin(ph) * p[1])
            if best is None or sd < best[0]:
                best = (sd, p)
    return best


def test_ellipsoid_inside_an_exact_cylinder_and_its_tessellation():
    """Inside the exact NURBS cylinder: the signed distance and the contact point are the
    support-function reference's to 1e-12 of the size.  The same cylinder as a mesh of n
    facets around: the error stays below the chord's sagitta R (1 − cos(π/n))."""
    drum = build_surface_wall([cylinder_patch(RADIUS, LENGTH)])
    rng = np.random.default_rng(4)
    meshes = {n: _tessellated_cylinder(n) for n in (32, 128)}
    for _ in range(6):
        R = _rotation(rng.normal(size=3))
        M = _support_matrix(R)
        phi = rng.uniform(0, 2 * math.pi)
        rho = RADIUS - math.sqrt(M[0, 0] * math.cos(phi) ** 2 + M[1, 1] * math.sin(phi) ** 2
                                 + 2 * M[0, 1] * math.sin(phi) * math.cos(phi)) + 1e-3
        c = np.array([rho * math.cos(phi), rho * math.sin(phi), rng.uniform(0.1, 0.3)])
        pos, R = _pose(c, R)
        f, i, ok = particle_surface_row(TABLE, 0, pos, R, drum)
        sd, p = _cylinder_reference(c, M)
        assert ok and i[I_ACTIVE] == 1
        assert f[F_SD] == pytest.approx(sd, abs=1e-12 * drum.size)
        np.testing.assert_allclose(f[F_PA:F_PA + 3], p, atol=1e-12 * drum.size)
        for n, mesh in meshes.items():
            rows, _ = particle_mesh_contacts(TABLE, 0, pos, R, mesh, active_only=False)
            err = abs(rows[:, F_SD].min() - sd)
            assert err <= RADIUS * (1 - math.cos(math.pi / n)) * (1 + 1e-9), (n, err)


def test_a_pocket_narrower_than_the_particle_is_refused():
    """The ellipsoid's flat side (radius of curvature b²/c = 2.7 cm across the drum) against
    a cylinder of radius 2.1 cm: the wall curves more tightly than the particle (two contact
    points), and the solve says so instead of returning one of them."""
    narrow = build_surface_wall([cylinder_patch(0.021, 0.2, base=(0, 0, -0.1),
                                                axis=(0, 0, 1))])
    R = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])   # a, b, c along z, x, y
    with pytest.raises(ContactNotUnique, match="narrow: .*not unique"):
        particle_surface_row(TABLE, 0, *_pose([0.0, 0.0065, 0.0], R), narrow, where="narrow")
    wide = build_surface_wall([cylinder_patch(0.03, 0.2, base=(0, 0, -0.1), axis=(0, 0, 1))])
    f, i, ok = particle_surface_row(TABLE, 0, *_pose([0.0, 0.0155, 0.0], R), wide)
    assert ok and f[F_SD] == pytest.approx(-5e-4, abs=1e-15)


def _fold(z_ridge: float) -> tuple[np.ndarray, np.ndarray]:
    """Two 0.2 x 0.1 m faces meeting along the y axis, their outer edges at height 0 and x =
    ±0.1, the fold at height z_ridge (> 0 a ridge: convex; < 0 a valley: concave)."""
    v = np.array([[-0.1, -0.1, 0], [-0.1, 0.1, 0], [0, -0.1, z_ridge], [0, 0.1, z_ridge],
                  [0.1, -0.1, 0], [0.1, 0.1, 0]], float)
    f = np.array([[0, 2, 3], [0, 3, 1], [2, 4, 5], [2, 5, 3]])
    return v, f


def test_convex_fold_gives_one_continuous_contact_and_a_concave_fold_one_per_face():
    """Over a ridge: one contact as the ellipsoid crosses it, a face's, then the edge's
    (against the support function), then the other face's, its depth continuous.  In a
    valley: one contact per face, each the flat wall's of that face's plane."""
    R = _rotation([0.4, 0.2, -0.3])
    M = _support_matrix(R)
    ridge = build_mesh_wall(*_fold(0.01))
    sds, feats = [], []
    for x in np.linspace(-0.02, 0.02, 41):                 # along the faces, 1 mm deep
        c = np.array([x, 0.0, 0.01 - 0.1 * abs(x) + math.sqrt(M[2, 2]) - 1e-3])
        rf, ri = particle_mesh_contacts(TABLE, 0, *_pose(c, R), ridge)
        assert len(rf) == 1
        sds.append(rf[0, F_SD])
        on_edge = abs(rf[0, F_PB]) < 1e-12
        feats.append(on_edge)
        if on_edge:
            ref = _edge_reference(c, M, np.array([0, -0.1, 0.01]), np.array([0, 0.1, 0.01]))
            assert rf[0, F_SD] == pytest.approx(ref, abs=1e-11 * max(AXES))
    assert any(feats) and not all(feats)
    assert np.max(np.abs(np.diff(sds))) < 2e-4              # no jump between the regions
    valley = build_mesh_wall(*_fold(-0.01))
    pos, R = _pose([0.0, 0.0, -0.01 + AXES[2] - 1e-3], np.eye(3))
    rf, ri = particle_mesh_contacts(TABLE, 0, pos, R, valley)
    assert len(rf) == 2
    for row in rf:
        nb = -row[F_N:F_N + 3]                              # the face's normal
        ref = detect_wall(ELLIPSOID, (pos, R), (np.array([0, -0.1, -0.01]),
                                                 *((np.array([0.1, 0, 0.01]), [0, 0.2, 0])
                                                   if nb[0] < 0 else
                                                   ([0, 0.2, 0], np.array([-0.1, 0, 0.01])))))
        assert row[F_SD] == pytest.approx(ref.signed_distance, abs=1e-16)


def test_a_moved_wall_gives_the_contacts_of_the_particle_moved_back():
    """A mesh and a surface wall at a pose (R, t): the contact of a particle equals that of
    the particle brought into the wall's frame, turned and shifted back."""
    Rw, tw = _rotation([0.2, -0.7, 0.4]), np.array([0.3, -0.1, 0.2])
    R = _rotation([0.4, 0.2, -0.3])
    drum = build_surface_wall([cylinder_patch(RADIUS, LENGTH)])
    floor = build_mesh_wall(*plane_mesh(4, half=0.1))
    M = _support_matrix(R)
    for wall, c in ((drum, [RADIUS - math.sqrt(M[0, 0]) + 5e-4, 0.0, 0.2]),
                    (floor, [0.01, 0.02, math.sqrt(M[2, 2]) - 5e-4])):
        pos, Rb = _pose(c, R)
        if wall is drum:
            f0 = particle_surface_row(TABLE, 0, pos, Rb, wall)[0][None]
            f1 = particle_surface_row(TABLE, 0, Rw @ pos + tw, Rw @ Rb, wall, Rw, tw)[0][None]
        else:
            f0 = particle_mesh_contacts(TABLE, 0, pos, Rb, wall)[0]
            f1 = particle_mesh_contacts(TABLE, 0, Rw @ pos + tw, Rw @ Rb, wall, Rw, tw)[0]
        assert len(f0) == len(f1) == 1 and f0[0, F_SD] < 0
        assert f1[0, F_SD] == pytest.approx(f0[0, F_SD], abs=1e-15)
        np.testing.assert_allclose(f1[0, F_N:F_N + 3], Rw @ f0[0, F_N:F_N + 3], atol=1e-12)
        np.testing.assert_allclose(f1[0, F_PA:F_PA + 3], Rw @ f0[0, F_PA:F_PA + 3] + tw,
                                   atol=1e-14)


def test_over_the_corner_of_a_cube_one_contact_passes_face_edge_vertex():
    """The ellipsoid carried diagonally over a corner of a 0.2 m cube (a closed convex mesh)
    at a constant height: one contact while it touches, from the top face through the edges'
    and the corner's regions (the vertex's against the support function), continuous."""
    import trimesh
    box = trimesh.creation.box(extents=(0.2, 0.2, 0.2))
    cube = build_mesh_wall(box.vertices, box.faces)
    corner = np.array([0.1, 0.1, 0.1])
    R = _rotation([0.4, 0.2, -0.3])
    M = _support_matrix(R)
    sds, seen = [], set()
    low = -M[:, 2] / math.sqrt(M[2, 2])               # the lowest point, from the centre
    for s in np.linspace(-0.01, 0.01, 41):             # lowest point over the corner at s = 0
        c = corner - low + np.array([s + 0.002, 0.8 * s, -1e-3])
        rf, _ = particle_mesh_contacts(TABLE, 0, *_pose(c, R), cube)
        assert len(rf) <= 1
        if len(rf) == 0:
            break
        sds.append(rf[0, F_SD])
        q = rf[0, F_PB:F_PB + 3]
        on = tuple(bool(abs(q[k] - 0.1) < 1e-12) for k in range(3))
        if sum(on) == 3 and 3 not in seen:
            assert rf[0, F_SD] == pytest.approx(_vertex_reference(c, M, corner),
                                                abs=1e-11 * max(AXES))
        seen.add(sum(on))
    assert seen == {1, 2, 3}                        # a face, an edge and the corner
    assert np.max(np.abs(np.diff(sds, 2))) < 3e-5     # its slope changes smoothly: no jump


INPUTS = Path(__file__).resolve().parents[1] / "inputs"


def _outcome(solve, table, pos, R, wall):
    try:
        return solve(table, 0, pos, R, wall, where="w")
    except ContactNotUnique as err:
        return str(err)


def test_the_compiled_surface_solve_is_the_python_one_in_the_drum_and_the_cone():
    """Random poses of an ellipsoid and of the paper's particle A (C in the narrower cone)
    near the wall, some crossing it, some apart: the compiled rows equal the Python
    reference's (the support oracle's Newton) to 1e-12 of the wall's size (points, depth)
    and 1e-12 (normal), the same patch and activity; a refusal is the same error."""
    drum = build_surface_wall(read_patches(INPUTS / "drum" / "drum.yaml")[0])  # r 0.1, z 0..0.1
    cone = build_surface_wall(read_patches(INPUTS / "hopper" / "cone.yaml")[0])
    rng = np.random.default_rng(7)
    paper = {k: table_of(shapes.paper_particle_shape(k)) for k in "AC"}
    seen = {"contact": 0, "apart": 0}
    for wall, name, radius_at, tables in (
            (drum, "drum", lambda z: 0.1, (TABLE, paper["A"])),
            (cone, "cone", lambda z: 0.02 + 0.05 * z / 0.08, (TABLE, paper["C"]))):
        for table in tables:
            rad = float(table.radius[0])
            for _ in range(6):
                R = _rotation(rng.normal(size=3))
                phi, z = rng.uniform(0, 2 * math.pi), rng.uniform(0.045, 0.06)
                rho = radius_at(z) - rad * rng.uniform(0.55, 1.05)
                c = np.array([rho * math.cos(phi), rho * math.sin(phi), z])
                pos = c - R @ table.centroid[0]
                got = _outcome(particle_surface_row, table, pos, R, wall)
                ref = _outcome(particle_surface_row_reference, table, pos, R, wall)
                if isinstance(ref, str):
                    assert got == ref, name
                    continue
                (f, i, ok), (fr, ir, okr) = got, ref
                assert ok == okr and i[I_ACTIVE] == ir[I_ACTIVE] and i[2] == ir[2], name
                tol = 1e-12 * wall.size
                assert f[F_SD] == pytest.approx(fr[F_SD], abs=tol)
                np.testing.assert_allclose(f[F_PA:F_PA + 3], fr[F_PA:F_PA + 3], rtol=0, atol=tol)
                np.testing.assert_allclose(f[F_PB:F_PB + 3], fr[F_PB:F_PB + 3], rtol=0, atol=tol)
                np.testing.assert_allclose(f[F_N:F_N + 3], fr[F_N:F_N + 3], rtol=0, atol=1e-12)
                seen["contact" if i[I_ACTIVE] else "apart"] += 1
    assert seen["contact"] >= 5 and seen["apart"] >= 3, seen


def _bumps() -> tuple[np.ndarray, np.ndarray]:
    """A 0.12 m square of 6 x 6 squares whose heights undulate by ±1 cm: convex and concave
    folds, bent edges and vertices."""
    v, f = plane_mesh(6, half=0.06)
    v[:, 2] = 0.01 * np.sin(40 * v[:, 0]) * np.cos(30 * v[:, 1])
    return v, f


def _compiled_equals_reference(table, mesh, poses) -> tuple[list, np.ndarray]:
    """The rows of the compiled mesh solve of the poses [(pos, R)] of the table's shape 0, in
    one call, equal the Python reference's (count, order, triangle, iterations) to 1e-12 of
    the size (points, depth) and 1e-12 (normal); returns (the reference's rows_f per pose,
    each compiled row's pose)."""
    from nurbsdem.contact.lcp import I_IT, I_PB
    from nurbsdem.contact.mesh_particle_compiled import mesh_rows
    pos, rot = np.array([p for p, _ in poses]), np.array([r for _, r in poses])
    rf, ri, owner, rank = mesh_rows(table, mesh, np.arange(len(poses)),
                                    np.zeros(len(poses), np.int64), pos, rot, np.eye(3),
                                    np.zeros(3), 8)
    tol = 1e-12 * 0.1
    refs = []
    for k, (p, R) in enumerate(poses):
        ref_f, ref_i = particle_mesh_contacts(table, 0, p, R, mesh)
        refs.append(ref_f)
        got = owner == k
        assert np.array_equal(rank[got], np.arange(len(ref_f)))
        f, i = rf[got], ri[got]
        assert np.array_equal(i[:, [I_ACTIVE, I_PB, I_IT]], ref_i[:, [I_ACTIVE, I_PB, I_IT]])
        for a, b in ((F_SD, 1), (F_PA, 3), (F_PB, 3)):
            np.testing.assert_allclose(f[:, a:a + b], ref_f[:, a:a + b], rtol=0, atol=tol)
        np.testing.assert_allclose(f[:, F_N:F_N + 3], ref_f[:, F_N:F_N + 3], rtol=0, atol=1e-12)
    return refs, owner


def test_the_compiled_mesh_solve_is_the_python_one_over_a_cube_and_bumps():
    """Random poses of the ellipsoid over a 6 cm cube (faces, edges, corners; half of them
    1 mm into a corner along a normal of its cone) and over a bumped plane (convex and
    concave folds; one pose out of reach of every triangle), and of the paper's particle A
    over the bumps: the compiled kernel's rows are the Python reference's
    (:func:`_compiled_equals_reference`)."""
    import trimesh
    box = trimesh.creation.box(extents=(0.06, 0.06, 0.06))
    cube, bumps = build_mesh_wall(box.vertices, box.faces), build_mesh_wall(*_bumps())
    rng = np.random.default_rng(3)
    poses = []
    for k in range(24):
        R = _rotation(rng.normal(size=3))
        if k % 2:                            # the support point along −n 1 mm into a corner
            sign = np.sign(rng.normal(size=3))
            n = sign * rng.uniform(0.2, 1.0, size=3)
            n /= np.linalg.norm(n)
            M = _support_matrix(R)
            c = 0.03 * sign - 1e-3 * n + M @ n / math.sqrt(n @ M @ n)
        else:
            d = rng.normal(size=3)
            c = d / np.linalg.norm(d) * rng.uniform(0.035, 0.06)
        poses.append(_pose(c, R))
    refs, _ = _compiled_equals_reference(TABLE, cube, poses)
    on_cube = {int(np.sum(np.abs(np.abs(q) - 0.03) < 1e-12))
               for rows in refs for q in rows[:, F_PB:F_PB + 3]}
    assert on_cube == {1, 2, 3}                                 # faces, edges and corners
    paper = table_of(shapes.paper_particle_shape("A"))
    for table, n in ((TABLE, 24), (paper, 8)):
        poses = []
        for k in range(n):
            R = _rotation(rng.normal(size=3))
            c = np.array([*rng.uniform(-0.04, 0.04, size=2), rng.uniform(0.0, 0.025)
                          if k else 0.06])          # the first: no triangle within reach
            poses.append((c - R @ table.centroid[0], R))
        refs, owner = _compiled_equals_reference(table, bumps, poses)
        assert len(refs[0]) == 0 and sum(len(r) > 0 for r in refs) >= n // 2
        assert table is paper or np.bincount(owner).max() >= 2    # a concave fold: two rows


def _orifice(side: float = 0.06, D: float = 0.024, segments: int = 64):
    """A square floor of side ``side`` (m) at z = 0 with a circular orifice of diameter D
    (a regular polygon), as the silo benchmark writes it."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    import tempfile
    from bench_beverloo import write_floor
    from nurbsdem.io.meshfile import read_wall_mesh
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "floor.stl"
        write_floor(path, side, D, segments)
        mesh = read_wall_mesh(path)
        return build_mesh_wall(mesh.vertices, mesh.faces)


def _slice_reach(c, M, z: float = 0.0) -> float:
    """How far (m) from the z axis the ellipsoid (centre c, support matrix M = R A² Rᵀ)
    reaches in the plane z (its section there, an ellipse: the largest radius of its
    boundary, densely sampled); −inf when it does not reach the plane."""
    Q = np.linalg.inv(M)                 # the ellipsoid: (x − c)ᵀ Q (x − c) ≤ 1
    dz = z - c[2]
    A = Q[:2, :2]
    b = Q[:2, 2] * dz
    rhs = 1.0 - Q[2, 2] * dz * dz + b @ np.linalg.solve(A, b)
    if rhs <= 0.0:
        return -math.inf
    centre = c[:2] - np.linalg.solve(A, b)
    w, V = np.linalg.eigh(A)
    a = np.linspace(0.0, 2.0 * math.pi, 20001)
    pts = centre + (V @ (np.sqrt(rhs / w)[:, None] * np.array([np.cos(a), np.sin(a)]))).T
    return float(np.hypot(pts[:, 0], pts[:, 1]).max())


def test_a_tilted_particle_over_the_rim_of_an_orifice_touches_from_its_first_overlap():
    """An elongated ellipsoid tilted 15° over the rim of a 24 mm orifice, moving outwards
    (its lower end leading, and its upper end), 0.6 mm off a polygon vertex: it touches the
    rim exactly when its section in the floor's plane reaches past it, each of the rim's
    edges it reaches with the depth of the analytic support function against that edge (the
    least over the edge's normal arc, on either side of the floor: a lower end that dipped
    through the orifice touches the rim with its upper surface), or against the edge's end
    where that is the edge's deepest point, the deepest growing
    steadily with the overlap; the compiled kernel gives the reference's rows."""
    mesh = _orifice()
    axes = (0.004, 0.0016, 0.0016)
    table = table_of(shapes.ellipsoid(*axes))
    for tilt, xs in ((15, np.linspace(0.0075, 0.0095, 11)),
                     (-15, np.linspace(0.0095, 0.0115, 11))):
        R = _rotation([0.0, math.radians(tilt), 0.0])
        M = R @ np.diag(np.square(axes)) @ R.T
        depth, poses = [], []
        for x in xs:
            c = np.array([x, 0.0006, 0.0008])
            pos = c - R @ table.centroid[0]
            poses.append((pos, R))
            rf, _ = particle_mesh_contacts(table, 0, pos, R, mesh)
            reach = _slice_reach(c, M) - 0.012 * math.cos(math.pi / 64)
            if reach < -1e-5:                                   # short of the rim
                assert len(rf) == 0
                depth.append(0.0)
                continue
            if reach < 1e-5:
                continue
            assert len(rf) >= 1
            for row in rf:      # each on a rim edge or at its deepest end (several: a polygon)
                q = row[F_PB:F_PB + 3]
                corner = np.linalg.norm(mesh.vertices - q, axis=1).min() < 1e-12
                if corner:
                    assert row[F_SD] == pytest.approx(_vertex_reference(c, M, q),
                                                      abs=1e-11 * axes[0])
                    continue
                k = math.floor(math.atan2(q[1], q[0]) / (2.0 * math.pi / 64))
                p0, p1 = (mesh.vertices[np.argmin(np.linalg.norm(
                    mesh.vertices - 0.012 * np.array([math.cos(a), math.sin(a), 0.0]), axis=1))]
                    for a in (2.0 * math.pi * k / 64, 2.0 * math.pi * (k + 1) / 64))
                assert abs(np.cross(p1 - p0, q - p0)[2]) < 1e-17 and abs(q[2]) < 1e-15
                ref = _edge_reference(c, M, p0, p1)
                assert row[F_SD] == pytest.approx(ref, abs=1e-11 * axes[0])
            depth.append(-rf[:, F_SD].min())
        step = np.diff(depth)
        assert np.all(step >= 0.0) and np.all(step <= 1.05 * (xs[1] - xs[0]))
        assert depth[-1] > 0.15 * axes[0]                       # deep: 0.6 mm and more
        _compiled_equals_reference(table, mesh, poses)


def test_a_long_particle_through_an_orifice_has_no_contact_under_the_rim():
    """A long ellipsoid (6.25 : 1) passing through the orifice at 30°, its lower end under
    the floor beyond the rim while its section in the floor's plane lies inside the
    orifice: it touches nothing (the face below which its lowest point lies is not reached:
    the particle passes the plane inside the orifice); the compiled kernel agrees."""
    mesh = _orifice()
    axes = (0.005, 0.0008, 0.0008)
    table = table_of(shapes.ellipsoid(*axes))
    R = _rotation([0.0, math.radians(30), 0.0])
    M = R @ np.diag(np.square(axes)) @ R.T
    poses = []
    for x in (0.0085, 0.009, 0.0095):
        c = np.array([x, 0.0006, 0.0005])
        low = c - M @ np.array([0.0, 0.0, 1.0]) / math.sqrt(M[2, 2])
        assert np.hypot(*low[:2]) > 0.0125 and low[2] < -0.002      # under the floor
        assert _slice_reach(c, M) < 0.0119                          # inside the orifice
        pos = c - R @ table.centroid[0]
        poses.append((pos, R))
        assert len(particle_mesh_contacts(table, 0, pos, R, mesh)[0]) == 0
    _compiled_equals_reference(table, mesh, poses)


def test_a_particle_at_a_corner_of_an_orifice_touches_wherever_the_corner_is_inside_it():
    """An elongated ellipsoid in random orientations beside a polygon vertex V of the
    orifice's rim (the floor turns by more than half a turn there: the vertex's normal cone
    is the plane's normal alone), its centre in the hole or over the rim, below or above the
    floor: wherever V lies inside the particle there is a contact, and every contact at V
    has the depth of the analytic support function at V (1e-11 of the particle's size);
    the compiled kernel gives the reference's rows.  Without the rule of the boundary edges'
    corners, or with the vertex Newton stopping where h_A(d) − d · V is not convex, some of
    the poses with V inside have no contact."""
    mesh = _orifice()
    V = mesh.vertices[np.argmin(np.linalg.norm(mesh.vertices - [0.012, 0.0, 0.0], axis=1))]
    assert np.allclose(V, [0.012, 0.0, 0.0])
    axes = (0.004, 0.0016, 0.0016)
    table = table_of(shapes.ellipsoid(*axes))
    rng = np.random.default_rng(1)
    inside = at_v = 0
    poses = []
    for _ in range(400):
        R = _rotation(rng.normal(size=3))
        M = R @ np.diag(np.square(axes)) @ R.T
        ang, rad = rng.uniform(-0.15, 0.15), rng.uniform(0.008, 0.0125)
        c = np.array([rad * math.cos(ang), rad * math.sin(ang), rng.uniform(-0.002, 0.002)])
        pos = c - R @ table.centroid[0]
        rf, _ = particle_mesh_contacts(table, 0, pos, R, mesh)
        if (V - c) @ np.linalg.solve(M, V - c) < 0.98:
            inside += 1
            assert len(rf) >= 1
            poses.append((pos, R))
        for row in rf:
            if np.linalg.norm(row[F_PB:F_PB + 3] - V) < 1e-12:
                at_v += 1
                assert row[F_SD] == pytest.approx(_vertex_reference(c, M, V),
                                                  abs=1e-11 * axes[0])
    assert inside > 100 and at_v > 50
    _compiled_equals_reference(table, mesh, poses[:60])

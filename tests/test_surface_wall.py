"""NURBS surface walls (nurbsdem.contact.surface_wall): a sphere inside an exact cylinder and
cone against the analytic distance, the rim, the back side, a moved wall, and the same
cylinder as a triangle mesh, whose error follows the chord error O(h^2)."""
import math

import numpy as np
import pytest

from nurbsdem.contact.lcp import F_N, F_PB, F_SD, I_ACTIVE
from nurbsdem.contact.mesh_wall import build_mesh_wall, sphere_contacts
from nurbsdem.contact.surface_wall import build_surface_wall, sphere_contact
from nurbsdem.geometry.surfaces import cone_patch, cylinder_patch

RADIUS, LENGTH = 0.25, 0.4


@pytest.fixture(scope="module")
def drum():
    return build_surface_wall([cylinder_patch(RADIUS, LENGTH)])


def test_sphere_inside_a_cylinder_has_the_analytic_distance(drum):
    rng = np.random.default_rng(5)
    r = 0.03
    for _ in range(300):
        rho = rng.uniform(0.05, RADIUS - 1e-4)
        phi = rng.uniform(0, 2 * math.pi)
        z = rng.uniform(0.05, LENGTH - 0.05)
        x = np.array([rho * math.cos(phi), rho * math.sin(phi), z])
        f, i, ok = sphere_contact(drum, x, r)
        assert ok
        radial = np.array([math.cos(phi), math.sin(phi), 0.0])
        assert f[F_SD] == pytest.approx(RADIUS - rho - r, abs=1e-12 * drum.size)
        assert np.allclose(f[F_N:F_N + 3], radial, atol=1e-12)
        assert np.allclose(f[F_PB:F_PB + 3], [RADIUS * radial[0], RADIUS * radial[1], z],
                           atol=1e-12 * drum.size)
        assert i[I_ACTIVE] == (RADIUS - rho < r)


def test_beyond_the_rim_the_sphere_touches_the_rim(drum):
    x = np.array([0.2, 0.0, LENGTH + 0.01])
    f, i, ok = sphere_contact(drum, x, 0.06)
    assert ok
    d = math.hypot(RADIUS - 0.2, 0.01)
    assert f[F_SD] == pytest.approx(d - 0.06, abs=1e-12)
    assert np.allclose(f[F_PB:F_PB + 3], [RADIUS, 0, LENGTH], atol=1e-12)
    assert i[I_ACTIVE] == 1


def test_a_sphere_behind_the_wall_makes_no_contact(drum):
    f, i, ok = sphere_contact(drum, np.array([RADIUS + 0.01, 0.0, 0.2]), 0.03)
    assert ok and f[F_SD] < 0 and i[I_ACTIVE] == 0


def test_sphere_inside_a_cone_has_the_analytic_distance():
    r0, r1, h = 0.3, 0.1, 0.4
    wall = build_surface_wall([cone_patch(r0, r1, h)])
    # the meridian line from (r0, 0) to (r1, h); its inward unit normal
    t = np.array([r1 - r0, h]) / math.hypot(r1 - r0, h)
    rng = np.random.default_rng(6)
    for _ in range(200):
        z = rng.uniform(0.1, 0.3)
        rho = rng.uniform(0.0, 0.9) * (r0 + (r1 - r0) * z / h)
        phi = rng.uniform(0, 2 * math.pi)
        x = np.array([rho * math.cos(phi), rho * math.sin(phi), z])
        rel = np.array([rho - r0, z])
        dist = abs(rel[0] * t[1] - rel[1] * t[0])
        f, _, ok = sphere_contact(wall, x, 0.05)
        assert ok
        assert f[F_SD] == pytest.approx(dist - 0.05, abs=1e-12 * wall.size)


def test_a_rotated_moved_drum_gives_the_same_contact(drum):
    rng = np.random.default_rng(7)
    R, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    R *= np.sign(np.linalg.det(R))
    t = rng.normal(size=3)
    x = np.array([0.1, 0.18, 0.2])
    f0, _, _ = sphere_contact(drum, x, 0.05)
    f1, _, ok = sphere_contact(drum, R @ x + t, 0.05, R, t)
    assert ok
    assert f1[F_SD] == pytest.approx(f0[F_SD], abs=1e-14)
    assert np.allclose(f1[F_N:F_N + 3], R @ f0[F_N:F_N + 3], atol=1e-13)


def _tessellated_cylinder(n, m=4):
    """n facets around, m rows along the axis (vertices on the exact cylinder)."""
    phi = 2 * math.pi * np.arange(n) / n
    z = np.linspace(0, LENGTH, m + 1)
    verts = np.array([[RADIUS * math.cos(p), RADIUS * math.sin(p), zz] for zz in z for p in phi])
    faces = []
    for j in range(m):
        for k in range(n):
            a, b = j * n + k, j * n + (k + 1) % n
            faces += [(a, b, b + n), (a, b + n, a + n)]
    return build_mesh_wall(verts, np.array(faces))


def test_the_same_cylinder_as_a_mesh_errs_by_the_chord_error():
    """The mesh's distance error stays within the sagitta R (1 - cos(pi/n)) and falls as
    h^2: about 4x per halving of the facets."""
    wall = build_surface_wall([cylinder_patch(RADIUS, LENGTH)])
    rng = np.random.default_rng(8)
    xs = []
    for _ in range(100):
        phi = rng.uniform(0, 2 * math.pi)
        xs.append(np.array([0.22 * math.cos(phi), 0.22 * math.sin(phi), rng.uniform(0.1, 0.3)]))
    errors = []
    for n in (16, 32, 64, 128):
        mesh = _tessellated_cylinder(n)
        worst = 0.0
        for x in xs:
            exact = sphere_contact(wall, x, 0.05)[0][F_SD]
            rows, _ = sphere_contacts(mesh, x, 0.05)
            assert len(rows) >= 1
            worst = max(worst, abs(rows[:, F_SD].min() - exact))
        assert worst <= RADIUS * (1 - math.cos(math.pi / n)) * (1 + 1e-9)
        errors.append(worst)
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((ratios > 3.0) & (ratios < 5.0)), ratios

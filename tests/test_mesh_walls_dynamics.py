"""Exact spheres against mesh and NURBS-surface walls in the step
(:mod:`nurbsdem.contact.curved_walls`), each against an analytic or independent result."""
from __future__ import annotations

import numpy as np
import pytest

from nurbsdem.contact.curved_walls import CurvedWall, CurvedWallContacts
from nurbsdem.contact.kinds import MESH_WALL, SURFACE_WALL
from nurbsdem.contact.mesh_wall import build_mesh_wall
from nurbsdem.contact.surface_wall import build_surface_wall
from nurbsdem.dynamics import (ContactLaw, DemSystem, InterfaceTable, SpherePlaneProvider,
                               sphere_inertia)
from nurbsdem.geometry.surfaces import cylinder_patch
from nurbsdem.io.meshfile import read_wall_mesh

M, R, K, G = 0.05, 0.01, 1e5, 9.81


def _system(law, z0, v0=None, dt=1e-4, xy=(0.0, 0.0)):
    s = DemSystem(dt=dt, gravity=(0, 0, -G), interfaces=InterfaceTable(default=law))
    s.add_particle(M, sphere_inertia(M, R), [xy[0], xy[1], z0], v=v0, radius=R)
    s.add_wall()
    return s


def _grid_plane(n: int, half: float) -> tuple[np.ndarray, np.ndarray]:
    """An n × n tessellated square of side 2·half in z = 0 (2 n² triangles, front +z)."""
    s = np.linspace(-half, half, n + 1)
    xx, yy = np.meshgrid(s, s, indexing="ij")
    verts = np.column_stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)])
    faces = []
    for i in range(n):
        for j in range(n):
            a, b, c, d = i * (n + 1) + j, (i + 1) * (n + 1) + j, (i + 1) * (n + 1) + j + 1, \
                i * (n + 1) + j + 1
            faces += [[a, b, c], [a, c, d]]
    return verts, np.array(faces)


def test_sphere_on_stl_floor_equals_flat_floor(tmp_path):
    """A sphere settling on a two-triangle STL floor: the same trajectory, rest overlap and
    force as on the analytic flat floor, to round-off; the rest overlap is m g / k."""
    import trimesh
    path = tmp_path / "floor.stl"
    trimesh.Trimesh([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]],
                    [[0, 1, 2], [0, 2, 3]]).export(path)
    mesh = read_wall_mesh(path)
    law = ContactLaw(en=K, cn=50.0, et=K, ct=0.0, mu=0.5)
    z0 = R + 1e-3
    flat = _system(law, z0)
    flat.set_contact_provider(SpherePlaneProvider([R], [([0, 0, 0], [0, 0, 1])]))
    curved = _system(law, z0)
    wall = CurvedWall(MESH_WALL, build_mesh_wall(mesh.vertices, mesh.faces))
    curved.set_contact_provider(CurvedWallContacts(None, [R], [True], [wall], first_wall=0))
    for _ in range(1500):
        flat.step()
        curved.step()
    assert abs(curved.bodies.x[0, 2] - flat.bodies.x[0, 2]) <= 1e-14
    np.testing.assert_allclose(curved.wall_contact_force, flat.wall_contact_force,
                               rtol=1e-12, atol=1e-15)
    assert R - curved.bodies.x[0, 2] == pytest.approx(M * G / K, rel=1e-6)
    assert curved.wall_contact_force[0, 2] == pytest.approx(-M * G, rel=1e-6)


def test_frictionless_slide_across_tessellated_plane_has_no_kicks():
    """A sphere sliding at 0.5 m/s across a 40 × 40 tessellated plane (3 200 triangles,
    oblique to the edges and diagonals) at its rest overlap: height and energy stay constant
    to round-off (one contact at the internal edges, the plane's distance and normal)."""
    verts, faces = _grid_plane(40, 0.2)
    law = ContactLaw(en=K, cn=0.0, et=K, ct=0.0, mu=0.0)
    z_rest = R - M * G / K
    s = _system(law, z_rest, v0=[0.5, 0.17, 0.0], dt=1e-2, xy=(-0.15, -0.05))
    wall = CurvedWall(MESH_WALL, build_mesh_wall(verts, faces))
    s.set_contact_provider(CurvedWallContacts(None, [R], [True], [wall], first_wall=0))
    s.initialize()
    e0 = s.energy()
    zs = []
    for _ in range(50):                    # 0.5 s: 0.25 m, about 25 internal edges crossed
        s.step()
        zs.append(s.bodies.x[0, 2])
    assert s.bodies.x[0, 0] > 0.09
    assert np.max(np.abs(np.array(zs) - z_rest)) <= 1e-13
    e1 = s.energy()
    assert abs(e1.mechanical - e0.mechanical) <= 1e-12 * e0.kinetic
    np.testing.assert_allclose(s.bodies.v[0, :2], [0.5, 0.17], rtol=0, atol=1e-12)


def test_sphere_resting_in_nurbs_cylinder():
    """A sphere at rest on the inside of an exact NURBS cylinder (horizontal axis x, radius
    0.1 m): the wall force balances the weight and the overlap is m g / k."""
    Rc = 0.1
    surf = build_surface_wall([cylinder_patch(Rc, 0.2, base=(-0.1, 0, 0), axis=(1, 0, 0))])
    law = ContactLaw(en=K, cn=50.0, et=K, ct=0.0, mu=0.5)
    z_rest = -(Rc - R) - M * G / K
    s = _system(law, z_rest + 2e-4)
    wall = CurvedWall(SURFACE_WALL, surf)
    provider = CurvedWallContacts(None, [R], [True], [wall], first_wall=0)
    s.set_contact_provider(provider)
    for _ in range(600):
        s.step()
    cs = s.last_contacts
    assert len(cs.depth) == 1
    assert cs.depth[0] == pytest.approx(M * G / K, rel=1e-6)
    np.testing.assert_allclose(s.wall_contact_force[0], [0, 0, -M * G], rtol=0, atol=1e-6 * M * G)
    assert s.bodies.x[0, 2] == pytest.approx(z_rest, abs=1e-9)


def test_friction_history_carries_across_triangles():
    """A sphere thrown spinning with friction across the tessellated plane follows the flat
    floor's trajectory to round-off: its tangential spring is kept from one triangle to the
    next (the contact is keyed by sphere and wall, not by triangle)."""
    verts, faces = _grid_plane(40, 0.2)
    law = ContactLaw(en=K, cn=20.0, et=K, ct=0.0, mu=0.3)
    z0 = R - M * G / K
    runs = []
    for provider in (SpherePlaneProvider([R], [([0, 0, 0], [0, 0, 1])]),
                     CurvedWallContacts(None, [R], [True],
                                        [CurvedWall(MESH_WALL, build_mesh_wall(verts, faces))],
                                        first_wall=0)):
        s = DemSystem(dt=1e-3, gravity=(0, 0, -G), interfaces=InterfaceTable(default=law))
        s.add_particle(M, sphere_inertia(M, R), [-0.15, -0.05, z0], v=[0.6, 0.2, 0.0],
                       omega=[0.0, 0.0, 30.0], radius=R)
        s.add_wall()
        s.set_contact_provider(provider)
        for _ in range(150):
            s.step()
        runs.append((s.bodies.x.copy(), s.bodies.v.copy(), s.hist_springs.copy()))
    assert np.max(np.abs(runs[1][0] - runs[0][0])) <= 1e-12
    np.testing.assert_allclose(runs[1][1], runs[0][1], rtol=0, atol=1e-10)
    assert np.max(np.abs(runs[0][2])) > 0.0            # a spring was carried: the test bites


@pytest.mark.parametrize("mu", [0.5, 0.0])
def test_sphere_in_a_turning_drum(mu):
    """A sphere on the floor of an exact NURBS drum (axis x, radius 0.1 m) turning at
    Ω = 0.5 rad/s: with friction its contact point moves with the drum (v_p = Ω × p, no
    slip: the sphere rolls on the drum, swinging about the bottom as a rolling pendulum);
    frictionless, the drum slides under it and it neither spins nor moves.  The drum's work on the sphere is booked (energy balance).  (A sphere carried up
    by the drum frame, at rest in it with v = Ω × r, needs rolling resistance or neighbours:
    the drum deck of inputs/drum.)"""
    from nurbsdem.contact.curved_walls import WallPose
    Rc, omega = 0.1, 0.5
    surf = build_surface_wall([cylinder_patch(Rc, 0.2, base=(-0.1, 0, 0), axis=(1, 0, 0))])
    law = ContactLaw(en=K, cn=20.0, et=K, ct=10.0, mu=mu)
    z_rest = -(Rc - R) - M * G / K
    s = _system(law, z_rest, dt=1e-3)
    pose = WallPose(omega=np.array([omega, 0, 0]), center=np.zeros(3))
    wall = CurvedWall(SURFACE_WALL, surf, pose)
    s.set_contact_provider(CurvedWallContacts(None, [R], [True], [wall], first_wall=0))
    s.wall_spin = np.array([[omega, 0, 0, 0, 0, 0]])
    for _ in range(1000):
        s.step()
    spin = s.bodies.omega()[0]
    x = s.bodies.x[0]
    p = s.last_contacts.point_a[0]
    v_point = s.bodies.v[0] + np.cross(spin, p - x)
    v_drum = np.cross([omega, 0, 0], p)
    if mu > 0:
        # to the overlap's order δ/r = m g/(k r) = 5e-4: which point of the overlap the
        # lever arms reach
        np.testing.assert_allclose(v_point, v_drum, rtol=0, atol=1e-3 * omega * Rc)
        assert spin[0] > 0.5 * omega * Rc / R          # it spins with the drum
    else:
        assert np.max(np.abs(spin)) < 1e-12 and np.max(np.abs(s.bodies.v[0])) < 1e-9
    e = s.energy()
    assert abs(e.mechanical - s.ledger.initial_mechanical - e.external_work
               + e.dissipated) <= 1e-3 * max(e.kinetic, M * G * R)

"""Periodic cells in the engine (nurbsdem.contact.periodic_scene, nurbsdem.dynamics.images):
a collision through a periodic face equals the same collision in the middle of the cell,
a periodic pack keeps its momentum along the periodic axes, and the energy balance stays
closed when particles wrap along gravity."""
from __future__ import annotations

import numpy as np
import pytest

from nurbsdem.contact.periodic import make_cell
from nurbsdem.contact.scene import SceneContacts
from nurbsdem.dynamics import ContactLaw, DemSystem, InterfaceTable, sphere_inertia
from nurbsdem.shapes import ellipsoid, sphere

ELASTIC = ContactLaw(en=1e5, cn=0.0, et=0.0, ct=0.0, mu=0.0)
R, M, L = 0.02, 0.1, 0.2


def two_bodies(x1, x2, cell, shape, v=0.5):
    s = DemSystem(dt=1e-4, gravity=(0, 0, 0), interfaces=InterfaceTable(default=ELASTIC))
    s.add_particle(M, sphere_inertia(M, R), [x1, 0.1, 0.1], v=[v, 0, 0], radius=R)
    s.add_particle(M, sphere_inertia(M, R), [x2, 0.1, 0.1], v=[-v, 0, 0], radius=R)
    s.set_contact_provider(SceneContacts([shape], np.zeros(2, np.int64), cell=cell))
    return s


def collide(x1, x2, cell, shape):
    s = two_bodies(x1, x2, cell, shape)
    touching = 0
    for _ in range(300):
        s.step()
        touching += s.contacts.a.shape[0] > 0
    return s, touching


@pytest.mark.parametrize("kind", ["sphere", "nurbs"])
def test_a_collision_through_the_face_equals_the_same_collision_in_the_middle(kind):
    """Exact spheres (closed form) and NURBS ellipsoids (the LCP, to its tolerance)."""
    shape, tol = (sphere(R), 1e-12) if kind == "sphere" else (ellipsoid(R, R, 0.9 * R), 1e-9)
    cell = make_cell((0, 0, 0), (L, 0.2, 0.2), (1, 0, 0))
    mid, t_mid = collide(0.07, 0.13, cell, shape)          # they meet at x = 0.1
    face, t_face = collide(0.17, 0.03, cell, shape)        # the same, 0.1 on: they meet at x = 0
    assert t_mid > 10 and t_face == t_mid
    # elastic head-on, equal masses: the velocities exchanged (to the step's discrete error)
    np.testing.assert_allclose(mid.bodies.v[:, 0], [-0.5, 0.5], rtol=3e-3)
    np.testing.assert_allclose(face.bodies.v, mid.bodies.v, rtol=0, atol=tol)
    dx = (face.bodies.x - mid.bodies.x - [0.1, 0, 0]) % L
    np.testing.assert_allclose(np.minimum(dx, L - dx), 0.0, atol=tol)
    assert np.all((face.bodies.x[:, 0] >= 0) & (face.bodies.x[:, 0] < L + 0.01))
    # the same energy books (the balance error is the step's O(h²) spring error, alike)
    assert abs(face.energy().balance_error - mid.energy().balance_error) < 1e-12


DAMPED = ContactLaw(en=1e5, cn=40.0, et=0.0, ct=0.0, mu=0.0)


def test_implicit_dashpots_through_the_face_equal_those_in_the_middle():
    """Two spheres press on a third from both sides with ``Damping Implicit`` (the dashpots
    solved over the network, nurbsdem.dynamics.implicit): in the middle of the cell, and with
    the middle one on the periodic face, so that it meets one partner directly and the other
    through the face.  The solve couples the two contacts through that sphere, which the
    image contact must reach as the same body: the bounces equal each other to round-off."""
    runs = []
    for shift in (0.0, -0.1):
        s = DemSystem(dt=1e-4, gravity=(0, 0, 0), interfaces=InterfaceTable(default=DAMPED),
                      implicit_damping=True)
        for x, v in ((0.0605, 0.5), (0.1, 0.0), (0.1395, -0.5)):     # touching already
            s.add_particle(M, sphere_inertia(M, R), [(x + shift) % L, 0.1, 0.1], v=[v, 0, 0],
                           radius=R)
        s.set_contact_provider(SceneContacts([sphere(R)], np.zeros(3, np.int64),
                                             cell=make_cell((0, 0, 0), (L, 0.2, 0.2),
                                                            (1, 0, 0))))
        for _ in range(300):
            s.step()
        runs.append(s)
    mid, face = runs
    assert mid.dashpot_solves[0] > 10 and face.dashpot_solves[0] == mid.dashpot_solves[0]
    assert mid.bodies.v[0, 0] < 0.0 < mid.bodies.v[2, 0]             # pushed apart
    np.testing.assert_allclose(face.bodies.v, mid.bodies.v, rtol=0, atol=1e-12)
    assert abs(face.energy().dissipated - mid.energy().dissipated) < 1e-12


def periodic_pack(rng):
    """32 spheres touching in a 4 x 4 x 2 lattice that fills a cell periodic in x and y, on a
    frictionless floor under a frictionless lid, with random velocities."""
    import nurbsdem
    r = 0.005
    sim = nurbsdem.Simulation(gravity=(0, 0, -9.81))
    sim.set_periodic(x=(0, 0.04), y=(0, 0.04))
    sim.add_material(1, 2700)
    sim.add_interface(1e5, 1e4, 0.5, 0.0, 0.5, between="particle-particle")
    sim.add_interface(1e5, 0.0, 0.5, 0.0, 0.0, between="particle-wall")
    for i, j, k in np.ndindex(4, 4, 2):
        sim.add_particle(sphere(r), 1, (r + 2 * r * i, r + 2 * r * j, r + 2 * r * k),
                         velocity=rng.uniform(-0.3, 0.3, 3) + (0.1, -0.05, 0))
    sim.add_wall("floor", (0.02, 0.02, 0), (0, 0, 1), (0.07, 0.07))
    sim.add_wall("lid", (0.02, 0.02, 0.021), (0, 0, -1), (0.07, 0.07))
    return sim


def test_a_periodic_pack_keeps_its_momentum_along_the_periodic_axes():
    sim = periodic_pack(np.random.default_rng(5))
    p0 = sim.velocities.sum(axis=0)
    across = 0
    for _ in range(3):
        sim.run_dynamic(0.004, 1e-3)
        pairs = sim.contacts()["pairs"]
        pairs = pairs[pairs[:, 1] < 32]
        x = sim.positions
        across += int(np.any(np.abs(x[pairs[:, 0], :2] - x[pairs[:, 1], :2]) > 0.02))
    sim.move_wall("lid", (0, 0, -0.001), 0.003, 1e-3)
    x, v = sim.positions, sim.velocities
    assert across >= 2                         # contacts through the faces did act
    assert np.all((x[:, :2] > -0.002) & (x[:, :2] < 0.042))      # wrapped into the cell
    np.testing.assert_allclose(v.sum(axis=0)[:2], p0[:2], rtol=0, atol=1e-13)
    assert abs(v.sum(axis=0)[2] - p0[2]) > 1e-3       # the floor and the lid act along z


def test_the_energy_balance_stays_closed_when_particles_wrap_along_gravity():
    """Two spheres collide obliquely through the face of a cell periodic along gravity (z),
    then fall, wrapping several times: each wrap lifts a sphere by L (its potential by
    m g L = 0.098 J), booked so that the balance error stays the collision's step error, to
    round-off."""
    cell = make_cell((0, 0, 0), (0.2, 0.2, 0.1), (0, 0, 1))
    s = DemSystem(dt=1e-3, gravity=(0, 0, -9.81), interfaces=InterfaceTable(default=ELASTIC))
    r = 0.008
    s.add_particle(M, sphere_inertia(M, r), [0.1, 0.1, 0.09], radius=r)
    s.add_particle(M, sphere_inertia(M, r), [0.108, 0.1, 0.01], v=[0, 0, -1.0], radius=r)
    s.set_contact_provider(SceneContacts([sphere(r)], np.zeros(2, np.int64), cell=cell))
    touching, z, error = [], [], []
    for _ in range(250):
        s.step()
        touching.append(s.contacts.a.shape[0] > 0)
        z.append(s.bodies.x[:, 2].copy())
        error.append(s.energy().balance_error)
    after = int(np.flatnonzero(touching)[-1]) + 1
    z = np.array(z)
    assert 0 < after < 50 and np.all((z > -0.01) & (z < 0.11))
    assert np.sum(np.diff(z[after:], axis=0) > 0.05) >= 6       # six wraps after the contact
    # the collision's step error (ω h ≈ 0.7 at the control's safety 0.5), then no change
    assert abs(error[after]) < 0.05 * 0.5 * M * 1.0 ** 2
    assert np.ptp(error[after:]) < 1e-13


def test_the_runs_energy_rows_stay_closed_over_wraps_and_steps():
    """A sphere falls through a cell periodic along gravity over two dynamic steps (a system
    each): the run's balance error (monitors/energy.csv, Simulation.energy) stays at
    round-off although the potential jumps by m g L at each wrap."""
    import nurbsdem
    sim = nurbsdem.Simulation(gravity=(0, 0, -9.81))
    sim.set_periodic(z=(0, 0.05))
    sim.add_material(1, 2700)
    sim.add_interface(1e5, 1e4, 0.5, 0.0, 0.5)
    sim.add_particle(sphere(0.005), 1, (0.02, 0.02, 0.04), velocity=(0, 0, -0.5))
    for _ in range(2):
        sim.run_dynamic(0.1, 1e-3)
    e = sim.energy()
    assert sim.positions[0, 2] < 0.051 and e["potential"] < 0.05 * 9.81 * 1.5e-3
    assert abs(e["balance_error"]) < 1e-12

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
from nurbsdem.shapes import sphere

ELASTIC = ContactLaw(en=1e5, cn=0.0, et=0.0, ct=0.0, mu=0.0)
R, M, L = 0.02, 0.1, 0.2


def two_spheres(x1, x2, cell, v=0.5):
    s = DemSystem(dt=1e-4, gravity=(0, 0, 0), interfaces=InterfaceTable(default=ELASTIC))
    s.add_particle(M, sphere_inertia(M, R), [x1, 0.1, 0.1], v=[v, 0, 0], radius=R)
    s.add_particle(M, sphere_inertia(M, R), [x2, 0.1, 0.1], v=[-v, 0, 0], radius=R)
    s.set_contact_provider(SceneContacts([sphere(R)], np.zeros(2, np.int64), cell=cell))
    return s


def collide(x1, x2, cell):
    s = two_spheres(x1, x2, cell)
    touching = 0
    for _ in range(300):
        s.step()
        touching += s.c_a.shape[0] > 0
    return s, touching


def test_a_collision_through_the_face_equals_the_same_collision_in_the_middle():
    cell = make_cell((0, 0, 0), (L, 0.2, 0.2), (1, 0, 0))
    mid, t_mid = collide(0.07, 0.13, cell)          # they meet at x = 0.1
    face, t_face = collide(0.17, 0.03, cell)        # the same, 0.1 further: they meet at x = 0
    assert t_mid > 10 and t_face == t_mid
    # elastic head-on, equal masses: the velocities exchanged (to the step's discrete error)
    np.testing.assert_allclose(mid.bodies.v[:, 0], [-0.5, 0.5], rtol=3e-3)
    np.testing.assert_allclose(face.bodies.v, mid.bodies.v, rtol=0, atol=1e-12)
    dx = (face.bodies.x - mid.bodies.x - [0.1, 0, 0]) % L
    np.testing.assert_allclose(np.minimum(dx, L - dx), 0.0, atol=1e-12)
    assert np.all((face.bodies.x[:, 0] >= 0) & (face.bodies.x[:, 0] < L + 0.01))
    # the same energy books (the balance error is the step's O(h²) spring error, alike)
    assert abs(face.energy().balance_error - mid.energy().balance_error) < 1e-12

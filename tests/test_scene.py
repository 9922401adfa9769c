"""The scene contact provider: global search + LCP batch for N bodies and flat walls."""
from types import SimpleNamespace

import numpy as np
import pytest

from nurbsdem.contact.scene import SceneContacts
from nurbsdem.shapes import box_walls, ellipsoid, sphere


def kinematics(x, R, shapes, body_shape, W):
    pos = np.array([x[i] - R[i] @ shapes[body_shape[i]].centroid for i in range(len(x))])
    return SimpleNamespace(x=np.asarray(x, float), R=np.asarray(R, float), position=pos,
                           wall_displacement=np.zeros((W, 3)))


def test_spheres_on_the_floor_and_against_each_other():
    r = 0.02
    shapes = [sphere(r)]
    walls = list(box_walls([0, 0, 0], [0.2, 0.2, 0.2]).values())
    x = np.array([[0.05, 0.05, r - 1e-4],           # 0.1 mm into the floor
                  [0.05 + 2 * r - 2e-4, 0.05, r - 1e-4],   # 0.2 mm into body 0, 0.1 mm into the floor
                  [0.15, 0.15, 0.10]])              # free
    R = np.repeat(np.eye(3)[None], 3, axis=0)
    scene = SceneContacts(shapes, np.zeros(3, np.int64), walls)
    cs = scene(kinematics(x, R, shapes, [0, 0, 0], len(walls)))
    got = {(int(a), int(b)): d for a, b, d in zip(cs.body_a, cs.body_b, cs.depth)}
    floor = 3                                        # global index of the first wall
    assert got == pytest.approx({(0, 1): 2e-4, (0, floor): 1e-4, (1, floor): 1e-4}, abs=1e-12)
    assert cs.active == len(got) and cs.failed == 0
    k = list(got).index((0, 1))
    np.testing.assert_allclose(cs.normal[k], [1, 0, 0], atol=1e-10)      # from A towards B
    assert cs.monitored >= cs.active
    # warm start: the same call again reproduces the result
    cs2 = scene(kinematics(x, R, shapes, [0, 0, 0], len(walls)))
    np.testing.assert_allclose(cs2.depth, cs.depth, atol=1e-15)


def test_separated_bodies_give_no_contacts_and_moving_walls_follow():
    shapes = [ellipsoid(0.03, 0.02, 0.01)]
    walls = list(box_walls([0, 0, 0], [0.3, 0.3, 0.3]).values())
    x = np.array([[0.1, 0.1, 0.1], [0.2, 0.2, 0.2]])
    R = np.repeat(np.eye(3)[None], 2, axis=0)
    scene = SceneContacts(shapes, np.zeros(2, np.int64), walls)
    kin = kinematics(x, R, shapes, [0, 0], len(walls))
    assert scene(kin).active == 0
    kin.wall_displacement[0] = [0, 0, 0.0905]       # lift the floor 0.5 mm into body 0
    cs = scene(kin)
    assert cs.active == 1 and cs.body_a[0] == 0 and cs.body_b[0] == 2
    assert cs.depth[0] == pytest.approx(5e-4, abs=1e-12)

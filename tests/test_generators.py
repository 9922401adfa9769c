"""Public generators: exact shapes load as closed, convex Shapes with analytic properties."""
import numpy as np
import pytest

import nurbsdem
from nurbsdem import shapes
from nurbsdem.errors import InputError


@pytest.mark.parametrize("radius", [1e-3, 0.02, 1.0, 37.0])
def test_every_sphere_generator_gives_a_valid_shape(radius):
    for make in (shapes.sphere, shapes.single_patch_sphere):
        s = make(radius)
        assert isinstance(s, nurbsdem.Shape)
        assert s.volume == pytest.approx(4 / 3 * np.pi * radius**3, rel=1e-10)
        assert np.allclose(s.centroid, 0.0, atol=1e-12 * radius)
        assert s.bounding_radius >= radius


def test_single_patch_sphere_connectivity_has_poles_and_seam():
    conn = shapes.single_patch_sphere(1.0).connectivity
    nb = conn.neighbours[0]
    assert sorted(nb[:, 0].tolist()).count(-2) == 2   # v_min and v_max collapse to poles
    assert nb[0, 0] == 0 and nb[0, 1] == 1             # the seam u_min <-> u_max
    assert nb[1, 0] == 0 and nb[1, 1] == 0


def test_ellipsoid_shape_properties():
    a, b, c = 0.03, 0.02, 0.01
    s = shapes.ellipsoid(a, b, c)
    V = 4 / 3 * np.pi * a * b * c
    assert s.volume == pytest.approx(V, rel=1e-10)
    J = V / 5 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])
    assert np.allclose(s.inertia, J, rtol=1e-10, atol=1e-10 * np.abs(J).max())
    assert len(s.connectivity.corners) == 8


def test_box_walls_face_inwards():
    walls = shapes.box_walls([0, 0, 0], [1, 2, 3], top=True)
    centre = np.array([0.5, 1.0, 1.5])
    for name, p in walls.items():
        d = p.evaluate(0.5, 0.5, 1)
        n = np.cross(d[1], d[2])
        assert n @ (centre - d[0]) > 0, name


def test_bad_generator_arguments_raise():
    """The API's generators raise the one-line InputError of bad input (no raw ValueError)."""
    with pytest.raises(InputError, match="sphere: Radius must be a finite number > 0"):
        shapes.sphere(0.0)
    with pytest.raises(InputError, match="ellipsoid"):
        shapes.ellipsoid(1.0, -1.0, 1.0)

"""Exact wall surfaces (nurbsdem.geometry.surfaces): points on the analytic cylinder and cone to
round-off, fronts facing the axis, the seam closed, the file round trip and bad arguments."""
import numpy as np
import pytest
from scipy.integrate import quad

from nurbsdem.geometry.surfaces import cone_patch, cylinder_patch, plane_patch
from nurbsdem.io.shapefile import read_patches, save_shape

U, V = np.meshgrid(np.linspace(0, 1, 97), np.linspace(0, 1, 5), indexing="ij")


def _radial(points, base, axis):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    rel = points - np.asarray(base, float)
    h = rel @ axis
    return rel - h[..., None] * axis, h


@pytest.mark.parametrize("axis", [(0, 0, 1), (1, 0, 0), (0.3, -0.5, 0.8)])
def test_cylinder_points_lie_on_the_cylinder(axis):
    base = np.array([0.1, -0.2, 0.3])
    patch = cylinder_patch(0.25, 0.4, base=base, axis=axis)
    radial, h = _radial(patch.points(U, V), base, axis)
    assert np.allclose(np.linalg.norm(radial, axis=-1), 0.25, rtol=0, atol=1e-15)
    assert np.allclose(h, 0.4 * V, atol=1e-15)
    # the front (S_u x S_v) faces the axis; outward when asked
    n = patch.normals(U[:-1], V[:-1])
    assert np.all(np.einsum("...k,...k", n, radial[:-1]) < 0)
    out = cylinder_patch(0.25, 0.4, base=base, axis=axis, inward=False)
    r_out, _ = _radial(out.points(U[:-1], V[:-1]), base, axis)
    assert np.all(np.einsum("...k,...k", out.normals(U[:-1], V[:-1]), r_out) > 0)


def test_circumference_is_exact():
    patch = cylinder_patch(0.3, 1.0)

    def speed(u):
        return np.linalg.norm(patch.evaluate(np.array([u]), np.array([0.0]), 1)[0, 1])

    length = sum(quad(speed, a, a + 0.25, epsabs=1e-14, epsrel=1e-14)[0]
                 for a in (0, 0.25, 0.5, 0.75))
    assert length == pytest.approx(2 * np.pi * 0.3, rel=1e-12)


def test_cone_radius_is_linear_in_height_and_the_seam_closes():
    patch = cone_patch(0.3, 0.05, 0.5)
    pts = patch.points(U, V)
    radial, h = _radial(pts, (0, 0, 0), (0, 0, 1))
    assert np.allclose(np.linalg.norm(radial, axis=-1), 0.3 + (0.05 - 0.3) * h / 0.5,
                       atol=1e-15)
    assert np.allclose(pts[0], pts[-1], atol=1e-15)
    n = patch.normals(U[:-1], V[:-1])
    assert np.all(np.einsum("...k,...k", n, radial[:-1]) < 0)


def test_surfaces_round_trip_through_a_shape_file(tmp_path):
    patches = [cylinder_patch(0.2, 0.3), cone_patch(0.2, 0.0, 0.1),
               plane_patch((0, 0, 0), (0, 0, 1), (1, 2))]
    for k, patch in enumerate(patches):
        path = tmp_path / f"s{k}.yaml"
        save_shape(path, [patch], name=f"surface {k}")
        (back,), name = read_patches(path)
        assert name == f"surface {k}"
        assert np.array_equal(back.points(U, V), patch.points(U, V))


@pytest.mark.parametrize("call, match", [
    (lambda: cylinder_patch(-1, 1), "base radius must be a positive length"),
    (lambda: cylinder_patch(1, float("nan")), "height must be a positive length"),
    (lambda: cone_patch(0, 0, 1), "needs a radius above zero"),
    (lambda: cylinder_patch(1, 1, axis=(0, 0, 0)), "has no direction"),
    (lambda: plane_patch((0, 0, 0), (0, 0, 1), (1, 0)), "side of the plane"),
])
def test_bad_arguments_say_what_is_wrong(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_shape_command_writes_wall_surfaces(tmp_path):
    from click.testing import CliRunner

    from nurbsdem.cli import main

    runner = CliRunner()
    out = tmp_path / "funnel.yaml"
    res = runner.invoke(main, ["shape", "cone", "--radius", "0.3", "--top-radius", "0.05",
                               "--length", "0.5", "-o", str(out)])
    assert res.exit_code == 0, res.output
    (patch,), _ = read_patches(out)
    radial, h = _radial(patch.points(U, V), (0, 0, 0), (0, 0, 1))
    assert np.allclose(np.linalg.norm(radial, axis=-1), 0.3 - 0.25 * h / 0.5, atol=1e-15)
    res = runner.invoke(main, ["shape", "cylinder", "--radius", "0.3", "-o", str(out)])
    assert res.exit_code == 2 and "shape cylinder: --length is required" in res.output

"""``nurbsdem export``: STL (tessellated) and Rhino .3dm (NURBS), and the round trips
fit -> export -> import. References: the shape's own exact volume (divergence theorem),
the bit-exact control points of the re-imported 3dm, trimesh's independent STL reader."""
from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from nurbsdem.cli import main
from nurbsdem.geometry import generators as gen
from nurbsdem.geometry.shape import Shape
from nurbsdem.io.export import shape_triangles
from nurbsdem.io.shapefile import load_shape, save_shape

trimesh = pytest.importorskip("trimesh")

AX = (0.03, 0.02, 0.012)


@pytest.fixture(scope="module")
def fitted_yaml(tmp_path_factory):
    """An ellipsoid mesh fitted with `nurbsdem fit` (8 x 8 control points)."""
    d = tmp_path_factory.mktemp("fit")
    m = trimesh.creation.icosphere(subdivisions=3)
    m.apply_scale(AX)
    m.export(d / "ell.stl")
    out = d / "ell.yaml"
    r = CliRunner().invoke(main, ["fit", str(d / "ell.stl"), "-o", str(out)])
    assert r.exit_code == 0, r.output
    return out


def test_stl_closed_outward_and_converging():
    sh = gen.ellipsoid(*AX)
    errs = []
    for n in (8, 16, 32):
        v, t = shape_triangles(sh, n)
        m = trimesh.Trimesh(v, t, process=False)
        assert m.is_watertight and m.is_winding_consistent
        assert m.volume > 0                               # outward
        errs.append(abs(m.volume / sh.volume - 1.0))
    # inscribed polyhedron: the volume error falls ~ 1/n^2
    assert errs[0] > 3 * errs[1] and errs[1] > 3 * errs[2] and errs[2] < 2e-3


def test_stl_of_a_shape_with_poles_is_closed():
    sh = Shape(gen.single_patch_sphere_patches(0.01), check=False)
    v, t = shape_triangles(sh, 32)
    m = trimesh.Trimesh(v, t, process=False)
    assert m.is_watertight and m.volume > 0
    assert abs(m.volume / (4 / 3 * np.pi * 1e-6) - 1.0) < 0.02


def test_round_trip_fit_export_3dm_import(fitted_yaml, tmp_path):
    pytest.importorskip("rhino3dm")
    f3 = tmp_path / "ell.3dm"
    r = CliRunner().invoke(main, ["export", str(fitted_yaml), "-o", str(f3)])
    assert r.exit_code == 0 and "6 NURBS surfaces" in r.output, r.output
    back = tmp_path / "back.yaml"
    r = CliRunner().invoke(main, ["import-3dm", str(f3), "-o", str(back)])
    assert r.exit_code == 0, r.output
    a, b = load_shape(fitted_yaml), load_shape(back)
    for p, q in zip(a.patches, b.patches):
        assert p.degree_u == q.degree_u and np.array_equal(p.knots_u, q.knots_u)
        assert np.array_equal(p.control_points, q.control_points)
        assert np.array_equal(p.weights, q.weights)
    assert b.volume == a.volume


def test_round_trip_fit_export_stl_fit(fitted_yaml, tmp_path):
    fs = tmp_path / "ell.stl"
    r = CliRunner().invoke(main, ["export", str(fitted_yaml), "-o", str(fs), "--resolution", "32"])
    assert r.exit_code == 0 and "STL" in r.output, r.output
    m = trimesh.load(fs)                                   # independent reader
    a = load_shape(fitted_yaml)
    assert m.is_watertight and abs(m.volume / a.volume - 1.0) < 2e-3
    again = tmp_path / "again.yaml"
    r = CliRunner().invoke(main, ["fit", str(fs), "-o", str(again)])
    assert r.exit_code == 0, r.output
    b = load_shape(again)
    assert abs(b.volume / a.volume - 1.0) < 5e-3
    assert np.linalg.norm(b.inertia - a.inertia) / np.linalg.norm(a.inertia) < 1e-2


def test_export_errors_one_line(tmp_path):
    f = tmp_path / "s.yaml"
    save_shape(f, gen.sphere_patches(0.01))
    r = CliRunner().invoke(main, ["export", str(f), "-o", str(tmp_path / "s.iges")])
    assert r.exit_code == 2 and "unknown export format '.iges'" in r.output
    assert "Traceback" not in r.output
    r = CliRunner().invoke(main, ["export", str(tmp_path / "none.yaml"), "-o", "x.stl"])
    assert r.exit_code == 2 and "none.yaml" in r.output

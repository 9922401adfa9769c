"""CAD import: Giraffe text records and Rhino .3dm files (through rhino3dm)."""
from __future__ import annotations

import sys
import textwrap

import numpy as np
import pytest
from click.testing import CliRunner

from nurbsdem.cli import main
from nurbsdem.errors import InputError, NurbsdemError
from nurbsdem.geometry import generators as gen
from nurbsdem.io.giraffe import (giraffe_text, import_giraffe, read_giraffe, read_giraffe_patches,
                                 write_giraffe)
from nurbsdem.io.shapefile import load_shape, read_patches


def _same_patches(a, b, tol=0.0):
    assert len(a) == len(b)
    rng = np.random.default_rng(0)
    for p, q in zip(a, b):
        assert (p.degree_u, p.degree_v) == (q.degree_u, q.degree_v)
        assert np.array_equal(p.knots_u, q.knots_u) and np.array_equal(p.knots_v, q.knots_v)
        if tol == 0.0:
            assert np.array_equal(p.control_points, q.control_points)
            assert np.array_equal(p.weights, q.weights)
        u0, u1, v0, v1 = p.domain
        u = rng.uniform(u0, u1, 200)
        v = rng.uniform(v0, v1, 200)
        assert np.abs(p.points(u, v) - q.points(u, v)).max() <= tol


# ---------------------------------------------------------------------- Giraffe
def test_giraffe_round_trip_sphere(tmp_path):
    patches = gen.sphere_patches(0.02)
    f = tmp_path / "sphere.txt"
    write_giraffe(f, patches)
    recs = read_giraffe(f)
    assert [r.id for r in recs] == [1, 2, 3, 4, 5, 6]
    assert all(r.subdivisions == (1, 1) for r in recs)
    _same_patches(patches, [r.patch for r in recs])          # bit-exact
    sh, warnings = import_giraffe(f)
    assert warnings == [] and sh.name == "sphere"
    assert np.isclose(sh.volume, 4 / 3 * np.pi * 0.02 ** 3, rtol=1e-12)
    # the file's connectivity is the geometry's, as neighbour IDs
    nbr = sh.connectivity.neighbours
    for i, r in enumerate(recs):
        assert r.connectivity == tuple(int(j) + 1 for j in nbr[i, :, 0])


def test_giraffe_round_trip_single_patch_and_particle(tmp_path):
    sps = gen.single_patch_sphere_patches(1.5)
    write_giraffe(tmp_path / "sps.txt", sps)
    rec, = read_giraffe(tmp_path / "sps.txt")
    assert rec.connectivity == (1, 1, 0, 0)                  # seam: itself; poles: 0
    _same_patches(sps, [rec.patch])
    particles = pytest.importorskip("nurbsdem.geometry.particles")
    pa = particles.paper_particle("A")
    write_giraffe(tmp_path / "a.txt", pa)
    _same_patches(pa, read_giraffe_patches(tmp_path / "a.txt"))


def test_giraffe_layout_u_fastest_and_tolerant_syntax(tmp_path):
    """UDim = n_u control points, UOrder = degree, u varies fastest; comments, odd spacing."""
    text = textwrap.dedent("""\
        // a test record
        ID 7 Subdivisions 2 3 Connectivity 0 0 0 0   // all on one line
        UDim 3 UOrder 2
        UKnotVector 0 0 0
           1 1 1
        VDim 2
        VOrder 1 VKnotVector 0 0 2 2
        Weights 1 2 3
                4 5 6   // w(i, j), u fastest
        ControlPoints
        0 0 0   1 0 0.5   2 0 0
        0 1 0   1 1 .5    2 1 1E-1
        """).replace("  ", "\t ")
    f = tmp_path / "one.txt"
    f.write_text(text)
    rec, = read_giraffe(f)
    p = rec.patch
    assert (rec.id, rec.subdivisions, rec.line) == (7, (2, 3), 2)
    assert (p.degree_u, p.degree_v, p.shape) == (2, 1, (3, 2))
    assert np.array_equal(p.weights, [[1, 4], [2, 5], [3, 6]])
    assert np.array_equal(p.control_points[:, 1], [[0, 1, 0], [1, 1, 0.5], [2, 1, 0.1]])
    assert np.array_equal(p.knots_v, [0, 0, 2, 2])
    # and the writer produces the same layout
    assert "Weights\n1 2 3\n4 5 6\n" in giraffe_text([p], ids=[7], subdivisions=[(2, 3)],
                                                     connectivity=[(0, 0, 0, 0)])


def _record_lines():
    return giraffe_text(gen.single_patch_sphere_patches(1.0)).splitlines()


@pytest.mark.parametrize("edit, line, msg", [
    (lambda L: L.__setitem__(3, "UDIM 9"), 4, "expected 'UDim', got 'UDIM'"),
    (lambda L: L.__setitem__(4, "UOrder two"), 5, "UOrder (the degree) must be an integer"),
    (lambda L: L.__setitem__(4, "UOrder 0"), 5,
     "UOrder (the degree) 0 is not supported: it must be from 1 to 9"),
    (lambda L: L.__setitem__(4, "UOrder 50"), 5,
     "UOrder (the degree) 50 is not supported: it must be from 1 to 9, the highest degree"),
    (lambda L: L.__setitem__(5, "UKnotVector 0 0 0 0.25 0.25 0.5 0.5 0.75 0.75 1 1 x"), 6,
     "UKnotVector (UDim + UOrder + 1) needs 12 numbers, got 'x' at number 12"),
    (lambda L: L.__setitem__(5, "UKnotVector 0 0 0 0.25 0.75 0.5 0.5 0.75 0.75 1 1 1"), 1,
     "patch ID 1: knots_u is not non-decreasing"),
    (lambda L: L.__setitem__(10, L[10].replace("1 ", "-1 ", 1)), 1,
     "patch ID 1: weight [0][0] = -1.0 is not > 0"),
    (lambda L: L.__delitem__(slice(-3, None)), None, "unexpected end of file: ControlPoints"),
    (lambda L: L.extend(["ID", "1"]), None, "duplicate patch ID 1 (first at line 1)"),
    (lambda L: L.insert(0, "Header"), 1, "expected 'ID', got 'Header'"),
])
def test_giraffe_errors_name_file_and_line(tmp_path, edit, line, msg):
    lines = _record_lines()
    edit(lines)
    f = tmp_path / "bad.txt"
    f.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError) as ei:
        read_giraffe(f)
    text = str(ei.value)
    assert msg in text and "\n" not in text
    assert ei.value.line is not None
    if line is not None:
        assert text.startswith(f"{f}:{line}: ") and ei.value.line == line
    else:   # end of file: the last line
        assert text.startswith(f"{f}:{ei.value.line}: ")


def test_giraffe_empty_and_missing(tmp_path):
    (tmp_path / "e.txt").write_text("// nothing\n")
    with pytest.raises(InputError, match="no patch records"):
        read_giraffe(tmp_path / "e.txt")
    with pytest.raises(InputError, match="cannot read file"):
        read_giraffe(tmp_path / "none.txt")


def test_giraffe_connectivity_mismatch_warns(tmp_path):
    text = giraffe_text(gen.sphere_patches(1.0))
    text = text.replace("Connectivity", "Connectivity 9 9 9 9 //", 1)
    f = tmp_path / "w.txt"
    f.write_text(text)
    sh, warnings = import_giraffe(f)
    assert len(warnings) == 4 and "patch ID 1 (line 1)" in warnings[0]
    res = CliRunner().invoke(main, ["import-giraffe", str(f), "-o", str(tmp_path / "w.yaml")])
    assert res.exit_code == 0
    assert res.stderr.count("nurbsdem: warning:") == 4


def test_import_giraffe_cli_round_trip(tmp_path):
    patches = gen.ellipsoid_patches(0.03, 0.02, 0.01)
    write_giraffe(tmp_path / "e.txt", patches)
    out = tmp_path / "e.yaml"
    res = CliRunner().invoke(main, ["import-giraffe", str(tmp_path / "e.txt"), "-o", str(out),
                                    "--name", "ell"])
    assert res.exit_code == 0, res.output
    assert "6 patches" in res.stdout
    back, name = read_patches(out)
    assert name == "ell"
    _same_patches(patches, back)
    # --scale (e.g. mm -> m)
    res = CliRunner().invoke(main, ["import-giraffe", str(tmp_path / "e.txt"), "-o", str(out),
                                    "--scale", "0.001"])
    assert res.exit_code == 0
    assert np.isclose(load_shape(out).volume, 4 / 3 * np.pi * 6e-6 * 1e-9, rtol=1e-10)


def test_import_giraffe_cli_error(tmp_path):
    f = tmp_path / "open.txt"
    write_giraffe(f, gen.sphere_patches(1.0)[:5], connectivity=[(0, 0, 0, 0)] * 5)
    res = CliRunner().invoke(main, ["import-giraffe", str(f), "-o", str(tmp_path / "o.yaml")])
    assert res.exit_code == 2
    assert res.stderr.startswith(f"nurbsdem: error: {f}: patch ")
    assert "not closed" in res.stderr and res.stderr.count("\n") == 1
    assert not (tmp_path / "o.yaml").exists()


# ---------------------------------------------------------------------- Rhino .3dm
@pytest.fixture(scope="module")
def r3():
    return pytest.importorskip("rhino3dm")


@pytest.mark.parametrize("breps", [False, True], ids=["surfaces", "breps"])
def test_3dm_round_trip(tmp_path, r3, breps):
    from nurbsdem.io.rhino import import_3dm, read_3dm_patches, write_3dm

    patches = gen.sphere_patches(0.05)
    assert not np.all(patches[0].weights == 1)               # rational
    f = tmp_path / "s.3dm"
    write_3dm(f, patches, breps=breps)
    model = r3.File3dm.Read(str(f))
    kinds = {type(o.Geometry).__name__ for o in model.Objects}
    assert kinds == ({"Brep"} if breps else {"NurbsSurface"})
    back = read_3dm_patches(f)
    _same_patches(patches, back, tol=1e-12)
    sh = import_3dm(f)
    assert sh.connectivity.closed and np.isclose(sh.volume, 4 / 3 * np.pi * 0.05 ** 3)


def test_3dm_reversed_brep_face_is_transposed(tmp_path, r3):
    """A face whose orientation is reversed relative to its surface: the imported patch
    is transposed so that S_u x S_v is the face's (outward) normal."""
    from nurbsdem.geometry.nurbs import Patch
    from nurbsdem.io.rhino import import_3dm, nurbs_surface_from_patch

    model = r3.File3dm()
    patches = gen.sphere_patches(1.0)
    for k, p in enumerate(patches):
        if k % 2:   # store the surface transposed (inward) and flip the face
            t = Patch(p.degree_v, p.degree_u, p.knots_v, p.knots_u,
                      p.control_points.transpose(1, 0, 2), p.weights.T)
            b = r3.Brep.CreateFromSurface(nurbs_surface_from_patch(t))
            b.Flip()
            assert b.Faces[0].OrientationIsReversed
        else:
            b = r3.Brep.CreateFromSurface(nurbs_surface_from_patch(p))
        model.Objects.AddBrep(b)
    model.Write(str(tmp_path / "f.3dm"), 7)
    sh = import_3dm(tmp_path / "f.3dm")
    _same_patches(patches, sh.patches, tol=1e-12)


def test_3dm_rhino_quad_sphere(tmp_path, r3):
    """A multi-face Brep made by openNURBS itself (Rhino's quad sphere)."""
    model = r3.File3dm()
    model.Objects.AddBrep(r3.Brep.CreateQuadSphere(r3.Sphere(r3.Point3d(1, 2, 3), 0.5)))
    model.Write(str(tmp_path / "q.3dm"), 7)
    out = tmp_path / "q.yaml"
    res = CliRunner().invoke(main, ["import-3dm", str(tmp_path / "q.3dm"), "-o", str(out)])
    assert res.exit_code == 0, res.output
    sh = load_shape(out)
    assert len(sh.patches) == 6 and sh.connectivity.closed and len(sh.connectivity.corners) == 8
    assert np.allclose(sh.centroid, [1, 2, 3], atol=1e-9)
    assert abs(sh.volume / (4 / 3 * np.pi * 0.125) - 1) < 2e-3   # not an exact sphere


def test_3dm_bad_files(tmp_path, r3):
    from nurbsdem.io.rhino import read_3dm_patches

    (tmp_path / "junk.3dm").write_bytes(b"not a rhino file")
    with pytest.raises(InputError, match="not a readable Rhino .3dm file"):
        read_3dm_patches(tmp_path / "junk.3dm")
    with pytest.raises(InputError, match="cannot read file"):
        read_3dm_patches(tmp_path / "none.3dm")
    model = r3.File3dm()
    model.Objects.AddPoint(r3.Point3d(0, 0, 0))
    model.Write(str(tmp_path / "pt.3dm"), 7)
    with pytest.raises(InputError, match="no surfaces or breps"):
        read_3dm_patches(tmp_path / "pt.3dm")
    res = CliRunner().invoke(main, ["import-3dm", str(tmp_path / "junk.3dm"), "-o", "x.yaml"])
    assert res.exit_code == 2
    junk = tmp_path / "junk.3dm"
    assert res.stderr == f"nurbsdem: error: {junk}: not a readable Rhino .3dm file\n"


def test_3dm_without_rhino3dm(tmp_path, monkeypatch):
    from nurbsdem.io.rhino import read_3dm_patches

    monkeypatch.setitem(sys.modules, "rhino3dm", None)     # import fails
    with pytest.raises(NurbsdemError, match=r"needs the optional package rhino3dm"):
        read_3dm_patches(tmp_path / "x.3dm")
    res = CliRunner().invoke(main, ["import-3dm", str(tmp_path / "x.3dm"), "-o", "x.yaml"])
    assert res.exit_code == 2
    assert res.stderr.startswith("nurbsdem: error: reading .3dm files needs the optional "
                                 "package rhino3dm")
    assert res.stderr.count("\n") == 1

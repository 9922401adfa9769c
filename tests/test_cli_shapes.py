"""Command line: shape, info, and one-line user errors (exit 2, no traceback)."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import click
import numpy as np
import pytest
from click.testing import CliRunner

from nurbsdem.cli import NurbsdemGroup, handles_errors, main
from nurbsdem.errors import InputError
from nurbsdem.geometry import generators as gen
from nurbsdem.geometry.nurbs import Patch
from nurbsdem.io.shapefile import load_shape, save_shape


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def assert_one_line_error(res, prefix: str):
    assert res.exit_code == 2, res.output
    assert res.stderr.startswith(f"nurbsdem: error: {prefix}"), res.stderr
    assert res.stderr.count("\n") == 1 and "Traceback" not in res.output
    assert res.stdout == "" or "Traceback" not in res.stdout


def test_version():
    res = run("--version")
    assert res.exit_code == 0 and "0.1.0" in res.stdout


@pytest.mark.parametrize("args, volume", [
    (["sphere", "--radius", "0.01"], 4 / 3 * np.pi * 1e-6),
    (["ellipsoid", "--semi-axes", "0.03", "0.02", "0.01"], 4 / 3 * np.pi * 6e-6),
    (["single-patch-sphere", "--radius", "2"], 4 / 3 * np.pi * 8),
])
def test_shape_generates_files(tmp_path, args, volume):
    out = tmp_path / "s.yaml"
    res = run("shape", *args, "-o", out)
    assert res.exit_code == 0, res.output
    sh = load_shape(out)
    assert np.isclose(sh.volume, volume, rtol=1e-10)
    assert f"wrote {out}" in res.stdout


def test_shape_particle(tmp_path):
    pytest.importorskip("nurbsdem.geometry.particles")
    out = tmp_path / "B.yaml"
    res = run("shape", "particle", "--kind", "B", "-o", out, "--name", "B")
    assert res.exit_code == 0, res.output
    sh = load_shape(out)
    assert sh.name == "B" and len(sh.patches) == 6
    assert np.isclose(sh.volume, 50.47e-6, rtol=2e-3)


@pytest.mark.parametrize("args, msg", [
    (["sphere"], "shape sphere: --radius is required"),
    (["sphere", "--radius", "-1"], "shape sphere: radius must be > 0"),
    (["ellipsoid", "--semi-axes", "1", "0", "1"], "shape ellipsoid: semi-axes must be > 0"),
    (["particle"], "shape particle: --kind A|B|C is required"),
])
def test_shape_bad_arguments(tmp_path, args, msg):
    res = run("shape", *args, "-o", tmp_path / "x.yaml")
    assert_one_line_error(res, msg)


def test_info_sphere(tmp_path):
    f = tmp_path / "s.yaml"
    save_shape(f, gen.sphere(0.01))
    res = run("info", f, "--density", "2700")
    assert res.exit_code == 0, res.output
    out = res.stdout
    assert "patches: 6" in out and "degrees (4, 4), control points 5 x 5" in out
    assert "connectivity: 8 corner nodes" in out
    vol = float(out.split("volume: ")[1].split()[0])
    assert np.isclose(vol, 4 / 3 * np.pi * 1e-6, rtol=1e-8)
    moments = out.split("principal moments (m^5): [")[1].split("]")[0]
    assert np.allclose([float(x) for x in moments.split(",")], 8 * np.pi / 15 * 1e-10, rtol=1e-8)
    assert "centroid: [" in out and "inertia tensor" in out and "bounding radius:" in out
    assert "mass: 0.0113097" in out
    assert "closed: yes" in out and "convex, outward oriented: yes" in out


def test_info_single_patch_sphere(tmp_path):
    f = tmp_path / "s.yaml"
    save_shape(f, gen.single_patch_sphere(1.0))
    res = run("info", f)
    assert res.exit_code == 0, res.output
    assert "2 pole edges, 2 seam edges" in res.stdout


# ---------------------------------------------------------------------- user errors
def test_missing_file(tmp_path):
    f = tmp_path / "nope.yaml"
    assert_one_line_error(run("info", f), f"{f}: cannot read file")


def test_bad_yaml(tmp_path):
    f = tmp_path / "dup.yaml"
    f.write_text("name: a\nname: b\npatches: []\n")
    assert_one_line_error(run("info", f), f"{f}:2: duplicate key 'name'")


def test_bad_patch(tmp_path):
    f = tmp_path / "w.yaml"
    save_shape(f, gen.sphere_patches(1.0))
    text, n = re.subn(r"(weights:\n\s*- \[)", r"\1-", f.read_text(), count=1)
    assert n == 1
    f.write_text(text)
    res = run("info", f)
    assert_one_line_error(res, f"{f}: patch 0: weight [0][0] = -")


def test_not_closed(tmp_path):
    f = tmp_path / "open.yaml"
    save_shape(f, gen.sphere_patches(1.0)[1:])
    res = run("info", f)
    assert_one_line_error(res, f"{f}: patch ")
    assert "not closed" in res.stderr
    assert "closed: no" in res.stdout      # info still shows what it could compute


def test_not_convex(tmp_path):
    patches = gen.sphere_patches(1.0)
    p = patches[5]
    cp = p.control_points.copy()
    cp[2, 2] *= -0.5
    patches[5] = Patch(4, 4, p.knots_u, p.knots_v, cp, p.weights)
    f = tmp_path / "dent.yaml"
    save_shape(f, patches)
    res = run("info", f)
    assert_one_line_error(res, f"{f}: patch 5: not convex")


def test_unwritable_output(tmp_path):
    (tmp_path / "file").write_text("")
    res = run("shape", "sphere", "--radius", "1", "-o", tmp_path / "file" / "x.yaml")
    assert res.exit_code == 2 and res.stderr.startswith("nurbsdem: error: ")
    assert res.stderr.count("\n") == 1


def test_error_wrapper_is_reusable():
    @click.group(cls=NurbsdemGroup)
    def grp():
        pass

    @grp.command()
    def boom():
        raise InputError("bad thing", path="deck.inp", line=12)

    res = CliRunner().invoke(grp, ["boom"])
    assert res.exit_code == 2 and res.stderr == "nurbsdem: error: deck.inp:12: bad thing\n"

    @click.command()
    @handles_errors
    def solo():
        open("/nonexistent/dir/file")

    res = CliRunner().invoke(solo, [])
    assert res.exit_code == 2
    assert res.stderr == "nurbsdem: error: /nonexistent/dir/file: No such file or directory\n"


def test_installed_script_error(tmp_path):
    exe = Path(sys.executable).parent / "nurbsdem"
    if not exe.exists():
        pytest.skip("nurbsdem script not installed in this environment")
    f = tmp_path / "missing.yaml"
    proc = subprocess.run([str(exe), "info", str(f)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr == f"nurbsdem: error: {f}: cannot read file: No such file or directory\n"
    assert proc.stdout == ""

"""The warning of a surface wall that curves toward the particles more tightly than a NURBS
particle (nurbsdem.curvature_checks): the sampled radii against the analytic ones, and the
warning of ``nurbsdem check`` at the wall's line for a cone narrower than the paper's
particles, none for the shipped hopper."""
from __future__ import annotations

import math
from pathlib import Path

import pytest
from click.testing import CliRunner

from nurbsdem.cli import main
from nurbsdem.curvature_checks import flattest_radius, tightest_concave_radius
from nurbsdem.geometry.generators import ellipsoid_patches, sphere_patches
from nurbsdem.geometry.surfaces import cone_patch, cylinder_patch, plane_patch
from nurbsdem.io.shapefile import save_shape
from nurbsdem.shapes import paper_particle

ROOT = Path(__file__).resolve().parents[1]
HOPPER = ROOT / "inputs" / "hopper"


def test_the_sampled_radii_are_the_analytic_ones():
    # a sphere is umbilic everywhere, where the closed form's root of H² − K keeps half the
    # digits
    assert flattest_radius(sphere_patches(0.01)) == pytest.approx(0.01, rel=1e-7)
    # an ellipsoid is flattest at the ends of its shortest axis, along its longest: a² / c
    assert flattest_radius(ellipsoid_patches(0.03, 0.02, 0.01)) == pytest.approx(
        0.03 ** 2 / 0.01, rel=1e-12)
    r, at = tightest_concave_radius([cylinder_patch(0.1, 0.2)])
    assert r == pytest.approx(0.1, rel=1e-12) and math.hypot(at[0], at[1]) == pytest.approx(0.1)
    # a cone of half-angle atan(0.1 / 0.16), narrowest at its base: r / cos(half-angle)
    r, at = tightest_concave_radius([cone_patch(0.04, 0.14, 0.16)])
    assert r == pytest.approx(0.04 / math.cos(math.atan(0.1 / 0.16)), rel=1e-12)
    assert at[2] == pytest.approx(0.0, abs=1e-15)
    assert tightest_concave_radius([plane_patch((0, 0, 0), (0, 0, 1), (0.1, 0.1))])[0] == math.inf


def check(tmp_path, cone: str | None):
    text = (HOPPER / "hopper_paper.inp").read_text()
    if cone is not None:
        text = text.replace("File cone_paper.yaml", f"File {cone}")
    for name in ("A", "B", "C"):
        text = text.replace(f"../shapes/{name}.yaml", str(ROOT / "inputs" / "shapes"
                                                          / f"{name}.yaml"))
    if cone is None:
        text = text.replace("File cone_paper.yaml", f"File {HOPPER / 'cone_paper.yaml'}")
    deck = tmp_path / "hopper.inp"
    deck.write_text(text)
    line = next(k for k, ln in enumerate(text.splitlines(), 1) if ln.strip().startswith("Surface"))
    r = CliRunner().invoke(main, ["check", str(deck)])
    assert r.exit_code == 0 and "Traceback" not in r.output, r.output
    return [ln for ln in r.output.splitlines() if ln.startswith("nurbsdem: warning:")], deck, line


def test_a_cone_tighter_than_the_paper_particles_is_a_warning_at_its_line(tmp_path):
    save_shape(tmp_path / "narrow.yaml", [cone_patch(0.04, 0.14, 0.16)])
    said, deck, line = check(tmp_path, "narrow.yaml")
    flat = flattest_radius(paper_particle("A"))
    assert said == [f"nurbsdem: warning: {deck}:{line}: Surface 1 ('hopper') curves toward the "
                    f"particles with a radius of 0.0472 m (near (0.02828, -0.02828, 0) m), "
                    f"tighter than shape 1's flattest part ({flat:.3g} m): where a particle "
                    f"touches it there its contact is not unique and the run stops (a wider "
                    f"wall or smaller particles avoid it)"]
    said, _, _ = check(tmp_path, None)
    assert said == []


def test_check_reads_a_surface_file_once_and_again_after_it_changes(tmp_path, monkeypatch):
    """The parse, the curvature warning and the wall's geometry share one read of a
    ``Surface`` file; an edit of the file (its time and size) is read anew."""
    import os

    from nurbsdem.io import deck_curved, shapefile
    read, calls = shapefile.read_patches, []
    monkeypatch.setattr(shapefile, "read_patches",
                        lambda p: (Path(p).name == "narrow.yaml" and calls.append(p)) or read(p))
    deck_curved._file_patches.cache_clear()
    save_shape(tmp_path / "narrow.yaml", [cone_patch(0.04, 0.14, 0.16)])
    said, _, _ = check(tmp_path, "narrow.yaml")
    assert len(said) == 1 and calls == [tmp_path / "narrow.yaml"]
    save_shape(tmp_path / "narrow.yaml", [cone_patch(0.2, 0.3, 0.16)])
    os.utime(tmp_path / "narrow.yaml", ns=(1, 1))
    said, _, _ = check(tmp_path, "narrow.yaml")
    assert said == [] and len(calls) == 2

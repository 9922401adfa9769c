"""The warning of ParaView samples larger than their disk's free space
(nurbsdem.output_checks): said once, one line at the deck's VTK line, the check still passes;
and its estimate of a sample's bytes against the samples a run writes."""
from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from nurbsdem import output_checks
from nurbsdem.cli import main
from nurbsdem.io.deck import build_model

ROOT = Path(__file__).resolve().parents[1]
POUR = ROOT / "tests" / "data" / "flow_pour.inp"


def test_samples_larger_than_the_free_disk_are_a_one_line_warning(tmp_path, monkeypatch):
    deck = tmp_path / "case.inp"
    deck.write_text(POUR.read_text())
    line = next(k for k, ln in enumerate(deck.read_text().splitlines(), 1)
                if ln.strip().startswith("VTK"))
    model = build_model(deck.read_text(), str(deck))
    need, samples, n = output_checks.vtk_output_bytes(model)
    # 0.08 s sampled every 0.02 s; the inlet's 60 spheres of 6 patches of 9 x 9 vertices
    assert (samples, n) == (5, 60)
    assert need == 5 * 60 * 6 * 81 * output_checks.DISK_BYTES_PER_VERTEX
    monkeypatch.setattr(output_checks, "free_bytes", lambda directory: int(need) // 2)
    r = CliRunner().invoke(main, ["check", str(deck)])
    assert r.exit_code == 0 and "Traceback" not in r.output, r.output
    said = [ln for ln in r.output.splitlines() if ln.startswith("nurbsdem: warning:")]
    assert len(said) == 1, r.output
    assert said[0].startswith(f"nurbsdem: warning: {deck}:{line}: VTK Every 0.02 s writes about ")
    assert "(5 samples of up to 60 particles at Resolution 8)" in said[0]
    assert "raise VTK Every to 0.08 s or more, or lower Resolution" in said[0]
    monkeypatch.setattr(output_checks, "free_bytes", lambda directory: int(need) // 6)
    r = CliRunner().invoke(main, ["check", str(deck)])
    assert "(not even two samples fit: lower Resolution)" in r.output, r.output
    monkeypatch.setattr(output_checks, "free_bytes", lambda directory: int(need))
    r = CliRunner().invoke(main, ["check", str(deck)])
    assert r.exit_code == 0 and "warning" not in r.output, r.output


def test_the_estimate_of_a_sample_matches_the_samples_a_run_writes(tmp_path):
    """Each particle sample of the pour takes within 30 % of the estimate's bytes per
    vertex (for the particles it holds)."""
    import meshio
    deck = tmp_path / "case.inp"
    deck.write_text(POUR.read_text().replace("Duration 0.08", "Duration 0.04"))
    r = CliRunner().invoke(main, ["solve", str(deck), "--quiet"])
    assert r.exit_code == 0, r.output
    files = sorted((tmp_path / "results" / "vtk").glob("particles_*.vtu"))
    assert len(files) == 3
    for f in files[1:]:                   # the first sample, at t = 0, holds no particle
        vertices = len(meshio.read(f).points)
        assert vertices % (6 * 81) == 0 and vertices > 0
        per_vertex = f.stat().st_size / vertices
        assert per_vertex == pytest.approx(output_checks.DISK_BYTES_PER_VERTEX, rel=0.3)

"""The scripts of examples/ run, and the one number each returns is checked against an
independent expectation (a formula, bounds, the monitors)."""
from __future__ import annotations

import csv
import importlib.util
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def load(name: str):
    spec = importlib.util.spec_from_file_location(f"example_{name}", EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_drop_test_rests_at_the_static_penalty_overlap():
    ex = load("drop_test")
    z = ex.main(quiet=True)
    m = ex.DENSITY * 4.0 / 3.0 * math.pi * ex.RADIUS ** 3
    overlap = m * ex.GRAVITY / ex.NORMAL_PENALTY            # k delta = m g
    assert ex.RADIUS - z == pytest.approx(overlap, rel=1e-4)


def test_friction_sweep_pack_heights(monkeypatch):
    ex = load("friction_sweep")
    heights = ex.sweep()
    n = 14
    volume = sum(4.0 / 3.0 * math.pi * ex.RADII[k % 3 == 0] ** 3 for k in range(n))
    area = ex.BOX[0] * ex.BOX[1]
    densest = volume / (area * math.pi / math.sqrt(18))      # Kepler's packing fraction 0.7405
    top = 0.012 + 0.018 * ((n - 1) // 4) + max(ex.RADII)     # where the highest one started
    h = [heights[mu] for mu in sorted(heights)]
    assert all(densest < x < top for x in h), h
    assert all(b > a for a, b in zip(h, h[1:])), h           # more friction, looser pack
    monkeypatch.setattr(ex, "sweep", lambda: heights)       # main() reports the sweep's
    assert ex.main(quiet=True) == h[-1]                      # value at the largest friction


def test_postprocessing_of_results_h5_agrees_with_the_monitors(tmp_path):
    ex = load("postprocess_results")
    emax = ex.main(output=tmp_path / "out", quiet=True)
    with open(tmp_path / "out" / "monitors" / "energy.csv") as fh:
        rows = [(float(r["time"]), float(r["kinetic"])) for r in csv.DictReader(fh)]
    times = ex.read_results_times(tmp_path / "out" / "results.h5")
    monitored = [e for t, e in rows if np.isclose(times, t, rtol=0, atol=1e-12).any()]
    assert len(monitored) == len(times) == 11
    assert emax == pytest.approx(max(monitored), rel=1e-9)


def test_examples_run_as_scripts():
    r = subprocess.run([sys.executable, str(EXAMPLES / "drop_test.py")], capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "rest height" in r.stdout

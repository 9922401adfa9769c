"""benchmarks/bench_heap.py and its section of the report: an unknown grain is refused before
any run, and the section renders the angles of both grains from the benchmark's JSON."""
import json
import math
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import bench_heap  # noqa: E402


def test_an_unknown_grain_is_refused():
    with pytest.raises(SystemExit, match="is not one of sphere, paper, both"):
        bench_heap.main(["--shape", "cube"])


def test_the_linear_laws_dashpot_gives_the_restitution():
    """damping(): the closed form of the linear spring-dashpot, e = exp(−ζπ/√(1−ζ²))."""
    m = bench_heap.DENSITY * 4 / 3 * math.pi * bench_heap.RADII[1] ** 3
    zeta = bench_heap.damping() / (2 * math.sqrt(0.5 * m * bench_heap.KN))
    e = math.exp(-zeta * math.pi / math.sqrt(1 - zeta ** 2))
    assert e == pytest.approx(bench_heap.RESTITUTION, rel=1e-12)


def test_the_report_gives_both_grains_angles(tmp_path, monkeypatch):
    import report_peers
    from report_base import Report
    cache = tmp_path / "benchmarks" / ".cache"
    cache.mkdir(parents=True)
    runs = [dict(shape=s, count=1000, on_floor=990, angle=a, error=0.4, foot=0.09, height=0.02,
                 wall=100.0) for s, a in (("sphere", 12.25), ("paper", 21.0))]
    (cache / "heap.json").write_text(json.dumps(dict(
        quick=False, radii=list(bench_heap.RADII), rolling=0.3, friction=0.5, rate=1000.0,
        height=0.05, runs=runs)))
    monkeypatch.setattr(report_peers, "REPO", tmp_path)
    rep = Report(tmp_path / "out", {}, quick=False)
    report_peers.section_heap(rep)
    text = "".join(rep.parts)
    assert "| exact spheres | 1000 | 990 | 12.2 ± 0.4 | 90 | 20 |" in text
    assert "| the paper's particles (A, B, C scaled) | 1000 | 990 | 21.0 ± 0.4 |" in text
    assert "about atan(μ_r / 2), 9 degrees" in text
    assert rep.headline["heap"] == dict(sphere=12.25, paper=21.0)

"""The verification report builds (``benchmarks/report.py --quick``, ~1–2 min on 2 cores).

Checks: the markdown and its PNG figures exist, every section is there, every section states
machine, version and date, and no table cell that should hold a number holds NaN."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
SCRIPT = REPO / "benchmarks" / "report.py"

SECTIONS = ("## Headline numbers", "## 1. Contact accuracy against cost",
            "## 2. Exact geometry against facets", "## 3. Robustness: randomised hard cases",
            "## 4. Time step against error", "## 5. Cost of a run", "### 112 spheres against Yade",
            "### An exact sphere against a NURBS particle",
            "### The paper's example",
            "## 6. Fit to meshes", "## 7. Hertz–Mindlin with the exact curvature",
            "## 8. Runs on several MPI ranks")
FIGURES = ("lcp_accuracy.png", "facets.png", "timestep.png", "scaling.png")


#: the quick report runs the benchmarks' short versions (about 2.5 min on 2 cores): with the
#: long runs (``pytest -m slow``), not in the default suite
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    if not SCRIPT.is_file():
        pytest.skip("benchmarks/ not present")
    out = tmp_path_factory.mktemp("report")
    p = subprocess.run([sys.executable, str(SCRIPT), "--quick", "--output", str(out)],
                       capture_output=True, text=True, timeout=600, cwd=REPO)
    assert p.returncode == 0, p.stderr[-3000:]
    return out, p


def test_markdown_and_figures(report):
    out, _ = report
    md = (out / "verification.md").read_text(encoding="utf-8")
    for s in SECTIONS:
        assert s in md, s
    assert "Not measured" not in md and "not measured" not in md.split("## 1.")[1].split("## 2.")[0]
    import nurbsdem
    assert f"nurbsdem {nurbsdem.__version__}" in md
    assert md.count("*Measured on ") >= 6          # every section carries the stamp
    for f in FIGURES:
        png = out / "verification" / f
        assert png.is_file() and png.stat().st_size > 5000, f
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert f"(verification/{f})" in md


def test_no_nan_numbers(report):
    out, _ = report
    md = (out / "verification.md").read_text(encoding="utf-8")
    rows = [ln for ln in md.splitlines() if ln.startswith("|") and not ln.startswith("|---")]
    assert len(rows) > 30
    for ln in rows:
        cells = [c.strip() for c in ln.strip("|").split("|")]
        for c in cells:
            assert c.lower() not in ("nan", "n/a", "inf", "-inf"), ln
            assert not re.search(r"\bnan\b", c, re.I), ln
    # the headline numbers are finite numbers
    head = md.split("## Headline numbers")[1].split("## 1.")[0]
    assert not re.search(r"\bnan\b|\binf\b", head, re.I)
    assert re.search(r"LCP sphere: \d+\.\d µs cold", head)


def test_robustness_counts_consistent(report):
    out, _ = report
    md = (out / "verification.md").read_text(encoding="utf-8")
    sec = md.split("## 3.")[1].split("## 4.")[0]
    row = next(ln for ln in sec.splitlines() if ln.startswith("| **all**"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    n, conv, fail = int(cells[1]), int(cells[2]), int(cells[3])
    assert 1000 <= n <= 10_000 and conv + fail == n
    assert int(cells[7]) > 0.5 * n          # most poses validated against a reference


def test_bench_paper_decks_differ_only_in_the_vtk_interval(tmp_path):
    """benchmarks/bench_paper.py: the few-samples variant of each paper deck is the deck with
    ``VTK Every 0.5`` and nothing else changed (parsed models compared)."""
    sys.path.insert(0, str(REPO / "benchmarks"))
    import bench_paper

    from nurbsdem.io.deck import parse_deck
    from nurbsdem.model import model_differences
    for quick in (False, True):
        models = []
        for few in (False, True):
            path = tmp_path / f"{quick}_{few}.inp"
            path.write_text(bench_paper.deck_text(few, quick))
            models.append(parse_deck(path, place=False))
        assert models[1].output.vtk_every == 0.5 != models[0].output.vtk_every
        assert model_differences(*models) == []          # all but the Output block
        models[1].output.vtk_every = models[0].output.vtk_every
        assert models[1].output == models[0].output

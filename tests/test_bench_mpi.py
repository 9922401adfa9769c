"""benchmarks/bench_mpi.py's strong scaling without MPI: the configurations are run in
alternated rounds and each row is the median of its runs (measurements stood in for by a
fixed table, so that the test checks the bookkeeping, not this machine's speed)."""
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import bench_mpi  # noqa: E402

#: seconds per deck step of each configuration's successive runs
TIMES = {(1, 1): [0.70, 0.80, 0.60], (1, 2): [0.40, 0.45, 0.35], (2, 1): [0.50, 0.70, 0.45]}


@pytest.fixture
def measured(monkeypatch, tmp_path):
    order = []

    def fake_measure(deck, ckpt, p, t, out):
        out.mkdir()
        (out / "results.h5").write_text("")
        order.append((p, t))
        per_step = TIMES[(p, t)][sum(1 for c in order if c == (p, t)) - 1]
        return dict(ranks=p, threads=t, per_step=per_step, steps=20, substeps=200, lcps=0,
                    active=0, failed=0, domain=[])

    monkeypatch.setattr(bench_mpi, "settled_checkpoint", lambda *a: (tmp_path / "d", tmp_path / "c"))
    monkeypatch.setattr(bench_mpi, "_measure", fake_measure)
    monkeypatch.setattr(bench_mpi, "_same_results", lambda a, b: True)
    monkeypatch.setattr(bench_mpi.os, "cpu_count", lambda: 2)
    return order


def test_the_configurations_alternate_and_each_row_is_its_median(measured):
    rows = bench_mpi.strong(100, 0.1, 3, 2, Path("unused"), repeat=3)
    assert measured == [(1, 1), (1, 2), (2, 1), (2, 1), (1, 2), (1, 1), (1, 1), (1, 2), (2, 1)]
    by = {(r["ranks"], r["threads"]): r for r in rows}
    assert by[(1, 1)]["per_step"] == 0.70 and by[(2, 1)]["per_step"] == 0.50
    assert by[(2, 1)]["per_step_runs"] == TIMES[(2, 1)]
    assert by[(2, 1)]["speedup"] == pytest.approx(0.70 / 0.50)


def test_one_run_each_gives_that_run(measured):
    rows = bench_mpi.strong(100, 0.1, 3, 2, Path("unused"), repeat=1)
    assert [r["per_step"] for r in rows] == [0.70, 0.40, 0.50]
    assert all(len(r["per_step_runs"]) == 1 for r in rows)

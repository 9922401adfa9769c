"""Runs on several MPI ranks (nurbsdem.parallel) give the serial run's results bit for bit.

The deck (tests/data/mpi/pack.inp) has every kind of step: deposition of paper particles and
exact spheres in a box, replication, deposition again, a lid brought to contact, pressing and
lifting.  Each test compares a run on P ranks with the serial run: every sample of results.h5,
every monitor file and the checkpoint, exactly.  They need the ``mpi`` extra (mpi4py and the
mpich wheel, which brings ``mpiexec``); without it they skip and say so.
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from nurbsdem.contact.kinds import CLOSED_FORM, LCP, POINT_SURFACE, WALL_SUPPORT
from nurbsdem.io.checkpoint import load_checkpoint
from nurbsdem.io.results import read_results_sample, read_results_times
from nurbsdem.parallel import decompose
from nurbsdem.parallel.cut import BODY_COST, SOLVE_COST, ContactWork, imbalance, pair_solvers
from nurbsdem.parallel.domain import merge_by_key

HERE = Path(__file__).resolve().parent
DECK = HERE / "data" / "mpi" / "pack.inp"
RUN = HERE / "mpi_run.py"
BIN = Path(sys.executable).parent
MPIEXEC = BIN / "mpiexec"


def _mpi_missing() -> str | None:
    try:
        import mpi4py  # noqa: F401
    except ImportError:
        return "mpi4py is not installed (pip install 'nurbsdem[mpi]')"
    if not MPIEXEC.exists() and shutil.which("mpiexec") is None:
        return "no mpiexec (pip install 'nurbsdem[mpi]' brings MPICH's)"
    return None


needs_mpi = pytest.mark.skipif(_mpi_missing() is not None, reason=str(_mpi_missing()))


def _env() -> dict:
    env = dict(os.environ)
    for name in ("PMI_SIZE", "PMI_RANK", "OMPI_COMM_WORLD_SIZE", "PMIX_SIZE", "MPI_LOCALNRANKS"):
        env.pop(name, None)          # a serial run must not believe it runs under mpiexec
    return env


def _run(args: list, ranks: int = 1, check_output: bool = False) -> str:
    """Run ``args`` (a nurbsdem or Python command) serially or on ``ranks`` ranks; returns
    its output (stdout and stderr)."""
    mpiexec = str(MPIEXEC) if MPIEXEC.exists() else "mpiexec"
    cmd = ([mpiexec, "-n", str(ranks)] if ranks > 1 else []) + [str(a) for a in args]
    res = subprocess.run(cmd, cwd=DECK.parent, env=_env(), capture_output=True, text=True,
                         timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    return res.stdout + res.stderr


def _solve(out: Path, ranks: int = 1, *extra) -> str:
    return _run([BIN / "nurbsdem", "solve", DECK, "--output", out, *extra], ranks)


def _script(out: Path, ranks: int = 1, *extra) -> str:
    return _run([sys.executable, RUN, DECK, out, *extra], ranks)


def assert_same_run(out: Path, ref: Path) -> None:
    """Every sample of results.h5, every monitor file and the checkpoint equal bit for bit."""
    times = read_results_times(out / "results.h5")
    np.testing.assert_array_equal(times, read_results_times(ref / "results.h5"))
    for i in range(len(times)):
        a = read_results_sample(out / "results.h5", i)
        b = read_results_sample(ref / "results.h5", i)
        for key, value in a.items():
            if isinstance(value, np.ndarray):
                np.testing.assert_array_equal(value, b[key], err_msg=f"sample {i} {key}")
    names = sorted(p.name for p in (ref / "monitors").glob("*.csv"))
    assert names == sorted(p.name for p in (out / "monitors").glob("*.csv"))
    for name in names:
        assert (out / "monitors" / name).read_text() == (ref / "monitors" / name).read_text(), name
    _same_state(load_checkpoint(out / "checkpoint.h5"), load_checkpoint(ref / "checkpoint.h5"))


def _same_state(a, b, path: str = "") -> None:
    """Two checkpoint states hold the same values (dicts in any order; NaN equals NaN)."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and sorted(a, key=str) == sorted(b, key=str), path
        for k in a:
            _same_state(a[k], b[k], f"{path}/{k}")
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            _same_state(x, y, f"{path}/{i}")
    elif isinstance(a, (np.ndarray, np.generic)):
        np.testing.assert_array_equal(a, b, err_msg=path)
    else:
        assert a == b or (a != a and b != b), path


@pytest.fixture(scope="module")
def serial(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("serial") / "out"
    _solve(out, 1)
    return out


# ---------------------------------------------------------------------- the cut
def test_the_cut_gives_equal_counts_and_does_not_depend_on_the_rank():
    rng = np.random.default_rng(1)
    x = rng.uniform(0, 1, (1001, 3)) * [4.0, 1.0, 1.0]
    for parts in (1, 2, 3, 4, 7):
        owner = decompose(x, parts)
        counts = np.bincount(owner, minlength=parts)
        assert counts.max() - counts.min() <= 1 + parts // 2, (parts, counts)
        assert set(owner) == set(range(parts))
    owner = decompose(x, 2)                   # first cut across the longest extent (x)
    assert x[owner == 0, 0].max() <= x[owner == 1, 0].min()
    same = np.zeros((6, 3))                   # ties are broken by the particle index
    np.testing.assert_array_equal(decompose(same, 2), [0, 0, 0, 1, 1, 1])


def test_the_cut_by_work_gives_equal_weights():
    """Particles weighted by their contact work: each group's weight is within one particle's
    of the even share, and the uneven example's excess falls from ~50 % to a few per cent."""
    rng = np.random.default_rng(2)
    x = rng.uniform(0, 1, (2000, 3)) * [1.0, 1.0, 3.0]
    w = np.where(x[:, 2] < 1.5, 300, 100).astype(np.int64)      # the bottom half works more
    even = decompose(x, 2)
    assert imbalance(even, w, 2) > 0.45
    for parts in (2, 3, 4):
        owner = decompose(x, parts, w)
        loads = np.bincount(owner, weights=w, minlength=parts)
        assert np.all(np.abs(loads - w.sum() / parts) <= w.max()), (parts, loads)
        assert imbalance(owner, w, parts) < 0.01
    np.testing.assert_array_equal(decompose(x, 3, np.ones(2000, np.int64)), decompose(x, 3))
    heavy = np.ones(10, np.int64)                 # one group per particle at least
    heavy[0] = 10 ** 6
    assert set(decompose(np.arange(30.0).reshape(10, 3), 4, heavy)) == {0, 1, 2, 3}


def test_the_work_counts_name_each_pairs_solver():
    sphere = np.array([True, True, False, False])
    a, b = np.array([0, 0, 2, 2, 3]), np.array([1, 2, 3, 4, 5])       # 4, 5: flat walls
    np.testing.assert_array_equal(pair_solvers(sphere, a, b, 4, True),
                                  [CLOSED_FORM, POINT_SURFACE, LCP, WALL_SUPPORT, WALL_SUPPORT])
    assert pair_solvers(sphere, a, b, 4, False)[1] == LCP


def test_the_work_counts_each_solve_once_over_the_ranks_across_list_changes():
    """Two ranks count the solves of their lists' due pairs; a list replaced mid-way (a
    rebuild) folds the old list's counts first.  The ranks' work summed gives each solve of
    each pair once, at its solver's cost, to both its particles (a wall pair's twice to its
    particle), plus the particles' own work per evaluation."""
    class Scene:
        is_sphere = np.array([False, False, False, True])
        point_surface = True

    owner = np.array([0, 0, 1, 1])
    a1, b1 = np.array([0, 1, 2, 3]), np.array([1, 2, 4, 4])      # 4: a flat wall
    a2, b2 = np.array([0, 2]), np.array([2, 3])                  # after a rebuild
    total = np.zeros(4, np.int64)
    for rank in (0, 1):
        work = ContactWork(owner == rank, Scene())
        listed = [(a1, b1, np.array([0, 1, 2, 3]))] * 2 + [(a2, b2, np.array([0, 1]))]
        for a, b, due in listed:
            work.count(a, b, due)
        total += work.folded()
        assert work.evaluations == 3
    lcp, wall, sphere_wall, point = (SOLVE_COST[k] for k in (LCP, WALL_SUPPORT, CLOSED_FORM,
                                                             POINT_SURFACE))
    expected = np.zeros(4, np.int64)
    for a, b, cost, times in ((0, 1, lcp, 2), (1, 2, lcp, 2), (0, 2, lcp, 1), (2, 3, point, 1)):
        expected[[a, b]] += cost * times
    expected[2] += 2 * wall * 2
    expected[3] += 2 * sphere_wall * 2
    np.testing.assert_array_equal(total, expected)
    assert np.all(work.weights(total) == expected + 2 * BODY_COST * 3)


def test_rows_merged_by_key_come_in_the_serial_order():
    a = dict(key=np.array([4, 9, 1]), v=np.array([[4.0], [9.0], [1.0]]))
    b = dict(key=np.array([7, 2]), v=np.array([[7.0], [2.0]]))
    m = merge_by_key([a, b], "key")
    np.testing.assert_array_equal(m["key"], [1, 2, 4, 7, 9])
    np.testing.assert_array_equal(m["v"][:, 0], [1, 2, 4, 7, 9])


# ---------------------------------------------------------------------- runs
@needs_mpi
def test_two_ranks_give_the_serial_run_bit_for_bit(serial, tmp_path):
    """``mpiexec -n 2 nurbsdem solve``: the particles are cut between the ranks, contacts
    cross the cut (ghosts), and results.h5, the monitors and the checkpoint are the serial
    run's, exactly.  The first cut of each step splits the particles evenly; the pack's
    contact work is uneven, so the ranks cut it again by that work during the run (the
    particles and their pairs' histories migrate): still the serial bits."""
    log = _solve(tmp_path / "out", 2, "--verbose")
    ghosts = [line for line in log.splitlines() if "MPI ranks" in line]
    assert ghosts and "(cut 1): owned [6, 6]" in ghosts[0]
    cut = int(re.search(r"\(cut (\d+)\)", ghosts[-1]).group(1))
    owned = [int(k) for k in re.search(r"owned \[(\d+), (\d+)\]", ghosts[-1]).groups()]
    assert cut > 1 and sum(owned) == 24 and min(owned) > 0, ghosts[-1]
    assert "ghosts [0, 0]" not in ghosts[-1]            # pairs across the cut were solved
    assert_same_run(tmp_path / "out", serial)


@needs_mpi
@pytest.mark.slow      # the suite's time: two_ranks_give_the_serial_run covers 2 ranks by default
@pytest.mark.parametrize("ranks", [2, 3])
def test_hertz_mindlin_on_several_ranks(tmp_path, ranks):
    """Hertz–Mindlin laws (the exact curvature per contact, its fallback count in
    monitors/hertz.csv) on 2 and 3 ranks: the serial results."""
    text = DECK.read_text().replace("../../../inputs", str(HERE.parent / "inputs"))
    text = text.replace("Material 1 Density 2700",
                        "Material 1 Density 2700 YoungModulus 7e7 PoissonRatio 0.3")
    text = text.replace("Interface 1 NormalPenalty 1e5 TangentialPenalty 1e4 NormalDamping 1e2 "
                        "TangentialDamping 0 Friction 0.5",
                        "Interface 1 Model HertzMindlin Restitution 0.5 Friction 0.3")
    text = text.replace("Step 3 Dynamic Duration 0.15", "Step 3 Dynamic Duration 0.05")
    assert "HertzMindlin" in text
    deck = tmp_path / "hertz.inp"
    deck.write_text(text)
    _run([BIN / "nurbsdem", "solve", deck, "--output", tmp_path / "ref"])
    _run([BIN / "nurbsdem", "solve", deck, "--output", tmp_path / "out"], ranks)
    assert_same_run(tmp_path / "out", tmp_path / "ref")


@needs_mpi
@pytest.mark.slow      # as the Hertz–Mindlin run: the suite's default covers 2 ranks once
def test_rolling_friction_on_two_ranks(tmp_path):
    """Rolling friction (the rolling springs in the contacts' history rows, their torques in
    the loads of the walls and of ghosts) on 2 ranks: the serial results."""
    text = DECK.read_text().replace("../../../inputs", str(HERE.parent / "inputs"))
    text = text.replace("TangentialDamping 0 Friction 0.5",
                        "TangentialDamping 0 Friction 0.5 RollingFriction 0.1")
    text = text.replace("Step 3 Dynamic Duration 0.15", "Step 3 Dynamic Duration 0.05")
    assert "RollingFriction" in text
    deck = tmp_path / "rolling.inp"
    deck.write_text(text)
    _run([BIN / "nurbsdem", "solve", deck, "--output", tmp_path / "ref"])
    _run([BIN / "nurbsdem", "solve", deck, "--output", tmp_path / "out"], 2)
    assert_same_run(tmp_path / "out", tmp_path / "ref")


@pytest.fixture(scope="module")
def implicit_run(tmp_path_factory) -> tuple[Path, Path]:
    """The MPI deck with ``Damping Implicit`` in every dynamic step (``Accuracy`` in the first,
    as the paper deck), shortened, and its serial run: (deck, output folder)."""
    text = DECK.read_text().replace("../../../inputs", str(HERE.parent / "inputs"))
    text = text.replace("Step 1 Dynamic Duration 0.25 TimeStep 1e-3",
                        "Step 1 Dynamic Duration 0.12 TimeStep 1e-3 Damping Implicit "
                        "Accuracy 3e-5")
    text = text.replace("Step 3 Dynamic Duration 0.15 TimeStep 1e-3",
                        "Step 3 Dynamic Duration 0.05 TimeStep 1e-3 Damping Implicit")
    text = text.replace("Duration 0.04 TimeStep 1e-3", "Duration 0.02 TimeStep 1e-3 "
                        "Damping Implicit")
    assert text.count("Damping Implicit") == 4
    folder = tmp_path_factory.mktemp("implicit")
    deck = folder / "implicit.inp"
    deck.write_text(text)
    if _mpi_missing() is None:
        _run([BIN / "nurbsdem", "solve", deck, "--output", folder / "ref"])
    return deck, folder / "ref"


@needs_mpi
@pytest.mark.parametrize("ranks", [2, pytest.param(3, marks=pytest.mark.slow)])
def test_implicit_damping_with_accuracy_on_several_ranks(implicit_run, tmp_path, ranks):
    """``Damping Implicit`` with ``Accuracy`` on 2 and 3 ranks: the dashpots solved over the
    whole network (the ranks' contacts merged in key order, every particle's state from its
    owner) give the serial results bit for bit."""
    deck, ref = implicit_run
    _run([BIN / "nurbsdem", "solve", deck, "--output", tmp_path / "out"], ranks)
    assert_same_run(tmp_path / "out", ref)


@needs_mpi
@pytest.mark.slow      # 3 ranks on the 2 cores CI has: the 2-rank tests cover the default suite
def test_three_ranks_through_the_python_api(serial, tmp_path):
    """The Python API under mpiexec (Simulation -> Solver picks up the MPI world), on a
    number of ranks that is not a power of two."""
    _script(tmp_path / "out", 3, "--api")
    assert_same_run(tmp_path / "out", serial)


@needs_mpi
@pytest.mark.slow      # the suite's time: restarts on other rank counts run with -m slow
@pytest.mark.parametrize("before, after", [(2, 1), (1, 2)])
def test_a_checkpoint_written_on_p_ranks_restarts_on_q(serial, tmp_path, before, after):
    """Killed after the replication (a checkpoint at 0.3 s) on ``before`` ranks, restarted
    from its checkpoint on ``after`` ranks: the serial run's results."""
    out = tmp_path / "out"
    assert "killed" in _script(out, before, "--kill-after", "0.32")
    _solve(out, after, "--restart", out / "checkpoint.h5")
    assert_same_run(out, serial)


@needs_mpi
@pytest.mark.slow      # the suite's time: the serial guard is tested by default (test_deck_steps)
def test_deck_steps_rolled_back_by_the_guard_on_two_ranks(tmp_path):
    """With the time-step control misjudging the limit, the guard rolls deck steps back and
    repeats them on all ranks together: the same results as the serial run doing so."""
    ref, out = tmp_path / "ref", tmp_path / "out"
    assert "repeated with" in _script(ref, 1, "--misjudge", "20")
    assert "repeated with" in _script(out, 2, "--misjudge", "20")
    assert_same_run(out, ref)


@needs_mpi
def test_bad_input_on_two_ranks_is_one_line_and_a_nonzero_exit(tmp_path):
    """A deck error under mpiexec: the one-line message naming file and line, exit status 2,
    no traceback, no rank left waiting."""
    deck = tmp_path / "bad.inp"
    deck.write_text(DECK.read_text().replace("../../../inputs", str(HERE.parent / "inputs"))
                    .replace("Material 1 Density 2700", "Material 1 Density abc"))
    res = subprocess.run([str(MPIEXEC) if MPIEXEC.exists() else "mpiexec", "-n", "2",
                          str(BIN / "nurbsdem"), "solve", str(deck), "--output",
                          str(tmp_path / "out")], env=_env(), capture_output=True, text=True,
                         timeout=300)
    assert res.returncode != 0
    assert "bad.inp:7" in res.stderr and "abc" in res.stderr
    assert "Traceback" not in res.stderr

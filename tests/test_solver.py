"""The solver a user runs: CLI, outputs ParaView and scripts read, restart, the paper deck."""
from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import h5py
import meshio
import numpy as np
import pytest
from click.testing import CliRunner

import nurbsdem
from nurbsdem.cli import main
from nurbsdem.io.deck import parse_deck
from nurbsdem.io.paraview import read_pvd
from nurbsdem.solver import Solver
from runs import assert_same_final_state, killed_and_restarted

ROOT = Path(__file__).resolve().parents[1]
SHAPES = ROOT / "inputs" / "shapes"

LID_DECK = f"""
Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2700
Shapes
  Shape 1 File {SHAPES / 'C.yaml'}
  Shape 2 Sphere Radius 0.015
Particles
  Particle 1 Shape 1 Material 1 Position 0.030 0.030 0.019
  Particle 2 Shape 1 Material 1 Position 0.075 0.040 0.019 Rotation 0 0 0.5
  Particle 3 Shape 2 Material 1 Position 0.050 0.080 0.016 Velocity 0.1 0 0
Walls
  Box 1 Min 0 0 0 Max 0.11 0.11 0.10
  Wall 6 Name lid Point 0.055 0.055 0.10 Normal 0 0 -1 Size 0.11 0.11
Contact
  Interface 1 NormalPenalty 1e5 TangentialPenalty 1e4 NormalDamping 1e2 TangentialDamping 0 Friction 0.5
Steps
  Step 1 Dynamic Duration 0.06 TimeStep 1e-3
  Step 2 MoveWall lid ToContact Gap 0.001
  Step 3 MoveWall lid Displacement 0 0 -0.003 Duration 0.06 TimeStep 1e-3
  Step 4 MoveWall lid Displacement 0 0 0.003 Duration 0.04 TimeStep 1e-3
Output
  Directory results
  VTK Every 0.02 Resolution 4
  Monitors Every 0.002
  Checkpoint Every 0.03
"""


@pytest.fixture(scope="module")
def lid_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("lid")
    deck = d / "case.inp"
    deck.write_text(LID_DECK)
    out = d / "out"
    summary = Solver(parse_deck(deck), output=out, quiet=True).run()
    return deck, out, summary


def test_outputs_are_what_paraview_and_scripts_read(lid_run):
    deck, out, summary = lid_run
    for series in ("particles", "walls", "contacts"):
        entries = read_pvd(out / f"{series}.pvd")
        assert len(entries) == 9          # t = 0, 0.02, ..., 0.16
        mesh = meshio.read(out / entries[-1][1])
        if series == "particles":
            for name in ("particle_id", "shape_id", "velocity", "angular_velocity"):
                assert name in mesh.point_data
            assert set(np.unique(mesh.point_data["particle_id"])) == {1, 2, 3}
        if series == "contacts":
            for name in ("force_normal", "force_tangential", "penetration", "degenerated"):
                assert name in mesh.point_data
    with open(out / "monitors" / "energy.csv") as fh:
        assert fh.readline().strip() == ("time,kinetic,potential,elastic,dissipated,"
                                         "external_work,mechanical,balance_error")
    with open(out / "monitors" / "contacts.csv") as fh:
        assert fh.readline().strip() == "time,monitored,active,degenerated,failed"
    with open(out / "monitors" / "wall_lid.csv") as fh:
        assert fh.readline().strip() == ("time,displacement_x,displacement_y,displacement_z,"
                                         "reaction_x,reaction_y,reaction_z,"
                                         "torque_x,torque_y,torque_z,work,power")
    with h5py.File(out / "results.h5") as h5:
        assert h5.attrs["nurbsdem_version"] == nurbsdem.__version__
        assert "Step 3 MoveWall lid" in h5.attrs["deck"]
    assert summary.failed == 0 and summary.steps == 160


def test_restart_reaches_the_same_final_state(lid_run, tmp_path, monkeypatch):
    deck, ref_out, _ = lid_run
    out = tmp_path / "out"
    killed_and_restarted(deck, out, 0.100, monkeypatch)   # mid step 3 (the lid moving)
    assert_same_final_state(out, ref_out, ("energy.csv", "contacts.csv", "wall_lid.csv"))


def test_check_prints_a_summary():
    r = CliRunner().invoke(main, ["check", str(ROOT / "inputs" / "paper" / "compaction.inp")])
    assert r.exit_code == 0, r.output
    assert "OK" in r.output


@pytest.mark.parametrize("line, message", [
    ("  Gravity 0 0", "Gravity"),
    ("  Frobnicate 3", "Frobnicate"),
])
def test_bad_deck_is_one_line_error_without_traceback(tmp_path, line, message):
    deck = tmp_path / "bad.inp"
    text = LID_DECK.replace("  Gravity 0 0 -9.81", line)
    deck.write_text(text)
    res = subprocess.run([sys.executable, "-m", "nurbsdem.cli", "solve", str(deck), "--quiet"],
                         capture_output=True, text=True)
    assert res.returncode == 2
    err = res.stderr.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in res.stderr
    assert err[0].startswith(f"nurbsdem: error: {deck}:3:") and message in err[0]


def test_restart_from_a_missing_file_is_a_clean_error(tmp_path):
    deck = tmp_path / "case.inp"
    deck.write_text(LID_DECK)
    r = CliRunner().invoke(main, ["solve", str(deck), "--restart", str(tmp_path / "nope.h5")])
    assert r.exit_code == 2
    assert "no such checkpoint" in r.output


def test_short_paper_example_runs_all_steps(tmp_path):
    """A shortened version of inputs/paper/compaction.inp (every step kind, 112 particles)."""
    text = (ROOT / "inputs" / "paper" / "compaction.inp").read_text()
    text = text.replace("../shapes/", str(SHAPES) + "/")
    text = text.replace("Step 1 Dynamic Duration 2.0", "Step 1 Dynamic Duration 0.25")
    text = text.replace("Step 3 Dynamic Duration 2.5", "Step 3 Dynamic Duration 0.05")
    text = text.replace("Duration 1.0", "Duration 0.02")
    text = text.replace("VTK Every 0.01", "VTK Every 0.05")
    deck = tmp_path / "paper_short.inp"
    deck.write_text(text)
    out = tmp_path / "out"
    summary = Solver(parse_deck(deck), output=out, quiet=True).run()
    assert summary.particles == 112
    assert summary.failed == 0
    with open(out / "monitors" / "wall_lid.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert float(rows[-1]["displacement_z"]) < -0.03      # the lid came down to the pack


def _misjudged_step(monkeypatch, factor: int, refinements: int) -> None:
    """Make the time-step control choose ``factor`` times too few sub-steps (an estimate that
    misjudges the stability limit), with ``refinements`` repetitions allowed to the guard."""
    from nurbsdem.dynamics.system import DemSystem

    original = DemSystem._needed_substeps

    def too_few(self, dt_safe):
        self.max_refinements = refinements
        return max(1, original(self, dt_safe) // factor)
    monkeypatch.setattr(DemSystem, "_needed_substeps", too_few)


def test_instability_stops_with_a_message_and_the_last_good_state_saved(tmp_path, monkeypatch):
    """Forced to one sub-step at the paper's Δt = 1e-3 s, the small particles' damped contacts
    are unstable (C–C: Δt_cr = 4.7e-4 s): without refinement the run must stop cleanly, not
    explode silently."""
    from nurbsdem.errors import NurbsdemError
    from nurbsdem.io.checkpoint import load_checkpoint

    _misjudged_step(monkeypatch, factor=100, refinements=0)
    deck = tmp_path / "unstable.inp"
    deck.write_text(LID_DECK.replace("Step 1 Dynamic Duration 0.06", "Step 1 Dynamic Duration 0.5"))
    with pytest.raises(NurbsdemError) as info:
        Solver(parse_deck(deck), output=tmp_path / "out", quiet=True).run()
    msg = str(info.value)
    assert "integration unstable" in msg and "\n" not in msg
    st = load_checkpoint(tmp_path / "out" / "checkpoint.h5")
    assert 0.0 <= st["time"] < 0.5
    assert np.all(np.isfinite(st["bodies"]["position"]))


def test_an_unstable_deck_step_is_repeated_with_more_substeps(tmp_path, monkeypatch, caplog):
    """The same run with the guard allowed to refine: each deck step found unstable at one
    sub-step is repeated with more, the run completes, and the log says so."""
    import logging

    _misjudged_step(monkeypatch, factor=100, refinements=3)
    deck = tmp_path / "unstable.inp"
    deck.write_text(LID_DECK.replace("Step 1 Dynamic Duration 0.06", "Step 1 Dynamic Duration 0.5"))
    with caplog.at_level(logging.WARNING, logger="nurbsdem"):
        summary = Solver(parse_deck(deck), output=tmp_path / "out", quiet=True).run()
    assert summary.simulated_time == pytest.approx(0.5 + 0.06 + 0.04)
    assert any("repeated with" in r.getMessage() for r in caplog.records)


@pytest.mark.parametrize("old, new, line, message", [
    ("Step 3 MoveWall lid Displacement", "Step 3 MoveWall roof Displacement", 21, "roof"),
    ("  Material 1 Density 2700", "  Material 1 Density abc", 5, "abc"),
    ("Position 0.075 0.040 0.019", "Position 0.035 0.030 0.019", 11, "overlaps"),
    ("Shape 2 Sphere Radius 0.015", "Shape 2 File missing.yaml", 8, "missing.yaml"),
])
def test_check_reports_mistakes_as_one_line_with_exit_code_2(tmp_path, old, new, line, message):
    deck = tmp_path / "case.inp"
    assert old in LID_DECK
    deck.write_text(LID_DECK.replace(old, new))
    r = CliRunner().invoke(main, ["check", str(deck)])
    assert r.exit_code == 2
    out = r.output.strip().splitlines()
    assert len(out) == 1 and "Traceback" not in r.output
    assert out[0].startswith(f"nurbsdem: error: {deck}:{line}:") and message in out[0]


def test_background_output_writes_the_same_files(lid_run, tmp_path):
    """ParaView files written from the worker thread equal, byte for byte, those written in
    the time loop's thread (and the .pvd lists them in the same order)."""
    deck, ref_out, _ = lid_run
    out = tmp_path / "fg"
    Solver(parse_deck(deck), output=out, quiet=True, background_output=False).run()
    names = sorted(p.relative_to(out) for p in out.rglob("*.vt*")) + [Path(f"{s}.pvd") for s in
                                                                     ("particles", "walls", "contacts")]
    assert len(names) > 10
    for rel in names:
        assert (out / rel).read_bytes() == (ref_out / rel).read_bytes(), rel


def test_background_write_errors_reach_the_caller():
    from nurbsdem.io.background import BackgroundWriter
    done = []
    w = BackgroundWriter(depth=2)

    def fail():
        raise OSError(28, "No space left on device")
    w.submit(done.append, 1)
    w.submit(fail)
    with pytest.raises(OSError, match="No space"):
        w.wait()
    w.submit(done.append, 2)
    w.submit(fail)
    w.abandon()                       # an aborting run: queued writes end, errors ignored
    assert done == [1]                # no write after a failed one (a hole in the files)


def test_held_writes_run_as_one_job_in_order():
    """Writes submitted inside ``held()`` reach the worker as one job when the block ends
    (none before), run in their order; an error among them reaches the caller."""
    import threading

    from nurbsdem.io.background import BackgroundWriter
    done = []
    gate = threading.Event()
    w = BackgroundWriter()
    with w.held():
        w.submit(done.append, 1)
        with w.held():                 # nested: the outer block holds them all
            w.submit(done.append, 2)
        w.submit(done.append, 3)
        assert done == [] and w._pending == []
    assert len(w._pending) == 1
    w.wait()
    assert done == [1, 2, 3]

    def fail():
        gate.wait()
        raise OSError(28, "No space left on device")
    with w.held():
        w.submit(fail)
        w.submit(done.append, 4)
    gate.set()
    with pytest.raises(OSError, match="No space"):
        w.wait()
    w.close()


def test_steps_to_the_next_output_equal_a_scan():
    """The compiled loop stops exactly where a step-by-step run would write output: the
    closed-form search of the next due step equals a scan with the same test."""
    from nurbsdem.io.intervals import due, steps_to_due
    rng = np.random.default_rng(5)
    for _ in range(2000):
        dt = float(rng.choice([1e-3, 1e-4, 2.5e-4, 3e-4, 1e-3 / 3]))
        every = float(rng.choice([1e-3, 2e-3, 0.01, 0.0015, 0.05, 0.007, 1000.0]))
        t0 = float(rng.choice([0.0, 0.25, 1.0 / 3]))
        count = int(rng.integers(0, 5000))
        n_max = int(rng.integers(1, 300))
        scan = next((k for k in range(1, n_max + 1) if due(t0 + (count + k) * dt, every, dt)),
                    n_max)
        assert steps_to_due(t0, count, dt, every, n_max) == scan, (dt, every, t0, count, n_max)

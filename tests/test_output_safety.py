"""Nothing already written is lost: a new run keeps the previous results until it
has a complete sample of its own, a full disk or a file-size limit ends in one clean line
with the last good checkpoint intact, and temporaries of killed writers are removed on the
next start."""
from __future__ import annotations

import errno
import os
import resource
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from nurbsdem.io import atomic
from nurbsdem.io.checkpoint import load_checkpoint, save_checkpoint
from nurbsdem.io.deck import parse_deck
from nurbsdem.io.writers import PREVIOUS_DIR, OutputWriters

DECK = """Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2700
Shapes
  Shape 1 Sphere Radius 0.02
Particles
  Particle 1 Shape 1 Material 1 Position 0.05 0.10 0.05
  Particle 2 Shape 1 Material 1 Position 0.15 0.10 0.05
Walls
  Box 1 Min 0 0 0 Max 0.25 0.25 0.25
Contact
  Interface 1 NormalPenalty 1e5 NormalDamping 10
Steps
  Step 1 Dynamic Duration 0.02 TimeStep 1e-3
Output
  Directory out
  VTK Every 0.01 Resolution 2
  Checkpoint Every 0.01
"""


@pytest.fixture()
def model(tmp_path):
    deck = tmp_path / "case.inp"
    deck.write_text(DECK)
    return parse_deck(deck)


def _previous_run(outdir: Path) -> dict[str, bytes]:
    """A fake previous run's files; returns their contents by relative path."""
    files = {"particles.pvd": b"<old pvd/>", "vtk/particles_000000.vtu": b"old frame 0",
             "vtk/particles_000001.vtu": b"old frame 1", "monitors/energy.csv": b"time\n0.0\n",
             "results.h5": b"old results", "checkpoint.h5": b"old checkpoint"}
    for rel, data in files.items():
        (outdir / rel).parent.mkdir(parents=True, exist_ok=True)
        (outdir / rel).write_bytes(data)
    return files


def _contents(outdir: Path, files: dict[str, bytes]) -> dict[str, bytes | None]:
    return {rel: ((outdir / rel).read_bytes() if (outdir / rel).exists() else None)
            for rel in files}


def test_failed_fresh_run_keeps_the_previous_results(model):
    out = Path(model.output.directory)
    old = _previous_run(out)
    w = OutputWriters(model)
    assert _contents(out, old)["vtk/particles_000001.vtu"] is None   # set aside, not deleted
    w.abort()                                                          # failed before a sample
    assert _contents(out, old) == old
    assert not (out / PREVIOUS_DIR).exists()


def test_previous_results_go_after_the_first_complete_sample(model):
    out = Path(model.output.directory)
    _previous_run(out)
    w = OutputWriters(model)
    assert (out / PREVIOUS_DIR).is_dir()
    w.paraview.write(0.0, model.bodies)
    w.monitors.energy(0.0, 0, 0, 0, 0, 0)
    w.results.append(0.0, model.bodies)
    assert not (out / PREVIOUS_DIR).exists() and w.committed
    w.close()
    assert not (out / "vtk/particles_000001.vtu").exists()
    assert (out / "vtk/particles_000000.vtu").read_bytes() != b"old frame 0"


def test_killed_fresh_run_is_undone_on_the_next_start(model):
    """A run killed before its first sample (no abort) leaves .previous-run and temporaries;
    the next start puts the previous results back and removes the temporaries."""
    out = Path(model.output.directory)
    old = _previous_run(out)
    OutputWriters(model)                         # ... and then SIGKILL: nothing more happens
    (out / ".results.h5.abc123.tmp").write_bytes(b"half")
    (out / "vtk" / ".particles_000000.vtu.x.tmp").write_bytes(b"half")
    from nurbsdem.io.writers import clean_output_directory
    clean_output_directory(out)
    assert _contents(out, old) == old
    assert not list(out.rglob("*.tmp"))


def test_restart_removes_stale_temporaries(model, tmp_path):
    out = Path(model.output.directory)
    OutputWriters(model).close()
    for rel in (".checkpoint.h5.k1.tmp", "vtk/.walls_000003.vtu.k2.tmp",
                "monitors/.energy.csv.k3.tmp"):
        (out / rel).write_bytes(b"left by SIGKILL")
    OutputWriters(model, restart_time=0.0).close()
    assert not list(out.rglob("*.tmp"))


def test_full_disk_keeps_the_last_good_checkpoint(tmp_path, monkeypatch):
    ck = tmp_path / "checkpoint.h5"
    save_checkpoint(ck, {"time": 1.0, "x": np.arange(10.0)})
    good = ck.read_bytes()

    class Full:
        free = 1000
    monkeypatch.setattr(atomic.shutil, "disk_usage", lambda p: Full)
    with pytest.raises(OSError) as info:
        save_checkpoint(ck, {"time": 2.0, "x": np.arange(10.0)})
    assert info.value.errno == errno.ENOSPC and str(tmp_path) in str(info.value)
    assert ck.read_bytes() == good and load_checkpoint(ck)["time"] == 1.0
    assert not list(tmp_path.glob(".*.tmp"))


def test_write_error_names_the_target_not_the_temporary(tmp_path, monkeypatch):
    target = tmp_path / "results.h5"

    def fail(self, data):
        raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr(Path, "write_bytes", fail)
    with pytest.raises(OSError) as info:
        atomic.atomic_write_bytes(target, b"x" * 10)
    assert info.value.filename == str(target) and "No space left" in str(info.value)
    assert not list(tmp_path.glob(".*.tmp"))


def _limit_file_size(nbytes: int):
    def pre() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (nbytes, nbytes))
    return pre


@pytest.mark.skipif(sys.platform != "linux", reason="RLIMIT_FSIZE semantics")
def test_solve_under_a_file_size_limit_ends_cleanly(tmp_path):
    """A write limit (like a full disk) hits the HDF5 results file: one line, exit 2, no
    crash in HDF5, the previous run's results and checkpoint intact, no temporaries."""
    deck = tmp_path / "case.inp"
    deck.write_text(DECK)
    exe = [sys.executable, "-m", "nurbsdem", "solve", str(deck), "--quiet"]
    env = dict(os.environ, NUMBA_CACHE_DIR=os.environ.get("NUMBA_CACHE_DIR", ""))
    env = {k: v for k, v in env.items() if v}
    first = subprocess.run(exe, capture_output=True, text=True, env=env, timeout=300)
    assert first.returncode == 0, first.stderr
    out = tmp_path / "out"
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    r = subprocess.run(exe, capture_output=True, text=True, env=env, timeout=300,
                       preexec_fn=_limit_file_size(100_000))
    assert r.returncode == 2, (r.returncode, r.stderr[-2000:])
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("nurbsdem: error: ") and "results.h5" in lines[0]
    after = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert after == before


def test_restart_after_a_killed_fresh_run_finds_the_previous_checkpoint(model, tmp_path):
    """A fresh run killed before its first sample had set the checkpoint aside; --restart
    from it puts the previous run back first."""
    from click.testing import CliRunner

    from nurbsdem.cli import main
    out = Path(model.output.directory)
    deck = Path(model.path)
    assert CliRunner().invoke(main, ["solve", str(deck), "--quiet"]).exit_code == 0
    good = (out / "checkpoint.h5").read_bytes()
    OutputWriters(model)                         # a fresh run, killed at once
    assert not (out / "checkpoint.h5").exists()
    r = CliRunner().invoke(main, ["solve", str(deck), "--quiet", "--restart",
                                  str(out / "checkpoint.h5")])
    assert r.exit_code == 0, r.output
    assert not (out / PREVIOUS_DIR).exists()
    assert load_checkpoint(out / "checkpoint.h5")["time"] == load_checkpoint_bytes(good, tmp_path)


def load_checkpoint_bytes(data: bytes, folder: Path) -> float:
    f = folder / "copy.h5"
    f.write_bytes(data)
    return load_checkpoint(f)["time"]


@pytest.mark.parametrize("victim,fragment", [
    ("particles.pvd", "not a readable ParaView collection"),
    ("results.h5", "cannot continue the results file: it is corrupted"),
])
def test_restart_with_a_corrupted_result_file_is_one_line(model, victim, fragment):
    from nurbsdem.errors import InputError
    out = Path(model.output.directory)
    w = OutputWriters(model)
    w.paraview.write(0.0, model.bodies)
    w.results.append(0.0, model.bodies)
    w.close()
    (out / victim).write_bytes(b"\xff\xfe garbage")
    with pytest.raises(InputError) as info:
        OutputWriters(model, restart_time=0.0)
    assert fragment in str(info.value) and str(info.value).startswith(str(out / victim))


def test_restart_with_a_binary_monitor_file(model):
    out = Path(model.output.directory)
    OutputWriters(model).close()
    (out / "monitors" / "energy.csv").write_bytes(b"\xff\xfe\x00garbage")
    OutputWriters(model, restart_time=0.0).close()
    assert (out / "monitors" / "energy.csv").read_text().startswith("time,")


def test_checkpoints_are_saved_by_the_worker_after_what_they_refer_to(model, monkeypatch):
    """The checkpoint is a job of the output worker (the time loop goes on meanwhile); when
    it is saved, results.h5, the monitors and the .pvd on disk already hold the samples up to
    its time (a restart from it finds them), and the state it saves is the one of its time."""
    import csv
    import threading

    import nurbsdem.run_checkpoint as checkpoint_module
    from nurbsdem.io.paraview import read_pvd
    from nurbsdem.io.results import read_results_times
    from nurbsdem.solver import Solver

    seen = []
    original = checkpoint_module.save_checkpoint

    def checked(path, state):
        t = float(state["time"])
        out = Path(path).parent
        with open(out / "monitors" / "energy.csv") as fh:
            rows = [float(r["time"]) for r in csv.DictReader(fh)]
        listed = max(t for t, _ in read_pvd(out / "particles.pvd"))
        seen.append((threading.current_thread().name, t, min(max(rows), listed),
                     read_results_times(out / "results.h5").max()))
        original(path, state)
    monkeypatch.setattr(checkpoint_module, "save_checkpoint", checked)
    Solver(model, quiet=True).run()
    assert len(seen) >= 2
    for thread, t, monitored, stored in seen[1:]:      # the first one commits the run
        assert thread.startswith("nurbsdem-output")
        assert monitored >= t - 1e-12 and stored >= t - 1e-12
    assert load_checkpoint(Path(model.output.directory) / "checkpoint.h5")["time"] == seen[-1][1]

"""Nothing lost on the output side: a full disk never leaves the checkpoint ahead
of the results, a restart refuses a folder cut short before its checkpoint, wall names stay
inside the output folder and read back from the deck, output intervals that are not whole
numbers of time steps are kept (not thinned), a Replicate first step keeps the energy ledger
closed, one run per output folder, Ctrl-C stops at a checkpoint with exit status 130, and a
closed stdout pipe ends quietly."""
from __future__ import annotations

import _thread
import csv
import math
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import example, given, settings
from hypothesis import strategies as st

from nurbsdem.cli import main
from nurbsdem.errors import InputError
from nurbsdem.io import intervals
from nurbsdem.io.checkpoint import load_checkpoint
from nurbsdem.io.deck import build_model, parse_deck
from nurbsdem.io.background import BackgroundWriter
from nurbsdem.io.monitors import MonitorWriter
from nurbsdem.io.paraview import read_pvd
from nurbsdem.io.results import read_results_times

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
  Step 1 Dynamic Duration {duration} TimeStep 1e-3
Output
  Directory out
  {output}
"""


def _deck(tmp_path: Path, duration: float = 0.02,
          output: str = "VTK Every 0.01 Resolution 2\n  Checkpoint Every 0.01",
          name: str = "case.inp") -> Path:
    deck = tmp_path / name
    deck.write_text(DECK.format(duration=duration, output=output))
    return deck


def _csv_times(path: Path) -> list[float]:
    with open(path) as fh:
        return [float(r["time"]) for r in csv.DictReader(fh)]


def _solve(*args: str):
    return CliRunner().invoke(main, ["solve", *args, "--quiet"])


# ---------------------------------------------------------------- output intervals


@settings(max_examples=300, deadline=None)
@given(dt=st.floats(1e-5, 1e-2), ratio=st.floats(0.05, 40.0), n=st.integers(1, 400),
       start=st.integers(0, 10 ** 6))
def test_every_output_time_gets_one_sample_within_a_time_step(dt, ratio, n, start):
    """The rounding of an output interval to the step grid: each asked time k·every in the
    span of n deck steps (starting at step ``start`` of a grid t0 = 0) is served by the one
    step end in [k·every, k·every + dt), and there are no other samples: none skipped, no
    drift, no thinning."""
    every = ratio * dt
    times = (start + np.arange(1, n + 1)) * dt
    due = intervals.due_mask(times, every, dt)
    t_first, t_last = start * dt, times[-1]
    k = np.arange(math.floor(t_first / every) - 1, math.floor(t_last / every) + 2)
    asked = k[k >= 1] * every
    asked = asked[(asked > t_first + 1e-7 * dt) & (asked < t_last - 1e-7 * dt)]
    served = set()
    for T in asked:
        j = np.flatnonzero((times >= T - 1e-9 * max(every, T)) &
                           (times < T + dt - 1e-9 * max(every, T)))
        assert len(j) == 1 and due[j[0]], (T, times[j], every, dt)
        served.add(int(j[0]))
    # every sample serves an asked time (up to the round-off at the span's ends)
    extra = set(np.flatnonzero(due).tolist()) - served
    for j in extra:
        near = abs(times[j] - np.round(times[j] / every) * every) <= 1e-7 * dt + 1e-9 * times[j]
        assert near or j in (0, n - 1), (times[j], every, dt)
    # the search of the next due step agrees with the mask
    if n > 1:
        first = intervals.steps_to_due(0.0, start, dt, every, n)
        hits = np.flatnonzero(due)
        assert first == (int(hits[0]) + 1 if hits.size else n)


def test_output_intervals_off_the_step_grid_are_kept(tmp_path):
    """TimeStep 1e-3: VTK Every 0.0025 wrote every 0.005 s and Every 0.0033 only t = 0; now
    each multiple is served by the first time step at or after it."""
    deck = _deck(tmp_path, output="VTK Every 0.0025 Resolution 2\n  Monitors Every 0.0015\n"
                                   "  Results Every 0.0033\n  Checkpoint Every 0.0075")
    r = _solve(str(deck))
    assert r.exit_code == 0, r.output
    out = tmp_path / "out"
    vtk = [t for t, _ in read_pvd(out / "particles.pvd")]
    np.testing.assert_allclose(vtk, [0, .003, .005, .008, .01, .013, .015, .018, .02], atol=1e-12)
    mon = _csv_times(out / "monitors" / "energy.csv")
    np.testing.assert_allclose(mon, [0, .002, .003, .005, .006, .008, .009, .011, .012, .014,
                                     .015, .017, .018, .02], atol=1e-12)
    res = read_results_times(out / "results.h5")
    np.testing.assert_allclose(res, [0, .004, .007, .01, .014, .017, .02], atol=1e-12)


def test_check_prints_the_effective_intervals(tmp_path):
    deck = _deck(tmp_path, output="VTK Every 0.0025 Resolution 2\n  Monitors Every 0.002")
    r = CliRunner().invoke(main, ["check", str(deck)])
    assert r.exit_code == 0, r.output
    line = next(ln for ln in r.output.splitlines() if ln.startswith("output with TimeStep"))
    assert "VTK 0.0025 s on average (0.002 or 0.003 s apart)" in line
    assert "monitors every 0.002 s" in line
    assert "first time step at or after each of its multiples" in r.output


# ---------------------------------------------------------------- full disk


class _Tmpfs:
    """A small tmpfs (root only), unmounted at the end."""

    def __init__(self, where: Path, size: str) -> None:
        self.where = where
        where.mkdir()
        r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)],
                           capture_output=True, text=True)
        if r.returncode != 0:
            pytest.skip(f"cannot mount a tmpfs here ({r.stderr.strip()})")

    def grow(self, size: str) -> None:
        subprocess.run(["mount", "-o", f"remount,size={size}", str(self.where)], check=True)

    def close(self) -> None:
        subprocess.run(["umount", "-l", str(self.where)], check=False)   # lazy: open files


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0,
                    reason="mounting a small tmpfs to fill needs root")
def test_full_disk_never_leaves_the_checkpoint_ahead_of_the_results(tmp_path):
    """A disk that fills during a run (a tmpfs of 8 MB; the results file's rewrite needs
    more room than the checkpoint's, so the results write fails first): the checkpoint on
    disk refers only to samples on disk, and after room is made a restart continues without
    a hole."""
    from nurbsdem.solver import Solver
    deck = _deck(tmp_path, duration=0.3,
                 output="VTK Every 0.001 Resolution 8\n  Results Every 0.001\n"
                        "  Checkpoint Every 0.005")
    disk = _Tmpfs(tmp_path / "disk", "8m")
    try:
        out = disk.where / "out"
        with pytest.raises(OSError) as info:
            Solver(parse_deck(deck), output=out, quiet=True).run()
        assert "no space left" in str(info.value).lower()
        t_ck = load_checkpoint(out / "checkpoint.h5")["time"]
        assert 0 < t_ck < 0.3
        tol = 1e-12
        assert read_results_times(out / "results.h5").max() >= t_ck - tol
        assert max(_csv_times(out / "monitors" / "energy.csv")) >= t_ck - tol
        assert max(t for t, _ in read_pvd(out / "particles.pvd")) >= t_ck - tol
        disk.grow("256m")
        r = _solve(str(deck), "--output", str(out), "--restart", str(out / "checkpoint.h5"))
        assert r.exit_code == 0, r.output
        t = read_results_times(out / "results.h5")
        np.testing.assert_allclose(t, np.arange(301) * 1e-3, atol=1e-9)
        np.testing.assert_allclose(_csv_times(out / "monitors" / "energy.csv"),
                                   np.arange(301) * 1e-3, atol=1e-9)
    finally:
        disk.close()


def test_no_write_after_a_failed_one_in_the_output_worker():
    """The output worker runs no job after a failed one (a checkpoint queued behind a failed
    results write would claim samples that are not on disk); each later job reports the
    first error."""
    w = BackgroundWriter()
    ran = []
    gate = threading.Event()

    def fail():
        gate.wait(10)                   # the checkpoint is queued before the write fails
        raise OSError(28, "No space left on device")
    w.submit(fail)
    w.submit(ran.append, "checkpoint")
    gate.set()
    with pytest.raises(OSError, match="No space"):
        w.wait()
    w.abandon()
    assert ran == []


# ---------------------------------------------------------------- restart checks


@pytest.fixture()
def finished_run(tmp_path):
    deck = _deck(tmp_path, duration=0.05,
                 output="VTK Every 0.01 Resolution 2\n  Checkpoint Every 0.01")
    r = _solve(str(deck))
    assert r.exit_code == 0, r.output
    return deck, tmp_path / "out"


def _cut_csv(path: Path, t_end: float) -> None:
    lines = path.read_text().splitlines(keepends=True)
    kept = [lines[0]] + [ln for ln in lines[1:] if float(ln.split(",")[0]) <= t_end + 1e-12]
    path.write_text("".join(kept))


@pytest.mark.parametrize("victim", ["monitors/energy.csv", "monitors/wall_bottom.csv",
                                    "results.h5"])
def test_restart_refuses_a_folder_cut_short_before_its_checkpoint(finished_run, victim):
    deck, out = finished_run
    path = out / victim
    if victim.endswith(".csv"):
        _cut_csv(path, 0.015)
    else:
        import h5py
        with h5py.File(path, "r+") as f:
            f["time"].resize((2,))           # samples at 0 and 0.01 s left
            f["count"].resize((2,))
            f["offset"].resize((3,))
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    r = _solve(str(deck), "--restart", str(out / "checkpoint.h5"))
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and str(path) in lines[0], r.output
    assert "t = 0.05 s" in lines[0] and ("ends at t = 0.01" in lines[0])
    after = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert after == before                         # refused before anything was touched


def test_restart_of_a_complete_folder_goes_on(finished_run):
    deck, out = finished_run
    r = _solve(str(deck), "--restart", str(out / "checkpoint.h5"))
    assert r.exit_code == 0, r.output


# ---------------------------------------------------------------- wall names

BAD_NAMES = ["../../../../precious", "a/b", ".hidden", "lid#1", 'li"d', "Duration", "movewall",
             "", "two words", "x" * 201]


@pytest.mark.parametrize("name", BAD_NAMES)
def test_bad_wall_names_are_refused_by_deck_and_api_alike(tmp_path, name):
    from nurbsdem import Simulation
    with pytest.raises(InputError) as api:
        Simulation().add_wall(name, [0, 0, 0], [0, 0, 1], [1, 1])
    word = name if '"' in name else f'"{name}"'     # quoted: as the deck reads it back
    text = DECK.format(duration=0.02, output="").replace(
        "  Box 1 Min 0 0 0 Max 0.25 0.25 0.25",
        f"  Wall 7 Name {word} Point 0 0 0 Normal 0 0 1 Size 1 1")
    deck = tmp_path / "case.inp"
    deck.write_text(text)
    with pytest.raises(InputError) as dk:
        parse_deck(deck)
    assert str(dk.value).startswith(f"{deck}:11:"), str(dk.value)
    if name not in ("", 'li"d', "two words"):      # the deck's word is the name itself
        assert str(api.value).split(": ", 1)[1] in str(dk.value)
    assert not (tmp_path.parent / "precious.csv").exists()


def test_the_writer_keeps_wall_files_inside_the_output_folder(tmp_path):
    out = tmp_path / "a" / "out"
    out.mkdir(parents=True)
    with pytest.raises(InputError, match="inside the output folder"):
        MonitorWriter(out, ["../../../precious"])
    assert not list(tmp_path.rglob("*precious*"))


@settings(max_examples=60, deadline=None)
@given(names=st.lists(st.from_regex(r"[A-Za-z0-9_-][A-Za-z0-9_.-]{0,12}", fullmatch=True),
                      min_size=1, max_size=3, unique_by=str.lower))
@example(names=["lid", "Duration", "step", "x.y-z_1"])
def test_api_wall_names_round_trip_through_deck_text(names):
    """Every name add_wall takes comes back from Simulation.deck_text (what results.h5 and
    the checkpoint store) as the same wall."""
    from nurbsdem import Simulation
    from nurbsdem.io.deck import SCHEMA
    from nurbsdem.io.wallname import wall_name_problem
    sim = Simulation()
    taken = []
    for k, name in enumerate(names):
        if wall_name_problem(name, SCHEMA) is not None:
            with pytest.raises(InputError, match="bad wall name"):
                sim.add_wall(name, [0, 0, k], [0, 0, 1], [1, 1])
            continue
        sim.add_wall(name, [0, 0, k], [0, 0, 1], [1, 1])
        taken.append(name)
    model = build_model(sim.deck_text, "deck_text.inp")
    assert model.wall_names == taken


# ---------------------------------------------------------------- energy ledger


def test_replicate_first_keeps_the_energy_balance(tmp_path):
    """A Replicate step before any dynamic step: the copies are the initial state, booked
    once (the balance error was the copies' whole energy, 100 % of the energy turned over)."""
    text = DECK.format(duration=0.01, output="VTK Every 0.01 Resolution 2").replace(
        "  Step 1 Dynamic Duration 0.01 TimeStep 1e-3",
        "  Step 1 Replicate Layers 2 Height 0.06\n  Step 2 Dynamic Duration 0.01 TimeStep 1e-3")
    deck = tmp_path / "case.inp"
    deck.write_text(text)
    r = _solve(str(deck))
    assert r.exit_code == 0, r.output
    with open(tmp_path / "out" / "monitors" / "energy.csv") as fh:
        rows = list(csv.DictReader(fh))
    last = {k: float(v) for k, v in rows[-1].items()}
    scale = abs(last["mechanical"])
    assert scale > 0.1                           # four spheres 2-8 cm up: ~0.18 J
    assert abs(last["balance_error"]) < 1e-9 * scale, last


# ---------------------------------------------------------------- one run per folder


def _hold_lock(folder: Path) -> subprocess.Popen:
    code = ("import sys, time; from nurbsdem.io import lock; lock.acquire(sys.argv[1]); "
            "print('held', flush=True); time.sleep(120)")
    p = subprocess.Popen([sys.executable, "-c", code, str(folder)], stdout=subprocess.PIPE,
                         text=True)
    assert p.stdout.readline().strip() == "held"
    return p


def test_a_second_run_into_a_busy_output_folder_is_refused(tmp_path):
    deck = _deck(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    holder = _hold_lock(out)
    try:
        r = _solve(str(deck))
        assert r.exit_code == 2, r.output
        lines = [ln for ln in r.output.splitlines() if ln.strip()]
        assert len(lines) == 1 and str(out) in lines[0] and f"pid {holder.pid}" in lines[0]
        assert not (out / "results.h5").exists()     # nothing of its own written
    finally:
        holder.kill()
        holder.wait()
    r = _solve(str(deck))                            # the lock goes with its holder
    assert r.exit_code == 0, r.output


# ---------------------------------------------------------------- Ctrl-C


def _default_sigint() -> None:
    """In the child before its exec: Ctrl-C's default disposition, as a terminal's process
    has it (a suite started in the background inherits SIGINT ignored)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _interrupted_run(deck: Path, delay: float) -> tuple[int, str]:
    """``nurbsdem solve`` sent SIGINT ``delay`` s after its first checkpoint is on disk."""
    out = deck.parent / "out"
    p = subprocess.Popen([sys.executable, "-m", "nurbsdem", "solve", str(deck), "--quiet"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         preexec_fn=_default_sigint)
    t0 = time.monotonic()
    while not (out / "checkpoint.h5").exists() and p.poll() is None:
        assert time.monotonic() - t0 < 300
        time.sleep(0.02)
    time.sleep(delay)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=300)
    return p.returncode, err


@pytest.mark.parametrize("delay", [0.0, 0.2, 0.4])
def test_ctrl_c_stops_at_a_checkpoint_with_exit_130(tmp_path, delay):
    deck = _deck(tmp_path, duration=2.0,
                 output="VTK Every 0.01 Resolution 2\n  Checkpoint Every 0.05")
    rc, err = _interrupted_run(deck, delay)
    assert rc == 130, (rc, err[-2000:])
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("nurbsdem: interrupted at t = "), err
    t = float(lines[0].split("t = ")[1].split(" s")[0])
    out = tmp_path / "out"
    assert 0 < t < 2.0 and load_checkpoint(out / "checkpoint.h5")["time"] == pytest.approx(t)
    assert read_results_times(out / "results.h5").max() >= t - 0.01 - 1e-9
    r = _solve(str(deck), "--restart", str(out / "checkpoint.h5"))
    assert r.exit_code == 0, r.output
    np.testing.assert_allclose(read_results_times(out / "results.h5"),
                               np.arange(201) * 0.01, atol=1e-9)


def test_ctrl_c_in_the_python_api_raises_keyboard_interrupt(tmp_path, request):
    """An interrupt of the main thread (a notebook's, here _thread.interrupt_main from a
    timer) during Simulation.run(): KeyboardInterrupt reaches the caller, the simulation's
    time is that of the checkpoint it left, and the previous SIGINT handler is back."""
    from nurbsdem import Simulation
    deck = _deck(tmp_path, duration=2.0,
                 output="VTK Every 0.01 Resolution 2\n  Checkpoint Every 0.05")
    sim = Simulation.from_deck(deck, quiet=True)
    out = tmp_path / "out"
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:     # a suite run in the background
        signal.signal(signal.SIGINT, signal.default_int_handler)
        request.addfinalizer(lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    handler = signal.getsignal(signal.SIGINT)

    def interrupt_when_running():
        t0 = time.monotonic()
        while not (out / "checkpoint.h5").exists() and time.monotonic() - t0 < 300:
            time.sleep(0.02)
        time.sleep(0.3)
        _thread.interrupt_main()
    threading.Thread(target=interrupt_when_running, daemon=True).start()
    with pytest.raises(KeyboardInterrupt, match="interrupted at t = "):
        sim.run()
    assert signal.getsignal(signal.SIGINT) is handler
    t = sim.time
    assert 0 < t < 2.0 and load_checkpoint(out / "checkpoint.h5")["time"] == t
    assert read_results_times(out / "results.h5").max() >= t - 0.01 - 1e-9


# ---------------------------------------------------------------- closed pipe


def test_a_closed_stdout_pipe_ends_quietly(tmp_path):
    """``nurbsdem info ... | head``: the reader goes away; no "error: Broken pipe"."""
    shape = tmp_path / "s.yaml"
    assert CliRunner().invoke(main, ["shape", "sphere", "--radius", "0.01", "-o",
                                     str(shape)]).exit_code == 0
    r, w = os.pipe()
    os.close(r)                                   # the reader is gone before any output
    p = subprocess.run([sys.executable, "-m", "nurbsdem", "info", str(shape)], stdout=w,
                       stderr=subprocess.PIPE, text=True, timeout=300)
    os.close(w)
    assert p.stderr.strip() == "", p.stderr
    assert p.returncode == 141

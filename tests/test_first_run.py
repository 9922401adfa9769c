"""The first solve after an install (:mod:`nurbsdem.first_run`): the kernels a deck needs
compiled in parallel processes, the run on the Python driver while the compiled loop compiles
in the background, and the run taking the loop once it is cached, with the same results."""
from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numba
import pytest

from nurbsdem import first_run, warmup
from nurbsdem.simulation import Simulation


def _monitors(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.rglob("*.csv"))}


def _longer(deck: Path, duration: str) -> Path:
    deck.write_text(deck.read_text().replace("Duration 0.004", f"Duration {duration}"))
    return deck


def test_a_run_that_takes_the_compiled_loop_midway_gives_the_same_results(tmp_path):
    """The deck steps before the switch on the Python driver, those after it in the compiled
    loop: the monitors are those of a run all in the compiled loop, byte for byte."""
    runs = {}
    for name in ("compiled", "switched"):
        folder = tmp_path / name
        folder.mkdir()
        sim = Simulation.from_deck(_longer(warmup._deck(folder, output=False), "0.03"),
                                   quiet=True)
        asked = []
        if name == "switched":
            sim.solver.compiled_steps = False
            sim.solver.compiled_when = lambda: asked.append(1) or len(asked) > 10
        sim.run()
        assert sim.solver.compiled_steps
        runs[name] = _monitors(folder / "results")
        if name == "switched":
            assert len(asked) == 11
    assert runs["compiled"] and runs["compiled"] == runs["switched"]


def _first_solve(monkeypatch, deck: Path, cached: list[bool]) -> tuple[Simulation, list]:
    """:func:`first_run.prepare_first_solve` of ``deck`` with nothing compiled or started:
    the stages it asks for and the background compilations it starts (as the string
    "loop") are returned; ``cached`` pops the answers of ``compiles_first``."""
    asked = []
    monkeypatch.setattr(first_run, "compiles_first", lambda: cached.pop(0))
    monkeypatch.setattr(warmup, "_usable_cores", lambda: 2)
    monkeypatch.setattr(warmup, "loop_compiling_in_background", lambda: "loop" in asked)
    monkeypatch.setattr(warmup, "warm_up", lambda stages, on_done: asked.extend(stages))
    monkeypatch.setattr(warmup, "compile_loop_in_background", lambda: asked.append("loop") or 4321)
    sim = Simulation.from_deck(deck, quiet=True)
    first_run.prepare_first_solve(sim)
    return sim, asked


def test_a_first_solve_compiles_the_stages_its_deck_needs_then_steps_on_the_python_driver(
        tmp_path, monkeypatch):
    threads = numba.get_num_threads()
    try:
        sim, asked = _first_solve(monkeypatch, warmup._deck(tmp_path, False), [True])
        assert [s.name for s in asked] == list(warmup.FIRST_RUN_STAGES)
        assert all(set(s.after) <= {s.name for s in asked} for s in asked)
        assert not sim.solver.compiled_steps
        assert numba.get_num_threads() == threads           # no background compilation yet
        spheres = warmup._spheres_deck(tmp_path)
        sim, asked = _first_solve(monkeypatch, spheres, [True])
        assert {s.name for s in asked} == {"batch kernels", "ParaView output",
                                           "contact forces", "contact detection"}
        when = sim.solver.compiled_when
        assert not when() and "loop" not in asked           # asked again within a second
        when.checked = -1e9
        when.t_start -= 10.0                                # 10 s for a tenth of the run:
        sim.solver.time = when.sim_start + 0.1 * (when.sim_end - when.sim_start)   # 90 s left
        assert not when() and asked[-1] == "loop"
        assert numba.get_num_threads() == 1                 # a core left to the background
        when.checked = -1e9
        assert not when()                                   # still compiling
        asked.remove("loop")                                # its process ended
        when.checked = -1e9
        cached = [False]
        monkeypatch.setattr(first_run, "compiles_first", lambda: cached.pop(0))
        assert when() and numba.get_num_threads() == threads
    finally:
        numba.set_num_threads(threads)
    sim, asked = _first_solve(monkeypatch, spheres, [False])     # the loop is cached
    assert sim.solver.compiled_steps and sim.solver.compiled_when is None and not asked


def test_a_short_first_run_keeps_every_core_and_compiles_the_loop_after_it(tmp_path,
                                                                            monkeypatch):
    """A first run that ends sooner than the loop would compile never shares its cores; the
    loop's background compilation starts once, after the run."""
    threads = numba.get_num_threads()
    sim, asked = _first_solve(monkeypatch, warmup._spheres_deck(tmp_path), [True])
    loop = sim.solver.compiled_when
    assert not loop()                                       # the run's start
    loop.checked = -1e9
    loop.t_start -= 10.0                                    # 10 s for half the run: 10 s left
    sim.solver.time = loop.sim_start + 0.5 * (loop.sim_end - loop.sim_start)
    assert not loop() and "loop" not in asked and numba.get_num_threads() == threads
    loop.t_start = time.monotonic()
    sim.run()
    assert "loop" not in asked and not sim.solver.compiled_steps
    loop.finish()
    assert asked.count("loop") == 1 and numba.get_num_threads() == threads
    loop.finish()
    assert asked.count("loop") == 1


def test_one_background_compilation_at_a_time(tmp_path, monkeypatch):
    pid_file = tmp_path / warmup.LOOP_PID_FILE
    monkeypatch.setattr(warmup, "_loop_pid_file", lambda: pid_file)
    assert not warmup.loop_compiling_in_background()
    pid_file.write_text(str(os.getpid()))
    assert warmup.loop_compiling_in_background()
    assert warmup.compile_loop_in_background() is None
    done = subprocess.Popen([sys.executable, "-c", "pass"])
    done.wait()
    pid_file.write_text(str(done.pid))
    assert not warmup.loop_compiling_in_background()
    ran = []
    monkeypatch.setattr(warmup, "_loop", lambda: ran.append(1))
    warmup._loop_in_background(str(pid_file), niceness=0)
    assert ran == [1] and not pid_file.exists()


@pytest.mark.slow
def test_a_first_solve_from_an_empty_cache(tmp_path):
    """``nurbsdem solve`` of a deck of spheres with an empty cache: it compiles in parallel
    processes and runs on the Python driver; once the loop's background compilation ends a
    second solve compiles nothing, and both write the same monitors (minutes)."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    deck = _longer(warmup._spheres_deck(tmp_path), "0.02")
    runs = []
    for out in ("first", "second"):
        run = subprocess.run([sys.executable, "-m", "nurbsdem", "solve", str(deck),
                              "--output", str(tmp_path / out)], env=env, capture_output=True,
                             text=True)
        assert run.returncode == 0, run.stderr
        runs.append(run.stderr)
        pid_file = next((tmp_path / "cache").rglob(warmup.LOOP_PID_FILE), None)
        deadline = time.monotonic() + 900
        while pid_file is not None and pid_file.exists() and time.monotonic() < deadline:
            time.sleep(2)
    assert "contact detection" in runs[0] and "in the background" in runs[0]
    assert "LCP batches" not in runs[0]                  # exact spheres: no LCP
    assert "compiling" not in runs[1]
    assert _monitors(tmp_path / "first") == _monitors(tmp_path / "second")

"""``nurbsdem warmup`` compiles the kernels ahead (nurbsdem.warmup): its stages run in worker
processes in their order, the small deck it solves is a valid deck, and a solve names the
kernels it compiles."""
from __future__ import annotations

import functools
import io
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from numba import njit

from nurbsdem import warmup


def _note(path: str, name: str, pause: float = 0.0) -> None:
    """A stage's work: append ``name start`` and ``name end`` to ``path`` (another process)."""
    with open(path, "a") as f:
        f.write(f"{name} start {os.getpid()}\n")
    time.sleep(pause)
    with open(path, "a") as f:
        f.write(f"{name} end {os.getpid()}\n")


def test_stages_run_in_their_order_in_worker_processes(tmp_path):
    log = str(tmp_path / "log")
    stages = (warmup.Stage("loop", functools.partial(_note, log, "loop"), 1.0,
                           after=("a", "b")),
              warmup.Stage("a", functools.partial(_note, log, "a", 0.5), 1.0),
              warmup.Stage("b", functools.partial(_note, log, "b", 0.5), 1.0))
    seen = []
    times = warmup.warm_up(jobs=2, on_done=lambda name, s: seen.append(name), stages=stages)
    lines = Path(log).read_text().split("\n")[:-1]
    events = [line.rsplit(" ", 1)[0] for line in lines]
    assert events.index("loop start") > max(events.index("a end"), events.index("b end"))
    assert max(events.index("a start"), events.index("b start")) < min(
        events.index("a end"), events.index("b end"))            # a and b at the same time
    assert {int(line.rsplit(" ", 1)[1]) for line in lines}.isdisjoint({os.getpid()})
    assert seen[-1] == "loop" and sorted(seen) == ["a", "b", "loop"] == sorted(times)
    assert all(t >= 0.0 for t in times.values())


def test_a_free_process_starts_the_ready_stage_that_leads_the_longest_chain(tmp_path):
    """With one process: x (which z comes after) starts before y of the same weight, and z
    (heavier) before y once x is done; a stage nobody waits for does not take the process
    first because it is listed first."""
    log = str(tmp_path / "log")
    stages = (warmup.Stage("y", functools.partial(_note, log, "y"), 1.0),
              warmup.Stage("x", functools.partial(_note, log, "x"), 1.0),
              warmup.Stage("z", functools.partial(_note, log, "z"), 2.0, after=("x",)))
    seen = []
    warmup.warm_up(jobs=1, on_done=lambda name, s: seen.append(name), stages=stages)
    assert seen == ["x", "z", "y"]
    assert warmup._priorities(stages) == {"x": 3.0, "y": 1.0, "z": 2.0}


def test_stages_in_a_cycle_or_after_unknown_ones_are_refused():
    run = functools.partial(time.sleep, 0)
    with pytest.raises(ValueError, match="unknown"):
        warmup.warm_up(stages=(warmup.Stage("a", run, 1.0, after=("z",)),))
    with pytest.raises(ValueError, match="cycle"):
        warmup.warm_up(stages=(warmup.Stage("a", run, 1.0, after=("b",)),
                               warmup.Stage("b", run, 1.0, after=("a",))))


#: a stage of :mod:`nurbsdem.warmup` (argv[1]) run in a fresh process, then the signatures of
#: the package's kernels called from Python (compiled or loaded from the cache), as JSON
_KERNELS_OF_A_STAGE = """
import json, sys
from numba.core.dispatcher import Dispatcher
from nurbsdem import warmup
getattr(warmup, sys.argv[1])()
seen = {}
for name, module in list(sys.modules.items()):
    if name.startswith("nurbsdem"):
        for obj in list(vars(module).values()):
            if isinstance(obj, Dispatcher) and obj.signatures:
                f = obj.py_func
                seen[f.__module__ + "." + f.__qualname__] = sorted(map(str, obj.signatures))
print(json.dumps(seen))
"""


def test_the_contact_forces_stage_compiles_kernels_the_contact_detection_then_loads():
    """The stage that evaluates without contact detection compiles the contact forces for
    the argument types the real run's evaluation passes, and nothing that run does not
    call: the contact detection's stage then loads them from the cache."""
    def kernels(stage: str) -> dict:
        out = subprocess.run([sys.executable, "-c", _KERNELS_OF_A_STAGE, stage],
                             capture_output=True, text=True, timeout=900, check=True)
        return json.loads(out.stdout.splitlines()[-1])
    forces, contacts = kernels("_forces"), kernels("_contacts")
    entry = "nurbsdem.dynamics.step.contact_part"
    assert entry in forces and "nurbsdem.dynamics.step.step_start" not in forces
    assert "nurbsdem.contact.listed.scene_list" not in forces
    assert {k: contacts.get(k) for k in forces} == forces


def test_the_warmup_deck_is_valid(tmp_path):
    """The small deck parses and passes the checks of ``nurbsdem check`` (its particles,
    sphere and walls apart), with and without ParaView output."""
    from nurbsdem.simulation import Simulation
    for output in (False, True):
        folder = tmp_path / str(output)
        folder.mkdir()
        sim = Simulation.from_deck(warmup._deck(folder, output), quiet=True)
        kinds = {type(s).__name__ for s in sim.solver.model.steps}
        assert kinds == {"DynamicStep"}
    out = subprocess.run([sys.executable, "-m", "nurbsdem", "check", str(folder / "warmup.inp")],
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stderr


def test_the_walls_deck_is_valid_and_has_both_curved_kinds(tmp_path):
    """The deck of the mesh and surface walls' stage passes ``nurbsdem check`` and holds a
    NURBS surface, a mesh, a NURBS particle and a sphere (the stage is in ``--all`` only)."""
    deck = warmup._walls_deck(tmp_path)
    text = deck.read_text()
    for word in ("Surface 1", "Mesh 2", "Ellipsoid", "Sphere", "Rotate"):
        assert word in text
    out = subprocess.run([sys.executable, "-m", "nurbsdem", "check", str(deck)],
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    names = [s.name for s in warmup.ALL_STAGES]
    assert set(names) == {s.name for s in warmup.STAGES} | {"mesh and surface walls"}
    loop = next(s for s in warmup.ALL_STAGES if s.name == "time loop")
    assert loop.run is warmup._loop_and_curved_walls and "mesh and surface walls" in loop.after


@njit
def _callee(x):
    return x + 1.0


@njit
def _entry(x):
    return _callee(x) * 2.0


@njit
def _other(x):
    return x - 1.0


def test_a_solve_names_the_kernels_it_compiles(monkeypatch):
    """One line per entry kernel compiled at the top, none for its callees, for kernels
    outside the list or for a kernel already compiled."""
    monkeypatch.setattr(warmup, "ENTRY_KERNELS",
                        {"test_warmup._entry": "the test's entry", "test_warmup._x": "another"})
    stream = io.StringIO()
    with warmup.reporting_compiles(True, stream):
        assert _entry(1.0) == 4.0
        assert _other(1.0) == 0.0
        assert _entry(2.0) == 6.0
    lines = stream.getvalue().splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("nurbsdem: compiling the test's entry (test_warmup._entry; "
                               "1 of 2 parts left")
    stream = io.StringIO()
    with warmup.reporting_compiles(False, stream):
        _entry(1)                                       # an int: compiled again, not told
    assert stream.getvalue() == ""


def test_the_time_left_follows_the_pace_so_far(monkeypatch):
    """The time left when an entry kernel starts: the shares of the entries not compiled yet
    (its own included) at the pace of those done; nothing before a tenth of the work."""
    monkeypatch.setattr(warmup, "ENTRY_KERNELS", {"m.a": "a", "m.b": "b", "m.c": "c"})
    monkeypatch.setattr(warmup, "ENTRY_SHARES", {"m.a": 0.2, "m.b": 0.3, "m.c": 0.5})
    report = warmup.CompileReport(io.StringIO())
    report.seen = {"m.a"}
    assert report._time_left("m.a", 5.0) == ""
    report.seen = {"m.a", "m.b"}
    assert report._time_left("m.b", 10.0) == ", about 40 s left"     # 0.2 in 10 s, 0.8 left
    report.seen = {"m.a", "m.b", "m.c"}
    assert report._time_left("m.c", 25.0) == ", about 25 s left"     # 0.5 in 25 s, 0.5 left


def test_the_shares_name_entry_kernels_and_sum_to_most_of_the_work():
    assert set(warmup.ENTRY_SHARES) == set(warmup.ENTRY_KERNELS)
    assert 0.8 < sum(warmup.ENTRY_SHARES.values()) <= 1.0


@pytest.mark.slow
def test_warmup_fills_an_empty_cache(tmp_path):
    """``nurbsdem warmup`` with an empty cache: afterwards the compiled loop is cached and
    a solve of the small deck compiles no entry kernel (minutes: it compiles them all)."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    run = subprocess.run([sys.executable, "-m", "nurbsdem", "warmup"], env=env,
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert "kernels compiled in" in run.stdout
    deck = warmup._deck(tmp_path, output=True)
    solve = subprocess.run([sys.executable, "-m", "nurbsdem", "solve", str(deck)], env=env,
                           capture_output=True, text=True)
    assert solve.returncode == 0, solve.stderr
    assert "nurbsdem: compiling" not in solve.stderr

"""Compiled deck steps for scenes of NURBS particles (nurbsdem.dynamics.deck_steps): the LCP
dispatch, the neighbour list with candidate patches and the walls inside the compiled loop
give the same bits as the Python path (the scenes of exact spheres: test_sphere_steps.py)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from nurbsdem.dynamics import system as system_module
from nurbsdem.io.deck import parse_deck
from nurbsdem.solver import Solver
from test_sphere_steps import _both_paths, _same_results

SHAPES = Path(__file__).resolve().parents[1] / "inputs" / "shapes"


def _deck(shapes: str, particles: str, side: float) -> str:
    """Particles falling into a box of the given side (m), a lid brought to contact and
    pressed."""
    return f"""Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2700
Shapes
{shapes}
Particles
{particles}
Walls
  Box 1 Min 0 0 0 Max {side} {side} 0.40
  Wall 6 Name lid Point {side / 2} {side / 2} 0.40 Normal 0 0 -1 Size {side} {side}
Contact
  Interface 1 NormalPenalty 1e5 TangentialPenalty 1e4 NormalDamping 1e2 TangentialDamping 0 Friction 0.5
Steps
  Step 1 Dynamic Duration 0.3 TimeStep 1e-3
  Step 2 MoveWall lid ToContact Gap 0.002
  Step 3 MoveWall lid Displacement 0 0 -0.003 Duration 0.02 TimeStep 1e-3
Output
  Directory results
  VTK Every 0.05 Resolution 4
  Monitors Every 0.004
  Checkpoint Every 0.1
"""


PAPER = _deck(f"  Shape 1 File {SHAPES / 'A.yaml'}\n  Shape 2 File {SHAPES / 'B.yaml'}\n"
              f"  Shape 3 File {SHAPES / 'C.yaml'}",
              "  Random 1 Shapes 1 2 3 Counts 3 2 3 Material 1 Region 0.005 0.005 0.005 0.155 "
              "0.155 0.3 Seed 3", 0.16)
MIXED = _deck("  Shape 1 Sphere Radius 0.012\n  Shape 2 Ellipsoid SemiAxes 0.016 0.011 0.008",
              "  Random 1 Shapes 1 2 Counts 5 5 Material 1 Region 0.005 0.005 0.005 0.095 0.095 "
              "0.2 Seed 4", 0.1)


@pytest.mark.parametrize("name, text", [("paper.inp", PAPER), ("mixed.inp", MIXED)])
def test_compiled_nurbs_steps_equal_the_python_path(tmp_path, monkeypatch, name, text):
    """Paper particles (NURBS–NURBS and NURBS–wall LCPs, candidate patches), and exact
    spheres with ellipsoids (closed forms, the point-to-surface solver, the LCP): every sample
    and monitor equal bit for bit, the same LCP counts; the compiled loop really ran, and took
    several monitor samples in one call (rows recorded inside the loop) and exact time-step
    estimates without returning (the same control figures and as many estimates in all)."""
    from nurbsdem.dynamics import deck_steps
    used, batched, estimates, systems = [], [], [], {}
    original = system_module.DemSystem.steps
    loop = deck_steps.run_deck_steps

    def estimating(*args):
        result = loop(*args)
        estimates.append(int(args[20][deck_steps.NETWORK_ESTIMATES]))   # counters
        return result
    monkeypatch.setattr(deck_steps, "run_deck_steps", estimating)

    def counting(self, n_max, sample_at=None, state_at=None):
        done = original(self, n_max, sample_at, state_at)
        compiled = self._deck_steps is not False and self.compiled_steps
        used.append(compiled)
        systems[self.compiled_steps] = self         # the last system of each run
        batched.append(compiled and len(self.last_steps.samples) > 1
                       and len(self.last_steps.states) > 0)
        return done
    monkeypatch.setattr(system_module.DemSystem, "steps", counting)
    (py, s_py), (cc, s_cc) = _both_paths(tmp_path, name, text)
    _same_results(py, cc)
    for key in ("steps", "substeps", "lcps", "active_total", "active_max", "degenerated"):
        assert getattr(s_py, key) == getattr(s_cc, key), key
    assert s_cc.active_max >= 8 and s_cc.lcps > 1000          # a pack pressed by the lid
    assert s_cc.failed == 0
    assert not (cc / "monitors" / "hertz.csv").exists()       # linear laws: no Hertz monitor
    assert any(used) and not all(used)                         # the Python run, then compiled
    assert any(batched)
    assert sum(estimates) >= 3
    figures = [(s.dt_bound, s.dt_network, s.dt_critical, s.network_estimates)
               for s in (systems[False], systems[True])]
    assert figures[0] == figures[1]


def test_a_guard_return_hands_the_deck_steps_to_the_python_path(tmp_path, monkeypatch):
    """What the loop's caller does when an LCP fails in the compiled loop (it returns GUARD at
    deck step ``done``): the system and the scene are rolled back to the call's start, the
    deck steps before the failed one run in the loop again, and the Python path runs the
    failed one alone, answering the failure.  A failure cannot be injected into compiled
    code, so here two calls of the loop in three claim one at their last deck step (and, run
    again, at the one before): paper particles, the same bits and counts as the Python path
    alone, with the Python path repeating only deck steps claimed at a call's start (fewer
    than half of all the deck steps)."""
    from nurbsdem.dynamics import deck_steps
    original = deck_steps.run_deck_steps
    claimed = []
    python_steps = []

    def failing(*args):
        status, done, *rest = original(*args)
        claim = done >= 1 and len(claimed) % 3 != 0
        claimed.append(claim)
        return (deck_steps.GUARD, done - 1, *rest) if claim else (status, done, *rest)
    monkeypatch.setattr(deck_steps, "run_deck_steps", failing)
    deck = tmp_path / "paper.inp"
    deck.write_text(PAPER)
    py, cc = tmp_path / "python", tmp_path / "compiled"
    s_py = Solver(parse_deck(deck), output=py, quiet=True, compiled_steps=False).run()
    step = system_module.DemSystem.step

    def counted(self):
        python_steps.append(self.time)
        return step(self)
    monkeypatch.setattr(system_module.DemSystem, "step", counted)
    s_cc = Solver(parse_deck(deck), output=cc, quiet=True).run()
    _same_results(py, cc)
    for key in ("steps", "substeps", "lcps", "active_total", "active_max", "degenerated"):
        assert getattr(s_py, key) == getattr(s_cc, key), key
    assert sum(claimed) >= 3
    # a deck step claimed at the start of a call (done 0) is the one the Python path repeats
    assert 1 <= len(python_steps) < s_cc.steps // 2


def _hertz(text: str) -> str:
    """The deck under Hertz–Mindlin (the exact curvature radii of NURBS contacts)."""
    return text.replace(
        "Material 1 Density 2700", "Material 1 Density 2700 YoungModulus 1e8 PoissonRatio 0.3"
    ).replace("Interface 1 NormalPenalty 1e5 TangentialPenalty 1e4 NormalDamping 1e2 "
              "TangentialDamping 0 Friction 0.5",
              "Interface 1 Model HertzMindlin Restitution 0.5 Friction 0.5")


# the suite's time: the implicit run holds the mixed scene's radii, the paper run the
# explicit Hertz dashpots; the explicit mixed run is in the slow suite
@pytest.mark.parametrize("name, text", [
    ("paper_hm.inp", _hertz(PAPER)),
    pytest.param("mixed_hm.inp", _hertz(MIXED), marks=pytest.mark.slow),
    ("implicit_hm.inp", _hertz(MIXED).replace("TimeStep 1e-3", "TimeStep 1e-3 Damping Implicit"))])
def test_compiled_hertz_mindlin_nurbs_steps_equal_the_python_path(tmp_path, monkeypatch, name,
                                                                   text):
    """Hertz–Mindlin between NURBS particles (and exact spheres with ellipsoids): the compiled
    loop takes the equivalent radii from the same curvature kernel as the Python path
    (``scene_contact_radii`` at the same poses): every sample, monitor (``hertz.csv`` too) and
    ParaView file equal bit for bit, the same counts, and the compiled loop really ran; also
    with implicit dashpots (their damping from the Hertz laws' per-contact coefficients)."""
    used = []
    original = system_module.DemSystem.steps

    def counting(self, n_max, sample_at=None, state_at=None):
        done = original(self, n_max, sample_at, state_at)
        used.append(self._deck_steps is not False and self.compiled_steps)
        return done
    monkeypatch.setattr(system_module.DemSystem, "steps", counting)
    (py, s_py), (cc, s_cc) = _both_paths(tmp_path, name, text)
    _same_results(py, cc)
    assert ((cc / "monitors" / "hertz.csv").read_text()
            == (py / "monitors" / "hertz.csv").read_text())
    for key in ("steps", "substeps", "lcps", "active_total", "active_max", "degenerated"):
        assert getattr(s_py, key) == getattr(s_cc, key), key
    assert s_cc.active_max >= 5 and s_cc.failed == 0          # a pack pressed by the lid
    rows = np.loadtxt(cc / "monitors" / "hertz.csv", delimiter=",", skiprows=1, ndmin=2)
    assert (rows[:, 1] > rows[:, 2]).any()                     # exact radii, not fallbacks
    assert any(used) and not all(used)                         # the Python run, then compiled

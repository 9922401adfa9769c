"""Compiled deck steps for scenes of exact spheres (nurbsdem.dynamics.deck_steps): the same
bits as the Python path, for every step kind, with the guard and restart."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from nurbsdem.dynamics import system as system_module
from nurbsdem.io.deck import parse_deck
from nurbsdem.io.results import read_results_sample, read_results_times
from nurbsdem.solver import Solver
from runs import STATE_KEYS, assert_same_final_state, killed_and_restarted, spread_points


def _sphere_deck() -> str:
    """24 spheres of two sizes falling into a box, a lid brought to contact, pressed, lifted."""
    rng = np.random.default_rng(7)
    lines = []
    pts = spread_points(rng, 24, [0.016, 0.016, 0.016], [0.094, 0.094, 0.12], 0.032)
    for i, p in enumerate(pts):
        v = rng.normal(size=3) * 0.2
        lines.append(f"  Particle {i + 1} Shape {1 + i % 2} Material 1 Position "
                     f"{p[0]:.6f} {p[1]:.6f} {p[2]:.6f} Velocity {v[0]:.4f} {v[1]:.4f} {v[2]:.4f}")
    return ("""Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2700
Shapes
  Shape 1 Sphere Radius 0.015
  Shape 2 Sphere Radius 0.011
Particles
""" + "\n".join(lines) + """
Walls
  Box 1 Min 0 0 0 Max 0.11 0.11 0.14
  Wall 6 Name lid Point 0.055 0.055 0.14 Normal 0 0 -1 Size 0.11 0.11
Contact
  Interface 1 NormalPenalty 1e5 TangentialPenalty 1e4 NormalDamping 1e2 TangentialDamping 0 Friction 0.5
Steps
  Step 1 Dynamic Duration 0.2 TimeStep 1e-3
  Step 2 MoveWall lid ToContact Gap 0.001
  Step 3 MoveWall lid Displacement 0 0 -0.004 Duration 0.05 TimeStep 1e-3
  Step 4 MoveWall lid Displacement 0 0 0.004 Duration 0.03 TimeStep 1e-3
Output
  Directory results
  VTK Every 0.05 Resolution 4
  Monitors Every 0.005
  Checkpoint Every 0.1
""")


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("spheres")
    deck = d / "spheres.inp"
    deck.write_text(_sphere_deck())
    out = {}
    for compiled in (False, True):
        o = d / ("compiled" if compiled else "python")
        s = Solver(parse_deck(deck), output=o, quiet=True, compiled_steps=compiled)
        out[compiled] = (o, s.run(), s)
    return deck, out


def _same_results(a: Path, b: Path) -> None:
    """Every sample equal bit for bit, the monitors, and every ParaView file byte for byte
    (the compiled loop keeps the states of the samples it runs through; the Python path
    writes them live)."""
    assert_same_final_state(a, b, ("energy.csv", "contacts.csv", "wall_lid.csv"))
    for k in range(len(read_results_times(a / "results.h5"))):
        ra, rb = read_results_sample(a / "results.h5", k), read_results_sample(b / "results.h5", k)
        for key in STATE_KEYS:
            np.testing.assert_array_equal(ra[key], rb[key])          # bit for bit
    names = sorted(p.name for p in (a / "vtk").glob("*.vtu"))
    assert names and names == sorted(p.name for p in (b / "vtk").glob("*.vtu"))
    for name in names + ["particles.pvd", "walls.pvd", "contacts.pvd"]:
        where = "vtk" if name.endswith(".vtu") else "."
        assert (a / where / name).read_bytes() == (b / where / name).read_bytes(), name


def _both_paths(tmp_path: Path, name: str, text: str):
    """The deck ``text`` solved by the Python path and by the compiled deck steps:
    [(output folder, summary)] in that order."""
    deck = tmp_path / name
    deck.write_text(text)
    outs = []
    for compiled in (False, True):
        o = tmp_path / ("compiled" if compiled else "python")
        summary = Solver(parse_deck(deck), output=o, quiet=True, compiled_steps=compiled).run()
        outs.append((o, summary))
    return outs


def test_compiled_steps_equal_the_python_path_bit_for_bit(runs):
    """Deposition, a lid moved to contact, pressed and lifted: every sample of results.h5 and
    every monitor line equal; the same counts of internal steps, LCPs and contacts."""
    _, out = runs
    (py, s_py, solver_py), (cc, s_cc, solver_cc) = out[False], out[True]
    _same_results(py, cc)
    for key in ("steps", "substeps", "lcps", "active_total", "active_max", "degenerated"):
        assert getattr(s_py, key) == getattr(s_cc, key), key
    assert s_cc.active_max > 10                       # a real pack, pressed by the lid
    assert solver_cc.system is None and solver_cc.end_energy == solver_py.end_energy


def test_compiled_hertz_mindlin_equals_the_python_path(tmp_path):
    """Hertz–Mindlin spheres (exact equivalent radii, tangent coefficients in the step
    control): the compiled deck steps give the Python path's results bit for bit."""
    text = _sphere_deck().replace(
        "Material 1 Density 2700", "Material 1 Density 2700 YoungModulus 1e8 PoissonRatio 0.3"
    ).replace("Interface 1 NormalPenalty 1e5 TangentialPenalty 1e4 NormalDamping 1e2 "
              "TangentialDamping 0 Friction 0.5",
              "Interface 1 Model HertzMindlin Restitution 0.5 Friction 0.5").replace(
        "Step 1 Dynamic Duration 0.2", "Step 1 Dynamic Duration 0.12")
    (py, s_py), (cc, s_cc) = _both_paths(tmp_path, "hertz.inp", text)
    assert_same_final_state(cc, py, ("energy.csv", "contacts.csv", "hertz.csv", "wall_lid.csv"))
    assert s_py.substeps == s_cc.substeps and s_cc.active_max > 10


def test_compiled_implicit_dashpots_equal_the_python_path(runs, tmp_path):
    """``Damping Implicit`` (nurbsdem.dynamics.implicit) in the compiled deck steps: the
    Python path's results bit for bit, with fewer sub-steps per deck step than the explicit
    dashpots of the same deck (``runs``)."""
    text = _sphere_deck().replace("TimeStep 1e-3", "TimeStep 1e-3 Damping Implicit").replace(
        "Step 1 Dynamic Duration 0.2", "Step 1 Dynamic Duration 0.12")
    (py, s_py), (cc, s_cc) = _both_paths(tmp_path, "implicit.inp", text)
    _same_results(py, cc)
    assert s_py.substeps == s_cc.substeps and s_cc.active_max > 10
    _, out = runs
    explicit = out[True][1]
    assert s_cc.substeps / s_cc.steps < 0.7 * explicit.substeps / explicit.steps
    # both paths time the integration, the contact forces, the dashpots and the step control
    # as parts of forces + integration
    for s in (s_py, s_cc):
        assert list(s.split) == ["integration", "contact forces", "implicit dashpots",
                                 "time-step control"]
        assert all(v > 0.0 for v in s.split.values())
        assert sum(s.split.values()) < s.timers["forces + integration"]
        assert "of forces + integration: integration" in s.text()
    assert explicit.split["implicit dashpots"] == 0.0 < explicit.split["time-step control"]


def test_compiled_steps_are_used_for_spheres(runs, monkeypatch):
    """The compiled path really ran (most deck steps in compiled loops of many steps)."""
    deck, _ = runs
    calls = []
    original = system_module.DemSystem.steps

    def counting(self, n_max, sample_at=None, state_at=None):
        done = original(self, n_max, sample_at, state_at)
        calls.append((done, self._deck_steps is not False))
        return done
    monkeypatch.setattr(system_module.DemSystem, "steps", counting)
    Solver(parse_deck(deck), write_output=False, quiet=True).run()
    assert all(fast for _, fast in calls)
    assert sum(done for done, _ in calls) == 280 and len(calls) < 280 / 2


def test_samples_kept_by_the_loop_or_taken_live_give_the_same_files(runs, tmp_path,
                                                                    monkeypatch):
    """With a state budget of one byte the compiled loop stops at every ParaView/results
    sample and the solver takes it live: every file the same as the
    run whose loop kept the samples' states, in fewer calls."""
    import nurbsdem.output_schedule as schedule_module
    deck, out = runs
    kept_dir = out[True][0]
    calls = []
    original = system_module.DemSystem.steps

    def counting(self, n_max, sample_at=None, state_at=None):
        done = original(self, n_max, sample_at, state_at)
        calls.append(len(self.last_steps.states))
        return done
    monkeypatch.setattr(system_module.DemSystem, "steps", counting)
    monkeypatch.setattr(schedule_module, "STATE_BUDGET_BYTES", 1)
    live = tmp_path / "live"
    Solver(parse_deck(deck), output=live, quiet=True).run()
    assert calls and not any(calls)                 # every sample taken live
    _same_results(kept_dir, live)


def test_the_state_budget_counts_what_the_loop_keeps(runs, tmp_path, monkeypatch):
    """DemSystem.state_sample_bytes, by which the solver budgets the states the compiled loop
    keeps in one call, bounds the bytes of every state kept (its arrays' nbytes) and is
    within 30 % of them."""
    from nurbsdem.dynamics import deck_steps
    deck, _ = runs
    seen = []
    original = deck_steps.DeckSteps.run

    def recording(self, n_deck, sample_at, state_at=None):
        result = original(self, n_deck, sample_at, state_at)
        for kept in result[4]:
            held = sum(a.nbytes for a in kept[1:])
            contacts = kept[6].shape[0]
            seen.append((held, self.system.state_sample_bytes(contacts), contacts))
        return result
    monkeypatch.setattr(deck_steps.DeckSteps, "run", recording)
    Solver(parse_deck(deck), output=tmp_path / "budget", quiet=True).run()
    assert seen and max(contacts for _, _, contacts in seen) > 0
    for held, budget, _ in seen:
        assert held <= budget <= 1.3 * held


def test_guard_inside_the_compiled_loop_falls_back_to_the_python_step(tmp_path):
    """A guard that fires inside the compiled loop (here: an energy tolerance of 1e-14, so it
    fires on round-off) hands the deck step to the Python path, which repeats it with more
    sub-steps and finally raises: the same outcome as the Python path alone."""
    deck = tmp_path / "spheres.inp"
    deck.write_text(_sphere_deck())
    outcomes = []
    for compiled in (False, True):
        s = Solver(parse_deck(deck), write_output=False, quiet=True, compiled_steps=compiled)
        original = system_module.DemSystem.__init__

        def tight(self, *a, **k):
            original(self, *a, **k)
            self.energy_tolerance = 1e-14
        system_module.DemSystem.__init__ = tight
        try:
            with pytest.raises(system_module.InstabilityError) as exc:
                s.run()
        finally:
            system_module.DemSystem.__init__ = original
        outcomes.append((exc.value.time, str(exc.value), s.bodies.position.copy()))
    assert outcomes[0][0] == outcomes[1][0] and outcomes[0][1] == outcomes[1][1]
    np.testing.assert_array_equal(outcomes[0][2], outcomes[1][2])


def test_compiled_restart_reaches_the_same_final_state(runs, tmp_path, monkeypatch):
    """Killed mid-deposition after a checkpoint, restarted: bit for bit the uninterrupted run."""
    deck, out = runs
    killed_and_restarted(deck, tmp_path / "out", 0.15, monkeypatch)
    assert_same_final_state(tmp_path / "out", out[True][0], ("energy.csv", "contacts.csv"))


def test_a_control_return_takes_the_loops_estimate_not_a_second_one(tmp_path, monkeypatch):
    """Where the compiled loop returns because the sub-step count changes, the control step
    takes the loop's exact estimate of the network (RATES_* of the loop's figures) instead of
    the same estimate again: the same critical step, bound and message as computed here."""
    from nurbsdem.dynamics.substep_control import SubstepControl
    limit, seen = SubstepControl._network_limit, []

    def spy(self, net, rates=None):
        out = limit(self, net, rates)
        if rates is not None:
            seen.append((out, rates[1], limit(self, net), self._network_bound(net)))
        return out

    monkeypatch.setattr(SubstepControl, "_network_limit", spy)
    deck = tmp_path / "spheres.inp"
    deck.write_text(_sphere_deck())
    Solver(parse_deck(deck), output=tmp_path / "out", quiet=True, compiled_steps=True).run()
    assert seen
    for taken, bound, again, bound_again in seen:
        assert taken == again and bound == bound_again

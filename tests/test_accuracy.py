"""The accuracy control (nurbsdem.dynamics.accuracy): a deck step whose energy-balance error
grows beyond its budget is repeated with twice the sub-steps; the compiled deck steps take the
same decisions as the Python path, to the bit."""
from __future__ import annotations

import csv

import numpy as np
import pytest

from nurbsdem.dynamics import deck_steps
from nurbsdem.dynamics import system as system_module
from nurbsdem.dynamics.accuracy import (ACCURACY_CONVERGENCE, ACCURACY_DECAY_STEPS,
                                        ACCURACY_MAX_REFINE, after_accepted,
                                        repeat_for_accuracy)
from nurbsdem.errors import InputError
from nurbsdem.io.deck import parse_deck
from nurbsdem.solver import Solver
from runs import assert_same_final_state, killed_and_restarted
from test_deck_steps import PAPER
from test_sphere_steps import _both_paths, _same_results


def _accurate(text: str, accuracy: float) -> str:
    """The deck with implicit dashpots and the accuracy control on its timed steps."""
    return text.replace("TimeStep 1e-3", f"TimeStep 1e-3 Damping Implicit Accuracy {accuracy:g}")


def test_the_policy():
    """Repeat above the budget while the factor and the sub-step limit allow and the repeats
    converge; halve the factor after ACCURACY_DECAY_STEPS calm deck steps (growth below a
    quarter of the budget)."""
    inf = np.inf
    assert repeat_for_accuracy(2.0, 1.0, 1, 4, 1000, inf)
    assert not repeat_for_accuracy(1.0, 1.0, 1, 4, 1000, inf)           # at the budget: kept
    assert not repeat_for_accuracy(2.0, 1.0, ACCURACY_MAX_REFINE, 4, 1000, inf)
    assert not repeat_for_accuracy(2.0, 1.0, 2, 600, 1000, inf)          # 1200 > max_substeps
    assert repeat_for_accuracy(2.0, 1.0, 2, 8, 1000, 8.0)                # a quarter: converging
    assert not repeat_for_accuracy(5.0, 1.0, 2, 8, 1000, 8.0)            # no error of the step
    acc, calm = 4, 0
    for k in range(ACCURACY_DECAY_STEPS - 1):
        acc, calm = after_accepted(0.2, 1.0, acc, calm)
        assert (acc, calm) == (4, k + 1)
    assert after_accepted(0.2, 1.0, acc, calm) == (2, 0)
    assert after_accepted(0.5, 1.0, 4, 3) == (4, 0)                     # not calm: count reset
    assert after_accepted(0.0, 1.0, 1, 9) == (1, 10)                     # nothing to halve


def test_compiled_steps_take_the_python_paths_decisions(tmp_path, monkeypatch):
    """Paper particles dropped, a lid pressed, with implicit dashpots and a tight budget: the
    Python path and the compiled loop (which rolls a rejected deck step back from its own
    snapshot) give every sample and monitor line bit for bit and the same counts, repeats
    included; the compiled loop really rejected deck steps and lowered its factor again."""
    statuses = []
    original = deck_steps.run_deck_steps

    def recording(*args):
        out = original(*args)
        statuses.append(out[:2])
        return out
    monkeypatch.setattr(deck_steps, "run_deck_steps", recording)
    (py, s_py), (cc, s_cc) = _both_paths(tmp_path, "paper.inp", _accurate(PAPER, 1e-6))
    _same_results(py, cc)
    for key in ("steps", "substeps", "lcps", "active_total", "active_max", "degenerated",
                "accuracy_repeats"):
        assert getattr(s_py, key) == getattr(s_cc, key), key
    assert s_cc.accuracy_repeats >= 3 and s_cc.failed == 0
    seen = {status for status, _ in statuses}
    assert deck_steps.REFINE in seen and deck_steps.RECOUNT in seen
    assert any(status == deck_steps.REFINE and done > 0 for status, done in statuses)


def _energy(out) -> dict[str, np.ndarray]:
    with open(out / "monitors" / "energy.csv") as fh:
        rows = list(csv.DictReader(fh))
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}


DROP = PAPER.replace("""  Step 2 MoveWall lid ToContact Gap 0.002
  Step 3 MoveWall lid Displacement 0 0 -0.003 Duration 0.02 TimeStep 1e-3
""", "").replace("Monitors Every 0.004", "Monitors Every 0.001")


@pytest.fixture(scope="module")
def drops(tmp_path_factory):
    """The drop (one Dynamic step, monitors at every deck step) with implicit dashpots:
    without the control, with it (the Python path, its decisions recorded), and with 4 x the
    sub-steps everywhere."""
    runs = {}
    plain = _accurate(DROP, 1e-4).replace(" Accuracy 0.0001", "")
    for label, text, safety in (("plain", plain, 0.5), ("controlled", _accurate(DROP, 1e-4), 0.5),
                                ("fine", plain, 0.125)):
        d = tmp_path_factory.mktemp(label)
        (d / "drop.inp").write_text(text)
        decisions = []
        original = system_module.repeat_for_accuracy

        def recording(*args):
            decisions.append(args + (original(*args),))
            return decisions[-1][-1]
        system_module.repeat_for_accuracy = recording
        try:
            summary = Solver(parse_deck(d / "drop.inp"), output=d / "out", quiet=True,
                             safety=safety, compiled_steps=False).run()
        finally:
            system_module.repeat_for_accuracy = original
        runs[label] = (summary, _energy(d / "out"), decisions)
    return runs


def test_every_deck_step_keeps_its_budget(drops):
    """The monitors against the decisions: the balance error of a deck step (energy.csv)
    grew by more than its budget only where the control stopped repeating it because the
    factor was at its largest or the repeats did not converge; each accepted decision's
    growth is the one the monitors show."""
    _, e, decisions = drops["controlled"]
    growth = np.abs(np.diff(e["balance_error"]))
    accepted = [d for d in decisions if not d[-1]]
    assert len(accepted) == len(growth) and len(decisions) > len(growth)
    for g, (g_acc, budget, acc, _, _, last, _) in zip(growth, accepted):
        assert g == pytest.approx(g_acc, rel=1e-6, abs=1e-12)
        if g > budget * (1 + 1e-9):
            assert acc == ACCURACY_MAX_REFINE or g_acc > ACCURACY_CONVERGENCE * last
    over = sum(g > b for g, (_, b, *_) in zip(growth, accepted))
    assert over <= 0.02 * len(growth)
    assert growth.max() > 0.3 * max(d[1] for d in accepted)          # the budget is what limits


def test_the_control_buys_accuracy_where_it_is_needed(drops):
    """Against the same drop at the stability control's step (3 sub-steps per deck step,
    energy-balance error 2.3e-2 J), Accuracy 1e-4 cuts the error more than 10 times (2.0e-3
    J); a step 3 x finer everywhere (safety 0.125) reaches the same error (1.8e-3 J) with
    2700 internal steps, the control with 1890 (measured when written)."""
    plain, controlled, fine = (drops[k][0] for k in ("plain", "controlled", "fine"))
    assert controlled.accuracy_repeats > 0 and plain.accuracy_repeats == 0
    assert abs(controlled.balance_error) < abs(plain.balance_error) / 10
    assert abs(controlled.balance_error) < 1.5 * abs(fine.balance_error)
    assert controlled.substeps < 0.8 * fine.substeps


def test_a_restart_continues_the_control_bit_for_bit(tmp_path, monkeypatch):
    """The accuracy factor, its calm count and the last rejected growth are part of the
    checkpoint: a run killed after a checkpoint and restarted ends in the same state, with
    the same monitors, as the run that was not stopped (compiled deck steps)."""
    deck = tmp_path / "drop.inp"
    deck.write_text(_accurate(DROP, 1e-5).replace("Checkpoint Every 0.1", "Checkpoint Every 0.05"))
    ref, out = tmp_path / "ref", tmp_path / "out"
    summary = Solver(parse_deck(deck), output=ref, quiet=True).run()
    assert summary.accuracy_repeats > 0
    killed_and_restarted(deck, out, 0.17, monkeypatch)
    assert_same_final_state(out, ref, ("energy.csv", "contacts.csv"))


@pytest.mark.parametrize("line, message", [
    ("Accuracy 0", "Step 1: Accuracy must be > 0, got 0"),
    ("Accuracy 0.5", "Step 1: Accuracy"),
    ("Accuracy fine", "Step 1: Accuracy"),
])
def test_a_bad_accuracy_is_one_line_naming_the_file_and_line(tmp_path, line, message):
    deck = tmp_path / "bad.inp"
    deck.write_text(DROP.replace("Duration 0.3 TimeStep 1e-3", f"Duration 0.3 TimeStep 1e-3 {line}"))
    with pytest.raises(InputError) as info:
        parse_deck(deck)
    text = str(info.value)
    assert message in text and "bad.inp:" in text and "\n" not in text


def test_the_python_api_writes_the_accuracy_into_its_deck():
    import nurbsdem
    sim = nurbsdem.Simulation()
    sim.add_material(1, 2700)
    sim.add_interface(normal_penalty=1e5, normal_damping=1e2)
    sim.add_box((0, 0, 0), (0.1, 0.1, 0.1))
    sim.add_particle(nurbsdem.shapes.sphere(0.01), 1, (0.05, 0.05, 0.03))
    sim.run_dynamic(0.01, 1e-3, damping="implicit", accuracy=1e-4)
    assert sim.model.steps[-1].accuracy == 1e-4
    assert "Damping Implicit Accuracy 0.0001" in sim.deck_text
    with pytest.raises(InputError, match="Accuracy must be > 0"):
        sim.run_dynamic(0.01, 1e-3, accuracy=0)

"""Periodic cells from a deck and from Python: ``inputs/periodic/shear_box.inp`` runs through
``nurbsdem solve`` and a killed run restarted from its checkpoint ends bit for bit where the
uninterrupted one ends; bad ``Periodic`` lines and walls are one-line errors at their line."""
from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from nurbsdem import Simulation
from nurbsdem.cli import main
from nurbsdem.errors import InputError
from runs import assert_same_final_state, killed_and_restarted

ROOT = Path(__file__).resolve().parents[1]
SHEAR_BOX = ROOT / "inputs" / "periodic" / "shear_box.inp"


def test_the_shear_box_solves_and_restarts_bit_for_bit(tmp_path, monkeypatch):
    ref = tmp_path / "ref"
    r = CliRunner().invoke(main, ["solve", str(SHEAR_BOX), "--output", str(ref), "--quiet"])
    assert r.exit_code == 0, r.output
    out = tmp_path / "out"
    killed_and_restarted(SHEAR_BOX, out, 0.07, monkeypatch)      # after the checkpoint at 0.06 s
    assert_same_final_state(out, ref, ("energy.csv", "contacts.csv"))


BAD = [
    ("Periodic X 0 0.06 Y 0 0.06", "Periodic X 0.06 0 Y 0 0.06", "Periodic",
     "Periodic: X needs lo < hi, got 0.06 0"),
    ("Periodic X 0 0.06 Y 0 0.06", "Periodic", "Periodic",
     "Periodic: give at least one axis (X lo hi, Y lo hi or Z lo hi)"),
    ("Periodic X 0 0.06 Y 0 0.06", "Periodic X 0 0.06 Y 0 0.02", "Periodic",
     "Periodic: the periodic length along y (0.02 m) is under twice the contact reach "
     "(0.0281563 m): a particle would touch its own image"),
    ("Periodic X 0 0.06 Y 0 0.06", "Periodic X 0 0.06 Y 0 0.06 Z 0 0.1", "Wall 1",
     "wall floor: its normal 0 0 1 has a component along the periodic axis z (Periodic, "
     "line 6): a flat wall must lie along every periodic axis"),
    ("Size 0.09 0.09\n  Wall 2", "Size 0.06 0.09\n  Wall 2", "Wall 1",
     "wall floor spans 0 .. 0.06 m along the periodic axis x: it must cover the cell (0 .. "
     "0.06 m, line 6) and 0.007679 m beyond each face (the largest bounding radius plus the "
     "skin)"),
    ("Random 1 Shapes 1 Counts 36 Material 1 Region 0 0 0.005 0.06 0.06 0.05 Seed 3",
     "Particle 1 Shape 1 Material 1 Position 0.002 0.03 0.02", "Particle 1",
     "particle 1 (centroid 0.002 0.03 0.02 m) reaches 0.003 m across the periodic face x = 0 "
     "m (Periodic, line 6): particles start inside the cell, clear of its faces"),
]


@pytest.mark.parametrize("old, new, where, message", BAD,
                         ids=["order", "empty", "short", "across", "narrow", "outside"])
def test_bad_periodic_cells_are_one_line_errors_at_their_line(tmp_path, old, new, where,
                                                             message):
    deck = tmp_path / "bad.inp"
    text = SHEAR_BOX.read_text()
    assert old in text
    deck.write_text(text.replace(old, new))
    line = next(k for k, ln in enumerate(deck.read_text().splitlines(), 1)
                if ln.strip().startswith(where))
    r = CliRunner().invoke(main, ["check", str(deck)])
    assert r.exit_code != 0
    err = [ln for ln in r.output.splitlines() if "error" in ln]
    assert len(err) == 1 and f"{deck}:{line}: {message}" in err[0], r.output


def test_the_api_checks_as_the_deck_and_writes_the_line_back():
    sim = Simulation()
    with pytest.raises(InputError, match=r"^set_periodic: X needs lo < hi, got 0.06 0$"):
        sim.set_periodic(x=(0.06, 0))
    with pytest.raises(InputError, match=r"^set_periodic: give at least one axis"):
        sim.set_periodic()
    sim.set_periodic(y=(0, 0.5), z=(-0.1, 0.2))
    assert "  Periodic Y 0.0 0.5 Z -0.1 0.2\n" in sim.deck_text

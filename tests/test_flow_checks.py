"""The rules an inlet and the outlets are held to before a run (nurbsdem.flow_checks), the
same for a deck (``nurbsdem check``: an error is one line naming the deck and the entry's
line, exit status non-zero; a warning is one line and the check passes) and for the Python
API (the same message): a region wholly behind a flat wall is an error and one partly behind
it a warning; an outlet that catches positions where an inlet places centroids is an error,
whichever of the two comes first; a region too small for one segment's particles is a
warning that says the inlet will wait."""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from nurbsdem import Simulation, shapes
from nurbsdem.cli import main
from nurbsdem.dynamics.flow import InsertionRegion, Outlet
from nurbsdem.errors import InputError
from nurbsdem.flow_checks import LOOSE_FRACTION, caught_fraction
from nurbsdem.io.deck import build_model

ROOT = Path(__file__).resolve().parents[1]
POUR = ROOT / "tests" / "data" / "flow_pour.inp"
INLET_BOX = "Box 0.005 0.005 0.01 0.055 0.055 0.05"
OUTLET = "Outlet 1 Name corner Box 0 0 0 0.02 0.02 0.012"


def check_deck(tmp_path: Path, *replacements: tuple[str, str]):
    """``nurbsdem check`` of the pour deck with ``replacements``: (result, deck path, line of
    Inlet 1, line of Outlet 1)."""
    text = POUR.read_text()
    for old, new in replacements:
        assert old in text
        text = text.replace(old, new)
    deck = tmp_path / "case.inp"
    deck.write_text(text)
    lines = deck.read_text().splitlines()
    at = {kw: next(k for k, ln in enumerate(lines, 1) if ln.strip().startswith(kw))
          for kw in ("Inlet 1", "Outlet 1")}
    return CliRunner().invoke(main, ["check", str(deck)]), deck, at["Inlet 1"], at["Outlet 1"]


def said(result, kind: str) -> list[str]:
    return [ln for ln in result.output.splitlines() if ln.startswith(f"nurbsdem: {kind}:")]


class Messages(logging.Handler):
    """The messages of the ``nurbsdem`` logger while it is attached."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


def api_scene() -> Simulation:
    sim = Simulation(gravity=(0, 0, -9.81), output=None, quiet=True)
    sim.add_material(1, density=2500.0)
    sim.add_interface(normal_penalty=1e4, normal_damping=0.5, tangential_penalty=1e4,
                      friction=0.3)
    sim.add_box((0, 0, 0), (0.06, 0.06, 0.12))
    return sim


# ---------------------------------------------------------------------------- walls


def test_a_disc_wholly_behind_a_wall_is_a_one_line_error(tmp_path):
    r, deck, line, _ = check_deck(tmp_path, (INLET_BOX, "Disc 0.1 0.03 0.03 Normal 1 0 0 "
                                                        "Radius 0.02"))
    assert r.exit_code != 0 and "Traceback" not in r.output
    assert said(r, "error") == [f"nurbsdem: error: {deck}:{line}: Inlet 1: its Disc lies "
                                f"wholly outside the walls (behind wall 'x_max'): every "
                                f"particle would start outside them"], r.output


def test_a_region_partly_behind_a_wall_or_too_small_warns_the_same_for_deck_and_api(tmp_path):
    box = (-0.01, 0.005, 0.01, 0.025, 0.035, 0.03)   # 35 x 30 x 20 mm, 10 mm behind x_min
    r, deck, line, _ = check_deck(tmp_path, (INLET_BOX, "Box " + " ".join(map(str, box))))
    assert r.exit_code == 0, r.output
    warnings = said(r, "warning")
    assert len(warnings) == 2, r.output
    assert warnings[0] == (f"nurbsdem: warning: {deck}:{line}: Inlet 1: its Box lies partly "
                           f"outside the walls (behind wall 'x_min'): particles placed there "
                           f"start outside the walls or pressed into that wall")
    # 15 particles per 10 ms segment, half of each shape, in 2.1e-5 m^3
    radii = [e.bounding_radius for e in build_model(deck.read_text(), str(deck)).shapes.values()]
    fill = 15 * 0.5 * 4 / 3 * np.pi * sum(r ** 3 for r in radii) / (0.035 * 0.03 * 0.02)
    assert fill > LOOSE_FRACTION
    assert warnings[1].startswith(f"nurbsdem: warning: {deck}:{line}: Inlet 1: its Box "
                                  f"(2.1e-05 m^3) cannot hold the 15 particles one segment "
                                  f"of 0.01 s must insert at Rate 1500 per s: their bounding "
                                  f"spheres would fill {100 * fill:.3g} % of it")
    assert "random loose packing" in warnings[1] and "the inlet will wait" in warnings[1]

    sim = api_scene()
    sim.add_inlet([shapes.sphere(0.005), shapes.sphere(0.004)], 1, box, rate=1500, count=60,
                  fractions=(0.5, 0.5), velocity=(0, 0, -1), seed=4, name="feed")
    sim.add_outlet(box=(0, 0, 0, 0.02, 0.02, 0.012), name="corner")
    seen = Messages()
    logging.getLogger("nurbsdem").addHandler(seen)
    try:
        sim.run_dynamic(0.002, 1e-3)
    finally:
        logging.getLogger("nurbsdem").removeHandler(seen)
        sim.close()
    prefix = f"nurbsdem: warning: {deck}:{line}: "
    assert [m for m in seen.messages if m.startswith("Inlet 1")] == \
        [w[len(prefix):] for w in warnings]


# ---------------------------------------------------------------------------- outlets


@pytest.mark.parametrize("outlet", ["Box 0 0 0 0.06 0.06 0.03", "Point 0 0 0.03 Normal 0 0 -1"],
                         ids=["box", "plane"])
def test_an_outlet_that_catches_an_inlet_is_an_error_at_its_line_as_in_the_api(tmp_path,
                                                                               outlet):
    r, deck, _, line = check_deck(tmp_path, (OUTLET, "Outlet 1 Name corner " + outlet))
    assert r.exit_code != 0 and "Traceback" not in r.output
    errors = said(r, "error")
    assert len(errors) == 1 and errors[0].startswith(
        f"nurbsdem: error: {deck}:{line}: Outlet 1: "), r.output
    message = errors[0].split(f"{deck}:{line}: ", 1)[1]
    assert "of the positions where Inlet 1 (feed) places particle centroids: the particles " \
           "inserted there are removed at the next segment end" in message
    words = outlet.split()
    where = ({"box": [float(w) for w in words[1:]]} if words[0] == "Box" else
             {"point": [float(w) for w in words[1:4]], "normal": [float(w) for w in words[5:]]})
    for outlet_first in (False, True):
        sim = api_scene()
        if outlet_first:
            sim.add_outlet(**where, name="corner")
        with pytest.raises(InputError) as err:
            sim.add_inlet([shapes.sphere(0.005), shapes.sphere(0.004)], 1,
                          (0.005, 0.005, 0.01, 0.055, 0.055, 0.05), rate=1500, count=60,
                          fractions=(0.5, 0.5), seed=4, name="feed")
            sim.add_outlet(**where, name="corner")
        assert str(err.value) == message


def test_the_caught_fraction_is_that_of_the_centroid_positions():
    """The centroids of particles of bounding radius 1 lie in [1, 9] of a [0, 10] box: a
    plane at 3 catches a quarter of them, one at 1 none, a box around [0, 5] half."""
    region = InsertionRegion(lo=np.zeros(3), hi=np.full(3, 10.0))
    plane = Outlet("low", point=np.array([0, 0, 3.0]), normal=np.array([0, 0, -1.0]))
    assert caught_fraction(region, 1.0, plane) == pytest.approx(0.25, abs=0.03)
    edge = Outlet("edge", point=np.array([0, 0, 1.0]), normal=np.array([0, 0, -1.0]))
    assert caught_fraction(region, 1.0, edge) == 0.0
    half = Outlet("half", lo=np.full(3, -1.0), hi=np.array([11, 11, 5.0]))
    assert caught_fraction(region, 1.0, half) == pytest.approx(0.5, abs=0.03)

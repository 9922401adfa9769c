"""inputs/hopper/hopper.inp, in a short version (60 spheres, shorter steps): a conical hopper
(an exact NURBS cone) closed by a flat gate is filled by an inlet; at rest the cone and the
gate carry the weight of the spheres (the vertical balance of the wall loads, a Janssen-like
check); the gate slides away and every sphere leaves through the outlet below."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from nurbsdem.simulation import Simulation

HOPPER = Path(__file__).resolve().parents[1] / "inputs" / "hopper"
RADIUS, DENSITY, G, COUNT = 0.003, 2500.0, 9.81, 60


def _short(tmp_path: Path) -> Path:
    """The deck with 60 spheres and steps of 0.25, 0.1, 0.05 and 0.15 s."""
    text = (HOPPER / "hopper.inp").read_text()
    for old, new in (("Count 200", f"Count {COUNT}"),
                     ("Step 1 Dynamic Duration 0.4", "Step 1 Dynamic Duration 0.25"),
                     ("Step 2 Dynamic Duration 0.2", "Step 2 Dynamic Duration 0.1"),
                     ("Step 4 Dynamic Duration 0.35", "Step 4 Dynamic Duration 0.15")):
        assert old in text, old
        text = text.replace(old, new)
    shutil.copy(HOPPER / "cone.yaml", tmp_path / "cone.yaml")
    deck = tmp_path / "hopper.inp"
    deck.write_text(text)
    return deck


def _csv(path: Path) -> np.ndarray:
    return np.genfromtxt(path, delimiter=",", names=True)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("hopper")
    Simulation.from_deck(_short(tmp), output=tmp / "out").run()
    return tmp / "out" / "monitors"


def test_at_rest_the_cone_and_the_gate_carry_the_weight(run):
    """Over the last 0.05 s before the gate opens (t in [0.3, 0.35] s) the vertical wall
    loads average to the spheres' weight N m g within 2 % (their momentum barely changes);
    both walls carry a share of it."""
    cone, gate = _csv(run / "wall_hopper.csv"), _csv(run / "wall_gate.csv")
    weight = COUNT * DENSITY * 4.0 / 3.0 * np.pi * RADIUS ** 3 * G
    window = (cone["time"] > 0.3 - 1e-9) & (cone["time"] < 0.35 + 1e-9)
    total = cone["reaction_z"][window] + gate["reaction_z"][window]
    assert total.mean() == pytest.approx(weight, rel=0.02)
    assert cone["reaction_z"][window].mean() > 0.05 * weight
    assert gate["reaction_z"][window].mean() > 0.05 * weight


def test_every_sphere_is_poured_and_discharged(run):
    """The inlet inserts all 60 spheres; none leaves before the gate opens; by the end the
    outlet has taken all of them, with their mass; the energy balance stays closed."""
    feed, out = _csv(run / "inlet_feed.csv"), _csv(run / "outlet_below.csv")
    mass = DENSITY * 4.0 / 3.0 * np.pi * RADIUS ** 3
    assert feed["inserted"][-1] == COUNT
    assert out["count"][out["time"] < 0.35 + 1e-9].max() == 0
    assert out["count"][-1] == COUNT
    assert out["mass"][-1] == pytest.approx(COUNT * mass, rel=1e-12)
    energy = _csv(run / "energy.csv")
    scale = np.abs(energy["external_work"]).max() + np.abs(energy["potential"]).max()
    assert np.abs(energy["balance_error"]).max() < 1e-2 * scale


@pytest.mark.slow
def test_paper_particles_at_rest_in_the_hopper(tmp_path):
    """inputs/hopper/hopper_paper.inp: the paper's particles A, B, C (7, 4, 9) settle in a
    conical NURBS hopper (a NURBS surface wall) closed by a flat gate. Over the last 0.2 s
    the vertical loads of the cone and the gate average to the particles' weight within 1 %
    (a vertical force balance: at rest the walls hold the weight): not exactly, since the
    pack still creeps (its residual motion's momentum change, kinetic energy ~1e-5 J, and
    the dashpot forces of its slowly moving contacts); the cone carries a share of it (its
    inclined normal and the wall friction: the Janssen-like load); no contact fails; the
    energy balance closes to 1 % of the energy turned over; the pack ends at rest."""
    from nurbsdem.io.shapefile import load_shape
    deck = HOPPER / "hopper_paper.inp"
    summary = Simulation.from_deck(deck, output=tmp_path / "out").run()
    mons = tmp_path / "out" / "monitors"
    cone, gate = _csv(mons / "wall_hopper.csv"), _csv(mons / "wall_gate.csv")
    shapes = HOPPER.parent / "shapes"
    volume = sum(n * load_shape(shapes / f"{s}.yaml").volume
                 for s, n in (("A", 7), ("B", 4), ("C", 9)))
    weight = volume * 2700.0 * G
    window = cone["time"] > cone["time"][-1] - 0.2 - 1e-9
    total = cone["reaction_z"][window] + gate["reaction_z"][window]
    share = cone["reaction_z"][window].mean() / weight
    print(f"weight {weight:.6g} N, walls/weight {total.mean() / weight:.6f}, cone share "
          f"{share:.4f}, balance {summary.balance_error:.3g} of {summary.balance_scale:.3g} J")
    assert total.mean() == pytest.approx(weight, rel=0.01)
    assert share > 0.05
    assert summary.failed == 0
    assert abs(summary.balance_error) < 1e-2 * abs(summary.balance_scale)
    energy = _csv(mons / "energy.csv")
    assert energy["kinetic"][-1] < 1e-4 * (energy["potential"][0] - energy["potential"][-1])

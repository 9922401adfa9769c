"""Inlets and outlets in a run (nurbsdem.flow_run): a pour by the Python API inserts its
count without overlaps and keeps its mass in the box; an outlet under falling particles
accounts for every particle and its mass with the energy balance closed, the scenes of
its exchanges sharing one contact table, and its exchanges are timed once
(``inlets + outlets``); a pour deck run by
``nurbsdem solve`` and restarted mid-pour ends bit for bit where the uninterrupted run ends;
bad Flow entries are one-line errors at their line; the history keys follow the new count."""
from __future__ import annotations

import csv
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from nurbsdem import Simulation, shapes
from nurbsdem.cli import main
from nurbsdem.contact.detect import ContactTable
from nurbsdem.errors import InputError
from nurbsdem.flow_run import FlowRun, remap_history
from nurbsdem.io.deck import build_model, parse_deck
from nurbsdem.solver import Solver
from runs import assert_same_final_state, killed_and_restarted

ROOT = Path(__file__).resolve().parents[1]
POUR = ROOT / "tests" / "data" / "flow_pour.inp"


def rows(path: Path) -> list[dict[str, float]]:
    with open(path) as fh:
        return [{k: float(v) for k, v in r.items()} for r in csv.DictReader(fh)]


def test_a_pour_inserts_its_count_without_overlap_and_keeps_its_mass(tmp_path, monkeypatch):
    inserted = []
    original = FlowRun.insert

    def spy(self, t, bodies):
        added = original(self, t, bodies)
        inserted.append((bodies.copy(), added.copy()))
        return added
    monkeypatch.setattr(FlowRun, "insert", spy)
    r = 0.004
    sim = Simulation(gravity=(0, 0, -9.81), output=tmp_path / "out", quiet=True)
    sim.add_material(1, density=2500.0)
    sim.add_interface(normal_penalty=1e4, normal_damping=0.5, tangential_penalty=1e4,
                      friction=0.3)
    sim.add_box((0, 0, 0), (0.05, 0.05, 0.15))
    sim.add_inlet([shapes.sphere(r)], 1, (0.004, 0.004, 0.1, 0.046, 0.046, 0.12), rate=1000,
                  count=40, velocity=(0, 0, -1), seed=2, name="feed")
    sim.run_dynamic(0.07, 1e-3)
    bodies = sim.bodies
    in_box = sum(sim.model.shapes[int(k)].mass(2500.0) for k in bodies.shape_id)
    sim.close()
    assert len(bodies) == 40 and len(set(bodies.id.tolist())) == 40
    for present, added in inserted:
        x = np.concatenate([present.position, added.position])
        d = np.linalg.norm(x[:, None] - x[None], axis=2)
        np.fill_diagonal(d, np.inf)
        assert np.all(d[len(present):] >= 2 * r)            # bounding spheres apart
    inlet = rows(tmp_path / "out" / "monitors" / "inlet_feed.csv")
    mass = 2500.0 * 4 / 3 * np.pi * r ** 3
    assert inlet[-1]["inserted"] == 40 and inlet[-1]["waiting"] == 0
    assert inlet[-1]["mass"] == pytest.approx(40 * mass, rel=1e-3)   # the exact sphere's volume
    assert inlet[-1]["mass"] == pytest.approx(in_box, rel=1e-12)
    assert np.all((bodies.position > 0) & (bodies.position < [0.05, 0.05, 0.15]))


OUTFLOW = """\
Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2500
Shapes
  Shape 1 Sphere Radius 0.005
  Shape 2 Sphere Radius 0.004
Particles
  Random 1 Shapes 1 2 Counts 12 12 Material 1 Region 0 0 0.02 0.05 0.05 0.2 Seed 3
Contact
  Interface 1 NormalPenalty 1e4 NormalDamping 0.2 TangentialPenalty 1e4 Friction 0.3
Steps
  Step 1 Dynamic Duration 0.15 TimeStep 1e-3
Flow
  Outlet 1 Name floor Point 0 0 0 Normal 0 0 -1 Every 0.005
Output
  Monitors Every 0.005
"""


def test_an_outlet_accounts_for_every_particle_and_the_energy_balance_stays_closed(
        tmp_path, monkeypatch):
    deck = tmp_path / "outflow.inp"
    deck.write_text(OUTFLOW)
    model = parse_deck(deck)
    start = model.bodies.copy()
    tables = []
    original = ContactTable.__init__
    monkeypatch.setattr(ContactTable, "__init__",
                        lambda self, shapes: (tables.append(1), original(self, shapes))[1])
    solver = Solver(model, output=tmp_path / "out", quiet=True)
    rebuild, calls, pause = solver.rebuild, [], 0.02

    def slow_rebuild(*args):                # a rebuild that takes at least `pause` s
        calls.append(time.sleep(pause))
        rebuild(*args)
    solver.rebuild = slow_rebuild
    summary = solver.run()
    # the exchanges, their rebuilt systems included, are booked once, in their own timer
    assert summary.timers["inlets + outlets"] >= pause * len(calls) > 0
    assert sum(summary.timers.values()) <= summary.wall_time
    out = rows(tmp_path / "out" / "monitors" / "outlet_floor.csv")
    assert solver.scene is not None and len(tables) == 1    # one table for every exchange
    left = len(solver.bodies)
    assert 0 < out[-1]["count"] < len(start) and out[-1]["count"] + left == len(start)

    def mass(b):
        return sum(model.shapes[int(s)].mass(2500.0) for s in b.shape_id)
    assert out[-1]["mass"] + mass(solver.bodies) == pytest.approx(mass(start), rel=1e-12)
    gone = sorted(set(start.id.tolist()) - set(solver.bodies.id.tolist()))
    assert len(gone) == out[-1]["count"]
    energy = rows(tmp_path / "out" / "monitors" / "energy.csv")
    scale = max(abs(e["external_work"]) + abs(e["kinetic"]) for e in energy)
    assert abs(energy[-1]["external_work"]) > 0.1 * scale     # the outflow took energy out
    assert max(abs(e["balance_error"]) for e in energy) < 1e-3 * scale


@pytest.mark.parametrize("kill_after", [0.03, 0.055], ids=["between", "at_an_exchange"])
def test_a_pour_deck_restarted_mid_pour_ends_bit_for_bit(tmp_path, monkeypatch, kill_after):
    """Restarted from the checkpoint at 0.025 s, and from the one at 0.05 s, written just
    after an exchange (its new system's carried-over time-step control in it)."""
    ref = tmp_path / "ref"
    r = CliRunner().invoke(main, ["solve", str(POUR), "--output", str(ref), "--quiet"])
    assert r.exit_code == 0, r.output
    inlet = rows(ref / "monitors" / "inlet_feed.csv")
    assert inlet[-1]["inserted"] > inlet[0]["inserted"] > 0
    out = tmp_path / "out"
    killed_and_restarted(POUR, out, kill_after, monkeypatch)
    assert_same_final_state(out, ref, ("energy.csv", "contacts.csv", "inlet_feed.csv",
                                       "outlet_corner.csv"))


BAD = [
    ("Box 0.005 0.005 0.01 0.055 0.055 0.05", "Box -0.06 0.005 0.01 -0.01 0.055 0.05",
     "Inlet 1: its Box lies wholly outside the walls (behind wall 'x_min')"),
    ("Fractions 0.5 0.5", "Fractions 0.5 0.4", "Inlet 1: Fractions must sum to 1, got 0.9"),
    ("Shapes 1 2", "Shapes 1 7", "Inlet 1: unknown shape 7 (defined shapes: 1, 2)"),
]


@pytest.mark.parametrize("old, new, message", BAD, ids=["outside", "fractions", "shape"])
def test_bad_flow_entries_are_one_line_errors_at_their_line(tmp_path, old, new, message):
    deck = tmp_path / "bad.inp"
    text = POUR.read_text()
    assert old in text
    deck.write_text(text.replace(old, new))
    line = next(k for k, ln in enumerate(deck.read_text().splitlines(), 1)
                if ln.strip().startswith("Inlet 1"))
    r = CliRunner().invoke(main, ["check", str(deck)])
    assert r.exit_code != 0
    err = [ln for ln in r.output.splitlines() if "error" in ln]
    assert len(err) == 1 and f"{deck}:{line}: {message}" in err[0], r.output


def test_the_python_api_checks_as_the_deck_does():
    sim = Simulation()
    sim.add_material(1, density=1000.0)
    sim.add_interface(normal_penalty=1e4)
    sim.add_box((0, 0, 0), (1, 1, 1))
    ball = shapes.sphere(0.01)
    with pytest.raises(InputError, match="Fractions must sum to 1"):
        sim.add_inlet([ball, shapes.sphere(0.02)], 1, (0.1, 0.1, 0.1, 0.9, 0.9, 0.9), 10, 5,
                      fractions=(0.3, 0.3))
    with pytest.raises(InputError, match="wholly outside the walls .behind wall"):
        sim.add_inlet([ball], 1, (0.1, 0.1, -0.5, 0.9, 0.9, -0.1), 10, 5)
    with pytest.raises(InputError, match="unknown material 2"):
        sim.add_inlet([ball], 2, (0.1, 0.1, 0.1, 0.9, 0.9, 0.9), 10, 5)
    with pytest.raises(InputError, match="either Box, or Point and Normal"):
        sim.add_outlet(box=(0, 0, 0, 1, 1, 1), point=(0, 0, 0), normal=(0, 0, -1))
    assert sim.add_inlet([ball], 1, (0.1, 0.1, 0.1, 0.9, 0.9, 0.9), 10, 5) == "inlet1"
    assert sim.add_outlet(point=(0, 0, 0.05), normal=(0, 0, -1), name="low") == "low"
    again = build_model(sim.deck_text, "scene.inp")
    assert [i.name for i in again.inlets] == ["inlet1"]
    assert [o.name for o in again.outlets] == ["low"]


def test_history_keys_follow_the_new_particle_count():
    # 4 particles, 2 flat walls, 1 curved wall (the last): particle 1 removed, 2 added
    n, walls, curved = 4, 3, 1
    nb = n + walls
    keys = np.array([0 * nb + 2, 1 * nb + 3, 2 * nb + 3, 3 * nb + 4, 0 * nb + 6,
                     nb * nb + (3 * 1 + 0) * 8 + 1], np.int64)
    springs = np.arange(len(keys) * 3, dtype=float).reshape(-1, 3)
    new_index = np.array([0, -1, 1, 2])
    k2, s2 = remap_history(keys, springs, new_index, 5, walls, curved)
    nb2 = 5 + walls
    expect = {0 * nb2 + 1: 0, 1 * nb2 + 2: 2, 2 * nb2 + 5: 3, 0 * nb2 + 7: 4,
              nb2 * nb2 + (2 * 1 + 0) * 8 + 1: 5}
    assert k2.tolist() == sorted(expect)
    for key, row in zip(k2.tolist(), s2):
        np.testing.assert_array_equal(row, springs[expect[key]])

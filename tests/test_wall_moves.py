"""Several walls in one MoveWall step (``Step`` lines of one id; ``move_wall([...])``,
:mod:`nurbsdem.wall_moves`): a floor and a lid that squeeze a sphere symmetrically push it
with equal and opposite forces and it stays where it is; the deck's lines read back; a
further line with timing keys, or a wall moved twice, is a one-line error."""
from __future__ import annotations

import csv
import re

import numpy as np
import pytest

import nurbsdem.shapes
from nurbsdem import Simulation
from nurbsdem.errors import InputError
from nurbsdem.io.deck import build_model
from nurbsdem.io.deck_format import format_model
from nurbsdem.model import model_differences

#: a floor and a lid 0.0202 m apart, 0.1 mm from a sphere (r = 1 cm) at the middle
WALLS = """  Wall 1 Name floor Point 0 0 -0.0101 Normal 0 0 1 Size 0.2 0.2
  Wall 2 Name lid Point 0 0 0.0101 Normal 0 0 -1 Size 0.2 0.2"""
SQUEEZE = """  Step 1 MoveWall lid Displacement 0 0 -0.0002 Duration 0.2 TimeStep 1e-3
  Step 1 MoveWall floor Displacement 0 0 0.0002"""


def _deck(path, steps: str = SQUEEZE, output: str = "") -> object:
    deck = path / "case.inp"
    deck.write_text(f"""Environment
  Gravity 0 0 0
Materials
  Material 1 Density 2500
Shapes
  Shape 1 Sphere Radius 0.01
Particles
  Particle 1 Shape 1 Material 1 Position 0 0 0 AngularVelocity 0 0 100
Walls
{WALLS}
Contact
  Interface 1 NormalPenalty 1e5 NormalDamping 5 TangentialPenalty 1e5 Friction 0.3
Steps
{steps}
Output
  Monitors Every 0.05
{output}""")
    return deck


def _rows(path) -> list[dict]:
    return [{k: float(v) for k, v in r.items()} for r in csv.DictReader(open(path))]


def test_two_walls_squeezing_a_sphere_push_equally_and_it_stays(tmp_path):
    """A floor and a lid 0.1 mm from a sphere (r = 1 cm) spinning about the vertical between
    them close in on it by 0.2 mm each in one step: at the end each presses 0.1 mm into it
    (k δ = 10 N); the lid's force is the floor's reversed and the sphere has not moved
    (the spin, on the contacts' axis, gives the energy a scale and slides no contact);
    ``move_wall`` with a list writes the same monitors, and its deck text is the deck's."""
    deck = _deck(tmp_path)
    sim = Simulation.from_deck(deck)
    sim.run()
    lid = _rows(tmp_path / "results" / "monitors" / "wall_lid.csv")
    floor = _rows(tmp_path / "results" / "monitors" / "wall_floor.csv")
    assert lid[-1]["displacement_z"] == -0.0002 and floor[-1]["displacement_z"] == 0.0002
    assert lid[-1]["reaction_z"] == pytest.approx(-10.0, rel=1e-2)     # the lid pushes down
    for a, b in zip(lid, floor):
        for c in "xyz":
            assert a[f"reaction_{c}"] == pytest.approx(-b[f"reaction_{c}"], rel=1e-12,
                                                       abs=1e-12)        # 1e-13 of 10 N
    np.testing.assert_allclose(sim.positions[0], [0, 0, 0], rtol=0, atol=1e-14)
    np.testing.assert_allclose(sim.velocities[0], [0, 0, 0], rtol=0, atol=1e-12)

    api = Simulation(gravity=(0, 0, 0), output=tmp_path / "api", monitors_every=0.05)
    api.add_material(1, density=2500)
    api.add_interface(normal_penalty=1e5, normal_damping=5, tangential_penalty=1e5,
                      friction=0.3)
    api.add_particle(nurbsdem.shapes.sphere(0.01), 1, (0, 0, 0), angular_velocity=(0, 0, 100))
    api.add_wall("floor", point=(0, 0, -0.0101), normal=(0, 0, 1), size=(0.2, 0.2))
    api.add_wall("lid", point=(0, 0, 0.0101), normal=(0, 0, -1), size=(0.2, 0.2))
    api.move_wall([("lid", dict(displacement=(0, 0, -0.0002))),
                   ("floor", dict(displacement=(0, 0, 0.0002)))],
                  duration=0.2, time_step=1e-3)
    api.close()
    assert _rows(tmp_path / "api" / "monitors" / "wall_lid.csv") == lid
    step = build_model(api.deck_text, str(tmp_path / "again.inp")).steps[0]
    assert [m.wall for m in step.moves()] == ["lid", "floor"]
    assert model_differences(build_model(format_model(sim.model), str(deck)), sim.model) == []


@pytest.mark.parametrize("steps, message", [
    (SQUEEZE + " Duration 0.2", "Step 1: Duration belongs on the step's first line (line 15)"),
    (SQUEEZE.replace("floor", "lid"), "Step 1: wall 'lid' moves twice in this step"),
    ("  Step 1 MoveWall lid ToContact\n  Step 1 MoveWall floor Displacement 0 0 0.01",
     "Step 1: a ToContact step moves one wall"),
    ("  Step 1 Dynamic Duration 0.1 TimeStep 1e-3\n  Step 1 MoveWall floor Displacement 0 0 1",
     "duplicate step id 1"),
], ids=["timing", "twice", "to-contact", "not-a-move"])
def test_bad_further_lines_are_errors_at_their_line(tmp_path, steps, message):
    """A further line of a step: the timing is the first line's, each wall moves once, only
    a timed MoveWall step takes more walls (else the id repeats: the usual error)."""
    deck = _deck(tmp_path, steps)
    with pytest.raises(InputError, match=re.escape(f"case.inp:16: {message}")):
        build_model(deck.read_text(), str(deck))


def test_api_list_errors():
    """``move_wall`` with a list: each item a (name, motion dict) pair, no motion outside."""
    sim = Simulation(gravity=(0, 0, 0))
    sim.add_material(1, density=2500)
    sim.add_interface(normal_penalty=1e5)
    sim.add_particle(nurbsdem.shapes.sphere(0.01), 1, (0, 0, 0))
    sim.add_wall("floor", point=(0, 0, -0.05), normal=(0, 0, 1), size=(0.2, 0.2))
    sim.add_wall("lid", point=(0, 0, 0.05), normal=(0, 0, -1), size=(0.2, 0.2))
    with pytest.raises(InputError, match="each wall of the list is"):
        sim.move_wall([("lid", (0, 0, -0.01))], duration=0.1, time_step=1e-3)
    with pytest.raises(InputError, match="moves twice"):
        sim.move_wall([("lid", dict(displacement=(0, 0, -0.01))),
                       ("lid", dict(displacement=(0, 0, 0.01)))], duration=0.1, time_step=1e-3)
    with pytest.raises(InputError, match="each wall's motion is in its own dict"):
        sim.move_wall([("lid", dict(displacement=(0, 0, -0.01)))], displacement=(0, 0, 1),
                      duration=0.1, time_step=1e-3)
    assert sim.model.steps == []


def test_restart_inside_a_step_of_two_walls_is_bit_for_bit(tmp_path, monkeypatch):
    """The lid follows a table (down, back up a little) while the floor rises, after a step
    in which the floor moved alone: a run killed inside the two-wall step and restarted
    from its checkpoint ends as the run straight through, monitors and all."""
    import sys
    from pathlib import Path
    sys.path.insert(0, str(Path(__file__).parent))
    from runs import assert_same_final_state, killed_and_restarted
    (tmp_path / "lid.csv").write_text("t,x,y,z\n0,0,0,0\n0.03,0,0,-0.00025\n"
                                      "0.04,0,0,-0.0002\n")
    deck = _deck(tmp_path, "  Step 1 MoveWall floor Displacement 0 0 0.00005 Duration 0.02 "
                           "TimeStep 1e-3\n"
                           "  Step 2 MoveWall lid Table lid.csv TimeStep 1e-3\n"
                           "  Step 2 MoveWall floor Displacement 0 0 0.00015",
                 "  Results Every 0.01\n  Checkpoint Every 0.01\n")
    ref, out = tmp_path / "ref", tmp_path / "out"
    Simulation.from_deck(deck, output=ref).run()
    killed_and_restarted(deck, out, 0.035, monkeypatch)
    assert_same_final_state(out, ref, ("wall_lid.csv", "wall_floor.csv", "energy.csv"))
    floor = _rows(ref / "monitors" / "wall_floor.csv")[-1]        # t = 0.05 s
    assert floor["time"] == 0.05
    assert floor["displacement_z"] == pytest.approx(0.00005 + 0.75 * 0.00015, rel=1e-12)
    assert _rows(ref / "monitors" / "wall_lid.csv")[-1]["displacement_z"] == -0.00025


def test_a_wall_pushing_a_resting_sphere_without_gravity_runs(tmp_path):
    """Without gravity or motion a scene's energy scale is ~0 J; the walls' work counts in the
    guard's scale, so the round-off of the first push does not stop the run as unstable.  A
    sphere at rest between a floor and a lid, both closing in on it: it is squeezed without
    moving, and the energy balance closes to the guard's tolerance of the wall work."""
    deck = _deck(tmp_path)
    deck.write_text(deck.read_text().replace(" AngularVelocity 0 0 100", ""))
    sim = Simulation.from_deck(deck)
    sim.run()
    lid = _rows(tmp_path / "results" / "monitors" / "wall_lid.csv")
    assert lid[-1]["reaction_z"] == pytest.approx(-10.0, rel=1e-2)
    np.testing.assert_allclose(sim.positions[0], [0, 0, 0], rtol=0, atol=1e-14)
    energy = _rows(tmp_path / "results" / "monitors" / "energy.csv")[-1]
    assert energy["external_work"] > 0
    assert abs(energy["balance_error"]) <= 1e-6 * energy["external_work"]

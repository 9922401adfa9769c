"""Servo walls (``MoveWall NAME Force F MaxSpeed v Gain g``, :mod:`nurbsdem.wall_servo`): a
lid servo-pressing a sphere that rests on a floor under gravity ends pressing it with F and
the floor bears F plus the sphere's weight; the lid never moves faster than MaxSpeed; the
deck's line reads back and ``move_wall(force=...)`` writes the same monitors; a mesh lid
driven along a Direction presses as the flat lid does; bad entries are one-line errors; a
restart inside a servo step is bit for bit."""
from __future__ import annotations

import csv
import math

import numpy as np
import pytest

import nurbsdem.shapes
from nurbsdem import Simulation
from nurbsdem.errors import InputError
from nurbsdem.io.deck import build_model
from nurbsdem.io.deck_format import format_model
from nurbsdem.model import model_differences

F, V, G = 1.0, 0.003, 0.004          # N, m/s, m/(s N): 1 / (50 k/2 DT), k = 1e5 N/m
SERVO = f"  Step 1 MoveWall lid Force {F} MaxSpeed {V} Gain {G} Duration 0.08 TimeStep 1e-4"
RHO, R, GRAV = 2500.0, 0.01, 9.81


def _deck(path, steps: str = SERVO, output: str = "", walls: str = "") -> object:
    """A sphere (r = 1 cm) resting on a floor, a lid 0.05 mm above it."""
    deck = path / "case.inp"
    deck.write_text(f"""Environment
  Gravity 0 0 -{GRAV}
Materials
  Material 1 Density {RHO}
Shapes
  Shape 1 Sphere Radius {R}
Particles
  Particle 1 Shape 1 Material 1 Position 0 0 -0.0001
Walls
  Wall 1 Name floor Point 0 0 -0.0101 Normal 0 0 1 Size 0.2 0.2
  Wall 2 Name lid Point 0 0 0.00995 Normal 0 0 -1 Size 0.2 0.2
{walls}
Contact
  Interface 1 NormalPenalty 1e5 NormalDamping 20 TangentialPenalty 1e5 Friction 0.3
Steps
{steps}
Output
  Monitors Every 0.001
{output}""")
    return deck


def _api(output=None, mesh=None) -> Simulation:
    """The deck's scene (:func:`_deck`) made by the API, without steps; ``mesh``: an STL file
    for a mesh wall ``plate``."""
    sim = Simulation(gravity=(0, 0, -GRAV), output=output, monitors_every=0.001)
    sim.add_material(1, density=RHO)
    sim.add_interface(normal_penalty=1e5, normal_damping=20, tangential_penalty=1e5,
                      friction=0.3)
    sim.add_particle(nurbsdem.shapes.sphere(R), 1, (0, 0, -0.0001))
    sim.add_wall("floor", point=(0, 0, -0.0101), normal=(0, 0, 1), size=(0.2, 0.2))
    sim.add_wall("lid", point=(0, 0, 0.00995), normal=(0, 0, -1), size=(0.2, 0.2))
    if mesh is not None:
        sim.add_mesh_wall("plate", mesh)
    return sim


def _build(deck):
    return build_model(deck.read_text(), str(deck))


def _rows(path) -> list[dict]:
    return [{k: float(v) for k, v in r.items()} for r in csv.DictReader(open(path))]


def test_a_servo_lid_presses_a_resting_sphere_with_its_force(tmp_path):
    """The lid closes the 0.05 mm gap at MaxSpeed, then presses the sphere until it pushes
    back with F: at the end the lid's reaction along its normal is F (1 %), the floor's F
    plus the sphere's weight (1 %), and between monitor rows the lid never went faster than
    MaxSpeed (it did go at MaxSpeed while closing the gap)."""
    Simulation.from_deck(_deck(tmp_path)).run()
    mon = tmp_path / "results" / "monitors"
    lid, floor = _rows(mon / "wall_lid.csv"), _rows(mon / "wall_floor.csv")
    weight = RHO * 4.0 / 3.0 * math.pi * R ** 3 * GRAV
    assert lid[-1]["time"] == pytest.approx(0.08)
    assert -lid[-1]["reaction_z"] == pytest.approx(F, rel=1e-2)
    assert floor[-1]["reaction_z"] == pytest.approx(F + weight, rel=1e-2)
    t = np.array([r["time"] for r in lid])
    z = np.array([r["displacement_z"] for r in lid])
    speed = np.abs(np.diff(z)) / np.diff(t)
    assert speed.max() <= V * (1 + 1e-9)
    assert speed.max() >= 0.99 * V


def test_the_deck_reads_back_and_the_api_writes_the_same_monitors(tmp_path):
    """``format_model`` writes the servo line back as it was read; ``move_wall(force=...)``
    on the deck's model without steps gives the deck's monitors, to the bit."""
    deck = _deck(tmp_path, SERVO.replace("0.08", "0.01"))
    model = _build(deck)
    again = tmp_path / "again.inp"
    again.write_text(format_model(model))
    assert not model_differences(model, _build(again))
    Simulation.from_deck(deck, output=tmp_path / "deck").run()
    sim = _api(tmp_path / "api")
    sim.move_wall("lid", force=F, max_speed=V, gain=G, duration=0.01, time_step=1e-4)
    sim.close()
    for name in ("wall_lid.csv", "wall_floor.csv", "energy.csv"):
        assert ((tmp_path / "api" / "monitors" / name).read_text()
                == (tmp_path / "deck" / "monitors" / name).read_text()), name


@pytest.mark.parametrize("line, message", [
    ("MoveWall lid Force 1 MaxSpeed 0 Gain 0.1 Duration 0.01 TimeStep 1e-4",
     "MaxSpeed must be > 0"),
    ("MoveWall lid Force 1 MaxSpeed 0.1 Gain -1 Duration 0.01 TimeStep 1e-4",
     "Gain must be >= 0"),
    ("MoveWall lid Force 1 Gain 0.1 Duration 0.01 TimeStep 1e-4", "missing MaxSpeed"),
    ("MoveWall lid Force 1 MaxSpeed 0.1 Gain 0.1 Displacement 0 0 1 Duration 0.01 "
     "TimeStep 1e-4", "exactly one of"),
    ("MoveWall lid Force 1 MaxSpeed 0.1 Gain 0.1 Center 0 0 0 Duration 0.01 TimeStep 1e-4",
     "Center does not apply to MoveWall Force"),
])
def test_bad_servo_entries_are_one_line_errors(tmp_path, line, message):
    deck = _deck(tmp_path, f"  Step 1 {line}")
    with pytest.raises(InputError) as err:
        _build(deck)
    text = str(err.value)
    assert message in text and "\n" not in text
    assert "case.inp:16: Step 1: " in text


def _plate(path, z: float = 0.00995):
    """An STL square of side 0.2 m at height z (m): two triangles, the flat lid's rectangle."""
    stl = path / "plate.stl"
    tri = [((-0.1, -0.1), (0.1, -0.1), (0.1, 0.1)), ((-0.1, -0.1), (0.1, 0.1), (-0.1, 0.1))]
    stl.write_text("solid p\n" + "".join(
        "facet normal 0 0 -1\nouter loop\n" + "".join(f"vertex {x} {y} {z}\n" for x, y in t)
        + "endloop\nendfacet\n" for t in tri) + "endsolid p\n")
    return stl


def test_a_mesh_lid_with_a_direction_is_the_flat_lids_servo(tmp_path):
    """A mesh plate in the flat lid's place (the same square as two triangles), servo-driven
    along Direction 0 0 -1, presses the sphere as the flat lid does: the same displacements
    and reactions at every monitor row (to 1e-9 of their scale: the mesh's face contact is
    the flat wall's closed form, summed on another path)."""
    flat = _deck(tmp_path, SERVO.replace("0.08", "0.03"))
    Simulation.from_deck(flat, output=tmp_path / "flat").run()
    _plate(tmp_path)
    text = flat.read_text().replace(
        "  Wall 2 Name lid Point 0 0 0.00995 Normal 0 0 -1 Size 0.2 0.2",
        "  Mesh 2 Name lid File plate.stl").replace("TimeStep 1e-4", "TimeStep 1e-4 "
                                                     "Direction 0 0 -1")
    mesh = tmp_path / "mesh.inp"
    mesh.write_text(text)
    again = tmp_path / "again.inp"
    again.write_text(format_model(_build(mesh)))
    assert not model_differences(_build(mesh), _build(again))     # Direction written back
    Simulation.from_deck(mesh, output=tmp_path / "mesh").run()
    for name in ("wall_lid.csv", "wall_floor.csv"):
        a = _rows(tmp_path / "flat" / "monitors" / name)
        b = _rows(tmp_path / "mesh" / "monitors" / name)
        assert len(a) == len(b) == 31
        for key in ("displacement_z", "reaction_z"):
            x, y = np.array([r[key] for r in a]), np.array([r[key] for r in b])
            assert np.abs(x - y).max() <= 1e-9 * np.abs(x).max(), (name, key)
    lid = _rows(tmp_path / "mesh" / "monitors" / "wall_lid.csv")
    assert lid[-1]["displacement_z"] < 0 and -lid[-1]["reaction_z"] > 0.5 * F   # pressing


def test_a_servo_direction_is_checked_at_its_line(tmp_path):
    """A Force on a mesh wall without a Direction, a zero Direction, or a flat wall's
    Direction that does not advance it towards the particles: one-line errors at the line;
    ``move_wall(force=...)`` says the same."""
    stl = _plate(tmp_path, -0.5)
    bad = [("Step 1 MoveWall plate Force 1 MaxSpeed 1 Gain 1", "needs Direction dx dy dz"),
           ("Step 1 MoveWall plate Force 1 MaxSpeed 1 Gain 1 Direction 0 0 0",
            "Direction must not be zero"),
           ("Step 1 MoveWall floor Force 1 MaxSpeed 1 Gain 1 Direction 0 0 -1",
            "Direction must advance the flat wall towards the particles")]
    for line, message in bad:
        deck = _deck(tmp_path, SERVO + "\n  " + line, walls="  Mesh 3 Name plate File plate.stl")
        with pytest.raises(InputError) as err:
            _build(deck)
        text = str(err.value)
        assert message in text and "\n" not in text, text
        assert f"case.inp:{deck.read_text().splitlines().index(SERVO) + 2}: Step 1: " in text
    sim = _api(mesh=stl)
    with pytest.raises(InputError, match="needs Direction"):
        sim.move_wall("plate", force=1, max_speed=1, gain=1, duration=0.01, time_step=1e-4)
    with pytest.raises(InputError, match="towards the particles"):
        sim.move_wall("lid", force=1, max_speed=1, gain=1, duration=0.01, time_step=1e-4,
                      direction=(0, 0, 1))
    for bad, message in [(dict(max_speed=0, gain=1), "MaxSpeed must be > 0"),
                         (dict(max_speed=1, gain=-1), "Gain must be >= 0"),
                         (dict(max_speed=1), "force needs max_speed and gain"),
                         (dict(max_speed=1, gain=1, displacement=(0, 0, 1)),
                          "force takes max_speed")]:
        with pytest.raises(InputError, match=message):
            sim.move_wall("lid", force=1, duration=0.01, time_step=1e-4, **bad)
    assert sim.model.steps == []


def test_restart_inside_a_servo_step_is_bit_for_bit(tmp_path, monkeypatch):
    """The lid servo-presses the sphere with F, then with 2 F: a run killed inside the
    second servo step and restarted from its checkpoint (the lid's speed, where it is and
    when its deck step began are in it) ends as the run straight through, monitors and
    all."""
    import sys
    from pathlib import Path
    sys.path.insert(0, str(Path(__file__).parent))
    from runs import assert_same_final_state, killed_and_restarted
    deck = _deck(tmp_path, SERVO.replace("0.08", "0.02") + "\n"
                 + SERVO.replace("Step 1", "Step 2").replace(f"Force {F}", f"Force {2 * F}")
                 .replace("0.08", "0.02"), "  Results Every 0.01\n  Checkpoint Every 0.01\n")
    ref, out = tmp_path / "ref", tmp_path / "out"
    Simulation.from_deck(deck, output=ref).run()
    killed_and_restarted(deck, out, 0.035, monkeypatch)
    assert_same_final_state(out, ref, ("wall_lid.csv", "wall_floor.csv", "energy.csv"))
    lid = _rows(ref / "monitors" / "wall_lid.csv")
    assert lid[-1]["time"] == pytest.approx(0.04) and lid[-1]["displacement_z"] < 0


def test_two_servo_walls_in_one_step_each_reach_their_force(tmp_path):
    """A floor and a lid servo-controlled in one step (``Step`` lines of one id), the floor
    to F plus the sphere's weight, the lid to F: each ends pushed with its own force (1 %)."""
    weight = RHO * 4.0 / 3.0 * math.pi * R ** 3 * GRAV
    deck = _deck(tmp_path, SERVO + f"\n  Step 1 MoveWall floor Force {F + weight} MaxSpeed {V} "
                 f"Gain {G}")
    Simulation.from_deck(deck).run()
    mon = tmp_path / "results" / "monitors"
    assert -_rows(mon / "wall_lid.csv")[-1]["reaction_z"] == pytest.approx(F, rel=1e-2)
    assert _rows(mon / "wall_floor.csv")[-1]["reaction_z"] == pytest.approx(F + weight,
                                                                            rel=1e-2)

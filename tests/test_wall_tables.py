"""Tabulated wall motion (``MoveWall NAME Table motion.csv``, :mod:`nurbsdem.wall_tables`):
a table of constant velocity is the ``Displacement`` step, the wall is at the table's rows at
their times exactly, the deck reads back, and a bad row is one line naming the CSV and its
line."""
from __future__ import annotations

import csv
import subprocess
import sys

import numpy as np
import pytest

from nurbsdem import Simulation
from nurbsdem.errors import InputError
from nurbsdem.io.deck import build_model
from nurbsdem.io.deck_format import format_model
from nurbsdem.model import model_differences
from nurbsdem.wall_tables import read_wall_table, table_from_array

#: a 1 cm sphere of density 2500 resting at its overlap m g / k on a floor z = 0
WEIGHT = 2500 * 4 / 3 * np.pi * 0.01 ** 3 * 9.81


def _deck(path, steps: str, walls: str = "  Wall 9 Name floor Point 0 0 0 Normal 0 0 1 "
                                          "Size 2 2") -> object:
    deck = path / "case.inp"
    deck.write_text(f"""Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2500
Shapes
  Shape 1 Sphere Radius 0.01
Particles
  Particle 1 Shape 1 Material 1 Position 0.3 -0.2 {0.01 - WEIGHT / 1e5!r}
Walls
{walls}
Contact
  Interface 1 NormalPenalty 1e5 NormalDamping 5 TangentialPenalty 1e5 Friction 0.3
Steps
{steps}
Output
  Monitors Every 0.01
""")
    return deck


def _rows(path) -> list[dict]:
    return [{k: float(v) for k, v in r.items()} for r in csv.DictReader(open(path))]


def _monitors(folder) -> dict:
    return {name: _rows(folder / "results" / "monitors" / name)
            for name in ("wall_floor.csv", "energy.csv")}


def _run(folder, steps: str, table: str | None = None) -> dict:
    folder.mkdir(exist_ok=True)
    if table is not None:
        (folder / "lift.csv").write_text(table)
    Simulation.from_deck(_deck(folder, steps)).run()
    return _monitors(folder)


def test_table_of_constant_velocity_is_the_displacement_step(tmp_path):
    """A flat floor lifting a resting sphere by 0.2 mm in 0.1 s: the two-row table (with a
    header) gives the monitors of ``Displacement 0 0 0.0002`` bit for bit, and a table with
    a middle row on the same line to round-off; Duration defaults to the table's last time."""
    ref = _run(tmp_path / "ref", "  Step 1 MoveWall floor Displacement 0 0 0.0002 Duration 0.1 "
                                 "TimeStep 1e-3")
    two = _run(tmp_path / "two", "  Step 1 MoveWall floor Table lift.csv TimeStep 1e-3",
               "t,x,y,z\n0,0,0,0\n0.1,0,0,0.0002\n")
    assert two == ref
    three = _run(tmp_path / "three", "  Step 1 MoveWall floor Table lift.csv TimeStep 1e-3",
                 "0,0,0,0\n# the middle of the stroke\n0.05,0,0,0.0001\n0.1,0,0,0.0002\n")
    for name, rows in ref.items():
        assert len(three[name]) == len(rows) == 11
        for a, b in zip(three[name], rows):
            for key in a:
                assert a[key] == pytest.approx(b[key], rel=1e-9, abs=1e-15), (name, key)
    assert ref["wall_floor.csv"][-1]["displacement_z"] == 0.0002


def test_wall_is_at_the_table_rows_at_their_times(tmp_path):
    """A table that lifts, holds, then lowers the floor below its start (velocity changes at
    rows 0.03, 0.05 s) and a Duration past its end: at each row's time the monitor's
    displacement is the row's exactly, and after the end the last row's."""
    table = [(0.0, 0.0, 0.0, 0.0), (0.03, 0.0, 0.0, 1.3e-4), (0.05, 0.0, 0.0, 1.3e-4),
             (0.08, 1e-5, 0.0, -7e-5)]
    text = "".join(",".join(repr(v) for v in row) + "\n" for row in table)
    rows = _run(tmp_path, "  Step 1 Dynamic Duration 0.02 TimeStep 1e-3\n"
                          "  Step 2 MoveWall floor Table lift.csv Duration 0.1 TimeStep 1e-3",
                text)["wall_floor.csv"]
    by_time = {round(r["time"], 9): r for r in rows}
    for t, x, y, z in table:
        r = by_time[round(0.02 + t, 9)]
        assert [r["displacement_x"], r["displacement_y"], r["displacement_z"]] == [x, y, z]
    assert [rows[-1][f"displacement_{c}"] for c in "xyz"] == list(table[-1][1:])


def test_table_deck_reads_back_and_api_matches(tmp_path):
    """The deck of a Table step (with Damping, a Duration and a quoted path) formats and
    reads back to the same model; ``move_wall(table=array)`` writes the table to
    ``<output>/tables/`` and its deck text reads back to the same table."""
    (tmp_path / "my tables").mkdir()
    (tmp_path / "my tables" / "lift.csv").write_text("0,0,0,0\n0.01,0,0,1e-5\n")
    deck = _deck(tmp_path, '  Step 1 MoveWall floor Table "my tables/lift.csv" Duration 0.02 '
                           'TimeStep 1e-3 Damping Implicit')
    model = build_model(deck.read_text(), str(deck))
    step = model.steps[0]
    assert step.duration == 0.02 and step.table.duration == 0.01 and step.center is None
    text = format_model(model)
    assert 'Table "my tables/lift.csv"' in text
    assert model_differences(build_model(text, str(deck)), model) == []

    sim = Simulation(gravity=(0, 0, -9.81), output=tmp_path / "api")
    sim.add_material(1, density=2500)
    sim.add_interface(normal_penalty=1e5)
    sim.add_wall("floor", point=(0, 0, 0), normal=(0, 0, 1), size=(2, 2))
    import nurbsdem.shapes
    sim.add_particle(nurbsdem.shapes.sphere(0.01), 1, (0.3, -0.2, 0.01 - WEIGHT / 1e5))
    rows = np.array([[0, 0, 0, 0], [0.01, 0, 0, 1e-5]], float)
    sim.move_wall("floor", table=rows, time_step=1e-3)
    np.testing.assert_array_equal(sim.wall_displacements["floor"], [0, 0, 1e-5])
    back = build_model(sim.deck_text, str(tmp_path / "again.inp")).steps[-1]
    np.testing.assert_array_equal(back.table.rows(), rows)
    assert back.duration == 0.01
    sim.close()


@pytest.mark.parametrize("text, line, message", [
    ("t,x,y,z\n0,0,0,0\n0.1,0,zero,0\n", 3, "y is not a number: 'zero'"),
    ("0,0,0,0\n0.1,0,0,0\n0.1,0,0,1\n", 3, "times must increase: 0.1 s after 0.1 s"),
    ("0,0,0,0\n\n0.1,0,0\n", 3, "3 columns, expected"),
    ("0,0,0,0\n0.1,0,0,0,0,0,0\n", 2, "7 columns, expected 4"),
    ("0.01,0,0,0\n0.1,0,0,0\n", 1, "the first time must be 0"),
], ids=["non-numeric", "times", "columns", "width", "start"])
def test_bad_rows_are_one_line_naming_the_csv_and_its_line(tmp_path, text, line, message):
    """``nurbsdem check``: each bad row is one line on stderr naming the CSV and its line
    (and the step's deck line), exit status non-zero."""
    (tmp_path / "lift.csv").write_text(text)
    deck = _deck(tmp_path, "  Step 1 MoveWall floor Table lift.csv TimeStep 1e-3")
    run = subprocess.run([sys.executable, "-m", "nurbsdem", "check", str(deck)],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode != 0
    err = run.stderr.strip()
    assert len(err.splitlines()) == 1, err
    assert f"lift.csv:{line}: " in err and message in err and f"{deck}:14" in err, err


def test_rotation_columns_on_a_flat_wall_and_bad_arrays(tmp_path):
    """Rotation columns turn mesh and surface walls only: for a flat wall the deck's error
    names the table and the step's line; arrays: the row and what is wrong."""
    (tmp_path / "lift.csv").write_text("t,x,y,z,rx,ry,rz\n0,0,0,0,0,0,0\n0.1,0,0,0,0.1,0,0\n")
    deck = _deck(tmp_path, "  Step 1 MoveWall floor Table lift.csv TimeStep 1e-3")
    with pytest.raises(InputError, match=r"case.inp:14: Step 1: the table lift.csv has rotation "
                                         r"columns .* wall 'floor' is flat"):
        build_model(deck.read_text(), str(deck))
    assert read_wall_table(tmp_path / "lift.csv").rotation.shape == (2, 3)
    with pytest.raises(InputError, match="Step 2: table row 1: times must increase"):
        table_from_array([[0, 0, 0, 0], [0, 0, 0, 1]], "Step 2")
    with pytest.raises(InputError, match="4 .* or 7 .* columns, got shape"):
        table_from_array([[0, 0, 0], [1, 0, 0]], "Step 2")


def test_mesh_wall_table_with_rotation_is_the_rotate_step(tmp_path):
    """A mesh floor under a resting sphere turning about x at 1 rad/s for 0.03 s about a line
    under the sphere while it translates by 1 mm: the table of the same motion (rotation vector ω t about the same
    centre, displacement u t) gives the monitors of the ``Rotate`` step to round-off (but
    at the step's end, where the table's floor has stopped, as a translation stops at its
    last row, and the Rotate step's still turns) and leaves the floor at the same pose."""
    import trimesh
    floor = (np.array([[-1.0, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]),
             np.array([[0, 1, 2], [0, 2, 3]]))
    walls = "  Mesh 7 Name floor File floor.stl"
    out = {}
    for name, steps in (
            ("rotate", "  Step 1 MoveWall floor Rotate AngularVelocity 1 0 0 Center 0 -0.2 0 "
                       "Displacement 0.001 0 0 Duration 0.03 TimeStep 1e-3"),
            ("table", "  Step 1 MoveWall floor Table turn.csv Center 0 -0.2 0 TimeStep 1e-3")):
        folder = tmp_path / name
        folder.mkdir()
        trimesh.Trimesh(*floor).export(folder / "floor.stl")
        (folder / "turn.csv").write_text("t,x,y,z,rx,ry,rz\n0,0,0,0,0,0,0\n"
                                         "0.03,0.001,0,0,0.03,0,0\n")
        sim = Simulation.from_deck(_deck(folder, steps, walls))
        sim.run()
        out[name] = (_monitors(folder), sim.solver.curved.rest[0])
    (ref, (R1, t1)), (got, (R2, t2)) = out["rotate"], out["table"]
    np.testing.assert_allclose(R2, R1, rtol=0, atol=1e-15)
    np.testing.assert_allclose(t2, t1, rtol=0, atol=1e-15)
    for name, rows in ref.items():
        assert len(got[name]) == len(rows) == 4
        for a, b in zip(got[name][:-1], rows[:-1]):
            for key in a:
                assert a[key] == pytest.approx(b[key], rel=1e-9, abs=1e-13), (name, key)
    assert ref["wall_floor.csv"][-1]["reaction_z"] > 0.5 * WEIGHT     # the sphere stays on it


def test_check_refuses_a_table_that_drives_a_wall_through_the_one_facing_it(tmp_path):
    """A box's top that a table (the step's second wall) drives 1.2 m down and back: the
    stroke check takes the table's farthest row, not its last, and names the step's line."""
    (tmp_path / "lift.csv").write_text("0,0,0,0\n0.05,0,0,-1.2\n0.1,0,0,0\n")
    deck = _deck(tmp_path, "  Step 1 MoveWall bottom Displacement 0 0 0 Duration 0.1 "
                           "TimeStep 1e-3\n  Step 1 MoveWall top Table lift.csv",
                 walls="  Box 1 Min -1 -1 0 Max 1 1 1 Top yes")
    run = subprocess.run([sys.executable, "-m", "nurbsdem", "check", str(deck)],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode != 0
    assert f"{deck}:15: Step 1: wall 'top' would have moved 1.2 m" in run.stderr, run.stderr

"""Mesh and surface walls in a periodic cell (nurbsdem.periodic_checks,
nurbsdem.contact.curved_walls): a wall that stays or translates meets the particles where the
system puts them, the wrap into the cell included, and a turning one is refused.

A sphere, and an exact ellipsoid (a NURBS particle, whose pose the wrap shifts), roll across
the cell's faces on a two-triangle mesh floor: each run equals the run on a flat floor (whose
numbers the mesh gives to round-off) to 1e-12, through the wraps (with the floor's contact
points left unwrapped at the build that wraps the sphere, its lever arm is off by a cell
length for one internal step and the runs part in the fifth digit; with the ellipsoid's
pose origin left unshifted, its runs part by 9e-6 m).
"""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

from nurbsdem.errors import InputError
from nurbsdem.io.deck import parse_deck
from nurbsdem.io.results import read_results_sample, read_results_times
from nurbsdem.solver import Solver

DECK = """Environment
  Gravity 0 0 -9.81
  Periodic X 0 0.03 Y 0 0.03
Materials
  Material 1 Density 2500
Shapes
SHAPE
Particles
  Particle 1 Shape 1 Material 1 Position 0.024 0.015 0.0039993 Velocity 0.4 0.1 0
Walls
FLOOR
Contact
  Interface 1 NormalPenalty 1e4 NormalDamping 0.5 TangentialPenalty 1e4 Friction 0.3
Steps
  Step 1 Dynamic Duration 0.1 TimeStep 1e-3
Output
  Monitors Every 0.005
  Results Every 0.01
"""
SPHERE = "  Shape 1 Sphere Radius 0.004"
ELLIPSOID = "  Shape 1 Ellipsoid SemiAxes 0.005 0.0045 0.004"
FLAT = "  Wall 1 Name floor Point 0.015 0.015 0 Normal 0 0 1 Size 0.07 0.07"
MESH = "  Mesh 1 Name floor File floor.stl"


def _floor(folder) -> None:
    """A square two-triangle floor at z = 0 covering the cell and 2 cm around it."""
    v = np.array([[-0.02, -0.02, 0], [0.05, -0.02, 0], [0.05, 0.05, 0], [-0.02, 0.05, 0]],
                 float)
    trimesh.Trimesh(v, np.array([[0, 1, 2], [0, 2, 3]]), process=False).export(
        folder / "floor.stl")


def _run(folder, floor: str, shape: str = SPHERE):
    deck = folder / f"{'mesh' if floor == MESH else 'flat'}.inp"
    deck.write_text(DECK.replace("FLOOR", floor).replace("SHAPE", shape))
    out = folder / deck.stem
    Solver(parse_deck(deck), output=out, quiet=True).run()
    return out


@pytest.mark.parametrize("shape", [SPHERE, ELLIPSOID], ids=["sphere", "ellipsoid"])
def test_a_particle_rolls_across_the_faces_on_a_mesh_floor_as_on_a_flat_one(tmp_path, shape):
    _floor(tmp_path)
    flat, mesh = _run(tmp_path, FLAT, shape), _run(tmp_path, MESH, shape)
    times = read_results_times(mesh / "results.h5")
    np.testing.assert_array_equal(times, read_results_times(flat / "results.h5"))
    xs = []
    for i in range(len(times)):
        a = read_results_sample(mesh / "results.h5", i)
        b = read_results_sample(flat / "results.h5", i)
        for key, tol in (("position", 1e-14), ("velocity", 1e-12),
                         ("angular_velocity", 1e-9)):
            np.testing.assert_allclose(a[key], b[key], rtol=0, atol=tol, err_msg=f"{i} {key}")
        xs.append(float(np.ravel(a["position"])[0]))
    assert min(xs) < 0.01 < 0.024 < max(xs)              # it crossed the face x = 0.03
    assert abs(float(np.ravel(a["angular_velocity"])[1])) > 10.0      # rolling


def test_a_turning_mesh_wall_in_a_periodic_cell_is_refused_at_its_step(tmp_path):
    _floor(tmp_path)
    deck = tmp_path / "turning.inp"
    text = DECK.replace("FLOOR", MESH).replace("SHAPE", SPHERE).replace(
        "  Step 1 Dynamic Duration 0.1 TimeStep 1e-3",
        "  Step 1 MoveWall floor Rotate AngularVelocity 0 0 1 Center 0.015 0.015 0 "
        "Duration 0.1 TimeStep 1e-3")
    deck.write_text(text)
    line = next(k for k, ln in enumerate(text.splitlines(), 1) if "Rotate" in ln)
    with pytest.raises(InputError, match="wall floor turns, and a mesh or surface wall in a "
                                         "periodic cell .line 3. can only translate") as err:
        parse_deck(deck)
    assert err.value.line == line

"""Mesh and surface walls in the deck (``Mesh`` / ``Surface`` in the Walls block), the Python
API (``add_mesh_wall`` / ``add_surface_wall``, ``deck_text``) and a short solve."""
from __future__ import annotations

import csv

import numpy as np
import pytest

from nurbsdem import Simulation
from nurbsdem.errors import InputError
from nurbsdem.geometry.surfaces import cylinder_patch
from nurbsdem.io.deck import build_model
from nurbsdem.io.shapefile import save_shape

HEAD = """Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2500 YoungModulus 1e9 PoissonRatio 0.3
Shapes
  Shape 1 {shape}
Particles
  Particle 1 Shape 1 Material 1 Position 0 0 {z}
Walls
{walls}
Contact
  Interface 1 NormalPenalty 1e5 NormalDamping 5 TangentialPenalty 1e5 Friction 0.3
Steps
  Step 1 Dynamic Duration {duration} TimeStep 1e-3
{extra}"""


@pytest.fixture
def files(tmp_path):
    import trimesh
    trimesh.Trimesh([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]],
                    [[0, 1, 2], [0, 2, 3]]).export(tmp_path / "floor.stl")
    save_shape(tmp_path / "drum.yaml", [cylinder_patch(0.1, 0.2, axis=(1, 0, 0))])
    return tmp_path


def _deck(path, walls, shape="Sphere Radius 0.01", z=0.0105, duration=0.01, extra=""):
    deck = path / "case.inp"
    deck.write_text(HEAD.format(shape=shape, z=z, walls=walls, duration=duration, extra=extra))
    return deck


def test_deck_reads_mesh_and_surface_walls(files):
    deck = _deck(files, "  Mesh 7 Name floor File floor.stl Scale 2 Position 0 0 -0.5 "
                        "Rotation 0 0 0.1 Material 1 OneSided yes\n"
                        "  Surface 8 Name drum File drum.yaml Position 0 0 1")
    m = build_model(deck.read_text(), str(deck))
    floor, drum = m.curved_walls
    assert (floor.kind, floor.name, floor.scale, floor.material_id, floor.one_sided) == (
        "mesh", "floor", 2.0, 1, True)
    np.testing.assert_array_equal(floor.position, [0, 0, -0.5])
    assert floor.path == files / "floor.stl"
    assert (drum.kind, drum.name, drum.one_sided) == ("surface", "drum", False)
    assert m.wall_names == ["floor", "drum"]


@pytest.mark.parametrize("walls, message", [
    ("  Mesh 7 Name floor File nothere.stl", "no such mesh file"),
    ("  Mesh 7 Name floor File floor.stl Scale -1", "Scale must be > 0"),
    ("  Surface 8 Name drum File drum.yaml Scale 2", "unknown keyword 'Scale'"),
    ("  Surface 8 Name drum File nothere.yaml", "no such surface file"),
    ("  Mesh 7 Name floor", "missing File"),
    ("  Mesh 7 Name floor File floor.stl\n  Surface 8 Name floor File drum.yaml",
     "duplicate wall name"),
])
def test_bad_wall_entries_are_one_line_errors_at_their_line(files, walls, message):
    deck = _deck(files, walls)
    with pytest.raises(InputError) as err:
        build_model(deck.read_text(), str(deck))
    text = str(err.value)
    assert message in text and "\n" not in text
    assert text.startswith(f"{deck}:1") or text.startswith(f"{deck}:")
    assert err.value.line in (10, 11)


def test_tilted_ellipsoid_on_a_mesh_floor_moves_as_on_the_flat_wall(files):
    """A tilted NURBS ellipsoid dropped on a two-triangle STL floor (its support mapping per
    triangle) moves as on the flat wall of the same plane: the same trajectory and floor
    force to round-off (the flat-wall kernel is the face contact's)."""
    ends = []
    for walls in ("  Mesh 7 Name floor File floor.stl",
                  "  Wall 7 Name floor Point 0 0 0 Normal 0 0 1 Size 2 2"):
        deck = _deck(files, walls, shape="Ellipsoid SemiAxes 0.01 0.012 0.02", z=0.0195,
                     duration=0.03)
        deck.write_text(deck.read_text().replace("Position 0 0 0.0195",
                                                 "Position 0 0 0.0195 Rotation 0.3 0.2 0"))
        with open(deck, "a") as fh:
            fh.write("Output\n  Monitors Every 0.01\n")
        sim = Simulation.from_deck(deck)
        sim.run()
        rows = list(csv.DictReader(open(files / "results" / "monitors" / "wall_floor.csv")))
        force = [float(v) for k, v in rows[-1].items() if k.lower().startswith("f")]
        ends.append((np.array(sim.positions[0]), np.array(force)))
    (x_mesh, f_mesh), (x_flat, f_flat) = ends
    assert x_mesh[2] < 0.0195 - 1e-4                    # it fell and touched
    np.testing.assert_allclose(x_mesh, x_flat, rtol=0, atol=1e-14)
    np.testing.assert_allclose(f_mesh, f_flat, rtol=1e-10, atol=1e-12)


def test_ellipsoid_dropped_into_the_nurbs_drum_closes_its_energy_balance(files):
    """A tilted NURBS ellipsoid dropped into the exact NURBS drum (its support mapping along
    the wall's normal, Newton over the drum's parameters), frictionless: it lands and rocks
    on the drum's bottom; the energy balance closes to 1e-3 of the dissipated energy (what
    is left is the integration's impact error: 7e-7 J at this step and accuracy, 1e-5 J at
    TimeStep 1e-3, as on a flat wall) and the ellipsoid stays inside."""
    deck = _deck(files, "  Surface 8 Name drum File drum.yaml",
                 shape="Ellipsoid SemiAxes 0.01 0.012 0.02", z=-0.07, duration=0.065)
    deck.write_text(deck.read_text()
                    .replace("Position 0 0 -0.07", "Position 0.1 0.01 -0.07 Rotation 0.3 0.2 0.1")
                    .replace("TimeStep 1e-3", "TimeStep 1e-4 Accuracy 1e-4")
                    .replace("Friction 0.3", "Friction 0")
                    .replace("NormalDamping 5", "NormalDamping 20"))
    sim = Simulation.from_deck(deck)
    sim.run()
    e = sim.energy()
    assert e["dissipated"] > 1e-3                          # it hit the drum
    assert abs(e["balance_error"]) < 1e-3 * e["dissipated"]
    x = np.array(sim.positions[0])
    assert np.hypot(x[1], x[2]) < 0.1 - 0.01


def test_move_wall_to_contact_of_a_mesh_wall_needs_a_direction(files):
    deck = _deck(files, "  Mesh 7 Name floor File floor.stl",
                 extra="  Step 2 MoveWall floor ToContact")
    with pytest.raises(InputError, match=r"case.inp:15: .*a mesh or surface wall needs a "
                                         r"Direction"):
        build_model(deck.read_text(), str(deck))
    moved = deck.read_text().replace("ToContact", "Displacement 0 0 0.1 Duration 0.1 "
                                                  "TimeStep 1e-3")
    step = build_model(moved, str(deck)).steps[-1]
    assert step.wall == "floor" and not step.rotate and step.displacement[2] == 0.1


def test_api_deck_text_round_trip(files):
    import nurbsdem.shapes
    sim = Simulation(gravity=(0, 0, -9.81))
    sim.add_material(1, density=2500)
    sim.add_interface(normal_penalty=1e5)
    sim.add_particle(nurbsdem.shapes.sphere(0.01), 1, (0, 0, 0.0105))
    sim.add_mesh_wall("floor", files / "floor.stl", scale=1.0, position=(0, 0, 0.0),
                      one_sided=True)
    sim.add_surface_wall("drum", files / "drum.yaml", position=(0, 0, 0.3))
    with pytest.raises(InputError, match="exists already"):
        sim.add_mesh_wall("drum", files / "floor.stl")
    with pytest.raises(InputError, match="no such mesh file"):
        sim.add_mesh_wall("other", files / "nothere.stl")
    text = sim.deck_text
    assert 'Mesh 1 Name floor File "' in text and "OneSided yes" in text
    m = build_model(text, str(files / "again.inp"))
    floor, drum = m.curved_walls
    assert floor.path == (files / "floor.stl").resolve() and floor.one_sided
    np.testing.assert_array_equal(drum.position, [0, 0, 0.3])


def test_sphere_on_mesh_floor_deck_reports_its_weight(files):
    """A sphere settling on an STL floor: the floor's monitored reaction is its weight."""
    deck = _deck(files, "  Mesh 7 Name floor File floor.stl", z=0.0101, duration=0.1)
    with open(deck, "a") as fh:
        fh.write("Output\n  Monitors Every 0.01\n")
    Simulation.from_deck(deck).run()
    rows = list(csv.DictReader(open(files / "results" / "monitors" / "wall_floor.csv")))
    weight = 2500 * 4 / 3 * np.pi * 0.01 ** 3 * 9.81
    last = rows[-1]
    fz = [float(v) for k, v in last.items() if k.lower().startswith(("reaction_z", "fz", "force_z"))]
    assert fz and abs(abs(fz[0]) - weight) < 1e-3 * weight


def test_rotate_step_parses_and_is_refused_for_flat_walls(files):
    deck = _deck(files, "  Surface 8 Name drum File drum.yaml\n"
                        "  Wall 9 Name lid Point 0 0 0.5 Normal 0 0 -1 Size 1 1",
                 extra="  Step 2 MoveWall drum Rotate AngularVelocity 2 0 0 Center 0 0 0.1 "
                       "Duration 0.1 TimeStep 1e-3")
    step = build_model(deck.read_text(), str(deck)).steps[1]
    assert step.rotate and step.wall == "drum" and step.duration == 0.1
    np.testing.assert_array_equal(step.angular_velocity, [2, 0, 0])
    np.testing.assert_array_equal(step.center, [0, 0, 0.1])
    bad = deck.read_text().replace("MoveWall drum Rotate", "MoveWall lid Rotate")
    with pytest.raises(InputError, match=r":16: .*only mesh and surface walls turn"):
        build_model(bad, str(deck))
    zero = deck.read_text().replace("AngularVelocity 2 0 0", "AngularVelocity 0 0 0")
    with pytest.raises(InputError, match=r":16: .*AngularVelocity must not be zero"):
        build_model(zero, str(deck))


def test_api_rotation_reads_back_from_deck_text(files):
    import nurbsdem.shapes
    sim = Simulation(gravity=(0, 0, -9.81))
    sim.add_material(1, density=2500)
    sim.add_interface(normal_penalty=1e5, tangential_penalty=1e5, friction=0.3)
    sim.add_particle(nurbsdem.shapes.sphere(0.01), 1, (0, 0, -0.0895))
    sim.add_surface_wall("drum", files / "drum.yaml", position=(-0.1, 0, 0))
    with pytest.raises(InputError, match="to_contact of a mesh or surface wall needs a "
                                         "direction"):
        sim.move_wall("drum", to_contact=True)
    sim.move_wall("drum", angular_velocity=(1.0, 0, 0), center=(0, 0, 0), duration=0.01,
                  time_step=1e-3)
    text = sim.deck_text
    assert "MoveWall drum Rotate AngularVelocity 1.0 0.0 0.0 Center 0.0 0.0 0.0" in text
    step = build_model(text, str(files / "again.inp")).steps[-1]
    assert step.rotate and step.angular_velocity[0] == 1.0


def test_drum_deck_carries_the_spheres_up(tmp_path):
    """inputs/drum/drum_spheres.inp: 50 spheres settle in an exact NURBS drum with end
    plates, then the drum turns at 3 rad/s about +x: its rising side (+y at the bottom)
    carries them up; none leaves the drum."""
    import h5py
    from pathlib import Path
    deck = Path(__file__).resolve().parents[1] / "inputs" / "drum" / "drum_spheres.inp"
    Simulation.from_deck(deck, output=tmp_path / "out").run()
    with h5py.File(tmp_path / "out" / "results.h5") as f:
        t, off, pos = f["time"][:], f["offset"][:], f["position"][:]
    settled = pos[off[np.searchsorted(t, 0.15 - 1e-9)]:off[np.searchsorted(t, 0.15 - 1e-9) + 1]]
    final = pos[off[-2]:off[-1]]
    assert abs(settled[:, 1].mean()) < 0.005             # a symmetric heap before turning
    assert final[:, 1].mean() > 0.015                      # carried up the rising side
    assert np.hypot(final[:, 1], final[:, 2]).max() < 0.1 - 0.007 + 1e-4
    assert np.abs(final[:, 0]).max() < 0.05 - 0.007 + 1e-4


def test_restart_after_a_rotate_step_is_bit_for_bit(files, monkeypatch):
    """A mesh floor tilted by a Rotate step (0.03 rad about x), a sphere rolling down it; the
    run killed in the next step and restarted from its checkpoint ends in the same state as
    the run straight through (the tilted pose is part of the checkpoint)."""
    import sys
    from pathlib import Path
    sys.path.insert(0, str(Path(__file__).parent))
    from runs import assert_same_final_state, killed_and_restarted
    deck = _deck(files, "  Mesh 7 Name floor File floor.stl", z=0.0099995, duration=0.02,
                 extra="  Step 2 MoveWall floor Rotate AngularVelocity 1 0 0 Center 0 0 0 "
                       "Duration 0.03 TimeStep 1e-3\n  Step 3 Dynamic Duration 0.04 "
                       "TimeStep 1e-3\nOutput\n  Results Every 0.01\n  Checkpoint Every 0.01\n")
    ref, out = files / "ref", files / "out"
    Simulation.from_deck(deck, output=ref).run()
    killed_and_restarted(deck, out, 0.065, monkeypatch)
    assert_same_final_state(out, ref, ("wall_floor.csv",))
    import h5py
    with h5py.File(ref / "results.h5") as f:
        v = f["velocity"][-1]
    assert v[1] < -1e-3                      # it rolls down the tilted floor (towards -y)


def test_walls_pvd_draws_the_turning_mesh_and_the_surface(files):
    """walls.pvd holds the mesh's triangles and the surface's tessellation after the flat
    walls' quads; a mesh turned by a Rotate step (1 rad/s about x for 0.03 s) is drawn at
    its turned place: its rest vertices rotated by 0.03 rad."""
    import meshio
    from scipy.spatial.transform import Rotation
    from nurbsdem.io.meshfile import read_wall_mesh
    deck = _deck(files, "  Mesh 7 Name floor File floor.stl\n"
                        "  Surface 8 Name drum File drum.yaml Position -0.1 0 0.5\n"
                        "  Wall 9 Name lid Point 0 0 0.3 Normal 0 0 -1 Size 1 1",
                 z=0.0099995, duration=0.01,
                 extra="  Step 2 MoveWall floor Rotate AngularVelocity 1 0 0 Center 0 0 0 "
                       "Duration 0.03 TimeStep 1e-3\nOutput\n  VTK Every 0.01\n")
    Simulation.from_deck(deck, output=files / "out").run()
    vtus = sorted((files / "out" / "vtk").glob("walls_*.vtu"))
    grid = meshio.read(vtus[-1])
    kinds = [c.type for c in grid.cells]
    assert kinds == ["quad", "triangle"]
    quad_ids, tri_ids = grid.cell_data["wall_id"]
    assert quad_ids.tolist() == [9] and sorted(set(tri_ids.tolist())) == [7, 8]
    assert (tri_ids == 7).sum() == 2                       # the floor's two triangles
    wall_id = grid.point_data["wall_id"]
    rest = read_wall_mesh(files / "floor.stl").vertices
    turned = rest @ Rotation.from_rotvec([0.03, 0, 0]).as_matrix().T
    np.testing.assert_allclose(grid.points[wall_id == 7], turned, rtol=0, atol=1e-7)  # Float32
    drum = grid.points[wall_id == 8]
    np.testing.assert_allclose(np.hypot(drum[:, 1], drum[:, 2] - 0.5), 0.1, rtol=1e-6)

"""Pre-run checks of mesh and surface walls (nurbsdem.wall_checks): particles crossing them or
inside a closed one-sided mesh, mesh sizes far from the particles', and MoveWall strokes that
carry them through a flat wall; one line each, at the deck line, the same through the API."""
from __future__ import annotations

import logging
import re

import numpy as np
import pytest
import trimesh

from nurbsdem import Simulation
from nurbsdem.errors import InputError
from nurbsdem.geometry.surfaces import cylinder_patch
from nurbsdem.io.deck import build_model, parse_deck
from nurbsdem.io.shapefile import save_shape
from nurbsdem.model import Bodies
from nurbsdem.wall_checks import (closed_and_oriented, signed_volume, winding_numbers,
                                  check_curved_walls_scene)

DECK = """Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2500
Shapes
  Shape 1 Sphere Radius {radius}
Particles
{particles}
Walls
{walls}
Contact
  Interface 1 NormalPenalty 1e5 NormalDamping 5
Steps
  Step 1 Dynamic Duration 0.01 TimeStep 1e-3
{steps}"""
#: the deck lines of the particles and of the first wall
PARTICLE_LINE, WALL_LINE = 8, 10


@pytest.fixture
def files(tmp_path):
    """floor.stl: 2 x 2 m at z = 0, fronts up; box.stl: a closed 0.2 m cube about the origin,
    fronts out; inbox.stl: the same, fronts in; drum.yaml: a cylinder of radius 0.1 m along
    x from x = 0 to 0.2, front inwards."""
    trimesh.Trimesh([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]],
                    [[0, 1, 2], [0, 2, 3]]).export(tmp_path / "floor.stl")
    box = trimesh.creation.box(extents=(0.2, 0.2, 0.2))
    box.export(tmp_path / "box.stl")
    trimesh.Trimesh(box.vertices, box.faces[:, ::-1]).export(tmp_path / "inbox.stl")
    save_shape(tmp_path / "drum.yaml", [cylinder_patch(0.1, 0.2, axis=(1, 0, 0))])
    return tmp_path


def _deck(path, positions, walls, radius=0.01, steps=""):
    particles = "\n".join(f"  Particle {k + 1} Shape 1 Material 1 Position {p}"
                          for k, p in enumerate(positions))
    deck = path / "case.inp"
    deck.write_text(DECK.format(radius=radius, particles=particles, walls=walls, steps=steps))
    return deck


def _refusal(deck) -> InputError:
    with pytest.raises(InputError) as err:
        parse_deck(deck)
    assert "\n" not in str(err.value)
    return err.value


# ---------------------------------------------------------------------------- winding numbers


def test_winding_numbers_of_a_closed_sphere_mesh_and_rays_through_its_vertices():
    """1 inside an outward icosphere, 0 outside, -1 inside it reversed; the rays from points
    straight below its vertices and edges' midpoints (ties in plan view) count each crossing
    once."""
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    assert closed_and_oriented(f) and signed_volume(v, f) == pytest.approx(mesh.volume)
    rng = np.random.default_rng(4)
    p = rng.uniform(-1.2, 1.2, (5000, 3))
    w = winding_numbers(v, f, p)
    r = np.linalg.norm(p, axis=1)
    assert np.all(w[r < 0.98] == 1) and np.all(w[r > 1.0] == 0)
    assert np.all(winding_numbers(v, f[:, ::-1], p[r < 0.98]) == -1)
    under = np.concatenate([v * 0.5, 0.25 * (v[f[:, 0]] + v[f[:, 1]])])
    assert np.all(winding_numbers(v, f, under) == 1)
    below = under - [0, 0, 5]
    assert np.all(winding_numbers(v, f, below) == 0)
    assert not closed_and_oriented(f[1:])
    assert not closed_and_oriented(np.vstack([f[:1, ::-1], f[1:]]))


# ---------------------------------------------------------------------------- particles


def test_a_sphere_through_a_mesh_floor_is_refused_at_its_line(files):
    """Two-sided floor: 1 mm into it, from above or below, is refused with the depth and the
    limit; a touching sphere (1e-7 m) is accepted."""
    err = _refusal(_deck(files, ["0.1 0.2 0.009"], "  Mesh 7 Name floor File floor.stl"))
    assert err.line == PARTICLE_LINE
    assert ("particle 1 (centre 0.1 0.2 0.009 m) penetrates mesh wall 'floor' by 0.001 m"
            in str(err))
    assert "at most 2.05e-05 m is accepted" in str(err)
    floor = "  Mesh 7 Name floor File floor.stl"
    err = _refusal(_deck(files, ["0 0 0.5", "0.1 0.2 -0.009"], floor))
    assert err.line == PARTICLE_LINE + 1 and "particle 2" in str(err)
    model = parse_deck(_deck(files, ["0.1 0.2 0.0099999"], "  Mesh 7 Name floor File floor.stl"))
    assert len(model.bodies) == 1


def test_behind_a_one_sided_mesh_floor(files):
    """A sphere whose centre is below a one-sided floor (fronts up) and which crosses it is
    refused (the floor would let it through); far below an open floor it is accepted (an
    open mesh has no solid side)."""
    walls = "  Mesh 7 Name floor File floor.stl OneSided yes"
    err = _refusal(_deck(files, ["0.1 0.2 -0.005"], walls))
    assert err.line == PARTICLE_LINE
    assert ("particle 1 (centre 0.1 0.2 -0.005 m) is behind one-sided mesh wall 'floor' (on the "
            "side its triangles' vertex order faces away from) and crosses its surface by "
            "0.005 m") in str(err)
    assert "OneSided no" in str(err)
    assert len(parse_deck(_deck(files, ["0.1 0.2 -0.5"], walls)).bodies) == 1


def test_inside_a_closed_one_sided_mesh_is_its_solid_side(files):
    """A particle inside a closed one-sided cube whose fronts face out is on its solid side;
    inside the same cube as a two-sided shell it is accepted; inside the cube with its fronts
    in it is accepted and outside it refused."""
    err = _refusal(_deck(files, ["0 0 0"], "  Mesh 7 Name box File box.stl OneSided yes"))
    assert err.line == PARTICLE_LINE
    assert ("particle 1 (centre 0 0 0 m) is inside the closed one-sided mesh wall 'box', whose "
            "triangles' fronts (vertex order) face outwards") in str(err)
    assert len(parse_deck(_deck(files, ["0 0 0"], "  Mesh 7 Name box File box.stl")).bodies) == 1
    inward = "  Mesh 7 Name box File inbox.stl OneSided yes"
    assert len(parse_deck(_deck(files, ["0 0 0", "0.05 0.05 -0.05"], inward)).bodies) == 2
    err = _refusal(_deck(files, ["0 0 0", "0.5 0 0"], inward))
    assert err.line == PARTICLE_LINE + 1
    assert "is outside the closed one-sided mesh wall 'box', whose triangles' fronts" in str(err)
    assert "face inwards" in str(err)


def test_a_sphere_crossing_a_surface_wall(files):
    """Inside the drum (front) 5 mm into the mantle; outside it (behind) crossing it; both
    refused; 1 mm clear of it accepted."""
    walls = "  Surface 8 Name drum File drum.yaml"
    err = _refusal(_deck(files, ["0.1 0 -0.095"], walls))
    assert err.line == PARTICLE_LINE
    assert "penetrates surface wall 'drum' by 0.005 m" in str(err)
    err = _refusal(_deck(files, ["0.1 0 -0.105"], walls))
    assert "is behind one-sided surface wall 'drum' (on the side S_u x S_v faces away from)" \
        in str(err) and "crosses its surface by 0.005 m" in str(err)
    assert len(parse_deck(_deck(files, ["0.1 0 -0.089"], walls)).bodies) == 1


def test_an_ellipsoid_crossing_a_mesh_floor_or_the_drum_is_refused(files):
    """An ellipsoid (semi-axis 0.02 m up) 1 mm into the floor and 5 mm into the drum's
    mantle: refused with the depths of the solver's NURBS kernels; clear of them, accepted."""
    def deck(position, walls):
        d = _deck(files, [position], walls)
        d.write_text(d.read_text().replace("Sphere Radius 0.01",
                                           "Ellipsoid SemiAxes 0.01 0.015 0.02"))
        return d
    err = _refusal(deck("0.1 0.2 0.019", "  Mesh 7 Name floor File floor.stl"))
    assert err.line == PARTICLE_LINE
    assert "particle 1 (centre 0.1 0.2 0.019 m) penetrates mesh wall 'floor' by 0.001 m" in str(err)
    err = _refusal(deck("0.1 0 -0.085", "  Surface 8 Name drum File drum.yaml"))
    assert "penetrates surface wall 'drum' by 0.005 m" in str(err)
    assert len(parse_deck(deck("0.1 0 -0.079", "  Surface 8 Name drum File drum.yaml")).bodies) == 1


def test_a_random_group_across_a_mesh_wall_is_refused_at_its_line(files):
    deck = _deck(files, [], "  Mesh 7 Name floor File floor.stl")
    text = deck.read_text().replace("Particles\n", "Particles\n  Random 1 Shapes 1 Counts 40 "
                                    "Material 1 Region -0.2 -0.2 -0.05 0.2 0.2 0.05 Seed 1\n")
    deck.write_text(text)
    err = _refusal(deck)
    assert err.line == PARTICLE_LINE and "penetrates mesh wall 'floor'" in str(err)


def test_the_api_refuses_with_the_same_message(files):
    import nurbsdem.shapes
    sim = Simulation(gravity=(0, 0, -9.81))
    sim.add_material(1, density=2500)
    sim.add_interface(normal_penalty=1e5, normal_damping=5)
    sim.add_particle(nurbsdem.shapes.sphere(0.01), 1, (0.1, 0.2, -0.005))
    sim.add_mesh_wall("floor", files / "floor.stl", one_sided=True)
    with pytest.raises(InputError) as err:
        sim.run_dynamic(0.01, 1e-3)
    assert str(err.value).startswith("particle 1 (centre 0.1 0.2 -0.005 m) is behind one-sided "
                                     "mesh wall 'floor'")


def test_ten_thousand_spheres_in_a_closed_one_sided_mesh(files):
    """10^4 spheres inside a closed cube of 768 triangles with fronts in: accepted; one of
    them moved outside, or into a wall, is refused."""
    box = trimesh.creation.box(extents=(0.2, 0.2, 0.2)).subdivide().subdivide().subdivide()
    trimesh.Trimesh(box.vertices, box.faces[:, ::-1]).export(files / "fine.stl")
    model = build_model(_deck(files, ["0 0 0"], "  Mesh 7 Name box File fine.stl OneSided yes",
                              radius=0.002).read_text(), str(files / "case.inp"))
    g = np.linspace(-0.095, 0.095, 22)
    pos = np.stack(np.meshgrid(g, g, g[:21], indexing="ij"), -1).reshape(-1, 3)[:10000]
    n = len(pos)
    bodies = Bodies(np.arange(1, n + 1), np.ones(n), np.ones(n), pos,
                    np.tile([1.0, 0, 0, 0], (n, 1)), np.zeros((n, 3)), np.zeros((n, 3)),
                    np.full(n, PARTICLE_LINE))
    check_curved_walls_scene(model, bodies)
    bodies.position[1234] = [0.3, 0, 0]
    with pytest.raises(InputError, match="particle 1235 .* is outside the closed one-sided"):
        check_curved_walls_scene(model, bodies)
    bodies.position[1234] = [0.099, 0, 0]
    with pytest.raises(InputError, match="particle 1235 .* penetrates mesh wall 'box' by 0.001 m"):
        check_curved_walls_scene(model, bodies)


# ---------------------------------------------------------------------------- sizes


def test_a_mesh_far_larger_or_smaller_than_the_particles_is_warned_of(files, caplog):
    """A 2.8 m floor under 0.2 mm spheres (a millimetre file read as metres?) and the same
    floor at Scale 0.001 under 2 cm spheres: one warning each at the wall's line, naming the
    file; a floor 140 times the particles: none."""
    caplog.set_level(logging.WARNING, logger="nurbsdem")
    deck = _deck(files, ["0 0 0.0001"], "  Mesh 7 Name floor File floor.stl", radius=1e-4)
    parse_deck(deck)
    (text,) = [r.getMessage() for r in caplog.records if "the mesh is" in r.getMessage()]
    assert re.fullmatch(rf"{re.escape(str(deck))}:{WALL_LINE}: Mesh 7 \(floor.stl\): the mesh is "
                        r"1\.\d+e\+04 times the particles' size: drawn in millimetres\? \(Scale "
                        r"0\.001 reads millimetres as metres\)", text)
    caplog.clear()
    parse_deck(_deck(files, ["0 0 0.01"], "  Mesh 7 Name floor File floor.stl Scale 0.001"))
    (text,) = [r.getMessage() for r in caplog.records if "the mesh is" in r.getMessage()]
    assert f":{WALL_LINE}: Mesh 7 (floor.stl, Scale 0.001): the mesh is smaller than one " \
           f"particle" in text
    caplog.clear()
    parse_deck(_deck(files, ["0 0 0.01"], "  Mesh 7 Name floor File floor.stl"))
    assert not [r for r in caplog.records if "the mesh is" in r.getMessage()]


def test_a_non_manifold_file_is_an_error_for_a_one_sided_wall_only(files, caplog):
    caplog.set_level(logging.WARNING, logger="nurbsdem")
    trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1]],
                    [[0, 1, 2], [0, 1, 3], [0, 1, 4]], process=False).export(files / "fan.stl")
    deck = _deck(files, ["0 0 0.5"], "  Mesh 7 Name fan File fan.stl")
    build_model(deck.read_text(), str(deck))
    assert any(r.getMessage().startswith(f"{deck}:{WALL_LINE}: fan.stl: 1 edges are shared by "
                                         f"more than two triangles") for r in caplog.records)
    one = deck.read_text().replace("fan.stl", "fan.stl OneSided yes")
    with pytest.raises(InputError, match=rf"case.inp:{WALL_LINE}: Mesh 7: fan.stl: 1 edges are "
                                         r"shared by more than two triangles"):
        build_model(one, str(deck))


# ---------------------------------------------------------------------------- strokes


PISTON = ("  Mesh 7 Name piston File box.stl Scale 0.5 Position 0 0 0.2\n"
          "  Wall 8 Name floor Point 0 0 0 Normal 0 0 1 Size 1 1")


def test_a_mesh_piston_pushed_through_the_floor_is_refused_at_the_step(files):
    """The 0.1 m cube 0.15 m above the floor: moved down 0.1 m it stops 0.05 m short; down 0.2 m
    more (0.3 m in all) its bottom would be 0.15 m behind the floor."""
    ok = "  Step 2 MoveWall piston Displacement 0 0 -0.1 Duration 0.01 TimeStep 1e-3"
    assert parse_deck(_deck(files, ["0 0 0.01"], PISTON, steps=ok)).steps[1].wall == "piston"
    bad = ok + "\n  Step 3 MoveWall piston Displacement 0 0 -0.2 Duration 0.01 TimeStep 1e-3"
    err = _refusal(_deck(files, ["0 0 0.01"], PISTON, steps=bad))
    assert err.line == 17
    assert ("Step 3: mesh wall 'piston' would be 0.15 m behind wall 'floor' by the end of this "
            "step, carried through it from the side it faces") in str(err)


def test_a_surface_wall_carried_out_of_the_box_and_a_turn_through_the_floor(files):
    """The drum (radius 0.1 m along x) in a Box: moved 0.5 m along y it leaves through the
    Box's wall; a floor mesh turned 0.5 rad about x through the Box's floor (its edge 0.04 m
    above it) is refused too."""
    walls = ("  Surface 8 Name drum File drum.yaml\n"
             "  Box 1 Min -0.5 -0.5 -0.5 Max 0.5 0.5 0.5")
    step = "  Step 2 MoveWall drum Displacement 0 0.5 0 Duration 0.01 TimeStep 1e-3"
    err = _refusal(_deck(files, ["0.1 0 0"], walls, steps=step))
    assert err.line == 16 and "surface wall 'drum' would be 0.1 m behind wall" in str(err)
    assert "of the Box" in str(err)
    walls = ("  Mesh 7 Name plate File floor.stl Scale 0.2 Position 0 0 -0.46\n"
             "  Box 1 Min -0.5 -0.5 -0.5 Max 0.5 0.5 0.5")
    turn = ("  Step 2 MoveWall plate Rotate AngularVelocity 50 0 0 Center 0 0 -0.46 "
            "Duration 0.01 TimeStep 1e-3")
    err = _refusal(_deck(files, ["0 0 0"], walls, steps=turn))
    assert err.line == 16 and "Step 2: mesh wall 'plate' would be" in str(err)
    small = turn.replace("AngularVelocity 50", "AngularVelocity 10")
    assert len(parse_deck(_deck(files, ["0 0 0"], walls, steps=small)).steps) == 2


def test_the_api_refuses_a_stroke_through_a_wall(files):
    import nurbsdem.shapes
    sim = Simulation(gravity=(0, 0, -9.81))
    sim.add_material(1, density=2500)
    sim.add_interface(normal_penalty=1e5, normal_damping=5)
    sim.add_particle(nurbsdem.shapes.sphere(0.01), 1, (0, 0, 0.01))
    sim.add_mesh_wall("piston", files / "box.stl", scale=0.5, position=(0, 0, 0.2))
    sim.add_wall("floor", point=(0, 0, 0), normal=(0, 0, 1), size=(1, 1))
    with pytest.raises(InputError, match=r"^Step 1: mesh wall 'piston' would be 0.05 m behind "
                                         r"wall 'floor'"):
        sim.move_wall("piston", displacement=(0, 0, -0.2), duration=0.01, time_step=1e-3)

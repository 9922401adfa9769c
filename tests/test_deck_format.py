"""The deck formatter (:func:`nurbsdem.io.deck_format.format_model`): the deck text of a model
reads back to the same model, bit for bit, for every deck of the repository and for decks that
use every entry and key; the comparison catches a formatter that drops an entry or rounds a
number; ``Simulation.deck_text`` reads back to the scene built in Python."""
from __future__ import annotations

import math
import shutil
from dataclasses import fields, is_dataclass
from pathlib import Path

import numpy as np
import pytest

from nurbsdem import Simulation, shapes
from nurbsdem.errors import InputError
from nurbsdem.geometry.surfaces import cylinder_patch
from nurbsdem.io import deck_format
from nurbsdem.io.deck import build_model, read_deck_text
from nurbsdem.io.deck_format import format_model, unit_preimage
from nurbsdem.io.deck_schema import SCHEMA
from nurbsdem.io.shapefile import save_shape

ROOT = Path(__file__).resolve().parents[1]
DECKS = sorted(p for folder in ("inputs", "tests/data") for p in (ROOT / folder).rglob("*.inp"))

#: every entry and optional key but the mesh and surface walls (those take exact spheres)
NURBS_DECK = """\
Environment
  Gravity 0.3 -0.1 -9.81
  Periodic X -0.5 0.5 Y 0 2 Z 0.1 0.25
Materials
  Material 1 Density 2700 YoungModulus 7e10 PoissonRatio 0.33
  Material 3 Density 1150.5 PoissonRatio 0.25
  Material 2 Density 7800 YoungModulus 2e11
Shapes
  Shape 2 File "my shapes/A.yaml" ConvexityTolerance 0.001
  Shape 1 Sphere Radius 0.012 Volume 7.1e-6
  Shape 3 Ellipsoid SemiAxes 0.01 0.014 0.008 Inertia 2e-6 3e-6 4e-6 1e-7 0 -2e-7
Particles
  Particle 40 Shape 1 Material 2 Position 0.05 0.06 0.31 Rotation 0.1 0.2 0.3 Velocity 0.1 0 -0.2 AngularVelocity 1 2 3
  Random 1 Shapes 1 2 3 Counts 2 1 3 Material 1 Region 0.01 0.01 0.01 0.19 0.19 0.25 Seed 11 MaxAttempts 5000
  Particle 41 Shape 3 Material 3 Position 0.15 0.14 0.3
Walls
  Box 1 Min -0.013 0.007 0 Max 0.2 0.2 0.41 Top no Material 1
  Wall 6 Name lid Point 0.1 0.1 0.37 Normal 0.01 0.02 -1 Size 0.23 0.21 Axis 1 0.3 0
  Wall 7 Name shelf Point 0.1 0.1 -0.05 Normal 0 0 1 Size 0.3 0.3 Material 2
Contact
  Interface 1 NormalPenalty 1e5 TangentialPenalty 1e4 NormalDamping 1e2 Friction 0.5
  Interface 2 Model HertzMindlin Restitution 0.6 Friction 0.2 Materials 1 2
  Interface 3 NormalPenalty 2e5 RollingFriction 0.05 RollingDamping 0.2 Between particle-wall
Steps
  Step 1 Dynamic Duration 0.1 TimeStep 1e-3 Damping Implicit Accuracy 3e-5 Safety 0.7
  Step 2 Replicate Layers 3 Height 0.1
  Step 3 MoveWall lid ToContact Gap 0.002 Direction 1 1 -3
  Step 4 MoveWall shelf ToContact
  Step 5 MoveWall lid Displacement 0 0 -0.004 Duration 0.1 TimeStep 1e-3
  Step 6 MoveWall lid Force 2.5 MaxSpeed 0.01 Gain 1e-4 Duration 0.1 TimeStep 1e-3 Safety 0.8
Flow
  Inlet 3 Name feed Shapes 1 3 Fractions 0.25 0.75 Material 1 Box 0.02 0.02 0.26 0.18 0.18 0.33 Rate 500 Count 20 Velocity 0 0 -0.5 Seed 7 Every 0.02
  Inlet 4 Shapes 1 Material 1 Disc 0.1 0.1 0.3 Normal 0.1 0 -1 Radius 0.05 Thickness 0.012 Rate 100 Count 5
  Outlet 1 Name bin Box -1 -1 -1 1 1 -0.1 Every 0.005
  Outlet 2 Point 0 0 -0.2 Normal 0 0 -1
Output
  Directory "out dir/run 1"
  VTK Every 0.02 Resolution 5
  Monitors Every 0.002
  Results Every 0.01
  Checkpoint Every 0.05
"""

CURVED_DECK = """\
Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2500 YoungModulus 1e9 PoissonRatio 0.3
Shapes
  Shape 1 Sphere Radius 0.01
Particles
  Particle 1 Shape 1 Material 1 Position 0 0 0.0105
Walls
  Mesh 7 Name floor File floor.stl Scale 2 Position 0 0 -0.5 Rotation 0 0 0.1 Material 1 OneSided yes
  Surface 8 Name drum File drum.yaml Position 0 0 1 Rotation 0 1.5707963267948966 0 Material 1
  Mesh 9 File floor.stl
  Box 10 Min -1 -1 -1 Max 1.3 1.7 1.1 Top yes
Contact
  Interface 1 NormalPenalty 1e5 NormalDamping 5 TangentialPenalty 1e5 Friction 0.3
Steps
  Step 1 Dynamic Duration 0.01 TimeStep 1e-3
  Step 2 MoveWall drum Rotate AngularVelocity 3 0 0 Center 0 0 1 Duration 0.01 TimeStep 1e-3 Damping Implicit Safety 0.4
  Step 3 MoveWall drum Table "turn table.csv" Center 0 0 1 Duration 0.02 TimeStep 1e-3 Accuracy 1e-4
  Step 3 MoveWall floor Displacement 0 0 0.001
  Step 4 MoveWall floor Table lift.csv TimeStep 1e-3
  Step 4 MoveWall drum Rotate AngularVelocity 1 0 0 Center 0 0 1 Displacement 0 0.001 0
  Step 4 MoveWall top Table lift.csv
"""


# ---------------------------------------------------------------------------- model equality


def signature(x):
    """A comparable form of a model value that tells apart everything a deck can set: every
    field of every entry (line numbers aside), floats by their exact value and sign, arrays
    by dtype, shape and bytes, shapes by their patches, name, file and convexity tolerance,
    paths as paths, dicts and lists in their order."""
    if is_dataclass(x) and not isinstance(x, type):
        return (type(x).__name__,) + tuple((f.name, signature(getattr(x, f.name)))
                                           for f in fields(x) if f.name != "line")
    if hasattr(x, "patches") and hasattr(x, "volume"):
        return ("shape", signature(list(x.patches)), x.name, x.source,
                signature(getattr(x, "convexity_tol", None)))
    if hasattr(x, "control_points") and hasattr(x, "knots_u"):
        return ("patch", x.degree_u, x.degree_v) + tuple(
            signature(getattr(x, k)) for k in ("knots_u", "knots_v", "control_points", "weights"))
    if isinstance(x, np.ndarray):
        return ("array", x.dtype.str, x.shape, x.tobytes())
    if isinstance(x, Path):
        return ("path", str(x))
    if isinstance(x, dict):
        return ("dict", tuple((k, signature(v)) for k, v in x.items()))
    if isinstance(x, (list, tuple)):
        return (type(x).__name__, tuple(signature(v) for v in x))
    if isinstance(x, (float, np.floating)):
        return (type(x).__name__, float(x).hex())
    return (type(x).__name__, x)


def model_signature(model):
    """The signature of everything a deck sets (its path, text and placed bodies aside)."""
    return tuple((f.name, signature(getattr(model, f.name))) for f in fields(model)
                 if f.name not in ("path", "text", "bodies"))


def round_trip(text: str, path: Path):
    """(model of ``text``, its formatted text, the model of that text), both read from
    ``path`` (the same folder)."""
    model = build_model(text, str(path))
    formatted = format_model(model)
    return model, formatted, build_model(formatted, str(path))


@pytest.fixture
def nurbs_deck(tmp_path):
    (tmp_path / "my shapes").mkdir()
    shutil.copy(ROOT / "inputs" / "shapes" / "A.yaml", tmp_path / "my shapes" / "A.yaml")
    path = tmp_path / "every_key.inp"
    path.write_text(NURBS_DECK)
    return path


@pytest.fixture
def curved_deck(tmp_path):
    import trimesh
    trimesh.Trimesh([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]],
                    [[0, 1, 2], [0, 2, 3]]).export(tmp_path / "floor.stl")
    save_shape(tmp_path / "drum.yaml", [cylinder_patch(0.1, 0.2, axis=(0, 0, 1))])
    (tmp_path / "turn table.csv").write_text("t,x,y,z,rx,ry,rz\n0,0,0,0,0,0,0\n"
                                             "0.01,0,0,0.001,0.01,0.02,0.03\n")
    (tmp_path / "lift.csv").write_text("0,0,0,0\n0.005,0,0,1e-4\n0.01,0,0,1.5e-4\n")
    path = tmp_path / "curved.inp"
    path.write_text(CURVED_DECK)
    return path


# ---------------------------------------------------------------------------- round trips


@pytest.mark.parametrize("deck", DECKS, ids=[str(p.relative_to(ROOT)) for p in DECKS])
def test_every_deck_of_the_repository_reads_back(deck):
    model, formatted, again = round_trip(read_deck_text(deck), deck)
    assert model_signature(again) == model_signature(model)
    assert format_model(again) == formatted


@pytest.mark.parametrize("fixture", ["nurbs_deck", "curved_deck"])
def test_every_entry_and_key_reads_back(fixture, request):
    path = request.getfixturevalue(fixture)
    model, formatted, again = round_trip(path.read_text(), path)
    assert model_signature(again) == model_signature(model)
    assert format_model(again) == formatted


def test_the_two_decks_write_every_key_of_the_schema(nurbs_deck, curved_deck):
    """Every key the parser accepts is on a formatted line of its entry (a key added to the
    schema needs its place in the formatter and in these decks)."""
    written = set()
    for path in (nurbs_deck, curved_deck):
        for line in round_trip(path.read_text(), path)[1].splitlines():
            words = line.split("#")[0].split()
            written |= {(words[0], w) for w in words[1:]} | {(words[0], None)}
    for block, specs in SCHEMA.items():
        for keyword, spec in specs.items():
            assert (keyword, None) in written, keyword
            for key in spec.keys:
                assert (keyword, key) in written, f"{keyword} {key}"


def test_the_formatted_deck_holds_what_the_deck_says(nurbs_deck):
    _, formatted, _ = round_trip(nurbs_deck.read_text(), nurbs_deck)
    lines = formatted.splitlines()
    assert '  Shape 2 File "my shapes/A.yaml" ConvexityTolerance 0.001' in lines
    assert "  Material 3 Density 1150.5 PoissonRatio 0.25" in lines
    assert "  Material 2 Density 7800.0 YoungModulus 200000000000.0 PoissonRatio 0.0" in lines
    assert "  Box 1 Min -0.013 0.007 0.0 Max 0.2 0.2 0.41 Top no Material 1" in lines
    assert "  Wall 7 Name shelf Point 0.1 0.1 -0.05 Normal 0.0 0.0 1.0 Size 0.3 0.3 Material 2" in lines
    assert "  Interface 2 Model HertzMindlin Restitution 0.6 Friction 0.2 Materials 1 2" in lines
    assert f'  Directory "{nurbs_deck.parent / "out dir" / "run 1"}"' in lines


def test_a_direction_is_written_so_that_it_normalises_to_itself():
    for d in ([1, 1, -3], [0.1, 0.2, 0.3], [3, 4, 0], [1e-3, -7, 2]):
        unit = np.asarray(d, float) / np.linalg.norm(d)
        c = unit_preimage(unit)
        assert np.array_equal(c / np.linalg.norm(c), unit)


# ---------------------------------------------------------------------------- it can fail


def test_a_dropped_entry_is_caught(nurbs_deck):
    """Without any one of its entry lines, the formatted deck is refused or reads as a
    different model."""
    model, formatted, _ = round_trip(nurbs_deck.read_text(), nurbs_deck)
    lines = formatted.splitlines()
    entries = [i for i, line in enumerate(lines) if line.startswith("  ")]
    assert len(entries) > 25
    for i in entries:
        text = "\n".join(lines[:i] + lines[i + 1:])
        try:
            other = build_model(text, str(nurbs_deck))
        except InputError:
            continue
        assert model_signature(other) != model_signature(model), lines[i]


def test_a_formatter_that_drops_an_entry_is_caught(monkeypatch):
    real = deck_format.particle_entries
    monkeypatch.setattr(deck_format, "particle_entries", lambda model: real(model)[:-1])
    deck = ROOT / "inputs" / "regression" / "lid_press.inp"
    model, _, again = round_trip(read_deck_text(deck), deck)
    assert len(again.particles) == 2
    assert model_signature(again) != model_signature(model)


def test_a_dropped_key_or_a_rounded_number_is_caught(nurbs_deck, monkeypatch):
    model, formatted, _ = round_trip(nurbs_deck.read_text(), nurbs_deck)
    for old in (" Seed 11", " MaxAttempts 5000", " PoissonRatio 0.25", " Top no",
                " Damping Implicit", " Results Every 0.01", " Axis"):
        assert old in formatted
    assert model_signature(build_model(formatted.replace(" Seed 11", ""), str(nurbs_deck))) \
        != model_signature(model)
    monkeypatch.setattr(deck_format, "number", lambda x: f"{float(x):.6g}")
    deck = ROOT / "inputs" / "regression" / "drop_one.inp"
    model, formatted, again = round_trip(read_deck_text(deck), deck)
    assert model_signature(again) != model_signature(model)


def test_a_model_the_deck_cannot_hold_is_refused(nurbs_deck):
    model = build_model(nurbs_deck.read_text(), str(nurbs_deck))
    model.walls[0].patch.control_points[0, 0, 0] += 1e-3   # no longer a box
    with pytest.raises(ValueError, match="no Box makes them exactly"):
        format_model(model)
    with pytest.raises(ValueError, match="cannot be written as one deck value"):
        deck_format.word('a "quoted" name')


# ---------------------------------------------------------------------------- Simulation


def test_deck_text_of_a_scene_built_in_python_reads_back(tmp_path):
    sim = Simulation(gravity=(0, 0.1, -9.81), output=str(tmp_path / "res"))
    sim.add_material(2, density=2700.1, young_modulus=1e9, poisson_ratio=0.3)
    sim.add_material(1, density=1000, young_modulus=2e8)
    sim.add_interface(normal_penalty=1e5, normal_damping=0.1, friction=0.3)
    sim.add_interface(model="HertzMindlin", restitution=0.5, materials=(1, 2))
    sim.add_box(min=(0, 0, 0), max=(0.1, 0.3, 0.7), top=True, material=2)
    sim.add_wall("lid", point=(0.05, 0.1, 0.33), normal=(0.1, 0.2, -1), size=(0.1, 0.2),
                 axis=(1, 0.3, 0))
    sim.add_particle(shapes.sphere(0.01), material=1, position=(0.05, 0.05, 0.1),
                     velocity=(0.1, 0, 0))
    sim.add_particle(ROOT / "inputs" / "shapes" / "A.yaml", material=2,
                     position=(0.05, 0.2, 0.3), rotation=(0.1, 0.2, math.pi / 3))
    text = sim.deck_text
    assert text.startswith("# scene built in Python (nurbsdem.Simulation)\nEnvironment\n")
    model = build_model(text, str(tmp_path / "generated.inp"))
    for part in ("gravity", "particles", "walls", "interfaces"):
        assert signature(getattr(model, part)) == signature(getattr(sim.model, part)), part
    assert list(model.materials) == [1, 2]          # deck_text lists the materials by id
    assert signature(dict(sorted(sim.model.materials.items()))) == signature(model.materials)
    for sid, entry in sim.model.shapes.items():
        assert signature(model.shapes[sid].shape.patches) == signature(entry.shape.patches)
    assert model.output.directory == (tmp_path / "res").resolve()


def test_deck_text_names_a_python_shape_object_by_its_geometry():
    sim = Simulation()
    sim.add_material(1, density=1000)
    sim.add_particle(shapes.ellipsoid(0.01, 0.02, 0.015), material=1, position=(0, 0, 0))
    line = [x for x in sim.deck_text.splitlines() if x.startswith("  Shape 1 ")][0]
    assert line.startswith('  Shape 1 File "<python object ellipsoid')
    assert "  # geometry sha256 " in line
    assert sim.deck_text.endswith("Steps\nOutput\n")

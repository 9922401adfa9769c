"""The input deck: the paper's example parses; every mistake is a one-line file:line error."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from nurbsdem import save_shape, shapes
from nurbsdem.errors import InputError
from nurbsdem.io.deck import parse_deck
from nurbsdem.model import DynamicStep, MoveWallStep, ReplicateStep

ROOT = Path(__file__).resolve().parents[1]
PAPER_SHAPES = ROOT / "inputs" / "shapes"

PAPER_DECK = """\
Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2700
Shapes
  Shape 1 File shapes/A.yaml
  Shape 2 File shapes/B.yaml
  Shape 3 File shapes/C.yaml
  Shape 4 Sphere Radius 0.02          # generators: Sphere, Ellipsoid SemiAxes a b c
  # mass properties may be overridden: Volume V Inertia Jxx Jyy Jzz Jxy Jxz Jyz
Particles
  Random 1 Shapes 1 2 3 Counts 5 3 6 Material 1 Region 0.01 0.01 0.01 0.24 0.24 0.24 Seed 1
  # single bodies: Particle 15 Shape 1 Material 1 Position x y z Rotation rx ry rz Velocity vx vy vz AngularVelocity wx wy wz
  # (Position = centroid; Rotation = rotation vector in rad; velocities in the world frame)
Walls
  Box 1 Min 0 0 0 Max 0.25 0.25 0.60      # bottom and four sides, flat NURBS
  Wall 6 Name lid Point 0.125 0.125 0.60 Normal 0 0 -1 Size 0.25 0.25
Contact
  Interface 1 NormalPenalty 1e5 TangentialPenalty 1e4 NormalDamping 1e2 TangentialDamping 0 Friction 0.5
Steps
  Step 1 Dynamic Duration 2.0 TimeStep 1e-3
  Step 2 Replicate Layers 8 Height 0.50
  Step 3 Dynamic Duration 2.5 TimeStep 1e-3
  Step 4 MoveWall lid ToContact Gap 0.005        # bring the lid down onto the pack
  Step 5 MoveWall lid Displacement 0 0 -0.08 Duration 1.0 TimeStep 1e-3
  Step 6 MoveWall lid Displacement 0 0 0.08 Duration 1.0 TimeStep 1e-3
Output
  Directory results
  VTK Every 0.01 Resolution 8
  Monitors Every 0.001
"""


@pytest.fixture(scope="module")
def workdir(tmp_path_factory) -> Path:
    """A folder with shapes/E.yaml (an ellipsoid), shapes/S.yaml and a few bad shape files."""
    d = tmp_path_factory.mktemp("decks")
    (d / "shapes").mkdir()
    save_shape(d / "shapes" / "E.yaml", shapes.ellipsoid(0.03, 0.025, 0.02, name="E"))
    save_shape(d / "shapes" / "S.yaml", shapes.sphere(0.02, name="S"))
    (d / "shapes" / "empty.yaml").write_text("patches: []\n")
    (d / "shapes" / "syntax.yaml").write_text("name: x\npatches:\n  - degree_u: [1\n")
    return d


BASE = """\
Materials
  Material 1 Density 2700
Shapes
  Shape 1 File shapes/E.yaml
Particles
  Random 1 Shapes 1 Counts 3 Material 1 Region 0 0 0 0.2 0.2 0.2 Seed 2
Walls
  Box 1 Min 0 0 0 Max 0.2 0.2 0.4
  Wall 6 Name lid Point 0.1 0.1 0.4 Normal 0 0 -1 Size 0.2 0.2
Contact
  Interface 1 NormalPenalty 1e5
Steps
  Step 1 Dynamic Duration 1 TimeStep 1e-3
  Step 2 MoveWall lid ToContact
"""


def _write(workdir: Path, text: str, name: str = "case.inp") -> str:
    path = workdir / name
    path.write_text(text)
    return str(path)


def _edit(line: int, new: str | None, base: str = BASE) -> str:
    """BASE with line ``line`` (1-based) replaced by ``new`` (None deletes; line 0 appends)."""
    lines = base.splitlines()
    if line == 0:
        lines.append(new)
    elif new is None:
        del lines[line - 1]
    else:
        lines[line - 1] = new
    return "\n".join(lines) + "\n"


def test_base_deck_parses(workdir):
    m = parse_deck(_write(workdir, BASE))
    assert len(m.bodies) == 3
    assert m.wall_names == ["bottom", "x_min", "x_max", "y_min", "y_max", "lid"]
    assert [w.id for w in m.walls] == [1, 2, 3, 4, 5, 6]
    assert m.output.directory == workdir / "results"
    assert m.output.vtk_every == 0.01 and m.output.vtk_resolution == 8
    assert m.output.monitors_every == 1e-3
    assert m.interface("particle-wall", (1,)).normal_penalty == 1e5
    assert m.text == BASE


# (line to replace (0 = append), new text, expected error line, expected message)
BAD_DECKS = [
    (1, "Materals", 1, "unknown block 'Materals' (did you mean 'Materials'?)"),
    (2, "  Material 1 Densty 2700", 2, "Material 1: unknown keyword 'Densty' (did you mean 'Density'?)"),
    (2, "  Material 1 Density", 2, "Material 1: Density needs a value"),
    (2, "  Material 1 Density 27o0", 2, "Material 1: Density: bad number '27o0'"),
    (2, "  Material 1 Density -5", 2, "Material 1: Density must be > 0, got -5"),
    (2, "  Material x Density 5", 2, "Material id: bad integer 'x'"),
    (2, "  Material 1 Density 2700 2", 2, "Material 1: Density takes 1 number, got more ('2')"),
    (2, "  Material 1 Density 2700 Density 3", 2, "Material 1: Density given twice"),
    (2, "  Foo 1 Density 2700", 2, "unknown keyword 'Foo' in block Materials (expected Material)"),
    (0, "Materials\n  Material 1 Density 2000", 16, "duplicate material id 1 (first at line 2)"),
    (1, "Materials 2", 1, "block keyword 'Materials' must be alone on its line (got '2' after it)"),
    (4, "  Shape 1 File shapes/missing.yaml", 4, "shape file shapes/missing.yaml: no such file"),
    (4, "  Shape 1 File shapes/empty.yaml", 4,
     "shape file shapes/empty.yaml: 'patches' must be a non-empty list"),
    (4, "  Shape 1 File shapes/syntax.yaml", 4,
     "shape file shapes/syntax.yaml:4: while parsing a flow sequence, expected ',' or ']', "
     "but got '<stream end>'"),
    (4, "  Shape 1 File shapes/E.yaml Radius 2", 4, "Shape 1: Radius does not apply to a File shape"),
    (4, "  Shape 1 Sphere", 4, "Shape 1: missing Radius"),
    (4, "  Shape 1 Ellipsoid SemiAxes 0.1 0.1", 4, "Shape 1: SemiAxes needs 3 numbers, got 2"),
    (4, "  Shape 1 Sphere Radius 0.02 File shapes/E.yaml", 4,
     "Shape 1: give exactly one of File, Sphere, Ellipsoid (got File and Sphere)"),
    (4, "  Shape 1 Sphere Radius 0.02 Inertia 1 1 1 0 0 2", 4,
     "Shape 1: Inertia is not positive definite (principal moments -1, 1, 3)"),
    (4, '  Shape 1 File "shapes/E.yaml', 4, "unbalanced double quote"),
    (6, "  Random 1 Shapes 2 Counts 3 Material 1 Region 0 0 0 0.2 0.2 0.2", 6,
     "Random 1: unknown shape 2 (defined shapes: 1)"),
    (6, "  Random 1 Shapes 1 Counts 3 Material 7 Region 0 0 0 0.2 0.2 0.2", 6,
     "Random 1: unknown material 7 (defined materials: 1)"),
    (6, "  Random 1 Shapes 1 Counts 3 2 Material 1 Region 0 0 0 0.2 0.2 0.2", 6,
     "Random 1: Shapes lists 1 shapes but Counts 2 numbers"),
    (6, "  Random 1 Shapes 1 Counts 3 Material 1 Region 0 0 0 0.2 0.2", 6,
     "Random 1: Region needs 6 numbers, got 5"),
    (6, "  Random 1 Shapes 1 Counts 3 Material 1", 6, "Random 1: missing Region"),
    (6, "  Random 1 Shapes 1 Counts 3 Material 1 Region 0 0 0 0.05 0.2 0.2", 6,
     "Random 1: the region is too small for shape 1 (bounding radius 0.03839 m needs at "
     "least 0.07679 m in each direction)"),
    (6, "  Random 1 Shapes 1 Counts 12 Material 1 Region 0 0 0 0.2 0.2 0.2 MaxAttempts 50", 6,
     "Random 1: could not place particle 7 (shape 1) without overlap after 50 attempts "
     "(6 of 12 placed); enlarge Region or reduce Counts"),
    (6, "  Random 1 Shapes 1 Counts 300 Material 1 Region 0 0 0 0.2 0.2 0.2 MaxAttempts 50", 6,
     "Random 1: the bounding spheres of its 300 particles fill 889 % of the Region, but random "
     "placement jams at about 38 %: enlarge Region to at least 0.187 m^3 or reduce Counts"),
    (0, "Particles\n  Particle 2 Shape 1 Material 1 Position 0.1 0.1 0.3", 16,
     "Particle 2: particle id 2 already used by Random 1 (line 6)"),
    (0, "Particles\n  Particle 9 Shape 3 Material 1 Position 0.1 0.1 0.3", 16,
     "Particle 9: unknown shape 3 (defined shapes: 1)"),
    (0, "Particles\n  Particle 9 Shape 1 Material 1 Position 0.1 0.1", 16,
     "Particle 9: Position needs 3 numbers, got 2"),
    (9, "  Wall 3 Name lid Point 0.1 0.1 0.4 Normal 0 0 -1 Size 0.2 0.2", 9,
     "Wall 3: wall id 3 already used (line 8)"),
    (9, "  Wall 6 Name bottom Point 0.1 0.1 0.4 Normal 0 0 -1 Size 0.2 0.2", 9,
     "Wall 6: duplicate wall name 'bottom' (first at line 8)"),
    (9, "  Wall 6 Name lid Point 0.1 0.1 0.4 Normal 0 0 0 Size 0.2 0.2", 9,
     "Wall 6: Normal must not be zero"),
    (8, "  Box 1 Min 0 0 0 Max 0.2 0.2 0.4 Top maybe", 8, "Box 1: Top: expected yes or no, got 'maybe'"),
    (11, "  Interface 1 NormalPenalty 1e5 Between particle-sky", 11,
     "Interface 1: Between must be particle-particle or particle-wall, got 'particle-sky'"),
    (11, "  Interface 1 NormalPenalty 1e5 Between particle-particle", 6,
     "no contact Interface covers particle-wall pairs of material 1"),
    (11, "  Interface 1 Friction 0.3", 11, "Interface 1: missing NormalPenalty"),
    (13, "  Step 1 Dynamic Duration 0 TimeStep 1e-3", 13, "Step 1: Duration must be > 0, got 0"),
    (13, "  Step 1 Dynamic Duration 1 TimeStep -1e-3", 13,
     "Step 1: TimeStep must be > 0, got -0.001"),
    (13, "  Step 1 Dynamic Duration 1", 13, "Step 1: missing TimeStep"),
    (13, "  Step 1 Dynamic Duration 1 TimeStep 1e-3 Damping Semi", 13,
     "Step 1: Damping must be Explicit or Implicit, got 'Semi'"),
    (14, "  Step 2 MoveWall lid ToContact Damping Implicit", 14,
     "Step 2: Damping does not apply to MoveWall ToContact"),
    (13, "  Step 1 Dynamc Duration 1 TimeStep 1e-3", 13,
     "Step 1: unknown keyword 'Dynamc' (did you mean 'Dynamic'?)"),
    (13, "  Step 1 Duration 1 TimeStep 1e-3", 13,
     "Step 1: give exactly one of Dynamic, Replicate, MoveWall"),
    (13, "  Step 1 Dynamic Duration 1 TimeStep 1e-3 Layers 3", 13,
     "Step 1: Layers does not apply to a Dynamic step"),
    (14, "  Step 2 MoveWall top ToContact", 14,
     "Step 2: no wall named 'top' (walls: bottom, x_min, x_max, y_min, y_max, lid)"),
    (14, "  Step 2 MoveWall lid Displacement 0 0 -0.1", 14, "Step 2: missing Duration"),
    (14, "  Step 2 MoveWall ToContact", 14, "Step 2: MoveWall needs a value"),
    (14, "  Step 1 Replicate Layers 2 Height 0.1", 14, "duplicate step id 1 (first at line 13)"),
    (0, "Output\n  VTK Every 0", 16, "VTK: Every must be > 0, got 0"),
    (0, "Output\n  Monitors Evry 0.1", 16, "Monitors: unknown keyword 'Evry' (did you mean 'Every'?)"),
    (0, "Environment\n  Gravity 0 -9.81", 16, "Gravity needs 3 numbers, got 2"),
    (0, "Environment\n  Gravity 0 0 -9.81 1", 16, "Gravity takes 3 numbers, got more ('1')"),
    (0, "Environment\n  Gravity 0 0 nan", 16, "Gravity: bad number 'nan'"),
]


@pytest.mark.parametrize("line,new,err_line,message", BAD_DECKS,
                         ids=[f"{i}:{c[3][:30]}" for i, c in enumerate(BAD_DECKS)])
def test_bad_deck(workdir, line, new, err_line, message):
    path = _write(workdir, _edit(line, new), "bad.inp")
    with pytest.raises(InputError) as info:
        parse_deck(path)
    text = str(info.value)
    assert "\n" not in text
    assert text == f"{path}:{err_line}: {message}"
    assert info.value.line == err_line


def test_entries_outside_block(workdir):
    path = _write(workdir, "Material 1 Density 2\n", "bad.inp")
    with pytest.raises(InputError, match=r"bad\.inp:1: 'Material' outside a block"):
        parse_deck(path)


def test_explicit_particles_overlap(workdir):
    text = _edit(0, "Particles\n  Particle 10 Shape 1 Material 1 Position 0.1 0.1 0.3\n"
                    "  Particle 11 Shape 1 Material 1 Position 0.1 0.12 0.31")
    path = _write(workdir, text, "bad.inp")
    with pytest.raises(InputError) as info:
        parse_deck(path)
    assert str(info.value).startswith(f"{path}:17: particle 11 overlaps particle 10 by ")


def test_explicit_particles_touching_bounding_spheres_is_fine(workdir):
    # ellipsoids 0.03 x 0.025 x 0.02: side by side along y at 0.052 m do not touch, though
    # their bounding spheres (0.038 m) overlap
    text = _edit(0, "Particles\n  Particle 10 Shape 1 Material 1 Position 0.1 0.1 0.3\n"
                    "  Particle 11 Shape 1 Material 1 Position 0.1 0.152 0.3")
    m = parse_deck(_write(workdir, text))
    assert list(m.bodies.id) == [1, 2, 3, 10, 11]


def test_comments_case_and_quotes(workdir):
    text = """\
// a comment line
materials   # lower-case block
  MATERIAL 1 density 1000   // trailing comment
shapes
  shape 1 file "shapes/E.yaml" volume 1e-4 inertia 1e-5 2e-5 2.5e-5 0 0 0
  Shape 2 Ellipsoid SemiAxes 0.03 0.02 0.01
particles
  particle 3 shape 1 material 1 position 0.1 0.1 0.1 rotation 0 0 1.5707963 velocity 1 0 0 angularvelocity 0 0 2
walls
  box 1 min 0 0 0 max 1 1 1 top yes
contact
  interface 1 normalpenalty 1e5 friction 0.3
  interface 2 NormalPenalty 2e5 Between particle-wall
  Interface 3 NormalPenalty 3e5 Materials 1 1
steps
  step 1 dynamic duration 0.5 timestep 1e-4
Output
  Directory out/here
  Checkpoint Every 0.25
  Results Every 0.05
"""
    m = parse_deck(_write(workdir, text))
    assert m.materials[1].density == 1000
    e = m.shapes[1]
    assert e.source == "shapes/E.yaml" and e.volume == 1e-4
    np.testing.assert_array_equal(e.mass_inertia(1000.0), np.diag([1e-5, 2e-5, 2.5e-5]))
    assert e.mass(1000.0) == pytest.approx(0.1)
    assert m.shapes[2].kind == "ellipsoid"
    np.testing.assert_allclose(m.shapes[2].mass_inertia(1.0), m.shapes[2].shape.inertia)
    assert m.wall_names[-1] == "top" and len(m.walls) == 6
    assert m.interface("particle-wall", (1,)).id == 2
    assert m.interface("particle-particle", (1, 1)).id == 3
    b = m.bodies
    np.testing.assert_allclose(b.rotation_matrices()[0] @ [1, 0, 0], [0, 1, 0], atol=1e-7)
    np.testing.assert_array_equal(b.velocity[0], [1, 0, 0])
    assert m.output.directory == workdir / "out" / "here"
    assert m.output.checkpoint_every == 0.25 and m.output.results_interval == 0.05
    assert m.output.vtk_every == 0.01


def test_steps_are_typed(workdir):
    text = BASE.replace("  Step 2 MoveWall lid ToContact\n",
                        "  Step 2 Replicate Layers 3 Height 0.3\n"
                        "  Step 3 MoveWall lid ToContact Gap 0.001\n"
                        "  Step 4 MoveWall lid Displacement 0 0 -0.01 Duration 0.5 TimeStep 1e-3\n")
    m = parse_deck(_write(workdir, text), place=False)
    assert m.bodies is None
    kinds = [type(s) for s in m.steps]
    assert kinds == [DynamicStep, ReplicateStep, MoveWallStep, MoveWallStep]
    assert m.steps[1].layers == 3 and m.steps[1].height == 0.3
    assert m.steps[2].to_contact and m.steps[2].gap == 0.001
    np.testing.assert_array_equal(m.steps[3].displacement, [0, 0, -0.01])
    assert m.total_time == 1.5


def _paper_shapes_ready() -> bool:
    return all((PAPER_SHAPES / f"{n}.yaml").is_file() for n in "ABC")


@pytest.mark.skipif(not _paper_shapes_ready(), reason="inputs/shapes/A,B,C.yaml not generated yet")
def test_paper_deck_as_written(tmp_path):
    shutil.copytree(PAPER_SHAPES, tmp_path / "shapes")
    deck = tmp_path / "case.inp"
    deck.write_text(PAPER_DECK)
    m = parse_deck(deck)
    _check_paper_model(m)
    assert m.output.directory == tmp_path / "results"


@pytest.mark.skipif(not _paper_shapes_ready(), reason="inputs/shapes/A,B,C.yaml not generated yet")
def test_shipped_paper_deck():
    m = parse_deck(ROOT / "inputs" / "paper" / "compaction.inp")
    _check_paper_model(m)


def _check_paper_model(m) -> None:
    assert len(m.bodies) == 14
    assert list(np.bincount(m.bodies.shape_id)[1:]) == [5, 3, 6]
    np.testing.assert_array_equal(m.gravity, [0, 0, -9.81])
    assert m.wall_names == ["bottom", "x_min", "x_max", "y_min", "y_max", "lid"]
    assert [s.kind for s in m.steps] == ["dynamic", "replicate", "dynamic", "movewall",
                                         "movewall", "movewall"]
    itf = m.interface("particle-particle", (1, 1))
    assert (itf.normal_penalty, itf.tangential_penalty, itf.normal_damping, itf.friction) == \
        (1e5, 1e4, 1e2, 0.5)
    assert m.total_time == pytest.approx(6.5)
    # volumes of the paper's particles (Table 1): 98.57, 50.47, 21.29 cm^3
    for sid, vol in ((1, 98.57e-6), (2, 50.47e-6), (3, 21.29e-6)):
        assert m.shapes[sid].volume == pytest.approx(vol, rel=2e-3)
    s = m.summary()
    assert "Particles: 14" in s and "lid" in s and "Total simulated time: 6.5 s" in s


def test_summary(workdir):
    m = parse_deck(_write(workdir, BASE))
    s = m.summary()
    assert s.splitlines()[0].startswith("Deck: ")
    assert "Particles: 3" in s and "MoveWall lid to contact" in s


def test_cannot_read_deck(tmp_path):
    with pytest.raises(InputError, match="cannot read deck"):
        parse_deck(tmp_path / "nope.inp")

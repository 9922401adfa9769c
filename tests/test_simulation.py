"""The Python API (nurbsdem.Simulation): a scene built in Python runs bit for bit like the same
scene written as a deck, through the same Solver; restart from a checkpoint; input errors."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import nurbsdem
from nurbsdem.errors import InputError
from nurbsdem.io.deck import build_model
from nurbsdem.io.results import read_results_sample, read_results_times
from nurbsdem.model import DynamicStep, MoveWallStep, ReplicateStep, model_differences
from nurbsdem.simulation import Simulation
from nurbsdem.solver import Solver

ROOT = Path(__file__).resolve().parents[1]
C_FILE = ROOT / "inputs" / "shapes" / "C.yaml"

#: Written by hand (not by Simulation.deck_text): the scene of build_scene() below.
DECK = f"""
Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2700
  Material 2 Density 1000
Shapes
  Shape 1 Sphere Radius 0.01
  Shape 2 File {C_FILE}
Particles
  Particle 1 Shape 1 Material 1 Position 0.03 0.03 0.011
  Particle 2 Shape 2 Material 1 Position 0.07 0.06 0.025 Rotation 0 0 0.5
  Particle 3 Shape 1 Material 2 Position 0.03 0.075 0.02 Velocity 0.1 0 0 AngularVelocity 0 3 0
Walls
  Box 1 Min 0 0 0 Max 0.1 0.1 0.12
  Wall 6 Name lid Point 0.05 0.05 0.12 Normal 0 0 -1 Size 0.1 0.1
Contact
  Interface 1 NormalPenalty 1e5 TangentialPenalty 1e4 NormalDamping 1e2 Friction 0.5
  Interface 2 NormalPenalty 2e5 TangentialPenalty 1e4 NormalDamping 50 Friction 0.3 Between particle-wall
Steps
  Step 1 Dynamic Duration 0.04 TimeStep 1e-3
  Step 2 Replicate Layers 2 Height 0.05
  Step 3 Dynamic Duration 0.02 TimeStep 1e-3
  Step 4 MoveWall lid ToContact Gap 0.002
  Step 5 MoveWall lid Displacement 0 0 -0.004 Duration 0.03 TimeStep 1e-3
Output
  Directory results
  VTK Every 0.02 Resolution 3
  Monitors Every 0.002
  Checkpoint Every 0.025
"""

OUTPUT = dict(vtk_every=0.02, vtk_resolution=3, monitors_every=0.002, checkpoint_every=0.025)


def build_scene(output=None, restart=None) -> Simulation:
    sim = Simulation(gravity=(0, 0, -9.81), output=output, restart=restart, **OUTPUT)
    sim.add_material(1, density=2700)
    sim.add_material(2, density=1000)
    sphere = nurbsdem.shapes.sphere(0.01)
    assert sim.add_particle(sphere, 1, (0.03, 0.03, 0.011)) == 1
    sim.add_particle(nurbsdem.load_shape(C_FILE), 1, (0.07, 0.06, 0.025), rotation=(0, 0, 0.5))
    sim.add_particle(sphere, 2, (0.03, 0.075, 0.02), velocity=(0.1, 0, 0),
                     angular_velocity=(0, 3, 0))
    assert sim.add_box(min=(0, 0, 0), max=(0.1, 0.1, 0.12)) == ["bottom", "x_min", "x_max",
                                                                 "y_min", "y_max"]
    sim.add_wall("lid", point=(0.05, 0.05, 0.12), normal=(0, 0, -1), size=(0.1, 0.1))
    sim.add_interface(normal_penalty=1e5, tangential_penalty=1e4, normal_damping=1e2,
                      friction=0.5)
    sim.add_interface(normal_penalty=2e5, tangential_penalty=1e4, normal_damping=50,
                      friction=0.3, between="particle-wall")
    return sim


def run_steps(sim: Simulation) -> Simulation:
    sim.run_dynamic(duration=0.04, time_step=1e-3)
    sim.replicate(layers=2, height=0.05)
    sim.run_dynamic(duration=0.02, time_step=1e-3)
    sim.move_wall("lid", to_contact=True, gap=0.002)
    sim.move_wall("lid", displacement=(0, 0, -0.004), duration=0.03, time_step=1e-3)
    return sim


MONITORS = ("energy.csv", "contacts.csv", "wall_lid.csv", "wall_bottom.csv")


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The scene run from the hand-written deck (as ``nurbsdem solve`` does) and from Python."""
    d = tmp_path_factory.mktemp("api")
    deck = d / "case.inp"
    deck.write_text(DECK)
    deck_sim = Simulation.from_deck(deck, output=d / "deck")
    deck_summary = deck_sim.run()
    py = run_steps(build_scene(output=d / "python"))
    py_summary = py.close()
    return d, deck_sim, deck_summary, py, py_summary


def test_python_scene_runs_bit_for_bit_like_the_deck(runs):
    d, deck_sim, deck_summary, py, py_summary = runs
    assert len(py.positions) == 6 and py_summary.steps == deck_summary.steps == 90
    np.testing.assert_array_equal(py.positions, deck_sim.positions)
    np.testing.assert_array_equal(py.quaternions, deck_sim.quaternions)
    np.testing.assert_array_equal(py.velocities, deck_sim.velocities)
    times = read_results_times(d / "python" / "results.h5")
    np.testing.assert_array_equal(times, read_results_times(d / "deck" / "results.h5"))
    a = read_results_sample(d / "python" / "results.h5", -1)
    b = read_results_sample(d / "deck" / "results.h5", -1)
    for key in ("particle_id", "position", "quaternion", "velocity", "angular_velocity"):
        np.testing.assert_array_equal(a[key], b[key])
    for name in MONITORS:
        assert ((d / "python" / "monitors" / name).read_text()
                == (d / "deck" / "monitors" / name).read_text()), name


def test_steps_are_the_decks_step_objects(runs):
    _, deck_sim, _, py, _ = runs
    kinds = [type(s) for s in py.model.steps]
    assert kinds == [DynamicStep, ReplicateStep, DynamicStep, MoveWallStep, MoveWallStep]
    # the generated deck of the Python scene is the hand-written deck, physically
    model = build_model(py.deck_text, str(runs[0] / "generated.inp"))
    assert model_differences(model, deck_sim.model) == []


def test_state_between_steps(runs):
    _, _, _, py, _ = runs
    assert py.time == pytest.approx(0.09)
    assert py.rotations.shape == (6, 3, 3)
    np.testing.assert_allclose(py.rotations @ py.rotations.transpose(0, 2, 1),
                               np.broadcast_to(np.eye(3), (6, 3, 3)), atol=1e-12)
    e = py.energy()
    assert set(e) >= {"kinetic", "potential", "elastic", "dissipated", "external_work",
                      "mechanical", "balance_error"}
    # the last row of monitors/energy.csv is the state at the end of the last step
    last = (runs[0] / "python" / "monitors" / "energy.csv").read_text().splitlines()[-1]
    row = [float(x) for x in last.split(",")]
    assert row[0] == pytest.approx(e["time"])
    assert row[1] == e["kinetic"] and row[2] == e["potential"] and row[4] == e["dissipated"]
    c = py.contacts()
    k = len(c["depth"])
    assert k > 0 and c["pairs"].shape == (k, 2) and c["force"].shape == (k, 3)
    assert np.all(c["depth"] >= 0)
    np.testing.assert_allclose(np.linalg.norm(c["normal"], axis=1), 1.0, atol=1e-9)
    # bodies N + k are walls (k in wall_names order), particle id 0 in "ids"
    n = len(py.positions)
    wall = c["pairs"][:, 1] >= n
    assert wall.any() and np.all(c["ids"][wall, 1] == 0)
    assert {py.wall_names[j - n] for j in c["pairs"][wall, 1]} == {"bottom"}
    np.testing.assert_array_equal(c["ids"][:, 0], py.ids[c["pairs"][:, 0]])
    # the floor carries the bottom layer: upward forces on the particles
    assert np.all(c["force"][wall, 2] < 0)      # force on the wall (second body): downward
    assert py.wall_displacements["lid"][2] < -0.004


def test_cli_solve_builds_a_simulation(tmp_path, monkeypatch):
    """`nurbsdem solve` is Simulation.from_deck(...).run()."""
    from click.testing import CliRunner

    from nurbsdem.cli import main
    calls = []
    original = Simulation.run

    def spy(self):
        calls.append(self)
        return original(self)
    monkeypatch.setattr(Simulation, "run", spy)
    deck = tmp_path / "case.inp"
    deck.write_text(DECK.replace("Duration 0.04", "Duration 0.002").replace(
        "Duration 0.02", "Duration 0.002").replace("Duration 0.03", "Duration 0.002"))
    r = CliRunner().invoke(main, ["solve", str(deck), "--quiet", "--output", str(tmp_path / "o")])
    assert r.exit_code == 0, r.output
    assert len(calls) == 1 and (tmp_path / "o" / "results.h5").is_file()


def test_restart_from_a_checkpoint_through_the_api(runs, tmp_path, monkeypatch):
    """The script killed mid-step, then run again with restart=: the same final state and
    monitors as the uninterrupted run, bit for bit."""
    ref = runs[0] / "python"
    out = tmp_path / "out"

    class Killed(Exception):
        pass

    original = Solver._sample

    def dying_sample(self, writers, force=False, samples=(), states=()):
        original(self, writers, force, samples, states)
        if self.time > 0.071:             # in step 5 (the lid moving), after a checkpoint
            raise Killed
    monkeypatch.setattr(Solver, "_sample", dying_sample)
    killed = build_scene(output=out)
    with pytest.raises(Killed):
        run_steps(killed)
    monkeypatch.setattr(Solver, "_sample", original)
    with pytest.raises(InputError, match="stopped after an error.*restart="):
        killed.run_dynamic(0.01, 1e-3)
    sim = run_steps(build_scene(output=out, restart=out / "checkpoint.h5"))
    sim.close()
    np.testing.assert_array_equal(sim.positions, runs[3].positions)
    a = read_results_sample(out / "results.h5", -1)
    b = read_results_sample(ref / "results.h5", -1)
    for key in ("position", "quaternion", "velocity", "angular_velocity"):
        np.testing.assert_array_equal(a[key], b[key])
    np.testing.assert_array_equal(read_results_times(out / "results.h5"),
                                  read_results_times(ref / "results.h5"))
    for name in MONITORS:
        assert (out / "monitors" / name).read_text() == (ref / "monitors" / name).read_text()


def test_restart_with_other_steps_or_scene_is_refused(runs, tmp_path):
    ck = runs[0] / "python" / "checkpoint.h5"
    other = build_scene(output=tmp_path / "a", restart=ck)
    with pytest.raises(InputError, match="Step 1 is not the step the checkpoint ran"):
        other.run_dynamic(duration=0.05, time_step=1e-3)
    other = build_scene(output=tmp_path / "b", restart=ck)
    other.add_material(3, density=500)
    with pytest.raises(InputError, match="different scene.*Material 3"):
        other.run_dynamic(duration=0.04, time_step=1e-3)


def test_without_output_nothing_is_written_and_the_state_is_the_same(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    a = build_scene()
    a.run_dynamic(duration=0.01, time_step=1e-3)
    assert list(tmp_path.iterdir()) == []
    b = build_scene(output=tmp_path / "out")
    b.run_dynamic(duration=0.01, time_step=1e-3)
    np.testing.assert_array_equal(a.positions, b.positions)
    assert a.energy() == b.energy()


def test_deck_scene_with_python_steps(tmp_path):
    deck = tmp_path / "case.inp"
    deck.write_text(DECK)
    sim = Simulation.from_deck(deck, steps=False)
    assert sim.model.steps == [] and len(sim.positions) == 3
    sim.run_dynamic(duration=0.004, time_step=1e-3)
    ref = build_scene()
    ref.run_dynamic(duration=0.004, time_step=1e-3)
    np.testing.assert_array_equal(sim.positions, ref.positions)
    with pytest.raises(InputError, match="edited in the deck"):
        sim.add_material(5, 100)


# ---------------------------------------------------------------------------- errors


def small_scene() -> Simulation:
    sim = Simulation(gravity=(0, 0, -9.81))
    sim.add_material(1, 2700)
    sim.add_interface(normal_penalty=1e5, between="particle-wall")
    sim.add_interface(normal_penalty=1e5, materials=(1, 1))
    sim.add_box((0, 0, 0), (0.1, 0.1, 0.1))
    sim.add_particle(nurbsdem.shapes.sphere(0.01), 1, (0.05, 0.05, 0.02))
    return sim


@pytest.mark.parametrize("call, message", [
    (lambda s: s.add_material(2, -5), "material 2: Density must be > 0, got -5"),
    (lambda s: s.add_material(1, 100), "material 1 is already defined"),
    (lambda s: s.add_material(0, 100), "id must be an integer >= 1"),
    (lambda s: s.add_material(3, 1e9), "Density 1e+09 kg/m^3 is out of range"),
    (lambda s: s.add_particle(nurbsdem.shapes.sphere(0.01), 7, (0, 0, 0)), "unknown material 7"),
    (lambda s: s.add_particle("nope.yaml", 1, (0.02, 0.02, 0.02)), "nope.yaml: no such file"),
    (lambda s: s.add_particle(3.0, 1, (0.02, 0.02, 0.02)), "shape must be a Shape"),
    (lambda s: s.add_particle(nurbsdem.shapes.sphere(0.01), 1, (0, 0)), "Position must be 3 numbers"),
    (lambda s: s.add_particle(nurbsdem.shapes.sphere(0.01), 1, (0, 0, float("nan"))),
     "Position must be finite"),
    (lambda s: s.add_interface(normal_penalty=0), "normal_penalty must be > 0"),
    (lambda s: s.add_interface(normal_penalty=1e5, friction=-1), "friction must be >= 0"),
    (lambda s: s.add_interface(normal_penalty=1e5, between="walls"), "between must be"),
    (lambda s: s.add_wall("lid", (0, 0, 1), (0, 0, 0), (1, 1)), "normal must not be zero"),
    (lambda s: s.add_wall("bottom", (0, 0, 1), (0, 0, -1), (1, 1)), "'bottom' exists already"),
    (lambda s: s.add_box((0, 0, 0), (1, 1, -1)), "max must exceed min"),
    (lambda s: s.run_dynamic(0.01, 0.1), "Step 1: time_step 0.1 s exceeds duration 0.01 s"),
    (lambda s: s.run_dynamic(0.01, 3e-3), "Step 1: Duration 0.01 s is not a whole number of TimeStep"),
    (lambda s: s.run_dynamic(-1, 1e-3), "Step 1: Duration must be > 0"),
    (lambda s: s.run_dynamic(0.01, 1e-3, damping="semi"),
     "Step 1: damping must be 'explicit' or 'implicit', got 'semi'"),
    (lambda s: s.replicate(0, 0.1), "layers must be an integer >= 1"),
    (lambda s: s.move_wall("roof", to_contact=True), "no wall named 'roof'"),
    (lambda s: s.move_wall("bottom", displacement=(0, 0, 1)), "needs displacement, duration and time_step"),
    (lambda s: (s.add_particle(nurbsdem.shapes.sphere(0.01), 1, (0.055, 0.05, 0.02)),
                s.run_dynamic(0.01, 1e-3)), "particle 2 overlaps particle 1 by 0.015 m"),
    (lambda s: (s.add_particle(nurbsdem.shapes.sphere(0.01), 1, (0.05, 0.05, -0.02)),
                s.run_dynamic(0.01, 1e-3)), "particle 2 (centroid 0.05 0.05 -0.02 m) is"),
    (lambda s: (s.add_material(2, 1000),
                s.add_interface(normal_penalty=1e5, materials=(1, 1), id=5),
                s.add_particle(nurbsdem.shapes.sphere(0.01), 2, (0.02, 0.02, 0.02)),
                s.run_dynamic(0.01, 1e-3)),
     "no contact interface covers particle-particle pairs of materials 1 and 2"),
])
def test_bad_input_is_an_input_error_with_a_clear_message(call, message):
    sim = small_scene()
    with pytest.raises(InputError) as info:
        call(sim)
    text = str(info.value)
    assert message in text and "\n" not in text and "<python>" not in text
    assert info.value.path is None and info.value.line is None


def test_a_refused_step_leaves_the_simulation_usable():
    sim = small_scene()
    with pytest.raises(InputError, match="nothing to run"):
        sim.run()
    assert sim.add_particle(str(C_FILE), 1, (0.075, 0.075, 0.03)) == 2
    assert sim.model.shapes[2].kind == "file"
    with pytest.raises(InputError, match="not a whole number"):
        sim.run_dynamic(0.01, 3e-3)
    sim.run_dynamic(0.01, 1e-3)
    with pytest.raises(InputError, match="Step 2: time_step"):
        sim.run_dynamic(0.001, 0.01)
    sim.run_dynamic(0.002, 1e-3)
    assert [s.id for s in sim.model.steps] == [1, 2]
    assert sim.time == pytest.approx(0.012)
    with pytest.raises(InputError, match="fixed once a step has run"):
        sim.add_particle(nurbsdem.shapes.sphere(0.01), 1, (0.02, 0.02, 0.05))


def test_simulation_is_exposed_lazily():
    code = ("import sys; import nurbsdem; "
            "assert 'nurbsdem.simulation' not in sys.modules; "
            "assert 'Simulation' in dir(nurbsdem); nurbsdem.Simulation; "
            "assert 'nurbsdem.simulation' in sys.modules")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


def test_closed_then_continued_and_results_h5_keeps_the_whole_deck(tmp_path):
    import h5py
    sim = small_scene_with_output(tmp_path / "out")
    sim.run_dynamic(0.02, 1e-3)
    sim.close()
    sim.run_dynamic(0.02, 1e-3)
    summary = sim.close()
    assert summary.simulated_time == pytest.approx(0.04)
    np.testing.assert_allclose(read_results_times(tmp_path / "out" / "results.h5"),
                               [0.0, 0.01, 0.02, 0.03, 0.04], atol=1e-12)
    rows = (tmp_path / "out" / "monitors" / "energy.csv").read_text().splitlines()
    assert len(rows) == 1 + 21 and rows[-1].startswith("0.04")
    with h5py.File(tmp_path / "out" / "results.h5") as f:
        assert f.attrs["deck"] == sim.deck_text and "Step 2 Dynamic" in sim.deck_text


def small_scene_with_output(out) -> Simulation:
    sim = Simulation(gravity=(0, 0, -9.81), output=out, monitors_every=0.002)
    sim.add_material(1, 2700)
    sim.add_interface(normal_penalty=1e5, normal_damping=50)
    sim.add_box((0, 0, 0), (0.1, 0.1, 0.1))
    sim.add_particle(nurbsdem.shapes.sphere(0.01), 1, (0.05, 0.05, 0.012))
    return sim


HERTZ_DECK = """
Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2500 YoungModulus 1e7 PoissonRatio 0.3
  Material 2 Density 7800 YoungModulus 2e9 PoissonRatio 0.25
Shapes
  Shape 1 Sphere Radius 0.01
Particles
  Particle 1 Shape 1 Material 1 Position 0.05 0.05 0.0101 Velocity 0 0 -0.2
  Particle 2 Shape 1 Material 1 Position 0.05 0.05 0.04
Walls
  Box 1 Min 0 0 0 Max 0.1 0.1 0.1 Material 2
Contact
  Interface 1 Model HertzMindlin Restitution 0.6 Friction 0.4
Steps
  Step 1 Dynamic Duration 0.03 TimeStep 5e-4
"""


def test_hertz_mindlin_scene_matches_its_deck(tmp_path):
    deck = tmp_path / "hertz.inp"
    deck.write_text(HERTZ_DECK)
    ref = Simulation.from_deck(deck, output=tmp_path / "deck")
    ref.run()
    sim = Simulation(gravity=(0, 0, -9.81))
    sim.add_material(1, 2500, young_modulus=1e7, poisson_ratio=0.3)
    sim.add_material(2, 7800, young_modulus=2e9, poisson_ratio=0.25)
    ball = nurbsdem.shapes.sphere(0.01)
    sim.add_particle(ball, 1, (0.05, 0.05, 0.0101), velocity=(0, 0, -0.2))
    sim.add_particle(ball, 1, (0.05, 0.05, 0.04))
    sim.add_box((0, 0, 0), (0.1, 0.1, 0.1), material=2)
    sim.add_interface(model="HertzMindlin", restitution=0.6, friction=0.4)
    sim.run_dynamic(0.03, 5e-4)
    np.testing.assert_array_equal(sim.positions, ref.positions)
    np.testing.assert_array_equal(sim.velocities, ref.velocities)
    assert model_differences(build_model(sim.deck_text, str(deck)), ref.model) == []
    with pytest.raises(InputError, match="normal_penalty does not apply to a HertzMindlin"):
        Simulation().add_interface(normal_penalty=1e5, model="HertzMindlin", restitution=0.5)


def test_a_replicate_refused_while_running_leaves_the_simulation_usable():
    sim = small_scene()
    sim.add_wall("lid", point=(0.05, 0.05, 0.08), normal=(0, 0, -1), size=(0.1, 0.1))
    sim.run_dynamic(0.005, 1e-3)
    with pytest.raises(InputError, match="Step 2: after replication, particle 2 .* is behind"):
        sim.replicate(layers=2, height=0.09)
    sim.replicate(layers=2, height=0.04)
    sim.run_dynamic(0.005, 1e-3)
    assert len(sim.positions) == 2 and [s.kind for s in sim.model.steps] == [
        "dynamic", "replicate", "dynamic"]


def test_cli_restart_goes_through_the_simulation(runs, tmp_path, monkeypatch):
    """`nurbsdem solve --restart` (Simulation.from_deck(restart=...)) continues bit for bit."""
    from click.testing import CliRunner

    from nurbsdem.cli import main
    d = runs[0]
    deck = d / "case.inp"
    out = tmp_path / "out"
    original = Solver._sample

    def dying_sample(self, writers, force=False, samples=(), states=()):
        original(self, writers, force, samples, states)
        if self.time > 0.051:             # in step 3, after the checkpoint at 0.05 s
            raise KeyboardInterrupt
    monkeypatch.setattr(Solver, "_sample", dying_sample)
    r = CliRunner().invoke(main, ["solve", str(deck), "--quiet", "--output", str(out)])
    assert r.exit_code == 130, r.output
    monkeypatch.setattr(Solver, "_sample", original)
    r = CliRunner().invoke(main, ["solve", str(deck), "--quiet", "--output", str(out),
                                  "--restart", str(out / "checkpoint.h5")])
    assert r.exit_code == 0, r.output
    a = read_results_sample(out / "results.h5", -1)
    b = read_results_sample(d / "deck" / "results.h5", -1)
    for key in ("position", "quaternion", "velocity", "angular_velocity"):
        np.testing.assert_array_equal(a[key], b[key])
    for name in MONITORS:
        assert (out / "monitors" / name).read_text() == (d / "deck" / "monitors" / name).read_text()


def test_a_missing_checkpoint_is_a_clean_error(tmp_path):
    sim = build_scene(output=tmp_path / "out", restart=tmp_path / "nope.h5")
    with pytest.raises(InputError, match="nope.h5: no such checkpoint file"):
        sim.run_dynamic(0.01, 1e-3)
    assert sim.model.steps == []

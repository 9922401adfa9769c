"""Mesh and NURBS-surface walls inside the compiled deck steps
(nurbsdem.contact.curved_compiled): a drum of exact spheres — an exact NURBS cylinder with a
triangle-mesh baffle inside and flat end plates — settling, then turning, gives the same bits
whichever driver runs it, and the compiled loop really ran; so does a drum of ellipsoids and
spheres without the baffle (NURBS particles against the surface wall,
nurbsdem.contact.surface_particle_compiled), and an ellipsoid rolling off a mesh ridge
(NURBS particles against a mesh wall, nurbsdem.contact.mesh_particle_compiled)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from nurbsdem.dynamics import deck_steps, system as system_module
from nurbsdem.geometry.surfaces import cylinder_patch
from nurbsdem.io.deck import parse_deck
from nurbsdem.io.results import read_results_sample, read_results_times
from nurbsdem.io.shapefile import save_shape
from nurbsdem.solver import Solver
from runs import STATE_KEYS
from test_sphere_steps import _both_paths


def _drum_deck(folder) -> str:
    import trimesh
    save_shape(folder / "drum.yaml", [cylinder_patch(0.06, 0.04, axis=(0, 0, 1))])
    # a baffle: two triangles across the drum's bottom, 15 mm above it
    v = np.array([[-0.02, -0.02, -0.045], [0.02, -0.02, -0.045], [0.02, 0.02, -0.045],
                  [-0.02, 0.02, -0.045]])
    trimesh.Trimesh(v, np.array([[0, 1, 2], [0, 2, 3]]), process=False).export(
        folder / "baffle.stl")
    return """Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2500
Shapes
  Shape 1 Sphere Radius 0.006
  Shape 2 Sphere Radius 0.005
Particles
  Random 1 Shapes 1 2 Counts 9 9 Material 1 Region -0.014 -0.035 -0.035 0.014 0.035 0.035 Seed 2
Walls
  Surface 1 Name drum File drum.yaml Rotation 0 1.5707963267948966 0 Position -0.02 0 0
  Mesh 2 Name baffle File baffle.stl
  Wall 3 Name plate_x_min Point -0.02 0 0 Normal 1 0 0 Size 0.15 0.15
  Wall 4 Name plate_x_max Point 0.02 0 0 Normal -1 0 0 Size 0.15 0.15
Contact
  Interface 1 NormalPenalty 2e4 NormalDamping 2 TangentialPenalty 2e4 Friction 0.5
Steps
  Step 1 Dynamic Duration 0.08 TimeStep 1e-3
  Step 2 MoveWall drum Rotate AngularVelocity 4 0 0 Center 0 0 0 Duration 0.08 TimeStep 1e-3
  Step 3 Dynamic Duration 0.02 TimeStep 1e-3
Output
  Directory results
  VTK Every 0.04 Resolution 4
  Monitors Every 0.004
  Results Every 0.02
"""


def _counting_steps(monkeypatch) -> list:
    """Whether each DemSystem.steps call ran the compiled loop, appended to the list."""
    used = []
    original = system_module.DemSystem.steps

    def counting(self, n_max, sample_at=None, state_at=None):
        done = original(self, n_max, sample_at, state_at)
        used.append(bool(self._deck_steps) and self.compiled_steps)
        return done
    monkeypatch.setattr(system_module.DemSystem, "steps", counting)
    return used


def _same_bits(py, cc, s_py, s_cc, monitors) -> None:
    """Monitors, results samples, VTK files and counters of the two runs equal."""
    for name in monitors:
        assert (py / "monitors" / name).read_text() == (cc / "monitors" / name).read_text(), name
    times = read_results_times(py / "results.h5")
    np.testing.assert_array_equal(times, read_results_times(cc / "results.h5"))
    for k in range(len(times)):
        a, b = read_results_sample(py / "results.h5", k), read_results_sample(cc / "results.h5", k)
        for key in STATE_KEYS:
            np.testing.assert_array_equal(a[key], b[key])
    names = sorted(p.name for p in (py / "vtk").glob("*.vtu"))
    assert names and names == sorted(p.name for p in (cc / "vtk").glob("*.vtu"))
    for name in names:                 # particles, walls and contacts, byte for byte
        assert (py / "vtk" / name).read_bytes() == (cc / "vtk" / name).read_bytes(), name
    for key in ("steps", "substeps", "active_total", "active_max"):
        assert getattr(s_py, key) == getattr(s_cc, key), key


def test_a_turning_drum_gives_the_same_bits_on_both_drivers(tmp_path, monkeypatch):
    used = _counting_steps(monkeypatch)
    text = _drum_deck(tmp_path)
    (py, s_py), (cc, s_cc) = _both_paths(tmp_path, "drum.inp", text)
    assert any(used) and not all(used)                     # the Python run, then compiled
    _same_bits(py, cc, s_py, s_cc, ("energy.csv", "contacts.csv", "wall_drum.csv",
                                    "wall_baffle.csv", "wall_plate_x_min.csv"))
    drum = np.genfromtxt(cc / "monitors" / "wall_drum.csv", delimiter=",", names=True)
    baffle = np.genfromtxt(cc / "monitors" / "wall_baffle.csv", delimiter=",", names=True)
    assert np.abs(drum["reaction_z"]).max() > 0 and np.abs(drum["torque_x"][-5:]).max() > 0
    assert np.abs(baffle["reaction_z"]).max() > 0
    assert s_cc.active_max >= 5


def _recorded_statuses(monkeypatch) -> list:
    """The status of every run of the compiled deck steps, appended as they return."""
    statuses = []
    original = deck_steps.DeckSteps.run

    def run(self, *args, **kwargs):
        out = original(self, *args, **kwargs)
        statuses.append(out[0])
        return out
    monkeypatch.setattr(deck_steps.DeckSteps, "run", run)
    return statuses


def test_ellipsoids_in_a_turning_drum_give_the_same_bits_on_both_drivers(tmp_path,
                                                                         monkeypatch):
    """Two ellipsoids and two spheres in the drum (no baffle), settling, turning, resting:
    the compiled loop takes the NURBS particles' contacts with the surface wall (it never
    hands a deck step back) and gives the Python driver's bits; at the end the drum carries
    more than the spheres' weight."""
    used = _counting_steps(monkeypatch)
    statuses = _recorded_statuses(monkeypatch)
    text = _drum_deck(tmp_path).replace("  Mesh 2 Name baffle File baffle.stl\n", "").replace(
        "  Shape 1 Sphere Radius 0.006", "  Shape 1 Ellipsoid SemiAxes 0.008 0.0065 0.005"
    ).replace("Counts 9 9 Material 1 Region -0.014 -0.035 -0.035 0.014 0.035 0.035",
              "Counts 2 2 Material 1 Region -0.012 -0.03 -0.05 0.012 0.03 -0.008"
              ).replace("NormalDamping 2", "NormalDamping 6").replace(
        "Center 0 0 0 Duration 0.08", "Center 0 0 0 Duration 0.04")
    (py, s_py), (cc, s_cc) = _both_paths(tmp_path, "ellipsoids.inp", text)
    assert any(used) and not all(used) and statuses and deck_steps.GUARD not in statuses
    _same_bits(py, cc, s_py, s_cc, ("energy.csv", "contacts.csv", "wall_drum.csv",
                                    "wall_plate_x_min.csv"))
    drum = np.genfromtxt(cc / "monitors" / "wall_drum.csv", delimiter=",", names=True)
    spheres = 2 * 2500 * 4 / 3 * np.pi * 0.005 ** 3 * 9.81          # N
    assert drum["reaction_z"][-5:].min() > 1.5 * spheres


SHAPES = Path(__file__).resolve().parents[1] / "inputs" / "shapes"


@pytest.mark.slow
def test_paper_particles_settle_and_turn_in_a_drum(tmp_path, monkeypatch):
    """20 of the paper's particles (2 A, 4 B, 14 C; its contact constants) in an exact NURBS
    drum (radius 0.1 m, axis x, length 0.2 m, flat end plates) settle for 0.3 s, then the
    drum turns at 3 rad/s for 0.2 s, on the compiled deck steps: no deck step handed back
    (no refused contact), the energy balance error below 3 % of the energy turned over
    (the impacts of the fall; with the accuracy control it is smaller), the drum carrying
    the particles' weight and turning the pile (torque about its axis)."""
    statuses = _recorded_statuses(monkeypatch)
    save_shape(tmp_path / "drum.yaml", [cylinder_patch(0.1, 0.2, axis=(0, 0, 1))])
    deck = tmp_path / "paper_drum.inp"
    deck.write_text(f"""Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2700
Shapes
  Shape 1 File {SHAPES / 'A.yaml'}
  Shape 2 File {SHAPES / 'B.yaml'}
  Shape 3 File {SHAPES / 'C.yaml'}
Particles
  Random 1 Shapes 1 2 3 Counts 2 4 14 Material 1 Region -0.1 -0.07 -0.07 0.1 0.07 0.07 Seed 1
Walls
  Surface 1 Name drum File drum.yaml Rotation 0 1.5707963267948966 0 Position -0.1 0 0
  Wall 2 Name plate_x_min Point -0.1 0 0 Normal 1 0 0 Size 0.22 0.22
  Wall 3 Name plate_x_max Point 0.1 0 0 Normal -1 0 0 Size 0.22 0.22
Contact
  Interface 1 NormalPenalty 1e5 TangentialPenalty 1e4 NormalDamping 1e2 Friction 0.5
Steps
  Step 1 Dynamic Duration 0.3 TimeStep 1e-3 Damping Implicit
  Step 2 MoveWall drum Rotate AngularVelocity 3 0 0 Center 0 0 0 Duration 0.2 TimeStep 1e-3 Damping Implicit
Output
  Directory results
  Monitors Every 0.01
""")
    summary = Solver(parse_deck(deck), output=tmp_path / "out", quiet=True).run()
    assert statuses and deck_steps.GUARD not in statuses and summary.failed == 0
    assert abs(summary.balance_error) < 0.03 * summary.balance_scale
    drum = np.genfromtxt(tmp_path / "out" / "monitors" / "wall_drum.csv", delimiter=",",
                         names=True)
    weight = 2700 * 9.81 * (2 * 98.57 + 4 * 50.47 + 14 * 21.29) * 1e-6          # N
    assert drum["reaction_z"][-10:].mean() == pytest.approx(weight, rel=0.3)
    assert np.all(np.abs(drum["torque_x"][-10:]) > 0)


def test_a_refused_surface_contact_hands_back_and_the_provider_names_the_wall():
    """An ellipsoid in a cylinder narrower than its flat side's radius of curvature (two
    contact points, test_particle_walls): the compiled search reports the refusal (count −1,
    the loop then hands the deck step back), and the Python provider raises
    ContactNotUnique naming the wall."""
    from nurbsdem import shapes
    from nurbsdem.contact.curved_compiled import curved_contacts, pack_curved
    from nurbsdem.contact.curved_walls import CurvedWall, CurvedWallContacts
    from nurbsdem.contact.detect import ContactTable
    from nurbsdem.contact.kinds import SURFACE_WALL
    from nurbsdem.contact.surface_particle import ContactNotUnique
    from nurbsdem.contact.surface_wall import build_surface_wall
    from nurbsdem.dynamics.internal_step import Kinematics
    from nurbsdem.jit import fill_lazy_kernels
    shape = shapes.ellipsoid(0.03, 0.02, 0.015)
    table = ContactTable([shape])
    narrow = build_surface_wall([cylinder_patch(0.021, 0.2, base=(0, 0, -0.1), axis=(0, 0, 1))])
    provider = CurvedWallContacts(None, np.zeros(1), np.zeros(1, bool),
                                  [CurvedWall(SURFACE_WALL, narrow, name="narrow")], 0,
                                  table=table, body_shape=np.zeros(1, np.int64))
    R = np.array([[[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]])  # a, b, c on z, x, y
    x = np.array([[0.0, 0.0065, 0.0]])
    pos = x - R[0] @ shape.centroid
    fill_lazy_kernels("surface_particles")
    cc, wk = pack_curved(provider, 1, table)
    curved_contacts(cc, wk, 0.0, x, R, pos, np.zeros((1, 3)))
    assert wk.count[0] == -1
    kin = Kinematics(0.0, x, R, pos, np.zeros((1, 3)), np.zeros((1, 3)), np.zeros((1, 3)),
                     np.zeros((1, 3)), 1, 2)
    with pytest.raises(ContactNotUnique, match="surface wall 'narrow': .*not unique"):
        provider(kin)


def test_walls_turned_by_tables_give_the_same_bits_on_both_drivers(tmp_path, monkeypatch):
    """The drum and the baffle both moved by tables in one MoveWall step (each turning by
    interpolated rotation vectors about its centre while it translates): the compiled loop
    runs that step (the walls' poses and spin tabulated at its times) and gives the Python
    driver's bits."""
    calls = []
    original = system_module.DemSystem.steps

    def recording(self, n_max, sample_at=None, state_at=None):
        done = original(self, n_max, sample_at, state_at)
        table = hasattr(self.provider, "inner")          # a table turns a wall
        calls.append((self.compiled_steps, table, bool(self._deck_steps)))
        return done
    monkeypatch.setattr(system_module.DemSystem, "steps", recording)
    (tmp_path / "turn.csv").write_text("t,x,y,z,rx,ry,rz\n0,0,0,0,0,0,0\n"
                                       "0.02,0,0.001,0,0.08,0,0\n0.04,0,0,0.001,0.1,0,0\n")
    (tmp_path / "lift.csv").write_text("t,x,y,z,rx,ry,rz\n0,0,0,0,0,0,0\n"
                                       "0.04,0,0.001,0.003,0.1,0,0\n")
    turn = ("  Step 2 MoveWall drum Rotate AngularVelocity 4 0 0 Center 0 0 0 Duration 0.08 "
            "TimeStep 1e-3")
    text = _drum_deck(tmp_path)
    assert turn in text
    text = text.replace(turn, "  Step 2 MoveWall drum Table turn.csv Center 0 0 0 TimeStep 1e-3\n"
                              "  Step 2 MoveWall baffle Table lift.csv Center 0 0 -0.045")
    text = text.replace("Duration 0.08", "Duration 0.04").replace("Duration 0.02",
                                                                  "Duration 0.01")
    (py, s_py), (cc, s_cc) = _both_paths(tmp_path, "tables.inp", text)
    compiled = [used for on, table, used in calls if on and table]
    assert compiled and all(compiled)                 # the table step ran compiled
    assert not any(used for on, _, used in calls if not on)
    _same_bits(py, cc, s_py, s_cc, ("energy.csv", "contacts.csv", "wall_drum.csv",
                                    "wall_baffle.csv"))
    baffle = np.genfromtxt(cc / "monitors" / "wall_baffle.csv", delimiter=",", names=True)
    assert np.abs(baffle["reaction_z"]).max() > 0


def test_an_ellipsoid_rolling_off_a_mesh_ridge_gives_the_same_bits_on_both_drivers(
        tmp_path, monkeypatch):
    """An ellipsoid dropped on a triangle-mesh ridge (a convex fold) just beside its edge
    rolls off it onto a face, beside a sphere on the mesh: the compiled loop takes the NURBS
    particle's contacts with the mesh (nurbsdem.contact.mesh_particle_compiled; it never
    hands a deck step back) and gives the Python driver's bits; the Python driver's contacts
    were the edge's, then the face's."""
    import trimesh
    from nurbsdem.contact import mesh_kind
    from nurbsdem.contact.lcp import F_PB
    used = _counting_steps(monkeypatch)
    statuses = _recorded_statuses(monkeypatch)
    points = []                                       # the wall points of the rows (m)
    rows_of = mesh_kind.mesh_rows

    def recording(*args, **kwargs):
        out = rows_of(*args, **kwargs)
        points.extend(out[0][:, F_PB:F_PB + 3].tolist())
        return out
    monkeypatch.setattr(mesh_kind, "mesh_rows", recording)
    v = np.array([[-0.1, -0.1, 0], [-0.1, 0.1, 0], [0, -0.1, 0.02], [0, 0.1, 0.02],
                  [0.1, -0.1, 0], [0.1, 0.1, 0]], float)
    trimesh.Trimesh(v, np.array([[0, 2, 3], [0, 3, 1], [2, 4, 5], [2, 5, 3]]),
                    process=False).export(tmp_path / "ridge.stl")
    text = """Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2500
Shapes
  Shape 1 Ellipsoid SemiAxes 0.01 0.012 0.02
  Shape 2 Sphere Radius 0.006
Particles
  Particle 1 Shape 1 Material 1 Position 0.0005 0 0.0402 Rotation 0 0 0.3 Velocity 0.05 0 0
  Particle 2 Shape 2 Material 1 Position 0.05 0.05 0.0163
Walls
  Mesh 1 Name ridge File ridge.stl
Contact
  Interface 1 NormalPenalty 1e5 NormalDamping 5 TangentialPenalty 1e5 Friction 0.3
Steps
  Step 1 Dynamic Duration 0.06 TimeStep 1e-3
Output
  Directory results
  VTK Every 0.03 Resolution 4
  Monitors Every 0.005
  Results Every 0.03
"""
    (py, s_py), (cc, s_cc) = _both_paths(tmp_path, "ridge.inp", text)
    assert any(used) and not all(used) and statuses and deck_steps.GUARD not in statuses
    _same_bits(py, cc, s_py, s_cc, ("energy.csv", "contacts.csv", "wall_ridge.csv"))
    ridge = np.genfromtxt(cc / "monitors" / "wall_ridge.csv", delimiter=",", names=True)
    assert ridge["reaction_z"][-3:].min() > 0
    x = np.array(points)[:, 0]
    assert np.any(np.abs(x) < 1e-12) and np.any(x > 1e-4)     # on the edge, on the face

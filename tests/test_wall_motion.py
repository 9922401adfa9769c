"""Mesh and NURBS-surface walls that translate (``MoveWall … Displacement``, alone or with a
turn) and the torque column of ``monitors/wall_<name>.csv``, each against an analytic result:
a sphere set rolling by a floor that slides under it (2U/7), a sphere lifted at constant
speed (weight, closed energy balance), the torque of a resting sphere's weight about the
wall's reference point (r × F), the pose of a wall that turns and translates at once."""
from __future__ import annotations

import csv

import numpy as np
import pytest

from nurbsdem import Simulation
from nurbsdem.contact.curved_walls import CurvedWall, CurvedWallContacts, WallPose
from nurbsdem.contact.kinds import MESH_WALL, SURFACE_WALL
from nurbsdem.contact.mesh_wall import build_mesh_wall
from nurbsdem.contact.surface_wall import build_surface_wall
from nurbsdem.dynamics import ContactLaw, DemSystem, InterfaceTable, PrescribedMotion, sphere_inertia
from nurbsdem.geometry.surfaces import plane_patch

M, R, K, G = 0.05, 0.01, 1e5, 9.81
FLOOR = (np.array([[-1.0, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]),
         np.array([[0, 1, 2], [0, 2, 3]]))


def _floor(kind: int):
    """A horizontal floor z = 0 (front +z), 2 m × 2 m: two triangles or one NURBS patch."""
    if kind == MESH_WALL:
        return build_mesh_wall(*FLOOR)
    return build_surface_wall([plane_patch((0, 0, 0), (0, 0, 1), (2.0, 2.0))])


def _sphere_on(kind: int, motion: PrescribedMotion, law: ContactLaw, dt: float,
               xy=(0.0, 0.0)) -> DemSystem:
    """A sphere (M, R) resting at its rest overlap m g / k on a floor that moves by motion."""
    s = DemSystem(dt=dt, gravity=(0, 0, -G), interfaces=InterfaceTable(default=law))
    s.add_particle(M, sphere_inertia(M, R), [xy[0], xy[1], R - M * G / K], radius=R)
    s.add_wall(motion)
    wall = CurvedWall(kind, _floor(kind))
    s.set_contact_provider(CurvedWallContacts(None, [R], [True], [wall], first_wall=0))
    return s


@pytest.mark.parametrize("kind", [MESH_WALL, SURFACE_WALL], ids=["mesh", "surface"])
def test_floor_sliding_under_a_sphere_sets_it_rolling_at_two_sevenths(kind):
    """A floor that starts to slide at U = 0.1 m/s under a sphere at rest: friction drags
    the sphere until it rolls without slip on the floor; its angular momentum about the
    contact point stays 0, so it ends at v = I/(I + m r²) U = 2U/7 (solid sphere), its
    contact point moving with the floor.  The energy balance closes to round-off."""
    U = 0.1
    law = ContactLaw(en=K, cn=20.0, et=K, ct=10.0, mu=0.5)
    s = _sphere_on(kind, PrescribedMotion.linear([U, 0, 0]), law, dt=1e-3)
    s.initialize()
    for _ in range(60):                    # slip ends after (2U/7)/(μ g) ≈ 6 ms
        s.step()
    v = s.bodies.v[0]
    w = s.bodies.omega()[0]
    assert v[0] == pytest.approx(2 * U / 7, rel=1e-2)
    v_contact = v + np.cross(w, [0.0, 0.0, -R])
    assert v_contact[0] == pytest.approx(U, rel=1e-2)
    assert abs(v[1]) < 1e-12 and abs(w[0]) < 1e-9
    assert s.wall_displacement[0, 0] == pytest.approx(U * s.time, rel=1e-12)
    e = s.energy()
    error = e.mechanical - s.ledger.initial_mechanical - e.external_work + e.dissipated
    assert e.external_work > 0 and abs(error) <= 1e-9 * e.external_work


def test_floor_lifting_a_sphere_carries_its_weight_and_closes_the_energy_balance():
    """A mesh floor lifting a sphere resting on it at 0.02 m/s (the sphere moving with it
    from the start): the floor carries the weight, m g, and its work is the potential
    energy gained, m g × lift, the energy balance closed to round-off."""
    U, T = 0.02, 0.2
    law = ContactLaw(en=K, cn=20.0, et=K, ct=10.0, mu=0.3)
    lift = PrescribedMotion(lambda t: (np.array([0.0, 0.0, U * t]), np.array([0.0, 0.0, U])))
    s = _sphere_on(MESH_WALL, lift, law, dt=1e-3)
    s.bodies.v[0] = [0.0, 0.0, U]
    s.initialize()
    z0 = s.bodies.x[0, 2]
    e0 = s.energy()
    while s.time < T - 1e-12:
        s.step()
    assert s.wall_reaction[0, 2] == pytest.approx(M * G, rel=1e-9)
    e = s.energy()
    height = s.bodies.x[0, 2] - z0
    assert height == pytest.approx(U * T, rel=1e-9)
    assert e.potential - e0.potential == pytest.approx(M * G * height, rel=1e-12)
    assert e.external_work == pytest.approx(e.potential - e0.potential, rel=1e-9)
    error = e.mechanical - s.ledger.initial_mechanical - e.external_work + e.dissipated
    assert abs(error) <= 1e-12 * e.external_work


#: the deck's sphere: mass (kg) and weight (N) of a 1 cm sphere of density 2500; it starts at
#: its rest overlap m g / k on a floor z = 0 (NormalPenalty 1e5)
MASS = 2500 * 4 / 3 * np.pi * 0.01 ** 3
WEIGHT = MASS * 9.81


def _rest_deck(path, walls: str, steps: str, output: str = "") -> object:
    import trimesh
    trimesh.Trimesh(*FLOOR).export(path / "floor.stl")
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
{output}""")
    return deck


def _rows(path) -> list[dict]:
    return [{k: float(v) for k, v in r.items()} for r in csv.DictReader(open(path))]


@pytest.mark.parametrize("walls, name", [
    ("  Mesh 7 Name floor File floor.stl", "floor"),
    ("  Box 1 Min -1 -1 0 Max 1 1 1", "bottom"),
], ids=["mesh", "flat"])
def test_torque_column_is_r_cross_f_about_the_reference_point(tmp_path, walls, name):
    """A sphere resting at (0.3, −0.2) on a fixed floor, a mesh or a flat wall (the compiled
    step): the torque column is r × F of its push F on the floor about the floor's
    reference point (the world origin, the floor not having moved), to 1e-9."""
    deck = _rest_deck(tmp_path, walls, "  Step 1 Dynamic Duration 0.02 TimeStep 1e-3")
    Simulation.from_deck(deck).run()
    row = _rows(tmp_path / "results" / "monitors" / f"wall_{name}.csv")[-1]
    push = -np.array([row[f"reaction_{c}"] for c in "xyz"])
    torque = np.array([row[f"torque_{c}"] for c in "xyz"])
    assert push[2] == pytest.approx(-WEIGHT, rel=1e-6)
    np.testing.assert_allclose(torque, np.cross([0.3, -0.2, 0.0], push), rtol=0,
                               atol=1e-9 * np.linalg.norm(torque))


def test_deck_lifts_a_mesh_floor_as_a_flat_floor(tmp_path):
    """``nurbsdem solve``: ``MoveWall floor Displacement`` lifts a mesh floor and the sphere
    resting on it at 2 mm/s (slow enough that the start's velocity jump does not throw it):
    its monitor (displacement; reaction: the weight while it lifts; torque about the origin
    carried up)
    and the energies are those of a flat floor lifted the same way, to 1e-9; the floor's
    work is the potential energy gained, but for the start's transient, and the balance
    error is the integration's (the velocity jump);
    ``ToContact`` of a mesh wall without a ``Direction`` is a one-line error at its line."""
    import subprocess
    import sys
    steps = ("  Step 1 MoveWall floor Displacement 0 0 0.0002 Duration 0.1 TimeStep 1e-3")
    deck = _rest_deck(tmp_path, "  Mesh 7 Name floor File floor.stl", steps)
    run = subprocess.run([sys.executable, "-m", "nurbsdem", "solve", str(deck), "--quiet"],
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    flat = tmp_path / "flat"
    flat.mkdir()
    Simulation.from_deck(_rest_deck(flat, "  Wall 9 Name floor Point 0 0 0 Normal 0 0 1 "
                                          "Size 2 2", steps)).run()
    for name in ("wall_floor.csv", "energy.csv"):
        mesh_rows = _rows(tmp_path / "results" / "monitors" / name)
        flat_rows = _rows(flat / "results" / "monitors" / name)
        assert len(mesh_rows) == len(flat_rows) == 11
        for a, b in zip(mesh_rows, flat_rows):
            for key in a:
                assert a[key] == pytest.approx(b[key], rel=1e-9, abs=1e-12), (name, key)
    rows = _rows(tmp_path / "results" / "monitors" / "wall_floor.csv")
    assert rows[-1]["displacement_z"] == pytest.approx(0.0002, rel=1e-12)
    row = rows[9]            # t = 0.09 s: lifting at constant speed, the start's ringing gone
    assert row["displacement_z"] == pytest.approx(0.00018, rel=1e-9)
    assert row["reaction_z"] == pytest.approx(WEIGHT, rel=1e-6)
    assert row["torque_x"] == pytest.approx(-0.2 * -row["reaction_z"], rel=1e-9)
    energy = _rows(tmp_path / "results" / "monitors" / "energy.csv")[-1]
    assert energy["external_work"] == pytest.approx(WEIGHT * 0.0002, rel=2e-3)
    assert abs(energy["balance_error"]) <= 1e-3 * energy["external_work"]
    deck.write_text(deck.read_text().replace(
        "Displacement 0 0 0.0002 Duration 0.1 TimeStep 1e-3", "ToContact"))
    run = subprocess.run([sys.executable, "-m", "nurbsdem", "check", str(deck)],
                         capture_output=True, text=True, timeout=600)
    assert run.returncode != 0
    assert "a mesh or surface wall needs a Direction" in run.stderr
    assert f"{deck}:14" in run.stderr and len(run.stderr.strip().splitlines()) == 1


def test_turning_and_translating_wall_moves_its_centre_with_it():
    """A wall turning at ω about c while it translates at u: its points move at
    u + ω × (x − c − d), the pose's finite difference (the centre rides with the wall), the
    velocity the step gives its contacts (internal_step._spun_contacts)."""
    omega, c, u = np.array([0.3, -0.2, 0.5]), np.array([0.1, 0.2, -0.3]), np.array([0.4, 0, -1])
    pose = WallPose(omega=omega, center=c)
    x_wall = np.array([0.7, -0.4, 0.25])
    t, h = 0.8, 1e-6

    def world(time):
        R, shift = pose.at(time, u * time)
        return R @ x_wall + shift

    x = world(t)
    velocity = (world(t + h) - world(t - h)) / (2 * h)
    np.testing.assert_allclose(velocity, u + np.cross(omega, x - c - u * t), rtol=0, atol=1e-8)


def test_api_turn_with_displacement_reads_back_and_runs(tmp_path):
    """``move_wall(angular_velocity=…, displacement=…)`` on a mesh wall: the deck text holds
    both and reads back; after the step the wall has turned about its centre, moved with
    it, and ``wall_displacements`` gives the translation."""
    import trimesh
    from nurbsdem.io.deck import build_model
    import nurbsdem.shapes
    trimesh.Trimesh(*FLOOR).export(tmp_path / "floor.stl")
    sim = Simulation(gravity=(0, 0, 0))
    sim.add_material(1, density=2500)
    sim.add_interface(normal_penalty=1e5)
    sim.add_particle(nurbsdem.shapes.sphere(0.01), 1, (0, 0, 0.5))
    sim.add_mesh_wall("floor", tmp_path / "floor.stl")
    sim.move_wall("floor", angular_velocity=(0, 0, 1.0), center=(1, 0, 0),
                  displacement=(0, 0.01, 0), duration=0.01, time_step=1e-3)
    text = sim.deck_text
    assert "Rotate AngularVelocity 0.0 0.0 1.0 Center 1.0 0.0 0.0 Displacement 0.0 0.01 0.0" \
        in text
    step = build_model(text, str(tmp_path / "again.inp")).steps[-1]
    assert step.rotate and list(step.displacement) == [0, 0.01, 0]
    np.testing.assert_allclose(sim.wall_displacements["floor"], [0, 0.01, 0], rtol=1e-12)
    solver = sim.solver
    (Rw, tw), = solver.curved.poses(sim.time, solver.wall_offset)
    turn = np.array([[np.cos(0.01), -np.sin(0.01), 0], [np.sin(0.01), np.cos(0.01), 0],
                     [0, 0, 1]])
    corner = np.array([-1.0, -1, 0])
    expected = turn @ (corner - [1, 0, 0]) + [1, 0, 0] + [0, 0.01, 0]
    np.testing.assert_allclose(Rw @ corner + tw, expected, rtol=0, atol=1e-12)
    sim.close()


@pytest.mark.parametrize("kill_after", [0.035, 0.065], ids=["in-the-turn", "after-it"])
def test_restart_with_a_turning_and_translating_mesh_is_bit_for_bit(tmp_path, monkeypatch,
                                                                     kill_after):
    """A mesh floor under a resting sphere turns (0.03 rad about x) while it translates, then
    lifts: a run killed inside the turn or after it and restarted from its checkpoint ends
    in the same state, with the same wall monitor, as the run straight through."""
    import sys
    from pathlib import Path
    sys.path.insert(0, str(Path(__file__).parent))
    from runs import assert_same_final_state, killed_and_restarted
    deck = _rest_deck(tmp_path, "  Mesh 7 Name floor File floor.stl",
                      "  Step 1 Dynamic Duration 0.02 TimeStep 1e-3\n"
                      "  Step 2 MoveWall floor Rotate AngularVelocity 1 0 0 Center 0 0 0 "
                      "Displacement 0.001 0 0 Duration 0.03 TimeStep 1e-3\n"
                      "  Step 3 MoveWall floor Displacement 0 0 0.0001 Duration 0.04 "
                      "TimeStep 1e-3",
                      "  Results Every 0.01\n  Checkpoint Every 0.01\n")
    ref, out = tmp_path / "ref", tmp_path / "out"
    Simulation.from_deck(deck, output=ref).run()
    killed_and_restarted(deck, out, kill_after, monkeypatch)
    assert_same_final_state(out, ref, ("wall_floor.csv", "energy.csv"))
    last = _rows(ref / "monitors" / "wall_floor.csv")[-1]
    assert [last[f"displacement_{c}"] for c in "xyz"] == pytest.approx([0.001, 0, 0.0001],
                                                                       rel=1e-12, abs=1e-15)

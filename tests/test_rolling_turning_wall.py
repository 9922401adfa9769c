"""Rolling resistance against a turning wall (nurbsdem/dynamics/rolling.py,
nurbsdem/dynamics/forces.py::add_rolling_work) and the walls' work and power monitors: a
sphere held by its rolling spring on a triangle-mesh floor that tilts about a horizontal axis.

The floor turns at Ω about the x axis through the origin; the rolling spring sees the relative
rotation ω_wall − ω_sphere and its torque M acts on both.  The torque's work splits into the
work on the spring, hk M·(ω_wall − ω̄_sphere), and the work of the wall's drive, −hk M·ω_wall
(external work), so the wall's work is the whole power its drive spends: minus Ω times the
x torque the particles exert on it about the axis (the monitor's torque column), integrated
over time.  Without the rolling torque's share the wall's work misses −∫M·ω_wall dt, which
here is most of it (the sphere turns with the floor)."""
from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

import nurbsdem
from nurbsdem.simulation import Simulation

R, RHO, G, KN = 0.01, 2700.0, 9.81, 1e5
MASS = RHO * 4.0 / 3.0 * math.pi * R ** 3
OMEGA, DT = 1.0, 1e-4


def _tilting_floor(folder, mu_r: float) -> Simulation:
    """A sphere at its static overlap on a two-triangle floor (0.2 m square) that turns at
    OMEGA rad/s about the x axis for 0.1 s, the monitors written every time step."""
    v = np.array([[-0.1, -0.1, 0.0], [0.1, -0.1, 0.0], [0.1, 0.1, 0.0], [-0.1, 0.1, 0.0]])
    trimesh.Trimesh(v, np.array([[0, 1, 2], [0, 2, 3]]), process=False).export(
        folder / "floor.stl")
    sim = Simulation(gravity=(0.0, 0.0, -G), output=folder / "out", monitors_every=DT)
    sim.add_material(1, RHO)
    sim.add_interface(normal_penalty=KN, tangential_penalty=1e4, normal_damping=20,
                      tangential_damping=5, friction=0.8, rolling_friction=mu_r)
    sim.add_mesh_wall("floor", folder / "floor.stl")
    sim.add_particle(nurbsdem.shapes.sphere(R), 1, (0, 0, R - MASS * G / KN))
    sim.move_wall("floor", angular_velocity=(OMEGA, 0.0, 0.0), center=(0.0, 0.0, 0.0),
                  duration=0.1, time_step=DT)
    return sim


@pytest.mark.parametrize("mu_r", [0.0, 0.3])
def test_a_turning_walls_work_includes_its_rolling_torque(tmp_path, mu_r):
    sim = _tilting_floor(tmp_path, mu_r)
    e = sim.energy()
    assert abs(e["balance_error"]) < 1e-6 * MASS * G * R
    mon = tmp_path / "out" / "monitors"
    wall = np.genfromtxt(mon / "wall_floor.csv", delimiter=",", names=True)
    energy = np.genfromtxt(mon / "energy.csv", delimiter=",", names=True)
    # the one moving wall does all the external work, row by row, to the bit
    np.testing.assert_array_equal(wall["work"], energy["external_work"])
    t = wall["time"]
    np.testing.assert_allclose(wall["power"][1:], np.diff(wall["work"]) / np.diff(t),
                               rtol=1e-12, atol=0)
    # the drive's power −Ω·(torque on the wall, from the loads), integrated by the trapezoid
    # rule: the half kicks' rule when each time step is one internal step
    torque = wall["torque_x"]
    drive = np.concatenate([[0.0], np.cumsum(0.5 * np.diff(t) * -OMEGA
                                             * (torque[1:] + torque[:-1]))])
    scale = np.abs(wall["work"]).max()
    assert scale > 1e-7
    np.testing.assert_allclose(wall["work"], drive, rtol=0, atol=1e-12 * scale)

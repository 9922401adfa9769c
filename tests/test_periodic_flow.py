"""Inlets and outlets in a periodic cell (nurbsdem/dynamics/flow.py with a PeriodicCell,
nurbsdem/periodic_checks.py): a new particle clears the images, across the cell's faces, of
the particles that straddle them; a pour into a box periodic in x and y accounts for every
particle and keeps the energy balance; an inlet region reaching out of the cell is refused
with its line."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from nurbsdem import shapes
from nurbsdem.contact.periodic import make_cell, minimum_image
from nurbsdem.dynamics.flow import InsertionRegion, Inlet
from nurbsdem.simulation import Simulation
from test_flow_inlets import rows, spy_insertions

R = 0.002
CELL = make_cell([0.0, 0.0, 0.0], [0.02, 0.02, 1.0], [True, True, False])


def _straddling() -> tuple[np.ndarray, np.ndarray]:
    """Spheres (centres, radii) along the x = 0 face of CELL, inside it but reaching across
    (their images lie along x = 0.02, in the region of :func:`_inlet`)."""
    y = np.linspace(0.001, 0.019, 6)
    z = np.linspace(0.003, 0.017, 5)
    yy, zz = np.meshgrid(y, z, indexing="ij")
    centres = np.column_stack([np.full(yy.size, 0.0008), yy.ravel(), zz.ravel()])
    return centres, np.full(len(centres), R)


def _inlet(cell) -> Inlet:
    region = InsertionRegion(lo=np.array([0.014, 0.0, 0.0]), hi=np.array([0.02, 0.02, 0.02]))
    return Inlet(region, np.array([1]), np.array([1.0]), np.array([R]), np.ones(1), 1e4,
                 count=12, seed=4, cell=cell)


def _overlaps(new: np.ndarray, centres: np.ndarray) -> int:
    """Pairs of a new sphere and an obstacle closer than 2R through the cell."""
    d = minimum_image(new[:, None, :] - centres[None, :, :], CELL)
    return int(np.count_nonzero(np.linalg.norm(d, axis=2) < 2 * R))


def test_a_new_particle_clears_the_images_across_the_faces():
    centres, radii = _straddling()
    new = _inlet(CELL).insert(1.0, centres, radii)
    assert len(new.shapes) == 12
    assert _overlaps(new.positions, centres) == 0
    # without the cell the same draws meet the images (the test sees what it checks)
    blind = _inlet(None).insert(1.0, centres, radii)
    assert _overlaps(blind.positions, centres) > 0


def _periodic_pour(tmp_path: Path, monkeypatch) -> tuple:
    seen = spy_insertions(monkeypatch)
    sim = Simulation(gravity=(0, 0, -9.81), output=tmp_path / "out", quiet=True,
                     monitors_every=1e-3)
    sim.add_material(1, density=2500.0)
    sim.add_interface(normal_penalty=1e4, normal_damping=0.5, tangential_penalty=1e4,
                      friction=0.3)
    sim.set_periodic(x=(0.0, 0.03), y=(0.0, 0.03))
    sim.add_wall("floor", (0.015, 0.015, 0.0), (0, 0, 1), (0.06, 0.06))
    sim.add_inlet([shapes.sphere(R)], 1, (0.0, 0.0, 0.02, 0.03, 0.03, 0.04), rate=4000,
                  count=60, velocity=(0.3, 0.2, -0.5), seed=7, every=0.005, name="feed")
    sim.run_dynamic(0.06, 1e-3)
    bodies = sim.bodies
    sim.close()
    return seen, bodies


def test_a_pour_into_a_periodic_box_accounts_for_every_particle(tmp_path, monkeypatch):
    """Particles enter with a sideways velocity, cross the periodic faces and pile on the
    floor: none placed overlapping another or an image, all inside the cell, all counted,
    the balance closed."""
    seen, bodies = _periodic_pour(tmp_path, monkeypatch)
    cell = make_cell([0.0, 0.0, 0.0], [0.03, 0.03, 1.0], [True, True, False])
    for present, added in seen:
        x = np.concatenate([present.position, added.position])
        n0 = len(present)
        for i in range(n0, len(x)):
            d = np.linalg.norm(minimum_image(x[:i] - x[i], cell), axis=1)
            assert np.all(d >= 2 * R), (i, d.min())
    assert len(bodies) == 60
    assert np.all((bodies.position[:, :2] >= 0.0) & (bodies.position[:, :2] < 0.03))
    inlet = rows(tmp_path / "out" / "monitors" / "inlet_feed.csv")
    assert inlet[-1]["inserted"] == 60 and inlet[-1]["waiting"] == 0
    # in free flight, through the exchanges and the wraps across the faces, the balance
    # holds to round-off; the landings leave the integrator's O(h²) (the same pour into a
    # walled box leaves 0.2 % of the energy turned over too)
    energy = rows(tmp_path / "out" / "monitors" / "energy.csv")
    scale = max(abs(e["external_work"]) + abs(e["kinetic"]) for e in energy)
    flight = [e for e in energy if e["time"] <= 0.03]
    assert flight[-1]["time"] == pytest.approx(0.03)
    assert max(abs(e["balance_error"]) for e in flight) < 1e-12 * scale
    assert max(abs(e["balance_error"]) for e in energy) < 4e-3 * scale


DECK = """Environment
  Gravity 0 0 -9.81
  Periodic X 0 0.03 Y 0 0.03
Materials
  Material 1 Density 2500
Shapes
  Shape 1 Sphere Radius 0.002
Walls
  Wall 1 Name floor Point 0.015 0.015 0 Normal 0 0 1 Size 0.06 0.06
Contact
  Interface 1 NormalPenalty 1e4 NormalDamping 0.5
Flow
  Inlet 1 Name feed Shapes 1 Material 1 Box 0 0 0.02 0.04 0.03 0.04 Rate 1000 Count 10
Steps
  Step 1 Dynamic Duration 0.01 TimeStep 1e-3
"""


def test_an_inlet_region_outside_the_cell_is_refused_with_its_line(tmp_path):
    deck = tmp_path / "pour.inp"
    deck.write_text(DECK)
    run = subprocess.run([sys.executable, "-m", "nurbsdem", "check", str(deck)],
                         capture_output=True, text=True, timeout=600)
    assert run.returncode != 0
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and f"{deck}:13" in lines[0]
    assert "Inlet feed: its region reaches outside the periodic cell along X" in lines[0]

"""Mesh and NURBS-surface walls inside the compiled deck steps
(nurbsdem.contact.curved_compiled): a drum of exact spheres — an exact NURBS cylinder with a
triangle-mesh baffle inside and flat end plates — settling, then turning, gives the same bits
whichever driver runs it, and the compiled loop really ran."""
from __future__ import annotations

import numpy as np

from nurbsdem.dynamics import system as system_module
from nurbsdem.geometry.surfaces import cylinder_patch
from nurbsdem.io.results import read_results_sample, read_results_times
from nurbsdem.io.shapefile import save_shape
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


def test_a_turning_drum_gives_the_same_bits_on_both_drivers(tmp_path, monkeypatch):
    used = []
    original = system_module.DemSystem.steps

    def counting(self, n_max, sample_at=None, state_at=None):
        done = original(self, n_max, sample_at, state_at)
        used.append(bool(self._deck_steps) and self.compiled_steps)
        return done
    monkeypatch.setattr(system_module.DemSystem, "steps", counting)
    text = _drum_deck(tmp_path)
    (py, s_py), (cc, s_cc) = _both_paths(tmp_path, "drum.inp", text)
    assert any(used) and not all(used)                     # the Python run, then compiled
    for name in ("energy.csv", "contacts.csv", "wall_drum.csv", "wall_baffle.csv",
                 "wall_plate_x_min.csv"):
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
    drum = np.genfromtxt(cc / "monitors" / "wall_drum.csv", delimiter=",", names=True)
    baffle = np.genfromtxt(cc / "monitors" / "wall_baffle.csv", delimiter=",", names=True)
    assert np.abs(drum["reaction_z"]).max() > 0 and np.abs(drum["torque_x"][-5:]).max() > 0
    assert np.abs(baffle["reaction_z"]).max() > 0
    assert s_cc.active_max >= 5

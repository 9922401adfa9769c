"""Custom post-processing of ``results.h5``: the kinetic energy of every sample, from the
stored body states alone.

``results.h5`` (see ``nurbsdem.io.results.ResultsWriter``) holds, for every sample, each
particle's id, shape id, centroid, quaternion, velocity and angular velocity. Together with
the masses and inertia tensors (from the shapes and densities) that is enough to compute
anything about the motion; here the kinetic energy
    E = sum_i 1/2 m_i |v_i|^2 + 1/2 w_i . (R_i J_i R_i^T) w_i
of each sample, which ``monitors/energy.csv`` also records (its ``kinetic`` column): the two
must agree. ``main()`` returns the largest kinetic energy over the samples (J);
tests/test_examples.py checks it against the monitors.

Run:  python examples/postprocess_results.py [OUTPUT_DIR]
(it first runs a small scene of four spheres and an ellipsoid, 0.1 s, about 3 s, into
OUTPUT_DIR or a temporary folder, then reads its results.h5.)
"""
from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

import nurbsdem
from nurbsdem.geometry.rotation import quat_to_matrix
from nurbsdem.io.results import read_results_sample, read_results_times

DENSITY = 2000.0


def scene(output) -> nurbsdem.Simulation:
    """Four spheres and an ellipsoid thrown into a box (spinning), with results every 0.01 s."""
    sim = nurbsdem.Simulation(gravity=(0, 0, -9.81), output=output, vtk_every=0.01,
                              vtk_resolution=2, monitors_every=0.001)
    sim.add_material(1, density=DENSITY)
    sim.add_interface(normal_penalty=5e4, tangential_penalty=2e4, normal_damping=5.0,
                      friction=0.4)
    sim.add_box(min=(0, 0, 0), max=(0.1, 0.1, 0.1))
    ball = nurbsdem.shapes.sphere(0.01)
    egg = nurbsdem.shapes.ellipsoid(0.012, 0.008, 0.008)
    for k, (x, y) in enumerate([(0.02, 0.02), (0.05, 0.02), (0.08, 0.03), (0.03, 0.07)]):
        sim.add_particle(ball, 1, (x, y, 0.03 + 0.01 * k), velocity=(0.3, 0.2 * k, 0),
                         angular_velocity=(0, 0, 5.0 * k))
    sim.add_particle(egg, 1, (0.07, 0.07, 0.05), rotation=(0.3, 0.2, 0.1),
                     velocity=(-0.2, 0, 0.1), angular_velocity=(4, -3, 2))
    return sim


def mass_properties(sim: nurbsdem.Simulation) -> dict[int, tuple[float, np.ndarray]]:
    """shape id -> (mass kg, inertia about the centroid, file frame, kg m^2) at DENSITY."""
    return {sid: (e.mass(DENSITY), e.mass_inertia(DENSITY)) for sid, e in sim.model.shapes.items()}


def kinetic_energies(results: Path, props) -> tuple[np.ndarray, np.ndarray]:
    """(sample times s, kinetic energy J of each sample) from ``results.h5``."""
    times = read_results_times(results)
    energy = np.zeros(len(times))
    for k in range(len(times)):
        s = read_results_sample(results, k)
        for sid, v, w, q in zip(s["shape_id"], s["velocity"], s["angular_velocity"],
                                s["quaternion"]):
            m, J = props[int(sid)]
            R = quat_to_matrix(q)
            energy[k] += 0.5 * m * v @ v + 0.5 * w @ (R @ J @ R.T) @ w
    return times, energy


def main(output: str | Path | None = None, quiet: bool = False) -> float:
    """Run the scene into ``output`` (default: a temporary folder), post-process its
    results.h5; returns the largest kinetic energy of the samples (J)."""
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(output) if output is not None else Path(tmp) / "results"
        sim = scene(folder)
        sim.run_dynamic(duration=0.1, time_step=5e-4)
        sim.close()
        times, energy = kinetic_energies(folder / "results.h5", mass_properties(sim))
    if not quiet:
        for t, e in zip(times, energy):
            print(f"t = {t:.3f} s: kinetic energy {e:.6e} J")
    return float(energy.max())


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None)

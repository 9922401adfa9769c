"""Benchmark: mass properties (nurbsdem.geometry.mass.mass_properties), time and error.

Prints, for the exact 6-patch sphere, the exact ellipsoid, the single-patch sphere and the
paper's particle A, the time per call and the relative errors of volume and inertia
against the analytic values (for A: against the paper's Table 1 at 2700 kg/m^3).
No assertions. Run: ``.venv/bin/python benchmarks/bench_mass.py``.
"""
from __future__ import annotations

import time

import numpy as np

from nurbsdem.geometry.generators import (ellipsoid_patches, single_patch_sphere_patches,
                                          sphere_patches)
from nurbsdem.geometry.mass import mass_properties
from nurbsdem.geometry.particles import DENSITY, INERTIA_A, VOLUME_A, paper_particle


def _time(patches, repeat: int = 20) -> float:
    mass_properties(patches)  # warm-up (Gauss rule cache)
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        mass_properties(patches)
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    r, (a, b, c) = 0.01, (0.03, 0.02, 0.012)
    vs = 4.0 / 3.0 * np.pi * r ** 3
    ve = 4.0 / 3.0 * np.pi * a * b * c
    cases = [
        ("sphere (6 rational biquartic)", sphere_patches(r), vs, 0.4 * r * r * vs * np.eye(3)),
        ("ellipsoid (6 rational biquartic)", ellipsoid_patches(a, b, c), ve,
         ve / 5.0 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])),
        ("single-patch sphere (biquadratic)", single_patch_sphere_patches(r), vs,
         0.4 * r * r * vs * np.eye(3)),
        ("particle A (6 bicubic) vs Table 1", paper_particle("A"), VOLUME_A, INERTIA_A / DENSITY),
    ]
    print(f"{'shape':36s} {'time/call':>11s} {'rel err V':>11s} {'rel err J':>11s}")
    for name, patches, V, J in cases:
        t = _time(patches)
        v, _, j = mass_properties(patches)
        ev = abs(v / V - 1.0)
        ej = np.linalg.norm(j - J) / np.linalg.norm(J)
        print(f"{name:36s} {t * 1e3:8.2f} ms {ev:11.2e} {ej:11.2e}")


if __name__ == "__main__":
    main()

"""Parameter sweep: the height of a pack of spheres against the friction coefficient.

Fourteen exact NURBS spheres (two sizes) are poured into a narrow box and settle; the sweep
runs the same scene for each friction coefficient and reports the pack height (the top of
the highest sphere). With more friction the spheres stop rolling into the gaps, so the pack
settles looser and higher. ``main()`` returns the pack height at the largest friction (m);
tests/test_examples.py checks the sweep against the bounds of a sphere packing and its trend.

Run:  python examples/friction_sweep.py        (about 10 s)
"""
from __future__ import annotations

import numpy as np

import nurbsdem

FRICTIONS = (0.0, 0.2, 0.8)
BOX = (0.04, 0.04, 0.2)               # m: a narrow column, so the pack is several layers deep
RADII = (0.008, 0.006)                # m


def scene(friction: float) -> nurbsdem.Simulation:
    """The same 14 spheres for every friction coefficient (a lattice, slightly staggered)."""
    sim = nurbsdem.Simulation(gravity=(0, 0, -9.81))
    sim.add_material(1, density=2500)
    sim.add_interface(normal_penalty=2e4, tangential_penalty=1e4, normal_damping=10.0,
                      friction=friction)
    sim.add_box(min=(0, 0, 0), max=BOX)
    shapes = [nurbsdem.shapes.sphere(r) for r in RADII]
    rng = np.random.default_rng(7)
    for k in range(14):
        i, j, layer = k % 2, (k // 2) % 2, k // 4
        x = 0.011 + 0.018 * i + rng.uniform(-1e-3, 1e-3)
        y = 0.011 + 0.018 * j + rng.uniform(-1e-3, 1e-3)
        sim.add_particle(shapes[k % 3 == 0], 1, (x, y, 0.012 + 0.018 * layer))
    return sim


def pack_height(sim: nurbsdem.Simulation) -> float:
    """Top of the highest sphere (m)."""
    radii = np.array([RADII[k % 3 == 0] for k in range(len(sim.positions))])
    return float(np.max(sim.positions[:, 2] + radii))


def sweep(frictions=FRICTIONS, duration: float = 0.3) -> dict[float, float]:
    """Pack height (m) after ``duration`` s of settling, for each friction coefficient."""
    out = {}
    for mu in frictions:
        sim = scene(mu)
        sim.run_dynamic(duration=duration, time_step=1e-3)
        out[mu] = pack_height(sim)
    return out


def main(quiet: bool = False) -> float:
    heights = sweep()
    if not quiet:
        for mu, h in heights.items():
            print(f"friction {mu:4.2f}: pack height {1000 * h:.3f} mm")
    return heights[max(heights)]


if __name__ == "__main__":
    main()

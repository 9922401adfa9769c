"""Drop test: one exact NURBS sphere falls onto the floor of a box and comes to rest.

At rest the floor's penalty spring carries the weight, so the sphere sinks into the floor by
the static overlap  delta = m g / en  (paper Eq. 16 with the velocity gone): its centroid
rests at  z = r - m g / en.  ``main()`` returns the rest height z (m);
tests/test_examples.py checks it against that formula.

Run:  python examples/drop_test.py        (about 2 s)
"""
from __future__ import annotations

import math

import nurbsdem

RADIUS = 0.01            # m
DENSITY = 2700.0         # kg/m^3
NORMAL_PENALTY = 1e5     # N/m
GRAVITY = 9.81           # m/s^2


def main(output: str | None = None, quiet: bool = False) -> float:
    """Drop the sphere from 2 mm above the floor, let it settle for 0.15 s and return the
    height (m) of its centroid. ``output``: a folder for the results (default: none)."""
    sim = nurbsdem.Simulation(gravity=(0, 0, -GRAVITY), output=output)
    sim.add_material(1, density=DENSITY)
    # damping above critical (2 sqrt(en m) = 67 N s/m): the bounce dies out quickly
    sim.add_interface(normal_penalty=NORMAL_PENALTY, tangential_penalty=1e4,
                      normal_damping=100.0, friction=0.5)
    sim.add_box(min=(0, 0, 0), max=(0.05, 0.05, 0.05))
    sim.add_particle(nurbsdem.shapes.sphere(RADIUS), material=1,
                     position=(0.025, 0.025, RADIUS + 0.002))
    sim.run_dynamic(duration=0.15, time_step=1e-3)
    z = float(sim.positions[0, 2])
    if not quiet:
        m = DENSITY * 4.0 / 3.0 * math.pi * RADIUS ** 3
        print(f"rest height {z:.9f} m; overlap {RADIUS - z:.4e} m, m g / en = "
              f"{m * GRAVITY / NORMAL_PENALTY:.4e} m; kinetic energy {sim.energy()['kinetic']:.2e} J")
    return z


if __name__ == "__main__":
    main()

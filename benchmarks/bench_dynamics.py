"""Speed against accuracy of the dynamics (analytic sphere contacts).

For (1) a sphere dropped on a wall (linear spring–dashpot, paper's εn, cn; particle C mass) and
(2) a small deposition of analytic spheres with the paper's contact law and masses in the paper's
box, runs several internal time steps and prints: internal step, sub-steps per 1e-3 s deck step,
|energy-balance error| relative to the dissipated energy, restitution error (drop), and wall time
per simulated second.  Usage: .venv/bin/python benchmarks/bench_dynamics.py [--quick]
"""
from __future__ import annotations

import math
import sys
import time

import numpy as np

from nurbsdem.dynamics import (ContactLaw, DemSystem, InstabilityError, InterfaceTable,
                               SpherePlaneProvider, sphere_inertia)

LAW = ContactLaw(en=1e5, cn=1e2, et=1e4, ct=0.0, mu=0.5)
M_C = 2700 * 21.29e-6
R_C = (3 * 21.29e-6 / (4 * math.pi)) ** (1 / 3)
BOX = 0.25
PLANES = [([0, 0, 0], [0, 0, 1]), ([0, 0, 0], [1, 0, 0]), ([BOX, 0, 0], [-1, 0, 0]),
          ([0, 0, 0], [0, 1, 0]), ([0, BOX, 0], [0, -1, 0])]


def drop(substeps: int, T: float = 0.1):
    s = DemSystem(dt=1e-3, interfaces=InterfaceTable(default=LAW), substeps=substeps)
    s.add_particle(M_C, sphere_inertia(M_C, R_C), [0, 0, R_C + 0.02], radius=R_C)
    s.add_wall()
    s.set_contact_provider(SpherePlaneProvider([R_C], [([0, 0, 0], [0, 0, 1])]))
    s.initialize()
    vmin, vmax = 0.0, 0.0
    t0 = time.perf_counter()
    n = int(round(T / 1e-3))
    for _ in range(n):
        s.step()
        vz = s.bodies.v[0, 2]
        if not s.contacts.a.size:
            if vz < vmin and vmax == 0.0:
                vmin = vz
            vmax = max(vmax, vz) if s.time > 0.05 else vmax
    wall = time.perf_counter() - t0
    e = s.energy()
    return s.dt_internal, e, -vmax / vmin if vmin else float("nan"), wall / T


def deposition(substeps: int, n: int = 24, T: float = 0.3):
    s = DemSystem(dt=1e-3, interfaces=InterfaceTable(default=LAW), substeps=substeps)
    rng = np.random.default_rng(1)
    for i in range(n):
        x = [0.03 + 0.045 * (i % 5), 0.03 + 0.045 * ((i // 5) % 5), 0.03 + 0.04 * (i // 5)]
        s.add_particle(M_C, sphere_inertia(M_C, R_C), x, v=rng.uniform(-0.3, 0.3, 3), radius=R_C)
    for _ in PLANES:
        s.add_wall()
    s.set_contact_provider(SpherePlaneProvider([R_C] * n, PLANES))
    s.initialize()
    t0 = time.perf_counter()
    try:
        e = s.advance(int(round(T / 1e-3)))
    except InstabilityError:
        return s.dt_internal, None, (time.perf_counter() - t0) / T
    return s.dt_internal, e, (time.perf_counter() - t0) / T


def main() -> None:
    quick = "--quick" in sys.argv
    subs = (2, 3, 5, 10, 20) if quick else (2, 3, 5, 10, 20, 40, 80)
    drop(5, 0.002), deposition(5, 4, 0.002)      # compile
    e_ref = None
    print("drop of a sphere (mass of particle C) on a wall, deck dt 1e-3 s, 0.1 s simulated")
    print(f"{'dt_int (s)':>10} {'substeps':>8} {'|balance|/dissipated':>21} {'CoR':>8} "
          f"{'wall s/sim s':>12}")
    rows = []
    for sub in subs:
        h, e, cor, w = drop(sub)
        rows.append((h, sub, abs(e.balance_error) / max(e.dissipated, 1e-300), cor, w))
    e_ref = rows[-1][3]
    for h, sub, be, cor, w in rows:
        print(f"{h:10.3g} {sub:8d} {be:21.3e} {cor:8.5f} {w:12.3f}")
    print(f"(CoR at the finest step: {e_ref:.5f})")
    print("\ndeposition of 24 C-mass spheres in the paper's box, 0.3 s simulated")
    print(f"{'dt_int (s)':>10} {'substeps':>8} {'|balance|/dissipated':>21} {'KE end (J)':>11} "
          f"{'wall s/sim s':>12}")
    for sub in (1,) + subs:
        h, e, w = deposition(sub)
        if e is None:
            print(f"{h:10.3g} {sub:8d} {'InstabilityError':>21} {'-':>11} {w:12.3f}")
        else:
            print(f"{h:10.3g} {sub:8d} {abs(e.balance_error) / e.dissipated:21.3e} "
                  f"{e.kinetic:11.3e} {w:12.3f}")


if __name__ == "__main__":
    main()

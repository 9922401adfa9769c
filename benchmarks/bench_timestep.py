"""The time-step control on a dense pack: speed and error together.

A block of 63 exact NURBS spheres in FCC order (12 contacts each inside, particle C's mass, the
paper's contact law, zero gravity, held by six walls; :func:`nurbsdem.lattice.fcc_sphere_block`)
is run for ``T`` seconds at the deck step 1e-3 s with

* the pair estimate alone (what nurbsdem did before the network control: the stiffest pair's
  critical step, safety 0.5, the period-2 guard off),
* the network control (automatic: the default),
* a fixed fine step (the reference).

Printed per run: sub-steps per deck step, the period-2 ("rattle") amplitude of the last internal
steps, the kinetic energy at the end (what the monitors show), the energy-balance error, the
largest distance of the final centroids from the fine run's, and the wall time.
Usage: .venv/bin/python benchmarks/bench_timestep.py [--quick]
"""
from __future__ import annotations

import math
import sys
import time

import numpy as np

from nurbsdem.dynamics.stepcontrol import period2_amplitude
from nurbsdem.lattice import fcc_sphere_block

DT = 1e-3
FINE = 60


def run(label: str, T: float, substeps: int | None = None, watch: bool = True) -> dict:
    """One run of the block; returns the row of the table."""
    s, trace = fcc_sphere_block(DT, substeps=substeps, watch_period2=watch)
    s.initialize()
    t0 = time.perf_counter()
    for _ in range(int(round(T / DT))):
        s.step()
    wall = time.perf_counter() - t0
    e = s.energy()
    return dict(label=label, substeps=s.substeps, rattle=period2_amplitude(trace),
                kinetic=e.kinetic, balance=abs(e.balance_error),
                turned=abs(e.dissipated) + abs(e.external_work), x=s.bodies.x.copy(), wall=wall,
                dt_pair=s.dt_apriori, dt_net=s.dt_network)


def rows(T: float) -> list[dict]:
    """The three runs (pair estimate, network control, fine reference) with position errors."""
    probe, _ = fcc_sphere_block(DT)
    probe.initialize()
    pair_substeps = math.ceil(DT / (0.5 * probe.dt_apriori) * (1 - 1e-12))
    out = [run("pair estimate (before)", T, substeps=pair_substeps, watch=False),
           run("network control (default)", T),
           run(f"fixed fine step ({FINE} sub-steps)", T, substeps=FINE)]
    ref = out[-1]["x"]
    for r in out:
        r["x_err"] = float(np.linalg.norm(r["x"] - ref, axis=1).max())
    return out


def main(argv: list[str]) -> None:
    T = 0.01 if "--quick" in argv else 0.03
    table = rows(T)
    print(f"FCC block of 63 exact spheres, deck dt {DT} s, {T} s simulated "
          f"(pair critical step {table[1]['dt_pair']:.3g} s, network {table[1]['dt_net']:.3g} s)")
    print(f"{'run':34s} {'sub-steps':>9s} {'rattle m':>10s} {'kinetic J':>10s} "
          f"{'balance J':>10s} {'x err m':>10s} {'wall s':>7s}")
    for r in table:
        print(f"{r['label']:34s} {r['substeps']:9d} {r['rattle']:10.2e} {r['kinetic']:10.2e} "
              f"{r['balance']:10.2e} {r['x_err']:10.2e} {r['wall']:7.2f}")


if __name__ == "__main__":
    main(sys.argv[1:])

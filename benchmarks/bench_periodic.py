"""Periodic cells on the compiled deck steps against the Python step driver: speed and error.

A box of ``--n`` spheres (radius 5 mm) periodic in x and y (side chosen for a bed about six
layers deep) falls onto a floor and settles for ``--settle`` s, then runs ``--measure`` s
more; the same deck runs on the compiled deck steps and on the Python driver of the internal
step (``compiled_steps=False``).  Printed per driver (both loaded by a short run first): the
time per internal step over the whole run (the time loop's search, LCP and forces +
integration, output and set-up apart) and the internal steps; then the largest difference of
the two runs' final positions (m), velocities (m/s) and angular velocities (rad/s): zero when
both drivers give the same bits.

Usage: .venv/bin/python benchmarks/bench_periodic.py [--n 300] [--settle 0.1]
       [--measure 0.02]
Prints one JSON line at the end (``RESULT {...}``).
"""
from __future__ import annotations

import argparse
import json
import math
import tempfile
import time
from pathlib import Path

import numpy as np

RADIUS = 0.005


def deck_text(n: int, settle: float, measure: float) -> str:
    """The periodic box of n spheres (module docstring)."""
    side = max(math.sqrt(n * math.pi * RADIUS ** 2 / (0.5 * 6)), 6 * RADIUS)
    top = RADIUS + n * (4 / 3 * math.pi * RADIUS ** 3) / (0.08 * (side - 2 * RADIUS) ** 2)
    return f"""Environment
  Gravity 0 0 -9.81
  Periodic X 0 {side:.6f} Y 0 {side:.6f}
Materials
  Material 1 Density 2700
Shapes
  Shape 1 Sphere Radius {RADIUS}
Particles
  Random 1 Shapes 1 Counts {n} Material 1 Region {RADIUS} {RADIUS} {RADIUS} {side - RADIUS:.6f} {side - RADIUS:.6f} {top:.6f} Seed 5
Walls
  Wall 1 Name floor Point {side / 2:.6f} {side / 2:.6f} 0 Normal 0 0 1 Size {side + 0.04:.6f} {side + 0.04:.6f}
Contact
  Interface 1 NormalPenalty 1e5 TangentialPenalty 1e4 NormalDamping 1 Friction 0.5
Steps
  Step 1 Dynamic Duration {settle} TimeStep 1e-3
  Step 2 Dynamic Duration {measure} TimeStep 1e-3
Output
  Directory results
  Results Every {settle + measure}
"""


def run(deck: Path, out: Path, compiled: bool) -> dict:
    """One run: its time per internal step (s), internal steps, builds and final state."""
    from nurbsdem.io.deck import parse_deck
    from nurbsdem.io.results import read_results_sample, read_results_times
    from nurbsdem.solver import Solver
    solver = Solver(parse_deck(deck), output=out, quiet=True, compiled_steps=compiled)
    t0 = time.process_time()
    summary = solver.run()
    cpu = time.process_time() - t0
    loop = sum(v for k, v in summary.timers.items() if k not in ("output", "setup"))
    last = len(read_results_times(out / "results.h5")) - 1
    state = read_results_sample(out / "results.h5", last)
    return {"per_step_s": loop / max(summary.substeps, 1), "substeps": summary.substeps,
            "cpu_s": cpu, "state": state}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--n", type=int, default=300)
    p.add_argument("--settle", type=float, default=0.1)
    p.add_argument("--measure", type=float, default=0.02)
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        deck = Path(tmp) / "periodic.inp"
        deck.write_text(deck_text(args.n, 0.002, 0.001))
        for c in (True, False):         # the compiled kernels loaded before the timing
            run(deck, Path(tmp) / f"warm{c}", c)
        deck.write_text(deck_text(args.n, args.settle, args.measure))
        res = {c: run(deck, Path(tmp) / str(c), c) for c in (True, False)}
    diff = {k: float(np.max(np.abs(res[True]["state"][k] - res[False]["state"][k])))
            for k in ("position", "velocity", "angular_velocity")}
    for c, name in ((True, "compiled deck steps"), (False, "Python driver")):
        r = res[c]
        print(f"{name:20s}: {1e6 * r['per_step_s']:9.1f} us per internal step "
              f"({r['substeps']} internal steps, {r['cpu_s']:.1f} s CPU in all)")
    speedup = res[False]["per_step_s"] / max(res[True]["per_step_s"], 1e-300)
    print(f"speed-up {speedup:.2f}x; largest difference of the final states: "
          + ", ".join(f"{k} {v:.3g}" for k, v in diff.items()))
    print("RESULT " + json.dumps({"n": args.n, "compiled_s": res[True]["per_step_s"],
                                  "python_s": res[False]["per_step_s"], "speedup": speedup,
                                  "max_difference": diff}))


if __name__ == "__main__":
    main()

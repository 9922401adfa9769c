"""Cost per particle-step of a *settled* dense pack of N paper particles (A, B, C, 1/3 each).

The particles are placed at random (bounding spheres apart, random sequential addition) in a
box region of solid fraction ~0.3 of their bounding spheres, just above the floor, released at
rest with the paper's contact law and TimeStep 1e-3 s, and let settle under gravity for
``--settle`` seconds (the kinetic energy is printed as it decays).  Then ``--measure`` more
deck steps are timed: the cost per deck step and per particle-step of the settled pack (search,
LCP, forces + integration), with its contact count and sub-steps.

Usage: .venv/bin/python benchmarks/bench_settled_pack.py [--n 10000] [--settle 0.6]
       [--measure 50]
"""
from __future__ import annotations

import argparse
import math
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def deck_text(n: int, settle: float, measure: int, out: Path) -> str:
    """Region: square base of side L, height L/2 per the packing, bounding-sphere fraction 0.3
    (bounding radii of A, B, C: ~37, 29, 22 mm)."""
    shapes = (REPO / "inputs" / "shapes").resolve()
    r_mean3 = (0.0365 ** 3 + 0.0291 ** 3 + 0.0219 ** 3) / 3
    volume = n * 4 / 3 * math.pi * r_mean3 / 0.3
    side = (2 * volume) ** (1 / 3)
    height = volume / side ** 2
    c = [n // 3, n // 3, n - 2 * (n // 3)]
    return f"""Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2700
Shapes
  Shape 1 File {shapes}/A.yaml
  Shape 2 File {shapes}/B.yaml
  Shape 3 File {shapes}/C.yaml
Particles
  Random 1 Shapes 1 2 3 Counts {c[0]} {c[1]} {c[2]} Material 1 Region 0 0 0 {side:.6f} {side:.6f} {height:.6f} Seed 1
Walls
  Box 1 Min 0 0 0 Max {side:.6f} {side:.6f} {2 * height:.6f}
Contact
  Interface 1 NormalPenalty 1e5 TangentialPenalty 1e4 NormalDamping 1e2 TangentialDamping 0 Friction 0.5
Steps
  Step 1 Dynamic Duration {settle:.6g} TimeStep 1e-3
  Step 2 Dynamic Duration {measure * 1e-3:.6g} TimeStep 1e-3
Output
  Directory {out}
  VTK Every 1000 Resolution 2
  Monitors Every 0.05
  Checkpoint Every 1000
"""


def main(argv: list[str] | None = None) -> dict:
    from nurbsdem.io.deck import parse_deck
    from nurbsdem.solver import Solver
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=10000)
    ap.add_argument("--settle", type=float, default=0.6)
    ap.add_argument("--measure", type=int, default=50)
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        deck = Path(tmp) / "pack.inp"
        deck.write_text(deck_text(a.n, a.settle, a.measure, Path(tmp) / "out"))
        t0 = time.perf_counter()
        s = Solver(parse_deck(deck), quiet=True)
        s.start()
        s.run_step(s.model.steps[0])
        e = s.end_energy
        t_settle = time.perf_counter() - t0
        timers0, summary0 = dict(s.timers), (s.summary.steps, s.summary.substeps, s.summary.lcps,
                                              s.summary.active_total)
        s.run_step(s.model.steps[1])
        e2 = s.end_energy
        summary = s.finish()
    steps = summary.steps - summary0[0]
    comp = sum(summary.timers[k] - timers0[k] for k in ("global search", "LCP",
                                                        "forces + integration"))
    per = comp / steps
    res = dict(n=a.n, settle_s=t_settle, kinetic_settled=e["kinetic"], kinetic_end=e2["kinetic"],
               potential=e2["potential"], ms_per_step=per * 1e3, us_per_particle_step=per / a.n * 1e6,
               substeps=(summary.substeps - summary0[1]) / steps,
               lcps_per_step=(summary.lcps - summary0[2]) / steps,
               active_per_step=(summary.active_total - summary0[3]) / steps,
               failed=summary.failed)
    print(f"{a.n} paper particles settled for {a.settle} s ({t_settle:.0f} s wall): kinetic energy "
          f"{res['kinetic_settled']:.3g} J then {res['kinetic_end']:.3g} J (potential "
          f"{res['potential']:.4g} J)")
    print(f"settled pack, {steps} deck steps of 1e-3 s: {res['ms_per_step']:.1f} ms per step, "
          f"{res['us_per_particle_step']:.2f} µs per particle-step, {res['substeps']:.1f} "
          f"sub-steps, {res['active_per_step']:.0f} contacts, {res['lcps_per_step']:.0f} LCPs per "
          f"deck step, {res['failed']} failed")
    return res


if __name__ == "__main__":
    main()

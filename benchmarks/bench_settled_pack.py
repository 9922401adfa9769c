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

from decks import paper_mix_deck


def pack_region(n: int) -> tuple[float, float]:
    """Side L and height L/2 (m) of the region where the n particles are released: square
    base, bounding-sphere fraction 0.3 (bounding radii of A, B, C: ~37, 29, 22 mm)."""
    r_mean3 = (0.0365 ** 3 + 0.0291 ** 3 + 0.0219 ** 3) / 3
    volume = n * 4 / 3 * math.pi * r_mean3 / 0.3
    side = (2 * volume) ** (1 / 3)
    return side, volume / side ** 2


def deck_text(n: int, settle: float, measure: int, out: Path) -> str:
    """The particles in :func:`pack_region`; the box twice as high."""
    side, height = pack_region(n)
    return paper_mix_deck(n, (side, side, height), 2 * height, [settle, measure * 1e-3], out,
                          monitors_every=0.05, vtk_resolution=2)


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

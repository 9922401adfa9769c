"""Cost per particle-step of a *settled* dense pack of N paper particles (A, B, C, 1/3 each).

Two ways to get the pack:

* **settle** (default): the particles are placed at random (bounding spheres apart, random
  sequential addition) in a box region of solid fraction ~0.3 of their bounding spheres, just
  above the floor, released at rest with the paper's contact law and TimeStep 1e-3 s, and let
  settle under gravity for ``--settle`` seconds (the kinetic energy is printed as it decays).
  Then ``--measure`` more deck steps are timed.
* **tiles** (``--tiles 1x1,2x1,5x1,5x2``): a pack of ``--n`` particles settled once for
  ``--settle`` s (the checkpoint of benchmarks/bench_mpi.py, kept in ``--cache`` and reused)
  is laid side by side nx × ny times in a box nx × ny times as wide: 10 000 settled particles
  become 10^5 without the hours of deposition that 10^5 would take.  The copies' bodies keep
  their settled positions, orientations and velocities; where two copies meet (the old side
  walls) their particles overlap by at most the two wall penetrations (~0.1 mm), which the
  ``--relax`` deck steps run before the timing absorb.  Each tiling is timed over
  ``--measure`` deck steps; the growth exponent of the cost with N is fitted.

Printed per pack: the cost per deck step and per particle-step (global search, LCP, forces +
integration; output and set-up apart), sub-steps, contacts, LCPs per deck step, failed LCPs,
and the kinetic energy (the pack stays settled).

Usage: .venv/bin/python benchmarks/bench_settled_pack.py [--n 10000] [--settle 0.6]
       [--measure 50]
       .venv/bin/python benchmarks/bench_settled_pack.py --tiles 1x1,2x1,5x1,5x2 [--n 10000]
       [--settle 0.9] [--relax 3] [--measure 5]
Prints one JSON line at the end (``RESULT {...}``) for benchmarks/report.py.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from decks import paper_mix_deck  # noqa: E402

#: the settle time (s) and measured deck steps of the checkpoint of bench_mpi.py that the
#: tiles reuse (the same cache file)
CKPT_MEASURE = 20


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


def tiled_model(ckpt: Path, nx: int, ny: int, relax: int, measure: int, out: Path):
    """The model of nx × ny copies of the settled pack of checkpoint ``ckpt`` side by side
    (module docstring) with two dynamic steps: ``relax`` and ``measure`` deck steps."""
    from nurbsdem.io.checkpoint import load_checkpoint
    from nurbsdem.io.deck import parse_deck
    from nurbsdem.model import Bodies
    settled = Bodies.from_dict(load_checkpoint(ckpt)["bodies"])
    n = len(settled)
    side, height = pack_region(n)
    shifts = np.array([[i * side, j * side, 0.0] for i in range(nx) for j in range(ny)])
    shape_ids = np.unique(settled.shape_id)
    counts = [int((settled.shape_id == s).sum()) * len(shifts) for s in shape_ids]
    deck = out.parent / f"{out.name}.inp"
    deck.write_text(paper_mix_deck(n * len(shifts), (nx * side, ny * side, height), 2 * height,
                                   [relax * 1e-3, measure * 1e-3], out, monitors_every=0.05,
                                   vtk_resolution=2, counts=counts))
    model = parse_deck(deck)        # random placement, replaced below by the tiles
    b = model.bodies
    for s in shape_ids:
        dst = np.nonzero(b.shape_id == s)[0]
        src = np.nonzero(settled.shape_id == s)[0]
        b.position[dst] = np.concatenate([settled.position[src] + d for d in shifts])
        for name in ("quaternion", "velocity", "angular_velocity"):
            getattr(b, name)[dst] = np.tile(getattr(settled, name)[src], (len(shifts), 1))
    return model


#: the time loop's parts timed (the solver's timers), in the order of ``split_us``
PARTS = ("global search", "LCP", "forces + integration")


def measure(model, n: int) -> dict:
    """Run the model's first step, then time its second: cost per deck step of the second
    (global search + LCP + forces/integration), per particle-step, and its figures."""
    from nurbsdem.solver import Solver
    t0 = time.perf_counter()
    s = Solver(model, quiet=True)
    s.start()
    s.run_step(s.model.steps[0])
    e = s.end_energy
    t_first = time.perf_counter() - t0
    timers0, summary0 = dict(s.timers), (s.summary.steps, s.summary.substeps, s.summary.lcps,
                                          s.summary.active_total)
    s.run_step(s.model.steps[1])
    e2 = s.end_energy
    summary = s.finish()
    steps = summary.steps - summary0[0]
    parts = {k: summary.timers[k] - timers0[k] for k in PARTS}
    per = sum(parts.values()) / steps
    return dict(n=n, first_s=t_first, kinetic_first=e["kinetic"], kinetic_end=e2["kinetic"],
                potential=e2["potential"], steps=steps, ms_per_step=per * 1e3,
                us_per_particle_step=per / n * 1e6,
                substeps=(summary.substeps - summary0[1]) / steps,
                lcps_per_step=(summary.lcps - summary0[2]) / steps,
                active_per_step=(summary.active_total - summary0[3]) / steps,
                failed=summary.failed,
                split_us=[parts[k] / steps / n * 1e6 for k in PARTS])


def _row_text(r: dict) -> str:
    split = " / ".join(f"{v:.1f}" for v in r["split_us"])
    return (f"{r['ms_per_step']:.1f} ms per step, {r['us_per_particle_step']:.2f} µs per "
            f"particle-step ({split}: {' / '.join(PARTS)}), {r['substeps']:.1f} sub-steps, "
            f"{r['active_per_step']:.0f} contacts, {r['lcps_per_step']:.0f} LCPs per deck "
            f"step, {r['failed']} failed")


def growth(rows: list[dict], values: list[float]) -> float:
    """The exponent p of a least-squares fit values ∝ N^p over the rows' particle counts N."""
    if len(rows) < 2:
        return math.nan
    return float(np.polyfit(np.log([r["n"] for r in rows]), np.log(values), 1)[0])


def settle_and_measure(n: int, settle: float, steps: int) -> dict:
    from nurbsdem.io.deck import parse_deck
    with tempfile.TemporaryDirectory() as tmp:
        deck = Path(tmp) / "pack.inp"
        deck.write_text(deck_text(n, settle, steps, Path(tmp) / "out"))
        res = measure(parse_deck(deck), n)
    print(f"{n} paper particles settled for {settle} s ({res['first_s']:.0f} s wall): kinetic "
          f"energy {res['kinetic_first']:.3g} J then {res['kinetic_end']:.3g} J (potential "
          f"{res['potential']:.4g} J)")
    print(f"settled pack, {res['steps']} deck steps of 1e-3 s: " + _row_text(res))
    return res


def tiles(n: int, settle: float, tilings: list[tuple[int, int]], relax: int, steps: int,
          cache: Path) -> dict:
    """The tiled packs (module docstring) and the fitted growth exponent of the cost."""
    import bench_mpi
    ranks = 2 if bench_mpi._mpiexec() is not None else 1
    _, ckpt = bench_mpi.settled_checkpoint(n, settle, CKPT_MEASURE, cache, ranks)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for nx, ny in tilings:
            model = tiled_model(ckpt, nx, ny, relax, steps, Path(tmp) / f"tiles{nx}x{ny}")
            r = measure(model, n * nx * ny)
            r["tiles"] = f"{nx}x{ny}"
            rows.append(r)
            print(f"{r['n']} particles ({nx} x {ny} copies of {n} settled for {settle} s; "
                  f"kinetic energy {r['kinetic_end']:.3g} J after {relax} + {steps} deck "
                  f"steps): " + _row_text(r), flush=True)
    slope = growth(rows, [r["ms_per_step"] for r in rows])
    parts = [growth(rows, [r["split_us"][k] * r["n"] for r in rows]) for k in range(len(PARTS))]
    print(f"cost per deck step ∝ N^{slope:.2f} over N = {rows[0]['n']} … {rows[-1]['n']} ("
          + ", ".join(f"{p} N^{e:.2f}" for p, e in zip(PARTS, parts)) + ")")
    return dict(n=n, settle=settle, relax=relax, measure=steps, rows=rows, exponent=slope,
                part_exponents=dict(zip(PARTS, parts)))


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=10000)
    ap.add_argument("--settle", type=float, default=None,
                    help="seconds of settling (default 0.6; with --tiles 0.9, bench_mpi's)")
    ap.add_argument("--measure", type=int, default=None,
                    help="deck steps timed (default 50; with --tiles 5)")
    ap.add_argument("--tiles", default=None, help="e.g. 1x1,2x1,5x1,5x2")
    ap.add_argument("--relax", type=int, default=3)
    ap.add_argument("--cache", type=Path, default=HERE / ".cache")
    a = ap.parse_args(argv)
    if a.tiles is None:
        res = settle_and_measure(a.n, 0.6 if a.settle is None else a.settle,
                                 50 if a.measure is None else a.measure)
    else:
        tilings = [tuple(int(k) for k in t.split("x")) for t in a.tiles.split(",")]
        res = tiles(a.n, 0.9 if a.settle is None else a.settle, tilings, a.relax,
                    5 if a.measure is None else a.measure, a.cache)
    print("RESULT " + json.dumps(res))
    return res


if __name__ == "__main__":
    main()

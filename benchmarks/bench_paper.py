"""The paper example's wall time, as shipped and with few ParaView samples, back to back.

`inputs/paper/compaction.inp` as shipped (a ParaView sample every 0.01 s: 651 of the
particles, ~1.2 MB each) and the same deck with ``VTK Every 0.5`` (14 samples, and as
many of ``results.h5``, which follows the VTK interval in this deck; monitors and checkpoints
as shipped), run alternately ``--rounds`` times each, every run in a
fresh output folder: the difference is what writing the samples costs the run on this
machine.  Runs on a shared machine move by tens of per cent from one to the next; compare runs of
the same invocation.

Printed per run: wall time, the solver's time split (global search, LCP, forces +
integration, output on the main thread, set-up; of forces + integration: the integration, the
contact forces, the implicit dashpots and the time-step control), the time outside the LCP over the LCP time, internal steps, LCPs solved, failed LCPs
and the energy-balance error (J; the integration's error: the accuracy figure beside the
speed); then the best and the median wall time of each variant.

``--threads 1`` runs everything on one numba thread (the LCP batch is the one part of this
112-particle deck that two threads speed up, so the measure outside/LCP depends on the count;
the results are the same bits at any count).

Usage: .venv/bin/python benchmarks/bench_paper.py [--rounds 2] [--quick] [--threads N]
(quick: ``inputs/paper/compaction_quick.inp`` instead, a smoke test)
"""
from __future__ import annotations

import argparse
import re
import statistics
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

#: the deck's ParaView interval (s), replaced by FEW_EVERY
VTK_EVERY = re.compile(r"^(\s*VTK Every )(\S+)", re.MULTILINE)
FEW_EVERY = "0.5"


def deck_text(few_frames: bool, quick: bool) -> str:
    """The paper deck (shape files by absolute path), with ``VTK Every 0.5`` if asked."""
    deck = REPO / "inputs" / "paper" / ("compaction_quick.inp" if quick else "compaction.inp")
    text = deck.read_text().replace("../shapes/", str(REPO / "inputs" / "shapes") + "/")
    if few_frames:
        text, n = VTK_EVERY.subn(lambda m: m.group(1) + FEW_EVERY, text)
        if n != 1:
            raise SystemExit(f"{deck}: no one 'VTK Every' line to replace")
    return text


def run(few_frames: bool, quick: bool, workdir: Path, k: int) -> dict:
    """One run in a fresh folder; its figures."""
    from nurbsdem.io.deck import parse_deck
    from nurbsdem.solver import Solver
    name = f"{'few' if few_frames else 'shipped'}_{k}"
    deck = workdir / f"{name}.inp"
    deck.write_text(deck_text(few_frames, quick))
    s = Solver(parse_deck(deck), output=workdir / name, quiet=True).run()
    samples = len(list((workdir / name / "vtk").glob("particles_*.vtu")))
    return dict(variant="VTK Every 0.5" if few_frames else "as shipped", wall=s.wall_time,
                timers=dict(s.timers), split=dict(s.split), substeps=s.substeps,
                lcps=s.lcps, failed=s.failed, balance=abs(s.balance_error), samples=samples)


def row(r: dict) -> str:
    split = ", ".join(f"{k} {v:.1f}" for k, v in r["timers"].items())
    parts = ", ".join(f"{k} {v:.1f}" for k, v in r["split"].items())
    outside = (r["wall"] - r["timers"]["LCP"]) / max(r["timers"]["LCP"], 1e-300)
    return (f"{r['variant']:14s} {r['wall']:6.1f} s  ({split}; of forces + integration: "
            f"{parts}; outside the LCP {outside:.2f} x the LCP)  {r['samples']} samples, "
            f"{r['substeps']} internal steps, {r['lcps']} LCPs, {r['failed']} failed, "
            f"energy-balance error {r['balance']:.3g} J")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--threads", type=int, default=0,
                    help="numba threads (default: all cores)")
    args = ap.parse_args()
    from common import machine_info, stamp
    if args.threads:
        import numba
        numba.set_num_threads(args.threads)
        print(f"numba threads: {numba.get_num_threads()}", flush=True)
    print(stamp(machine_info()), flush=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.rounds):
            for few in (False, True):
                rows.append(run(few, args.quick, Path(tmp), k))
                print(row(rows[-1]), flush=True)
    for variant in ("as shipped", "VTK Every 0.5"):
        walls = [r["wall"] for r in rows if r["variant"] == variant]
        print(f"{variant}: best {min(walls):.1f} s, median {statistics.median(walls):.1f} s "
              f"over {len(walls)} runs")


if __name__ == "__main__":
    main()

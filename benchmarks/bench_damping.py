"""The paper's example with explicit and with implicit normal dashpots, side by side.

`inputs/paper/compaction.inp` as shipped (``Damping Explicit``, the default: the dashpots
limit the step, Eq. 1 of :mod:`nurbsdem.dynamics.stepcontrol`) and the same deck with
``Damping Implicit`` on its four timed steps (:mod:`nurbsdem.dynamics.implicit`: the step is
limited by the springs alone).  Printed per run: wall time, internal steps, LCPs, failed
LCPs, the energy-balance error (absolute and as a share of the energy turned over — the
integration error, which grows with the step), and two outcomes of the physics: the lid's
height after ``MoveWall lid ToContact Gap 0.005`` (the pack's top + 5 mm) and the lid's
largest reaction during the compaction (paper Fig. 7).  A packing is one realisation of a chaotic
process: the two runs are not expected to agree to more than a few per cent.

Usage: .venv/bin/python benchmarks/bench_damping.py [--quick]
(quick: the deck's durations shortened 10 x, the lid stroke with them; a smoke test)
"""
from __future__ import annotations

import argparse
import csv
import re
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

DECK = REPO / "inputs" / "paper" / "compaction.inp"


def deck_text(damping: str, quick: bool = False) -> str:
    """The paper deck with ``Damping <damping>`` on its timed steps and absolute shape paths
    (quick: durations and the lid stroke divided by 10)."""
    text = DECK.read_text().replace("../shapes/", str(REPO / "inputs" / "shapes") + "/")
    text = re.sub(r"(TimeStep \S+)", rf"\1 Damping {damping}", text)
    if quick:
        text = re.sub(r"Duration (\S+)", lambda m: f"Duration {float(m.group(1)) / 10:g}", text)
        text = text.replace("-0.08 Duration", "-0.008 Duration").replace(
            "0 0 0.08 Duration", "0 0 0.008 Duration")
    return text


def _lid(out: Path) -> tuple[float, float]:
    """(lid height z after ToContact (m): the pack's top + the deck's gap, largest
    |reaction z| (N)) from its monitor."""
    with open(out / "monitors" / "wall_lid.csv") as fh:
        rows = list(csv.DictReader(fh))
    z0 = 0.60                    # the lid's Point z in inputs/paper/compaction.inp
    moved = [float(r["displacement_z"]) for r in rows]
    # the first sample of the compaction: the lid sits where ToContact put it
    top = z0 + next((d for d in moved if d != 0.0), 0.0)
    peak = max(abs(float(r["reaction_z"])) for r in rows)
    return top, peak


def run(damping: str, workdir: Path, quick: bool = False) -> dict:
    """Run the paper deck with the given damping; returns its figures."""
    from nurbsdem.io.deck import parse_deck
    from nurbsdem.solver import Solver
    case = workdir / f"paper_{damping.lower()}.inp"
    case.write_text(deck_text(damping, quick))
    out = workdir / f"out_{damping.lower()}"
    return figures(damping, Solver(parse_deck(case), output=out, quiet=True).run(), out)


def figures(label: str, s, out: Path) -> dict:
    """The row of :func:`table` for a run's summary ``s`` and its output folder ``out``."""
    top, peak = _lid(out)
    return dict(damping=label, wall=s.wall_time, steps=s.steps, substeps=s.substeps,
                lcps=s.lcps, failed=s.failed, balance=abs(s.balance_error),
                share=abs(s.balance_error) / max(abs(s.balance_scale), 1e-300),
                lcp=s.timers["LCP"], top=top, peak=peak)


def table(rows: list[dict]) -> tuple[list[str], list[list[str]]]:
    head = ["Damping", "wall s", "internal steps", "LCPs", "failed", "LCP s",
            "energy-balance error J", "share of energy turned over",
            "lid after ToContact m", "lid peak reaction N"]
    body = [[r["damping"], f"{r['wall']:.1f}", f"{r['substeps']}", f"{r['lcps']}",
             f"{r['failed']}", f"{r['lcp']:.1f}", f"{r['balance']:.3g}", f"{r['share']:.2e}",
             f"{r['top']:.4f}", f"{r['peak']:.4g}"] for r in rows]
    return head, body


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    from common import machine_info, stamp
    print(stamp(machine_info()))
    with tempfile.TemporaryDirectory() as tmp:
        rows = [run(d, Path(tmp), args.quick) for d in ("Explicit", "Implicit")]
    head, body = table(rows)
    print(" | ".join(head))
    for r in body:
        print(" | ".join(r))
    print(f"implicit / explicit wall time: {rows[1]['wall'] / rows[0]['wall']:.2f}")


if __name__ == "__main__":
    main()

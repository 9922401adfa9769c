"""The paper's example with explicit and implicit normal dashpots and the accuracy control.

`inputs/paper/compaction.inp` with, on its four timed steps,

* ``Damping Explicit`` (the default: the dashpots limit the step, Eq. 1 of
  :mod:`nurbsdem.dynamics.stepcontrol`),
* ``Damping Implicit`` (:mod:`nurbsdem.dynamics.implicit`: the springs alone limit the step),
* ``Damping Implicit Accuracy 3e-5``, as shipped (:mod:`nurbsdem.dynamics.accuracy`: deck
  steps whose energy-balance error grows beyond the budget are repeated with more
  sub-steps),

all with the shipped ``Safety 0.7`` (the sub-step is 0.7 × the contact network's stability
limit), and the shipped settings with the default ``Safety 0.5``.

Printed per run: wall time, internal steps, LCPs, failed
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


#: the variants: (label, Damping, Accuracy or None, Safety or None: the deck's)
VARIANTS = (("Explicit", "Explicit", None, None), ("Implicit", "Implicit", None, None),
            ("Implicit, Accuracy 3e-5 (as shipped)", "Implicit", 3e-5, None),
            ("Implicit, Accuracy 3e-5, Safety 0.5 (the default)", "Implicit", 3e-5, 0.5))


def deck_text(damping: str, quick: bool = False, accuracy: float | None = None,
              safety: float | None = None) -> str:
    """The paper deck with ``Damping <damping> [Accuracy <accuracy>]`` on its timed steps
    (instead of the shipped settings; ``safety``: ``Safety <safety>`` instead of the deck's)
    and absolute shape paths (quick: durations and the lid stroke divided by 10)."""
    text = DECK.read_text().replace("../shapes/", str(REPO / "inputs" / "shapes") + "/")
    extra = f" Damping {damping}" + (f" Accuracy {accuracy:g}" if accuracy is not None else "")
    strip = r" Damping \S+| Accuracy \S+"
    if safety is not None:
        extra += f" Safety {safety:g}"
        strip += r"| Safety \S+"
    lines = [re.sub(r"(TimeStep \S+)", rf"\1{extra}", re.sub(strip, "", line))
             if line.lstrip().startswith("Step ") else line for line in text.splitlines()]
    text = "\n".join(lines) + "\n"
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


def run(label: str, damping: str, accuracy: float | None, safety: float | None,
        workdir: Path, quick: bool = False) -> dict:
    """Run the paper deck with the given damping, accuracy and safety; returns its
    figures."""
    from nurbsdem.io.deck import parse_deck
    from nurbsdem.solver import Solver
    name = f"{damping.lower()}_{accuracy:g}" if accuracy is not None else damping.lower()
    name += f"_safety{safety:g}" if safety is not None else ""
    case = workdir / f"paper_{name}.inp"
    case.write_text(deck_text(damping, quick, accuracy, safety))
    out = workdir / f"out_{name}"
    return figures(label, Solver(parse_deck(case), output=out, quiet=True).run(), out)


def figures(label: str, s, out: Path) -> dict:
    """The row of :func:`table` for a run's summary ``s`` and its output folder ``out``."""
    top, peak = _lid(out)
    return dict(damping=label, wall=s.wall_time, steps=s.steps, substeps=s.substeps,
                repeats=s.accuracy_repeats,
                lcps=s.lcps, failed=s.failed, balance=abs(s.balance_error),
                share=abs(s.balance_error) / max(abs(s.balance_scale), 1e-300),
                lcp=s.timers["LCP"], top=top, peak=peak)


def table(rows: list[dict]) -> tuple[list[str], list[list[str]]]:
    head = ["Damping", "wall s", "internal steps", "repeated deck steps", "LCPs", "failed",
            "LCP s", "energy-balance error J", "share of energy turned over",
            "lid after ToContact m", "lid peak reaction N"]
    body = [[r["damping"], f"{r['wall']:.1f}", f"{r['substeps']}", f"{r['repeats']}",
             f"{r['lcps']}",
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
        rows = [run(*v, Path(tmp), args.quick) for v in VARIANTS]
    head, body = table(rows)
    print(" | ".join(head))
    for r in body:
        print(" | ".join(r))
    for r in rows[1:]:
        print(f"{r['damping']} / explicit wall time: {r['wall'] / rows[0]['wall']:.2f}")


if __name__ == "__main__":
    main()

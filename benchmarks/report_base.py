"""The verification report's building blocks: the report being written (:class:`Report`: its
parts, figures and headline numbers), number formatting and Markdown tables."""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import stamp  # noqa: E402


def fmt(x, spec=".2e") -> str:
    """A number for a table; '–' for None, 'n/a' for NaN."""
    if x is None:
        return "–"
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    x = float(x)
    if math.isnan(x):
        return "n/a"
    return format(x, spec)


def md_table(header: list[str], rows: list[list]) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for r in rows:
        out.append("| " + " | ".join(str(c) for c in r) + " |")
    return "\n".join(out)


class Report:
    """Collects markdown and figures."""

    def __init__(self, outdir: Path, info: dict, quick: bool) -> None:
        self.outdir = outdir
        self.figdir = outdir / "verification"
        self.figdir.mkdir(parents=True, exist_ok=True)
        self.info = info
        self.quick = quick
        self.parts: list[str] = []
        self.figures: list[Path] = []
        self.headline: dict = {}

    def add(self, text: str) -> None:
        self.parts.append(text)

    def stamp_line(self) -> str:
        return f"*Measured on {stamp(self.info)}; mode: {'quick' if self.quick else 'full'}.*"

    def figure(self, fig, name: str, caption: str) -> None:
        fig.text(0.01, 0.005, f"{stamp(self.info)} ({'quick' if self.quick else 'full'})",
                 fontsize=6, color="0.4", ha="left", va="bottom")
        path = self.figdir / name
        fig.savefig(path, dpi=110)
        import matplotlib.pyplot as plt
        plt.close(fig)
        self.figures.append(path)
        self.add(f"![{caption}](verification/{name})\n\n*Figure: {caption}. "
                 f"{stamp(self.info)}.*\n")


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


# =========================================================================== 1. LCP accuracy

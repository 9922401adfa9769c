#!/usr/bin/env python
"""Plot a nurbsdem run's monitors like the paper's Figures 4, 5 and 7.

Usage::

    python postproc/plot_monitors.py RESULTS_DIR [--out FOLDER]

Reads ``RESULTS_DIR/monitors/*.csv`` (written by :mod:`nurbsdem.io.monitors`) and writes,
into ``--out`` (default RESULTS_DIR):

* ``energy.png`` — kinetic, potential, elastic, mechanical energy, dissipated energy,
  external work and the balance error against time (Fig. 4);
* ``contacts.png`` — monitored LCPs, active, degenerated and failed contacts against time
  (Fig. 5);
* ``<wall>_reaction.png`` for every wall that moved (``lid_reaction.png`` in the paper's
  example) — the particles' resistance to the wall's motion (the monitored reaction, the
  force that holds the wall on its path, projected on the motion), against the wall's displacement along its motion (Fig. 7).

Needs numpy and matplotlib only (Agg backend, no display).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def read_csv(path: Path) -> dict[str, np.ndarray]:
    """Columns of a monitor CSV by header name (empty arrays when there are no rows)."""
    lines = [ln for ln in path.read_text().splitlines() if ln.strip()]
    header = lines[0].split(",")
    rows = []
    for ln in lines[1:]:
        parts = ln.split(",")
        if len(parts) != len(header):
            continue  # a row cut by a crash
        try:
            rows.append([float(p) for p in parts])
        except ValueError:
            continue
    data = np.array(rows, float).reshape(-1, len(header))
    return {name: data[:, k] for k, name in enumerate(header)}


def plot_energy(d: dict[str, np.ndarray], out: Path) -> None:
    """energy.png: energies (J) against time (s)."""
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for name, style in (("kinetic", "-"), ("potential", "-"), ("elastic", "-"),
                        ("mechanical", "-"), ("dissipated", "--"), ("external_work", "--"),
                        ("balance_error", ":")):
        if name in d:
            ax.plot(d["time"], d[name], style, label=name.replace("_", " "))
    ax.set_xlabel("time (s)")
    ax.set_ylabel("energy (J)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)


def plot_contacts(d: dict[str, np.ndarray], out: Path) -> None:
    """contacts.png: contact counts against time (s)."""
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for name in ("monitored", "active", "degenerated", "failed"):
        if name in d:
            ax.plot(d["time"], d[name], label=name)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("number of contacts")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)


def motion_direction(disp: np.ndarray) -> np.ndarray | None:
    """Unit direction of a wall's largest displacement, or None if it never moved."""
    if disp.size == 0:
        return None
    norms = np.linalg.norm(disp, axis=1)
    k = int(np.argmax(norms))
    if norms[k] <= 1e-12:
        return None
    return disp[k] / norms[k]


def continuous_start(s: np.ndarray) -> int:
    """Index after the last jump of a displacement history (a ``MoveWall ToContact`` step
    moves a wall instantly); the continuous motion after it is what Fig. 7 shows."""
    if len(s) < 3:
        return 0
    steps = np.abs(np.diff(s))
    moving = steps[steps > 0]
    if moving.size == 0:
        return 0
    jumps = np.nonzero(steps > 20.0 * np.median(moving))[0]
    return int(jumps[-1] + 1) if jumps.size else 0


def plot_wall(name: str, d: dict[str, np.ndarray], out: Path) -> bool:
    """<name>_reaction.png: reaction against displacement along the wall's motion, measured
    from where its continuous motion starts (after any instantaneous ToContact move).

    Returns False (and writes nothing) when the wall did not move.
    """
    disp = np.stack([d[f"displacement_{c}"] for c in "xyz"], axis=1)
    reac = np.stack([d[f"reaction_{c}"] for c in "xyz"], axis=1)
    u = motion_direction(disp)
    if u is None:
        return False
    axis = "xyz"[int(np.argmax(np.abs(u)))]
    sign = "+" if u[int(np.argmax(np.abs(u)))] > 0 else "-"
    along = disp @ u
    start = continuous_start(along)
    fig, ax = plt.subplots(figsize=(6, 4.5))
    # reaction = force holding the wall on its path = minus the particles' push, so the
    # particles' resistance to the motion u is reaction . u
    ax.plot(along[start:] - along[start], reac[start:] @ u)
    ax.set_xlabel(f"{name} displacement along its motion ({sign}{axis}), m")
    ax.set_ylabel(f"{name} reaction (particles resisting the motion), N")
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return True


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("results_dir", type=Path)
    ap.add_argument("--out", type=Path, default=None, help="folder for the PNGs")
    args = ap.parse_args(argv)
    mon = args.results_dir / "monitors"
    if not mon.is_dir():
        print(f"{mon}: no monitors folder", file=sys.stderr)
        return 2
    out = args.out or args.results_dir
    out.mkdir(parents=True, exist_ok=True)
    written = []
    if (mon / "energy.csv").is_file():
        plot_energy(read_csv(mon / "energy.csv"), out / "energy.png")
        written.append("energy.png")
    if (mon / "contacts.csv").is_file():
        plot_contacts(read_csv(mon / "contacts.csv"), out / "contacts.png")
        written.append("contacts.png")
    for csv in sorted(mon.glob("wall_*.csv")):
        name = csv.stem[len("wall_"):]
        if plot_wall(name, read_csv(csv), out / f"{name}_reaction.png"):
            written.append(f"{name}_reaction.png")
    for w in written:
        print(out / w)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Decks the benchmarks write: N paper particles (A, B, C, one third each) placed at random in
a box region, the paper's contact law, TimeStep 1e-3 s."""
from __future__ import annotations

from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def paper_mix_deck(n: int, region: tuple[float, float, float], box_height: float,
                   durations: list[float], out: Path, monitors_every: float = 0.001,
                   vtk_resolution: int = 4, counts: list[int] | None = None) -> str:
    """Deck text: ``n`` particles in the region [0, region] (m), a box of the region's base
    and ``box_height`` (m), dynamic steps of the given durations (s), results in ``out``
    (no VTK or checkpoint during the run).  ``counts``: of A, B, C (default n/3 each)."""
    shapes = (REPO / "inputs" / "shapes").resolve()
    c = list(counts) if counts is not None else [n // 3, n // 3, n - 2 * (n // 3)]
    lx, ly, lz = region
    steps = "\n".join(f"  Step {k + 1} Dynamic Duration {d:.6g} TimeStep 1e-3"
                      for k, d in enumerate(durations))
    return f"""Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2700
Shapes
  Shape 1 File {shapes}/A.yaml
  Shape 2 File {shapes}/B.yaml
  Shape 3 File {shapes}/C.yaml
Particles
  Random 1 Shapes 1 2 3 Counts {c[0]} {c[1]} {c[2]} Material 1 Region 0 0 0 {lx:.6f} {ly:.6f} {lz:.6f} Seed 1
Walls
  Box 1 Min 0 0 0 Max {lx:.6f} {ly:.6f} {box_height:.6f}
Contact
  Interface 1 NormalPenalty 1e5 TangentialPenalty 1e4 NormalDamping 1e2 TangentialDamping 0 Friction 0.5
Steps
{steps}
Output
  Directory {out}
  VTK Every 1000 Resolution {vtk_resolution}
  Monitors Every {monitors_every:g}
  Checkpoint Every 1000
"""

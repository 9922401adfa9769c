"""What a triangle-mesh wall of 10^5 triangles adds to the step of a 10^4-particle pack.

The scene: N exact spheres (radius 5 mm, glass-like) in a simple cubic block of three layers
resting on a floor, gravity on, linear contacts (εn 1e4 N/m, cn 0.5 N·s/m, εt 1e4 N/m,
μ 0.5); the floor is either a flat `Wall` or a `Mesh` of the same square tessellated into
2 × k × k triangles (k = 224: 100 352 triangles), a file the benchmark writes.  Both decks
run the same deck steps (TimeStep 1e-3 s, sub-stepped by the solver) in the compiled deck
steps, each ``--repeats`` times, the two decks alternated (one run of 280 internal steps
varies by tens of per cent on a shared machine); printed for each: the median time loop (the
solver's own timers of the time loop: search, LCPs, forces and integration) of the measured
step, which follows a warm-up step of ``WARM_STEPS`` deck steps (it loads the compiled
kernels: not a cost of the step), its cost per internal step and per particle-step, and the
median of the paired ratios mesh / flat with their range.  The set-up (the mesh read and
binned), the output and the writers' opening (the mesh drawn for ``walls.pvd``) are not in
the time loop.  The error: the floor's
vertical reaction at the end against the flat floor's, relative to the pack's weight (the
mesh's face contacts are the flat wall's closed form; the positions themselves drift apart
by round-off amplified in the stacked block, whose contacts are summed in another order).

Usage: .venv/bin/python benchmarks/bench_mesh_floor.py [--n 10000] [--k 224] [--steps 20]
       [--repeats 5] [--quick]   (quick: 1 000 spheres, k = 64, 5 deck steps)
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

R = 0.005
#: deck steps of the warm-up step before the measured one
WARM_STEPS = 2
RUN = """
import json, sys
from nurbsdem.io.deck import parse_deck
from nurbsdem.solver import Solver
LOOP = ("global search", "LCP", "forces + integration")
s = Solver(parse_deck(sys.argv[1]), output=sys.argv[2], quiet=True)
s.start()
s.run_step(s.model.steps[0])              # the warm-up step: loads the compiled kernels
loop0, substeps0 = sum(s.timers[k] for k in LOOP), s.summary.substeps
s.run_step(s.model.steps[1])
loop, substeps = sum(s.timers[k] for k in LOOP) - loop0, s.summary.substeps - substeps0
s.finish()
import numpy as np
mon = np.genfromtxt(sys.argv[2] + "/monitors/wall_floor.csv", delimiter=",", names=True)
print(json.dumps(dict(loop=loop, substeps=substeps, reaction=float(mon["reaction_z"][-1]))))
"""


def block(n: int) -> tuple[np.ndarray, float]:
    """Centres of about n spheres in a simple cubic block of 3 layers on z = 0 (spacing 2R,
    the first layer at its rest height on the floor), and the block's side (m)."""
    m = int(math.ceil(math.sqrt(n / 3)))
    g = (np.arange(m) - (m - 1) / 2) * 2 * R
    x, y, z = np.meshgrid(g, g, R * (1 + 2 * np.arange(3)), indexing="ij")
    return np.column_stack([x.ravel(), y.ravel(), z.ravel()]), m * 2 * R + 4 * R


def write_floor(path: Path, side: float, k: int) -> int:
    """The square [−side/2, side/2]² at z = 0 as an STL of 2 k² triangles (front +z)."""
    import trimesh
    g = np.linspace(-side / 2, side / 2, k + 1)
    X, Y = np.meshgrid(g, g, indexing="ij")
    v = np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])
    i = np.arange(k)[:, None] * (k + 1) + np.arange(k)[None, :]
    a, b, c, d = i.ravel(), (i + k + 1).ravel(), (i + k + 2).ravel(), (i + 1).ravel()
    faces = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    trimesh.Trimesh(v, faces, process=False).export(path)
    return len(faces)


def deck(pos: np.ndarray, side: float, floor: str, steps: int) -> str:
    lines = "\n".join(f"  Particle {i + 1} Shape 1 Material 1 Position {p[0]:.17g} {p[1]:.17g} "
                      f"{p[2]:.17g}" for i, p in enumerate(pos))
    return f"""Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2500
Shapes
  Shape 1 Sphere Radius {R}
Particles
{lines}
Walls
  {floor}
Contact
  Interface 1 NormalPenalty 1e4 NormalDamping 0.5 TangentialPenalty 1e4 Friction 0.5
Steps
  Step 1 Dynamic Duration {WARM_STEPS * 1e-3:.6g} TimeStep 1e-3
  Step 2 Dynamic Duration {steps * 1e-3:.6g} TimeStep 1e-3
Output
  Directory out
  Monitors Every 1e-3
"""


def run(deck_path: Path, out: Path) -> dict:
    r = subprocess.run([sys.executable, "-c", RUN, str(deck_path), str(out)], env=dict(os.environ),
                       capture_output=True, text=True, check=True)
    return json.loads(r.stdout.strip().splitlines()[-1])


def main(argv: list[str]) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=10000)
    ap.add_argument("--k", type=int, default=224)
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=5,
                    help="runs of each deck, alternated; the medians are reported")
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args(argv)
    if a.quick:
        a.n, a.k, a.steps = 1000, 64, 5
    pos, side = block(a.n)
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        triangles = write_floor(work / "floor.stl", side, a.k)
        floors = {"flat": f"Wall 1 Name floor Point 0 0 0 Normal 0 0 1 Size {side} {side}",
                  "mesh": "Mesh 1 Name floor File floor.stl"}
        for name, line in floors.items():
            (work / f"{name}.inp").write_text(deck(pos, side, line, a.steps))
            run(work / f"{name}.inp", work / f"warm_{name}")      # compiled kernels cached
        runs = {name: [] for name in floors}
        for k in range(max(1, a.repeats)):       # alternated: a slower minute hits both
            for name in floors:
                runs[name].append(run(work / f"{name}.inp", work / f"out_{name}_{k}"))
        ratios = [(m["loop"] / m["substeps"]) / (f["loop"] / f["substeps"])
                  for f, m in zip(runs["flat"], runs["mesh"])]
        for name in floors:                      # the run of the median time loop
            by_loop = sorted(runs[name], key=lambda r: r["loop"])
            out[name] = by_loop[len(by_loop) // 2]
    n = len(pos)
    weight = len(pos) * 2500.0 * 4.0 / 3.0 * math.pi * R ** 3 * 9.81
    err = abs(out["mesh"]["reaction"] - out["flat"]["reaction"]) / weight
    print(f"{n} spheres in 3 layers on a floor of side {side:.3f} m, {a.steps} deck steps; "
          f"each deck run {len(ratios)} times, alternated (medians)")
    for name in ("flat", "mesh"):
        r = out[name]
        per = r["loop"] / r["substeps"]
        label = "flat wall" if name == "flat" else f"mesh, {triangles} triangles"
        print(f"  {label:<26} time loop {r['loop']:.2f} s, {r['substeps']} internal steps, "
              f"{1e3 * per:.2f} ms per step, {1e6 * per / n:.2f} µs per particle-step")
    ratio = float(np.median(ratios))
    print(f"mesh / flat cost per internal step: {ratio:.3f} ({100 * (ratio - 1):+.1f} %; pairs "
          f"{min(ratios):.3f} to {max(ratios):.3f}); "
          f"floor reactions at the end differ by {err:.2e} of the weight "
          f"({out['flat']['reaction'] / weight:.4f} x the weight on the flat floor)")
    return dict(n=n, triangles=triangles, ratio=ratio, error=err,
                flat=out["flat"]["loop"], mesh=out["mesh"]["loop"])


if __name__ == "__main__":
    main(sys.argv[1:])

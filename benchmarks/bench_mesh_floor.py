"""What a triangle-mesh wall of 10^5 triangles adds to the step of a 10^4-particle pack.

The scene: N exact spheres (radius 5 mm, glass-like) in a simple cubic block of three layers
resting on a floor, gravity on, linear contacts (εn 1e4 N/m, cn 0.5 N·s/m, εt 1e4 N/m,
μ 0.5); the floor is either a flat `Wall` or a `Mesh` of the same square tessellated into
2 × k × k triangles (k = 224: 100 352 triangles), a file the benchmark writes.  Both decks
run in the compiled deck steps, in **one process**: each is set up and runs a warm-up step of
``WARM_STEPS`` deck steps (it loads the compiled kernels: not a cost of the step), then the
two run ``--repeats`` measured steps of ``--steps`` deck steps (TimeStep 1e-3 s, sub-stepped
by the solver) each, alternated, flat then mesh.  One process because the same run's speed
differs by tens of per cent from one process to the next (its memory layout), more than the
difference measured; alternated so that a slower minute of a shared machine hits both.
Printed for each deck: the median time loop of its measured steps (the solver's own timers
of the time loop: search, LCPs, forces and integration), its cost per internal step and per
particle-step, and the median of the paired ratios mesh / flat per internal step with their
range.  The set-up (the mesh read and binned), the output and the writers' opening (the mesh
drawn for ``walls.pvd``) are not in the time loop.  The error: the floor's vertical
reaction at the end against the flat floor's, relative to the pack's weight (the mesh's
face contacts are the flat wall's closed form; the positions themselves drift apart by
round-off amplified in the stacked block, whose contacts are summed in another order).

Usage: .venv/bin/python benchmarks/bench_mesh_floor.py [--n 10000] [--k 224] [--steps 20]
       [--repeats 8] [--quick]   (quick: 1 000 spheres, k = 64, 5 deck steps, 2 repeats)
"""
from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

R = 0.005
#: deck steps of the warm-up step before the measured ones
WARM_STEPS = 2
#: both decks in one process (argv: the two decks, their output folders, the repeats): per
#: deck the measured steps' time loops (s) and internal steps, and the floor's reaction (N)
RUN = """
import json, sys
import numpy as np
from nurbsdem.io.deck import parse_deck
from nurbsdem.solver import Solver
LOOP = ("global search", "LCP", "forces + integration")
decks, outs, repeats = sys.argv[1:3], sys.argv[3:5], int(sys.argv[5])
solvers = [Solver(parse_deck(d), output=o, quiet=True) for d, o in zip(decks, outs)]
for s in solvers:
    s.start()
    s.run_step(s.model.steps[0])          # the warm-up step: loads the compiled kernels
runs = [dict(loop=[], substeps=[]) for _ in solvers]
for k in range(1, repeats + 1):
    for s, run in zip(solvers, runs):
        loop0, substeps0 = sum(s.timers[x] for x in LOOP), s.summary.substeps
        s.run_step(s.model.steps[k])
        run["loop"].append(sum(s.timers[x] for x in LOOP) - loop0)
        run["substeps"].append(s.summary.substeps - substeps0)
for s, run, o in zip(solvers, runs, outs):
    s.finish()
    mon = np.genfromtxt(o + "/monitors/wall_floor.csv", delimiter=",", names=True)
    run["reaction"] = float(mon["reaction_z"][-1])
print(json.dumps(runs))
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


def deck(pos: np.ndarray, side: float, floor: str, steps: int, repeats: int) -> str:
    """The deck: the warm-up step, then ``repeats`` measured steps of ``steps`` deck steps."""
    measured = "".join(f"  Step {k} Dynamic Duration {steps * 1e-3:.6g} TimeStep 1e-3\n"
                       for k in range(2, repeats + 2))
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
{measured}Output
  Directory out
  Monitors Every 1e-3
"""


def main(argv: list[str]) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=10000)
    ap.add_argument("--k", type=int, default=224)
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=8,
                    help="measured steps of each deck, alternated; the medians are reported")
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args(argv)
    if a.quick:
        a.n, a.k, a.steps, a.repeats = 1000, 64, 5, 2
    repeats = max(1, a.repeats)
    pos, side = block(a.n)
    names = ("flat", "mesh")
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        triangles = write_floor(work / "floor.stl", side, a.k)
        floors = {"flat": f"Wall 1 Name floor Point 0 0 0 Normal 0 0 1 Size {side} {side}",
                  "mesh": "Mesh 1 Name floor File floor.stl"}
        for name in names:
            (work / f"{name}.inp").write_text(deck(pos, side, floors[name], a.steps, repeats))
        r = subprocess.run([sys.executable, "-c", RUN]
                           + [str(work / f"{name}.inp") for name in names]
                           + [str(work / f"out_{name}") for name in names] + [str(repeats)],
                           capture_output=True, text=True, check=True)
        runs = dict(zip(names, json.loads(r.stdout.strip().splitlines()[-1])))
    per = {name: np.array(runs[name]["loop"]) / np.array(runs[name]["substeps"])
           for name in names}
    ratios = per["mesh"] / per["flat"]
    out = {}
    for name in names:                           # the measured step of the median time loop
        k = int(np.argsort(runs[name]["loop"])[len(runs[name]["loop"]) // 2])
        out[name] = dict(loop=runs[name]["loop"][k], substeps=runs[name]["substeps"][k],
                         reaction=runs[name]["reaction"])
    n = len(pos)
    weight = len(pos) * 2500.0 * 4.0 / 3.0 * math.pi * R ** 3 * 9.81
    err = abs(out["mesh"]["reaction"] - out["flat"]["reaction"]) / weight
    print(f"{n} spheres in 3 layers on a floor of side {side:.3f} m, {a.steps} deck steps "
          f"measured {len(ratios)} times per deck in one process, alternated (medians)")
    for name in ("flat", "mesh"):
        r = out[name]
        cost = r["loop"] / r["substeps"]
        label = "flat wall" if name == "flat" else f"mesh, {triangles} triangles"
        print(f"  {label:<26} time loop {r['loop']:.2f} s, {r['substeps']} internal steps, "
              f"{1e3 * cost:.2f} ms per step, {1e6 * cost / n:.2f} µs per particle-step")
    ratio = float(np.median(ratios))
    print(f"mesh / flat cost per internal step: {ratio:.3f} ({100 * (ratio - 1):+.1f} %; pairs "
          f"{min(ratios):.3f} to {max(ratios):.3f}); "
          f"floor reactions at the end differ by {err:.2e} of the weight "
          f"({out['flat']['reaction'] / weight:.4f} x the weight on the flat floor)")
    return dict(n=n, triangles=triangles, ratio=ratio, error=err,
                flat=out["flat"]["loop"], mesh=out["mesh"]["loop"])


if __name__ == "__main__":
    main(sys.argv[1:])

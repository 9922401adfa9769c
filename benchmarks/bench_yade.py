"""nurbsdem against Yade on the same scene of 112 spheres, side by side in one run.

The scene: the paper's box (0.25 × 0.25 × 0.60 m) and contact law (εn 1e5 N/m, cn 1e2 N·s/m,
εt 1e4 N/m, μ 0.5, density 2700 kg/m³), with 112 spheres whose radii are the volume-equivalent
radii of the paper's particles A, B, C (40 + 24 + 48, the counts after the paper's replication),
placed at random without overlap (seeded) and released under gravity for ``T`` seconds at the
time step 1e-4 s.  Both codes get the same positions and the same linear spring–dashpot law
(Yade: ``ViscElMat`` with kn 2e5, cn 200, ks 2e4 per material, which Yade combines in series
into the contact's 1e5, 100, 1e4 — printed from a Yade interaction to be sure).

Printed: the wall time of the time loop of each code on one thread (nurbsdem:
``NUMBA_NUM_THREADS=1``, the solver's timers of its time loop — search, LCPs, forces and
integration — after a short deck in the same process has loaded the compiled kernels; Yade:
``-j1``, its ``O.run``), its ratio, and the mean height of the spheres at the end (the outcome
both must agree on).  When Yade is not installed (``apt-get install yade``) the
benchmark says so and measures nurbsdem alone.

Usage: .venv/bin/python benchmarks/bench_yade.py [--quick]   (quick: T = 0.1 s)
"""
from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

import numpy as np

VOLUMES = {"A": 98.57e-6, "B": 50.47e-6, "C": 21.29e-6}       # paper Table 1 (m³)
COUNTS = {"A": 40, "B": 24, "C": 48}
BOX = (0.25, 0.25, 0.60)
DT = 1e-4


def radii() -> dict[str, float]:
    return {k: (3 * v / (4 * math.pi)) ** (1 / 3) for k, v in VOLUMES.items()}


def place(seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Centres (112,3) and radii (112,) placed at random without overlap in the box (largest
    first), 1 mm clear of each other and of the walls."""
    rng = np.random.default_rng(seed)
    r = radii()
    rad = np.concatenate([np.full(COUNTS[k], r[k]) for k in ("A", "B", "C")])
    pos = np.zeros((rad.size, 3))
    for i, ri in enumerate(rad):
        for _ in range(100000):
            p = rng.uniform([ri + 1e-3] * 3, np.array(BOX) - ri - 1e-3)
            if i == 0 or np.all(np.linalg.norm(pos[:i] - p, axis=1) > rad[:i] + ri + 1e-3):
                pos[i] = p
                break
        else:  # pragma: no cover - the box holds them easily
            raise RuntimeError("could not place the spheres")
    return pos, rad


def nurbsdem_deck(pos: np.ndarray, rad: np.ndarray, T: float) -> str:
    r = radii()
    shape = {r["A"]: 1, r["B"]: 2, r["C"]: 3}
    lines = [f"  Particle {i + 1} Shape {shape[float(ri)]} Material 1 Position "
             f"{p[0]:.17g} {p[1]:.17g} {p[2]:.17g}" for i, (p, ri) in enumerate(zip(pos, rad))]
    return textwrap.dedent(f"""\
        Environment
          Gravity 0 0 -9.81
        Materials
          Material 1 Density 2700
        Shapes
          Shape 1 Sphere Radius {r['A']:.17g}
          Shape 2 Sphere Radius {r['B']:.17g}
          Shape 3 Sphere Radius {r['C']:.17g}
        Particles
        """) + "\n".join(lines) + textwrap.dedent(f"""
        Walls
          Box 1 Min 0 0 0 Max {BOX[0]} {BOX[1]} {BOX[2]}
        Contact
          Interface 1 NormalPenalty 1e5 TangentialPenalty 1e4 NormalDamping 1e2 TangentialDamping 0 Friction 0.5
        Steps
          Step 1 Dynamic Duration {T} TimeStep {DT}
        Output
          Directory out
          VTK Every {T} Resolution 4
          Monitors Every 0.01
        """)


NURBSDEM_RUN = """
import json, sys, time
from nurbsdem.io.deck import parse_deck
from nurbsdem.solver import Solver
LOOP = ("global search", "LCP", "forces + integration")
if len(sys.argv) > 3:       # a short deck first, in this process: it loads the compiled kernels
    Solver(parse_deck(sys.argv[3]), output=sys.argv[2] + "_warm", quiet=True).run()
s = Solver(parse_deck(sys.argv[1]), output=sys.argv[2], quiet=True)
t = time.perf_counter()
summary = s.run()
wall = time.perf_counter() - t
print(json.dumps(dict(wall=wall, loop=sum(summary.timers[k] for k in LOOP),
                      height=float(s.bodies.position[:, 2].mean()), substeps=summary.substeps,
                      steps=summary.steps)))
"""

YADE_RUN = """
import json, time
from math import atan
data = json.load(open(DATA))
m = O.materials.append(ViscElMat(kn=2e5, cn=200, ks=2e4, cs=0, frictionAngle=atan(0.5), density=2700))
O.bodies.append([sphere(tuple(p), r, material=m) for p, r in zip(data['pos'], data['rad'])])
L = data['box']
O.bodies.append([wall((0, 0, 0), axis=2, material=m), wall((0, 0, 0), axis=0, material=m),
                 wall((L[0], 0, 0), axis=0, material=m), wall((0, 0, 0), axis=1, material=m),
                 wall((0, L[1], 0), axis=1, material=m), wall((0, 0, L[2]), axis=2, material=m)])
O.engines = [ForceResetter(), InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Wall_Aabb()]),
             InteractionLoop([Ig2_Sphere_Sphere_ScGeom(), Ig2_Wall_Sphere_ScGeom()],
                             [Ip2_ViscElMat_ViscElMat_ViscElPhys()], [Law2_ScGeom_ViscElPhys_Basic()]),
             NewtonIntegrator(damping=0, gravity=(0, 0, -9.81))]
O.dt = data['dt']
t = time.perf_counter()
O.run(int(round(data['T'] / data['dt'])), True)
wall_t = time.perf_counter() - t
i = next((i for i in O.interactions if i.isReal), None)
law = [i.phys.kn, i.phys.cn, i.phys.ks] if i is not None else []
h = sum(b.state.pos[2] for b in O.bodies if isinstance(b.shape, Sphere)) / len(data['rad'])
print('YADE-RESULT ' + json.dumps(dict(wall=wall_t, height=h, law=law)))
"""


#: runs of each code, alternated; the faster of each is compared
ROUNDS = 2


def run_nurbsdem(deck: Path, out: Path, warmup: Path) -> dict:
    """Time loop of nurbsdem on ``deck`` (the solver's timers of its time loop: search, LCPs,
    forces and integration).  ``warmup``, a short deck, runs first in the same process: it
    compiles the kernels into numba's cache on the first call and loads them into the process
    on every call, so that neither is timed (as Yade's time is its ``O.run``, its start-up
    aside)."""
    env = dict(os.environ, NUMBA_NUM_THREADS="1")
    r = subprocess.run([sys.executable, "-c", NURBSDEM_RUN, str(deck), str(out), str(warmup)],
                       env=env, capture_output=True, text=True, check=True)
    return json.loads(r.stdout.strip().splitlines()[-1])


def run_yade_script(script_text: str, data: dict, work: Path, timeout: float = 3600
                    ) -> dict | str:
    """Run the Yade script ``script_text`` (``DATA`` names a JSON file of ``data``) with
    ``yade -n -j1`` in ``work``: the JSON dict it prints after ``YADE-RESULT``, or why there
    is none (Yade not installed, or failed)."""
    exe = shutil.which("yade")
    if exe is None:
        return "Yade is not installed (apt-get install yade): it could not be measured"
    path = work / "scene.json"
    path.write_text(json.dumps(data))
    script = work / "yade_run.py"
    script.write_text(f"DATA = {str(path)!r}\n" + script_text)
    r = subprocess.run([exe, "-n", "-j1", "-x", str(script)], capture_output=True, text=True,
                       cwd=work, timeout=timeout)
    for line in r.stdout.splitlines():
        if line.startswith("YADE-RESULT "):
            return json.loads(line[len("YADE-RESULT "):])
    return f"Yade failed (exit {r.returncode}): {r.stderr.strip().splitlines()[-1:]}"


def run_yade(pos, rad, T: float, work: Path) -> dict | str:
    return run_yade_script(YADE_RUN, dict(pos=pos.tolist(), rad=rad.tolist(), box=BOX, dt=DT,
                                          T=T), work)


def main(argv: list[str]) -> dict:
    T = 0.1 if "--quick" in argv else 2.5
    pos, rad = place()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        deck = work / "spheres112.inp"
        deck.write_text(nurbsdem_deck(pos, rad, T))
        warm = work / "warmup.inp"
        warm.write_text(nurbsdem_deck(pos, rad, 0.02))
        nds, yds = [], []
        for k in range(ROUNDS):             # alternated: a machine's speed drifts
            nds.append(run_nurbsdem(deck, work / "out", warm))
            yds.append(run_yade(pos, rad, T, work))
    nd = min(nds, key=lambda r: r["loop"])
    yd = (min(yds, key=lambda r: r["wall"]) if all(isinstance(y, dict) for y in yds)
          else next(y for y in yds if isinstance(y, str)))
    nd["loops"] = [r["loop"] for r in nds]
    if isinstance(yd, dict):
        yd["walls"] = [y["wall"] for y in yds]
    print(f"112 spheres, {T} s at dt {DT} s, one thread each, the faster of {ROUNDS} runs each "
          f"(alternated)")
    print(f"nurbsdem: time loop {nd['loop']:.2f} s (runs: "
          f"{', '.join(f'{t:.2f}' for t in nd['loops'])} s; whole run {nd['wall']:.2f} s, "
          f"{nd['substeps']} internal steps), mean height at the end {nd['height']:.4f} m")
    if isinstance(yd, str):
        print(yd)
    else:
        print(f"Yade:     time loop {yd['wall']:.2f} s (runs: "
              f"{', '.join(f'{t:.2f}' for t in yd['walls'])} s), mean height at the end "
              f"{yd['height']:.4f} m "
              f"(contact law kn, cn, ks = {yd['law']})")
        print(f"ratio nurbsdem / Yade: {nd['loop'] / yd['wall']:.2f}; mean heights differ by "
              f"{100 * abs(nd['height'] / yd['height'] - 1):.2f} %")
    return dict(nurbsdem=nd, yade=yd, T=T)


if __name__ == "__main__":
    main(sys.argv[1:])

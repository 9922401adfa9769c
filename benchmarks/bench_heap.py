"""A heap poured onto a floor: its angle of repose measured from the output, for exact spheres
and for the paper's particles of the spheres' volumes, and the time it takes.

The scene: a square floor (a flat ``Wall``, 0.3 m, the grains' friction) under an inlet disc
``HEIGHT`` above its centre that pours ``--count`` grains (three sizes in equal numbers: the
silo benchmark's spheres of radii 1.8, 2.0 and 2.2 mm, d = 4 mm, glass-like, or the paper's
particles A, B and C scaled to those volumes, at random orientations) at ``RATE`` per second
with a downward speed of 0.5 m/s; they settle for ``SETTLE`` seconds after the last one is
placed.  Grains that roll off the floor leave through an outlet plane below it.  The contact
law is the silo's soft linear spring–dashpot (εn = εt = 500 N/m, restitution about 0.5,
μ 0.5) with a rolling friction ``ROLLING`` (:mod:`nurbsdem.dynamics.rolling`: without
rolling resistance smooth spheres on a flat floor spread into a layer a few grains high).
The rolling torque is at most μ_r R_r f_n with R_r the contact's rolling radius (R/2 between
two equal spheres), so that a sphere rolling over another one is held up to a slope of about
tan α = μ_r R_r / R: with μ_r 0.3, about 9 degrees (the largest μ_r the solver accepts, 0.4,
about 11 degrees); the pockets between grains hold a heap's flank steeper than that.  A
grain whose shape resists rolling (the paper's particles) piles up steeper with the same law.
Built with the Python API (:class:`nurbsdem.Simulation`).

The angle of repose is that of the heap's flank (``postproc/repose.py``,
:func:`angle_of_repose`: the highest grain top in 12 rings between 25 % and 85 % of the
heap's foot radius, a straight line fitted to them; ± its standard error), from the grains'
centroids and bounding radii at the end.  ``postproc/repose.py`` is checked against lattice
cones of known angle in ``tests/test_repose.py``.  Printed with it: the grains left on the
floor and rolled off, the heap's foot radius and height, and the time of the run on one
thread.

Usage: .venv/bin/python benchmarks/bench_heap.py [--shape sphere|paper|both] [--count N]
       [--quick] [--json OUT]   (quick: 150 grains, a smoke test of the pipeline, not a
measurement; default: both grains, 1000 each, JSON ``benchmarks/.cache/heap.json`` that
``benchmarks/report.py`` reads)
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "postproc"))
sys.path.insert(0, str(ROOT / "benchmarks"))
from repose import angle_of_repose  # noqa: E402
import common  # noqa: E402
# the silo's grains and linear law (one definition: the heap is poured with the same)
from bench_beverloo import DENSITY, G, KN, MU, RADII, RESTITUTION, damping  # noqa: E402,F401

ROLLING = 0.3                             # rolling friction μ_r
FLOOR = 0.3                               # m, the floor's side
HEIGHT = 0.05                             # m, the inlet disc above the floor
INLET_RADIUS, INLET_THICKNESS = 0.02, 0.03
RATE = 1000.0                             # grains per second
SETTLE = 0.6                              # s after the last grain is placed
SHAPES = ("sphere", "paper")


def grains(shape: str, folder: Path) -> list:
    """The three grains of ``shape``: exact spheres of radii RADII, or the paper's particles
    scaled to their volumes (shape files written into ``folder``)."""
    from nurbsdem import shapes
    if shape == "sphere":
        return [shapes.sphere(r) for r in RADII]
    if shape == "paper":
        return [folder / name for name, _ in common.write_paper_shapes(folder, RADII)]
    raise SystemExit(f"--shape: {shape!r} is not one of {', '.join(SHAPES)}, both")


def heap(shape: str, count: int, out: Path) -> dict:
    """Pour ``count`` grains of ``shape`` onto the floor (module docstring) with the output in
    ``out``; returns the angle of repose and the run's figures."""
    from nurbsdem import Simulation
    sim = Simulation(gravity=(0, 0, -G), output=out, quiet=True, vtk_every=1.0,
                     monitors_every=0.01)
    sim.add_material(1, density=DENSITY)
    sim.add_interface(normal_penalty=KN, tangential_penalty=KN, normal_damping=damping(),
                      friction=MU, rolling_friction=ROLLING)
    sim.add_wall("floor", (0, 0, 0), (0, 0, 1), (FLOOR, FLOOR))
    sim.add_inlet(grains(shape, out.parent), 1, None, rate=RATE, count=count,
                  fractions=(1 / 3, 1 / 3, 1 / 3), velocity=(0, 0, -0.5), seed=3, every=0.01,
                  name="feed", disc=(0, 0, HEIGHT), normal=(0, 0, 1), radius=INLET_RADIUS,
                  thickness=INLET_THICKNESS)
    sim.add_outlet(point=(0, 0, -0.02), normal=(0, 0, -1), every=0.01, name="off")
    simulated = count / RATE + SETTLE
    t0 = time.perf_counter()
    sim.run_dynamic(simulated, 1e-3)
    wall = time.perf_counter() - t0
    bodies, model = sim.bodies, sim.model
    summary = sim.close()
    x = bodies.position
    radius = np.array([model.shapes[int(s)].bounding_radius for s in bodies.shape_id])
    rep = angle_of_repose(x, radius)
    top = x[:, 2] + radius
    return dict(shape=shape, count=count, on_floor=len(bodies), rolled_off=count - len(bodies),
                angle=rep.angle, error=rep.error, foot=rep.foot,
                height=float(top.max()), simulated=simulated, wall=wall,
                substeps=summary.substeps, timers=dict(summary.timers))


def main(argv: list[str]) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shape", default="both", help="sphere, paper or both")
    ap.add_argument("--count", type=int, default=1000)
    ap.add_argument("--quick", action="store_true", help="150 grains: a smoke test")
    ap.add_argument("--json", type=Path, help="write the result here")
    a = ap.parse_args(argv)
    kinds = SHAPES if a.shape == "both" else (a.shape,)
    for k in kinds:
        if k not in SHAPES:
            raise SystemExit(f"--shape: {k!r} is not one of {', '.join(SHAPES)}, both")
    import numba
    numba.set_num_threads(1)
    count = 150 if a.quick else a.count
    out = dict(quick=a.quick, radii=list(RADII), rolling=ROLLING, friction=MU, rate=RATE,
               height=HEIGHT, runs=[], machine=common.machine_info())
    with tempfile.TemporaryDirectory() as tmp:
        for k in kinds:
            folder = Path(tmp) / k
            folder.mkdir()
            r = heap(k, count, folder / "out")
            out["runs"].append(r)
            print(f"{k}: {r['count']} grains poured, {r['on_floor']} on the floor "
                  f"({r['rolled_off']} rolled off): angle of repose {r['angle']:.1f} ± "
                  f"{r['error']:.1f} degrees, foot radius {r['foot'] * 1e3:.0f} mm, height "
                  f"{r['height'] * 1e3:.0f} mm; {r['simulated']:.2f} s simulated in "
                  f"{r['wall']:.1f} s ({r['substeps']} internal steps, one thread)")
    path = a.json or ROOT / "benchmarks" / ".cache" / ("heap_quick.json" if a.quick
                                                        else "heap.json")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=1, default=float))
    return out


if __name__ == "__main__":
    main(sys.argv[1:])

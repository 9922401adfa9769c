"""Pouring 2 000 spheres into a box: every particle accounted for, none placed overlapping,
the energy balance closed, and the time it takes.

The scene: an open box 0.1 × 0.1 × 0.3 m; an inlet box near the top pours a 60/40 mix of
exact spheres of radius 4 and 3 mm (glass-like, 2500 kg/m^3) at 2000 particles/s with a
downward speed of 1 m/s until the count; an outlet in one corner of the floor (0.03 × 0.03 ×
0.01 m) removes the spheres that land there.  Linear contacts (εn = εt = 2e4 N/m, cn 0.5
N·s/m, μ 0.4), deck time step 1e-3 s (sub-stepped by the solver), the pour's time and
0.4 s of settling.  Built with the Python API (:class:`nurbsdem.Simulation`).

Checked (the errors printed beside the time):

* accounting — inserted = in the box + discharged, in count and in mass (exact: the
  counts are integers and the masses of the same spheres);
* placement — the smallest gap between a new sphere and any sphere present at its insertion
  (must be ≥ 0: the inlet places clear of the bounding spheres, which for an exact sphere is
  the sphere itself);
* containment — every sphere left is inside the box;
* energy — the largest balance error of ``monitors/energy.csv`` relative to the energy
  turned over (dissipated + external work: the particles entering and leaving carry theirs).

The time is that of the run on ``--threads`` threads (default one: numba's threaded row
kernels share the machine's cores with whatever else runs there), its internal steps, and the
solver's split of it (global search, contact rows, forces and integration, set-up: the set-up
holds the system built anew at every exchange of particles).

``--convergence``: the pour again at half the internal step (``Safety`` 0.25 instead of
0.5): the balance error of an explicit scheme falls as h², so it must fall about fourfold.

Usage: .venv/bin/python benchmarks/bench_pour.py [--count 2000] [--quick] [--threads 1]
       [--convergence] [--json OUT]   (quick: 300 spheres)
"""
from __future__ import annotations

import argparse
import csv
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_info  # noqa: E402

BOX = (0.1, 0.1, 0.3)          # m
RADII = (0.004, 0.003)         # m
FRACTIONS = (0.6, 0.4)
DENSITY = 2500.0               # kg/m^3
RATE = 2000.0                  # particles/s
SETTLE = 0.4                   # s after the pour's time
INLET = (0.01, 0.01, 0.22, 0.09, 0.09, 0.28)
OUTLET = (0.0, 0.0, 0.0, 0.03, 0.03, 0.01)


def _rows(path: Path) -> list[dict[str, float]]:
    with open(path) as fh:
        return [{k: float(v) for k, v in r.items()} for r in csv.DictReader(fh)]


def _min_gap(present, added, shapes: dict) -> float:
    """Smallest surface gap (m) between each new sphere and every other sphere present
    (``shapes``: the model's shape entries; a sphere's bounding radius is its radius)."""
    x = np.concatenate([present.position, added.position])
    ids = np.concatenate([present.shape_id, added.shape_id])
    r = np.array([shapes[int(s)].bounding_radius for s in ids])
    new = np.arange(len(present), len(x))
    d = np.linalg.norm(x[new, None] - x[None], axis=2) - r[new, None] - r[None]
    d[np.arange(len(new)), new] = np.inf
    return float(d.min()) if d.size else float("inf")


def pour(count: int, out: Path, safety: float | None = None) -> dict:
    """Run the pour of ``count`` spheres into ``out``; returns the checks and timings."""
    from nurbsdem import Simulation, shapes
    from nurbsdem.flow_run import FlowRun
    gaps: list[float] = []
    original = FlowRun.insert

    def watched(self, t, bodies):
        added = original(self, t, bodies)
        if len(added):
            gaps.append(_min_gap(bodies, added, sim.model.shapes))
        return added
    FlowRun.insert = watched
    try:
        sim = Simulation(gravity=(0, 0, -9.81), output=out, quiet=True)
        sim.add_material(1, density=DENSITY)
        sim.add_interface(normal_penalty=2e4, normal_damping=0.5, tangential_penalty=2e4,
                          friction=0.4)
        sim.add_box((0, 0, 0), BOX)
        spheres = [shapes.sphere(r) for r in RADII]
        sim.add_inlet(spheres, 1, INLET, rate=RATE, count=count, fractions=FRACTIONS,
                      velocity=(0, 0, -1), seed=1, every=0.01, name="feed")
        sim.add_outlet(OUTLET, every=0.01, name="corner")
        t0 = time.perf_counter()
        sim.run_dynamic(count / RATE + SETTLE, 1e-3, safety=safety)
        wall = time.perf_counter() - t0
        bodies = sim.bodies
        model = sim.model
        summary = sim.close()
    finally:
        FlowRun.insert = original
    mass = {k: e.mass(DENSITY) for k, e in model.shapes.items()}
    inlet = _rows(out / "monitors" / "inlet_feed.csv")[-1]
    outlet = _rows(out / "monitors" / "outlet_corner.csv")[-1]
    energy = _rows(out / "monitors" / "energy.csv")
    in_box_mass = sum(mass[int(s)] for s in bodies.shape_id)
    turned = max(e["dissipated"] + abs(e["external_work"]) for e in energy)
    inside = bool(np.all((bodies.position > 0) & (bodies.position < BOX)))
    timers = dict(summary.timers)
    return dict(count=count, inserted=int(inlet["inserted"]), waiting=int(inlet["waiting"]),
                in_box=len(bodies), discharged=int(outlet["count"]),
                count_error=int(inlet["inserted"]) - len(bodies) - int(outlet["count"]),
                mass_error=abs(inlet["mass"] - in_box_mass - outlet["mass"]) / inlet["mass"],
                min_gap=min(gaps), inside=inside,
                balance=max(abs(e["balance_error"]) for e in energy) / turned,
                wall=wall, substeps=summary.substeps, timers=timers,
                simulated=count / RATE + SETTLE)


def main(argv: list[str]) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=2000)
    ap.add_argument("--quick", action="store_true", help="300 spheres")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--convergence", action="store_true", help="also at half the step")
    ap.add_argument("--json", type=Path, help="write the result here")
    a = ap.parse_args(argv)
    import numba
    numba.set_num_threads(min(a.threads, numba.config.NUMBA_NUM_THREADS))
    count = 300 if a.quick else a.count
    with tempfile.TemporaryDirectory() as tmp:
        r = pour(count, Path(tmp) / "out")
        if a.convergence:
            r["half_step"] = pour(count, Path(tmp) / "half", safety=0.25)
    r["machine"] = machine_info()
    r["threads"] = numba.get_num_threads()
    print(f"pour of {r['count']} spheres ({r['simulated']:.2f} s simulated, "
          f"{r['substeps']} internal steps): run {r['wall']:.1f} s")
    print(f"  inserted {r['inserted']} (waiting {r['waiting']}) = in the box {r['in_box']} "
          f"+ discharged {r['discharged']}: count error {r['count_error']}, "
          f"mass error {r['mass_error']:.1e}")
    print(f"  smallest gap at insertion {r['min_gap'] * 1e3:.3f} mm; all inside the box: "
          f"{r['inside']}; energy balance error {r['balance']:.2e} of the energy turned over")
    split = ", ".join(f"{k} {v:.1f} s" for k, v in r["timers"].items())
    print(f"  time split ({r['threads']} thread(s)): {split}")
    if "half_step" in r:
        h = r["half_step"]
        print(f"  at half the internal step ({h['substeps']} internal steps, {h['wall']:.1f} s): "
              f"balance error {h['balance']:.2e}, {r['balance'] / h['balance']:.1f} times "
              "smaller (h^2: 4)")
    if a.json:
        a.json.write_text(json.dumps(r, indent=1))
    return r


if __name__ == "__main__":
    main(sys.argv[1:])

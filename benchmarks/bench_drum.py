"""A rotating drum of spheres: nurbsdem (exact NURBS cylinder, and the same cylinder as a
triangle mesh) against Yade (a facet cylinder turned by a ``RotationEngine``), side by side.

The scene: a horizontal drum of radius 0.1 m and length 0.04 m about x, closed by two flat
fixed end plates; spheres of three radii (3.5, 4 and 4.5 mm; glass-like, 2500 kg/m³) placed at
random without overlap (seeded) in the drum, settled for 0.5 s, then the drum turns at Ω
about x (Froude number Ω²R/g = 0.01) for ``T`` seconds.  Both codes get the same positions,
the same linear spring–dashpot law (εn 1e4 N/m, cn 1 N·s/m, εt 1e4 N/m, μ 0.5; Yade's
``ViscElMat`` per material at twice these, which Yade combines in series) and the same time
step (Yade runs at nurbsdem's mean internal step).

Measured from each code's output over the last ``WINDOW`` seconds of the turn: the dynamic
angle of repose (the tilt of the bed's cross-section, ``postproc/repose.py`` ``bed_angle``,
mean and spread over samples 0.1 s apart) and the drive torque about the axis (the mean of
the torque the drive applies, minus the particles' load on the drum about x: nurbsdem
``monitors/wall_drum.csv``; Yade: the facets' forces' moments about the axis).  Printed
with the wall time of each time loop on one thread (nurbsdem ``NUMBA_NUM_THREADS=1``, the
solver's timers of its time loop: search, LCPs, forces and integration, the compiled
kernels' loading from numba's cache included, about a second; Yade ``-j1``, its ``O.run``)
and their ratio.  When Yade is not installed (``apt-get install yade``) the benchmark says so
and measures nurbsdem alone.

Then **the paper's particles**, which only nurbsdem runs: each sphere becomes a paper particle
of its volume (A, B and C scaled to the spheres of 3.5, 4 and 4.5 mm: :func:`paper_shapes`),
placed on sites drawn at random from a lattice (:func:`place_lattice`: their bounding spheres
clear of each other) and turned at random, in the
exact NURBS drum, with the same law, settling and turn; their angle and torque against the
spheres'.  The drum's concave radius (0.1 m) is far above the particles' largest radius of
curvature (A's, 10 mm at this scale), so every contact with the mantle is unique (the
``Surface`` wall's condition).

Usage: .venv/bin/python benchmarks/bench_drum.py [--quick] [--count N]
(quick: 150 spheres, a 0.3 s turn: a smoke test of the pipeline, not a measurement).
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "postproc"))
sys.path.insert(0, str(ROOT / "benchmarks"))
from repose import bed_angle  # noqa: E402
from bench_yade import NURBSDEM_RUN, run_yade_script  # noqa: E402
from common import write_paper_shapes  # noqa: E402

R_DRUM, LENGTH, G = 0.1, 0.04, 9.81
RADII = (0.0035, 0.004, 0.0045)
DENSITY = 2500.0
KN, CN, KT, MU = 1e4, 1.0, 1e4, 0.5
SETTLE = 0.5
FROUDE = 0.01
OMEGA = math.sqrt(FROUDE * G / R_DRUM)
SEGMENTS = 72                     # the mesh and Yade's facets: chord error R (1 − cos π/72)
WINDOW = 1.0


def place(count: int, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Centres (n,3) and radii (n,) at random without overlap in the drum, 1 mm clear of
    each other and of the mantle and end plates (largest first)."""
    rng = np.random.default_rng(seed)
    rad = np.sort(rng.choice(RADII, count))[::-1]
    pos = np.zeros((count, 3))
    for i, ri in enumerate(rad):
        for _ in range(200000):
            p = np.array([rng.uniform(-LENGTH / 2 + ri + 1e-3, LENGTH / 2 - ri - 1e-3),
                          *rng.uniform(-R_DRUM, R_DRUM, 2)])
            if math.hypot(p[1], p[2]) > R_DRUM - ri - 1e-3:
                continue
            if i == 0 or np.all(np.linalg.norm(pos[:i] - p, axis=1) > rad[:i] + ri + 1e-3):
                pos[i] = p
                break
        else:  # pragma: no cover - the drum holds them at this fill
            raise RuntimeError("could not place the spheres")
    return pos, rad


def place_lattice(count: int, clear: dict[float, float], seed: int = 1, gap: float = 2e-4
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Centres (n,3) and radii (n,) of :data:`RADII` (drawn at random, seeded) on ``count``
    sites drawn at random from a hexagonal close-packed lattice in the drum whose spacing is
    the largest of ``clear`` (a radius of :data:`RADII` → the bounding radius of the particle
    that stands for it) doubled plus ``gap`` (m), the sites ``gap`` clear of the mantle and
    the end plates.  Elongated particles' bounding spheres fill the drum too densely for
    :func:`place`'s random sequential placement."""
    rng = np.random.default_rng(seed)
    rb = max(clear.values())
    s = 2.0 * rb + gap
    x0, x1 = -LENGTH / 2 + rb + gap, LENGTH / 2 - rb - gap
    layers = int(math.floor((x1 - x0) / (s * math.sqrt(2.0 / 3.0)) + 1e-9)) + 1
    room = R_DRUM - rb - gap
    m = int(math.ceil(room / s)) + 2
    sites = []
    for k in range(layers):
        shift = (0.5 * s, 0.5 * s / math.sqrt(3.0)) if k % 2 else (0.0, 0.0)
        for i in range(-m, m + 1):
            for j in range(-2 * m, 2 * m + 1):
                y = (i + 0.5 * (j % 2)) * s + shift[0]
                z = j * s * math.sqrt(3.0) / 2.0 + shift[1]
                if math.hypot(y, z) <= room:
                    sites.append((x0 + k * s * math.sqrt(2.0 / 3.0), y, z))
    if len(sites) < count:
        raise RuntimeError(f"the drum's lattice holds {len(sites)} particles, not {count}")
    pick = rng.choice(len(sites), count, replace=False)
    return np.array(sites)[pick], rng.choice(RADII, count)


def paper_shapes(folder: Path) -> dict[float, tuple[str, float]]:
    """The paper's particles A, B and C scaled to the volumes of the spheres of radius 3.5,
    4 and 4.5 mm (each sphere of the drum becomes a paper particle of its volume), written
    to ``folder`` as shape files: radius → (file name, bounding radius m)."""
    return dict(zip(RADII, write_paper_shapes(folder, RADII)))


def write_mesh(path: Path) -> None:
    """The drum's mantle as an STL of 2 × SEGMENTS triangles (vertices on the circle),
    axis x, from −L/2 to L/2."""
    import trimesh
    a = np.linspace(0.0, 2.0 * math.pi, SEGMENTS, endpoint=False)
    ring = np.column_stack([np.cos(a), np.sin(a)]) * R_DRUM
    v = np.vstack([np.column_stack([np.full(SEGMENTS, x), ring]) for x in (-LENGTH / 2,
                                                                            LENGTH / 2)])
    f = []
    for k in range(SEGMENTS):
        k1 = (k + 1) % SEGMENTS
        f += [[k, k1, SEGMENTS + k1], [k, SEGMENTS + k1, SEGMENTS + k]]
    trimesh.Trimesh(v, np.array(f), process=False).export(path)


def nurbsdem_deck(pos, rad, T: float, wall_line: str,
                  files: dict[float, tuple[str, float]] | None = None, seed: int = 2) -> str:
    """The drum's deck: spheres of :data:`RADII`, or with ``files`` (:func:`paper_shapes`)
    the shape files of those radii, each particle turned by a random rotation (seeded)."""
    shape = {r: k + 1 for k, r in enumerate(RADII)}
    rng = np.random.default_rng(seed)
    lines = []
    for i, (p, ri) in enumerate(zip(pos, rad)):
        line = (f"  Particle {i + 1} Shape {shape[float(ri)]} Material 1 Position "
                f"{p[0]:.17g} {p[1]:.17g} {p[2]:.17g}")
        if files:
            rv = Rotation.random(random_state=rng).as_rotvec()
            line += f" Rotation {rv[0]:.17g} {rv[1]:.17g} {rv[2]:.17g}"
        lines.append(line)
    shapes = "\n".join(f"  Shape {k + 1} File {files[r][0]}" if files else
                       f"  Shape {k + 1} Sphere Radius {r}" for k, r in enumerate(RADII))
    return textwrap.dedent("""\
        Environment
          Gravity 0 0 -9.81
        Materials
          Material 1 Density {rho}
        Shapes
        {shapes}
        Particles
        """).format(rho=DENSITY, shapes=shapes) + "\n".join(lines) + textwrap.dedent(f"""
        Walls
          {wall_line}
          Wall 2 Name plate_x_min Point {-LENGTH / 2} 0 0 Normal 1 0 0 Size 0.22 0.22
          Wall 3 Name plate_x_max Point {LENGTH / 2} 0 0 Normal -1 0 0 Size 0.22 0.22
        Contact
          Interface 1 NormalPenalty {KN} NormalDamping {CN} TangentialPenalty {KT} Friction {MU}
        Steps
          Step 1 Dynamic Duration {SETTLE} TimeStep 1e-3
          Step 2 MoveWall drum Rotate AngularVelocity {OMEGA:.17g} 0 0 Center 0 0 0 Duration {T} TimeStep 1e-3
        Output
          Directory out
          Results Every 0.1
          Monitors Every 0.01
        """)


YADE_RUN = """
import json, time
from math import atan, pi
from yade import geom
data = json.load(open(DATA))
m = O.materials.append(ViscElMat(kn=2 * data['kn'], cn=2 * data['cn'], ks=2 * data['kt'], cs=0,
                                 frictionAngle=atan(data['mu']), density=data['rho']))
O.bodies.append([sphere(tuple(p), r, material=m) for p, r in zip(data['pos'], data['rad'])])
n = len(data['rad'])
facets = geom.facetCylinder((0, 0, 0), data['R'], data['L'], orientation=Quaternion((0, 1, 0), pi / 2),
                            segmentsNumber=data['segments'], wallMask=4, material=m)
ids = O.bodies.append(facets)
O.bodies.append([wall((-data['L'] / 2, 0, 0), axis=0, material=m),
                 wall((data['L'] / 2, 0, 0), axis=0, material=m)])
turn = RotationEngine(ids=ids, rotationAxis=(1, 0, 0), rotateAroundZero=True, zeroPoint=(0, 0, 0),
                      angularVelocity=0.0)
O.engines = [ForceResetter(),
             InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Facet_Aabb(), Bo1_Wall_Aabb()]),
             InteractionLoop([Ig2_Sphere_Sphere_ScGeom(), Ig2_Facet_Sphere_ScGeom(),
                              Ig2_Wall_Sphere_ScGeom()],
                             [Ip2_ViscElMat_ViscElMat_ViscElPhys()], [Law2_ScGeom_ViscElPhys_Basic()]),
             turn, NewtonIntegrator(damping=0, gravity=(0, 0, -9.81)),
             PyRunner(command='collect()', virtPeriod=0.01)]
samples, torques, last = [], [], [-1]
def collect():
    t = O.time
    if t < data['settle'] + data['T'] - data['window'] - 1e-9:
        return
    tq = 0.0
    for i in ids:
        f, p = O.forces.f(i), O.bodies[i].state.pos
        tq += p[1] * f[2] - p[2] * f[1] + O.forces.t(i)[0]
    torques.append(tq)
    k = int((t + 0.5 * data['dt']) / 0.1)
    if k != last[0]:
        last[0] = k
        samples.append([list(O.bodies[i].state.pos) for i in range(n)])
O.dt = data['dt']
t0 = time.perf_counter()
O.run(int(round(data['settle'] / data['dt'])), True)
turn.angularVelocity = data['omega']
O.run(int(round(data['T'] / data['dt'])), True)
wall_t = time.perf_counter() - t0
print('YADE-RESULT ' + json.dumps(dict(wall=wall_t, samples=samples, torques=torques)))
"""


def run_nurbsdem(deck: Path, out: Path) -> dict:
    """Time loop of nurbsdem on ``deck`` on one thread, then its angle and torque."""
    import h5py
    env = dict(os.environ, NUMBA_NUM_THREADS="1")
    r = subprocess.run([sys.executable, "-c", NURBSDEM_RUN, str(deck), str(out)], env=env,
                       capture_output=True, text=True, check=True)
    res = json.loads(r.stdout.strip().splitlines()[-1])
    with h5py.File(out / "results.h5") as f:
        t, off, pos = f["time"][:], f["offset"][:], f["position"][:]
    end = t[-1]
    angles = [bed_angle(pos[off[k]:off[k + 1]]) for k in range(len(t))
              if t[k] >= end - WINDOW - 1e-9]
    mon = np.genfromtxt(out / "monitors" / "wall_drum.csv", delimiter=",", names=True)
    torque = mon["torque_x"][mon["time"] >= end - WINDOW - 1e-9]
    res.update(angle=float(np.mean(angles)), angle_spread=float(np.std(angles)),
               torque=float(-np.mean(torque)), samples=len(angles))
    return res


def run_yade(pos, rad, T: float, dt: float, work: Path) -> dict | str:
    """Yade's run of the same drum (:data:`YADE_RUN`), its angle and torque as
    :func:`run_nurbsdem` gives them; or why it could not run."""
    res = run_yade_script(YADE_RUN, dict(pos=pos.tolist(), rad=rad.tolist(), R=R_DRUM,
                                         L=LENGTH, segments=SEGMENTS, kn=KN, cn=CN, kt=KT,
                                         mu=MU, rho=DENSITY, settle=SETTLE, T=T, omega=OMEGA,
                                         dt=dt, window=WINDOW), work, timeout=7200)
    if isinstance(res, str):
        return res
    angles = [bed_angle(np.array(s)) for s in res.pop("samples")]
    torques = res.pop("torques")
    res.update(angle=float(np.mean(angles)), angle_spread=float(np.std(angles)),
               torque=float(-np.mean(torques)), samples=len(angles))
    return res

def main(argv: list[str]) -> dict:
    quick = "--quick" in argv
    count = int(argv[argv.index("--count") + 1]) if "--count" in argv else (150 if quick
                                                                             else 800)
    T = 0.3 if quick else 2.5
    global WINDOW
    WINDOW = min(WINDOW, T)
    pos, rad = place(count)
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        subprocess.run([sys.executable, "-m", "nurbsdem", "shape", "cylinder", "--radius",
                        str(R_DRUM), "--length", str(LENGTH), "-o", str(work / "drum.yaml")],
                       check=True, capture_output=True)
        write_mesh(work / "drum.stl")
        walls = {"nurbs": "Surface 1 Name drum File drum.yaml Rotation 0 1.5707963267948966 0 "
                          f"Position {-LENGTH / 2} 0 0",
                 "mesh": "Mesh 1 Name drum File drum.stl"}
        for kind, line in walls.items():
            deck = work / f"drum_{kind}.inp"
            deck.write_text(nurbsdem_deck(pos, rad, T, line))
            out[kind] = run_nurbsdem(deck, work / f"out_{kind}")
        dt = (SETTLE + T) / out["nurbs"]["substeps"]
        out["yade"] = run_yade(pos, rad, T, dt, work)
        files = paper_shapes(work)
        ppos, prad = place_lattice(count, {r: v[1] for r, v in files.items()})
        deck = work / "drum_paper.inp"
        deck.write_text(nurbsdem_deck(ppos, prad, T, walls["nurbs"], files=files))
        out["paper"] = run_nurbsdem(deck, work / "out_paper")
    print(f"rotating drum: {count} spheres, R {R_DRUM} m, L {LENGTH} m, Froude {FROUDE} "
          f"(Ω {OMEGA:.3f} rad/s), {SETTLE} s settling + {T} s turning; angle and torque over "
          f"the last {WINDOW} s; one thread each")
    print(f"{'code':<22}{'loop (s)':>10}{'angle (deg)':>16}{'torque (N m)':>15}")
    rows = [("nurbsdem, NURBS drum", out["nurbs"]), ("nurbsdem, mesh drum", out["mesh"])]
    if isinstance(out["yade"], dict):
        rows.append((f"Yade, {SEGMENTS} facets", out["yade"]))
    rows.append(("paper particles, NURBS", out["paper"]))
    for name, r in rows:
        print(f"{name:<22}{r.get('loop', r.get('wall')):>10.2f}"
              f"{r['angle']:>10.2f} ± {r['angle_spread']:<4.2f}{r['torque']:>15.5f}")
    if isinstance(out["yade"], str):
        print(out["yade"])
    else:
        y, n = out["yade"], out["nurbs"]
        print(f"ratio nurbsdem (NURBS drum) / Yade time: {n['loop'] / y['wall']:.2f}; angles "
              f"differ by {n['angle'] - y['angle']:+.2f} deg; torques by "
              f"{100 * (n['torque'] / y['torque'] - 1):+.1f} % (Yade at dt {dt:.3g} s)")
    p, n = out["paper"], out["nurbs"]
    print(f"the paper's particles of the spheres' volumes (only nurbsdem runs them): angle "
          f"{p['angle'] - n['angle']:+.2f} deg and torque {100 * (p['torque'] / n['torque'] - 1):+.1f} % "
          f"against the spheres; time loop {p['loop'] / n['loop']:.1f} x theirs")
    out.update(count=count, window=WINDOW, T=T)
    return out


if __name__ == "__main__":
    main(sys.argv[1:])

"""Silo discharge of spheres against Beverloo's law, against Yade, and the cost of the inlet
and the outlet in the step.

The scene: a square flat-bottomed silo of side ``L`` (flat side ``Wall`` rectangles) whose
floor is a ``Mesh`` with a circular orifice of diameter D in its centre (the square less a
regular 64-gon of circumradius D/2, triangulated radially; a file the benchmark writes).  A
mesh, not flat ``Wall`` rectangles around a hole: a flat wall ends at its rectangle's edge, so
a sphere whose centre is over the hole loses the floor although it still rests on the rim
(the orifice would act about one grain wider, and shift Beverloo's k by about −1); the mesh's
rim is its boundary edges, each touched exactly (:mod:`nurbsdem.contact.mesh_wall`).  The
spheres: three radii 1.8, 2.0 and 2.2 mm (equal numbers; the mean diameter d = 4 mm is the
grain size of the law; the spread keeps the bed from crystallising on the flat floor),
glass-like (2500 kg/m³), a soft linear spring–dashpot law (εn = εt = ``KN`` N/m: the weight
of the fill presses the lowest contacts by about 1 % of d; normal damping for a restitution
of about 0.5; μ 0.5), the solver's sub-steps at ``Safety`` 0.8 of the contact network's
stability limit.

1. **Fill** (once, for all orifices): the silo with a closed floor (a flat ``Wall``: the
   orifice shut by its gate) is filled to 24 d (full run) by an ``Inlet`` pouring the
   spheres at 1.5 m/s down from a slab 11 d thick above the bed over ``POUR`` seconds (for
   every ``POUR_HEIGHT`` of bed); they
   settle for ``SETTLE`` seconds after the last has landed (their speeds at the end are
   printed).  The bulk density ρ_b is the mass of the spheres whose centres lie in the core
   of the settled bed (2 d from the side walls, the floor and the free surface) over the
   core's volume.
2. **Discharge** (per orifice): the settled bed (positions and velocities) in the silo whose
   floor is the mesh with the orifice: the gate is gone at t = 0; 0.4 s of discharge (full
   run) at orifices of 6, 8, 11 and 15 d (over 0.28 s from an 18 d fill, the rates through
   8 to 15 d still rose by 3–7 % between the window's halves; the bed ends above 1.2 D).
   The spheres falling out pass an ``Outlet`` plane 4 d below the floor; the steady mass
   flow rate W is the slope of a linear fit of the discharged mass
   (``monitors/outlet_below.csv``) over the steady window, leaving out the first ``LEAD``
   and the last ``TAIL`` of the run (the start-up and the sampling end); its spread is the
   difference between the slopes of the window's two halves.
3. **Beverloo**: ``postproc/beverloo.py`` fits W = C ρ_b √g (D − k d)^n to the orifices
   (n, k, C with their standard errors and the RMS of the relative residuals), each against
   the published range for spheres (n 2.5 ± 0.3, k 1–2, C 0.5–0.7), and k and C at n 2.5
   (the free exponent needs a wide range of D: with rates 2.5 % in error, the fitted n
   spreads by about 0.2 over orifices of 6 to 15 d, by 1.4 over 6 to 9.5 d; k and C at n 2.5
   far less); with each orifice, the C its rate gives at n 2.5 and k 1.5 (the
   law with the middle of the ranges).

The silo is 2.5 times as wide as the largest orifice and filled to well above it, so that
the flow rate is the silo's and not its walls' or the fill height's; the fill's height left
at the end of each discharge is printed.

**Yade** (when installed; CI has none): the discharge of the smallest orifice from the same
settled positions, with the same law (``ViscElMat`` per material at twice εn, cn and εt, which
Yade combines in series), the mesh's triangles as ``facet``s, the side walls as ``wall``s, and
Yade's time step set to nurbsdem's mean internal step; a ``PyRunner`` every 0.01 s erases and
weighs the spheres below the outlet plane (nurbsdem's outlet, also every 0.01 s).  Printed: the
wall time of each time loop on one thread (nurbsdem: ``NUMBA_NUM_THREADS=1``, the run less its
set-up and output; the inlet and outlet exchanges and the rebuilt systems are in the loop;
Yade: ``-j1``, its ``O.run``), their ratio and the two flow rates; and the CPU time of each
(nurbsdem: its whole run, set-up and output included; Yade: its ``O.run``), which a machine
shared with other work disturbs less than the wall time.

**Inlet and outlet cost**: the solver books its exchanges (the outlets' removal, the inlets'
placement and the system built anew for the new set of particles) in the timer
``inlets + outlets`` of ``summary.timers`` (:func:`nurbsdem.flow_run.exchange`); printed as a
share of the time loop for the fill (the inlet) and each discharge (the outlet).

**Other grains** (``--shape ellipsoid | paper``): the same fill and discharges with grains of
the spheres' volumes, ellipsoids of semi-axes ``ELLIPSOID`` × r or the paper's particles A,
B and C scaled (shape files the run writes), through orifices of 6, 7 and 8 d in a silo
2.5 × 8 d wide filled to 9 d (a NURBS particle's contacts cost LCPs); no Yade run (it has no
exact ellipsoids or NURBS particles).

Usage: python benchmarks/bench_beverloo.py [--quick] [--shape S] [--seed S]
[--orifices R... [--yade-at R]] [--discharge S] [--json PATH] | --refit PATH |
--combine PATH... [--json PATH]
(quick: one orifice of 6 d in a silo 2.5 × 6 d wide, short runs: a smoke test of the
pipeline, not a measurement; no Beverloo fit, which needs three orifices; ``--orifices``: the
same silo and fill of the seed discharged through these orifices instead, and Yade through
the one of ``--yade-at``; ``--discharge``: S seconds of discharge instead of 0.4, at most
:data:`MAX_DISCHARGE`).  Writes the JSON ``benchmarks/.cache/beverloo.json``
(``--quick``: ``beverloo_quick.json``; other grains: ``beverloo_<shape>[_quick].json``;
another seed: ``beverloo_seed<S>.json``; other orifices: ``…_D<R>-<R>.json``; another
discharge time: ``…_T<S>.json``) that
``benchmarks/report.py`` reads; ``--refit`` fits its rates again; ``--combine`` fits the
rates of several fills' JSONs averaged, a seed's runs of other orifices joined to its run
(:func:`combine`: ``beverloo_fills.json``).
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "postproc"))
sys.path.insert(0, str(ROOT / "benchmarks"))
from beverloo import fit_beverloo  # noqa: E402
from bench_yade import run_yade_script  # noqa: E402
import common  # noqa: E402

G = 9.81
RADII = (0.0018, 0.0020, 0.0022)          # m, equal numbers
D_GRAIN = 2.0 * float(np.mean(RADII))     # d (m): the mean diameter
DENSITY = 2500.0                          # kg/m^3
KN = 5.0e2                                # N/m, normal and tangential penalty
MU = 0.5
RESTITUTION = 0.5
SAFETY = 0.8
DT = 1.0e-3                               # the deck's TimeStep (s); the solver sub-steps it
EVERY = 0.01                              # inlet and outlet segments (s)
SEGMENTS = 64                             # the orifice's polygon
FRACTIONS = "Fractions 0.3333333333333333 0.3333333333333334 0.3333333333333333"
POUR, SETTLE = 0.15, 0.15                 # the fill's pour and settling times (s)
#: the most bed height (in d) the inlet pours in ``POUR`` seconds: a deeper fill pours longer
#: (faster, a segment's particles do not fit in the room the last ones left: they wait)
POUR_HEIGHT = 18.0
LEAD, TAIL = 0.35, 0.1                    # fractions of a discharge left out of the fit
#: the published ranges for spheres: exponent, k, C
RANGES = {"n": (2.2, 2.8), "k": (1.0, 2.0), "C": (0.5, 0.7)}
FULL = dict(orifices=(6.0, 8.0, 11.0, 15.0), fill=24.0, discharge=0.4)
#: the longest ``--discharge`` (s): through 15 d the 24 d fill then ends about 16 d high
MAX_DISCHARGE = 0.8
QUICK = dict(orifices=(6.0,), fill=9.0, discharge=0.15)
#: the runs of the other grains (``--shape ellipsoid | paper``): three orifices, a shallower
#: fill and shorter discharges (a NURBS particle's contacts cost LCPs)
SHAPED = dict(orifices=(6.0, 7.0, 8.0), fill=9.0, discharge=0.15)
#: the grains: exact spheres; ellipsoids of semi-axes ELLIPSOID × r (aspect ratio 1.56,
#: the sphere's volume); the paper's particles A, B and C scaled to the spheres' volumes
SHAPES = ("sphere", "ellipsoid", "paper")
ELLIPSOID = (1.25, 1.0, 0.8)
#: the smallest orifice (in d) of the combined fills' second fit, which shows how much the
#: free exponent rests on the smallest orifice, the one nearest to clogging (where the law
#: is least sure: Mankoc et al., Granular Matter 9, 2007); the first fit takes them all
FIT_FROM = 8.0
#: the resamples of the fills for the free exponent's spread (:func:`bootstrap_exponent`)
BOOT_DRAWS = 2000
#: the inlet's seed of the fill (``--seed``): another seed pours another bed of the same
#: grains, whose discharges give the rates' spread from fill to fill
SEED = 3


def mean_mass() -> float:
    """The mean mass (kg) of a sphere of the mix."""
    return DENSITY * 4.0 / 3.0 * math.pi * float(np.mean(np.array(RADII) ** 3))


def damping() -> float:
    """The normal dashpot (N s/m) of a restitution ``RESTITUTION`` for two spheres of the
    middle radius (the linear law's closed form, ζ = −ln e / √(π² + ln² e))."""
    m = DENSITY * 4.0 / 3.0 * math.pi * RADII[1] ** 3
    ln_e = math.log(RESTITUTION)
    zeta = -ln_e / math.sqrt(math.pi ** 2 + ln_e ** 2)
    return 2.0 * zeta * math.sqrt(0.5 * m * KN)


def write_floor(path: Path, side: float, D: float, segments: int = SEGMENTS) -> None:
    """The floor [−side/2, side/2]² at z = 0 less the regular ``segments``-gon of
    circumradius D/2 about the origin, as an STL: each polygon vertex joined to the square's
    boundary point on its ray (the square's corners among them: ``segments`` a multiple of
    8), two triangles per sector, fronts +z."""
    import trimesh
    if segments % 8:
        raise ValueError("segments must be a multiple of 8 (the square's corners on rays)")
    a = 2.0 * math.pi * np.arange(segments) / segments
    c, s = np.cos(a), np.sin(a)
    inner = 0.5 * D * np.column_stack([c, s, np.zeros(segments)])
    reach = 0.5 * side / np.maximum(np.abs(c), np.abs(s))
    outer = np.column_stack([reach * c, reach * s, np.zeros(segments)])
    faces = []
    for i in range(segments):
        j = (i + 1) % segments
        faces += [[i, segments + i, segments + j], [i, segments + j, j]]
    trimesh.Trimesh(np.vstack([inner, outer]), np.array(faces), process=False).export(path)


def side_walls(side: float, height: float) -> str:
    """The four side walls of the silo (deck lines, numbered from 2), each a square of
    side max(side, height) + margin, reaching below the floor."""
    size = max(side, 2.0 * height) + 0.02
    h = 0.5 * side
    return "\n".join(
        f"  Wall {k + 2} Name {name} Point {p[0]:.17g} {p[1]:.17g} 0 Normal {n} Size {size} {size}"
        for k, (name, p, n) in enumerate((("xmin", (-h, 0), "1 0 0"), ("xmax", (h, 0), "-1 0 0"),
                                          ("ymin", (0, -h), "0 1 0"), ("ymax", (0, h), "0 -1 0"))))


def _shape_lines(shape: str) -> str:
    """The deck's three shapes of the grain ``shape`` (:data:`SHAPES`), each of the volume of
    the sphere of radius RADII[k]."""
    if shape == "sphere":
        return "\n".join(f"  Shape {k + 1} Sphere Radius {r}" for k, r in enumerate(RADII))
    if shape == "ellipsoid":
        a, b, c = ELLIPSOID
        return "\n".join(f"  Shape {k + 1} Ellipsoid SemiAxes {a * r:.17g} {b * r:.17g} "
                         f"{c * r:.17g}" for k, r in enumerate(RADII))
    if shape == "paper":
        return "\n".join(f"  Shape {k + 1} File paper_{k + 1}.yaml" for k in range(len(RADII)))
    raise ValueError(f"unknown shape {shape!r} (one of {', '.join(SHAPES)})")


def write_paper_shapes(folder: Path) -> None:
    """The paper's particles A, B and C scaled to the volumes of the spheres of radii RADII,
    as shape files ``paper_1.yaml`` … in ``folder`` (:func:`common.write_paper_shapes`)."""
    common.write_paper_shapes(folder, RADII)


def _header(shape: str = "sphere") -> str:
    return (f"Environment\n  Gravity 0 0 -{G}\nMaterials\n  Material 1 Density {DENSITY}\n"
            f"Shapes\n{_shape_lines(shape)}\n")


def _contact() -> str:
    return (f"Contact\n  Interface 1 NormalPenalty {KN} NormalDamping {damping():.6g} "
            f"TangentialPenalty {KN} Friction {MU}\n")


def fill_count(side: float, height: float) -> int:
    """Spheres that fill the silo of ``side`` to ``height`` (m) at a solid fraction 0.6."""
    v = 4.0 / 3.0 * math.pi * float(np.mean(np.array(RADII) ** 3))
    return int(round(0.6 * side * side * height / v / 3.0)) * 3


def fill_deck(side: float, height: float, count: int, shape: str = "sphere"
              ) -> tuple[str, float]:
    """The fill: an inlet pours ``count`` spheres into the closed silo at 1.5 m/s down over
    ``POUR`` seconds (longer for a bed above ``POUR_HEIGHT``) from a slab 11 d thick above
    the bed's expected top ``height`` (m);
    the run lasts until the last of them has fallen to the floor and ``SETTLE`` seconds more.
    The deck and its duration (s)."""
    h = 0.5 * side - 1.2 * RADII[-1]
    top = height + 12.0 * D_GRAIN
    v0 = 1.5
    fall = (math.sqrt(v0 * v0 + 2.0 * G * top) - v0) / G
    pour = POUR * max(1.0, height / (POUR_HEIGHT * D_GRAIN))
    T = round((pour + fall + SETTLE) / EVERY) * EVERY
    box = f"Box {-h} {-h} {height + D_GRAIN} {h} {h} {top}"
    flow = f"Rate {count / pour:.6g} Count {count} Velocity 0 0 {-v0} Seed {SEED} Every {EVERY}"
    deck = _header(shape) + textwrap.dedent(f"""\
        Walls
          Wall 1 Name floor Point 0 0 0 Normal 0 0 1 Size {side + 0.02} {side + 0.02}
        """) + side_walls(side, top) + "\n" + _contact() + textwrap.dedent(f"""\
        Flow
          Inlet 1 Name feed Shapes 1 2 3 {FRACTIONS} Material 1 {box} {flow}
        Steps
          Step 1 Dynamic Duration {T:.6g} TimeStep {DT} Safety {SAFETY}
        Output
          Directory out
          Monitors Every 0.1
          VTK Every {T:.6g}
        """)
    return deck, T


def discharge_deck(top: float, side: float, T: float, shape: str = "sphere") -> str:
    """The discharge deck for T seconds through the mesh floor ``floor.stl`` of a silo of
    ``side`` filled to ``top`` (m), ParaView samples at its start and end only, as the fill's
    (every 0.01 s, the samples of a bed of 4·10^4 tessellated grains filled the disk, and the
    benchmark reads none); its particles are the settled bed, which the run sets
    (:data:`RUN`: a state that a settled run left, as a restart does; deck ``Particle``
    lines would be refused by ``check``, which accepts at most 20 times the resting overlap
    of a pair under one weight, while the bottom of the bed carries many)."""
    return (_header(shape) + "Walls\n" + "  Mesh 1 Name floor File floor.stl\n"
            + side_walls(side, top + D_GRAIN) + "\n" + _contact() + textwrap.dedent(f"""\
        Flow
          Outlet 1 Name below Point 0 0 {-4.0 * D_GRAIN} Normal 0 0 -1 Every {EVERY}
        Steps
          Step 1 Dynamic Duration {T:.6g} TimeStep {DT} Safety {SAFETY}
        Output
          Directory out
          Monitors Every 0.1
          VTK Every {T:.6g}
        """))


#: a sphere on a floor for a few deck steps, run before each timed run in its process: the
#: solver's compiled kernels are loaded from numba's cache then (set-up, as for the time loop
#: of a run whose particles are there from the start), not in the first inlet exchange
def warm_deck(shape: str = "sphere") -> str:
    """:data:`WARM` with a grain of ``shape`` (dropped from 1.5 d: a NURBS particle's
    bounding sphere reaches further than r)."""
    return WARM.replace(_header(), _header(shape)).replace(
        f"Position 0 0 {RADII[1]}", f"Position 0 0 {1.5 * D_GRAIN}")


WARM = _header() + textwrap.dedent(f"""\
    Particles
      Particle 1 Shape 2 Material 1 Position 0 0 {RADII[1]}
    Walls
      Wall 1 Name floor Point 0 0 0 Normal 0 0 1 Size 0.1 0.1
    """) + _contact() + textwrap.dedent(f"""\
    Steps
      Step 1 Dynamic Duration {3 * DT} TimeStep {DT} Safety {SAFETY}
    Output
      Directory out
    """)

RUN = """
import json, sys, time
import numpy as np
from nurbsdem.io.deck import parse_deck
from nurbsdem.model import Bodies
from nurbsdem.solver import Solver
warm = sys.argv[1][:-4] + '_warm.inp'   # one sphere for a few steps: the compiled kernels
Solver(parse_deck(warm), output=sys.argv[2] + '_warm', quiet=True).run()   # loaded untimed
model = parse_deck(sys.argv[1], place=len(sys.argv) == 3)
if len(sys.argv) > 3:                  # the settled state of another run
    st = np.load(sys.argv[3])
    n = len(st['shape'])
    q = st['quaternion'] if 'quaternion' in st.files else np.tile([1.0, 0, 0, 0], (n, 1))
    w = st['angular_velocity'] if 'angular_velocity' in st.files else np.zeros((n, 3))
    model.bodies = Bodies(np.arange(1, n + 1), st['shape'], np.ones(n), st['position'], q,
                          st['velocity'], w, np.zeros(n))
s = Solver(model, output=sys.argv[2], quiet=True)
t, c = time.perf_counter(), time.process_time()
summary = s.run()
wall, cpu = time.perf_counter() - t, time.process_time() - c
b = s.bodies
np.savez(sys.argv[2] + '/end.npz', position=b.position, velocity=b.velocity, shape=b.shape_id,
         quaternion=b.quaternion, angular_velocity=b.angular_velocity)
tm = summary.timers
print(json.dumps(dict(wall=wall, cpu=cpu, loop=wall - tm.get('output', 0.0) - tm.get('setup', 0.0),
                      flow=tm.get('inlets + outlets', 0.0), timers=tm, split=summary.split,
                      substeps=summary.substeps, steps=summary.steps,
                      time=summary.simulated_time)))
"""


def run_nurbsdem(deck_text: str, work: Path, name: str, state: Path | None = None,
                 shape: str = "sphere") -> dict:
    """Run ``deck_text`` (in ``work``; its particles those of the ``state`` file of another
    run when given; grains of ``shape``) on one thread: the timers (wall, loop, flow s),
    internal steps, and the end state (``end``: the arrays of ``out_<name>/end.npz``, which
    it names ``state``)."""
    deck = work / f"{name}.inp"
    deck.write_text(deck_text)
    (work / f"{name}_warm.inp").write_text(warm_deck(shape))
    out = work / f"out_{name}"
    env = dict(os.environ, NUMBA_NUM_THREADS="1")
    r = subprocess.run([sys.executable, "-c", RUN, str(deck), str(out)]
                       + ([str(state)] if state is not None else []), env=env,
                       capture_output=True, text=True, cwd=work)
    if r.returncode:
        raise RuntimeError(f"nurbsdem failed on {name}: {r.stderr.strip()[-2000:]}")
    res = json.loads(r.stdout.strip().splitlines()[-1])
    end = np.load(out / "end.npz")
    res["end"] = {k: end[k] for k in end.files}
    res["out"] = out
    res["state"] = out / "end.npz"
    return res


def bed_top(z: np.ndarray) -> float:
    """The height (m) of a bed's free surface from its centres' heights z (N,): the top of the
    highest slab of thickness d holding at least half the bulk's centres (the median count
    of the slabs between 2 d and mid-height)."""
    d = D_GRAIN
    edges = np.arange(0.0, float(z.max()) + 2.0 * d, d)
    counts = np.histogram(z, edges)[0]
    bulk = float(np.median(counts[2:max(3, len(counts) // 2)]))
    return float(edges[np.flatnonzero(counts >= 0.5 * bulk)[-1] + 1])


def bulk_density(pos: np.ndarray, shape: np.ndarray, side: float) -> tuple[float, float]:
    """ρ_b (kg/m³): the mass of the spheres whose centres lie in the core of the bed (2 d
    clear of the side walls and the floor, 2 d below the free surface) over the core's
    volume; and the height of the free surface (m, :func:`bed_top`)."""
    r = np.asarray(RADII)[shape - 1]
    top = bed_top(pos[:, 2])
    h = 0.5 * side - 2.0 * D_GRAIN
    lo, hi = 2.0 * D_GRAIN, top - 2.0 * D_GRAIN
    core = (np.all(np.abs(pos[:, :2]) < h, axis=1) & (pos[:, 2] > lo) & (pos[:, 2] < hi))
    mass = DENSITY * 4.0 / 3.0 * math.pi * float(np.sum(r[core] ** 3))
    return mass / ((2 * h) ** 2 * (hi - lo)), top


def steady_rate(csv: Path, T: float) -> dict:
    """The steady mass flow rate (kg/s) of an outlet's monitor: the slope of the discharged
    mass over [LEAD T, (1 − TAIL) T], its two halves' slopes, and the mass discharged."""
    mon = np.genfromtxt(csv, delimiter=",", names=True)
    t, m = np.atleast_1d(mon["time"]), np.atleast_1d(mon["mass"])
    a, b = LEAD * T, (1.0 - TAIL) * T
    w = (t >= a - 1e-9) & (t <= b + 1e-9)
    W = float(np.polyfit(t[w], m[w], 1)[0])
    mid = 0.5 * (a + b)
    halves = [float(np.polyfit(t[w & s], m[w & s], 1)[0])
              for s in (t <= mid + 1e-9, t >= mid - 1e-9)]
    return dict(W=W, halves=halves, mass=float(m[-1]), count=int(np.atleast_1d(mon["count"])[-1]),
                window=(a, b))


YADE_RUN = """
import json, time
from math import atan
data = json.load(open(DATA))
m = O.materials.append(ViscElMat(kn=2 * data['kn'], cn=2 * data['cn'], ks=2 * data['kt'], cs=0,
                                 frictionAngle=atan(data['mu']), density=data['rho']))
spheres = O.bodies.append([sphere(tuple(p), r, material=m)
                           for p, r in zip(data['pos'], data['rad'])])
for i, v in zip(spheres, data['vel']):
    O.bodies[i].state.vel = Vector3(*v)
verts = data['verts']
O.bodies.append([facet([Vector3(*verts[a]), Vector3(*verts[b]), Vector3(*verts[c])],
                       material=m, wire=False) for a, b, c in data['faces']])
h = data['side'] / 2
O.bodies.append([wall((-h, 0, 0), axis=0, material=m), wall((h, 0, 0), axis=0, material=m),
                 wall((0, -h, 0), axis=1, material=m), wall((0, h, 0), axis=1, material=m)])
rows = []
gone = [0.0, 0]
def outlet():
    out = [b for b in O.bodies if isinstance(b.shape, Sphere) and b.state.pos[2] < data['zout']]
    for b in out:
        gone[0] += b.state.mass
        gone[1] += 1
        O.bodies.erase(b.id)
    rows.append([O.time, gone[0], gone[1]])
O.engines = [ForceResetter(),
             InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Facet_Aabb(), Bo1_Wall_Aabb()]),
             InteractionLoop([Ig2_Sphere_Sphere_ScGeom(), Ig2_Facet_Sphere_ScGeom(),
                              Ig2_Wall_Sphere_ScGeom()],
                             [Ip2_ViscElMat_ViscElMat_ViscElPhys()],
                             [Law2_ScGeom_ViscElPhys_Basic()]),
             NewtonIntegrator(damping=0, gravity=(0, 0, -9.81)),
             PyRunner(command='outlet()', virtPeriod=data['every'])]
O.dt = data['dt']
t0, c0 = time.perf_counter(), time.process_time()
O.run(int(round(data['T'] / data['dt'])), True)
wall_t, cpu = time.perf_counter() - t0, time.process_time() - c0
print('YADE-RESULT ' + json.dumps(dict(wall=wall_t, cpu=cpu, rows=rows)))
"""


def run_yade(pos, shape, vel, side: float, D: float, T: float, dt: float, work: Path
             ) -> dict | str:
    """Yade's discharge of the same bed through the same floor (:data:`YADE_RUN`): its time
    loop and steady rate as :func:`steady_rate` gives them; or why it could not run."""
    import trimesh
    floor = trimesh.load(work / "floor.stl", process=False)
    res = run_yade_script(YADE_RUN, dict(
        pos=pos.tolist(), rad=np.asarray(RADII)[shape - 1].tolist(), vel=vel.tolist(),
        verts=np.asarray(floor.vertices).tolist(), faces=np.asarray(floor.faces).tolist(),
        side=side, kn=KN, cn=damping(), kt=KN, mu=MU, rho=DENSITY, T=T, dt=dt, every=EVERY,
        zout=-4.0 * D_GRAIN), work, timeout=7200)
    if isinstance(res, str):
        return res
    rows = np.array(res.pop("rows"), float).reshape(-1, 3)
    csv = work / "yade_outlet.csv"
    np.savetxt(csv, rows, delimiter=",", header="time,mass,count", comments="")
    res.update(steady_rate(csv, T))
    return res


def in_range(key: str, value: float) -> bool:
    lo, hi = RANGES[key]
    return lo <= value <= hi


def _c_mid(W: float, D: float, rho_b: float) -> float:
    """The C of a rate W at n 2.5 and k 1.5."""
    return W / (rho_b * math.sqrt(G) * max(D - 1.5 * D_GRAIN, 1e-12) ** 2.5)


def _split(res: dict) -> str:
    """The time loop's parts (s) of a run: search, contact solves, forces + integration
    (and of those the time-step control), inlet and outlet exchanges."""
    tm, sp = res["timers"], res["split"]
    return (f"search {tm['global search']:.1f}, contacts {tm['LCP']:.1f}, forces + integration "
            f"{tm['forces + integration']:.1f} (time-step control "
            f"{sp.get('time-step control', 0.0):.1f}), exchanges {res['flow']:.1f}")


def _fill(work: Path, side: float, height: float, count: int, shape: str = "sphere") -> dict:
    """Run the fill; write the settled bed to ``work/bed.npz``; its numbers."""
    d = D_GRAIN
    deck, T_fill = fill_deck(side, height, count, shape)
    fill = run_nurbsdem(deck, work, "fill", shape=shape)
    end = fill.pop("end")
    keep = end["position"][:, 2] > 0.0          # all of them: the floor is closed
    bed = {k: v[keep] for k, v in end.items()}
    np.savez(work / "bed.npz", **bed)
    rho_b, top = bulk_density(bed["position"], bed["shape"], side)
    inl = np.genfromtxt(fill.pop("out") / "monitors" / "inlet_feed.csv", delimiter=",",
                        names=True)
    n = int(keep.sum())
    speed = np.linalg.norm(bed["velocity"], axis=1)
    res = dict(loop=fill["loop"], flow=fill["flow"], substeps=fill["substeps"], T=T_fill,
               inserted=int(np.atleast_1d(inl["inserted"])[-1]),
               waiting=int(np.atleast_1d(inl["waiting"])[-1]), count=n, rho_b=rho_b,
               top=top, timers=fill["timers"], split=fill["split"],
               speed_max=float(speed.max()), speed_mean=float(speed.mean()),
               per_particle_step=fill["loop"] / (n * fill["substeps"]))
    grains = "spheres" if shape == "sphere" else f"{shape} grains (volume-equivalent"
    print(f"fill: {n} {grains} (d {d * 1e3:.1f} mm, radii "
          f"{', '.join(f'{r * 1e3:.1f}' for r in RADII)} mm{'' if shape == 'sphere' else ')'}) "
          f"poured into a silo "
          f"{side * 1e3:.0f} mm square in {T_fill:.2f} s: bed {top * 1e3:.1f} mm "
          f"({top / d:.1f} d) high, bulk density {rho_b:.0f} kg/m^3 (solid fraction "
          f"{rho_b / DENSITY:.3f}); {res['waiting']} still waiting at the inlet, speeds at the "
          f"end {res['speed_mean']:.2g} m/s mean, {res['speed_max']:.2g} m/s at most; "
          f"time loop {fill['loop']:.1f} s ({_split(fill)}), inlet "
          f"{100 * fill['flow'] / fill['loop']:.1f} % of it; {fill['substeps']} internal "
          f"steps (mean {T_fill / fill['substeps']:.3g} s)")
    return res


def _discharge(work: Path, side: float, ratio: float, T: float, fill: dict,
               shape: str = "sphere") -> dict:
    """Run the discharge through the orifice ``ratio`` d from the bed of :func:`_fill`."""
    d = D_GRAIN
    D = ratio * d
    write_floor(work / "floor.stl", side, D)
    res = run_nurbsdem(discharge_deck(fill["top"], side, T, shape), work, f"D{ratio:g}",
                       work / "bed.npz", shape)
    left = res.pop("end")
    rate = steady_rate(res.pop("out") / "monitors" / "outlet_below.csv", T)
    inside = left["position"][:, 2] > 0
    _, top_end = bulk_density(left["position"][inside], left["shape"][inside], side)
    row = dict(D=D, ratio=ratio, loop=res["loop"], cpu=res["cpu"], flow=res["flow"],
               substeps=res["substeps"],
               dt=T / res["substeps"], top_end=top_end, timers=res["timers"],
               split=res["split"], C_mid=_c_mid(rate["W"], D, fill["rho_b"]),
               per_particle_step=res["loop"] / (fill["count"] * res["substeps"]), **rate)
    print(f"D = {ratio:g} d (silo {side / D:.2f} D wide): W = {rate['W']:.4f} kg/s (window "
          f"halves {rate['halves'][0]:.4f}, {rate['halves'][1]:.4f}), {rate['count']} grains "
          f"out, bed left {top_end / d:.1f} d high; C at n 2.5, k 1.5: {row['C_mid']:.3f}; "
          f"time loop {res['loop']:.1f} s ({_split(res)}; outlet "
          f"{100 * res['flow'] / res['loop']:.1f} %), {res['substeps']} internal steps, "
          f"{1e6 * row['per_particle_step']:.2f} us per particle-step")
    return row


def _fit(out: dict) -> None:
    """Beverloo's fits over the orifices of ``out``, printed: the free fit (n, k, C with
    their standard errors, into ``out["fit"]``) and the fit of k and C at n 2.5
    (``out["fit_n25"]``), which a narrow range of D determines much better."""
    rows = out["orifices"]
    out["fit"] = out["fit_n25"] = None
    if len(rows) < 3:
        print(f"Beverloo fit: needs three orifices ({len(rows)} run)")
        return
    D, W = [r["D"] for r in rows], [r["W"] for r in rows]
    rho_b = out["fill"]["rho_b"]
    try:
        fit = fit_beverloo(D, W, out["d"], rho_b, G)
        fixed = fit_beverloo(D, W, out["d"], rho_b, G, n=2.5)
    except (ValueError, RuntimeError) as exc:
        print(f"Beverloo fit failed: {exc}")
        return
    for key, f in (("fit", fit), ("fit_n25", fixed)):
        out[key] = dict(n=f.n, k=f.k, C=f.C, rms=f.rms, sd_n=f.sd_n, sd_k=f.sd_k, sd_C=f.sd_C,
                        inside={k: in_range(k, getattr(f, k)) for k in RANGES})
    ratios = ", ".join(f"{r['ratio']:g}" for r in rows)
    for key, f, what in (("fit", fit, "Beverloo fit"), ("fit_n25", fixed, "at n = 2.5")):
        keys = RANGES if key == "fit" else ("k", "C")
        print(f"{what} over D/d = {ratios}: "
              + ", ".join(f"{k} {getattr(f, k):.3f} ± {getattr(f, 'sd_' + k):.2g} "
                          f"({'inside' if out[key]['inside'][k] else 'OUTSIDE'} "
                          f"{RANGES[k][0]}-{RANGES[k][1]})" for k in keys)
              + f", RMS of W {f.rms:.2%}")


def _yade_row(out: dict) -> dict:
    """The orifice row of the run's Yade comparison (``out["yade_at"]``)."""
    return next(r for r in out["orifices"] if r["ratio"] == out["yade_at"])


def _costs(out: dict) -> None:
    """The inlet and outlet share and the ratio to Yade, into ``out``, printed."""
    rows = out["orifices"]
    flow = sum(r["flow"] for r in rows) + out["fill"]["flow"]
    loop = sum(r["loop"] for r in rows) + out["fill"]["loop"]
    out["flow_share"] = flow / loop
    print(f"inlet + outlet exchanges: {flow:.2f} s of {loop:.1f} s of time loop "
          f"({100 * flow / loop:.1f} %; target at most 5 %)")
    y = out["yade"]
    if isinstance(y, str):
        print(y)
        return
    n0 = _yade_row(out)
    dt_yade = n0["dt"]
    out["ratio"] = n0["loop"] / y["wall"]
    y["per_particle_step"] = y["wall"] / (out["fill"]["count"] * out["T"] / dt_yade)
    print(f"Yade, D = {n0['ratio']:g} d at dt {dt_yade:.3g} s: time loop {y['wall']:.1f} s "
          f"({1e6 * y['per_particle_step']:.2f} us per particle-step), W = {y['W']:.4f} kg/s "
          f"(window halves {y['halves'][0]:.4f}, {y['halves'][1]:.4f}); nurbsdem / Yade time "
          f"{out['ratio']:.2f} (target at most 2); rates differ by "
          f"{100 * (n0['W'] / y['W'] - 1):+.1f} %")
    out["cpu_ratio"] = n0["cpu"] / y["cpu"]
    print(f"CPU time (the machine may be shared): nurbsdem's whole run {n0['cpu']:.1f} s "
          f"(set-up and output included), Yade's time loop {y['cpu']:.1f} s: ratio "
          f"{out['cpu_ratio']:.2f}")


def refit(path: Path) -> dict:
    """The fits of :func:`_fit` again on the rates of the JSON ``path`` a run wrote, which
    gets them."""
    out = json.loads(path.read_text())
    _fit(out)
    path.write_text(json.dumps(out, indent=1, default=float))
    return out


def _merge_seed(runs: list[tuple[Path, dict]]) -> dict:
    """One fill's run (the JSON of the default orifices) with the rates of its other runs
    (``--orifices``, ``--discharge``: the same seed) joined in, sorted by orifice, each
    orifice's rate from its longest discharge (the widest fit window; its time in the
    orifice's ``T``); refused unless every run poured the same bed (count and bulk density
    equal)."""
    (p0, base), rest = runs[0], runs[1:]
    merged = dict(base, orifices=[dict(o, T=base["T"]) for o in base["orifices"]])
    for p, r in rest:
        if (r["fill"]["count"] != base["fill"]["count"]
                or abs(r["fill"]["rho_b"] - base["fill"]["rho_b"]) > 1e-9 * base["fill"]["rho_b"]):
            raise SystemExit(f"--combine: {p} has seed {r.get('seed', 3)} as {p0} has, but "
                             "not the same fill")
        have = {o["ratio"]: i for i, o in enumerate(merged["orifices"])}
        for o in r["orifices"]:
            i = have.get(o["ratio"])
            if i is None:
                merged["orifices"].append(dict(o, T=r["T"]))
            elif r["T"] > merged["orifices"][i]["T"]:
                merged["orifices"][i] = dict(o, T=r["T"])
    merged["orifices"].sort(key=lambda o: o["ratio"])
    if rest:
        _fit(merged)
    return merged


def _fits_from(out: dict, smallest: float) -> None:
    """The fits of :func:`_fit` over the orifices of ``out`` of at least ``smallest`` d,
    into ``out["fit_from"]`` and ``out["fit_n25_from"]`` (with ``out["from"]``); none with
    fewer than four such orifices (three parameters need a spare one)."""
    keep = [o for o in out["orifices"] if o["ratio"] >= smallest - 1e-9]
    out["from"], out["fit_from"], out["fit_n25_from"] = smallest, None, None
    if len(keep) < 4 or len(keep) == len(out["orifices"]):
        return
    part = dict(out, orifices=keep)
    _fit(part)
    out["fit_from"], out["fit_n25_from"] = part["fit"], part["fit_n25"]


def bootstrap_exponent(W_fills: np.ndarray, D: list[float], d: float, rho_b: float,
                       draws: int = BOOT_DRAWS, seed: int = 1) -> dict | None:
    """The free Beverloo exponent's spread from fill to fill: ``draws`` resamples of the
    fills (rows of ``W_fills`` (F, orifices) kg/s, drawn with replacement), each fitted on
    its mean rates; the 16th, 50th and 84th percentiles of the exponent and the share of the
    draws inside the published range (fits that fail are left out).  None with fewer than
    three fills."""
    W_fills = np.asarray(W_fills, float)
    F = W_fills.shape[0]
    if F < 3:
        return None
    rng = np.random.default_rng(seed)
    ns = []
    for _ in range(draws):
        W = W_fills[rng.integers(0, F, F)].mean(axis=0)
        try:
            ns.append(fit_beverloo(D, W, d, rho_b, G).n)
        except (ValueError, RuntimeError):
            continue
    ns = np.array(ns)
    lo, hi = RANGES["n"]
    p16, p50, p84 = (float(np.percentile(ns, q)) for q in (16, 50, 84))
    return dict(draws=int(ns.size), p16=p16, p50=p50, p84=p84,
                inside=float(np.mean((ns >= lo) & (ns <= hi))))


def combine(paths: list[Path], json_path: Path | None = None) -> dict:
    """Beverloo's fits on the rates of several fills (runs with ``--seed``, and runs of the
    same seeds with ``--orifices``; their JSONs at ``paths``): per orifice the mean rate over
    the fills and its standard error; the fits of :func:`_fit` on the mean rates with the
    fills' mean bulk density, over all orifices and over those of at least :data:`FIT_FROM`
    d (:func:`_fits_from`); and each fill's own free exponent (their spread is the
    fill-to-fill scatter of the fit).  Written to ``json_path`` (default
    ``benchmarks/.cache/beverloo_fills.json``, which ``benchmarks/report.py`` reads) and
    returned."""
    by_seed: dict[int, list] = {}
    for p in paths:
        r = json.loads(p.read_text())
        by_seed.setdefault(r.get("seed", 3), []).append((p, r))
    runs = [_merge_seed(sorted(v, key=lambda pr: -len(pr[1]["orifices"])))
            for _, v in sorted(by_seed.items())]
    ratios = [o["ratio"] for o in runs[0]["orifices"]]
    for r in runs:
        if [o["ratio"] for o in r["orifices"]] != ratios:
            raise SystemExit(f"--combine: the fill of seed {r.get('seed', 3)} has other "
                             "orifices than the first")
    rows = []
    for i, ratio in enumerate(ratios):
        W = np.array([r["orifices"][i]["W"] for r in runs])
        sem = float(W.std(ddof=1) / math.sqrt(len(W))) if len(W) > 1 else float("nan")
        rows.append(dict(ratio=ratio, D=runs[0]["orifices"][i]["D"], W=float(W.mean()),
                         W_fills=W.tolist(), sem=sem,
                         T_fills=[r["orifices"][i]["T"] for r in runs]))
        print(f"D = {ratio:g} d: W = {W.mean():.4f} ± {sem:.4f} kg/s over {len(W)} fills "
              f"({', '.join(f'{w:.4f}' for w in W)})")
    rho = [r["fill"]["rho_b"] for r in runs]
    out = dict(seeds=[r.get("seed", 3) for r in runs], d=runs[0]["d"], T=runs[0]["T"],
               fill_height=runs[0]["fill"]["top"], orifices=rows, rho_b_fills=rho,
               fill=dict(rho_b=float(np.mean(rho))),
               n_fills=[r["fit"]["n"] if r.get("fit") else None for r in runs])
    _fit(out)
    print("each fill's free exponent: " + ", ".join(
        "-" if n is None else f"{n:.2f}" for n in out["n_fills"]))
    out["bootstrap"] = bootstrap_exponent(np.array([o["W_fills"] for o in rows]).T,
                                          [o["D"] for o in rows], out["d"],
                                          out["fill"]["rho_b"])
    if out["bootstrap"]:
        b = out["bootstrap"]
        print(f"the free exponent over {b['draws']} resamples of the fills: {b['p16']:.2f} to "
              f"{b['p84']:.2f} (16th to 84th percentile), {100 * b['inside']:.0f} % of them "
              f"inside {RANGES['n'][0]}-{RANGES['n'][1]}")
    _fits_from(out, FIT_FROM)
    if out["fit_from"]:
        print(f"(the fits over the orifices of at least {FIT_FROM:g} d)")
    path = json_path or ROOT / "benchmarks" / ".cache" / "beverloo_fills.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=1, default=float))
    return out


def _orifices_option(argv: list[str], side: float) -> list[float]:
    """The orifices (in d) of ``--orifices R...`` (the numbers after it), each at most the
    default silo's 2.5 D wide; [] without the option.  A run of other orifices pours the same
    fill of its seed (the inlet and the solver are deterministic), so that ``--combine``
    joins its rates to those of the default run of that seed."""
    if "--orifices" not in argv:
        return []
    ratios = []
    for a in argv[argv.index("--orifices") + 1:]:
        try:
            ratios.append(float(a))
        except ValueError:
            break
    if not ratios:
        raise SystemExit("--orifices: give the orifice diameters in grain diameters d")
    wide = side / (2.5 * D_GRAIN)
    for r in ratios:
        if not 6.0 <= r <= wide:
            raise SystemExit(f"--orifices: {r:g} d is outside 6 to {wide:g} d (the silo is "
                             f"{side * 1e3:.0f} mm wide, at least 2.5 D)")
    return ratios


def _discharge_option(argv: list[str], T: float) -> float:
    """The discharge time (s) of ``--discharge S`` (else ``T``, the configuration's): a longer
    discharge of the same fill widens the fit window (the same fractions of the run left out)
    and so narrows the rate of an intermittent small orifice; refused below 0.2 s (the window
    would hold the start-up) or where the bed would fall below the largest orifice."""
    if "--discharge" not in argv:
        return T
    try:
        S = float(argv[argv.index("--discharge") + 1])
    except (IndexError, ValueError):
        raise SystemExit("--discharge: give the discharge time in seconds") from None
    if not 0.2 <= S <= MAX_DISCHARGE:
        raise SystemExit(f"--discharge: {S:g} s is outside 0.2 to {MAX_DISCHARGE:g} s (the bed "
                         "of the 24 d fill stays above 1 D through 15 d up to then)")
    return S


def _yade_option(argv: list[str], ratios: list[float], shape: str, extra: bool
                 ) -> float | None:
    """The orifice (in d) of the run's Yade comparison: ``--yade-at R`` (one of the run's
    orifices), else the smallest orifice of the default spheres' run of seed 3; None for no
    Yade run."""
    if "--yade-at" in argv:
        at = float(argv[argv.index("--yade-at") + 1])
        if at not in ratios or shape != "sphere":
            raise SystemExit(f"--yade-at: {at:g} d is not an orifice of this run of spheres")
        return at
    return ratios[0] if shape == "sphere" and SEED == 3 and not extra else None


def main(argv: list[str]) -> dict:
    if "--refit" in argv:
        return refit(Path(argv[argv.index("--refit") + 1]))
    if "--combine" in argv:
        rest = argv[argv.index("--combine") + 1:]
        json_path = Path(rest[rest.index("--json") + 1]) if "--json" in rest else None
        return combine([Path(a) for a in rest if a != "--json" and Path(a) != json_path],
                       json_path)
    quick = "--quick" in argv
    shape = argv[argv.index("--shape") + 1] if "--shape" in argv else "sphere"
    _shape_lines(shape)                         # an unknown shape: refused before any run
    global SEED
    SEED = int(argv[argv.index("--seed") + 1]) if "--seed" in argv else SEED
    cfg = dict(QUICK if quick else FULL if shape == "sphere" else SHAPED)
    d = D_GRAIN
    side = 2.5 * max(cfg["orifices"]) * d      # the silo of the default orifices
    extra = _orifices_option(argv, side)
    if extra:
        cfg["orifices"] = extra
    cfg["discharge"] = _discharge_option(argv, cfg["discharge"])
    longer = cfg["discharge"] != (QUICK if quick else FULL if shape == "sphere" else SHAPED)[
        "discharge"]
    name = ("beverloo" + ("" if shape == "sphere" else f"_{shape}") + ("_quick" if quick else "")
            + ("" if SEED == 3 else f"_seed{SEED}")
            + ("" if not extra else "_D" + "-".join(f"{r:g}" for r in extra))
            + (f"_T{cfg['discharge']:g}" if longer else ""))
    json_path = Path(argv[argv.index("--json") + 1]) if "--json" in argv else (
        ROOT / "benchmarks" / ".cache" / f"{name}.json")
    count = fill_count(side, cfg["fill"] * d)
    T = cfg["discharge"]
    out: dict = dict(quick=quick, shape=shape, seed=SEED, d=d, side=side, count=count,
                     radii=RADII, kn=KN,
                     cn=damping(), mu=MU, safety=SAFETY, T=T, lead=LEAD, tail=TAIL,
                     orifices=[])
    at = _yade_option(argv, cfg["orifices"], shape, bool(extra))
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        if shape == "paper":
            write_paper_shapes(work)
        out["fill"] = _fill(work, side, cfg["fill"] * d, count, shape)
        for ratio in cfg["orifices"]:
            out["orifices"].append(_discharge(work, side, ratio, T, out["fill"], shape))
        if at is not None:                     # Yade's step: nurbsdem's mean step there
            out["yade_at"] = at
            bed = np.load(work / "bed.npz")
            write_floor(work / "floor.stl", side, at * d)
            out["yade"] = run_yade(bed["position"], bed["shape"], bed["velocity"], side,
                                   at * d, T, _yade_row(out)["dt"], work)
        elif extra:
            out["yade"] = "Yade is compared on the default orifices only (or --yade-at R)"
        elif shape == "sphere":
            out["yade"] = f"Yade is compared on the fill of seed 3 only (this is seed {SEED})"
        else:
            out["yade"] = (f"Yade is not compared for {shape} grains: it has no exact "
                           f"ellipsoids or NURBS particles")
    out["wall"] = time.perf_counter() - t0
    _fit(out)
    _costs(out)
    json_path.parent.mkdir(parents=True, exist_ok=True)
    json_path.write_text(json.dumps(out, indent=1, default=float))
    return out


if __name__ == "__main__":
    main(sys.argv[1:])

"""Hertz–Mindlin with the exact local curvature: what the exact curvature changes,
what it costs, and the benchmark impacts.

    .venv/bin/python benchmarks/bench_hertz.py [--quick]

1. Equivalent radius: for sampled contact points over the surface of ellipsoids and the paper
   particles, the exact force-equivalent Hertz radius (both surfaces' principal curvatures and
   directions, :mod:`nurbsdem.geometry.curvature`) against a flat wall and against a randomly
   turned copy of the same shape, and the force error of the volume-equivalent-radius
   approximation at equal overlap: F ∝ √R, so the error is √(R_v / R) − 1 (R_v = (3V/4π)^{1/3}
   against a wall, R_v / 2 for a pair).
2. Cost of the curvature per contact (compiled, one thread).
3. Chung & Ooi (2011) test 4: tangential restitution, spin and contact-point rebound angle of
   an aluminium-oxide sphere on a rigid plane at 3.9 m/s, 5–85°, against rigid-body sliding
   theory where the sphere slides throughout (θ > atan 7μ).
4. The same impact on a glass anvil (MFIX's DEM-05 verification case, Kharaz et al.'s
   experiment): e_t against MFIX's published curve and the measurements.
5. A pack of paper particles deposited under Hertz–Mindlin (E 1e8 Pa): the compiled deck
   steps against the Python path, their reference (``compiled_steps``
   off), wall time of each and whether every result is the same bit for bit.
"""
from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import REPO  # noqa: E402

from nurbsdem import load_shape, shapes  # noqa: E402
from nurbsdem.contact.detect import ContactTable  # noqa: E402
from nurbsdem.geometry.curvature import KIND_FLAT, KIND_PATCH, equivalent_radii  # noqa: E402


def surface_samples(shape, n: int):
    """(patch (S,), uv (S,2), points (S,3), outward normals (S,3)) on an n × n grid per patch
    (cell centres, so no sample sits on a patch edge or pole)."""
    pids, uvs, pts, nrm = [], [], [], []
    for ip, p in enumerate(shape.patches):
        u0, u1, v0, v1 = p.domain
        s = (np.arange(n) + 0.5) / n
        U, V = np.meshgrid(u0 + s * (u1 - u0), v0 + s * (v1 - v0), indexing="ij")
        U, V = U.ravel(), V.ravel()
        x = np.asarray(p.points(U, V), float).reshape(-1, 3)
        nn = np.asarray(p.normals(U, V), float).reshape(-1, 3)
        out = np.sign(np.einsum("ij,ij->i", x - shape.centroid, nn))[:, None]
        pids.append(np.full(U.size, ip))
        uvs.append(np.column_stack([U, V]))
        pts.append(x)
        nrm.append(nn * out)
    return (np.concatenate(pids), np.concatenate(uvs), np.concatenate(pts),
            np.concatenate(nrm))


def _align(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """A rotation taking unit vector a to unit vector b."""
    v = np.cross(a, b)
    c = float(a @ b)
    if c < -1 + 1e-12:
        p = np.cross(a, [1.0, 0, 0] if abs(a[0]) < 0.9 else [0, 1.0, 0])
        p /= np.linalg.norm(p)
        return 2 * np.outer(p, p) - np.eye(3)
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1 + c)


def wall_radii(shape, n: int):
    """Exact equivalent radius (S,) of the shape resting on a flat wall at each sample, and the
    status (S,) (1: degenerate curvature, bounding-sphere fallback)."""
    table = ContactTable([shape])
    pid, uv, _, nrm = surface_samples(shape, n)
    S = pid.size
    eye = np.broadcast_to(np.eye(3), (S, 3, 3)).copy()
    r, _, _, st = equivalent_radii(
        table, np.column_stack([np.zeros(S, np.int64), -np.ones(S, np.int64)]),
        np.full(S, KIND_PATCH), np.full(S, KIND_FLAT), pid, np.zeros(S, np.int64),
        np.column_stack([uv, np.zeros((S, 2))]), eye, eye, np.ones(S), np.ones(S), nrm,
        np.full(S, shape.bounding_radius), np.zeros(S, np.int64))
    return r, st


def pair_radii(shape, n: int, seed: int = 0, timing: list | None = None):
    """Exact equivalent radius of two copies of the shape touching at random sample points,
    B turned so that its normal opposes A's and spun randomly about it; and the status."""
    table = ContactTable([shape])
    pid, uv, _, nrm = surface_samples(shape, n)
    S = pid.size
    rng = np.random.default_rng(seed)
    j = rng.permutation(S)
    rot_b = np.empty((S, 3, 3))
    for k in range(S):
        R = _align(nrm[j[k]], -nrm[k])
        th = rng.uniform(0, 2 * np.pi)
        ax = nrm[k]
        K = np.array([[0, -ax[2], ax[1]], [ax[2], 0, -ax[0]], [-ax[1], ax[0], 0]])
        spin = np.eye(3) + math.sin(th) * K + (1 - math.cos(th)) * K @ K
        rot_b[k] = spin @ R
    eye = np.broadcast_to(np.eye(3), (S, 3, 3)).copy()
    t0 = time.perf_counter()
    r, _, _, st = equivalent_radii(
        table, np.zeros((S, 2), np.int64), np.full(S, KIND_PATCH), np.full(S, KIND_PATCH),
        pid, pid[j], np.column_stack([uv, uv[j]]), eye, rot_b, np.ones(S), np.ones(S), nrm,
        np.full(S, shape.bounding_radius / 2), np.zeros(S, np.int64))
    if timing is not None:
        timing.append(time.perf_counter() - t0)
    return r, st


def test_shapes(quick: bool) -> list[tuple[str, object]]:
    out = [("sphere r 10 mm", shapes.sphere(0.01)),
           ("ellipsoid 20×15×10 mm", shapes.ellipsoid(0.02, 0.015, 0.01)),
           ("ellipsoid 30×10×10 mm", shapes.ellipsoid(0.03, 0.01, 0.01))]
    for name in ("A", "B", "C"):
        p = REPO / "inputs" / "shapes" / f"{name}.yaml"
        if p.is_file():
            out.append((f"paper particle {name}", load_shape(p)))
    return out


def radius_table(quick: bool) -> list[dict]:
    """Section 1 rows: per shape and contact kind, the exact radius against R_v and the force
    error √(R_v/R) − 1 of the volume-equivalent radius at equal overlap."""
    n = 6 if quick else 16
    rows = []
    for name, sh in test_shapes(quick):
        rv = (3 * sh.volume / (4 * math.pi)) ** (1 / 3)
        for kind, fn, ref in (("wall", wall_radii, rv), ("pair", pair_radii, rv / 2)):
            r, st = fn(sh, n)
            ok = st == 0
            err = np.sqrt(ref / r[ok]) - 1.0
            rows.append(dict(shape=name, kind=kind, samples=int(r.size), fallback=int((~ok).sum()),
                             r_v=ref, r_min=float(r[ok].min()), r_med=float(np.median(r[ok])),
                             r_max=float(r[ok].max()), err_med=float(np.median(np.abs(err))),
                             err_lo=float(err.min()), err_hi=float(err.max())))
    return rows


def curvature_cost(n_contacts: int = 20000) -> float:
    """µs per contact of the compiled curvature + elliptic radius (paper particle pairs)."""
    p = REPO / "inputs" / "shapes" / "A.yaml"
    sh = load_shape(p) if p.is_file() else shapes.ellipsoid(0.02, 0.015, 0.01)
    pair_radii(sh, 2)                    # compile
    n = int(math.sqrt(n_contacts / len(sh.patches))) + 1
    t: list = []
    r, _ = pair_radii(sh, n, timing=t)
    return 1e6 * t[0] / r.size


def oblique_test4(angles) -> list[dict]:
    """Chung & Ooi (2011) test 4 with the Hertz–Mindlin law (see tests/test_hertz.py)."""
    sys.path.insert(0, str(REPO / "tests"))
    from test_hertz import _oblique
    out = []
    for a in angles:
        o = _oblique(float(a))
        mu, vt, vn = o["mu"], o["vt"], o["vn"]
        slide = math.tan(math.radians(a)) > 7 * mu
        out.append(dict(angle=a, et=o["et"], omega=o["omega"], rebound=o["rebound"],
                        et_slide=1 - 2 * mu * vn / vt if slide else math.nan,
                        omega_slide=5 * mu * vn / o["r"] if slide else math.nan,
                        rebound_slide=(math.degrees(math.atan((vt - 7 * mu * vn) / vn))
                                       if slide else math.nan)))
    return out


#: MFIX DEM-05 tangential restitution (incidence °, e_t): Al-oxide sphere on soda-lime glass
#: (Kharaz et al. 2001), MFIX verification manual (values as digitised in Lethe's
#: oblique-wall-impact example); and Kharaz et al.'s measurements
MFIX_DEM05 = [(3.203, 0.965), (4.522, 0.94), (6.12, 0.869), (8.49, 0.7507), (12.183, 0.657),
              (19.777, 0.617), (30.416, 0.687), (39.107, 0.7773), (49.977, 0.844),
              (60.747, 0.897)]
KHARAZ_2001 = [(1.84, 0.79344), (3.703, 0.74533), (9.496, 0.67257), (20.012, 0.59691),
               (30.127, 0.68756), (39.382, 0.77148), (49.694, 0.84761), (60.02, 0.90142)]


def glass_anvil(angles) -> list[float]:
    """e_t of the MFIX DEM-05 / Kharaz set-up (E* of Al oxide on glass, e 0.98, μ 0.092)."""
    sys.path.insert(0, str(REPO / "tests"))
    from test_hertz import _law, _run_impact, _sphere_system
    from nurbsdem.dynamics.laws.hertz_mindlin import hertz_impact
    r, rho, E, nu, mu, v = 2.5e-3, 4000.0, 3.8e11, 0.23, 0.092, 3.9
    m = rho * 4 / 3 * math.pi * r ** 3
    out = []
    for a in angles:
        law = _law(E, nu, 0.98, mu=mu, E_b=7e10, nu_b=0.25, r=r, m=m, v=v)
        th = hertz_impact(law.e_star, r, m, v * math.cos(math.radians(a)))
        s, _ = _sphere_system(law, r, rho, v, th["duration"] / 400, wall=True, angle=a)
        _run_impact(s, 2000)
        out.append(float(s.bodies.v[0, 0] / (v * math.sin(math.radians(a)))))
    return out


def hertz_pack_deck(n: int, duration: float, out: Path) -> str:
    """Deck text: n paper particles (A, B, C) released in the region of
    :func:`bench_settled_pack.pack_region` onto the floor of a box, Hertz–Mindlin with
    E = 1e8 Pa, ν 0.3, restitution 0.5, friction 0.5, for ``duration`` s of 1e-3 s steps."""
    from bench_settled_pack import pack_region
    from decks import paper_mix_deck
    side, height = pack_region(n)
    text = paper_mix_deck(n, (side, side, height), 2 * height, [duration], out,
                          monitors_every=0.01)
    return text.replace(
        "Material 1 Density 2700", "Material 1 Density 2700 YoungModulus 1e8 PoissonRatio 0.3"
    ).replace("Interface 1 NormalPenalty 1e5 TangentialPenalty 1e4 NormalDamping 1e2 "
              "TangentialDamping 0 Friction 0.5",
              "Interface 1 Model HertzMindlin Restitution 0.5 Friction 0.5")


def pack_paths(n: int = 60, duration: float = 0.3) -> dict:
    """:func:`hertz_pack_deck` solved by the Python path and by the compiled deck steps (one
    untimed run of each first: numba's cache): wall times (s), internal steps, LCPs, active
    contacts at most, and whether the results (every sample of results.h5, the monitors with
    ``hertz.csv``) are equal bit for bit."""
    import tempfile
    from nurbsdem.io.deck import parse_deck
    from nurbsdem.io.results import read_results_sample, read_results_times
    from nurbsdem.solver import Solver
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for compiled in (False, True, False, True):
            o = Path(tmp) / ("compiled" if compiled else "python")
            deck = Path(tmp) / "hertz_pack.inp"
            deck.write_text(hertz_pack_deck(n, duration, o))
            t0 = time.perf_counter()
            s = Solver(parse_deck(deck), quiet=True, compiled_steps=compiled).run()
            out[compiled] = (time.perf_counter() - t0, s, o)
        (t_py, s_py, o_py), (t_cc, s_cc, o_cc) = out[False], out[True]
        times = read_results_times(o_py / "results.h5")
        same = bool(np.array_equal(times, read_results_times(o_cc / "results.h5")))
        for k in range(len(times)):
            a, b = (read_results_sample(o / "results.h5", k) for o in (o_py, o_cc))
            same = same and all(np.array_equal(a[key], b[key]) for key in a)
        for name in ("energy.csv", "contacts.csv", "hertz.csv"):
            same = same and ((o_py / "monitors" / name).read_bytes()
                             == (o_cc / "monitors" / name).read_bytes())
    return dict(n=n, duration=duration, python_s=t_py, compiled_s=t_cc, same=same,
                substeps=s_cc.substeps, lcps=s_cc.lcps, active_max=s_cc.active_max,
                failed=s_cc.failed)


def main(argv=None) -> int:
    quick = "--quick" in (argv if argv is not None else sys.argv[1:])
    print("1. equivalent radius: exact curvature vs volume-equivalent radius (force error at "
          "equal overlap = sqrt(R_v/R) - 1)")
    for r in radius_table(quick):
        print(f"  {r['shape']:24s} {r['kind']:4s} n={r['samples']:5d} fallback={r['fallback']:3d} "
              f"R_v={r['r_v']:.4g} R exact {r['r_min']:.4g}..{r['r_med']:.4g}..{r['r_max']:.4g} m; "
              f"error median {100 * r['err_med']:.1f} %, range {100 * r['err_lo']:+.1f} .. "
              f"{100 * r['err_hi']:+.1f} %")
    print(f"2. curvature cost: {curvature_cost():.2f} us per contact (paper particle pairs)")
    print("3. Chung & Ooi test 4 (Al oxide, 3.9 m/s): angle, e_t, omega (rad/s), rebound (deg); "
          "sliding theory")
    for r in oblique_test4([5, 10, 20, 30, 40, 50, 60, 70, 80] if quick else range(5, 90, 5)):
        print(f"  {r['angle']:3.0f}  {r['et']:.4f} {r['omega']:8.1f} {r['rebound']:7.2f}   "
              f"{r['et_slide']:.4f} {r['omega_slide']:8.1f} {r['rebound_slide']:7.2f}")
    print("4. MFIX DEM-05 (Al oxide on glass, e 0.98): angle, e_t ours, MFIX; Kharaz et al. 2001")
    for (a, ref), et in zip(MFIX_DEM05, glass_anvil([a for a, _ in MFIX_DEM05])):
        print(f"  {a:6.2f}  {et:.4f}  {ref:.4f}")
    for (a, ref), et in zip(KHARAZ_2001, glass_anvil([a for a, _ in KHARAZ_2001])):
        print(f"  {a:6.2f}  {et:.4f}  measured {ref:.4f}")
    pk = pack_paths(30 if quick else 60)
    print(f"5. {pk['n']} paper particles deposited under Hertz-Mindlin for {pk['duration']} s: "
          f"Python path {pk['python_s']:.2f} s, compiled deck steps {pk['compiled_s']:.2f} s "
          f"({pk['python_s'] / pk['compiled_s']:.1f} x), results "
          f"{'bit for bit equal' if pk['same'] else 'NOT equal'}; {pk['substeps']} internal "
          f"steps, {pk['lcps']} LCPs, at most {pk['active_max']} contacts, {pk['failed']} failed")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

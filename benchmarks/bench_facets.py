"""Benchmark: polyhedral particles (GJK/EPA on tessellated hulls) vs exact NURBS contact.

Ellipsoid pairs (A: semi-axes 32.4 × 29.1 × 25.1 mm, roughly the paper's particle A; B: A
scaled by 0.8), both exact 6-patch NURBS ellipsoids, in random relative poses (random
orientations, random direction of B from A) with B's distance chosen so that the exact
penetration is 0.1–5 % of the size (log-uniform). Size L = 2 × 32.4 mm (A's long axis).

Exact reference: the support-function formula,
depth = min_{|d|=1} hA(d) + hB(−d) with h(d) = c·d + sqrt(dᵀ M d), dense start + SciPy
refine (:func:`nurbsdem.contact.reference.ellipsoid_pair`); B's distance is found by
``brentq`` on it.

For each tessellation level n (quads per parameter direction per patch; the polyhedron is
the convex hull of the tessellation points, inscribed in the exact surface):

* facets: triangular facets of A's hull; verts: its vertices;
* pen err/L: median |depth_poly − depth_exact| / L; p90 the 90th percentile; err/depth: the
  median of |depth_poly − depth_exact| / depth_exact (the error relative to the penetration,
  which is what the contact force sees);
* normal err: median angle (rad) between the polyhedral and exact normals;
* µs/query: median wall time per call of the Python API
  (:func:`polyhedral.polyhedral_contact`, hill-climbing supports);
  kernel µs: compiled loop over all poses (no Python overhead); brute µs: the same compiled
  loop with brute-force supports over all hull vertices.

If :func:`nurbsdem.contact.detect` imports and runs, NURBS rows are added: cold (no
previous result) and warm (``previous`` = the result of the same pair at a pose one
"time step" earlier: B moved by 1e-3 L and turned by 1e-3 rad); their kernel µs is the
compiled :func:`nurbsdem.contact.detect_batch` on one thread. The polyhedral query has no
warm start (each query starts from the centroid direction).

Run: ``.venv/bin/python benchmarks/bench_facets.py [--quick]``. No assertions; times
depend on the machine and its load.
"""
from __future__ import annotations

import sys
import time

import numpy as np
from scipy.optimize import brentq
from scipy.spatial.transform import Rotation

from polyhedral import Polyhedron, polyhedral_contact, polyhedral_contact_batch
from nurbsdem.contact.reference import ellipsoid_pair
from nurbsdem.geometry.generators import ellipsoid

AXES_A = (0.0324, 0.0291, 0.0251)  # m
AXES_B = tuple(0.8 * np.array(AXES_A))
SIZE = 2 * AXES_A[0]  # m
LEVELS = (2, 4, 8, 16, 32)


def make_poses(k: int, seed: int = 1):
    """k relative poses with exact penetration 0.1–5 % of SIZE.

    Returns a list of dicts: Ra, Rb (3, 3), pb (3,) m (A at the origin), ref =
    (signed_distance, normal, point_a, point_b) from the support-function reference."""
    rng = np.random.default_rng(seed)
    rots = Rotation.random(2 * k, random_state=seed).as_matrix()
    out = []
    for i in range(k):
        Ra, Rb = rots[2 * i], rots[2 * i + 1]
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        depth = SIZE * 10 ** rng.uniform(np.log10(1e-3), np.log10(5e-2))

        def f(s):
            return ellipsoid_pair(AXES_A, (np.zeros(3), Ra), AXES_B, (s * u, Rb))[0] + depth

        s = brentq(f, 0.0, AXES_A[0] + AXES_B[0] + depth, xtol=1e-15, rtol=1e-14)
        ref = ellipsoid_pair(AXES_A, (np.zeros(3), Ra), AXES_B, (s * u, Rb))
        out.append(dict(Ra=Ra, Rb=Rb, pb=s * u, ref=ref, depth=depth))
    return out


def _errors(sd: float, n: np.ndarray, ref) -> tuple[float, float, float]:
    """(|error| / SIZE, |error| / exact depth, normal angle error (rad))."""
    e = abs(sd - ref[0])
    ang = np.arctan2(np.linalg.norm(np.cross(n, ref[1])), float(n @ ref[1]))
    return e / SIZE, e / abs(ref[0]), float(ang)


def _time_call(fn, repeat: int) -> float:
    """Best-of-3 mean time (µs) of ``repeat`` calls."""
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        for _ in range(repeat):
            fn()
        best = min(best, (time.perf_counter() - t0) / repeat)
    return best * 1e6


def _row(method, n, facets, verts, errs, us, kernel_us=np.nan, brute_us=np.nan, its=np.nan):
    pen, rel, nrm = (np.asarray(e) for e in zip(*errs))
    return dict(method=method, n=n, facets=facets, vertices=verts,
                pen_err_median=float(np.median(pen)), pen_err_p90=float(np.percentile(pen, 90)),
                pen_err_rel_depth_median=float(np.median(rel)),
                normal_err_median=float(np.median(nrm)), us_median=float(us),
                kernel_us=float(kernel_us), brute_us=float(brute_us),
                iterations_median=float(its))


def _nurbs_kernel_us(shape_a, shape_b, poses, prevs, repeat: int) -> tuple[float, float]:
    """µs per query of the compiled NURBS batch (:func:`nurbsdem.contact.detect_batch`) on
    one thread (cold, warm from ``prevs``); NaN if unavailable."""
    try:
        import numba
        from nurbsdem.contact import ContactTable, detect_batch
    except ImportError:  # pragma: no cover
        return np.nan, np.nan
    K = len(poses)
    tab = ContactTable([shape_a, shape_b])
    sa, sb = np.zeros(K, np.int64), np.ones(K, np.int64)
    pa, Ra = np.zeros((K, 3)), np.array([p["Ra"] for p in poses])
    pb, Rb = np.array([p["pb"] for p in poses]), np.array([p["Rb"] for p in poses])
    pf = np.array([q.row_f for q in prevs])
    pi = np.array([q.row_i for q in prevs])
    nt = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        detect_batch(tab, sa, pa, Ra, sb, pb, Rb)  # JIT
        cold = _time_call(lambda: detect_batch(tab, sa, pa, Ra, sb, pb, Rb), repeat) / K
        warm = _time_call(lambda: detect_batch(tab, sa, pa, Ra, sb, pb, Rb, pf, pi), repeat) / K
    finally:
        numba.set_num_threads(nt)
    return cold, warm


def run(quick: bool = False) -> list[dict]:
    """Run the benchmark; returns one dict per row (see the module docstring for the keys:
    method, n, facets, vertices, pen_err_median / pen_err_p90 (relative to SIZE),
    pen_err_rel_depth_median (relative to the exact depth),
    normal_err_median (rad), us_median, kernel_us, brute_us (µs per query),
    iterations_median)."""
    K = 12 if quick else 50
    repeat = 3 if quick else 10
    poses = make_poses(K)
    shape_a, shape_b = ellipsoid(*AXES_A), ellipsoid(*AXES_B)
    I0 = np.zeros(3)
    rows = []
    for n in (LEVELS[:4] if quick else LEVELS):
        PA, PB = Polyhedron.from_shape(shape_a, n), Polyhedron.from_shape(shape_b, n)
        polyhedral_contact(PA, (I0, np.eye(3)), PB, (np.array([0.05, 0, 0]), np.eye(3)))  # JIT
        errs, us, its = [], [], []
        for p in poses:
            args = (PA, (I0, p["Ra"]), PB, (p["pb"], p["Rb"]))
            sd, nn, _, _, it = polyhedral_contact(*args)
            errs.append(_errors(sd, nn, p["ref"]))
            its.append(it)
            us.append(_time_call(lambda: polyhedral_contact(*args), repeat))
        Ra = np.array([p["Ra"] for p in poses])
        Rb = np.array([p["Rb"] for p in poses])
        pb = np.array([p["pb"] for p in poses])
        pa = np.zeros((K, 3))
        kus = _time_call(lambda: polyhedral_contact_batch(PA, pa, Ra, PB, pb, Rb), repeat) / K
        bus = _time_call(lambda: polyhedral_contact_batch(PA.vertices, pa, Ra, PB.vertices, pb, Rb),
                         max(1, repeat // 3)) / K
        rows.append(_row("polyhedral GJK/EPA", n, PA.n_facets, PA.n_vertices, errs,
                         np.median(us), kus, bus, np.median(its)))
    try:
        from nurbsdem.contact import detect
    except ImportError as exc:  # pragma: no cover - depends on the other helper's module
        print(f"note: nurbsdem.contact.detect not available ({exc}); NURBS rows skipped")
        return rows
    try:
        detect(shape_a, (I0, np.eye(3)), shape_b, (np.array([0.05, 0, 0]), np.eye(3)))  # JIT
        rng = np.random.default_rng(5)
        ec, uc, ic, ew, uw, iw, prevs = ([] for _ in range(7))
        for p in poses:
            pa_, pb_ = (I0, p["Ra"]), (p["pb"], p["Rb"])
            r = detect(shape_a, pa_, shape_b, pb_)
            ec.append(_errors(r.signed_distance, r.normal, p["ref"]))
            ic.append(r.iterations)
            uc.append(_time_call(lambda: detect(shape_a, pa_, shape_b, pb_), repeat))
            step = rng.normal(size=3)
            step *= 1e-3 * SIZE / np.linalg.norm(step)
            axis = rng.normal(size=3)
            dR = Rotation.from_rotvec(1e-3 * axis / np.linalg.norm(axis)).as_matrix()
            prev = detect(shape_a, pa_, shape_b, (p["pb"] - step, dR @ p["Rb"]))
            prevs.append(prev)
            r = detect(shape_a, pa_, shape_b, pb_, previous=prev)
            ew.append(_errors(r.signed_distance, r.normal, p["ref"]))
            iw.append(r.iterations)
            uw.append(_time_call(lambda: detect(shape_a, pa_, shape_b, pb_, previous=prev), repeat))
        kc, kw = _nurbs_kernel_us(shape_a, shape_b, poses, prevs, repeat)
        rows.append(_row("NURBS exact (cold)", None, None, None, ec, np.median(uc), kc,
                         its=np.median(ic)))
        rows.append(_row("NURBS exact (warm)", None, None, None, ew, np.median(uw), kw,
                         its=np.median(iw)))
    except Exception as exc:  # pragma: no cover - report, do not hide the polyhedral table
        print(f"note: nurbsdem.contact.detect failed ({type(exc).__name__}: {exc}); NURBS rows skipped")
    return rows


def print_table(rows: list[dict]) -> None:
    """Print the rows as a fixed-width table."""
    print(f"ellipsoid pairs, size L = {SIZE * 1e3:.1f} mm, exact penetration 0.1-5 % of L; "
          "errors are medians (p90 = 90th percentile) over the poses")
    cols = [("method", "method", 20, "s"), ("n", "n", 3, "d"), ("facets", "facets", 6, "d"),
            ("verts", "vertices", 5, "d"), ("pen err/L", "pen_err_median", 9, ".2e"),
            ("p90 /L", "pen_err_p90", 8, ".1e"), ("err/depth", "pen_err_rel_depth_median", 9, ".2e"),
            ("normal rad", "normal_err_median", 10, ".2e"), ("us/query", "us_median", 8, ".1f"),
            ("kernel us", "kernel_us", 9, ".1f"), ("brute us", "brute_us", 8, ".1f"),
            ("iters", "iterations_median", 5, ".0f")]
    print(" ".join(f"{h:<{w}}" if f == "s" else f"{h:>{w}}" for h, _, w, f in cols))
    for r in rows:
        cells = []
        for _, key, w, f in cols:
            x = r[key]
            if x is None or (isinstance(x, float) and np.isnan(x)):
                cells.append(f"{'-':>{w}}")
            elif f == "s":
                cells.append(f"{x:<{w}}")
            else:
                cells.append(f"{x:>{w}{f}}")
        print(" ".join(cells))


if __name__ == "__main__":
    print_table(run(quick="--quick" in sys.argv))

"""An exact sphere against a NURBS particle: the 2-parameter point-to-surface problem
(``nurbsdem/contact/sphere.py``) against the 4-parameter LCP, speed and error together.

Poses: a sphere (r = 10 mm) whose centre lies along a random direction from the particle's
centroid, at 0.55–0.95 of (bounding radius + r), the particle randomly rotated: separated and
penetrating pairs.  For each particle shape (an exact NURBS ellipsoid 30 × 20 × 12 mm and the
paper's particle A) it prints, per pair and one thread: the LCP cold and warm, the point
solver cold and warm-started from the LCP's row, the share of pairs it solves (the rest are
left to the LCP: the centre inside the particle, a crease, another patch), and the largest
differences to the LCP (signed distance, normal); for the ellipsoid also the largest error
against the closed-form distance (the root of the Lagrange equation, scipy's brentq).

Usage: .venv/bin/python benchmarks/bench_point_surface.py [--quick]
"""
from __future__ import annotations

import sys
import time

import numpy as np
from scipy.optimize import brentq
from scipy.spatial.transform import Rotation

from nurbsdem.contact.detect import ContactTable, detect_batch
from nurbsdem.contact.lcp import F_N, F_SD, I_PA, NF, NI
from nurbsdem.contact.sphere import sphere_nurbs_rows
from nurbsdem.geometry.generators import ellipsoid
from nurbsdem.geometry.particles import paper_particle_shape
from nurbsdem.shapes import sphere

R_S = 0.01
AXES = (0.03, 0.02, 0.012)


def ellipsoid_distance(y: np.ndarray) -> float:
    """Distance (m) from y (ellipsoid frame, outside) to the ellipsoid AXES."""
    a = np.array(AXES)
    f = lambda t: np.sum((a * y / (a * a + t)) ** 2) - 1.0      # noqa: E731
    t = brentq(f, 0.0, 10.0 * np.linalg.norm(y) * a.max(), xtol=1e-300, rtol=1e-15, maxiter=500)
    return float(np.linalg.norm(y - a * a * y / (a * a + t)))


def timed(fn, repeat: int = 3):
    best, out = np.inf, None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def run(K: int, seed: int = 0) -> list[dict]:
    """The rows of the module docstring, one thread (the caller's thread count restored)."""
    import numba
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        return _rows(K, seed)
    finally:
        numba.set_num_threads(threads)


def _rows(K: int, seed: int) -> list[dict]:
    table = ContactTable([sphere(R_S), ellipsoid(*AXES), paper_particle_shape("A")])
    rng = np.random.default_rng(seed)
    rows = []
    for sb, name in ((1, "ellipsoid 30x20x12 mm"), (2, "paper particle A")):
        Rb = Rotation.random(K, random_state=rng).as_matrix()
        pb = rng.normal(size=(K, 3)) * 0.01
        d = rng.normal(size=(K, 3))
        d /= np.linalg.norm(d, axis=1)[:, None]
        cen = pb + np.einsum("kij,j->ki", Rb, table.centroid[sb])
        c = cen + d * (table.radius[sb] + R_S) * rng.uniform(0.55, 0.95, (K, 1))
        sph = np.zeros(K, np.int64)
        ps, Rs = c - table.centroid[0], np.tile(np.eye(3), (K, 1, 1))
        shape_b = np.full(K, sb)
        args = (table, sph, ps, Rs, shape_b, pb, Rb)
        t_lcp_cold, (f, i) = timed(lambda: detect_batch(*args))
        t_lcp_warm, _ = timed(lambda: detect_batch(*args, f, i))
        i_prev = i.copy()
        i_prev[:, I_PA] = -1

        def point(prev_f, prev_i):
            rf, ri = np.zeros((K, NF)), np.zeros((K, NI), np.int64)
            ok = sphere_nurbs_rows(table.tab, table.info, table.centroid, table.radius,
                                   table.seeds, shape_b, c, np.full(K, R_S), pb, Rb,
                                   np.ones(K, np.bool_), prev_f, prev_i, rf, ri)
            return ok, rf
        zf, zi = np.zeros((K, NF)), np.zeros((K, NI), np.int64)
        t_pt_cold, (ok_c, rc) = timed(lambda: point(zf, zi))
        t_pt_warm, (ok_w, rw) = timed(lambda: point(f, i_prev))
        ok = ok_w
        err_sd = float(np.abs(rw[ok, F_SD] - f[ok, F_SD]).max()) / table.radius[sb]
        err_n = float(np.linalg.norm(rw[ok, F_N:F_N + 3] - f[ok, F_N:F_N + 3], axis=1).max())
        exact = np.nan
        if sb == 1:
            ref = np.array([ellipsoid_distance(Rb[k].T @ (c[k] - cen[k])) - R_S
                            for k in np.nonzero(ok)[0]])
            exact = float(np.abs(rw[ok, F_SD] - ref).max())
        rows.append(dict(shape=name, pairs=K, penetrating=int((f[:, F_SD] < 0).sum()),
                         lcp_cold=t_lcp_cold / K * 1e6, lcp_warm=t_lcp_warm / K * 1e6,
                         pt_cold=t_pt_cold / K * 1e6, pt_warm=t_pt_warm / K * 1e6,
                         solved_cold=float(ok_c.mean()), solved_warm=float(ok_w.mean()),
                         err_sd=err_sd, err_n=err_n, err_exact=exact))
    return rows


def main(argv: list[str]) -> list[dict]:
    rows = run(300 if "--quick" in argv else 3000)
    print("sphere (r = 10 mm) against a NURBS particle, one thread, µs per pair")
    for r in rows:
        print(f"{r['shape']}: {r['pairs']} pairs ({r['penetrating']} penetrating); LCP cold "
              f"{r['lcp_cold']:.1f} / warm {r['lcp_warm']:.1f}; point-to-surface cold "
              f"{r['pt_cold']:.2f} / warm {r['pt_warm']:.2f} (solved {100 * r['solved_cold']:.0f} "
              f"/ {100 * r['solved_warm']:.0f} %, the rest by the LCP); against the LCP: "
              f"|Δsd|/R {r['err_sd']:.1e}, normal {r['err_n']:.1e} rad"
              + (f"; against the closed form: |Δsd| {r['err_exact']:.1e} m"
                 if np.isfinite(r["err_exact"]) else ""))
    return rows


if __name__ == "__main__":
    main(sys.argv[1:])

"""Verification report: runs the benchmarks and writes ``docs/verification.md`` + PNG plots,
and ``docs/performance.md`` (its timing sections: the headline numbers, sections 5 and 8).

Sections (every number is measured by this script in this run; each error names its
reference):

1. Contact accuracy against cost (LCP tolerance sweep, cold/warm µs, Newton iterations).
2. Exact geometry against facets (``bench_facets.py``: GJK/EPA on tessellated hulls).
3. Robustness: randomised hard-case sweep with exact references (``common.py``).
4. Time step against error (drop test, small deposition; solver ``safety`` sweep).
5. Cost of a run: scaling with the number of particles; the paper's example (full mode).
6. Fit to meshes (``nurbsdem fit``): ellipsoid meshes against the analytic ellipsoid; the
   synthetic scanned grain.
7. Hertz–Mindlin with the exact curvature (radius errors, cost, impact benchmarks).
8. Runs on several MPI ranks (speed-up, weak scaling, a model for more ranks).

``--performance-only`` rewrites ``performance.md`` from the ``verification.md`` already in
``--output`` without measuring anything.

Usage::

    .venv/bin/python benchmarks/report.py [--quick] [--output DIR]     # or: nurbsdem bench

``--quick`` (CI) runs in about two minutes on 2 cores; the full mode in about 15–20 min.
The LCP tolerance sweep recompiles the LCP with a patched ``ANGLE_TOL`` (the direction
Newton's stopping angle, a module constant of :mod:`nurbsdem.contact.stage2`) in worker
processes with their own numba cache (kept under the temp folder, keyed by the source).
"""
from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402
from common import REPO, machine_info, stamp  # noqa: E402

from nurbsdem.contact.reference import random_pair_poses  # noqa: E402

DEFAULT_TOL = "default"


# =========================================================================== helpers
def fmt(x, spec=".2e") -> str:
    """A number for a table; '–' for None, 'n/a' for NaN."""
    if x is None:
        return "–"
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    x = float(x)
    if math.isnan(x):
        return "n/a"
    return format(x, spec)


def md_table(header: list[str], rows: list[list]) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for r in rows:
        out.append("| " + " | ".join(str(c) for c in r) + " |")
    return "\n".join(out)


class Report:
    """Collects markdown and figures."""

    def __init__(self, outdir: Path, info: dict, quick: bool) -> None:
        self.outdir = outdir
        self.figdir = outdir / "verification"
        self.figdir.mkdir(parents=True, exist_ok=True)
        self.info = info
        self.quick = quick
        self.parts: list[str] = []
        self.figures: list[Path] = []
        self.headline: dict = {}

    def add(self, text: str) -> None:
        self.parts.append(text)

    def stamp_line(self) -> str:
        return f"*Measured on {stamp(self.info)}; mode: {'quick' if self.quick else 'full'}.*"

    def figure(self, fig, name: str, caption: str) -> None:
        fig.text(0.01, 0.005, f"{stamp(self.info)} ({'quick' if self.quick else 'full'})",
                 fontsize=6, color="0.4", ha="left", va="bottom")
        path = self.figdir / name
        fig.savefig(path, dpi=110)
        import matplotlib.pyplot as plt
        plt.close(fig)
        self.figures.append(path)
        self.add(f"![{caption}](verification/{name})\n\n*Figure: {caption}. "
                 f"{stamp(self.info)}.*\n")


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


# =========================================================================== 1. LCP accuracy
LCP_TYPES = ("sphere", "ellipsoid", "A-A")
LCP_R = 0.02
LCP_AXES = (0.03, 0.02, 0.012)


def _lcp_table():
    from nurbsdem.contact import ContactTable
    from nurbsdem.geometry.generators import ellipsoid, sphere
    from nurbsdem.geometry.particles import paper_particle_shape
    shapes = [sphere(LCP_R), ellipsoid(*LCP_AXES), paper_particle_shape("A")]
    return shapes, ContactTable(shapes)


def _source_hash() -> str:
    h = hashlib.sha1()
    for p in sorted(list((REPO / "nurbsdem" / "contact").rglob("*.py")) +
                    list((REPO / "nurbsdem" / "geometry").rglob("*.py"))):
        h.update(p.read_bytes())
    return h.hexdigest()[:12]


def lcp_worker(inp: str, out: str, tol: str) -> None:
    """Worker process: solve the saved poses at ANGLE_TOL = tol (cold, warm) and time them."""
    from nurbsdem.contact import stage2
    if tol != DEFAULT_TOL:
        stage2.ANGLE_TOL = float(tol)     # read by numba at (re)compilation: own cache dir
    import numba
    from nurbsdem.contact import detect_batch
    numba.set_num_threads(1)
    _, table = _lcp_table()
    data = np.load(inp)
    reps = int(data["reps"])
    res = {}
    t_compile = time.perf_counter()
    for t in LCP_TYPES:
        g = lambda k: data[f"{t}_{k}"]  # noqa: E731
        sa, sb = g("sa"), g("sb")
        prev = detect_batch(table, sa, g("ppa"), g("pRa"), sb, g("ppb"), g("pRb"))
        args = (table, sa, g("pa"), g("Ra"), sb, g("pb"), g("Rb"))
        cold = detect_batch(*args)
        warm = detect_batch(*args, prev[0], prev[1])
        res[f"{t}_fc"], res[f"{t}_ic"] = cold
        res[f"{t}_fw"], res[f"{t}_iw"] = warm
        K = len(sa)
        ch = 16   # < PARALLEL_MIN_PAIRS: the serial path, one thread

        def timed(pf, pi):
            best = np.inf
            for _ in range(3):
                t0 = time.perf_counter()
                for _ in range(reps):
                    for k0 in range(0, K, ch):
                        s = slice(k0, min(K, k0 + ch))
                        detect_batch(table, sa[s], args[2][s], args[3][s], sb[s], args[5][s],
                                     args[6][s], None if pf is None else pf[s],
                                     None if pi is None else pi[s])
                best = min(best, time.perf_counter() - t0)
            return best / (reps * K) * 1e6
        res[f"{t}_us_cold"] = timed(None, None)
        res[f"{t}_us_warm"] = timed(prev[0], prev[1])
    res["wall"] = time.perf_counter() - t_compile
    np.savez(out, **res)


class LcpSweep:
    """Poses, the background worker chain (one tolerance after the other), references."""

    def __init__(self, quick: bool, workdir: Path) -> None:
        import bench_lcp
        self.quick = quick
        self.workdir = workdir
        self.tols = ([1e-6] if quick else [1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9])
        self.K = 64 if quick else 300
        self.reps = 3 if quick else 5
        self.shapes, table = _lcp_table()
        rng = np.random.default_rng(0)
        arrays = {"reps": self.reps}
        self.poses = {}
        for s, t in enumerate(LCP_TYPES):
            cfg = bench_lcp._configs(table, s, s, self.K, rng, (-0.05, 0.01))
            prev = bench_lcp._step(rng, cfg[1], cfg[2], cfg[4], cfg[5], float(table.radius[s]))
            self.poses[t] = cfg
            for k, a in zip(("sa", "pa", "Ra", "sb", "pb", "Rb"), cfg):
                arrays[f"{t}_{k}"] = a
            for k, a in zip(("ppa", "pRa", "ppb", "pRb"), prev):
                arrays[f"{t}_{k}"] = a
        self.inp = workdir / "lcp_poses.npz"
        np.savez(self.inp, **arrays)
        self.results: dict = {}
        self.errors: dict = {}
        self.thread = threading.Thread(target=self._run_all, daemon=True)
        self.thread.start()

    def _run_one(self, tol) -> None:
        tag = DEFAULT_TOL if tol == DEFAULT_TOL else f"{tol:.0e}"
        out = self.workdir / f"lcp_{tag}.npz"
        env = dict(os.environ)
        if tol != DEFAULT_TOL:
            env["NUMBA_CACHE_DIR"] = str(Path(tempfile.gettempdir()) / "nurbsdem-report-numba"
                                         / f"{_source_hash()}-tol{tag}")
        cmd = [sys.executable, str(Path(__file__).resolve()), "--lcp-worker", str(self.inp),
               str(out), tag]
        t0 = time.perf_counter()
        p = subprocess.run(cmd, env=env, capture_output=True, text=True)
        if p.returncode != 0:
            self.errors[tag] = (p.stderr or p.stdout).strip().splitlines()[-1:]
            return
        d = np.load(out)
        self.results[tag] = {k: d[k] for k in d.files}
        self.results[tag]["process_s"] = time.perf_counter() - t0

    def _run_all(self) -> None:
        for tol in [DEFAULT_TOL] + self.tols:
            try:
                self._run_one(tol)
            except Exception as exc:  # pragma: no cover
                self.errors[str(tol)] = [f"{type(exc).__name__}: {exc}"]

    def references(self) -> dict:
        """Reference (signed distance, normal) per type for the first n pairs."""
        from nurbsdem.contact import reference as ref
        n_ref = {"sphere": self.K, "ellipsoid": self.K if self.quick else 150,
                 "A-A": 4 if self.quick else 24}
        out = {}
        for t in LCP_TYPES:
            sa, pa, Ra, sb, pb, Rb = self.poses[t]
            sd, nn = [], []
            t0 = time.perf_counter()
            for k in range(n_ref[t]):
                if t == "sphere":
                    dc = pb[k] - pa[k]
                    dist = np.linalg.norm(dc)
                    sd.append(dist - 2 * LCP_R)
                    nn.append(dc / dist)
                elif t == "ellipsoid":
                    r = ref.ellipsoid_pair(LCP_AXES, (pa[k], Ra[k]), LCP_AXES, (pb[k], Rb[k]))
                    sd.append(r[0])
                    nn.append(r[1])
                else:
                    r = ref.nurbs_pair(self.shapes[2], (pa[k], Ra[k]), self.shapes[2], (pb[k], Rb[k]))
                    sd.append(r[0])
                    nn.append(r[1])
            out[t] = (np.array(sd), np.array(nn), time.perf_counter() - t0)
        return out


REF_NAMES = {"sphere": "analytic (centre distance − 2r)",
             "ellipsoid": "support function h(d) = c·d + √(dᵀMd), dense start + BFGS "
                          "(`reference.ellipsoid_pair`)",
             "A-A": "dense surface sampling (40×40 per patch) + L-BFGS-B + Newton polish, "
                    "direction by BFGS (`reference.nurbs_pair`)"}


def section_lcp(rep: Report, sweep: LcpSweep) -> None:
    from nurbsdem.contact.lcp import F_IT1, F_N, F_SD, I_FAIL, I_IT, I_STAGE
    plt = _plt()
    refs = sweep.references()
    sweep.thread.join()
    rep.add("## 1. Contact accuracy against cost\n")
    rep.add(rep.stamp_line() + "\n")
    rep.add(
        f"{sweep.K} random pairs per type (signed distance −5 % … +1 % of the radius, placed as in "
        "`bench_lcp.py`): exact 6-patch spheres (r = 20 mm), exact ellipsoids (30 × 20 × 12 mm), "
        "paper particle A against A. References:\n\n" +
        "\n".join(f"* {t}: {REF_NAMES[t]} — {len(refs[t][0])} pairs, {refs[t][2]:.1f} s"
                  for t in LCP_TYPES) + "\n")
    rep.add(
        "The LCP has no tolerance argument: the direction Newton (stage 2) stops when its step is "
        "below the module constant `ANGLE_TOL` (default 1e-11 rad; a last step below 1e-7 rad is "
        "a Taylor update) or the tangential gradient is below 1e-15 × scale. The sweep recompiles "
        "the LCP with `ANGLE_TOL` patched (other constants unchanged, including stage 1's "
        "`GRAD_TOL` = 1e-12) in a worker process per value. µs per LCP: mean over the pairs, one "
        "thread, serial batches of 16, best of 3; cold = no previous solution, warm = previous "
        "solution of the pair one step earlier (displacement 1e-4 r, rotation 2e-3 rad). "
        "Errors: |Δsd| relative to the bounding radius r, normal angle (rad); max over the "
        "pairs with a reference. The signed distance is stationary in the normal, so a "
        "reference computed by an optimiser (ellipsoids, A-A) pins the depth to ~1e-15 but its "
        "own normal only to ~1e-8 rad: normal errors near 1e-8 there are the reference's.\n")
    if sweep.errors:
        rep.add("Worker failures (these tolerances could not be measured): " +
                "; ".join(f"{k}: {' '.join(v)}" for k, v in sweep.errors.items()) + "\n")
    rows, plot = [], {t: [] for t in LCP_TYPES}
    for tag in [DEFAULT_TOL] + [f"{t:.0e}" for t in sweep.tols]:
        r = sweep.results.get(tag)
        if r is None:
            rows.append([tag] + ["not measured"] + [""] * 11)
            continue
        tol_v = 1e-11 if tag == DEFAULT_TOL else float(tag)
        for s, t in enumerate(LCP_TYPES):
            sd_ref, n_ref, _ = refs[t]
            m = len(sd_ref)
            rad = float(sweep.shapes[s].bounding_radius)
            e = {}
            for lab in ("c", "w"):
                f = r[f"{t}_f{lab}"]
                e[lab + "sd"] = np.abs(f[:m, F_SD] - sd_ref) / rad
                e[lab + "n"] = np.linalg.norm(np.cross(f[:m, F_N:F_N + 3], n_ref), axis=1)
            fc, ic = r[f"{t}_fc"], r[f"{t}_ic"]
            fw, iw = r[f"{t}_fw"], r[f"{t}_iw"]
            it1c = fc[:, F_IT1]
            it2c = ic[:, I_IT] - it1c
            st1 = np.mean(ic[:, I_STAGE] == 1)
            fails = int(ic[:, I_FAIL].sum() + iw[:, I_FAIL].sum())
            rows.append([f"{tol_v:.0e}" + (" (default)" if tag == DEFAULT_TOL else ""), t,
                         fmt(e["csd"].max()), fmt(e["wsd"].max()), fmt(e["cn"].max()),
                         fmt(e["wn"].max()), fmt(float(r[f"{t}_us_cold"]), ".1f"),
                         fmt(float(r[f"{t}_us_warm"]), ".1f"),
                         f"{np.mean(ic[:, I_IT]):.1f} ({np.mean(it1c):.1f} / {np.mean(it2c):.1f})",
                         f"{np.mean(iw[:, I_IT]):.1f} ({np.mean(fw[:, F_IT1]):.1f} / "
                         f"{np.mean(iw[:, I_IT] - fw[:, F_IT1]):.1f})",
                         f"{100 * st1:.0f} / {100 * (1 - st1):.0f}", fails])
            plot[t].append((tol_v, e["csd"].max(), e["cn"].max(), np.mean(it2c),
                            float(r[f"{t}_us_cold"]), float(r[f"{t}_us_warm"]),
                            np.median(e["csd"]), np.mean(iw[:, I_IT])))
            if tag == DEFAULT_TOL:
                rep.headline[f"lcp_{t}"] = dict(us_cold=float(r[f"{t}_us_cold"]),
                                               us_warm=float(r[f"{t}_us_warm"]),
                                               sd_err=float(max(e["csd"].max(), e["wsd"].max())),
                                               n_err=float(max(e["cn"].max(), e["wn"].max())),
                                               it_cold=float(np.mean(ic[:, I_IT])),
                                               it_warm=float(np.mean(iw[:, I_IT])))
    rep.add(md_table(["ANGLE_TOL (rad)", "pair", "max |Δsd|/r cold", "max |Δsd|/r warm",
                      "max normal err cold", "max normal err warm", "µs cold", "µs warm",
                      "Newton it. cold: all (stage 1 / stage 2)", "Newton it. warm",
                      "results by stage 1 / 2 (%, cold)", "failed"], rows) + "\n")
    if any(plot.values()):
        fig, axs = plt.subplots(1, 3, figsize=(13, 4))
        for t, mk in zip(LCP_TYPES, "osd"):
            p = sorted(plot[t])
            if not p:
                continue
            p = np.array(p)
            fl = lambda a: np.maximum(a, 1e-17)  # noqa: E731 - log axes; 0 error drawn at 1e-17
            axs[0].loglog(p[:, 0], fl(p[:, 1]), mk + "-", label=f"{t} |Δsd|/r")
            axs[0].loglog(p[:, 0], fl(p[:, 2]), mk + "--", label=f"{t} normal (rad)")
            axs[1].semilogy(p[:, 3], fl(p[:, 1]), mk + "-", label=f"{t} |Δsd|/r")
            axs[1].semilogy(p[:, 3], fl(p[:, 2]), mk + "--", label=f"{t} normal")
            axs[2].semilogx(p[:, 0], p[:, 4], mk + "-", label=f"{t} cold")
            axs[2].semilogx(p[:, 0], p[:, 5], mk + ":", label=f"{t} warm")
        axs[0].set_xlabel("ANGLE_TOL (rad)")
        axs[0].set_ylabel("max error (cold)")
        axs[0].set_title("error vs LCP stopping tolerance")
        axs[1].set_xlabel("mean stage-2 Newton iterations (cold)")
        axs[1].set_title("error vs Newton iterations")
        axs[2].set_xlabel("ANGLE_TOL (rad)")
        axs[2].set_ylabel("µs per LCP (1 thread)")
        axs[2].set_title("cost vs tolerance")
        for a in axs:
            a.grid(True, which="both", alpha=0.3)
            a.legend(fontsize=6)
        fig.tight_layout(rect=(0, 0.03, 1, 1))
        rep.figure(fig, "lcp_accuracy.png", "LCP error (against the references above) and cost "
                   "against the stopping tolerance and the Newton iteration count; errors of 0 "
                   "are drawn at 1e-17")


# =========================================================================== 2. facets
def section_facets(rep: Report) -> None:
    import bench_facets as bf
    plt = _plt()
    rep.add("## 2. Exact geometry against facets\n")
    rep.add(rep.stamp_line() + "\n")
    t0 = time.perf_counter()
    rows = bf.run(quick=rep.quick)
    el = time.perf_counter() - t0
    rep.add(
        f"`bench_facets.py` ({el:.0f} s): ellipsoid pairs (A: 32.4 × 29.1 × 25.1 mm, B = 0.8 A), "
        "exact penetration 0.1–5 % of L = 64.8 mm. Polyhedra: convex hulls of the NURBS "
        "tessellation at n quads per patch direction, GJK/EPA (`benchmarks/polyhedral.py`). "
        "Reference: the ellipsoid support function (`reference.ellipsoid_pair`). Errors are "
        "medians over the poses; kernel µs = compiled batch loop, one thread.\n")
    tab = []
    for r in rows:
        tab.append([r["method"], fmt(r["n"]), fmt(r["facets"]), fmt(r["pen_err_median"]),
                    fmt(r["pen_err_p90"]), fmt(r["pen_err_rel_depth_median"]),
                    fmt(r["normal_err_median"]), fmt(r["us_median"], ".1f"),
                    fmt(r["kernel_us"], ".1f")])
    rep.add(md_table(["method", "n", "facets", "pen. err / L (median)", "p90 / L",
                      "err / depth", "normal err (rad)", "µs per query (Python API)",
                      "kernel µs"], tab) + "\n")
    poly = [r for r in rows if r["facets"] is not None]
    nurbs = [r for r in rows if r["facets"] is None]
    # crossover statement
    text = []
    if poly and nurbs:
        nb = min(nurbs, key=lambda r: r["kernel_us"] if not math.isnan(r["kernel_us"]) else 1e99)
        cheaper = [r for r in poly if r["kernel_us"] < nb["kernel_us"]]
        as_good = [r for r in poly if r["pen_err_median"] <= max(nb["pen_err_median"], 1e-12)]
        best = poly[-1]
        text.append(
            f"At the finest tessellation measured ({best['facets']} facets) the polyhedral error "
            f"is {best['pen_err_median']:.1e} L (median; {best['pen_err_rel_depth_median']:.1e} of "
            f"the depth) at {best['kernel_us']:.1f} µs per query, against the exact NURBS LCP's "
            f"{nb['pen_err_median']:.1e} L at {nb['kernel_us']:.1f} µs ({nb['method']}).")
        for nr in nurbs:
            ch = [r for r in poly if r["kernel_us"] < nr["kernel_us"]]
            text.append(f"Against {nr['method']} ({nr['kernel_us']:.1f} µs): " +
                        (f"tessellations up to {max(r['facets'] for r in ch)} facets are cheaper."
                         if ch else "no tessellation measured is cheaper."))
        if cheaper:
            c = max(cheaper, key=lambda r: r["facets"])
            text.append(
                f"At {c['facets']} facets, the largest tessellation cheaper than the fastest NURBS "
                f"LCP, the error is {c['pen_err_median']:.1e} L ({c['pen_err_rel_depth_median']:.0%} "
                "of the depth): where facets win on speed they carry a geometric error the exact "
                "method does not have.")
        else:
            text.append("No tessellation measured is cheaper than the NURBS LCP.")
        if not as_good:
            text.append("No tessellation measured reaches the NURBS accuracy; the polyhedral error "
                        "falls roughly as 1/facets (second order in the mesh size).")
        rep.headline["facets"] = dict(best_facets=best["facets"], best_err=best["pen_err_median"],
                                      best_us=best["kernel_us"], nurbs_err=nb["pen_err_median"],
                                      nurbs_us=nb["kernel_us"],
                                      cheaper_up_to=(max(cheaper, key=lambda r: r["facets"])["facets"]
                                                     if cheaper else None))
    rep.add("**Crossover.** " + " ".join(text) + "\n")
    if poly:
        fig, axs = plt.subplots(1, 2, figsize=(10, 4))
        F = np.array([r["facets"] for r in poly], float)
        axs[0].loglog(F, [r["pen_err_median"] for r in poly], "o-", label="polyhedral, depth / L")
        axs[0].loglog(F, [r["normal_err_median"] for r in poly], "s--", label="polyhedral, normal (rad)")
        axs[1].loglog(F, [r["kernel_us"] for r in poly], "o-", label="polyhedral GJK/EPA (kernel)")
        for r, c in zip(nurbs, ("C3", "C2")):
            axs[0].axhline(max(r["pen_err_median"], 1e-17), color=c, ls=":",
                           label=f"{r['method']} depth / L")
            axs[1].axhline(r["kernel_us"], color=c, ls=":", label=r["method"])
        axs[0].set_xlabel("facets of A")
        axs[0].set_ylabel("median error")
        axs[1].set_xlabel("facets of A")
        axs[1].set_ylabel("µs per query (1 thread)")
        for a in axs:
            a.grid(True, which="both", alpha=0.3)
            a.legend(fontsize=7)
        fig.tight_layout(rect=(0, 0.03, 1, 1))
        rep.figure(fig, "facets.png", "error and cost of polyhedral contact against facet count, "
                   "with the exact NURBS LCP as horizontal lines (reference: ellipsoid support "
                   "function)")


# =========================================================================== 3. robustness
def section_robustness(rep: Report) -> None:
    from scipy.spatial.transform import Rotation
    from nurbsdem.contact import ContactTable, detect_batch
    from nurbsdem.contact.lcp import F_N, F_PA, F_PB, F_SD, I_DEG, I_FAIL, I_PA, I_PB
    from nurbsdem.contact.reference import SampledBody, ellipsoid_pair
    from nurbsdem.contact.wall import detect_wall_batch
    from nurbsdem.geometry.generators import sphere
    rep.add("## 3. Robustness: randomised hard cases\n")
    rep.add(rep.stamp_line() + "\n")
    t_start = time.perf_counter()
    quick = rep.quick
    total = 3000 if quick else 100_000
    rng = np.random.default_rng(2024)
    shapes = common.sweep_shapes()
    BIG_R = 0.2
    big = sphere(BIG_R)
    table = ContactTable(shapes + [big])
    NS = len(shapes)
    TOL_SD, TOL_N = 1e-8, 1e-6
    recs = []   # dicts of arrays per batch

    def solve(cat, regime, sa, pa, Ra, sb, pb, Rb, ref_sd=None, ref_n=None, scale=None):
        K = len(sa)
        f, i = detect_batch(table, sa, pa, Ra, sb, pb, Rb)
        dr = Rotation.from_rotvec(rng.normal(size=(K, 3)) * 2e-3).as_matrix()
        step = rng.normal(size=(K, 3)) * 1e-4 * table.radius[sa][:, None]
        fp, ip = detect_batch(table, sa, pa + step, np.einsum("kij,kjl->kil", dr, Ra), sb, pb, Rb)
        fw, iw = detect_batch(table, sa, pa, Ra, sb, pb, Rb, fp, ip)
        recs.append(dict(cat=cat, regime=regime, f=f, i=i, fw=fw, iw=iw, ip=ip, sa=sa, sb=sb,
                         pa=pa, Ra=Ra, pb=pb, Rb=Rb, ref_sd=ref_sd, ref_n=ref_n, scale=scale))

    # --- (a) the generator of tests/test_contact_sweep.py, all shape pairs
    n_rand = int(0.3 * total)
    sa = rng.integers(0, NS, n_rand)
    sb = rng.integers(0, NS, n_rand)
    pa, Ra, pb, Rb = random_pair_poses(table, sa, sb, rng, -0.15, 0.03)
    solve("random pairs (test generator)", "−15 … +3 %", sa, pa, Ra, sb, pb, Rb)
    # --- (b) features against probe spheres (exact reference by construction)
    regimes = {"normal": lambda k: rng.uniform(-0.05, 0.02, k),
               "grazing": lambda k: rng.choice([-1, 1], k) * 10 ** rng.uniform(-9, -5, k),
               "deep": lambda k: -rng.uniform(0.15, 0.45, k)}
    cases = [(s, kind) for s in range(NS) for kind in common.FEATURES
             if common.feature_points(shapes[s], kind, rng, 1)]
    n_case = int(0.55 * total) // (len(cases) * len(regimes))
    for s, kind in cases:
        for reg, draw in regimes.items():
            pn = common.feature_points(shapes[s], kind, rng, n_case)
            probe = int(rng.integers(0, 2))             # 6-patch or single-patch sphere
            rB = common.SWEEP_R                         # exact radius of both probes
            sds = draw(len(pn)) * rB
            pa, Ra, pb, Rb, n_ref, _ = common.probe_poses(shapes[s], pn, rB, sds, rng)
            K = len(pn)
            solve(kind, reg, np.full(K, s), pa, Ra, np.full(K, probe), pb, Rb, sds, n_ref,
                  np.full(K, rB))
    # --- (c) flat faces: patch centres against a large sphere (r = 0.2 m) and a flat wall
    n_flat = int(0.15 * total) // 2 // 3
    wall_recs = []
    for s in range(2, NS):
        pn = common.feature_points(shapes[s], "face", rng, n_flat)
        rB = BIG_R
        sds = rng.uniform(-0.05, 0.02, len(pn)) * float(table.radius[s])
        pa, Ra, pb, Rb, n_ref, _ = common.probe_poses(shapes[s], pn, rB, sds, rng)
        K = len(pn)
        solve("flat face vs sphere r=0.2 m", "normal", np.full(K, s), pa, Ra, np.full(K, NS),
              pb, Rb, sds, n_ref, np.full(K, float(table.radius[s])))
        pn = common.feature_points(shapes[s], "face", rng, n_flat)
        sdw = rng.uniform(-0.05, 0.02, len(pn)) * float(table.radius[s])
        pos, R = common.wall_poses(shapes[s], pn, sdw, rng)
        o = np.tile([-1.0, -1.0, 0.0], (K, 1))
        a = np.tile([2.0, 0.0, 0.0], (K, 1))
        b = np.tile([0.0, 2.0, 0.0], (K, 1))
        sid = np.full(K, s)
        f, i = detect_wall_batch(table, sid, pos, R, o, a, b)
        dr = Rotation.from_rotvec(rng.normal(size=(K, 3)) * 2e-3).as_matrix()
        fp, ip = detect_wall_batch(table, sid, pos + 1e-4 * float(table.radius[s]),
                                   np.einsum("kij,kjl->kil", dr, R), o, a, b)
        fw, iw = detect_wall_batch(table, sid, pos, R, o, a, b, prev_f=fp, prev_i=ip)
        wall_recs.append(dict(cat="flat face on a flat wall", regime="normal", f=f, i=i, fw=fw,
                              iw=iw, ip=ip, sa=sid, sb=None, ref_sd=sdw,
                              ref_n=np.tile([0.0, 0.0, -1.0], (K, 1)),
                              scale=np.full(K, float(table.radius[s]))))
    recs.extend(wall_recs)
    t_solve = time.perf_counter() - t_start

    # --- validation
    n_cert = 60 if quick else 600
    cert_done = 0
    agg: dict = {}
    max_ell = 400 if quick else 6000
    ell_done = 0
    for r in recs:
        K = len(r["sa"])
        f, i, fw, iw = r["f"], r["i"], r["fw"], r["iw"]
        checked = np.zeros(K, bool)
        bad = np.zeros(K, bool)
        esd = np.full(K, np.nan)
        en = np.full(K, np.nan)
        if r["ref_sd"] is not None:
            for ff in (f, fw):
                e1 = np.abs(ff[:, F_SD] - r["ref_sd"]) / r["scale"]
                e2 = np.linalg.norm(np.cross(ff[:, F_N:F_N + 3], r["ref_n"]), axis=1)
                esd = np.fmax(esd, e1)
                en = np.fmax(en, e2)
            checked[:] = True
        else:
            sa, sb = r["sa"], r["sb"]
            for k in range(K):
                a, b = int(sa[k]), int(sb[k])
                if a <= 2 and b <= 2:
                    ca = r["pa"][k] + r["Ra"][k] @ table.centroid[a]
                    cb = r["pb"][k] + r["Rb"][k] @ table.centroid[b]
                    if a <= 1 and b <= 1:        # two spheres: analytic
                        dist = np.linalg.norm(cb - ca)
                        sd_ref, n_ref = dist - 2 * common.SWEEP_R, (cb - ca) / dist
                    else:                          # ellipsoid support function
                        if ell_done >= max_ell:
                            continue
                        ell_done += 1
                        ax = lambda s: (common.SWEEP_AXES if s == 2 else (common.SWEEP_R,) * 3)  # noqa: E731
                        sd_ref, n_ref, _, _ = ellipsoid_pair(ax(a), (ca, r["Ra"][k]), ax(b),
                                                             (cb, r["Rb"][k]), n_dirs=1500)
                    sc = min(table.radius[a], table.radius[b])
                    e1 = max(abs(f[k, F_SD] - sd_ref), abs(fw[k, F_SD] - sd_ref)) / sc
                    e2 = max(np.linalg.norm(np.cross(f[k, F_N:F_N + 3], n_ref)),
                             np.linalg.norm(np.cross(fw[k, F_N:F_N + 3], n_ref)))
                    esd[k], en[k] = e1, e2
                    checked[k] = True
                elif a >= 3 and b >= 3 and cert_done < n_cert and i[k, I_FAIL] == 0:
                    # optimality certificate from dense samples (no sample beyond the
                    # support planes at the contact points; gap parallel to the normal)
                    cert_done += 1
                    n_k = f[k, F_N:F_N + 3]
                    sc = table.radius[a] + table.radius[b]
                    viol = 0.0
                    for s_, pose, p, sign in ((a, (r["pa"][k], r["Ra"][k]), f[k, F_PA:F_PA + 3], 1.0),
                                              (b, (r["pb"][k], r["Rb"][k]), f[k, F_PB:F_PB + 3], -1.0)):
                        body = SampledBody(shapes[s_], pose, n=24)
                        viol = max(viol, np.max(body.x @ (sign * n_k)) - sign * (n_k @ p))
                    gap = f[k, F_PA:F_PA + 3] - f[k, F_PB:F_PB + 3]
                    esd[k] = max(viol, 0.0) / sc
                    en[k] = np.linalg.norm(gap + f[k, F_SD] * n_k) / sc
                    checked[k] = True
                    bad[k] = viol > 1e-12 * sc or en[k] > 1e-9
                    en[k] = np.nan    # not a normal angle: kept out of the normal column
            # the certificate rows already set bad; the others by tolerance below
        tolbad = checked & ((np.nan_to_num(esd) > TOL_SD) | (np.nan_to_num(en) > TOL_N))
        if r["ref_sd"] is None:
            certrows = checked & np.isnan(en)
            tolbad = np.where(certrows, bad, tolbad)
        conv = (i[:, I_FAIL] == 0)
        mig = (iw[:, I_PA] != r["ip"][:, I_PA]) | ((iw[:, I_PB] != r["ip"][:, I_PB]) if r["sb"] is not None else False)
        key = r["cat"]
        a_ = agg.setdefault(key, dict(n=0, conv=0, fail=0, failw=0, deg=0, mig=0, checked=0,
                                      out=0, esd=0.0, en=0.0, regimes=set()))
        a_["n"] += K
        a_["conv"] += int(conv.sum())
        a_["fail"] += int((~conv).sum())
        a_["failw"] += int(iw[:, I_FAIL].sum())
        a_["deg"] += int((i[:, I_DEG] > 0).sum())
        a_["mig"] += int(mig.sum())
        a_["checked"] += int(checked.sum())
        a_["out"] += int(tolbad.sum())
        if np.any(~np.isnan(esd)):
            a_["esd"] = max(a_["esd"], float(np.nanmax(esd)))
        if np.any(~np.isnan(en)):
            a_["en"] = max(a_["en"], float(np.nanmax(en)))
        a_["regimes"].add(r["regime"])
        rg = agg.setdefault("__regime__" + r["regime"], dict(n=0, fail=0, out=0, checked=0))
        rg["n"] += K
        rg["fail"] += int((~conv).sum()) + int(iw[:, I_FAIL].sum())
        rg["out"] += int(tolbad.sum())
        rg["checked"] += int(checked.sum())
    t_all = time.perf_counter() - t_start
    n_tot = sum(v["n"] for k, v in agg.items() if not k.startswith("__"))
    rep.add(
        f"{n_tot} seeded poses (seed 2024), each solved cold and warm-started (previous solution "
        "of the pose one step earlier: A moved by 1e-4 r and turned by 2e-3 rad) with "
        f"`detect_batch` / `detect_wall_batch` ({t_solve:.0f} s to generate and solve, "
        f"{t_all - t_solve:.0f} s to validate). Shapes: 6-patch sphere and single-patch sphere "
        "(seam, two poles) r = 10 mm, ellipsoid 30 × 20 × 12 mm, paper particles A, B, C.\n\n"
        "* *random pairs*: the pose generator of `tests/test_contact_sweep.py` (all shape "
        "pairs, signed distance −15 … +3 % of the smaller radius). References: analytic for two "
        "spheres; the ellipsoid support function (`reference.ellipsoid_pair`, spheres as "
        f"ellipsoids) for the other sphere/ellipsoid pairs (up to {max_ell}); for particle pairs "
        f"(up to {n_cert}) the optimality certificate of `test_contact_sweep.py` (no dense "
        "sample (24×24 per patch) beyond the support planes at the contact points, gap "
        "parallel to the normal); pairs of a sphere/ellipsoid with a particle: no cheap reference, "
        "not validated.\n"
        "* *seam, pole, corner (3+ patches), edge (2 patches), face (patch centre), random "
        "point*: a surface point of that kind on body A against a probe sphere (6-patch or "
        "single-patch, r = 10 mm) whose centre is on A's outward normal there at distance "
        "r + sd. **Exact reference** by construction: signed distance sd, normal = A's normal "
        "at the point (vectorised NURBS evaluator; at a pole the normal's limit by Richardson "
        "extrapolation, ~1e-10 rad). Regimes: normal (sd = −5 … +2 % r), grazing "
        "(|sd| = 1e-9 … 1e-5 r, both signs), deep (sd = −15 … −45 % r).\n"
        "* *flat faces*: patch centres of the ellipsoid and particles A/B/C (their flattest "
        "parts) against a sphere of radius 0.2 m (near flat on flat) and on a flat wall "
        "(exact reference: the face point is the support point along the wall normal).\n\n"
        f"Counts: converged / failed = the cold LCP's flag (failed LCPs return the best "
        "iterate and are counted by the solver); failed warm = the warm-started solve's flag; "
        "degenerated = the cold solution has fixed parameters (crease / 3-patch node, paper "
        "Eq. 10–15); migrated = the warm-started solve ended on another patch than its start. "
        f"Out of tolerance = validated results with |Δsd| > {TOL_SD:g} × r or normal error "
        f"> {TOL_N:g} rad (cold or warm), or a violated certificate.\n")
    rows = []
    tot = dict(n=0, conv=0, fail=0, failw=0, deg=0, mig=0, checked=0, out=0)
    for k, v in agg.items():
        if k.startswith("__"):
            continue
        rows.append([k, v["n"], v["conv"], v["fail"], v["failw"], v["deg"], v["mig"],
                     v["checked"], v["out"], fmt(v["esd"]), fmt(v["en"])])
        for c in tot:
            tot[c] += v[c]
    rows.append(["**all**", tot["n"], tot["conv"], tot["fail"], tot["failw"], tot["deg"],
                 tot["mig"], tot["checked"], tot["out"], "", ""])
    rep.add(md_table(["case", "poses", "converged", "failed (cold)", "failed (warm)",
                      "degenerated", "migrated (warm)", "validated", "out of tolerance",
                      "max |Δsd|/r", "max normal err (rad)"], rows) + "\n")
    rrows = [[k[len("__regime__"):], v["n"], v["fail"], v["checked"], v["out"]]
             for k, v in agg.items() if k.startswith("__regime__")]
    rep.add("By depth regime (failed = cold + warm):\n\n" +
            md_table(["regime", "poses", "failed", "validated", "out of tolerance"], rrows) + "\n")
    rep.headline["robustness"] = tot


# =========================================================================== 4. time step
def _run_deck(deck: Path, duration: float, safety: float, outdir: Path):
    from nurbsdem.dynamics.system import InstabilityError
    from nurbsdem.io.deck import parse_deck
    from nurbsdem.solver import Solver
    m = parse_deck(deck)
    m.steps = m.steps[:1]
    m.steps[0].duration = duration
    m.output.vtk_every = 1e3
    m.output.results_every = 1e3
    m.output.checkpoint_every = 1e3
    m.output.monitors_every = 1e-3
    s = Solver(m, output=outdir, quiet=True, safety=safety)
    try:
        summ = s.run()
    except InstabilityError as exc:
        return None, str(exc).splitlines()[0]
    compute = summ.timers["global search"] + summ.timers["LCP"] + summ.timers["forces + integration"]
    return dict(pos=s.bodies.position.copy(), summary=summ, compute=compute,
                sub=summ.substeps / max(summ.steps, 1),
                bal=abs(summ.balance_error) / summ.balance_scale if summ.balance_scale > 0 else float("nan"),
                size=float(np.mean([e.bounding_radius for e in m.shapes.values()]))), None


def section_timestep(rep: Report, workdir: Path) -> None:
    plt = _plt()
    rep.add("## 4. Time step against error\n")
    rep.add(rep.stamp_line() + "\n")
    quick = rep.quick
    cases = [("drop_one.inp (one particle A dropped 2 mm on the floor)",
              REPO / "inputs/regression/drop_one.inp", 0.2 if quick else 0.4),
             ("deposition_small.inp (2 A + 2 B + 2 C, shortened)",
              REPO / "inputs/regression/deposition_small.inp", 0.1 if quick else 0.3)]
    safeties = [1.0, 0.5, 0.25] if quick else [1.0, 0.5, 0.25, 0.1, 0.05]
    ref_safety = 0.05 if quick else 0.02
    rep.add(
        "The solver sub-steps each deck step (TimeStep 1e-3 s) into internal steps of at most "
        "`safety` × Δt_cr (Δt_cr the smaller of the a-priori pair estimate, with each shape's "
        "worst point compliance, and the highest mode of the current contact network; default "
        "safety 0.5). "
        f"Swept: safety ∈ {safeties}; **reference** = the same run with safety {ref_safety}. "
        "Energy-balance error = |balance error| / energy turned over (dissipated + external "
        "work), which is 0 for an exact integration (no reference needed); position error = "
        "max over particles of |x − x_ref| at the end, relative to the mean bounding radius. "
        "Compute time = global search + LCP + forces/integration (no set-up, no output), per "
        "simulated second. A deposition is chaotic: its position error after collisions also "
        "measures the sensitivity of the trajectory, not only the integration error.\n")
    fig, axs = plt.subplots(1, 2, figsize=(11, 4))
    for ci, (label, deck, dur) in enumerate(cases):
        ref, err = _run_deck(deck, dur, ref_safety, workdir / f"dt_ref_{ci}")
        rows = []
        pts = []
        if ref is None:
            rep.add(f"**{label}**: reference run failed ({err}); not measured.\n")
            continue
        for s in safeties + [ref_safety]:
            r, err = (ref, None) if s == ref_safety else _run_deck(deck, dur, s, workdir / f"dt_{ci}_{s}")
            if r is None:
                rows.append([s, "–", "unstable: " + err[:80], "–", "–"])
                continue
            pe = float(np.max(np.linalg.norm(r["pos"] - ref["pos"], axis=1))) / ref["size"]
            rows.append([f"{s:g}" + (" (reference)" if s == ref_safety else ""),
                         f"{r['sub']:.0f}", fmt(r["bal"]),
                         fmt(pe) if s != ref_safety else "0 (reference)",
                         fmt(r["compute"] / dur, ".2f")])
            pts.append((r["compute"] / dur, r["bal"], pe, s))
        rep.add(f"**{label}**, {dur:g} s simulated:\n\n" +
                md_table(["safety", "sub-steps per deck step", "energy-balance error",
                          "position error / r", "compute s per simulated s"], rows) + "\n")
        if pts:
            p = np.array(pts)
            axs[0].loglog(p[:, 0], np.maximum(p[:, 1], 1e-17), "o-", label=label.split(" ")[0])
            q = p[p[:, 3] != ref_safety]
            axs[1].loglog(q[:, 0], np.maximum(q[:, 2], 1e-17), "o-", label=label.split(" ")[0])
            for x, y, z, s in pts:
                axs[0].annotate(f"{s:g}", (x, max(y, 1e-17)), fontsize=6)
        if ci == 0 and pts:
            rep.headline["drop_dt"] = pts
    axs[0].set_xlabel("compute s per simulated s")
    axs[0].set_ylabel("|energy-balance error| / energy turned over")
    axs[1].set_xlabel("compute s per simulated s")
    axs[1].set_ylabel(f"position error / r (reference: safety {ref_safety})")
    from matplotlib.ticker import NullFormatter
    for a in axs:
        a.grid(True, which="both", alpha=0.3)
        a.xaxis.set_minor_formatter(NullFormatter())
        if a.get_legend_handles_labels()[0]:
            a.legend(fontsize=7)
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    rep.figure(fig, "timestep.png", "energy-balance and position error against compute time for "
               "several sub-step safety factors (labels); position reference: the finest run")
    section_dense_pack(rep)


def section_dense_pack(rep: Report) -> None:
    """The dense FCC block (benchmarks/bench_timestep.py): pair estimate vs network control vs
    a fixed fine step."""
    import bench_timestep
    T = 0.01 if rep.quick else 0.03
    table = bench_timestep.rows(T)
    rep.add("### A dense pack: the contact network against the stiffest pair\n\n"
            "63 exact NURBS spheres in FCC order (12 contacts each inside, particle C's mass, "
            f"the paper's contact law, zero gravity, walls touching the outer spheres), {T:g} s "
            f"at the deck step 1e-3 s (`benchmarks/bench_timestep.py`). The stiffest pair's "
            f"critical step is {table[1]['dt_pair']:.3g} s, the network's highest mode "
            f"{table[1]['dt_net']:.3g} s. Rattle = period-2 amplitude of the centroids over the "
            "last 40 internal steps (invisible in the kinetic energy the monitors show); "
            "position error = largest distance of the final centroids from the fine run's.\n\n"
            + md_table(["run", "sub-steps per deck step", "rattle (m)", "kinetic energy (J)",
                        "energy-balance error (J)", "position error (m)", "wall time (s)"],
                       [[r["label"], r["substeps"], fmt(r["rattle"]), fmt(r["kinetic"]),
                         fmt(r["balance"]), fmt(r["x_err"]) if r["x_err"] else "0 (reference)",
                         fmt(r["wall"], ".2f")] for r in table]) + "\n")


# =========================================================================== 5. cost
def _scaling_deck(N: int, steps: int, d: Path) -> Path:
    """N particles in a box of volume N × 1 L (base side (N/2 L)^(1/3), height twice that)."""
    from decks import paper_mix_deck
    side = (N * 1.0e-3 / 2) ** (1 / 3)
    d.mkdir(parents=True, exist_ok=True)
    p = d / "case.inp"
    p.write_text(paper_mix_deck(N, (side, side, 2 * side), 2 * side, [steps * 1e-3], d / "results"))
    return p


def section_cost(rep: Report, workdir: Path) -> None:
    from nurbsdem.io.deck import parse_deck
    from nurbsdem.solver import Solver
    plt = _plt()
    quick = rep.quick
    rep.add("## 5. Cost of a run\n")
    rep.add(rep.stamp_line() + "\n")
    counts = [14, 112, 1000] if quick else [14, 112, 1000, 10000]
    steps = {14: 20, 112: 20, 1000: 20} if quick else {14: 300, 112: 300, 1000: 300, 10000: 200}
    rep.add(
        "Decks written by the report: `Random` placement of A, B, C (1/3 each) in a box of "
        "volume N × 1 L (base side (N/2 L)^(1/3), height twice that), released at rest, the "
        "paper's contact law and TimeStep 1e-3 s (sub-stepped by the solver); monitors every "
        "deck step, no VTK or checkpoint during the run. Time per step = (global search + LCP + "
        "forces/integration) / deck steps; set-up and output reported apart. The particles are "
        "falling and the lower layers reach the floor during the run, so the contact count "
        "(LCPs per step) is given with each row.\n")
    rows, pts = [], []
    for N in counts:
        d = workdir / f"scale_{N}"
        deck = _scaling_deck(N, steps[N], d)
        t0 = time.perf_counter()
        m = parse_deck(deck)
        t_parse = time.perf_counter() - t0
        s = Solver(m, quiet=True).run()
        t = s.timers
        comp = t["global search"] + t["LCP"] + t["forces + integration"]
        per = comp / s.steps
        rows.append([N, s.steps, f"{s.substeps / s.steps:.0f}", fmt(per * 1e3, ".2f"),
                     fmt(per / N * 1e6, ".2f"),
                     " / ".join(f"{100 * t[k] / comp:.0f}" for k in ("global search", "LCP",
                                                                      "forces + integration")),
                     f"{s.lcps / s.steps:.1f}", s.failed,
                     fmt(s.lcps / t["LCP"], ".3g") if s.lcps and t["LCP"] > 0 else "– (no LCP)",
                     fmt(t_parse, ".1f"), fmt(t["setup"], ".1f"), fmt(t["output"], ".2f")])
        pts.append((N, per, per / N))
    rep.add(md_table(["particles", "deck steps", "sub-steps", "ms per step", "µs per "
                      "particle-step", "split % (search / LCP / forces+int.)", "LCPs per step",
                      "failed LCPs",
                      "LCPs per s of LCP time", "placement s", "set-up s", "output s"], rows) + "\n")
    rep.headline["scaling"] = rows
    if len(pts) >= 2:
        p = np.array(pts)
        slope = np.polyfit(np.log(p[:, 0]), np.log(p[:, 1]), 1)[0]
        rep.add(f"Fitted growth of the cost per step: ∝ N^{slope:.2f} over N = "
                f"{int(p[0, 0])} … {int(p[-1, 0])}.\n")
        fig, ax = plt.subplots(figsize=(6, 4))
        ax.loglog(p[:, 0], p[:, 1] * 1e3, "o-", label="ms per deck step")
        ax.loglog(p[:, 0], p[:, 2] * 1e6, "s--", label="µs per particle-step")
        ax.set_xlabel("particles")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
        fig.tight_layout(rect=(0, 0.03, 1, 1))
        rep.figure(fig, "scaling.png", "cost per deck step (1e-3 s) against the number of "
                   "particles (falling particles, see the LCP counts in the table)")
    if not quick:
        _section_large(rep, workdir)
        _section_settled(rep)
    section_spheres(rep)
    section_drum(rep)
    section_beverloo(rep)
    section_point_surface(rep)
    _section_paper(rep, workdir, quick)


def _section_paper(rep: Report, workdir: Path, quick: bool) -> None:
    """The paper's example as shipped and with few samples (:func:`_paper_runs`), its time
    split, and its damping variants."""
    rep.add("### The paper's example\n")
    if quick:
        rep.add("Not run in quick mode: the full mode runs `inputs/paper/compaction.inp` "
                "(all six steps) and reports its time split here.\n")
        return
    shipped, few = _paper_runs(workdir)
    s, sparse = shipped[0], few[0]
    t = s.timers
    rows = []
    for k, v in t.items():
        rows.append([k, fmt(v, ".1f"), f"{100 * v / s.wall_time:.1f}"])
        if k == "forces + integration":        # its measured parts (RunSummary.split)
            rows += [[f"… of which {part}", fmt(w, ".1f"), f"{100 * w / s.wall_time:.1f}"]
                     for part, w in s.split.items()]
    rest = s.wall_time - sum(t.values())
    rows.append(["other (steps bookkeeping)", fmt(rest, ".1f"), f"{100 * rest / s.wall_time:.1f}"])
    rows.append(["**total wall time**", fmt(s.wall_time, ".1f"), "100"])
    rep.add(f"`inputs/paper/compaction.inp` as shipped (`Damping Implicit Accuracy 3e-5 "
            f"Safety 0.7` on its timed steps), run in full by the report: {s.particles} particles "
            f"at the end, {s.simulated_time:.2f} s simulated, {s.steps} deck steps "
            f"({s.substeps} internal; {s.accuracy_repeats} deck steps repeated by the accuracy "
            f"control), {s.lcps} LCPs ({s.lcps / s.wall_time:.0f} per second of "
            f"wall time, {s.lcps / t['LCP'] if t['LCP'] else float('nan'):.3g} per second of LCP "
            f"time; {_lcps_per_active(s):.2f} LCPs per active contact and contact "
            f"evaluation: {s.evaluations} evaluations, "
            f"{s.active_total / max(s.steps, 1):.0f} active contacts at the end of a deck step "
            f"on average), {s.degenerated} "
            f"degenerated, {s.failed} failed; energy-balance error "
            f"{abs(s.balance_error):.3e} J ({abs(s.balance_error) / max(s.balance_scale, 1e-300):.2e} "
            f"of the energy turned over). {_best_of(shipped)}\n\n" +
            md_table(["part", "s", "%"], rows) + "\n\n" +
            f"Time outside the LCP kernel (everything but the LCP row): "
            f"{_outside_lcp(s):.2f} × the LCP time.\n")
    _paper_with_few_frames(rep, workdir, s, few)
    one = _paper_one_thread(rep, workdir, few[0])
    _section_damping(rep, workdir, s)
    rep.headline["paper"] = dict(wall=s.wall_time, timers=t, lcps=s.lcps, steps=s.steps,
                                 sparse_wall=sparse.wall_time, sparse_lcp=sparse.timers["LCP"],
                                 sparse_frames=sparse.frames,
                                 frames=sparse.frames_shipped,
                                 lcps_per_active=_lcps_per_active(s),
                                 outside=_outside_lcp(s), sparse_outside=_outside_lcp(sparse),
                                 one_thread_outside=_outside_lcp(one),
                                 particles=s.particles, failed=s.failed)


#: runs of the paper deck as shipped and with few samples, alternated (the report takes the
#: faster of each: a shared machine's speed can move by a third from one minute to the next)
PAPER_ROUNDS = 2


def _paper_runs(workdir: Path) -> tuple[list, list]:
    """The paper deck as shipped and with ``VTK Every 0.5`` (``bench_paper.deck_text``: a few
    ParaView samples instead of the deck's one every 0.01 s), alternated PAPER_ROUNDS times,
    each in a fresh folder: (shipped runs, few-sample runs), each list fastest first (the
    summaries carry ``folder`` and ``order``: when each ran)."""
    import bench_paper

    from nurbsdem.io.deck import parse_deck
    from nurbsdem.solver import Solver
    runs: dict[bool, list] = {False: [], True: []}
    for k in range(PAPER_ROUNDS):
        for few in (False, True):
            name = f"paper{'_few_frames' if few else ''}_{k + 1}"
            deck = workdir / f"{name}.inp"
            deck.write_text(bench_paper.deck_text(few_frames=few, quick=False))
            s = Solver(parse_deck(deck), output=workdir / name, quiet=True).run()
            s.folder, s.order = workdir / name, 2 * k + few + 1
            runs[few].append(s)
    return (sorted(runs[False], key=lambda r: r.wall_time),
            sorted(runs[True], key=lambda r: r.wall_time))


def _walls_in_order(runs: list) -> str:
    """The runs' wall times in the order they ran ("33.3 s, 32.1 s")."""
    return ", ".join(f"{r.wall_time:.1f} s" for r in sorted(runs, key=lambda r: r.order))


def _best_of(runs: list) -> str:
    """The sentence saying which of the alternated runs a figure is from."""
    return (f"The faster of {len(runs)} runs alternated with the deck with few samples below "
            f"(their wall times in the order run: {_walls_in_order(runs)}; a shared machine's "
            f"speed can move by up to a third from one minute to the next, and a run's contact "
            f"work is the same bits each time).")


def _paper_with_few_frames(rep: Report, workdir: Path, shipped, runs: list) -> None:
    """What writing the samples costs the run: the faster of the ``runs`` of the deck with
    few samples (:func:`_paper_runs`, fastest first) beside the faster run as shipped (its
    summary gains ``frames``: its particle samples, and ``frames_shipped``)."""
    import bench_paper

    s = runs[0]
    t, t0 = s.timers, shipped.timers
    frames = [sorted((r.folder / "vtk").glob("particles_*.vtu")) for r in (s, shipped)]
    mb = sum(f.stat().st_size for f in frames[1]) / max(len(frames[1]), 1) / 1e6
    s.frames, s.frames_shipped = len(frames[0]), len(frames[1])
    rep.add(f"The same deck with `VTK Every {bench_paper.FEW_EVERY}` ({len(frames[0])} "
            f"ParaView samples of the "
            f"particles instead of {len(frames[1])}, {mb:.2f} MB each; monitors as shipped), "
            f"the faster of its runs (in the order run: {_walls_in_order(runs)}): "
            f"**{s.wall_time:.1f} s** wall "
            f"time against {shipped.wall_time:.1f} s, LCP {t['LCP']:.1f} s against "
            f"{t0['LCP']:.1f} s, output (main thread) {t['output']:.1f} s against "
            f"{t0['output']:.1f} s, {s.substeps} internal steps against {shipped.substeps} "
            f"(the same when the two runs' contact states agree to the bit); time outside the "
            f"LCP {_outside_lcp(s):.2f} × the LCP time (of forces + integration "
            f"{t['forces + integration']:.1f} s: "
            + ", ".join(f"{k} {v:.1f} s" for k, v in s.split.items()) + "). The samples are "
            f"written by a worker thread; what they cost beyond its own CPU time is the LCP's "
            f"two threads running slower meanwhile when the machine has no spare core.\n")


def _paper_one_thread(rep: Report, workdir: Path, two):
    """The deck with few samples once more on one numba thread (the LCP batch is the one part
    of this 112-particle deck that the second thread speeds up, so the ratio of the time
    outside the LCP to the LCP time depends on the count), beside ``two``, the faster run on all threads; returns
    its summary."""
    import bench_paper
    import numba

    from nurbsdem.io.deck import parse_deck
    from nurbsdem.solver import Solver
    deck = workdir / "paper_one_thread.inp"
    deck.write_text(bench_paper.deck_text(few_frames=True, quick=False))
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        s = Solver(parse_deck(deck), output=workdir / "paper_one_thread", quiet=True).run()
    finally:
        numba.set_num_threads(threads)
    t, t2 = s.timers, two.timers
    same = s.lcps == two.lcps and s.substeps == two.substeps
    rep.add(f"The same deck on one numba thread (`bench_paper.py --threads 1`): "
            f"**{s.wall_time:.1f} s** wall time, LCP {t['LCP']:.1f} s against "
            f"{t2['LCP']:.1f} s on {threads} threads ({t['LCP'] / max(t2['LCP'], 1e-300):.2f} ×), "
            f"outside the LCP {s.wall_time - t['LCP']:.1f} s against "
            f"{two.wall_time - t2['LCP']:.1f} s: **{_outside_lcp(s):.2f} ×** the LCP time "
            f"against {_outside_lcp(two):.2f} × ({s.lcps} LCPs and {s.substeps} internal steps"
            f"{', the same as on all threads' if same else ' (NOT the same as on all threads)'})."
            f" The time outside the LCP is serial passes over ~100-300 rows, which do not gain "
            f"from a second thread at this size; the LCP batch does.\n")
    return s


def _outside_lcp(s) -> float:
    """The wall time outside the LCP kernel over the LCP time."""
    return (s.wall_time - s.timers["LCP"]) / max(s.timers["LCP"], 1e-300)


def _lcps_per_active(s) -> float:
    """LCPs solved per active contact and contact evaluation: the LCPs
    over the evaluations times the mean number of active contacts (sampled at the end of
    each deck step)."""
    return s.lcps / max(s.evaluations * s.active_total / max(s.steps, 1), 1e-300)


def _section_damping(rep: Report, workdir: Path, shipped) -> None:
    """The paper's example again with explicit and with plain implicit dashpots, and as
    shipped with the default Safety 0.5 (benchmarks/bench_damping.py), beside the shipped
    deck's run ``shipped``."""
    import bench_damping as bd
    runs = [bd.run(*v, workdir) for v in bd.VARIANTS[:2]]
    runs.append(bd.figures(bd.VARIANTS[2][0], shipped, shipped.folder))
    runs.append(bd.run(*bd.VARIANTS[3], workdir))
    explicit, implicit, ours, default_safety = runs
    head, body = bd.table(runs)
    rep.add("The same deck with each way of integrating the dashpots on its four timed steps "
            "(`benchmarks/bench_damping.py`): `Damping Explicit` (the dashpots limit the step), "
            "`Damping Implicit` (normal dashpots at the velocity after the step's two half "
            "kicks, `dynamics/implicit.py`: the springs alone set the step), and the shipped "
            "`Damping Implicit Accuracy 3e-5` (deck steps whose energy-balance error grows "
            "beyond 3e-5 × the energy scale are repeated with twice the sub-steps, "
            "`dynamics/accuracy.py`), all with the shipped `Safety 0.7` (the sub-step is 0.7 × "
            "the contact network's stability limit), and the shipped settings with the default "
            "`Safety 0.5`. The energy-balance error is the integration error, which "
            "grows as h²; the pack is one realisation of a chaotic process (the lid's height "
            "after ToContact, the pack's top + 5 mm, and its reaction are outcomes, not "
            "invariants).\n\n"
            + md_table(head, body) + "\n\n"
            f"Wall time against the explicit run: implicit "
            f"**{implicit['wall'] / explicit['wall']:.2f}**, implicit with the accuracy control "
            f"(shipped) **{ours['wall'] / explicit['wall']:.2f}**; the shipped deck against "
            f"the same at Safety 0.5: **{ours['wall'] / default_safety['wall']:.2f}** "
            f"({ours['substeps']} against {default_safety['substeps']} internal steps).\n")
    rep.headline["damping"] = dict(explicit=explicit["wall"], implicit=implicit["wall"],
                                   balance=implicit["balance"], shipped=ours["wall"],
                                   shipped_balance=ours["balance"],
                                   explicit_balance=explicit["balance"],
                                   safety_default=default_safety["wall"],
                                   safety_default_balance=default_safety["balance"])


def _section_large(rep: Report, workdir: Path) -> None:
    """Up to 10^5 particles: 10 deck steps of the same decks (all still falling, the lowest
    layer on the floor), to see how the cost per step grows with N."""
    from nurbsdem.io.deck import parse_deck
    from nurbsdem.solver import Solver
    rows = []
    for N in (1000, 10000, 100000):
        deck = _scaling_deck(N, 10, workdir / f"large_{N}")
        t0 = time.perf_counter()
        m = parse_deck(deck)
        t_parse = time.perf_counter() - t0
        s = Solver(m, quiet=True, write_output=False).run()
        t = s.timers
        per = (t["global search"] + t["LCP"] + t["forces + integration"]) / s.steps
        rows.append([N, f"{s.substeps / s.steps:.0f}", fmt(per * 1e3, ".1f"),
                     fmt(per / N * 1e6, ".2f"), f"{s.lcps / s.steps:.0f}", fmt(t_parse, ".1f"),
                     fmt(t["setup"], ".1f")])
    rep.add("Up to 10^5 particles, 10 deck steps of the same decks (the particles still fall; "
            "the lowest layer reaches the floor): the cost per step grows about linearly once "
            "the fixed cost of a step is amortised (a settled pack: below).\n\n" +
            md_table(["particles", "sub-steps", "ms per step", "µs per particle-step",
                      "LCPs per step", "placement s", "set-up s"], rows) + "\n")


def _section_settled(rep: Report) -> None:
    """Settled dense packs of 10^4 … 10^5 paper particles: copies of one settled pack side by
    side (benchmarks/bench_settled_pack.py --tiles)."""
    import bench_settled_pack as bsp
    n, settle, relax, steps = 10000, 0.9, 3, 5
    tilings = [(1, 1), (2, 1), (5, 1), (5, 2)]
    res = bsp.tiles(n, settle, tilings, relax, steps, bsp.HERE / ".cache")
    rows = [[r["n"], r["tiles"], f"{r['substeps']:.0f}", fmt(r["ms_per_step"], ".0f"),
             fmt(r["us_per_particle_step"], ".1f"),
             " / ".join(fmt(v, ".1f") for v in r["split_us"]), f"{r['active_per_step']:.0f}",
             f"{r['lcps_per_step']:.0f}", r["failed"], fmt(r["kinetic_end"], ".2g")]
            for r in res["rows"]]
    growth = ", ".join(f"{part} N^{e:.2f}" for part, e in res["part_exponents"].items())
    rep.add(f"Settled dense packs, `benchmarks/bench_settled_pack.py --tiles`: {n} paper "
            f"particles settled under gravity for {settle} s (the checkpoint of section 8, kept "
            f"in `benchmarks/.cache/`), laid side by side nx × ny times in a box as much wider "
            f"(10^5 settled particles without the hours their deposition would take); {relax} "
            f"deck steps to absorb the seams where copies meet (overlaps of at most two wall "
            f"penetrations), then {steps} deck steps timed (numba threads: all cores). "
            f"Cost per deck step ∝ N^{res['exponent']:.2f} over N = {res['rows'][0]['n']} … "
            f"{res['rows'][-1]['n']} ({growth}).\n\n" +
            md_table(["particles", "copies", "sub-steps", "ms per step",
                      "µs per particle-step", "split µs (search / LCP / forces+int.)",
                      "contacts", "LCPs per step", "failed LCPs",
                      "kinetic energy at the end J"], rows) + "\n")
    rep.headline["settled"] = res


def section_point_surface(rep: Report) -> None:
    """An exact sphere against a NURBS particle: the point-to-surface problem against the
    LCP (benchmarks/bench_point_surface.py)."""
    import bench_point_surface as bp
    rep.add("### An exact sphere against a NURBS particle\n")
    rows = bp.run(300 if rep.quick else 3000)
    table = [[r["shape"], r["pairs"], r["penetrating"], fmt(r["lcp_cold"], ".1f"),
              fmt(r["lcp_warm"], ".1f"), fmt(r["pt_cold"], ".2f"), fmt(r["pt_warm"], ".2f"),
              f"{100 * r['solved_cold']:.0f} / {100 * r['solved_warm']:.0f}",
              fmt(r["err_sd"], ".1e"), fmt(r["err_n"], ".1e"),
              fmt(r["err_exact"], ".1e") if np.isfinite(r["err_exact"]) else "–"] for r in rows]
    rep.add("`benchmarks/bench_point_surface.py`: a sphere (r = 10 mm) against a particle in "
            "random poses (separated and penetrating), one thread, µs per pair. The point-to-"
            "surface solver (2 parameters) is warm-started from the LCP's row; the pairs it "
            "does not solve (the sphere's centre inside the particle, the nearest point on a "
            "crease or another patch) go to the LCP. Errors: against the LCP on the solved "
            "pairs (signed distance / bounding radius, normal in rad) and, for the ellipsoid, "
            "against the closed-form distance (m).\n\n" +
            md_table(["particle", "pairs", "penetrating", "LCP cold", "LCP warm",
                      "point cold", "point warm", "solved % cold / warm", "max Δsd/R vs LCP",
                      "max normal error vs LCP", "max Δsd vs closed form (m)"], table) + "\n")
    rep.headline["point_surface"] = rows


def section_spheres(rep: Report) -> None:
    """112 exact spheres against the real Yade (benchmarks/bench_yade.py), side by side."""
    import bench_yade
    rep.add("### 112 spheres against Yade\n")
    r = bench_yade.main(["--quick"] if rep.quick else [])
    nd, yd = r["nurbsdem"], r["yade"]
    rows = [["nurbsdem (compiled deck steps)", fmt(nd["loop"], ".2f"), nd["substeps"],
             fmt(nd["height"], ".4f")]]
    if isinstance(yd, dict):
        rows.append(["Yade " + "(`-j1`)", fmt(yd["wall"], ".2f"), "", fmt(yd["height"], ".4f")])
    rep.add(f"`benchmarks/bench_yade.py`: the paper's box and contact law with 112 exact spheres "
            f"(volume-equivalent radii of A, B, C), released at rest, {r['T']} s at dt 1e-4 s, "
            "one thread each, the same positions; time of the time loop (compiled kernels "
            f"cached: a warm-up run first); the faster of {bench_yade.ROUNDS} runs of each, "
            "alternated (nurbsdem: " + ", ".join(f"{t:.2f}" for t in nd["loops"]) + " s"
            + ("; Yade: " + ", ".join(f"{t:.2f}" for t in yd["walls"]) + " s"
               if isinstance(yd, dict) else "") + ").\n\n" +
            md_table(["code", "time loop s", "internal steps", "mean height at the end m"], rows)
            + "\n")
    if isinstance(yd, dict):
        ratio = nd["loop"] / yd["wall"]
        rep.add(f"Ratio nurbsdem / Yade: **{ratio:.2f}**; mean heights differ by "
                f"{100 * abs(nd['height'] / yd['height'] - 1):.2f} %.\n")
        rep.headline["spheres"] = dict(ratio=ratio, nurbsdem=nd["loop"], yade=yd["wall"])
    else:
        rep.add(f"{yd}.\n")
        rep.headline["spheres"] = dict(ratio=None, nurbsdem=nd["loop"], yade=None)


def section_drum(rep: Report) -> None:
    """A rotating drum of spheres against the real Yade (benchmarks/bench_drum.py)."""
    import bench_drum
    rep.add("### A rotating drum against Yade\n")
    r = bench_drum.main(["--quick"] if rep.quick else [])
    rows = [[name, fmt(res.get("loop", res.get("wall")), ".2f"),
             f"{res['angle']:.2f} ± {res['angle_spread']:.2f}", fmt(res["torque"], ".4f")]
            for name, res in (("nurbsdem, exact NURBS drum", r["nurbs"]),
                              ("nurbsdem, mesh drum", r["mesh"]),
                              (f"Yade, {bench_drum.SEGMENTS} facets", r["yade"]))
            if isinstance(res, dict)]
    rep.add(f"`benchmarks/bench_drum.py`: {r['count']} spheres (radii "
            f"{', '.join(str(x) for x in bench_drum.RADII)} m) in a drum of radius "
            f"{bench_drum.R_DRUM} m and length {bench_drum.LENGTH} m turning at Froude number "
            f"{bench_drum.FROUDE} after settling; the same positions, linear law and time step "
            "for both codes, one thread each; the dynamic angle of repose (the bed's tilt) and "
            f"the drive torque over the last {r['window']} s.\n\n"
            + md_table(["code", "time loop s", "angle of repose (deg)", "drive torque N m"],
                       rows) + "\n")
    y = r["yade"]
    if isinstance(y, dict):
        n = r["nurbs"]
        ratio = n["loop"] / y["wall"]
        rep.add(f"Ratio nurbsdem (NURBS drum) / Yade: **{ratio:.2f}**; angles differ by "
                f"{n['angle'] - y['angle']:+.2f} degrees, torques by "
                f"{100 * (n['torque'] / y['torque'] - 1):+.1f} %.\n")
        rep.headline["drum"] = dict(ratio=ratio, angle=n["angle"] - y["angle"])
    else:
        rep.add(f"{y}.\n")


def section_beverloo(rep: Report) -> None:
    """Silo discharge against Beverloo's law and against Yade, and the inlet's and outlet's
    share of the step (benchmarks/bench_beverloo.py), read from the JSON it wrote (its full
    run takes minutes of CPU: it is run on its own, not from here)."""
    import bench_beverloo as bb
    rep.add("### Silo discharge: Beverloo's law, Yade, and the inlet and outlet cost\n")
    cache = REPO / "benchmarks" / ".cache"
    path = next((p for p in (cache / "beverloo.json", cache / "beverloo_quick.json")
                 if p.exists()), None)
    if path is None:
        rep.add("Not measured: run `benchmarks/bench_beverloo.py` (it writes "
                "`benchmarks/.cache/beverloo.json`, which this section reads).\n")
        return
    r = json.loads(path.read_text())
    d = r["d"]
    fill = r["fill"]
    rep.add(f"`benchmarks/bench_beverloo.py`{' (quick: a smoke test)' if r['quick'] else ''}: "
            f"{r['count']} spheres (radii {', '.join(f'{x * 1e3:g}' for x in r['radii'])} mm, "
            f"d {d * 1e3:g} mm) poured by an inlet into a square silo {r['side'] * 1e3:.0f} mm "
            f"wide, settled (bed {fill['top'] / d:.1f} d high, bulk density "
            f"{fill['rho_b']:.0f} kg/m³), then discharged for {r['T']} s through a circular "
            "orifice in a mesh floor into an outlet; W is the slope of the discharged mass over "
            f"the run less its first {100 * r.get('lead', bb.LEAD):.0f} % and last "
            f"{100 * r.get('tail', bb.TAIL):.0f} %; "
            "one thread; the time loop includes the inlet's and outlet's exchanges.\n\n")
    rows = [[f"{o['ratio']:g}", fmt(o["W"], ".4f"),
             f"{fmt(o['halves'][0], '.4f')} / {fmt(o['halves'][1], '.4f')}",
             fmt(o["C_mid"], ".3f"), f"{o['top_end'] / d:.1f}", fmt(o["loop"], ".1f"),
             f"{100 * o['flow'] / o['loop']:.1f}", fmt(o["dt"], ".3g")] for o in r["orifices"]]
    rep.add(md_table(["D / d", "W kg/s", "W of the window's halves", "C at n 2.5, k 1.5",
                      "bed left (d)", "time loop s", "outlet % of loop", "mean step s"], rows)
            + "\n\n")
    fit, fixed = r.get("fit"), r.get("fit_n25")
    if fit:
        def par(f, k, spec):
            mark = "inside" if f["inside"][k] else "**outside**"
            lo, hi = bb.RANGES[k]
            return f"{f[k]:{spec}} ± {f.get('sd_' + k, float('nan')):.2g} ({mark} {lo}–{hi})"
        rep.add(f"Beverloo fit (`postproc/beverloo.py`, ± its standard errors): exponent "
                f"{par(fit, 'n', '.2f')}, k {par(fit, 'k', '.2f')}, C {par(fit, 'C', '.3f')}; "
                f"RMS of W {100 * fit['rms']:.2f} %.")
        if fixed:
            rep.add(f" At n = 2.5: k {par(fixed, 'k', '.2f')}, C {par(fixed, 'C', '.3f')}; "
                    f"RMS of W {100 * fixed['rms']:.2f} %.")
        rep.add("\n")
        rep.headline["beverloo"] = dict(n=fit["n"], k=fit["k"], C=fit["C"])
    else:
        rep.add("No Beverloo fit: it needs three orifices.\n")
    rep.add(f"Inlet and outlet exchanges: **{100 * r['flow_share']:.1f} %** of the time loop "
            f"(target at most 5 %; the fill's inlet {100 * fill['flow'] / fill['loop']:.1f} %).\n")
    y = r["yade"]
    if isinstance(y, dict):
        o = r["orifices"][0]
        rep.add(f"Yade, the same bed through D = {o['ratio']:g} d: time loop {y['wall']:.1f} s "
                f"against nurbsdem's {o['loop']:.1f} s, ratio nurbsdem / Yade "
                f"**{r['ratio']:.2f}** (target at most 2); W {y['W']:.4f} kg/s, nurbsdem's "
                f"differs by {100 * (o['W'] / y['W'] - 1):+.1f} %."
                + (f" CPU time: nurbsdem's whole run {o['cpu']:.1f} s, Yade's time loop "
                   f"{y['cpu']:.1f} s, ratio {r['cpu_ratio']:.2f}." if "cpu_ratio" in r else "")
                + "\n")
        rep.headline["beverloo_yade"] = r["ratio"]
    else:
        rep.add(f"{y}.\n")


# =========================================================================== 6. fit
def section_fit(rep: Report) -> None:
    """Accuracy of ``nurbsdem fit`` on exact inputs (ellipsoid meshes) and on the synthetic
    scanned grain; references: the analytic ellipsoid (distance, volume, inertia)."""
    import trimesh
    from nurbsdem.geometry.fit import FitInput, fit_particle, read_input
    rep.add("## 6. Fit to meshes (`nurbsdem fit`)\n")
    rep.add(rep.stamp_line() + "\n")
    ax = np.array([0.03, 0.02, 0.012])
    v_ex = 4.0 / 3.0 * np.pi * ax.prod()
    j_ex = v_ex / 5.0 * np.diag([ax[1] ** 2 + ax[2] ** 2, ax[0] ** 2 + ax[2] ** 2,
                                 ax[0] ** 2 + ax[1] ** 2])
    subs = (4,) if rep.quick else (2, 3, 4, 5)
    ncps = (6, 8) if rep.quick else (5, 6, 8, 10)
    rows = []
    best = None
    for sub in subs:
        m = trimesh.creation.icosphere(subdivisions=sub)
        m.apply_scale(ax)
        for n_cp in ncps:
            t0 = time.perf_counter()
            r = fit_particle(FitInput(np.asarray(m.vertices), m, "ellipsoid"), n_cp=n_cp)
            dt = time.perf_counter() - t0
            X = np.concatenate([p.points(*[a.ravel() for a in np.meshgrid(
                np.linspace(0, 2, 40), np.linspace(0, 2, 40), indexing="ij")])
                for p in r.shape.patches])
            y = X / ax
            F = np.linalg.norm(y, axis=1)
            e = np.abs((F - 1.0) / (np.linalg.norm(y / ax, axis=1) / F)) / r.size
            sh = r.shape
            dj = np.linalg.norm(sh.inertia - j_ex) / np.linalg.norm(j_ex)
            rows.append([len(m.vertices), n_cp, f"{r.smoothing:g}", fmt(r.err_max / r.size),
                         fmt(r.err_rms / r.size), fmt(e.max()), fmt(np.sqrt(np.mean(e ** 2))),
                         f"{100 * (sh.volume / v_ex - 1):+.4f}",
                         f"{100 * (m.volume / v_ex - 1):+.3f}", f"{100 * dj:.4f}",
                         f"{r.kink_deg:.2f}", fmt(sh.convexity.relative), f"{dt:.1f}"])
            if best is None or e.max() < best[0]:
                best = (float(e.max()), len(m.vertices), n_cp,
                        float(100 * (sh.volume / v_ex - 1)))
    rep.add("Ellipsoid 30 × 20 × 12 mm as an icosphere mesh (every vertex on the ellipsoid), "
            "fitted with the defaults (bicubic, smoothing chosen by the convexity check). "
            "*Fit error*: what `nurbsdem fit` prints (distance of the input vertices to the "
            "surface / size, size = hull bounding-box diagonal). *True error*: distance of "
            "40 × 40 surface points per patch to the exact ellipsoid (first-order distance "
            "|F − 1| / |∇F|) / size. Volume and inertia (volume inertia tensor, Frobenius norm) "
            "against the analytic values; the mesh's own volume error for comparison.\n\n"
            + md_table(["vertices", "control points", "smoothing", "fit error max",
                        "fit error RMS", "true error max", "true error RMS", "volume err %",
                        "mesh volume err %", "inertia err %", "max kink (deg)",
                        "non-convexity", "s"], rows) + "\n")
    scan = REPO / "inputs" / "shapes" / "grain_scan.ply"
    if scan.is_file():
        t0 = time.perf_counter()
        r = fit_particle(read_input(scan), name="synthetic grain")
        dt = time.perf_counter() - t0
        dj = np.linalg.norm(r.shape.inertia - r.inertia_mesh) / np.linalg.norm(r.inertia_mesh)
        rep.add(f"The synthetic scanned grain of the README (`inputs/shapes/grain_scan.ply`, "
                f"{r.n_points} points, noise σ = 15 µm): fit error max {fmt(r.err_max / r.size)}"
                f", RMS {fmt(r.err_rms / r.size)} of the size {r.size * 1e3:.1f} mm (RMS "
                f"{r.err_rms * 1e6:.1f} µm: the noise); volume "
                f"{100 * (r.shape.volume / r.volume_mesh - 1):+.2f} % and inertia "
                f"{100 * dj:.2f} % against the input mesh; largest kink {r.kink_deg:.2f}°; "
                f"non-convexity {fmt(r.shape.convexity.relative)} of the size; {dt:.1f} s.\n")
    rep.headline["fit"] = dict(best_err=best[0], vertices=best[1], n_cp=best[2],
                               vol_err=best[3])


# =========================================================================== 7. Hertz
def section_hertz(rep: Report) -> None:
    """Hertz–Mindlin with the exact local curvature: the exact force-equivalent
    radius against the volume-equivalent radius other codes use, as a force error at equal
    overlap, on ellipsoids and the paper particles; its cost; Chung & Ooi's test 4."""
    import bench_hertz as bh
    rep.add("## 7. Hertz–Mindlin with the exact curvature\n")
    rep.add(rep.stamp_line() + "\n")
    rows = bh.radius_table(rep.quick)
    n = rows[0]["samples"] if rows else 0
    rep.add(f"Contact points sampled over each surface ({n} per shape: a grid of cell centres "
            "per patch); *wall*: the particle on a flat wall at that point; *pair*: two copies "
            "touching at random sample points, the second turned about the normal at random. "
            "R: the exact force-equivalent radius of elliptical Hertz from both surfaces' "
            "principal curvatures and directions (`nurbsdem/geometry/curvature.py`). R_v: the "
            "volume-equivalent radius (3V/4π)^(1/3) (halved for a pair), what codes without the "
            "curvature use. Force error of R_v at equal overlap: √(R_v/R) − 1 (F ∝ √R δ^(3/2)); "
            "median of its magnitude and its range. Fallbacks: samples whose curvature is "
            "degenerate (bounding-sphere radius).\n\n" + md_table(
                ["shape", "contact", "R_v (mm)", "R min / median / max (mm)",
                 "force error median", "force error range", "fallbacks"],
                [[r["shape"], r["kind"], f"{1e3 * r['r_v']:.2f}",
                  f"{1e3 * r['r_min']:.2f} / {1e3 * r['r_med']:.2f} / {1e3 * r['r_max']:.2f}",
                  f"{100 * r['err_med']:.1f} %",
                  f"{100 * r['err_lo']:+.1f} … {100 * r['err_hi']:+.1f} %", r["fallback"]]
                 for r in rows]) + "\n")
    us = bh.curvature_cost(4000 if rep.quick else 20000)
    rep.add(f"Cost of the curvature (both surfaces' second derivatives, the relative curvature "
            f"and the elliptic-integral radius), compiled, one thread: {us:.1f} µs per contact "
            "(paper particle pairs), on top of the LCP.\n")
    angles = [10, 20, 40, 60, 80] if rep.quick else list(range(5, 90, 5))
    ob = bh.oblique_test4(angles)
    rep.add("Chung & Ooi (2011) test 4: aluminium-oxide sphere (R 2.5 mm, E 380 GPa, ν 0.23, "
            "μ 0.092) on a rigid plane at 3.9 m/s, elastic. Where the sphere slides throughout "
            "(tan θ > 7μ, θ > 32.8°) rigid-body theory is exact: e_t = 1 − 2μ/tan θ, "
            "ω = 5μ v_n/R; below, Mindlin's tangential compliance (the benchmark's curves; the "
            "contact point recoils, rebound angle < 0).\n\n" + md_table(
                ["incidence (°)", "e_t", "e_t theory", "ω (rad/s)", "ω theory",
                 "rebound (°)", "rebound theory"],
                [[f"{r['angle']:.0f}", f"{r['et']:.4f}",
                  "stick/slip" if math.isnan(r["et_slide"]) else f"{r['et_slide']:.4f}",
                  f"{r['omega']:.1f}",
                  "stick/slip" if math.isnan(r["omega_slide"]) else f"{r['omega_slide']:.1f}",
                  f"{r['rebound']:.2f}",
                  "stick/slip" if math.isnan(r["rebound_slide"]) else f"{r['rebound_slide']:.2f}"]
                 for r in ob]) + "\n")
    mf = bh.glass_anvil([a for a, _ in bh.MFIX_DEM05])
    kh = bh.glass_anvil([a for a, _ in bh.KHARAZ_2001])
    rep.add("The same sphere on a soda-lime glass anvil (E 70 GPa, ν 0.25, e 0.98): MFIX's "
            "verification case DEM-05 (its published curve) and Kharaz et al.'s (2001) "
            "measurements. From 8° on the Hertz–Mindlin law agrees with MFIX to 0.01; below "
            "6° the codes differ (MFIX tends to e_t = 1) and the measurements lie lower "
            "still.\n\n" + md_table(
                ["incidence (°)", "e_t", "MFIX DEM-05", "difference"],
                [[f"{a:.2f}", f"{e:.4f}", f"{ref:.4f}", f"{e - ref:+.4f}"]
                 for (a, ref), e in zip(bh.MFIX_DEM05, mf)]) + "\n\n" + md_table(
                ["incidence (°)", "e_t", "measured (Kharaz et al.)", "difference"],
                [[f"{a:.2f}", f"{e:.4f}", f"{ref:.4f}", f"{e - ref:+.4f}"]
                 for (a, ref), e in zip(bh.KHARAZ_2001, kh)]) + "\n")
    pk = bh.pack_paths(30 if rep.quick else 60)
    rep.add(f"A pack of {pk['n']} paper particles deposited under Hertz–Mindlin (E 1e8 Pa, ν "
            f"0.3, restitution 0.5, friction 0.5) for {pk['duration']:g} s: the compiled deck "
            f"steps {pk['compiled_s']:.2f} s against {pk['python_s']:.2f} s for the Python path "
            f"(the reference the compiled steps are checked against; several MPI ranks run it) "
            f"({pk['python_s'] / pk['compiled_s']:.1f} x; {pk['substeps']} internal steps, "
            f"{pk['lcps']} LCPs, at most {pk['active_max']} contacts, {pk['failed']} failed), "
            f"the results {'bit for bit equal' if pk['same'] else 'NOT equal'} (every sample, "
            "the monitors with `hertz.csv`): the equivalent radii come from the same curvature "
            "kernel at the same poses.\n")
    ell = [r for r in rows if r["shape"].startswith("ellipsoid") and r["kind"] == "wall"]
    rep.headline["hertz"] = dict(us=us, ell_err=max((r["err_hi"] for r in ell), default=0.0),
                                 pack=pk)


# =========================================================================== 8. MPI
def section_mpi(rep: Report) -> None:
    """Strong and weak scaling on MPI ranks (benchmarks/bench_mpi.py), results bit for bit
    equal to one rank, and the model of benchmarks/mpi_model.py for 16 and 64 ranks."""
    import bench_mpi
    import mpi_model
    from bench_settled_pack import pack_region
    rep.add("## 8. Runs on several MPI ranks\n")
    n, settle, measure = (600, 0.05, 3) if rep.quick else (10000, 0.9, 20)
    res = bench_mpi.main(["--n", str(n), "--settle", str(settle), "--measure", str(measure),
                          "--weak-n", "300" if rep.quick else "1500"])
    if not res:
        rep.add("**Not measured**: mpi4py or mpiexec is missing (`pip install "
                "'nurbsdem[mpi]'`).\n")
        return
    rows = []
    for r in res["strong"]:
        ghosts = [d["ghosts"] for d in r["domain"]]
        wait = [sum(d["seconds"].values()) / max(r["steps"], 1) for d in r["domain"]]
        rows.append([r["ranks"], r["threads"], fmt(r["per_step"], ".3f"), fmt(r["speedup"], ".2f"),
                     fmt(r["efficiency"], ".2f"), str(ghosts) if ghosts else "",
                     ", ".join(f"{w:.3f}" for w in wait),
                     "yes" if r["same"] else "**no**"])
    rep.add(f"`benchmarks/bench_mpi.py`: a pack of {n} paper particles settled for {settle} s "
            f"(once, on 2 ranks, from a checkpoint kept in `benchmarks/.cache/`), then {measure} "
            "deck steps of 1e-3 s from its checkpoint on each configuration (`mpiexec -n P`, "
            "`NUMBA_NUM_THREADS` threads per rank); time of the time loop per deck step, "
            "including the communication and the wait for the slowest rank.\n\n" +
            md_table(["ranks", "threads", "s per deck step", "speed-up", "efficiency",
                      "ghosts per rank", "s per deck step in communication (per rank)",
                      "results.h5 equal to 1 rank"], rows) + "\n")
    two = next((r for r in res["strong"] if r["ranks"] == 2), None)
    if two:
        rep.headline["mpi"] = dict(n=n, speedup=two["speedup"], same=two["same"])
    ws, w = res["weak_settled"], res["weak"]
    rep.add("Weak scaling (measured as far as this machine goes, 1 thread per rank): settled "
            f"packs of {ws[0]['n']} paper particles per rank: " +
            ", ".join(f"{r['ranks']} rank(s): {r['per_step']:.3f} s per deck step "
                      f"(efficiency {r['efficiency']:.2f})" for r in ws) +
            f"; falling packs of {w[0]['n']} per rank (little contact work: the per-step "
            "communication and the work every rank repeats for all particles show): " +
            ", ".join(f"{r['ranks']} rank(s): {r['per_step'] * 1e3:.0f} ms per deck step "
                      f"(efficiency {r['efficiency']:.2f})" for r in w) + ".\n")
    if not two:
        return
    m = mpi_model.calibrate(res["strong"], w, n, pack_region(n)[0])
    rows = []
    for big in (10 ** 4, 10 ** 5, 10 ** 6):
        for p in (2, 16, 64):
            e = mpi_model.efficiency(m, big, p)
            rows.append([big, p, f"{e['gamma']:.3f}", f"{e['bytes_per_internal_step'] / 1e3:.1f}",
                         fmt(e["compute"], ".3g"), fmt(e["comm"], ".3g"),
                         fmt(e["repeated"], ".3g"), f"{e['efficiency']:.2f}"])
    rep.add("**Modelled** (benchmarks/mpi_model.py; its docstring states every assumption): "
            f"calibrated by the runs above (t1 {m['t1']:.3f} s per deck step on one rank, "
            f"{m['s']:.1f} internal steps per deck step, ghost layer {m['w'] * 1e3:.0f} mm from "
            f"{m['g2']:.0f} ghosts per rank on 2 ranks, {m['G'] / 1e6:.2f} MB gathered per deck "
            f"step, {m['Tg'] * 1e3:.1f} ms per deck step in the gathers and merges, "
            f"{m['c_rep'] * 1e6:.2f} µs per particle and deck step repeated on every rank), "
            f"with a network of {mpi_model.ALPHA * 1e6:.0f} µs latency and "
            f"{1e-9 / mpi_model.BETA:.0f} GB/s (assumed, an InfiniBand-class cluster; not "
            "measured here). Per rank, per deck step:\n\n" +
            md_table(["N", "ranks", "ghost fraction", "kB per internal step", "compute s",
                      "communication s", "repeated O(N) s", "efficiency"], rows) + "\n")
    rep.add("What limits it: the gathers at deck ends and rebuilds and the work every rank "
            "repeats for all N particles (integration of frozen copies, odometers, the cell "
            "grid) grow with N, not N/P; at 10^6 particles on 64 ranks they are what the "
            "next step must distribute (owned + ghost arrays only, a point-to-point migration "
            "instead of the gathers).\n")


# =========================================================================== main
def _headline_md(rep: Report) -> str:
    h = rep.headline
    out = ["## Headline numbers\n", rep.stamp_line() + "\n"]
    for t in LCP_TYPES:
        v = h.get(f"lcp_{t}")
        if v:
            out.append(f"* LCP {t}: {v['us_cold']:.1f} µs cold, {v['us_warm']:.1f} µs warm "
                       f"(one thread), {v['it_cold']:.1f} / {v['it_warm']:.1f} Newton iterations; "
                       f"max error |Δsd|/r {v['sd_err']:.1e}, normal {v['n_err']:.1e} rad "
                       "(references in section 1).")
        else:
            out.append(f"* LCP {t}: not measured (see section 1).")
    f = h.get("facets")
    if f:
        out.append(f"* Facets: {f['best_facets']} facets give a median depth error of "
                   f"{f['best_err']:.1e} L at {f['best_us']:.1f} µs; the exact LCP "
                   f"{f['nurbs_err']:.1e} L at {f['nurbs_us']:.1f} µs.")
    r = h.get("robustness")
    if r:
        out.append(f"* Robustness: {r['n']} poses, {r['fail']} failed cold, {r['failw']} failed "
                   f"warm, {r['deg']} degenerated, {r['mig']} migrated; {r['checked']} validated "
                   f"against a reference, {r['out']} out of tolerance.")
    fi = h.get("fit")
    if fi:
        out.append(f"* Fit (`nurbsdem fit`, ellipsoid mesh of {fi['vertices']} vertices, "
                   f"{fi['n_cp']} × {fi['n_cp']} control points): true error "
                   f"{fi['best_err']:.1e} of the size, volume {fi['vol_err']:+.4f} % "
                   "(section 6).")
    hz = h.get("hertz")
    if hz:
        out.append(f"* Hertz–Mindlin: the exact curvature costs {hz['us']:.1f} µs per contact; "
                   f"the volume-equivalent radius errs by up to {100 * hz['ell_err']:+.0f} % in "
                   "force on ellipsoids against a wall (section 7).")
        pk = hz.get("pack")
        if pk:
            out.append(f"* Hertz–Mindlin pack of {pk['n']} paper particles: compiled deck steps "
                       f"{pk['python_s'] / pk['compiled_s']:.1f} x faster than the Python path, "
                       f"results {'bit for bit equal' if pk['same'] else 'NOT equal'} "
                       "(section 7).")
    sp = h.get("spheres")
    if sp and sp.get("ratio") is not None:
        out.append(f"* 112 spheres against Yade (one thread each): {sp['ratio']:.2f} x Yade's "
                   f"time, section 5.")
    dr = h.get("drum")
    if dr:
        out.append(f"* Rotating drum of spheres against Yade (one thread each): {dr['ratio']:.2f} "
                   f"x Yade's time, angles of repose {dr['angle']:+.2f} degrees apart, "
                   "section 5.")
    st = h.get("settled")
    if st:
        lo, hi = st["rows"][0], st["rows"][-1]
        out.append(f"* Settled dense packs: {lo['us_per_particle_step']:.0f} µs per "
                   f"particle-step at {lo['n']} particles, {hi['us_per_particle_step']:.0f} at "
                   f"{hi['n']} (cost ∝ N^{st['exponent']:.2f}), section 5.")
    p = h.get("paper")
    if p:
        out.append(f"* Paper example: {p['wall']:.0f} s wall time ({p['sparse_wall']:.0f} s with "
                   f"{p['sparse_frames']} ParaView samples instead of {p['frames']}), "
                   f"{p['lcps']} LCPs "
                   f"({p['lcps_per_active']:.2f} per active contact and evaluation), "
                   f"{p['failed']} failed; time outside the LCP {p['outside']:.2f} × the LCP "
                   f"time ({p['sparse_outside']:.2f} with few samples, "
                   f"{p['one_thread_outside']:.2f} with few samples on one thread).")
    dm = h.get("damping")
    if dm:
        out.append(f"* Paper example as shipped (`Damping Implicit Accuracy 3e-5 Safety "
                   f"0.7`): "
                   f"{dm['shipped']:.0f} s, energy-balance error {dm['shipped_balance']:.3g} J; "
                   f"with explicit dashpots {dm['explicit']:.0f} s "
                   f"({dm['explicit_balance']:.3g} J), implicit without the accuracy control "
                   f"{dm['implicit']:.0f} s ({dm['balance']:.3g} J); at the default Safety 0.5 "
                   f"{dm['safety_default']:.0f} s ({dm['safety_default_balance']:.3g} J); "
                   f"section 5.")
    mp = h.get("mpi")
    if mp:
        out.append(f"* {mp['n']} settled paper particles on 2 MPI ranks: {mp['speedup']:.2f} x "
                   f"one rank, results {'bit for bit equal' if mp['same'] else 'NOT equal'} "
                   "(section 8).")
    return "\n".join(out) + "\n"


#: The sections of the report that ``performance.md`` repeats: what the run costs.
PERFORMANCE_SECTIONS = ("## Headline numbers", "## 5. Cost of a run",
                        "## 8. Runs on several MPI ranks")


def _sections(md: str) -> tuple[str, dict[str, str]]:
    """A report's text before its first ``## `` heading, and each ``## `` section by its
    heading line (the section's text includes the heading and its ``###`` subsections)."""
    head, *rest = md.split("\n## ")
    return head, {("## " + part).split("\n", 1)[0]: "## " + part for part in rest}


def performance_md(verification: str) -> str:
    """``performance.md``: the timing sections of a verification report's text (its machine,
    version and date, the headline numbers, section 5 and section 8), so that the speed
    figures a reader finds are those of the latest run and no older."""
    head, sections = _sections(verification)
    header = [ln for ln in head.splitlines() if ln.startswith("* ")]
    generated = next((ln for ln in head.splitlines() if ln.startswith("Generated by")), "")
    out = ["# nurbsdem performance\n",
           "The speed figures of the latest run of the verification report "
           "(`benchmarks/report.py`, which rewrites this file with "
           "[verification.md](verification.md)); the accuracy figures, and the references "
           "each error is measured against, are in [verification.md](verification.md). "
           "Timings depend on the machine and its load; ratios measured side by side in one "
           "run are the figures to compare.\n",
           generated + "\n" if generated else "", "\n".join(header) + "\n"]
    for title in PERFORMANCE_SECTIONS:
        key = next((k for k in sections if k.startswith(title)), None)
        if key is not None:
            out.append(sections[key].rstrip() + "\n")
    return "\n".join(part for part in out if part)


def _write_atomically(path: Path, text: str) -> None:
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(path)


def build(outdir: Path, quick: bool) -> Path:
    info = machine_info()
    rep = Report(outdir, info, quick)
    t_all = time.perf_counter()
    timings = {}
    with tempfile.TemporaryDirectory(prefix="nurbsdem-report-") as tmp:
        work = Path(tmp)
        sweep = None
        try:
            sweep = LcpSweep(quick, work)
        except Exception:
            sweep_err = traceback.format_exc().strip().splitlines()[-1]
        sections = [("facets", lambda: section_facets(rep)),
                    ("robustness", lambda: section_robustness(rep)),
                    ("timestep", lambda: section_timestep(rep, work)),
                    ("cost", lambda: section_cost(rep, work)),
                    ("fit", lambda: section_fit(rep)),
                    ("hertz", lambda: section_hertz(rep)),
                    ("mpi", lambda: section_mpi(rep))]
        bodies = {}
        # section 1 is written first, but measured while its workers run in the background
        for name, fn in sections:
            if name == "cost" and sweep is not None:
                # the sweep's workers compile the LCP anew after a change of its sources
                # (minutes of CPU): the timed runs of section 5 must not share the cores
                sweep.thread.join()
            t0 = time.perf_counter()
            n0 = len(rep.parts)
            try:
                fn()
            except Exception as exc:
                rep.add(f"**Not measured**: this section failed ({type(exc).__name__}: {exc}).\n")
                traceback.print_exc()
            bodies[name] = rep.parts[n0:]
            del rep.parts[n0:]
            timings[name] = time.perf_counter() - t0
            print(f"report: {name} done in {timings[name]:.0f} s", file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        try:
            if sweep is None:
                raise RuntimeError(sweep_err)
            section_lcp(rep, sweep)
        except Exception as exc:
            rep.add("## 1. Contact accuracy against cost\n")
            rep.add(f"**Not measured**: this section failed ({type(exc).__name__}: {exc}).\n")
            traceback.print_exc()
        bodies["lcp"] = rep.parts[:]
        rep.parts.clear()
        timings["lcp (after the others)"] = time.perf_counter() - t0
        print(f"report: lcp done in {timings['lcp (after the others)']:.0f} s", file=sys.stderr)
    total = time.perf_counter() - t_all
    head = [
        "# nurbsdem verification report\n",
        f"Generated by `benchmarks/report.py{' --quick' if quick else ''}` "
        f"(`nurbsdem bench{' --quick' if quick else ''}`) in {total:.0f} s.\n",
        f"* machine: {info['cpu']}, {info['cores']} cores ({info['os']}); numba threads "
        f"{info['numba_threads']}\n* nurbsdem {info['nurbsdem']}, Python {info['python']}, "
        f"NumPy {info['numpy']}, numba {info['numba']}\n* date: {info['date']}\n",
        "Every number below was measured by this run of the report; every error names its "
        "reference. Timings depend on the machine and its load.\n",
    ]
    parts = head + [_headline_md(rep)]
    for name in ("lcp", "facets", "robustness", "timestep", "cost", "fit", "hertz", "mpi"):
        parts += bodies.get(name, [])
    parts.append("## Run time of the report\n\n" + md_table(
        ["section", "s"], [[k, f"{v:.0f}"] for k, v in timings.items()] + [["total", f"{total:.0f}"]]) + "\n")
    md = outdir / "verification.md"
    _write_atomically(md, "\n".join(parts))
    _write_atomically(outdir / "performance.md", performance_md("\n".join(parts)))
    (rep.figdir / "headline.json").write_text(json.dumps(rep.headline, default=str, indent=1))
    print(f"report: wrote {md} ({len(rep.figures)} figures) in {total:.0f} s", file=sys.stderr)
    return md


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the CI mode (about two minutes)")
    ap.add_argument("--output", default=str(REPO / "docs"),
                    help="folder of verification.md (figures in its verification/ subfolder)")
    ap.add_argument("--performance-only", action="store_true",
                    help="only rewrite performance.md from the verification.md in --output")
    ap.add_argument("--lcp-worker", nargs=3, metavar=("IN", "OUT", "TOL"), help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.lcp_worker:
        lcp_worker(*a.lcp_worker)
        return 0
    if a.performance_only:
        out = Path(a.output)
        _write_atomically(out / "performance.md",
                          performance_md((out / "verification.md").read_text(encoding="utf-8")))
        return 0
    build(Path(a.output), a.quick)
    return 0


if __name__ == "__main__":
    sys.exit(main())

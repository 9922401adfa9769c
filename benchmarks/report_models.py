"""Sections 6–8 of the verification report: shapes fitted to meshes, the Hertz–Mindlin law
with the exact curvature, runs on several MPI ranks."""
from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import REPO  # noqa: E402

from report_base import Report, fmt, md_table  # noqa: E402


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
    repeat = 1 if rep.quick else 3
    res = bench_mpi.main(["--n", str(n), "--settle", str(settle), "--measure", str(measure),
                          "--weak-n", "300" if rep.quick else "1500", "--repeat", str(repeat)])
    if not res:
        rep.add("**Not measured**: mpi4py or mpiexec is missing (`pip install "
                "'nurbsdem[mpi]'`).\n")
        return
    rows = []
    for r in res["strong"]:
        ghosts = [d["ghosts"] for d in r["domain"]]
        wait = [sum(d["seconds"].values()) / max(r["steps"], 1) for d in r["domain"]]
        runs = r.get("per_step_runs", [r["per_step"]])
        rows.append([r["ranks"], r["threads"], fmt(r["per_step"], ".3f")
                     + (f" ({min(runs):.3f}–{max(runs):.3f})" if len(runs) > 1 else ""),
                     fmt(r["speedup"], ".2f"),
                     fmt(r["efficiency"], ".2f"), str(ghosts) if ghosts else "",
                     ", ".join(f"{w:.3f}" for w in wait),
                     "yes" if r["same"] else "**no**"])
    rep.add(f"`benchmarks/bench_mpi.py`: a pack of {n} paper particles settled for {settle} s "
            f"(once, on 2 ranks, from a checkpoint kept in `benchmarks/.cache/`), then {measure} "
            "deck steps of 1e-3 s from its checkpoint on each configuration, after "
            f"{bench_mpi.WARM_STEPS} deck steps that load the cached kernels (`mpiexec -n P`, "
            "`NUMBA_NUM_THREADS` threads per rank); time of the time loop per deck step, "
            "including the communication and the wait for the slowest rank"
            + (f"; each configuration run {repeat} times, alternated: the median, with the "
               "range of the runs in brackets" if repeat > 1 else "") + ".\n\n" +
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

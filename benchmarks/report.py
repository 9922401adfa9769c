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

The sections live in ``report_contact.py`` (1–3), ``report_runs.py`` (4–5),
``report_peers.py`` (runs beside a reference: Yade, Beverloo's law, a pour's accounting) and
``report_models.py`` (6–8); ``report_base.py`` holds the report object and the tables.

Usage::

    .venv/bin/python benchmarks/report.py [--quick] [--output DIR]     # or: nurbsdem bench

``--quick`` (CI) runs in about two minutes on 2 cores; the full mode in about 15–20 min.
The LCP tolerance sweep recompiles the LCP with a patched ``ANGLE_TOL`` (the direction
Newton's stopping angle, a module constant of :mod:`nurbsdem.contact.stage2`) in worker
processes with their own numba cache (kept under the temp folder, keyed by the source).
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
import traceback
from pathlib import Path


sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import REPO, machine_info  # noqa: E402

from report_base import Report, md_table  # noqa: E402
from report_contact import (LCP_TYPES, LcpSweep, lcp_worker, section_facets,  # noqa: E402
                            section_lcp, section_robustness)
from report_models import section_fit, section_hertz, section_mpi  # noqa: E402
from report_runs import section_cost, section_timestep  # noqa: E402


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
    dp = h.get("drum_paper")
    if dp:
        out.append(f"* The same drum with the paper's particles of the spheres' volumes: angle "
                   f"of repose {dp['angle']:.1f} degrees against the spheres' "
                   f"{dp['spheres']:.1f}, section 5.")
    bv = h.get("beverloo_fills") or h.get("beverloo")
    if bv:
        fills = f" over {bv['fills']} fills" if "fills" in bv else ""
        spread = (f" ({bv['p16']:.2f}–{bv['p84']:.2f} over the fills resampled)"
                  if "p16" in bv else "")
        out.append(f"* Silo discharge of spheres{fills}: Beverloo's exponent {bv['n']:.2f}"
                   f"{spread}; "
                   f"at n = 2.5, k {bv['k']:.2f} and C {bv['C']:.3f} (spheres' published "
                   "range: n 2.5 ± 0.3, k 1–2, C 0.5–0.7), section 5.")
        if "n_from" in bv:
            out.append(f"* The same fills through the orifices of at least {bv['start']:g} d: "
                       f"Beverloo's exponent {bv['n_from']:.2f}; at n = 2.5, k "
                       f"{bv['k_from']:.2f} and C {bv['C_from']:.3f}, section 5.")
    hp = h.get("heap")
    if hp:
        names = dict(sphere="spheres", paper="the paper's particles")
        out.append("* A heap poured onto a floor, angle of repose: " + ", ".join(
            f"{a:.1f} degrees ({names.get(k, k)})" for k, a in hp.items()) + ", section 5.")
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

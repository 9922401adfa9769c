"""Sections of the verification report that run nurbsdem beside a reference: exact spheres and
a rotating drum against the real Yade, a silo's discharge against Beverloo's law (and Yade),
a pour's accounting and energy balance, a poured heap's angle of repose."""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path


sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import REPO  # noqa: E402

from report_base import Report, fmt, md_table  # noqa: E402


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
            "one thread each, the same positions; time of the time loop (nurbsdem: its "
            "solver's timers, after a short deck in the same process loaded the compiled "
            f"kernels; Yade: its `O.run`); the faster of {bench_yade.ROUNDS} runs of each, "
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
                              (f"Yade, {bench_drum.SEGMENTS} facets", r["yade"]),
                              ("nurbsdem, paper particles, exact NURBS drum", r["paper"]))
            if isinstance(res, dict)]
    rep.add(f"`benchmarks/bench_drum.py`: {r['count']} spheres (radii "
            f"{', '.join(str(x) for x in bench_drum.RADII)} m) in a drum of radius "
            f"{bench_drum.R_DRUM} m and length {bench_drum.LENGTH} m turning at Froude number "
            f"{bench_drum.FROUDE} after settling; the same positions, linear law and time step "
            "for both codes, one thread each; the dynamic angle of repose (the bed's tilt) and "
            f"the drive torque over the last {r['window']} s. Last row: the same drum with "
            "each sphere replaced by the paper's particle of its volume (A, B, C for the "
            "three radii, turned at random), which only nurbsdem runs.\n\n"
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
    p, n = r["paper"], r["nurbs"]
    rep.add(f"The paper's particles against the spheres of their volumes: angle of repose "
            f"{p['angle'] - n['angle']:+.2f} degrees, drive torque "
            f"{100 * (p['torque'] / n['torque'] - 1):+.1f} %, time loop "
            f"{p['loop'] / n['loop']:.1f} × the spheres'.\n")
    rep.headline["drum_paper"] = dict(angle=p["angle"], spheres=n["angle"])


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

    def par(f, k, spec):
        mark = "inside" if f["inside"][k] else "**outside**"
        lo, hi = bb.RANGES[k]
        return f"{f[k]:{spec}} ± {f.get('sd_' + k, float('nan')):.2g} ({mark} {lo}–{hi})"
    if fit:
        rep.add(f"Beverloo fit (`postproc/beverloo.py`, ± its standard errors): exponent "
                f"{par(fit, 'n', '.2f')}, k {par(fit, 'k', '.2f')}, C {par(fit, 'C', '.3f')}; "
                f"RMS of W {100 * fit['rms']:.2f} %.")
        if fixed:
            rep.add(f" At n = 2.5: k {par(fixed, 'k', '.2f')}, C {par(fixed, 'C', '.3f')}; "
                    f"RMS of W {100 * fixed['rms']:.2f} %.")
        rep.add("\n")
        rep.headline["beverloo"] = dict(n=fit["n"], k=(fixed or fit)["k"],
                                        C=(fixed or fit)["C"])
    else:
        rep.add("No Beverloo fit: it needs three orifices.\n")
    if not r["quick"]:
        _beverloo_fills(rep, cache, par)
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
    _beverloo_yade_at(rep, cache, r)
    _beverloo_shapes(rep, cache)


def _beverloo_yade_at(rep: Report, cache: Path, base: dict) -> None:
    """Yade through the other orifices of the default run's bed (``bench_beverloo.py
    --orifices R --yade-at R``: ``beverloo_D<R>.json``), when their JSONs are there: the rates
    of both codes, and with four orifices or more (the default run's own Yade orifice among
    them) Beverloo's fits of each code's rates on that bed, which check the exponent
    nurbsdem's rates give against an independent code's."""
    import bench_beverloo as bb
    pairs, rows = {}, []
    if isinstance(base.get("yade"), dict):
        at = base.get("yade_at", base["orifices"][0]["ratio"])
        o = next(o for o in base["orifices"] if o["ratio"] == at)
        pairs[at] = (o["D"], o["W"], base["yade"]["W"])
    for path in sorted(cache.glob("beverloo_D*.json")):
        r = json.loads(path.read_text())
        y = r.get("yade")
        if not isinstance(y, dict) or r.get("seed", 3) != base.get("seed", 3):
            continue
        o = next(o for o in r["orifices"] if o["ratio"] == r["yade_at"])
        pairs[o["ratio"]] = (o["D"], o["W"], y["W"])
        rows.append([o["ratio"], f"{o['W']:.4f}", f"{y['W']:.4f}",
                     f"{100 * (o['W'] / y['W'] - 1):+.1f}", fmt(r.get("ratio"), ".2f")])
    if not rows:
        return
    rows = [[f"{row[0]:g}"] + row[1:] for row in sorted(rows)]
    rep.add("\nYade through other orifices of the same bed (`--orifices R --yade-at R`; the "
            "time ratio where both ran in one benchmark run):\n\n"
            + md_table(["D / d", "nurbsdem W kg/s", "Yade W kg/s", "difference %",
                        "time nurbsdem / Yade"], rows) + "\n\n")
    if len(pairs) < 4:
        return
    keys = sorted(pairs)
    D = [pairs[k][0] for k in keys]
    fits = []
    for col in (1, 2):
        W = [pairs[k][col] for k in keys]
        free = _fit_or_none(D, W, base["d"], base["fill"]["rho_b"], bb.G)
        fixed = _fit_or_none(D, W, base["d"], base["fill"]["rho_b"], bb.G, n=2.5)
        fits.append("–" if free is None or fixed is None else
                    f"exponent {free.n:.2f} ± {free.sd_n:.2g}; at n = 2.5, k {fixed.k:.2f}, "
                    f"C {fixed.C:.3f}")
    rep.add(f"Beverloo's fits on this bed through {', '.join(f'{k:g}' for k in keys)} d: "
            f"nurbsdem's rates {fits[0]}; Yade's rates {fits[1]}.\n")


def _fit_or_none(D, W, d, rho_b, g, n=None):
    """:func:`beverloo.fit_beverloo` (postproc), or None where it fails."""
    import bench_beverloo as bb
    try:
        return bb.fit_beverloo(D, W, d, rho_b, g, n=n)
    except (ValueError, RuntimeError):
        return None


def _beverloo_fills(rep: Report, cache: Path, par) -> None:
    """The rates of several fills of the same silo (``bench_beverloo.py --seed S``, then
    ``--combine``), averaged per orifice, and the fits on them, when their JSON is there."""
    import bench_beverloo as bb
    path = cache / "beverloo_fills.json"
    if not path.exists():
        rep.add("One fill only: the rates' spread from fill to fill is not measured (run "
                "`bench_beverloo.py --seed S` for other seeds, then `--combine`).\n")
        return
    f = json.loads(path.read_text())
    rows = [[f"{o['ratio']:g}", f"{o['W']:.4f} ± {o['sem']:.4f}",
             ", ".join(f"{w:.4f}" for w in o["W_fills"])] for o in f["orifices"]]
    header = ["D / d", "mean W kg/s", "W of each fill"]
    times = [o.get("T_fills", [f["T"]] * len(o["W_fills"])) for o in f["orifices"]]
    longer = any(t != f["T"] for ts in times for t in ts)
    if longer:                       # some rates from longer discharges (``--discharge``)
        header.append("discharge of each fill s")
        for row, ts in zip(rows, times):
            row.append(", ".join(f"{t:g}" for t in ts))
    rep.add(f"\nOver {len(f['seeds'])} fills of the same silo (inlet seeds "
            f"{', '.join(str(x) for x in f['seeds'])}; bulk densities "
            f"{', '.join(f'{x:.0f}' for x in f['rho_b_fills'])} kg/m³), the mean rate of each "
            "orifice ± its standard error"
            + (" (each fill's rate from its longest discharge through that orifice, "
               "`--discharge`: the same fractions of the run left out, a wider window)"
               if longer else "") + ":\n\n"
            + md_table(header, rows) + "\n\n")
    fit, fixed = f.get("fit"), f.get("fit_n25")
    if fit:
        rep.add(f"Beverloo fit on the mean rates: exponent {par(fit, 'n', '.2f')}, "
                f"k {par(fit, 'k', '.2f')}, C {par(fit, 'C', '.3f')}; RMS of W "
                f"{100 * fit['rms']:.2f} %; at n = 2.5: k {par(fixed, 'k', '.2f')}, "
                f"C {par(fixed, 'C', '.3f')}. Each fill's own free exponent: "
                + ", ".join("-" if n is None else f"{n:.2f}" for n in f["n_fills"]) + ".\n")
        rep.headline["beverloo_fills"] = dict(n=fit["n"], k=fixed["k"], C=fixed["C"],
                                              fills=len(f["seeds"]))
        boot = f.get("bootstrap")
        if boot:
            rep.headline["beverloo_fills"].update(p16=boot["p16"], p84=boot["p84"])
            lo, hi = bb.RANGES["n"]
            rep.add(f"Resampling the fills ({boot['draws']} draws with replacement, each fitted "
                    f"on its mean rates): free exponent {boot['p16']:.2f} to {boot['p84']:.2f} "
                    f"(16th to 84th percentile, median {boot['p50']:.2f}); "
                    f"{100 * boot['inside']:.0f} % of the draws inside {lo}–{hi}.\n")
    part, part25 = f.get("fit_from"), f.get("fit_n25_from")
    if part:
        keep = [o for o in f["orifices"] if o["ratio"] >= f["from"] - 1e-9]
        rep.add(f"Over the {len(keep)} orifices of at least {f['from']:g} d "
                f"({', '.join(format(o['ratio'], 'g') for o in keep)} d): exponent "
                f"{par(part, 'n', '.2f')}, k {par(part, 'k', '.2f')}, C "
                f"{par(part, 'C', '.3f')}; RMS of W {100 * part['rms']:.2f} %; at n = 2.5: "
                f"k {par(part25, 'k', '.2f')}, C {par(part25, 'C', '.3f')}. The free fit's C "
                "is in m^(2.5 − n): it compares with the published 0.5–0.7 at n = 2.5 only.\n")
        rep.headline["beverloo_fills"].update(
            n_from=part["n"], k_from=part25["k"], C_from=part25["C"], start=f["from"])


def _beverloo_shapes(rep: Report, cache: Path) -> None:
    """The same discharge with ellipsoids and with the paper's particles
    (``bench_beverloo.py --shape ellipsoid | paper``), when their JSON is there."""
    import bench_beverloo as bb
    runs = [json.loads(p.read_text()) for p in (cache / f"beverloo_{shape}.json"
                                                for shape in bb.SHAPES[1:]) if p.exists()]
    if not runs:
        rep.add("Ellipsoids and the paper's particles: not measured (run "
                "`benchmarks/bench_beverloo.py --shape ellipsoid` and `--shape paper`).\n")
        return
    rows = [[r["shape"], f"{o['ratio']:g}", fmt(o["W"], ".4f"),
             f"{fmt(o['halves'][0], '.4f')} / {fmt(o['halves'][1], '.4f')}",
             fmt(o["C_mid"], ".3f"), f"{r['fill']['rho_b']:.0f}", fmt(o["loop"], ".1f"),
             f"{100 * o['flow'] / o['loop']:.1f}"] for r in runs for o in r["orifices"]]
    rep.add("\nThe same silo (a smaller fill: "
            f"{runs[0]['count']} grains in a silo {runs[0]['side'] * 1e3:.0f} mm wide, "
            f"{runs[0]['T']} s per orifice) with grains of the spheres' volumes: ellipsoids "
            f"of semi-axes {' : '.join(f'{a:g}' for a in bb.ELLIPSOID)} × r, and the paper's "
            "particles A, B and C scaled (only an exact-geometry code runs these):\n\n")
    rep.add(md_table(["grain", "D / d", "W kg/s", "W of the window's halves",
                      "C at n 2.5, k 1.5", "ρ_b kg/m³", "time loop s", "outlet % of loop"],
                     rows) + "\n\n")
    for r in runs:
        f = r.get("fit_n25")
        if f:
            rep.add(f"{r['shape']}: at n = 2.5, k {f['k']:.2f} ± {f['sd_k']:.2g}, C "
                    f"{f['C']:.3f} ± {f['sd_C']:.2g}, RMS of W {100 * f['rms']:.1f} %. ")
    rep.add("Runs this short (a few hundred grains out per orifice) do not determine the law: "
            "the rates' window halves show their noise.\n")


def section_pour(rep: Report) -> None:
    """A pour of spheres into a box with an outlet (benchmarks/bench_pour.py): accounting,
    placement, containment and the energy balance with its convergence."""
    import bench_pour
    rep.add("### A pour: every particle accounted for\n")
    r = bench_pour.main(["--quick"] if rep.quick else ["--count", "2000", "--convergence"])
    h = r.get("half_step")
    rows = [["0.5 (default)", r["substeps"], fmt(r["wall"], ".1f"), fmt(r["balance"], ".2e")]]
    if h:
        rows.append(["0.25", h["substeps"], fmt(h["wall"], ".1f"), fmt(h["balance"], ".2e")])
    rep.add(f"`benchmarks/bench_pour.py`: {r['count']} exact spheres (radii "
            f"{', '.join(f'{x * 1e3:g}' for x in bench_pour.RADII)} mm) poured at "
            f"{bench_pour.RATE:g} per second into a box with an outlet in a corner of its floor, "
            f"{r['simulated']:.2f} s simulated, one thread. Inserted {r['inserted']} = in the box "
            f"{r['in_box']} + discharged {r['discharged']} (count error {r['count_error']}, mass "
            f"error {r['mass_error']:.1e}); smallest gap at an insertion "
            f"{r['min_gap'] * 1e3:.3f} mm; every sphere left inside the box: {r['inside']}. "
            "The energy balance error relative to the energy turned over, at the solver's "
            "safety factor and at half of it (an explicit scheme's error falls as h²):\n\n"
            + md_table(["safety", "internal steps", "run s", "balance error"], rows) + "\n")
    rep.headline["pour"] = dict(count=r["count"], count_error=r["count_error"],
                                balance=r["balance"])


def section_heap(rep: Report) -> None:
    """A heap poured onto a floor (``benchmarks/bench_heap.py``, its JSON
    ``benchmarks/.cache/heap.json``): the angle of repose of spheres and of the paper's
    particles with the same law."""
    rep.add("### A poured heap: the angle of repose\n")
    path = REPO / "benchmarks" / ".cache" / "heap.json"
    if not path.exists():
        rep.add("Not measured: run `benchmarks/bench_heap.py` (it writes "
                "`benchmarks/.cache/heap.json`, which this section reads).\n")
        return
    r = json.loads(path.read_text())
    names = dict(sphere="exact spheres", paper="the paper's particles (A, B, C scaled)")
    rows = [[names.get(x["shape"], x["shape"]), x["count"], x["on_floor"],
             f"{x['angle']:.1f} ± {x['error']:.1f}", f"{x['foot'] * 1e3:.0f}",
             f"{x['height'] * 1e3:.0f}", fmt(x["wall"], ".1f")] for x in r["runs"]]
    rep.add(f"`benchmarks/bench_heap.py`{' (quick: a smoke test)' if r['quick'] else ''}: "
            f"grains of the volumes of spheres of radii "
            f"{', '.join(f'{x * 1e3:g}' for x in r['radii'])} mm poured at {r['rate']:g} per "
            f"second from a disc {r['height'] * 1e3:.0f} mm above a flat floor, the silo's "
            f"linear law with friction {r['friction']:g} and rolling friction {r['rolling']:g} "
            f"(the rolling torque is at most μ_r R_r f_n, R_r the contact's rolling radius, R/2 "
            f"between two equal spheres: a sphere rolling over another is held up to a slope of "
            f"about atan(μ_r / 2), {math.degrees(math.atan(r['rolling'] / 2)):.0f} degrees); "
            "the angle of the heap's flank by `postproc/repose.py` (± its standard error) "
            "at the end, one thread:\n\n"
            + md_table(["grains", "poured", "on the floor", "angle of repose (deg)",
                        "foot radius mm", "height mm", "run s"], rows) + "\n")
    rep.headline["heap"] = {x["shape"]: x["angle"] for x in r["runs"]}

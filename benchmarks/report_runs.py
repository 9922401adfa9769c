"""Sections 4–5 of the verification report: the time step against the error, and the cost of
a run (scaling with the particle count, the paper's example, damping, large and settled
packs)."""
from __future__ import annotations

import sys
import time
import traceback
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import REPO  # noqa: E402

from report_base import Report, _plt, fmt, md_table  # noqa: E402
from report_contact import section_point_surface  # noqa: E402
from report_peers import (section_beverloo, section_drum, section_heap,  # noqa: E402
                          section_pour, section_spheres)


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
    for part in (section_spheres, section_drum, section_beverloo, section_pour, section_heap,
                 section_point_surface, lambda r: _section_paper(r, workdir, quick)):
        _guarded(rep, part)


def _guarded(rep: Report, part) -> None:
    """One part of section 5; a failure is said where its text would be, and the next part
    runs."""
    try:
        part(rep)
    except Exception as exc:
        rep.add(f"**Not measured**: this part failed ({type(exc).__name__}: {exc}).\n")
        traceback.print_exc()


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
            "(the same when the two runs' contact states agree to the bit); time outside the "
            f"LCP {_outside_lcp(s):.2f} × the LCP time (of forces + integration "
            f"{t['forces + integration']:.1f} s: "
            + ", ".join(f"{k} {v:.1f} s" for k, v in s.split.items()) + "). The samples are "
            "written by a worker thread; what they cost beyond its own CPU time is the LCP's "
            "two threads running slower meanwhile when the machine has no spare core.\n")


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

"""Strong and weak scaling of the domain decomposition (nurbsdem.parallel) on this machine.

Strong scaling: a dense pack of N paper particles (A, B, C, 1/3 each; the deck of
bench_settled_pack.py) is settled under gravity once (on 2 ranks; its checkpoint is kept in
the cache folder and reused), then ``--measure`` more deck steps are run from that checkpoint
on 1 rank with 1 thread, 1 rank with all cores as threads (numba), and P = 2.. ranks with
one thread each, each run after :data:`WARM_STEPS` deck steps that are not measured (a
process loads its cached kernels at their first call: one rank loads its compiled loop in
the set-up, several ranks the Python driver's kernels in their first steps).  Each
configuration runs ``--repeat`` times, the configurations alternated, and its median counts:
on a shared machine one run's time per deck step can be 20 % off the next one's.  Printed
per configuration: wall time per deck step (the median, and the range of the runs),
speed-up and efficiency against 1 rank x 1 thread, the ranks' ghost counts, the bytes each
rank sent per internal step, and whether results.h5 equals the 1-rank run bit for bit (it
must).

Weak scaling: settled packs of N/P particles per rank (the same deck and settling), and
falling packs of ``--weak-n`` particles per rank (where the work each rank repeats for all
particles shows; after :data:`WARM_STEPS` deck steps too), on 1.. P ranks (as far as a
2-core machine goes), 1 thread each, one run each: efficiency = t(1 rank) / t(P ranks).

Usage: .venv/bin/python benchmarks/bench_mpi.py [--n 10000] [--settle 0.9] [--measure 20]
       [--ranks 2] [--weak-n 1500] [--repeat 3] [--cache DIR]
Prints one JSON line at the end (``RESULT {...}``) for benchmarks/report.py.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_settled_pack import pack_region  # noqa: E402
from decks import paper_mix_deck  # noqa: E402

#: deck steps of 1e-3 s run from the checkpoint before the measured ones: each process loads
#: its cached kernels at their first call, which the measured steps leave out
WARM_STEPS = 2

BIN = Path(sys.executable).parent


def _mpiexec() -> str | None:
    exe = BIN / "mpiexec"
    if exe.exists():
        return str(exe)
    from shutil import which
    return which("mpiexec")


def _launch(ranks: int, threads: int, args: list[str]) -> dict:
    """Run this script's worker on ``ranks`` ranks with ``threads`` numba threads each;
    returns rank 0's RESULT."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("PMI_SIZE", "PMI_RANK", "OMPI_COMM_WORLD_SIZE", "PMIX_SIZE")}
    env["NUMBA_NUM_THREADS"] = str(threads)
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", *args]
    if ranks > 1:
        cmd = [_mpiexec(), "-n", str(ranks), *cmd]
    res = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if res.returncode:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{res.stderr[-3000:]}")
    line = [s for s in res.stdout.splitlines() if s.startswith("WORKER ")][-1]
    return json.loads(line[len("WORKER "):])


def deck_text(n: int, settle: float, measure: int, out: Path) -> str:
    """The settled pack's deck (bench_settled_pack.py's): the settling step, the warm-up
    step and the measured step."""
    side, height = pack_region(n)
    return paper_mix_deck(n, (side, side, height), 2 * height,
                          [settle, WARM_STEPS * 1e-3, measure * 1e-3], out,
                          monitors_every=0.05, vtk_resolution=2)


_LOOP = ("global search", "LCP", "forces + integration")


def worker(argv: list[str]) -> None:
    """One run (on the ranks of mpiexec when so started): ``settle DECK`` runs the first
    step and leaves its checkpoint; ``measure DECK CKPT OUT`` restarts from it, runs the
    warm-up step and then the measured one; ``fall DECK OUT`` runs a deck's warm-up step,
    then the rest.  Rank 0 prints its figures: the time loop of the measured steps."""
    from nurbsdem.io.deck import parse_deck
    from nurbsdem.solver import Solver
    mode, deck = argv[0], Path(argv[1])
    kw = {}
    if mode == "measure":
        kw = dict(restart=argv[2], output=argv[3])
    elif mode == "fall":
        kw = dict(output=argv[2])
    s = Solver(parse_deck(deck), quiet=True, **kw)
    s.start()
    if mode in ("measure", "fall"):   # the warm-up step
        s.run_step(s.model.steps[s.step_index])
    before = {k: s.timers[k] for k in _LOOP}
    done = {k: getattr(s.summary, k) for k in ("steps", "substeps", "lcps", "active_total",
                                                 "failed")}
    t0 = time.perf_counter()
    if mode == "settle":
        s.run_step(s.model.steps[0])
    else:
        s.run_pending()
    summary = s.finish()
    # the time loop (search, LCP, forces + integration, communication), without the set-up
    per_rank = {k: summary.timers[k] - before[k] for k in _LOOP}
    wall = sum(per_rank.values())
    dom_info = dict(run_wall=time.perf_counter() - t0)
    if s.comm is not None:
        from mpi4py import MPI
        d = s.domain
        # (each dynamic step has a domain of its own: the figures are the measured step's)
        figures = s.comm.gather(dict(d.figures() if d is not None else {}, timers=per_rank),
                                root=0)
        wall = s.comm.allreduce(wall, op=MPI.MAX)
        dom_info.update(ranks=figures)
    if s.rank == 0:
        print("WORKER " + json.dumps(dict(
            wall=wall, steps=summary.steps - done["steps"],
            substeps=summary.substeps - done["substeps"], lcps=summary.lcps - done["lcps"],
            active=summary.active_total - done["active_total"],
            failed=summary.failed - done["failed"], **dom_info)), flush=True)


def settled_checkpoint(n: int, settle: float, measure: int, cache: Path, ranks: int) -> tuple[Path, Path]:
    """The deck and the checkpoint of its settled pack (made once, on ``ranks`` ranks)."""
    cache.mkdir(parents=True, exist_ok=True)
    deck = cache / f"pack_{n}_{settle:g}_{measure}.inp"
    out = cache / f"pack_{n}_{settle:g}_{measure}"
    text = deck_text(n, settle, measure, out)
    ckpt = out / "checkpoint.h5"
    if not (deck.is_file() and deck.read_text() == text and ckpt.is_file()):
        deck.write_text(text)
        t0 = time.perf_counter()
        _launch(ranks, 1, ["settle", str(deck)])
        print(f"settled {n} particles for {settle} s on {ranks} ranks in "
              f"{time.perf_counter() - t0:.0f} s (checkpoint kept in {ckpt})", flush=True)
    return deck, ckpt


def _same_results(a: Path, b: Path) -> bool:
    import numpy as np

    from nurbsdem.io.results import read_results_sample, read_results_times
    ta, tb = read_results_times(a), read_results_times(b)
    if not np.array_equal(ta, tb):
        return False
    for i in range(len(ta)):
        x, y = read_results_sample(a, i), read_results_sample(b, i)
        if any(isinstance(v, np.ndarray) and not np.array_equal(v, y[k]) for k, v in x.items()):
            return False
    return True


def _measure(deck: Path, ckpt: Path, p: int, t: int, out: Path) -> dict:
    """The measured deck steps from the settled checkpoint on p ranks x t threads."""
    import shutil
    out.mkdir()
    shutil.copy(ckpt, out / "checkpoint.h5")
    res = _launch(p, t, ["measure", str(deck), str(out / "checkpoint.h5"), str(out)])
    return dict(ranks=p, threads=t, per_step=res["wall"] / max(res["steps"], 1),
                **{k: res[k] for k in ("steps", "substeps", "lcps", "active", "failed")},
                domain=res.get("ranks", []))


def strong(n: int, settle: float, measure: int, ranks: int, cache: Path,
           repeat: int = 1) -> list[dict]:
    """The strong scaling: each configuration measured ``repeat`` times, the configurations
    alternated (in reverse order every other round), so that a change of the machine's speed
    during the runs falls on all of them; each row's ``per_step`` is the median of its runs,
    ``per_step_runs`` all of them."""
    deck, ckpt = settled_checkpoint(n, settle, measure, cache, ranks)
    cores = os.cpu_count() or 1
    configs = [(1, 1), (1, cores)] + [(p, 1) for p in range(2, ranks + 1)]
    runs: dict[tuple, list[dict]] = {c: [] for c in configs}
    with tempfile.TemporaryDirectory() as tmp:
        ref = None
        for k in range(max(repeat, 1)):
            for p, t in (configs if k % 2 == 0 else configs[::-1]):
                out = Path(tmp) / f"r{p}t{t}k{k}"
                row = _measure(deck, ckpt, p, t, out)
                row["same"] = True if ref is None else _same_results(out / "results.h5", ref)
                ref = ref or out / "results.h5"
                runs[(p, t)].append(row)
    rows = [_median_row(runs[c]) for c in configs]
    base = rows[0]["per_step"]
    print(f"strong scaling, {n} settled paper particles, {measure} deck steps of 1e-3 s from the "
          f"checkpoint ({rows[0]['substeps'] / max(rows[0]['steps'], 1):.1f} sub-steps, "
          f"{rows[0]['active'] / max(rows[0]['steps'], 1):.0f} contacts per deck step"
          + (f"; medians of {repeat} alternated runs" if repeat > 1 else "") + "):")
    for r in rows:
        r["speedup"] = base / r["per_step"]
        r["efficiency"] = r["speedup"] / (r["ranks"] * r["threads"])
        ghosts = [d.get("ghosts", 0) for d in r["domain"]]
        sent = [d.get("bytes_per_internal_step", 0) for d in r["domain"]]
        spread = (f" (runs {min(r['per_step_runs']):.3f}-{max(r['per_step_runs']):.3f})"
                  if len(r["per_step_runs"]) > 1 else "")
        print(f"  {r['ranks']} rank(s) x {r['threads']} thread(s): {r['per_step']:.3f} s per deck "
              f"step{spread}, speed-up {r['speedup']:.2f}, efficiency {r['efficiency']:.2f}"
              + (f", ghosts {ghosts}, sent {[f'{b / 1e3:.1f} kB' for b in sent]} per internal step"
                 if ghosts else "")
              + f", results {'equal to 1 rank bit for bit' if r['same'] else 'DIFFER'}", flush=True)
    return rows


def _median_row(runs: list[dict]) -> dict:
    """One configuration's row: its median run (the lower middle one for an even count), with
    every run's time per deck step, and ``same`` only when every run's results were equal."""
    order = sorted(range(len(runs)), key=lambda i: runs[i]["per_step"])
    row = dict(runs[order[(len(runs) - 1) // 2]])
    row["per_step_runs"] = [r["per_step"] for r in runs]
    row["same"] = all(r["same"] for r in runs)
    return row


def weak_settled(n_per_rank: int, ranks: int, settle: float, measure: int, cache: Path,
                 strong_rows: list[dict], n_strong: int) -> list[dict]:
    """Settled packs of n_per_rank particles per rank on 1.. ranks, 1 thread each (a pack
    measured by the strong scaling is not measured again)."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for p in range(1, ranks + 1):
            n = n_per_rank * p
            done = [r for r in strong_rows if n == n_strong and r["ranks"] == p and r["threads"] == 1]
            if done:
                row = done[0]
            else:
                deck, ckpt = settled_checkpoint(n, settle, measure, cache, ranks)
                row = _measure(deck, ckpt, p, 1, Path(tmp) / f"w{p}")
            rows.append(dict(ranks=p, n=n, per_step=row["per_step"]))
    for r in rows:
        r["efficiency"] = rows[0]["per_step"] / r["per_step"]
    print(f"weak scaling, settled packs of {n_per_rank} paper particles per rank, 1 thread per "
          "rank: " + ", ".join(f"{r['ranks']} rank(s) {r['n']} particles {r['per_step']:.3f} s per "
                               f"deck step (efficiency {r['efficiency']:.2f})" for r in rows),
          flush=True)
    return rows


def weak(n_per_rank: int, ranks: int, steps: int = 20) -> list[dict]:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for p in range(1, ranks + 1):
            n = n_per_rank * p
            r3 = (0.0365 ** 3 + 0.0291 ** 3 + 0.0219 ** 3) / 3     # bounding radii of A, B, C
            side = (n * 4 / 3 * 3.14159 * r3 / 0.2) ** (1 / 3)   # bounding-sphere fraction 0.2
            deck = Path(tmp) / f"fall{p}.inp"
            deck.write_text(paper_mix_deck(n, (side, side, side), 2 * side,
                                           [WARM_STEPS * 1e-3, steps * 1e-3],
                                           Path(tmp) / f"out{p}", monitors_every=0.01))
            res = _launch(p, 1, ["fall", str(deck), str(Path(tmp) / f"out{p}")])
            rows.append(dict(ranks=p, n=n, per_step=res["wall"] / res["steps"]))
    for r in rows:
        r["efficiency"] = rows[0]["per_step"] / r["per_step"]
    print(f"weak scaling, falling packs of {n_per_rank} paper particles per rank, 1 thread per rank: "
          + ", ".join(f"{r['ranks']} rank(s) {r['n']} particles {r['per_step'] * 1e3:.0f} ms per "
                      f"deck step (efficiency {r['efficiency']:.2f})" for r in rows), flush=True)
    return rows


def main(argv: list[str] | None = None) -> dict:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == "--worker":
        worker(argv[1:])
        return {}
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=10000)
    ap.add_argument("--settle", type=float, default=0.9)
    ap.add_argument("--measure", type=int, default=20)
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--weak-n", type=int, default=1500)
    ap.add_argument("--cache", type=Path, default=HERE / ".cache")
    ap.add_argument("--repeat", type=int, default=3,
                    help="alternated runs of each strong-scaling configuration (their median)")
    a = ap.parse_args(argv)
    if _mpiexec() is None:
        print("bench_mpi: no mpiexec (pip install 'nurbsdem[mpi]'): nothing measured")
        return {}
    try:
        import mpi4py  # noqa: F401
    except ImportError:
        print("bench_mpi: mpi4py is not installed (pip install 'nurbsdem[mpi]'): nothing measured")
        return {}
    rows = strong(a.n, a.settle, a.measure, a.ranks, a.cache, a.repeat)
    res = dict(n=a.n, cores=os.cpu_count(), strong=rows,
               weak_settled=weak_settled(a.n // a.ranks, a.ranks, a.settle, a.measure, a.cache,
                                         rows, a.n),
               weak=weak(a.weak_n, a.ranks))
    print("RESULT " + json.dumps(res))
    return res


if __name__ == "__main__":
    main()

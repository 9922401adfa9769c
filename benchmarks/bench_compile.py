"""The first run's compilation: cold and warm times of decks, of ``nurbsdem warmup`` and of the
test suite.

Each deck (default: the quick paper example and the two-sphere deck) is solved twice in fresh
processes with an empty numba cache of its own (``NUMBA_CACHE_DIR`` in a temporary folder):
the first run compiles the kernels it needs (``nurbsdem.first_run``: in parallel processes,
then it runs on the Python driver; the compiled loop compiles in the background, after the
run where it is short), the second, once that background compilation has ended, loads them.  Printed per deck: both
wall times and CPU times (the processes' user + system time: less sensitive to other work
on the machine than the wall time), their difference (the compilation), the cached libraries
(files, MB), the kernels cached in more than one specialisation (each a second compilation
of the kernel and everything it calls) and whether the two runs wrote the same monitor files
byte for byte (compiled code from the cache must give the same bits).

Run it with nothing else on the machine: the solver's threads wait for each other actively, so
beside a second process with threads of its own the second run of the quick deck took about ten
times as long (two instances side by side on 2 cores), while the first runs, which compile on
one thread, took a third longer.

``--warmup``: also ``nurbsdem warmup`` into an empty cache, then the first deck from it.
``--suite``: also the test suite (``pytest -q -x``) with an empty cache, then again.
``--compiles``: also each kernel's compile time in a first run of the first deck that
compiles everything in its own process (numba's compile events), the longest first.

Usage: .venv/bin/python benchmarks/bench_compile.py [--deck CASE.inp ...] [--warmup]
       [--suite] [--compiles N]
"""
from __future__ import annotations

import argparse
import json
import os
import pickle
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import REPO, machine_info, stamp  # noqa: E402

DECKS = ("inputs/paper/compaction_quick.inp", "inputs/regression/two_spheres.inp")


def timed(cmd: list[str], cache: Path) -> tuple[float, float]:
    """(wall s, CPU s) of ``cmd`` in a new process with numba's cache in ``cache``."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, env=env, cwd=REPO, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def solve_cmd(deck: Path, out: Path) -> list[str]:
    return [sys.executable, "-m", "nurbsdem", "solve", str(deck), "--output", str(out),
            "--quiet"]


def specialisations(cache: Path) -> dict[str, int]:
    """Kernel name -> number of cached specialisations, from numba's index files."""
    counts = {}
    for index in cache.rglob("*.nbi"):
        with open(index, "rb") as f:
            pickle.load(f)                          # numba's version
            _, overloads = pickle.loads(f.read())
        counts[index.name.split(".py")[0]] = len(overloads)
    return counts


def monitors(out: Path) -> dict[str, bytes]:
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*.csv"))}


def fmt(label: str, t: tuple[float, float]) -> str:
    return f"{label} {t[0]:.1f} s (CPU {t[1]:.1f} s)"


def background_seconds(cache: Path, limit: float = 1800.0) -> float:
    """Seconds until the compiled loop's background compilation, which a first solve
    starts (:func:`nurbsdem.warmup.compile_loop_in_background`), has ended (its process id
    file in ``cache`` gone); 0 when none runs."""
    from nurbsdem.warmup import LOOP_PID_FILE
    t0 = time.perf_counter()
    pid_file = next(cache.rglob(LOOP_PID_FILE), None)
    while pid_file is not None and pid_file.exists() and time.perf_counter() - t0 < limit:
        time.sleep(0.5)
    return time.perf_counter() - t0


def bench_deck(deck: Path, tmp: Path) -> bool:
    """Cold and warm run of ``deck``; prints them; returns whether the monitors agree."""
    cache = tmp / f"cache-{deck.stem}"
    cold = timed(solve_cmd(deck, tmp / f"{deck.stem}-cold"), cache)
    behind = background_seconds(cache)
    warm = timed(solve_cmd(deck, tmp / f"{deck.stem}-warm"), cache)
    files = [p for p in cache.rglob("*") if p.suffix in (".nbi", ".nbc")]
    size = sum(p.stat().st_size for p in files) / 1e6
    twice = {k: n for k, n in specialisations(cache).items() if n > 1}
    same = monitors(tmp / f"{deck.stem}-cold") == monitors(tmp / f"{deck.stem}-warm")
    print(f"{deck.name}: {fmt('first run', cold)}, {fmt('second run', warm)}: compiling "
          f"{cold[0] - warm[0]:.1f} s (CPU {cold[1] - warm[1]:.1f} s); the compiled loop "
          f"in the background {behind:.1f} s after the first run; cache {len(files)} "
          f"files, {size:.1f} MB")
    print(f"  kernels in more than one specialisation: {len(twice)}"
          + "".join(f"\n    {k}: {n}" for k, n in sorted(twice.items())))
    print(f"  monitor files of both runs identical: {'yes' if same else 'NO'}")
    return same


def bench_warmup(deck: Path, tmp: Path) -> None:
    """``nurbsdem warmup`` into an empty cache, then ``deck`` from it."""
    cache = tmp / "cache-warmup"
    warm_up = timed([sys.executable, "-m", "nurbsdem", "warmup"], cache)
    run = timed(solve_cmd(deck, tmp / "after-warmup"), cache)
    print(f"nurbsdem warmup: {fmt('empty cache', warm_up)}; then {deck.name}: {fmt('', run)}")


def bench_suite(tmp: Path) -> None:
    """The test suite with an empty cache, then again with the cache it filled."""
    cache = tmp / "cache-suite"
    cmd = [sys.executable, "-m", "pytest", "-q", "-x", "-p", "no:cacheprovider"]
    cold = timed(cmd, cache)
    warm = timed(cmd, cache)
    print(f"test suite: {fmt('empty cache', cold)}, {fmt('filled cache', warm)}")


_PROFILE = r"""
import json, os, sys, time
from numba.core import event
stack, out = [], []
class L(event.Listener):
    def on_start(self, ev):
        stack.append([time.perf_counter(), 0.0])
    def on_end(self, ev):
        t0, inner = stack.pop()
        dt = time.perf_counter() - t0
        if stack:
            stack[-1][1] += dt
        f = ev.data["dispatcher"].py_func
        out.append((f"{f.__module__}.{f.__qualname__}", dt, dt - inner, len(stack)))
event.register("numba:compile", L())
import nurbsdem.first_run
nurbsdem.first_run.prepare_first_solve = lambda sim: None    # everything in this process
from nurbsdem.cli import main
try:
    main(["solve", sys.argv[1], "--output", sys.argv[2], "--quiet"], standalone_mode=False)
finally:
    json.dump(out, open(sys.argv[3], "w"))
"""


def bench_compiles(deck: Path, tmp: Path, n: int) -> None:
    """Each kernel's compile time (with and without the kernels it calls) in a cold run."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp / "cache-profile"))
    subprocess.run([sys.executable, "-c", _PROFILE, str(deck), str(tmp / "profile-out"),
                    str(tmp / "profile.json")], check=True, env=env, cwd=REPO,
                   stdout=subprocess.DEVNULL)
    rows = json.loads((tmp / "profile.json").read_text())
    total = sum(r[2] for r in rows)
    print(f"{deck.name}: {len(rows)} compilations, {total:.1f} s; the longest (own s, with "
          f"the kernels compiled within s, depth):")
    for name, incl, own, depth in sorted(rows, key=lambda r: -r[2])[:n]:
        print(f"  {own:7.1f} {incl:7.1f}  {depth}  {name}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--deck", action="append", default=None,
                    help="a deck to time (repeatable; default: the quick paper example and "
                         "the two-sphere deck)")
    ap.add_argument("--warmup", action="store_true", help="also time nurbsdem warmup")
    ap.add_argument("--suite", action="store_true",
                    help="also time the test suite, cold and warm (the longest part)")
    ap.add_argument("--compiles", type=int, default=0, metavar="N",
                    help="also list the N longest kernel compilations of the first deck")
    a = ap.parse_args(argv)
    decks = [(REPO / d).resolve() for d in (a.deck or DECKS)]
    print(stamp(machine_info()))
    same = True
    with tempfile.TemporaryDirectory(prefix="nurbsdem-compile-") as tmp:
        tmp = Path(tmp)
        for deck in decks:
            same &= bench_deck(deck, tmp)
        if a.warmup:
            bench_warmup(decks[0], tmp)
        if a.compiles:
            bench_compiles(decks[0], tmp, a.compiles)
        if a.suite:
            bench_suite(tmp)
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())

"""The first run's compilation: time and duplicate work together.

``nurbsdem solve`` of a deck (default: the quick paper example) twice in fresh processes with
an empty numba cache of its own (``NUMBA_CACHE_DIR`` in a temporary folder): the first run
compiles every kernel it needs, the second loads them.  Printed: both wall times and their
difference (the compilation), the cached libraries (files, MB), the kernels cached in more
than one specialisation (each a second compilation of the kernel and everything it calls;
``nurbsdem/jit.py`` says which ones are deliberate), and whether the two runs wrote the same
monitor files byte for byte (compiled code from the cache must give the same bits).

Usage: .venv/bin/python benchmarks/bench_compile.py [--deck CASE.inp]   (~5 min on 2 cores)
"""
from __future__ import annotations

import argparse
import os
import pickle
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import REPO, machine_info, stamp  # noqa: E402


def solve(deck: Path, out: Path, cache: Path) -> float:
    """Wall time (s) of ``nurbsdem solve deck`` in a new process with numba's cache in
    ``cache``."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "nurbsdem", "solve", str(deck), "--output",
                    str(out), "--quiet"], check=True, env=env, cwd=REPO)
    return time.perf_counter() - t0


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


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--deck", default=str(REPO / "inputs/paper/compaction_quick.inp"))
    a = ap.parse_args(argv)
    deck = Path(a.deck).resolve()
    print(stamp(machine_info()))
    with tempfile.TemporaryDirectory(prefix="nurbsdem-compile-") as tmp:
        tmp = Path(tmp)
        cold = solve(deck, tmp / "cold", tmp / "cache")
        warm = solve(deck, tmp / "warm", tmp / "cache")
        files = [p for p in (tmp / "cache").rglob("*") if p.suffix in (".nbi", ".nbc")]
        size = sum(p.stat().st_size for p in files) / 1e6
        twice = {k: n for k, n in specialisations(tmp / "cache").items() if n > 1}
        same = monitors(tmp / "cold") == monitors(tmp / "warm")
    print(f"{deck.name}: first run {cold:.1f} s, second run {warm:.1f} s: compiling "
          f"{cold - warm:.1f} s; cache {len(files)} files, {size:.1f} MB")
    print(f"kernels in more than one specialisation: {len(twice)}"
          + "".join(f"\n  {k}: {n}" for k, n in sorted(twice.items())))
    print(f"monitor files of both runs identical: {'yes' if same else 'NO'}")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())

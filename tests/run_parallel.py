"""The test suite on every usable core: what ``make test`` (and so CI) runs.

1. The kernels are compiled into numba's cache first (:func:`nurbsdem.warmup.warm_up`, its
   independent stages in parallel processes, the mesh and surface walls' kernels included),
   so that the test processes load them instead of each compiling them again.
2. One pytest process per usable core (at most :data:`MAX_WORKERS`) then shares the test
   files (``tests/conftest.py``: each claims whole files as it reaches them, so the load
   balances itself).  The first starts as soon as the warm-up leaves a core free (its last
   stage, the time loop, compiles alone) and takes the files that do not run the time loop
   first.  Progress is told every 30 s, the reports at the end.
3. Each process's report is printed; the exit status is the first non-zero one, and a file
   no process ran fails the run.

Arguments are passed to every pytest process (``python tests/run_parallel.py -x -k mpi``).
A plain ``pytest`` runs the same tests in one process.  pytest-xdist would do step 2, but it
is not among the project's dependencies, and a run here needs the warm-up step anyway.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TESTS = Path(__file__).resolve().parent
T0 = time.perf_counter()


#: at most this many pytest processes (each holds the compiled kernels, ~1 GB, and starts
#: numba's threads on every core)
MAX_WORKERS = 4


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:          # not Linux
        return os.cpu_count() or 1


def _warm_up(on_free_core=None) -> None:
    """Compile the kernels into numba's cache; a failure is reported and the tests go on
    (they show the error where it matters).  ``on_free_core()`` is called after each stage
    that leaves fewer stages than there are cores (the last stage, the time loop, compiles
    alone)."""
    from nurbsdem.warmup import ALL_STAGES, warm_up
    t0 = time.perf_counter()
    done: set[str] = set()

    def on_done(name: str, seconds: float) -> None:
        done.add(name)
        if on_free_core is not None and len(ALL_STAGES) - len(done) < _cores():
            on_free_core()

    try:
        times = warm_up(stages=ALL_STAGES, on_done=on_done)
    except Exception as exc:        # noqa: BLE001 - the tests report it properly
        print(f"run_parallel: the warm-up failed ({type(exc).__name__}: {exc}); "
              "the tests compile what they need", flush=True)
        return
    print(f"run_parallel: kernels compiled in {time.perf_counter() - t0:.0f} s ("
          + ", ".join(f"{k} {v:.0f} s" for k, v in times.items()) + ")", flush=True)


def _wait(procs: list, claims: Path, every: float = 30.0) -> list[int]:
    """Wait for the workers, saying every ``every`` s how many test files they have started
    (the reports come at the end); returns their exit statuses."""
    listed = claims / "files.txt"
    said = -1
    while any(p.poll() is None for p in procs):
        time.sleep(every if said >= 0 else 1.0)
        started = len(list(claims.glob("*.claim")))
        if started != said and listed.is_file():
            total = len(listed.read_text().split())
            print(f"run_parallel: {started} of {total} test files started, "
                  f"{time.perf_counter() - T0:.0f} s", flush=True)
            said = started
    return [p.wait() for p in procs]


def main(argv: list[str]) -> int:
    n = min(_cores(), MAX_WORKERS)
    with tempfile.TemporaryDirectory(prefix="nurbsdem-tests-") as tmp:
        claims = Path(tmp) / "claims"
        claims.mkdir()
        procs, logs = [], []

        def start_worker(early: bool = False) -> None:
            k = len(procs)
            log = open(Path(tmp) / f"worker{k}.log", "w+", encoding="utf-8")
            env = dict(os.environ, NURBSDEM_TEST_CLAIMS=str(claims),
                       NURBSDEM_TEST_WORKER=f"{k}/{n}")
            if early:
                env["NURBSDEM_TEST_EARLY"] = "1"
                print(f"run_parallel: a core is free, worker 1 starts ("
                      f"{time.perf_counter() - T0:.0f} s)", flush=True)
            procs.append(subprocess.Popen(
                [sys.executable, "-m", "pytest", "-p", "no:cacheprovider",
                 f"--basetemp={Path(tmp) / f'basetemp{k}'}", *argv],
                cwd=TESTS.parent, env=env, stdout=log, stderr=subprocess.STDOUT))
            logs.append(log)

        def start_early() -> None:
            if not procs:
                start_worker(early=True)

        _warm_up(on_free_core=start_early if n > 1 else None)
        while len(procs) < n:
            start_worker()
        codes = _wait(procs, claims)
        summaries = []
        for k, log in enumerate(logs):
            log.seek(0)
            text = log.read()
            log.close()
            print(f"\n===== pytest worker {k + 1} of {n} (exit status {codes[k]}) =====")
            print(text, end="", flush=True)
            last = [ln.strip("= ") for ln in text.splitlines()
                    if re.search(r"\d+ (passed|failed|errors?|skipped|deselected)", ln)]
            summaries.append(last[-1] if last else "no summary")
        listed = claims / "files.txt"
        files = listed.read_text().split() if listed.is_file() else []
        missed = [f for f in files
                  if not (claims / (f.replace(os.sep, "__") + ".claim")).is_file()]
    if missed:
        print(f"run_parallel: no worker ran {', '.join(missed)}")
        return 1
    print("run_parallel: " + "; ".join(f"worker {k + 1}: {t}" for k, t in enumerate(summaries))
          + f"; {time.perf_counter() - T0:.0f} s in all, the warm-up included", flush=True)
    failed = [c for c in codes if c != 0]
    return failed[0] if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

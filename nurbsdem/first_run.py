"""The first solve after an install, an upgrade or an edit of the kernels' sources
(``nurbsdem solve`` with numba's cache lacking the compiled time loop).

The kernels a deck needs compile in parallel processes (:func:`nurbsdem.warmup.first_run_stages`:
the LCP's beside the Python driver's, which a deck of exact spheres compiles without an LCP),
then the deck runs on the Python driver of the internal steps, the same compiled parts with
the same results as the compiled time loop, while the loop, about a third of a cold
compilation, compiles in a background process for the next runs
(:func:`nurbsdem.warmup.compile_loop_in_background`).  Once it is cached the run goes on in
it.  On several MPI ranks, or with ``NUMBA_DISABLE_JIT``, a solve compiles what it calls as
it calls it.
"""
from __future__ import annotations

import logging
import os
import time
from typing import Any

import numba
from numba.core import config

from . import warmup
from .cachecheck import compiles_first
from .geometry.analytic import exact_sphere
from .parallel.comm import launched_size


def prepare_first_solve(sim: Any) -> None:
    """When numba's cache lacks the compiled time loop (the first solve after an install, an
    upgrade or an edit of the kernels' sources) and no MPI launcher started several processes:
    compile the kernels the deck needs in parallel processes
    (:func:`nurbsdem.warmup.first_run_stages`; on one core they compile as the run calls
    them), run the deck on the Python driver of the internal steps (the same parts, the same
    results as the compiled loop) and compile the loop in the background for later solves
    (:func:`nurbsdem.warmup.compile_loop_in_background`).  The loop alone is about a third
    of a cold compilation: so the first result comes sooner, and the second run is as fast
    as any later one."""
    if config.DISABLE_JIT or launched_size() > 1 or not compiles_first():
        return
    log = logging.getLogger("nurbsdem")
    if warmup.loop_compiling_in_background():
        log.info("the compiled time loop is still compiling in the background; this run "
                 "steps on the Python driver, with the same results, on one core less")
    else:
        _compile_in_parallel(needs_lcp(sim.solver.model), log)
        pid = warmup.compile_loop_in_background()
        if pid is None:         # no writable cache folder: the run compiles the loop itself
            return
        log.info("compiling the compiled time loop in the background for the next runs "
                 "(process %d); this run steps on the Python driver, with the same results, "
                 "on one core less", pid)
    sim.solver.compiled_steps = False
    sim.solver.compiled_when = LoopInBackground(log)


def _compile_in_parallel(lcp: bool, log: logging.Logger) -> None:
    """The stages of :func:`nurbsdem.warmup.first_run_stages` in parallel processes where
    there are two cores or more (else the run compiles what it calls); a stage that fails
    leaves its kernels to the run, with a warning."""
    if warmup._usable_cores() < 2:
        return
    stages = warmup.first_run_stages(lcp)
    log.info("compiling %s in %d processes", ", ".join(s.name for s in stages),
             min(len(stages), warmup._usable_cores()))
    try:
        warmup.warm_up(stages=stages, on_done=lambda name, seconds: log.info(
            "compiled %s (%.0f s)", name, seconds))
    except Exception as exc:      # the run compiles the kernels it calls itself
        log.warning("compiling in parallel processes failed (%s); the run compiles the "
                    "kernels it calls", exc)


class LoopInBackground:
    """While the compiled loop compiles in the background: the kernels' threads one fewer
    than the usable cores, since the threads of a parallel batch wait for each other
    actively and one that shares its core with the compilation holds every batch up (the
    LCP of the quick paper deck took twenty times as long with both threads).  Called
    (:attr:`nurbsdem.solver.Solver.compiled_when`), at most once a second it looks whether
    the compilation is done and the loop cached; then the threads are as before and it
    answers True: the run goes on in the compiled loop."""

    def __init__(self, log: Any) -> None:
        self.log = log
        self.threads = numba.get_num_threads()
        if "NUMBA_NUM_THREADS" not in os.environ:
            numba.set_num_threads(max(1, min(self.threads, warmup._usable_cores() - 1)))
        self.checked = time.monotonic()
        self.failed = False

    def __call__(self) -> bool:
        if self.failed or time.monotonic() - self.checked < 1.0:
            return False
        self.checked = time.monotonic()
        if warmup.loop_compiling_in_background():
            return False
        numba.set_num_threads(self.threads)
        if compiles_first():            # the background compilation failed
            self.failed = True
            self.log.info("the compiled time loop is not in the cache: the run goes on "
                          "on the Python driver, on all cores")
            return False
        self.log.info("the compiled time loop is compiled: the run goes on in it")
        return True


def needs_lcp(model: Any) -> bool:
    """Whether any particle shape of ``model`` is not an exact sphere (its pairs need the
    LCP's kernels)."""
    return any(exact_sphere(entry.shape) is None for entry in model.shapes.values())

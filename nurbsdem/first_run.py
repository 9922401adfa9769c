"""The first solve after an install, an upgrade or an edit of the kernels' sources
(``nurbsdem solve`` with numba's cache lacking the compiled time loop).

The kernels a deck needs compile in parallel processes (:func:`nurbsdem.warmup.first_run_stages`:
the LCP's beside the Python driver's, which a deck of exact spheres compiles without an LCP),
then the deck runs on the Python driver of the internal steps, the same compiled parts with
the same results as the compiled time loop.  The loop, about a third of a cold compilation,
compiles in a background process for the next runs (:func:`nurbsdem.warmup.compile_loop_in_background`):
at once when the run promises to last longer than that compilation takes, and the run goes
on in the loop once it is cached; else when the run ends, so that a short first run keeps
every core.  On several MPI ranks, or with ``NUMBA_DISABLE_JIT``, a solve compiles what it
calls as it calls it.
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


def prepare_first_solve(sim: Any) -> "LoopInBackground | None":
    """When numba's cache lacks the compiled time loop (the first solve after an install, an
    upgrade or an edit of the kernels' sources) and no MPI launcher started several processes:
    compile the kernels the deck needs in parallel processes
    (:func:`nurbsdem.warmup.first_run_stages`; on one core they compile as the run calls
    them) and run the deck on the Python driver of the internal steps (the same parts, the
    same results as the compiled loop); the loop compiles in the background
    (:class:`LoopInBackground`).  The loop alone is about a third of a cold compilation: so
    the first result comes sooner, and the second run is as fast as any later one.  Returns
    the :class:`LoopInBackground` whose :meth:`~LoopInBackground.finish` the caller calls
    after the run (None: nothing to compile)."""
    if config.DISABLE_JIT or launched_size() > 1 or not compiles_first():
        return None
    log = logging.getLogger("nurbsdem")
    running = warmup.loop_compiling_in_background()
    if running:
        log.info("the compiled time loop is still compiling in the background; this run "
                 "steps on the Python driver, with the same results, on one core less")
    else:
        _compile_in_parallel(needs_lcp(sim.solver.model), log)
    loop = LoopInBackground(log, sim.solver, started=running)
    sim.solver.compiled_steps = False
    sim.solver.compiled_when = loop
    return loop


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


#: a first run expected to go on for longer than this (s of wall time) starts the compiled
#: loop's background compilation at once, to take the loop when it is cached; about what that
#: compilation takes beside the run on two cores
WORTH_THE_LOOP_S = 60.0
#: wall time (s) a first run steps before it estimates how long it goes on
ESTIMATE_AFTER_S = 2.0


class LoopInBackground:
    """The compiled loop's background compilation during and after a first run on the Python
    driver (:attr:`nurbsdem.solver.Solver.compiled_when`, asked before each chunk of deck
    steps).  At most once a second it estimates the run's wall time left from the simulated
    time done since its first call (``solver.time`` of ``solver.model.total_time``; a
    restart's run starts at its checkpoint's time); when that exceeds
    :data:`WORTH_THE_LOOP_S` it starts the compilation
    (:func:`nurbsdem.warmup.compile_loop_in_background`) and runs the kernels on one thread
    fewer than the usable cores, since the threads of a parallel batch wait for each other
    actively and one that shares its core with the compilation holds every batch up (the
    LCP of the quick paper deck took twenty times as long with both threads).  Once the loop
    is cached it restores the threads and answers True: the run goes on in the compiled
    loop.  A shorter run keeps every core and starts the compilation at its end
    (:meth:`finish`).  ``started``: a compilation runs already (another solve's)."""

    def __init__(self, log: Any, solver: Any, started: bool = False) -> None:
        self.log = log
        self.solver = solver
        self.threads = numba.get_num_threads()
        self.t_start = time.monotonic()
        self.sim_start: float | None = None       # the simulated time at the first call
        self.sim_end = float(solver.model.total_time)
        self.checked = self.t_start
        self.started = False
        self.failed = False
        if started:
            self._share_the_cores()

    def __call__(self) -> bool:
        if self.sim_start is None:      # before the first chunk of deck steps
            self.sim_start, self.t_start = float(self.solver.time), time.monotonic()
        if self.failed or time.monotonic() - self.checked < 1.0:
            return False
        self.checked = time.monotonic()
        if not self.started:
            if self.seconds_left() > WORTH_THE_LOOP_S:
                self._start("the run goes on in it once it is compiled")
            return False
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

    def seconds_left(self) -> float:
        """The run's wall time left (s), estimated from the simulated time done in the wall
        time since the first call; 0 before :data:`ESTIMATE_AFTER_S`, infinite when no simulated
        time is done after it."""
        elapsed = time.monotonic() - self.t_start
        if self.sim_start is None or elapsed < ESTIMATE_AFTER_S:
            return 0.0
        done = float(self.solver.time) - self.sim_start
        if done <= 0.0:
            return float("inf")
        return elapsed * max(self.sim_end - float(self.solver.time), 0.0) / done

    def finish(self) -> None:
        """After the run: start the background compilation for the next runs if the run did
        not (a short run); the threads as before."""
        if not self.started and not self.failed:
            self._start("for the next runs")
        numba.set_num_threads(self.threads)

    def _start(self, then: str) -> None:
        pid = warmup.compile_loop_in_background()
        if pid is None:       # no writable cache folder, or another solve compiles it already
            self.failed = not warmup.loop_compiling_in_background()
            self.started = not self.failed
        else:
            self.started = True
            self.log.info("compiling the compiled time loop in the background (process %d); "
                          "%s", pid, then)
        if self.started:
            self._share_the_cores()

    def _share_the_cores(self) -> None:
        self.started = True
        if "NUMBA_NUM_THREADS" not in os.environ:
            numba.set_num_threads(max(1, min(self.threads, warmup._usable_cores() - 1)))


def needs_lcp(model: Any) -> bool:
    """Whether any particle shape of ``model`` is not an exact sphere (its pairs need the
    LCP's kernels)."""
    return any(exact_sphere(entry.shape) is None for entry in model.shapes.values())

"""What a run tells its user: a progress line per step while it runs (:class:`Progress`) and
the summary at its end (:class:`RunSummary`, printed by ``nurbsdem solve``), with the
wall-time split the summary reports (:class:`ChunkMeter`)."""
from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field


@dataclass
class RunSummary:
    """What :meth:`Solver.run <nurbsdem.solver.Solver.run>` reports at the end (also printed
    by ``nurbsdem solve``)."""

    wall_time: float = 0.0
    steps: int = 0
    substeps: int = 0
    lcps: int = 0
    #: contact evaluations (calls of the contact search, rejected attempts included)
    evaluations: int = 0
    degenerated: int = 0
    failed: int = 0
    active_max: int = 0
    active_total: int = 0
    balance_error: float = 0.0
    balance_scale: float = 0.0
    #: deck steps the accuracy control repeated with more sub-steps (``Accuracy`` on a step)
    accuracy_repeats: int = 0
    simulated_time: float = 0.0
    particles: int = 0
    timers: dict = field(default_factory=dict)
    #: two parts of ``timers["forces + integration"]`` (s): the implicit dashpots' solves and
    #: the time-step control (Gershgorin gates and exact estimates) in the time loop
    split: dict = field(default_factory=dict)

    def _balance_share(self) -> str:
        """The balance error relative to the energy turned over (dissipated + external work),
        or that energy itself when it is too small for a ratio to mean anything."""
        err, scale = abs(self.balance_error), abs(self.balance_scale)
        if scale > 0 and math.isfinite(scale) and err <= scale:
            return f"({err / scale:.2e} of the {scale:.3g} J turned over)"
        return f"(only {scale:.3g} J of energy was turned over)"

    def text(self) -> str:
        t = self.timers
        total = max(self.wall_time, 1e-12)
        split = ", ".join(f"{k} {v:.1f} s ({100 * v / total:.0f} %)" for k, v in t.items())
        parts = ", ".join(f"{k} {v:.1f} s" for k, v in self.split.items() if v > 0.0)
        return (f"done: {self.simulated_time:.4g} s simulated, {self.particles} particles, "
                f"{self.steps} time steps ({self.substeps} internal), wall time "
                f"{self.wall_time:.1f} s\n"
                f"contacts: {self.lcps} LCPs solved, at most {self.active_max} active; over all "
                f"steps {self.active_total} active contacts, {self.degenerated} of them "
                f"degenerated ({100 * self.degenerated / max(self.active_total, 1):.2f} %), "
                f"{self.failed} failed LCPs\n"
                f"energy balance error: {self.balance_error:.3e} J {self._balance_share()}\n"
                + (f"accuracy control: {self.accuracy_repeats} deck steps repeated with more "
                   f"sub-steps\n" if self.accuracy_repeats else "")
                + f"time split: {split}"
                + (f" (of forces + integration: {parts})" if parts else ""))


class ChunkMeter:
    """The counters of a scene and its system when a chunk of deck steps starts, to book the
    chunk's wall time (s) and counts into a run's timers and :class:`RunSummary` when it
    ends (:meth:`book`)."""

    def __init__(self, scene, system) -> None:
        self.t_before = time.perf_counter()
        timers = scene.timers
        self.search, self.lcp = timers.global_search, timers.lcp
        self.lcps, self.calls = timers.lcps, timers.calls
        self.parts = dict(system.split)

    def book(self, scene, system, done: int, timers: dict, split: dict,
             summary: RunSummary) -> None:
        """Add the chunk of ``done`` deck steps: the wall time since the start split into the
        global search, the LCPs and the rest (forces + integration, its parts in ``split``),
        and the system's tally of the chunk (:attr:`DemSystem.last_steps`) to ``summary``."""
        dt_wall = time.perf_counter() - self.t_before
        g = scene.timers.global_search - self.search
        lc = scene.timers.lcp - self.lcp
        timers["global search"] += g
        timers["LCP"] += lc
        timers["forces + integration"] += dt_wall - g - lc
        for k, v in system.split.items():
            split[k] += v - self.parts[k]
        summary.steps += done
        summary.lcps += scene.timers.lcps - self.lcps
        summary.evaluations += scene.timers.calls - self.calls
        tally = system.last_steps
        summary.substeps += tally.substeps
        summary.active_max = max(summary.active_max, tally.active_max)
        summary.active_total += tally.active_sum
        summary.degenerated += tally.degenerated_sum
        summary.failed += tally.failed_sum


class Progress:
    """A one-line progress display per step on stderr (simulated time, time step, active
    contacts, estimated time left). Silent when ``quiet``."""

    def __init__(self, quiet: bool, stream=None) -> None:
        self.quiet = quiet
        self.stream = stream or sys.stderr
        self.last = 0.0
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()

    def start(self, label: str, duration: float) -> None:
        self.label, self.duration, self.t_start, self.t_wall = label, duration, None, time.perf_counter()

    def update(self, t_step: float, dt: float, substeps: int, active: int, force: bool = False) -> None:
        if self.quiet:
            return
        now = time.perf_counter()
        if not force and now - self.last < (0.5 if self.tty else 10.0):
            return
        self.last = now
        frac = min(1.0, t_step / self.duration) if self.duration > 0 else 1.0
        el = now - self.t_wall
        eta = el * (1 - frac) / frac if frac > 0 else float("nan")
        bar = "#" * int(30 * frac)
        line = (f"{self.label} [{bar:<30s}] {100 * frac:5.1f} %  t={t_step:.4f}/{self.duration:g} s  "
                f"dt={dt:.3g} s x{substeps}  contacts={active}  left~{eta:5.0f} s")
        end = "\r" if self.tty else "\n"
        print(line, end=end, file=self.stream, flush=True)

    def finish(self) -> None:
        if not self.quiet and self.tty:
            print(file=self.stream)

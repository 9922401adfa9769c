"""When output falls due: ``VTK Every``, ``Monitors Every``, ``Results Every`` and
``Checkpoint Every`` on the time grid of a step.

The output times asked for are the multiples k·every (k = 0, 1, 2, ...) of an interval
``every`` (s).  The solver can write only at the end of a deck time step (time t0 + n·dt of a
step), so a multiple is served by the first step end at or after it: a step ending at t (s)
after a step of dt (s) is due when a multiple lies in (t − dt, t].  With dt dividing
``every`` this is every multiple exactly; otherwise each multiple's sample comes within one
time step after it, without drift (the multiples are k·every, not sums of rounded gaps) and
without skipping any (an interval shorter than dt gives a sample at every step, serving
every multiple in the step).  Times are compared to 1e-9 of the larger of the interval and
the time, so that t0 + n·dt rounded in floating point still meets its multiple.
"""
from __future__ import annotations

import math

import numpy as np

#: relative tolerance of "t is at or past a multiple"
REL_TOL = 1e-9


def multiples_upto(t, every: float):
    """How many multiples k·every with k >= 1 lie at or before time ``t`` (s; a float or an
    array), i.e. floor(t / every) to within :data:`REL_TOL`."""
    t = np.asarray(t, float)
    q = t / every
    k = np.floor(q + REL_TOL * np.maximum(1.0, np.abs(q)))
    return k if k.ndim else float(k)


def due_mask(times: np.ndarray, every: float, dt: float) -> np.ndarray:
    """(n,) bool: whether the step ending at each time ``times`` (n,) s, after a step of
    ``dt`` s, is the first at or after a multiple of ``every`` (s); all False for
    ``every <= 0`` (no output of that kind)."""
    times = np.asarray(times, float)
    if every <= 0:
        return np.zeros(times.shape, bool)
    return multiples_upto(times, every) > multiples_upto(times - dt, every)


def due(t: float, every: float, dt: float) -> bool:
    """:func:`due_mask` of one time."""
    return bool(due_mask(np.array([float(t)]), every, dt)[0])


def steps_to_due(t0: float, count: int, dt: float, every: float, n_max: int) -> int:
    """The first k in 1..n_max whose step end t0 + (count + k)·dt is due (:func:`due_mask`),
    n_max if none."""
    if every <= 0:
        return n_max
    k = np.arange(1, n_max + 1)
    hit = np.flatnonzero(due_mask(t0 + (count + k) * dt, every, dt))
    return int(k[hit[0]]) if hit.size else n_max


def last_multiple(t: float, every: float) -> float:
    """The last multiple k·every (k >= 1) at or before ``t`` (s); 0.0 if none."""
    return float(multiples_upto(t, every)) * every if every > 0 else 0.0


def exact(every: float, dt: float) -> bool:
    """Whether ``every`` (s) is a whole number (>= 1) of time steps ``dt`` (s)."""
    ratio = every / dt
    n = round(ratio)
    return n >= 1 and abs(ratio - n) <= REL_TOL * max(1.0, ratio)


def describe(every: float, dt: float) -> str:
    """What an interval ``every`` gives on a time grid of ``dt`` (s), for ``nurbsdem check``:
    "every 0.0025 s" when dt divides it, else how far apart the samples come."""
    if every <= 0:
        return "never"
    if exact(every, dt):
        return f"every {every:g} s"
    ratio = every / dt
    if ratio < 1:
        return f"every time step ({dt:g} s, shorter than the interval asked {every:g} s)"
    lo, hi = math.floor(ratio), math.ceil(ratio)
    return f"{every:g} s on average ({lo * dt:g} or {hi * dt:g} s apart)"

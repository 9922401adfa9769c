"""Where a dynamic step's compiled loop stops for the solver, and which of the deck steps in
between take output samples: each output interval is served by the first deck time step at
or after each of its multiples (:mod:`nurbsdem.io.intervals`)."""
from __future__ import annotations

import numpy as np

from .io import intervals

#: most deck steps handed to DemSystem.steps at once (compiled scenes; progress granularity)
MAX_COMPILED_STEPS = 200
#: the most bytes of ParaView/results states (:class:`~nurbsdem.dynamics.monitor.StateSample`)
#: the compiled loop keeps in one call: a call ends at the sample that would pass it (10^5
#: particles with 2.4·10^5 contacts: ~57 MB per sample)
STATE_BUDGET_BYTES = 256 * 2 ** 20


def steps_to_event(sysm, out, left: int,
                   ck_every: float) -> tuple[int, np.ndarray, np.ndarray]:
    """Deck steps n of system ``sysm`` from now to the next one at which a checkpoint falls
    due (every ``ck_every`` s; monitors too with Hertz–Mindlin laws), or to the end of the
    solution step (``left`` deck steps), at most MAX_COMPILED_STEPS, and at most as many
    ParaView/results states as STATE_BUDGET_BYTES holds; with the flags of :func:`due_flags`
    for those n deck steps (``out``: the model's output settings).  The monitors, ParaView
    and results samples in between are taken by the system at the deck steps' ends: the
    compiled loop runs on through them."""
    n = min(left, MAX_COMPILED_STEPS)
    # monitors are recorded inside the compiled loop, except the Hertz row (taken live)
    monitors = out.monitors_every if sysm.uses_hertz else 0.0
    for every in (monitors, ck_every):
        if every > 0:
            n = min(n, intervals.steps_to_due(sysm.t0, sysm.step_count, sysm.dt, every, n))
    monitors_due, states_due = due_flags(sysm, out, n)
    due = np.flatnonzero(states_due)
    most = max(1, STATE_BUDGET_BYTES // max(sysm.state_sample_bytes(), 1))
    if len(due) > most:             # the last deck step's sample is taken live
        n = int(due[most - 1]) + 1
    return n, monitors_due[:n], states_due[:n]


def due_flags(sysm, out, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(monitors, states), (n,) bool each: the next n deck steps of system ``sysm`` at whose
    end the monitors fall due, and the ParaView or results output (``out``: the model's
    output settings)."""
    times = sysm.t0 + (sysm.step_count + np.arange(1, n + 1)) * sysm.dt
    dt = sysm.dt
    return (intervals.due_mask(times, out.monitors_every, dt),
            intervals.due_mask(times, out.vtk_every, dt)
            | intervals.due_mask(times, out.results_interval, dt))

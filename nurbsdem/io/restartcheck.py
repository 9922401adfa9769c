"""Before a restart continues an output folder: do its files reach the checkpoint's time?

A checkpoint is saved only after the samples up to its time are durable (results.h5, the
monitor CSVs, the .pvd indices: :meth:`~nurbsdem.io.writers.OutputWriters.checkpoint`), so in
the folder that wrote it every series holds the sample of the last output time at or before
the checkpoint's time t: the last multiple K·every <= t of its interval is served by the
first time step at or after it (:mod:`nurbsdem.io.intervals`), which is at or before t,
because t is itself the end of a time step.  A file that ends earlier was cut short (a full
disk, a copy of an older folder, a file put back by hand): continuing it would leave a hole
from its end to t, so the restart is refused with one line naming the file and both times.
A missing file is started anew at the checkpoint's time (no hole inside it).
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Iterable

from ..errors import InputError
from .intervals import REL_TOL, last_multiple


def csv_last_time(path: Path, n_columns: int) -> float:
    """The time of the last complete, well-formed row of a monitor CSV (-inf if none)."""
    last = -math.inf
    with open(path, encoding="utf-8", errors="replace") as fh:
        text = fh.read()
    lines = text.split("\n")
    complete = lines[1:] if text.endswith("\n") else lines[1:-1]
    for line in complete:
        parts = line.split(",")
        if len(parts) != n_columns:
            break
        try:
            last = float(parts[0])
        except ValueError:
            break
    return last


def results_last_time(path: Path) -> float | None:
    """The last sample time of a results.h5 (-inf if none; None if it cannot be read: the
    results writer reports that itself)."""
    import h5py
    try:
        with h5py.File(path, "r") as f:
            t = f["time"][:]
    except (OSError, KeyError, ValueError, TypeError):
        return None
    return float(t.max()) if t.size else -math.inf


def check_restart_outputs(series: Iterable[tuple[Path, float | None, str, float]],
                          time: float) -> None:
    """Refuse (:class:`~nurbsdem.errors.InputError`, naming the file) to continue an output
    folder one of whose files ends before the last output time at or before the
    checkpoint's ``time`` (s): the module docstring says why that is a hole.  ``series``:
    (file, the time of its last sample or None when unreadable, the deck setting that
    paces it, its interval in s) of each file of the folder."""
    for path, last, setting, every in series:
        if last is None or every <= 0:
            continue
        need = last_multiple(time, every)
        if need <= 0.0:
            continue                    # no output falls due after t = 0 before the checkpoint
        if last < need - REL_TOL * max(every, abs(need)):
            have = "has no samples" if last == -math.inf else f"ends at t = {last:.9g} s"
            raise InputError(
                f"{have}, but the checkpoint is at t = {time:.9g} s ({setting} {every:g} s: "
                f"the sample at or just after t = {need:.9g} s is missing): the folder does "
                f"not match the checkpoint; put back the files written with it, or move this one away to "
                f"start it anew at the checkpoint's time", path=str(path))

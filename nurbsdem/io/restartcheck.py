"""Before a restart continues an output folder: do its files reach the checkpoint's time?

A checkpoint is saved only after the samples up to its time are durable (results.h5, the
monitor CSVs, the .pvd indices: :meth:`~nurbsdem.io.writers.OutputWriters.checkpoint`), so in
the folder that wrote it every series holds the sample of the last output time at or before
the checkpoint's time t: the last multiple K·every <= t of its interval is served by the
first time step at or after it (:mod:`nurbsdem.io.intervals`), which is at or before t,
because t is itself the end of a time step.  A file that ends earlier was cut short (a full
disk, a copy of an older folder, a file put back by hand): continuing it would leave a hole
from its end to t, so the restart is refused with one line naming the file and both times.
A missing file is started anew at the checkpoint's time (no hole inside it), as before.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Iterator

from ..errors import InputError
from .intervals import REL_TOL, last_multiple

if TYPE_CHECKING:  # pragma: no cover
    from ..model import Model


def _csv_last_time(path: Path, n_columns: int) -> float:
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


def _results_last_time(path: Path) -> float | None:
    """The last sample time of a results.h5 (-inf if none; None if it cannot be read: the
    results writer reports that itself)."""
    import h5py
    try:
        with h5py.File(path, "r") as f:
            t = f["time"][:]
    except (OSError, KeyError, ValueError, TypeError):
        return None
    return float(t.max()) if t.size else -math.inf


def _pvd_last_time(path: Path) -> float | None:
    from .writers import read_pvd
    try:
        entries = read_pvd(path)
    except InputError:
        return None                     # the series reports it when it reads the file
    return max((t for t, _ in entries), default=-math.inf)


def _series(directory: Path, model: "Model") -> Iterator[tuple[Path, float | None, str, float]]:
    """(file, its last time or None, the deck setting, its interval) of each output series
    in ``directory`` (files that exist only)."""
    from .writers import (CONTACT_COLUMNS, ENERGY_COLUMNS, HERTZ_COLUMNS, MONITOR_DIR,
                          RESULTS_NAME, SERIES, WALL_COLUMNS)
    out = model.output
    results = directory / RESULTS_NAME
    if results.is_file():
        yield results, _results_last_time(results), "Results Every", out.results_interval
    mon = directory / MONITOR_DIR
    csvs = [("energy.csv", ENERGY_COLUMNS), ("contacts.csv", CONTACT_COLUMNS),
            ("hertz.csv", HERTZ_COLUMNS)]
    csvs += [(f"wall_{name}.csv", WALL_COLUMNS) for name in model.wall_names]
    for name, columns in csvs:
        path = mon / name
        if path.is_file():
            yield path, _csv_last_time(path, len(columns)), "Monitors Every", out.monitors_every
    for name in SERIES:
        path = directory / f"{name}.pvd"
        if path.is_file():
            yield path, _pvd_last_time(path), "VTK Every", out.vtk_every


def check_restart_outputs(directory: str | Path, model: "Model", time: float) -> None:
    """Refuse (:class:`~nurbsdem.errors.InputError`, naming the file) to continue an output
    folder one of whose files ends before the last output time at or before the
    checkpoint's ``time`` (s): the module docstring says why that is a hole."""
    directory = Path(directory)
    for path, last, setting, every in _series(directory, model):
        if last is None or every <= 0:
            continue
        need = last_multiple(time, every)
        if need <= 0.0:
            continue                    # no output falls due after t = 0 before the checkpoint
        if last < need - REL_TOL * max(every, abs(need)):
            have = "has no samples" if last == -math.inf else f"ends at t = {last:.9g} s"
            raise InputError(
                f"{have}, but the checkpoint is at t = {time:.9g} s ({setting} {every:g} s: "
                f"the sample at or just after t = {need:.9g} s is missing): the folder does not match the "
                f"checkpoint; put back the files written with it, or move this one away to "
                f"start it anew at the checkpoint's time", path=str(path))

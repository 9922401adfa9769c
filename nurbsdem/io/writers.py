"""Result writers. File names are fixed so that scripts can rely on them.

In the output directory (``Output Directory``, default ``results`` next to the deck)::

    particles.pvd  walls.pvd  contacts.pvd     ParaView time collections of ...
    vtk/particles_000000.vtu ...               ... one .vtu per sample (zlib, raw: io/vtu.py)
    monitors/energy.csv                        time,kinetic,potential,elastic,dissipated,
                                               external_work,mechanical,balance_error
    monitors/contacts.csv                      time,monitored,active,degenerated,failed
    monitors/hertz.csv (Hertz-Mindlin runs)    time,active,fallback_radius,radius_min,radius_median,radius_max,stiffness_normal_max
    monitors/wall_<name>.csv                   time,displacement_x,displacement_y,
                                               displacement_z,reaction_x,reaction_y,reaction_z,
                                               torque_x,torque_y,torque_z
    results.h5                                 every sample's body states (see
                                               nurbsdem.io.results.ResultsWriter)

The writers: :mod:`nurbsdem.io.paraview` (the .pvd series and their .vtu files),
:mod:`nurbsdem.io.monitors` (the CSV files), :mod:`nurbsdem.io.results` (results.h5); the
names: :mod:`nurbsdem.io.layout`. This module opens them together for a run
(:class:`OutputWriters`) and keeps the previous run's results until the new run has a
complete sample.

Crash safety: every .vtu, the .pvd files and results.h5 are replaced atomically (temporary
file, fsync, rename), so a run killed at any moment leaves each of them complete (old or
new) or absent. CSV rows are appended and flushed one whole line at a time; on a restart
(``restart_time=t``) every writer drops what lies after t (samples, rows, an incomplete last
line) and carries on, so the files continue seamlessly from the checkpoint.

A fresh start (``restart_time=None``) empties the series, monitors and results.h5.

Typical use by the solver (see :class:`OutputWriters`)::

    out = OutputWriters(model, restart_time=None)
    out.paraview.write(t, bodies, wall_displacement=dW, contacts=c)   # every VTK Every
    out.monitors.energy(t, kinetic=..., potential=..., elastic=..., dissipated=...,
                        external_work=...)                              # every Monitors Every
    out.monitors.contacts(t, monitored, active, degenerated, failed)
    out.monitors.wall("lid", t, displacement, reaction, torque, work)
    out.results.append(t, bodies)                                       # every Results Every
    out.checkpoint(save, *args)   # results.h5 flushed, CSVs fsynced, then save(*args)
    out.close()
"""
from __future__ import annotations

import errno
import math
import os
import shutil
from pathlib import Path
from typing import TYPE_CHECKING

from . import lock as output_lock
from .atomic import remove_stale_temporaries
from . import restartcheck
from .layout import MONITOR_DIR, RESULTS_NAME, SERIES, VTK_DIR
from .monitors import CONTACT_COLUMNS, ENERGY_COLUMNS, HERTZ_COLUMNS, WALL_COLUMNS, MonitorWriter
from .paraview import ParaViewWriter, read_pvd
from .results import ResultsWriter

if TYPE_CHECKING:  # pragma: no cover
    from ..model import Model

#: Result files and folders of a run in its output directory (what a new run replaces).
RUN_FILES = tuple(f"{name}.pvd" for name in SERIES) + (VTK_DIR, MONITOR_DIR, RESULTS_NAME,
                                                       "checkpoint.h5")
#: Where a fresh run keeps the previous run's results until it has its first complete sample.
PREVIOUS_DIR = ".previous-run"


def restore_previous_run(directory: str | Path) -> bool:
    """Put back the results a fresh run set aside (``.previous-run``) when that run ended
    before writing a complete sample (killed, disk full, ...); returns whether it did.
    The unfinished run's files of the same names are discarded."""
    directory = Path(directory)
    prev = directory / PREVIOUS_DIR
    if not prev.is_dir():
        return False
    for name in RUN_FILES:
        if (prev / name).exists():
            _remove(directory / name)
            os.replace(prev / name, directory / name)
    shutil.rmtree(prev, ignore_errors=True)
    return True


def set_previous_run_aside(directory: str | Path) -> bool:
    """Move a previous run's result files into ``.previous-run`` (renames: no copy, no
    space needed); returns whether there were any."""
    directory = Path(directory)
    found = [name for name in RUN_FILES if (directory / name).exists()]
    if not found:
        return False
    prev = directory / PREVIOUS_DIR
    prev.mkdir(exist_ok=True)
    for name in found:
        os.replace(directory / name, prev / name)
    return True


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif path.exists() or path.is_symlink():
        path.unlink()


def clean_output_directory(directory: str | Path) -> None:
    """What a start does first: temporaries of killed writers are removed, and results a
    fresh run had set aside are put back if that run never completed a sample.  Done under
    the folder's lock (:mod:`nurbsdem.io.lock`); while another process holds it (a run still
    writing there, or rank 0 of this MPI run) nothing is touched: that run's temporaries are
    not stale, and a run that goes on to write there is refused when it opens its writers."""
    from ..errors import InputError
    directory = Path(directory)
    try:
        key = output_lock.acquire(directory)
    except InputError:
        return
    try:
        restore_previous_run(directory)
        for folder in (directory, directory / VTK_DIR, directory / MONITOR_DIR):
            remove_stale_temporaries(folder)
    finally:
        output_lock.release(key)


def _output_series(directory: Path, model: "Model"):
    """(file, the time of its last sample or None if unreadable, the deck setting that paces
    it, its interval in s) of each output file in ``directory``, for
    :func:`~nurbsdem.io.restartcheck.check_restart_outputs`."""
    out = model.output
    results = directory / RESULTS_NAME
    if results.is_file():
        yield (results, restartcheck.results_last_time(results), "Results Every",
               out.results_interval)
    csvs = [("energy.csv", ENERGY_COLUMNS), ("contacts.csv", CONTACT_COLUMNS),
            ("hertz.csv", HERTZ_COLUMNS)]
    csvs += [(f"wall_{name}.csv", WALL_COLUMNS) for name in model.wall_names]
    for name, columns in csvs:
        path = directory / MONITOR_DIR / name
        if path.is_file():
            yield (path, restartcheck.csv_last_time(path, len(columns)), "Monitors Every",
                   out.monitors_every)
    for name in SERIES:
        path = directory / f"{name}.pvd"
        if path.is_file():
            from ..errors import InputError
            try:
                last = max((t for t, _ in read_pvd(path)), default=-math.inf)
            except InputError:
                last = None                 # the series reports it when it reads the file
            yield path, last, "VTK Every", out.vtk_every


class OutputWriters:
    """All writers of a run, from the model's ``Output`` block.

    restart_time: ``None`` for a fresh run, or the checkpoint's time (s) on a restart.
    Attributes: ``directory``, ``paraview`` (:class:`~nurbsdem.io.paraview.ParaViewWriter`),
    ``monitors`` (:class:`~nurbsdem.io.monitors.MonitorWriter`), ``results``
    (:class:`~nurbsdem.io.results.ResultsWriter`).

    Safety of earlier results: on every start, temporaries of killed writers are removed
    (:func:`clean_output_directory`). A fresh run first moves the previous run's files into
    ``.previous-run`` and deletes them only once it has a complete sample of its own (its
    first ``results.append``, or a :meth:`sync` before a checkpoint); if it fails before
    that (:meth:`abort`, or killed: the next start), the previous files are put back.
    """

    def __init__(self, model: "Model", restart_time: float | None = None,
                 flush_every: int = 20, background: bool = False) -> None:
        assert model.output is not None
        self.directory = Path(model.output.directory)
        if self.directory.exists() and not self.directory.is_dir():
            raise OSError(errno.ENOTDIR, "the output directory is a file", str(self.directory))
        self.directory.mkdir(parents=True, exist_ok=True)
        self._lock = output_lock.acquire(self.directory)      # before touching anything
        self._committed = True
        try:
            clean_output_directory(self.directory)
            if restart_time is not None:
                restartcheck.check_restart_outputs(_output_series(self.directory, model),
                                                   restart_time)
        except BaseException:
            self._release()
            raise
        self._committed = restart_time is not None
        if restart_time is None:
            set_previous_run_aside(self.directory)
        try:
            shapes = {sid: e.shape for sid, e in model.shapes.items()}
            self.paraview = ParaViewWriter(self.directory, shapes, model.walls,
                                           model.output.vtk_resolution, restart_time,
                                           background)
            if getattr(model, "curved_walls", None):
                from .deck_curved import curved_tessellation
                self.paraview.add_curved_walls(curved_tessellation(model))
            self.monitors = MonitorWriter(self.directory, model.wall_names, restart_time)
            self.results = ResultsWriter(self.directory / RESULTS_NAME, model.text, model.path,
                                         restart_time, flush_every, after_append=self._commit,
                                         background=self.paraview.background)
        except BaseException:
            self._restore()
            self._release()
            raise

    def _release(self) -> None:
        lock, self._lock = getattr(self, "_lock", None), None
        output_lock.release(lock)

    @property
    def committed(self) -> bool:
        """Whether this run's results have replaced the previous run's."""
        return self._committed

    def _commit(self) -> None:
        """The first complete sample is on disk: the previous run's results can go."""
        if self._committed:
            return
        self.results.flush()
        self.monitors.sync()
        self._committed = True
        shutil.rmtree(self.directory / PREVIOUS_DIR, ignore_errors=True)

    def _restore(self) -> None:
        if not self._committed:
            restore_previous_run(self.directory)

    def sync(self) -> None:
        """Make everything written so far durable (call before saving a checkpoint)."""
        self.paraview.sync()
        self.results.flush()
        self.monitors.sync()
        self._commit()

    def checkpoint(self, save, *args) -> None:
        """Make everything written so far durable, then call ``save(*args)`` (write the
        checkpoint that refers to it), in this order.  With a background worker both happen
        on it, after the writes queued before, while the caller goes on: ``args`` must not
        change afterwards (hand over copies); the monitor rows written so far are handed to
        the operating system here and fsynced there.  An error is raised at the next write
        or :meth:`sync`, as a background write's."""
        bg = self.paraview.background
        if bg is None or not self._committed:
            self.sync()
            save(*args)
            return
        self.monitors.flush()
        self.results.flush(wait=False)
        bg.submit(self._durable_then_save, save, args)

    def _durable_then_save(self, save, args: tuple) -> None:
        self.paraview.write_index()
        self.monitors.fsync()
        save(*args)

    def abort(self) -> None:
        """The run failed: close the files and, if this run has no complete sample yet, put
        the previous run's results back. Never raises."""
        pv = getattr(self, "paraview", None)
        if pv is not None:
            pv.abandon()
        for m in (getattr(self, "monitors", None),):
            try:
                if m is not None:
                    m.close()
            except OSError:
                pass
        if not self._committed:
            try:
                restore_previous_run(self.directory)
            except OSError:
                pass
            self._aborted = True
            self._release()             # nothing more is written (close() does nothing)

    def close(self) -> None:
        """Flush and close (after :meth:`abort`: nothing more is written); the folder's lock
        is given back either way."""
        if getattr(self, "_aborted", False):
            self._release()
            return
        try:
            self.results.close()            # its last samples are a job of the worker too
            self.paraview.close()
            self.monitors.close()
            self._commit()
        finally:
            self._release()


def is_multiple(t: float, every: float, tol: float = 1e-9) -> bool:
    """Whether time t (s) falls on a multiple of ``every`` (s), within tol * every."""
    k = round(t / every)
    return math.isclose(t, k * every, rel_tol=0.0, abs_tol=tol * every)

"""The monitor files ``monitors/*.csv`` (:class:`MonitorWriter`): energies, contact counts,
Hertz radii and each wall's displacement, reaction, torque, work and power, one row per
sample, each file a :class:`CsvMonitor`."""
from __future__ import annotations

from contextlib import contextmanager
import math
import os
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .atomic import atomic_write_text
from .layout import MONITOR_DIR, time_tol

#: Column names of the monitor files (fixed).
ENERGY_COLUMNS = ("time", "kinetic", "potential", "elastic", "dissipated", "external_work",
                  "mechanical", "balance_error")
CONTACT_COLUMNS = ("time", "monitored", "active", "degenerated", "failed")
HERTZ_COLUMNS = ("time", "active", "fallback_radius", "radius_min", "radius_median",
                 "radius_max", "stiffness_normal_max")
WALL_COLUMNS = ("time", "displacement_x", "displacement_y", "displacement_z",
                "reaction_x", "reaction_y", "reaction_z", "torque_x", "torque_y", "torque_z",
                "work", "power")

_float_repr = float.__repr__


def _fmt(x: Any) -> str:
    """A CSV field: integers as integers, floats by repr (shortest exact round trip)."""
    if isinstance(x, float):            # Python and NumPy floats (float.__repr__: no "np.")
        return float.__repr__(x)
    if isinstance(x, (int, np.integer)) and not isinstance(x, bool):
        return str(int(x))
    return repr(float(x))


class CsvMonitor:
    """A CSV file with a fixed header, one row per sample, each row flushed when written.

    restart_time: ``None`` (fresh file, header only) or a time (s): rows after it, and an
    incomplete or malformed trailing row, are removed (atomic rewrite) before appending.  A
    file whose header lacks trailing columns of ``columns`` (written by an earlier version)
    keeps its rows, those columns NaN.
    """

    def __init__(self, path: str | Path, columns: Sequence[str],
                 restart_time: float | None = None) -> None:
        self.path = Path(path)
        self.columns = tuple(columns)
        self.header = ",".join(self.columns)
        rows: list[str] = []
        if restart_time is not None and self.path.exists():
            rows = self._kept_rows(restart_time)
        atomic_write_text(self.path, "".join(line + "\n" for line in [self.header] + rows))
        self.rows_at_start = [list(map(float, r.split(","))) for r in rows]
        #: rows are flushed by the batch that holds them (MonitorWriter.batch)
        self.batched = False
        self._fh = open(self.path, "a", newline="", buffering=1 << 20)

    def _kept_rows(self, restart_time: float) -> list[str]:
        text = self.path.read_text(encoding="utf-8", errors="replace")
        lines = text.split("\n")
        old = lines[0].strip().split(",") if lines else []
        if not old or tuple(old) != self.columns[:len(old)]:
            return []
        pad = ",nan" * (len(self.columns) - len(old))
        complete = lines[1:-1] if not text.endswith("\n") else lines[1:]
        kept = []
        limit = restart_time + time_tol(restart_time)
        for line in complete:
            parts = line.split(",")
            if len(parts) != len(old):
                break
            try:
                vals = [float(p) for p in parts]
            except ValueError:
                break
            if vals[0] > limit:
                break
            kept.append(line + pad)
        return kept

    def append(self, values: Sequence[Any]) -> None:
        """Write one row (len(columns) values; time first) and flush it (in a
        :meth:`MonitorWriter.batch`: at its end, whole rows at once)."""
        self._write_row(len(values), ",".join(_fmt(v) for v in values))

    def append_floats(self, values: Sequence[float]) -> None:
        """:meth:`append` of a row of floats (Python or NumPy; the same text, without the
        per-field type dispatch: the monitors write one row per deck step)."""
        self._write_row(len(values), ",".join(map(_float_repr, values)))

    def _write_row(self, n_values: int, text: str) -> None:
        """The row ``text`` of ``n_values`` fields, checked against the header, written and
        flushed unless a batch holds it."""
        if n_values != len(self.columns):
            raise ValueError(f"{self.path.name}: expected {len(self.columns)} values, got {n_values}")
        self._fh.write(text + "\n")
        if not self.batched:
            self._fh.flush()

    def sync(self) -> None:
        """Flush and fsync (call before writing a checkpoint)."""
        if not self._fh.closed:
            self._fh.flush()
            os.fsync(self._fh.fileno())

    def flush(self) -> None:
        """Hand the rows written so far to the operating system (whole rows)."""
        if not self._fh.closed:
            self._fh.flush()

    def fsync(self) -> None:
        """Make the rows the last :meth:`flush` handed over durable (safe from the output
        worker while the time loop appends: the file stays open until the worker is done)."""
        if not self._fh.closed:
            os.fsync(self._fh.fileno())

    def close(self) -> None:
        if not self._fh.closed:
            self.sync()
            self._fh.close()


def _file_in(folder: Path, name: str) -> Path:
    """``folder / name``, refused (InputError) unless it is a plain file name of ``folder``:
    names come from the deck (wall names), and no output goes outside the output folder
    (the deck and the API check the names first; this is the writer's own guard)."""
    path = folder / name
    if Path(name).name != name or name in (".", "..") or \
            path.resolve().parent != folder.resolve():
        from ..errors import InputError
        raise InputError(f"refusing to write {name!r}: it is not a file name inside the "
                         f"output folder {folder}")
    return path


class MonitorWriter:
    """``monitors/energy.csv``, ``monitors/contacts.csv`` and ``monitors/wall_<name>.csv``.

    Energies in J, times in s, displacements in m, reactions in N (the force that holds the
    wall on its path: minus the total force the particles exert on it, world frame), torques
    in N m (of the particles' contact forces on the wall about its reference point: the
    rotation centre of a turning wall, else the point its displacement carries from the
    world origin; world frame), a wall's work in J (what its motion has done on the
    particles since the start: its share of the energy balance's external work) and power
    in W (the work's mean rate since the previous row; 0 on a file's first row).
    """

    def __init__(self, outdir: str | Path, wall_names: Sequence[str] = (),
                 restart_time: float | None = None) -> None:
        self.dir = Path(outdir) / MONITOR_DIR
        self.dir.mkdir(parents=True, exist_ok=True)
        self.energy_csv = CsvMonitor(self.dir / "energy.csv", ENERGY_COLUMNS, restart_time)
        self.contacts_csv = CsvMonitor(self.dir / "contacts.csv", CONTACT_COLUMNS, restart_time)
        self.wall_csv = {name: CsvMonitor(_file_in(self.dir, f"wall_{name}.csv"), WALL_COLUMNS,
                                          restart_time)
                         for name in wall_names}
        self.hertz_csv: CsvMonitor | None = None       # made by the first hertz() row
        #: ``inlet_<name>.csv`` and ``outlet_<name>.csv`` by file name, made by their first row
        self.flow_csv: dict[str, CsvMonitor] = {}
        self._restart_time = restart_time
        #: each wall's (time, work) of its last row, for the power column
        self._last_work = {name: tuple(csv.rows_at_start[-1][i] for i in (0, -2))
                           for name, csv in self.wall_csv.items() if csv.rows_at_start}
        self._reference: float | None = None
        if self.energy_csv.rows_at_start:
            r = self.energy_csv.rows_at_start[0]
            # balance_error = mechanical + dissipated - external_work - reference
            self._reference = r[6] + r[4] - r[5] - r[7]

    def energy(self, time: float, kinetic: float, potential: float, elastic: float,
               dissipated: float, external_work: float,
               balance_error: float | None = None) -> float:
        """Append an energy row; returns the balance error written.

        kinetic (translational + rotational), potential (gravity), elastic (contact springs),
        dissipated (cumulative, >= 0), external_work (cumulative work done on the system by
        moving walls and anything else external, e.g. energy added by a Replicate step).
        mechanical = kinetic + potential + elastic. balance_error, unless given, is
        ``mechanical + dissipated - external_work`` minus its value at the first row.
        """
        mech = float(kinetic) + float(potential) + float(elastic)
        total = mech + float(dissipated) - float(external_work)
        if balance_error is None:
            if self._reference is None:
                self._reference = total
            balance_error = total - self._reference
        self.energy_csv.append_floats([float(time), float(kinetic), float(potential),
                                       float(elastic), float(dissipated),
                                       float(external_work), mech, float(balance_error)])
        return float(balance_error)

    def contacts(self, time: float, monitored: int, active: int, degenerated: int,
                 failed: int) -> None:
        """Append a contact-count row (numbers of monitored LCPs, active, degenerated and
        failed contacts, paper Fig. 5)."""
        self.contacts_csv.append([time, int(monitored), int(active), int(degenerated), int(failed)])

    def hertz(self, time: float, active: int, fallback: int, radius: np.ndarray,
              stiffness: np.ndarray) -> None:
        """Append a row to ``monitors/hertz.csv`` (runs with Hertz–Mindlin interfaces): active
        contacts, how many took the bounding-sphere radius (degenerated contact or curvature),
        the smallest / median / largest equivalent radius (m) and the largest normal tangent
        stiffness (N/m) used (NaN without contacts)."""
        if self.hertz_csv is None:
            self.hertz_csv = CsvMonitor(self.dir / "hertz.csv", HERTZ_COLUMNS, self._restart_time)
        r = np.asarray(radius, float)
        k = np.asarray(stiffness, float)
        stats = ([float(r.min()), float(np.median(r)), float(r.max()), float(k.max())]
                 if r.size else [math.nan] * 4)
        self.hertz_csv.append([time, int(active), int(fallback), *stats])

    def wall(self, name: str, time: float, displacement: Sequence[float],
             reaction: Sequence[float], torque: Sequence[float], work: float) -> None:
        """Append a row to ``wall_<name>.csv``: displacement from the deck position (m),
        reaction (N): the force that holds the wall on its prescribed path, i.e. minus the
        sum of the contact forces the particles exert on it, torque (N m): that of the
        particles' contact forces on the wall about its reference point, and the work (J)
        the wall's motion has done on the particles since the start; the power (W) is the
        work's mean rate since the wall's previous row."""
        d = np.asarray(displacement, float).reshape(3).tolist()
        r = np.asarray(reaction, float).reshape(3).tolist()
        m = np.asarray(torque, float).reshape(3).tolist()
        t, work = float(time), float(work)
        t0, w0 = self._last_work.get(name, (t, work))
        power = (work - w0) / (t - t0) if t > t0 else 0.0
        self._last_work[name] = (t, work)
        self.wall_csv[name].append_floats([t, *d, *r, *m, work, power])

    def walls(self, time: float, displacement: np.ndarray, reaction: np.ndarray,
              torque: np.ndarray, work: np.ndarray) -> None:
        """:meth:`wall` rows of every wall at once: displacement, reaction, torque (W, 3) and
        work (W,) in the order of the wall names given at construction."""
        for name, d, r, m, w in zip(self.wall_csv, np.asarray(displacement, float),
                                    np.asarray(reaction, float), np.asarray(torque, float),
                                    np.asarray(work, float).tolist()):
            self.wall(name, time, d, r, m, w)

    def flow(self, name: str, columns: Sequence[str], row: Sequence[Any]) -> None:
        """Append ``row`` to the inlet or outlet monitor ``name`` (its ``columns`` given with
        its first row; :mod:`nurbsdem.flow_run`)."""
        if name not in self.flow_csv:
            self.flow_csv[name] = CsvMonitor(_file_in(self.dir, name), columns,
                                             self._restart_time)
        self.flow_csv[name].append(row)

    def _all(self) -> list[CsvMonitor]:
        return [self.energy_csv, self.contacts_csv, *self.wall_csv.values(),
                *([self.hertz_csv] if self.hertz_csv is not None else []),
                *self.flow_csv.values()]

    @contextmanager
    def batch(self):
        """Rows appended inside are flushed together at the end (whole rows: a run killed
        meanwhile leaves at most an incomplete last row, which a restart drops)."""
        files = self._all()
        for m in files:
            m.batched = True
        try:
            yield self
        finally:
            for m in self._all():
                m.batched = False
                if not m._fh.closed:
                    m._fh.flush()

    def sync(self) -> None:
        for m in self._all():
            m.sync()

    def flush(self) -> None:
        """:meth:`CsvMonitor.flush` of every file."""
        for m in self._all():
            m.flush()

    def fsync(self) -> None:
        """:meth:`CsvMonitor.fsync` of every file."""
        for m in self._all():
            m.fsync()

    def close(self) -> None:
        for m in self._all():
            m.close()

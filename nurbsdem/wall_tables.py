"""Tabulated wall motion: ``Step ID MoveWall NAME Table motion.csv [Center cx cy cz]
[Duration T] TimeStep DT`` (and ``Simulation.move_wall(name, table=...)``).

The table's rows are times t (s, from the step's start, increasing, the first 0) with the
wall's displacement x, y, z (m) from where it is at the step's start and, for mesh and surface
walls, a rotation vector rx, ry, rz (rad: axis × angle) about its centre (``Center``, m,
where it is at the step's start; it translates with the wall).  Between rows both are
interpolated linearly in t; after the last row the wall stays where the table leaves it.

A CSV line is ``t,x,y,z`` or ``t,x,y,z,rx,ry,rz``; a first line of these column names is a
header, blank lines and lines that start with ``#`` are skipped.  A bad row is an
:class:`~nurbsdem.errors.InputError` naming the CSV file and its line.

At a row's time the wall is at the row's displacement exactly (bit for bit): a time within
1e-9 of the shortest row interval of a row's time is taken as that row's time, so that the
round-off of t0 + k·dt does not move the wall off the table.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .contact.curved_walls import WallPose
from .dynamics import PrescribedMotion
from .errors import InputError, vector_text as _vec

#: the column names of a header line: translation only, or translation and rotation
COLUMNS = (("t", "x", "y", "z"), ("t", "x", "y", "z", "rx", "ry", "rz"))

#: a time within SNAP × the shortest row interval of a row's time is that row's time
SNAP = 1e-9


@dataclass
class WallTable:
    """A wall's tabulated motion: row times (T,) s from the step's start, displacements
    (T,3) m from the wall's place at the step's start, rotation vectors (T,3) rad about its
    centre (None: it does not turn); ``file``: the CSV as written in the deck (None: given as
    an array), ``path``: where it was read."""

    times: np.ndarray
    displacement: np.ndarray
    rotation: np.ndarray | None = None
    file: str | None = None
    path: Path | None = field(default=None, compare=False)

    @property
    def duration(self) -> float:
        """The time of the last row (s): the step's duration unless it gives one."""
        return float(self.times[-1])

    def rows(self) -> np.ndarray:
        """(T, 4) or (T, 7): the table as its CSV holds it."""
        cols = [self.times[:, None], self.displacement]
        if self.rotation is not None:
            cols.append(self.rotation)
        return np.hstack(cols)


def _check_rows(rows: np.ndarray, where) -> None:
    """Times start at 0 and increase; ``where(k)`` the (path, line) of row k for messages."""
    if len(rows) < 2:
        raise InputError("a motion table needs at least two rows (times 0 and the end)",
                         *where(len(rows) - 1 if len(rows) else None))
    if rows[0, 0] != 0.0:
        raise InputError(f"the first time must be 0, got {rows[0, 0]:g}", *where(0))
    for k in range(1, len(rows)):
        if not rows[k, 0] > rows[k - 1, 0]:
            raise InputError(f"times must increase: {rows[k, 0]:g} s after "
                             f"{rows[k - 1, 0]:g} s", *where(k))


def read_wall_table(path: str | Path, file: str | None = None) -> WallTable:
    """The table of a CSV file (module docstring); ``file``: its name as the deck writes it."""
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read the motion table: {getattr(exc, 'strerror', None) or exc}",
                         path=str(path)) from None
    rows: list[list[float]] = []
    lines: list[int] = []
    width = None
    for lineno, raw in enumerate(text.splitlines(), start=1):
        s = raw.strip()
        if not s or s.startswith("#"):
            continue
        cells = [c.strip() for c in s.split(",")]
        if not rows and width is None and tuple(c.lower() for c in cells) in COLUMNS:
            width = len(cells)                  # a header
            continue
        if len(cells) not in (4, 7) or (width is not None and len(cells) != width):
            want = str(width) if width is not None else "4 (t, x, y, z) or 7 (t, x, y, z, rx, ry, rz)"
            raise InputError(f"{len(cells)} columns, expected {want}", path=str(path),
                             line=lineno)
        width = len(cells)
        values = []
        for name, c in zip(COLUMNS[1], cells):
            try:
                v = float(c)
            except ValueError:
                v = float("nan")
            if not np.isfinite(v):
                raise InputError(f"{name} is not a number: {c!r}", path=str(path), line=lineno)
            values.append(v)
        rows.append(values)
        lines.append(lineno)
    arr = np.array(rows, float).reshape(len(rows), width or 4)
    _check_rows(arr, lambda k: (str(path), lines[k] if k is not None else None))
    return WallTable(arr[:, 0].copy(), arr[:, 1:4].copy(),
                     arr[:, 4:7].copy() if arr.shape[1] == 7 else None, file=file, path=path)


def table_from_array(rows, what: str) -> WallTable:
    """The table of an array (T, 4) or (T, 7) of rows t, x, y, z[, rx, ry, rz] (s, m, rad);
    ``what`` begins the messages (e.g. ``"Step 3"``)."""
    try:
        arr = np.array(rows, float)
    except (TypeError, ValueError):
        raise InputError(f"{what}: table must be an array of numbers (rows t, x, y, z[, rx, "
                         f"ry, rz])") from None
    if arr.ndim != 2 or arr.shape[1] not in (4, 7):
        raise InputError(f"{what}: table must have 4 (t, x, y, z) or 7 (t, x, y, z, rx, ry, "
                         f"rz) columns, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{what}: table holds a value that is not a finite number")
    _check_rows(arr, lambda k: (None, None, f"{what}: table row {k}"))
    return WallTable(arr[:, 0].copy(), arr[:, 1:4].copy(),
                     arr[:, 4:7].copy() if arr.shape[1] == 7 else None)


def write_wall_table(table: WallTable, path: str | Path) -> Path:
    """Write the table as CSV (header, then every row with 17 significant digits: the
    numbers read back bit for bit)."""
    path = Path(path)
    cols = COLUMNS[1] if table.rotation is not None else COLUMNS[0]
    lines = [",".join(cols)] + [",".join(repr(float(v)) for v in row) for row in table.rows()]
    path.write_text("\n".join(lines) + "\n")
    return path


def keep_table(table: WallTable, path: Path) -> None:
    """Write a table given as an array to ``path`` (its folder made) and name it there."""
    path.parent.mkdir(parents=True, exist_ok=True)
    write_wall_table(table, path)
    table.file, table.path = str(path.resolve()), path


def _snapped(knots: np.ndarray, t: np.ndarray) -> np.ndarray:
    """t with each time within SNAP × the shortest interval of a knot replaced by it."""
    tol = SNAP * float(np.min(np.diff(knots)))
    j = np.clip(np.searchsorted(knots, t), 1, len(knots) - 1)
    near = np.where(np.abs(t - knots[j - 1]) <= np.abs(knots[j] - t), j - 1, j)
    return np.where(np.abs(t - knots[near]) <= tol, knots[near], t)


def interpolate(knots: np.ndarray, values: np.ndarray, times,
                moving_at_start: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(values (n,3), rates (n,3)) at the times (n,): linear between the knots (T,) s, the
    first row before them and the last after them (rate 0 there); at a knot (snapped, module
    docstring) the knot's row exactly and the rate of the interval after it, but at the
    first knot rate 0 (the wall starts from rest, as ``PrescribedMotion.piecewise_linear``
    has it) unless ``moving_at_start`` (a turn, as a ``Rotate`` step's, turns from t0 on)."""
    t = np.asarray(times, float)
    ts = _snapped(knots, t)
    inside = ((ts >= knots[0]) if moving_at_start else (ts > knots[0])) & (ts < knots[-1])
    k = np.clip(np.searchsorted(knots, ts, side="right") - 1, 0, len(knots) - 2)
    span = (knots[k + 1] - knots[k])[:, None]
    step = values[k + 1] - values[k]
    s = (ts - knots[k])[:, None] / span
    d = np.where(inside[:, None], values[k] + s * step,
                 np.where((ts <= knots[0])[:, None], values[0], values[-1]))
    rate = np.where(inside[:, None], step / span, 0.0)
    return d, rate


def table_motion(table: WallTable, t_start: float, d0) -> PrescribedMotion:
    """The wall's translation: ``d0`` (3,) m (its displacement at the step's start, time
    ``t_start`` s) plus the table's, interpolated (:func:`interpolate`)."""
    knots = t_start + table.times
    values = np.asarray(d0, float) + table.displacement

    def at_times(times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return interpolate(knots, values, times)

    def f(t: float):
        d, u = at_times(np.array([t]))
        return d[0], u[0]
    return PrescribedMotion(f, table=at_times)


def _left_jacobian(r: np.ndarray) -> np.ndarray:
    """J with ω = J(r) ṙ, the world angular velocity of R = exp([r]×) (rad/s)."""
    th = float(np.linalg.norm(r))
    K = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
    if th < 1e-8:
        return np.eye(3) + 0.5 * K + K @ K / 6.0
    return (np.eye(3) + (1.0 - np.cos(th)) / th ** 2 * K
            + (th - np.sin(th)) / th ** 3 * K @ K)


@dataclass(frozen=True)
class TablePose(WallPose):
    """The pose of a mesh or surface wall that a table turns: the rest pose ``R0``,
    ``shift0`` turned by the rotation vector interpolated at t (rad) about ``center`` (m,
    before the wall's displacement, which the pose adds after the turn); ``knots`` (T,) s
    absolute times, ``rotvecs`` (T,3) rad."""

    knots: np.ndarray = field(default_factory=lambda: np.zeros(2))
    rotvecs: np.ndarray = field(default_factory=lambda: np.zeros((2, 3)))

    def rotvec(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(rotation vector (3,) rad, its rate (3,) rad/s) at time t (s)."""
        r, rate = interpolate(self.knots, self.rotvecs, np.array([float(t)]),
                              moving_at_start=True)
        return r[0], rate[0]

    def at(self, t: float, d: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(R (3,3), t (3,) m) at time t (s), displaced by d (3,) m (None: none)."""
        from scipy.spatial.transform import Rotation
        rot = Rotation.from_rotvec(self.rotvec(t)[0]).as_matrix()
        c = np.asarray(self.center, float)
        shift = rot @ (self.shift0 - c) + c
        return rot @ self.R0, (shift if d is None else shift + np.asarray(d, float))

    def angular_velocity(self, t: float) -> np.ndarray:
        """The wall's angular velocity (3,) rad/s at time t: J(r) ṙ (:func:`_left_jacobian`)."""
        r, rate = self.rotvec(t)
        return _left_jacobian(r) @ rate


def describe_moves(step) -> str:
    """The walls a MoveWall step moves and how, for the model's summary."""
    def one(m) -> str:
        if m.force is not None:
            return (f"{m.wall} servo-controlled to a push of {m.force:g} N (at most "
                    f"{m.max_speed:g} m/s, gain {m.gain:g} m/(s N))")
        if m.table is not None:
            return f"{m.wall} by the table {m.table.file or '(array)'}"
        turn = f" turning at {_vec(m.angular_velocity)} rad/s" if m.rotate else ""
        return f"{m.wall} by {_vec(m.net_displacement())} m{turn}"
    return ", ".join(one(m) for m in step.moves())

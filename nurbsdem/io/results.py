"""``results.h5``: every sample's body states (:class:`ResultsWriter`), and the functions
that read it back (:func:`read_results_times`, :func:`read_results_sample`)."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .atomic import ensure_space, write_hdf5_atomically
from .background import BackgroundWriter
from .layout import time_tol

if TYPE_CHECKING:  # pragma: no cover
    from ..model import Bodies

RESULTS_FIELDS = {"particle_id": ((), np.int64), "shape_id": ((), np.int64),
                  "position": ((3,), np.float64), "quaternion": ((4,), np.float64),
                  "velocity": ((3,), np.float64), "angular_velocity": ((3,), np.float64)}


class ResultsWriter:
    """``results.h5``: every sample's body states, ragged by sample (N may change).

    Layout::

        attrs: deck (text), deck_path, nurbsdem_version, format = "nurbsdem-results-1",
               conventions (str)
        time        (S,)   float64  sample times, s
        count       (S,)   int64    bodies in each sample
        offset      (S+1,) int64    sample k's rows are offset[k]:offset[k+1]
        particle_id (R,)   int64    deck body id
        shape_id    (R,)   int64
        position    (R, 3) float64  centroid, world, m
        quaternion  (R, 4) float64  (w, x, y, z), file frame -> world
        velocity    (R, 3) float64  m/s
        angular_velocity (R, 3) float64 rad/s, world frame

    Samples are buffered and written ``flush_every`` at a time (and by :meth:`flush`,
    :meth:`close`): each flush copies the file, appends, fsyncs and renames it into place,
    so the file is always complete. Read with :func:`read_results_sample`.

    background: a :class:`BackgroundWriter` (the ParaView series' worker) that writes the
    buffered samples while the time loop goes on; every write of the file is then one of its
    jobs, in order, and a write the caller waits for waits for the jobs queued before it.
    """

    def __init__(self, path: str | Path, deck_text: str = "", deck_path: str = "",
                 restart_time: float | None = None, flush_every: int = 20,
                 after_append=None, background: BackgroundWriter | None = None) -> None:
        self.path = Path(path)
        self.flush_every = int(flush_every)
        self.after_append = after_append   # called after each append (OutputWriters' commit)
        self.background = background
        self._pending: list[tuple[float, dict[str, np.ndarray]]] = []
        if restart_time is not None and self.path.exists():
            self._truncate(restart_time)
        else:
            self._create(deck_text, deck_path)

    def _create(self, deck_text: str, deck_path: str) -> None:
        from .. import __version__

        def fill(f) -> None:
            f.attrs["deck"] = deck_text
            f.attrs["deck_path"] = str(deck_path)
            f.attrs["nurbsdem_version"] = __version__
            f.attrs["format"] = "nurbsdem-results-1"
            f.attrs["conventions"] = ("SI units; position = centroid in the world; "
                                      "quaternion (w, x, y, z) maps the shape file frame "
                                      "to the world; velocities in the world frame; "
                                      "sample k = rows offset[k]:offset[k+1]")
            f.create_dataset("time", (0,), np.float64, maxshape=(None,), chunks=(1024,))
            f.create_dataset("count", (0,), np.int64, maxshape=(None,), chunks=(1024,))
            f.create_dataset("offset", data=np.zeros(1, np.int64), maxshape=(None,),
                             chunks=(1024,))
            for name, (tail, dt) in RESULTS_FIELDS.items():
                f.create_dataset(name, (0, *tail), dt, maxshape=(None, *tail),
                                 chunks=(4096, *tail))
        write_hdf5_atomically(self.path, fill)

    def _rewrite(self, edit, adding: int = 0) -> None:
        """Copy the file, apply ``edit(h5file)`` (which adds ``adding`` bytes), fsync, rename
        into place."""
        ensure_space(self.path.parent, 2 * (self.path.stat().st_size + adding) + 1024 * 1024)
        write_hdf5_atomically(self.path, edit, source=self.path)

    def set_deck(self, text: str) -> None:
        """Replace the deck text the file records (after the queued writes)."""
        if self.background is not None:
            self.background.wait()
        self._rewrite(lambda f: f.attrs.__setitem__("deck", text))

    def _truncate(self, restart_time: float) -> None:
        try:
            self._truncate_file(restart_time)
        except (OSError, KeyError, ValueError, TypeError, IndexError) as exc:
            from ..errors import InputError
            raise InputError(f"cannot continue the results file: it is corrupted "
                             f"({' '.join(str(exc).split())[:120]}); move it away to restart "
                             f"(a new one starts at the checkpoint's time)",
                             path=str(self.path)) from None

    def _truncate_file(self, restart_time: float) -> None:
        def edit(f) -> None:
            t = f["time"][:]
            s = int(np.searchsorted(t, restart_time + time_tol(restart_time), side="right"))
            r = int(f["offset"][s])
            f["time"].resize((s,))
            f["count"].resize((s,))
            f["offset"].resize((s + 1,))
            for name in RESULTS_FIELDS:
                f[name].resize((r, *f[name].shape[1:]))
        self._rewrite(edit)

    def append(self, time: float, bodies: "Bodies") -> None:
        """Queue one sample (time in s) of the bodies' state; flushes every ``flush_every``."""
        data = {"particle_id": bodies.id, "shape_id": bodies.shape_id,
                "position": bodies.position, "quaternion": bodies.quaternion,
                "velocity": bodies.velocity, "angular_velocity": bodies.angular_velocity}
        self._pending.append((float(time), {k: np.array(v, RESULTS_FIELDS[k][1])
                                            for k, v in data.items()}))
        if len(self._pending) >= self.flush_every:
            self.flush(wait=False)
        if self.after_append is not None:
            self.after_append()

    def flush(self, wait: bool = True) -> None:
        """Write the buffered samples (atomic replace of the file): on the background worker
        if there is one (``wait``: and wait until it is written)."""
        pending, self._pending = self._pending, []
        if pending:
            if self.background is None:
                self._write_samples(pending)
            else:
                self.background.submit(self._write_samples, pending)
        if wait and self.background is not None:
            self.background.wait()

    def _write_samples(self, pending: list) -> None:
        """Append the samples ``pending`` [(time, arrays)] to the file."""
        def edit(f) -> None:
            s0 = f["time"].shape[0]
            r0 = int(f["offset"][s0])
            counts = np.array([len(d["particle_id"]) for _, d in pending], np.int64)
            s1, r1 = s0 + len(pending), r0 + int(counts.sum())
            f["time"].resize((s1,))
            f["time"][s0:s1] = [t for t, _ in pending]
            f["count"].resize((s1,))
            f["count"][s0:s1] = counts
            f["offset"].resize((s1 + 1,))
            f["offset"][s0 + 1:s1 + 1] = r0 + np.cumsum(counts)
            for name in RESULTS_FIELDS:
                ds = f[name]
                ds.resize((r1, *ds.shape[1:]))
                if r1 > r0:
                    ds[r0:r1] = np.concatenate([d[name] for _, d in pending])
        self._rewrite(edit, sum(d[k].nbytes for _, d in pending for k in d))

    def close(self) -> None:
        self.flush()


def read_results_times(path: str | Path) -> np.ndarray:
    """Sample times (s) of a results.h5."""
    import h5py
    with h5py.File(path, "r") as f:
        return f["time"][:]


def read_results_sample(path: str | Path, k: int) -> dict[str, Any]:
    """Sample k (negative counts from the end) of a results.h5: ``time`` and the arrays of
    :data:`RESULTS_FIELDS`."""
    import h5py
    with h5py.File(path, "r") as f:
        s = f["time"].shape[0]
        if k < 0:
            k += s
        if not 0 <= k < s:
            raise IndexError(f"sample {k} out of range ({s} samples)")
        a, b = int(f["offset"][k]), int(f["offset"][k + 1])
        out: dict[str, Any] = {"time": float(f["time"][k])}
        for name in RESULTS_FIELDS:
            out[name] = f[name][a:b]
        return out


# ---------------------------------------------------------------------------- bundle

"""The output worker: one thread that writes files in the order they are submitted, while
the time loop goes on (:class:`BackgroundWriter`, used by :mod:`nurbsdem.io.paraview` and
:mod:`nurbsdem.io.results`)."""
from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager


class BackgroundWriter:
    """One worker thread that runs file writes in the order they are submitted, so that the
    time loop does not wait for them (VTU compression releases the GIL).  The files are the
    same, byte for byte, as when written in the foreground.  An error of a write is raised
    in the caller's thread at the next :meth:`submit`, :meth:`wait` or :meth:`close`; at most
    ``depth`` writes are queued (a further submit waits for the oldest).

    After a write has failed no later job runs (each raises that first error instead): a
    checkpoint queued behind a failed results or ParaView write must not be saved, or it
    would claim samples that are not on disk."""

    def __init__(self, depth: int = 16) -> None:
        self.depth = int(depth)
        self._pool: ThreadPoolExecutor | None = None
        self._pending: list[Future] = []
        self._held: list | None = None
        #: the first error of a job (then no later job runs)
        self._failure: BaseException | None = None

    def _guarded(self, job, args: tuple) -> None:
        """Run ``job(*args)`` on the worker unless an earlier job failed."""
        if self._failure is not None:
            raise self._failure
        try:
            job(*args)
        except BaseException as exc:
            self._failure = exc
            raise

    @contextmanager
    def held(self):
        """The writes submitted inside are queued as one, at the end: the worker starts once
        the caller has prepared them all, instead of taking the interpreter from it meanwhile
        (one sample's three series)."""
        if self._held is not None:
            yield
            return
        self._held = []
        try:
            yield
        finally:
            jobs, self._held = self._held, None
            if jobs:
                self.submit(_run_in_turn, jobs)

    def submit(self, job, *args) -> None:
        """Queue ``job(*args)`` (its arguments must not be changed afterwards)."""
        if self._held is not None:
            self._held.append((job, args))
            return
        self._collect(block=len(self._pending) >= self.depth)
        if self._pool is None:
            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="nurbsdem-output")
        self._pending.append(self._pool.submit(self._guarded, job, args))

    def _collect(self, block: bool) -> None:
        """Drop finished writes from the queue, raising the first error; with ``block``, wait
        for the oldest first."""
        if block and self._pending:
            self._pending[0].result()
        while self._pending and self._pending[0].done():
            self._pending.pop(0).result()

    def wait(self) -> None:
        """Wait until everything queued is written (raises the first error)."""
        while self._pending:
            self._pending.pop(0).result()

    def close(self) -> None:
        """:meth:`wait`, then stop the worker."""
        try:
            self.wait()
        finally:
            self.abandon()

    def abandon(self) -> None:
        """Let the queued writes finish, ignoring their errors, and stop the worker."""
        for f in self._pending:
            f.exception()
        self._pending = []
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None


def _run_in_turn(jobs: list) -> None:
    """Run the (job, args) one after the other (a :meth:`BackgroundWriter.held` batch)."""
    for job, args in jobs:
        job(*args)

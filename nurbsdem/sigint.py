"""Ctrl-C (SIGINT) during a run: obeyed at the end of a deck time step, after a checkpoint of
that moment, instead of wherever the signal lands (:class:`SigintDeferral`); the run then ends
with :class:`Interrupted` (``nurbsdem solve`` exits with status 130)."""
from __future__ import annotations

import contextlib
import signal
import threading


class Interrupted(KeyboardInterrupt):
    """Ctrl-C (SIGINT) stopped a run at the end of a deck time step, after a checkpoint of
    that moment (``str()`` says when, and where the checkpoint is)."""


class SigintDeferral:
    """Whether a Ctrl-C waits to be obeyed (:attr:`requested`) and whether the time loop, the
    only place where it waits, runs now (:attr:`loop_active`)."""

    def __init__(self) -> None:
        #: SIGINT while the time loop runs sets this; the loop stops at the next deck-step
        #: boundary
        self.requested = False
        self.loop_active = False

    @contextlib.contextmanager
    def deferring(self, comm):
        """While a step runs, Ctrl-C (SIGINT) inside its time loop only sets :attr:`requested`,
        obeyed at the next deck-step boundary: a KeyboardInterrupt raised in the middle of the
        compiled loop's threads or of a background write kills the process or leaves files
        behind the checkpoint.  Outside the time loop (set-up, compiling) the handler that was
        there is called.  Installed only where Python allows it (the main thread) and on one
        rank (``comm`` None: several MPI ranks would have to agree on where to stop); the
        previous handler is put back after the step."""
        previous = signal.getsignal(signal.SIGINT)
        if (comm is not None or threading.current_thread() is not threading.main_thread()
                or previous in (None, signal.SIG_IGN)):
            yield
            return

        def handler(signum, frame):
            if self.loop_active:
                self.requested = True
            elif callable(previous):
                previous(signum, frame)
            else:                               # SIG_DFL
                raise KeyboardInterrupt

        signal.signal(signal.SIGINT, handler)
        try:
            yield
        finally:
            signal.signal(signal.SIGINT, previous)

    @contextlib.contextmanager
    def time_loop(self):
        """The time loop runs inside: a Ctrl-C now waits for the next deck-step boundary."""
        self.loop_active = True
        try:
            yield
        finally:
            self.loop_active = False

"""One run per output folder: an advisory lock (``fcntl.flock``) on ``<folder>/.nurbsdem.lock``.

A run holds the lock from the moment it opens its writers (before it cleans or sets aside
anything in the folder) until it closes them; a second run into the same folder is refused
at once with one line naming the folder and the holder's process id (written into the lock
file), instead of interleaving its samples with the first run's.  The operating system
releases the lock when the holder exits, killed or not, so a stale lock file never blocks a
later run.  The lock is re-entrant within a process (a Simulation that closes and reopens its
writers, the command line cleaning a restart's folder before the run opens it).
"""
from __future__ import annotations

import os
import threading
from pathlib import Path

from ..errors import InputError

LOCK_NAME = ".nurbsdem.lock"

#: folder (resolved) -> [open file descriptor, holders in this process]
_held: dict[str, list[int]] = {}
_guard = threading.Lock()


def _other_pid(fd: int) -> str:
    try:
        text = os.pread(fd, 64, 0).decode("ascii", "replace").strip()
    except OSError:
        return "unknown"
    return text if text.isdigit() else "unknown"


def acquire(folder: str | Path) -> str | None:
    """Take the lock of ``folder`` (created if missing) for this process; returns the key for
    :func:`release`.  Raises :class:`~nurbsdem.errors.InputError` when another process holds
    it.  Where the file system has no locks (``flock`` not supported) or the lock file cannot
    be made (a read-only folder: None) the run goes on unlocked."""
    import fcntl
    folder = Path(folder)
    key = str(folder.resolve())
    with _guard:
        if key in _held:
            _held[key][1] += 1
            return key
        try:
            fd = os.open(folder / LOCK_NAME, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError:                  # a read-only folder: the run's own writes say so
            return None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            pid = _other_pid(fd)
            os.close(fd)
            raise InputError(f"the output folder {folder} is in use by another nurbsdem run "
                             f"(pid {pid}); wait for it to end or give another output folder") \
                from None
        except OSError:                  # no flock on this file system: unlocked
            pass
        try:
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        except OSError:
            pass
        _held[key] = [fd, 1]
        return key


def release(key: str | None) -> None:
    """Give back one hold of :func:`acquire` (the lock goes with the last one)."""
    if key is None:
        return
    with _guard:
        entry = _held.get(key)
        if entry is None:
            return
        entry[1] -= 1
        if entry[1] > 0:
            return
        del _held[key]
        fd = entry[0]
    try:
        os.ftruncate(fd, 0)
    except OSError:
        pass
    os.close(fd)                          # closing the descriptor drops the flock

"""Atomic file writes: a file is either complete or absent, never torn."""
from __future__ import annotations

import errno
import os
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator, Sequence


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success rename it onto ``path``.

    On an exception the temporary file is removed and ``path`` keeps its old content.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the usual file mode
    try:
        yield Path(tmp)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        _unlink_quietly(tmp)
        if exc.filename in (None, tmp, str(tmp)):   # name the file the user knows
            raise OSError(exc.errno, f"cannot write: {exc.strerror or exc}", str(path)) from None
        raise
    except BaseException:
        _unlink_quietly(tmp)
        raise


def _unlink_quietly(path: str) -> None:
    try:
        if os.path.exists(path):
            os.unlink(path)
    except OSError:
        pass


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_text(path: str | Path, text: str) -> None:
    """Write text to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def atomic_write_bytes(path: str | Path, data: bytes | Sequence[bytes]) -> None:
    """Write bytes (or pieces of bytes, one after the other) to ``path`` atomically (plain
    file I/O: a full disk is an OSError)."""
    with atomic_path(path) as tmp:
        if isinstance(data, (bytes, bytearray, memoryview)):
            tmp.write_bytes(data)
        else:
            with open(tmp, "wb") as fh:
                fh.writelines(data)


def write_hdf5_atomically(path: str | Path, fill, source: str | Path | None = None,
                          **file_kwargs) -> None:
    """Build an HDF5 file in memory and write it to ``path`` atomically.

    ``fill(h5file)`` writes the content; ``source``: an existing file to start from (opened
    ``r+`` in memory) instead of an empty one. HDF5 never writes to the disk itself, so a
    full disk or a file-size limit ends in a clean ``OSError`` instead of an HDF5 failure
    inside the library (which can crash the process).
    """
    import io

    import h5py

    buf = io.BytesIO(Path(source).read_bytes()) if source is not None else io.BytesIO()
    with h5py.File(buf, "r+" if source is not None else "w", **file_kwargs) as f:
        fill(f)
    atomic_write_bytes(path, buf.getvalue())


#: Prefix/suffix of the temporaries of :func:`atomic_path` (``.NAME.XXXX.tmp``).
TEMP_GLOB = ".*.tmp"


def remove_stale_temporaries(folder: str | Path) -> list[Path]:
    """Delete the temporaries a killed writer left in ``folder`` (``.NAME.XXXX.tmp``, the
    names :func:`atomic_path` uses); returns what was removed. Missing folder: nothing."""
    removed = []
    folder = Path(folder)
    if not folder.is_dir():
        return removed
    for tmp in folder.glob(TEMP_GLOB):
        try:
            if tmp.is_file():
                tmp.unlink()
                removed.append(tmp)
        except OSError:
            pass
    return removed


#: Free space kept in reserve on the output file system (bytes) by :func:`ensure_space`.
SPACE_RESERVE = 4 * 1024 * 1024


def ensure_space(folder: str | Path, nbytes: int) -> None:
    """Raise ``OSError(ENOSPC)`` naming ``folder`` when its file system has less than
    ``nbytes`` + :data:`SPACE_RESERVE` free: a clean error before a library (HDF5) meets a
    full disk in the middle of a write."""
    folder = Path(folder)
    try:
        free = shutil.disk_usage(folder).free
    except OSError:
        return
    need = int(nbytes) + SPACE_RESERVE
    if free < need:
        raise OSError(errno.ENOSPC, f"no space left on device: {need / 1e6:.3g} MB needed, "
                      f"{free / 1e6:.3g} MB free", str(folder))

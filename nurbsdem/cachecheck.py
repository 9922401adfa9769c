"""Stale compiled kernels: drop numba's on-disk cache when any source of the package changed.

numba keys each cached kernel on its own source file only.  A kernel that calls (and
inlines) a kernel of another module keeps its machine code after that other module
changed — a ``git pull`` or an upgrade that edits ``contact/support.py`` but not
``contact/detect.py`` left ``detect``'s cached batch calling the old layout of a table: wrong
numbers or a segmentation fault at the first contact.  Here one hash of all the package's
sources stands for the whole cache: each cache folder holds it in :data:`STAMP`, and where it
differs from the sources the folder's ``*.nbi`` / ``*.nbc`` files are deleted before any
kernel loads (numba compiles them again on first use, once).

The folders are the ones numba's cache locators choose (``numba.core.caching``), without
importing numba (``import nurbsdem`` stays light): ``$NUMBA_CACHE_DIR/<dir>_<sha1 of the
dir>`` when that variable is set, else the source folder's ``__pycache__`` when it is
writable, else the user-wide cache (``~/.cache/numba/<dir>_<sha1>`` on Linux).
"""
from __future__ import annotations

import hashlib
import os
import sys
import tempfile
from pathlib import Path

#: the file in each cache folder that holds the hash of the sources its kernels came from
STAMP = "nurbsdem-sources.sha1"
PACKAGE = Path(__file__).resolve().parent


def sources_hash(package: Path = PACKAGE) -> str:
    """SHA-1 of every ``.py`` file of ``package`` (relative path and bytes, sorted).  numba's
    own index checks its version, and the files' names carry Python's."""
    h = hashlib.sha1()
    for path in sorted(package.rglob("*.py")):
        h.update(str(path.relative_to(package)).encode() + b"\0")
        h.update(path.read_bytes())
    return h.hexdigest()


def _suitable_subpath(source_dir: Path) -> str:
    """numba's ``_CacheLocator.get_suitable_cache_subpath`` for the files of ``source_dir``."""
    subpath = os.path.abspath(source_dir)
    return "_".join([os.path.split(subpath)[-1], hashlib.sha1(subpath.encode()).hexdigest()])


def _usable(folder: Path) -> bool:
    """numba's ``ensure_cache_path``: the folder exists or can be made, and takes a file."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
        return True
    except OSError:
        return False


def _user_wide_dir() -> Path:
    """numba's user-wide cache folder (its own ``AppDirs`` where not on Linux)."""
    if sys.platform.startswith("linux"):
        base = os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache")
        return Path(base) / "numba"
    from numba.misc.appdirs import AppDirs          # macOS, Windows: numba's own rule
    return Path(AppDirs(appname="numba", appauthor=False).user_cache_dir)


def cache_folder(source_dir: Path) -> Path | None:
    """The folder numba caches the kernels of ``source_dir``'s modules in (None: none)."""
    user_dir = os.environ.get("NUMBA_CACHE_DIR", "")
    candidates = ([Path(user_dir) / _suitable_subpath(source_dir)] if user_dir else []) + [
        source_dir / "__pycache__", _user_wide_dir() / _suitable_subpath(source_dir)]
    for folder in candidates:
        if _usable(folder):
            return folder
    return None


def drop_stale(folder: Path, digest: str) -> int:
    """Delete the numba cache files of ``folder`` unless its :data:`STAMP` holds ``digest``,
    then write ``digest`` there (atomically); returns the number of files deleted."""
    stamp = folder / STAMP
    try:
        if stamp.read_text().strip() == digest:
            return 0
    except OSError:
        pass
    dropped = 0
    for pattern in ("*.nbi", "*.nbc"):
        for path in folder.glob(pattern):
            try:
                path.unlink()
                dropped += 1
            except OSError:             # another process took it first
                pass
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=STAMP)
    with os.fdopen(fd, "w") as f:
        f.write(digest + "\n")
    os.replace(tmp, stamp)
    return dropped


def compiles_first(package: Path = PACKAGE) -> bool:
    """Whether the compiled deck loop is missing from numba's cache: the next run compiles
    the kernels before it starts (minutes, once per install or upgrade; tell the user)."""
    folder = cache_folder(package / "dynamics")
    return folder is None or not any(folder.glob("deck_steps.run_deck_steps-*.nbi"))


def check_caches(package: Path = PACKAGE) -> int:
    """:func:`drop_stale` in the cache folder of every source folder of ``package``; returns
    the files deleted.  Errors of the file system leave the caches as they are (numba's own
    per-file check still applies)."""
    try:
        digest = sources_hash(package)
        dirs = sorted({p.parent for p in package.rglob("*.py")
                       if "__pycache__" not in p.parts})
        dropped = 0
        for source_dir in dirs:
            folder = cache_folder(source_dir)
            if folder is not None:
                dropped += drop_stale(folder, digest)
        return dropped
    except OSError:
        return 0

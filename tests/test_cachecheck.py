"""numba's on-disk cache is dropped as a whole when any source of the package changes
(nurbsdem.cachecheck): a kernel inlined from another module must not keep old code."""
from __future__ import annotations

import importlib
import os
from pathlib import Path

import pytest

from nurbsdem import cachecheck


def _package(root: Path) -> Path:
    """A package of two folders, each with a module and a numba cache beside its bytecode."""
    pkg = root / "pkg"
    for folder, module in ((pkg, "a.py"), (pkg / "sub", "b.py")):
        (folder / "__pycache__").mkdir(parents=True)
        (folder / module).write_text("X = 1\n")
        for name in ("m.f-10.py311.nbi", "m.f-10.py311.1.nbc", "m.cpython-311.pyc"):
            (folder / "__pycache__" / name).write_bytes(b"old")
    return pkg


def _cached(pkg: Path) -> list[str]:
    return sorted(p.name for p in pkg.rglob("__pycache__/*") if p.suffix in (".nbi", ".nbc"))


def test_a_change_in_one_module_drops_the_kernels_of_every_folder(tmp_path, monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    pkg = _package(tmp_path)
    assert cachecheck.check_caches(pkg) == 4         # no stamp yet: nothing is trusted
    for folder in (pkg, pkg / "sub"):                 # numba compiles again, into the folders
        for name in ("m.f-10.py311.nbi", "m.f-10.py311.1.nbc"):
            (folder / "__pycache__" / name).write_bytes(b"new")
    assert cachecheck.check_caches(pkg) == 0          # the same sources: the cache stays
    assert len(_cached(pkg)) == 4
    (pkg / "sub" / "b.py").write_text("X = 2\n")      # one module of one folder changes
    assert cachecheck.check_caches(pkg) == 4          # ... and the kernels of both go
    assert _cached(pkg) == []
    assert len(list(pkg.rglob("*.pyc"))) == 2         # Python's bytecode is not numba's
    assert cachecheck.check_caches(pkg) == 0


def test_the_stamp_names_the_sources(tmp_path, monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    pkg = _package(tmp_path)
    cachecheck.check_caches(pkg)
    digest = cachecheck.sources_hash(pkg)
    for folder in (pkg, pkg / "sub"):
        assert (folder / "__pycache__" / cachecheck.STAMP).read_text().strip() == digest
    (pkg / "a.py").write_text("X = 1  # the same code, another text\n")
    assert cachecheck.sources_hash(pkg) != digest


@pytest.mark.parametrize("user_dir", [False, True])
def test_the_folders_are_those_numba_caches_in(tmp_path, monkeypatch, user_dir):
    """The folder found for a module's kernels is the one numba's own locator picks, with and
    without NUMBA_CACHE_DIR."""
    import numba
    from numba.core.caching import FunctionCache

    detect = importlib.import_module("nurbsdem.contact.detect")
    if user_dir:
        monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
        monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path / "numba"))
    else:
        monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
        monkeypatch.setattr(numba.config, "CACHE_DIR", "")
    expected = FunctionCache(detect.solve_rows.py_func)._cache_path
    assert os.path.samefile(cachecheck.cache_folder(Path(detect.__file__).parent), expected)


def test_the_installed_package_is_stamped():
    """Importing nurbsdem checked its own caches: each folder's stamp is the sources' hash."""
    import nurbsdem
    pkg = Path(nurbsdem.__file__).parent
    folder = cachecheck.cache_folder(pkg / "dynamics")
    assert (folder / cachecheck.STAMP).read_text().strip() == cachecheck.sources_hash(pkg)


def test_a_missing_compiled_loop_is_told(tmp_path, monkeypatch, caplog):
    """Before a run that must compile the kernels first (numba's cache without the compiled
    deck loop: a fresh install, an upgrade), ``nurbsdem solve`` says so in one log line."""
    import logging

    import numba
    from numba.core.caching import FunctionCache

    from nurbsdem import cli
    deck_steps = importlib.import_module("nurbsdem.dynamics.deck_steps")
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path / "numba"))
    monkeypatch.setattr(logging.getLogger("nurbsdem"), "propagate", True)
    caplog.set_level(logging.INFO, logger="nurbsdem")
    assert cachecheck.compiles_first()
    cli._tell_first_compilation()
    assert [r.getMessage()[:29] for r in caplog.records] == ["compiling the kernels for thi"]
    index = Path(FunctionCache(deck_steps.run_deck_steps.py_func)._cache_file._index_path)
    index.parent.mkdir(parents=True, exist_ok=True)
    index.write_bytes(b"")                            # where numba keeps the loop's index
    caplog.clear()
    assert not cachecheck.compiles_first()
    cli._tell_first_compilation()
    assert caplog.records == []

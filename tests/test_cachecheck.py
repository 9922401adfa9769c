"""numba's on-disk cache loses a module's kernels when the code of that module or of a
package module it imports changed (nurbsdem.cachecheck): a kernel inlined from another module
must not keep old code, and an unrelated edit keeps the cache."""
from __future__ import annotations

import importlib
import os
from pathlib import Path

import pytest

from nurbsdem import cachecheck


def _package(root: Path) -> Path:
    """A package of two folders: ``a`` imports ``sub.b`` (inside a function), ``sub.b``
    imports ``sub.c`` (a chain), ``sub.d`` imports nothing of the package; each module has
    kernels in numba's cache beside its bytecode."""
    pkg = root / "pkg"
    sources = {pkg / "a.py": "def f():\n    from .sub.b import X\n    return X\n",
               pkg / "sub" / "b.py": '"""b"""\nfrom pkg.sub import c\nX = c.Y  # one\n',
               pkg / "sub" / "c.py": "import numpy as np\nY = 1\n",
               pkg / "sub" / "d.py": "Z = 1\n"}
    for path, text in sources.items():
        (path.parent / "__pycache__").mkdir(parents=True, exist_ok=True)
        path.write_text(text)
        _compile(path)
        (path.parent / "__pycache__" / f"{path.stem}.cpython-311.pyc").write_bytes(b"old")
    return pkg


def _compile(module: Path) -> None:
    """What numba writes for one kernel of ``module``: an index and a library."""
    for name in (f"{module.stem}.f-10.py311.nbi", f"{module.stem}.f-10.py311.1.nbc"):
        (module.parent / "__pycache__" / name).write_bytes(b"new")


def _cached(pkg: Path) -> list[str]:
    return sorted({p.name.split(".")[0] for p in pkg.rglob("__pycache__/*")
                   if p.suffix in (".nbi", ".nbc")})


def test_an_edit_drops_the_kernels_of_the_modules_built_from_it(tmp_path, monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    pkg = _package(tmp_path)
    assert cachecheck.check_caches(pkg) == 8         # no stamp yet: nothing is trusted
    for module in pkg.rglob("*.py"):                  # numba compiles again, into the folders
        _compile(module)
    assert cachecheck.check_caches(pkg) == 0          # the same sources: the cache stays
    assert _cached(pkg) == ["a", "b", "c", "d"]
    (pkg / "sub" / "c.py").write_text("import numpy as np\nY = 2\n")
    assert cachecheck.check_caches(pkg) == 6          # c, b importing it, a importing b
    assert _cached(pkg) == ["d"]                      # ... in both folders; d stays
    assert len(list(pkg.rglob("*.pyc"))) == 4         # Python's bytecode is not numba's
    assert cachecheck.check_caches(pkg) == 0
    for module in pkg.rglob("*.py"):
        _compile(module)
    (pkg / "sub" / "b.py").write_text('"""b"""\nfrom pkg.sub import c\nX = -c.Y\n')
    assert cachecheck.check_caches(pkg) == 4          # b and a; c and d stay
    assert _cached(pkg) == ["c", "d"]


def test_an_edit_of_an_unrelated_module_keeps_the_kernels(tmp_path, monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    pkg = _package(tmp_path)
    cachecheck.check_caches(pkg)
    for module in pkg.rglob("*.py"):
        _compile(module)
    (pkg / "sub" / "d.py").write_text("Z = 3\n")
    assert cachecheck.check_caches(pkg) == 2          # d's own kernel only
    assert _cached(pkg) == ["a", "b", "c"]


def test_an_edit_of_comments_or_docstrings_keeps_the_kernels(tmp_path, monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    pkg = _package(tmp_path)
    cachecheck.check_caches(pkg)
    for module in pkg.rglob("*.py"):
        _compile(module)
    (pkg / "sub" / "b.py").write_text('"""Another text."""\nfrom pkg.sub import c\n\n'
                                      'X = c.Y   # two\n')
    (pkg / "sub" / "c.py").write_text('import numpy as np\n\n\nY = 1  # the same\n')
    before = (pkg / "sub" / "__pycache__" / cachecheck.STAMP).read_text()
    assert cachecheck.check_caches(pkg) == 0
    assert _cached(pkg) == ["a", "b", "c", "d"]
    after = (pkg / "sub" / "__pycache__" / cachecheck.STAMP).read_text()
    assert after.splitlines()[1:] == before.splitlines()[1:]    # the same module hashes
    assert after.splitlines()[0] != before.splitlines()[0]      # new sources: parsed once


def test_a_module_that_does_not_parse_drops_its_importers(tmp_path, monkeypatch):
    """A source being edited (a syntax error) stands for itself by its bytes: the kernels of
    the modules importing it go, the others stay."""
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    pkg = _package(tmp_path)
    cachecheck.check_caches(pkg)
    for module in pkg.rglob("*.py"):
        _compile(module)
    (pkg / "sub" / "c.py").write_text("Y = (\n")
    assert cachecheck.check_caches(pkg) == 6
    assert _cached(pkg) == ["d"]


def test_the_imports_found_are_the_package_modules(tmp_path):
    """Relative and absolute imports, ``from p import module`` and ``from p import name``
    (the package's ``__init__``), imports inside functions; other packages' are not."""
    import ast
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    for name in ("__init__.py", "jit.py", "sub/__init__.py", "sub/lcp.py", "sub/x.py"):
        (pkg / name).write_text("V = 1\n")
    text = ("import numpy\nfrom numpy import linalg\nfrom . import lcp\nfrom .. import V\n"
            "def g():\n    import pkg.jit\n    from .lcp import V\n")
    found = cachecheck.imported_modules(pkg / "sub" / "x.py", ast.parse(text), pkg)
    assert sorted(str(p.relative_to(pkg)) for p in found) == [
        "__init__.py", "jit.py", "sub/lcp.py"]


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
    """Importing nurbsdem checked its own caches: each folder's stamp holds the sources' hash
    and the hashes of the folder's modules."""
    import nurbsdem
    pkg = Path(nurbsdem.__file__).parent
    folder = cachecheck.cache_folder(pkg / "dynamics")
    digest, modules = cachecheck.read_stamp(folder)
    assert digest == cachecheck.sources_hash(pkg)
    hashes = cachecheck.module_hashes(pkg)
    assert modules == {p.stem: h for p, h in hashes.items() if p.parent == pkg / "dynamics"}


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
    # a set: where an earlier test left a handler on the logger, the line is captured twice
    assert {r.getMessage()[:29] for r in caplog.records} == {"compiling the kernels for thi"}
    index = Path(FunctionCache(deck_steps.run_deck_steps.py_func)._cache_file._index_path)
    index.parent.mkdir(parents=True, exist_ok=True)
    index.write_bytes(b"")                            # where numba keeps the loop's index
    caplog.clear()
    assert not cachecheck.compiles_first()
    cli._tell_first_compilation()
    assert caplog.records == []

"""Stale compiled kernels: drop a module's kernels from numba's on-disk cache when the code
they were compiled from changed, in that module or in a module of the package it imports.

numba keys each cached kernel on its own source file only.  A kernel that calls (and
inlines) a kernel of another module, or reads its constants (numba freezes imported globals
into the machine code), keeps its machine code after that other module changed — a
``git pull`` or an upgrade that edits ``contact/support.py`` but not ``contact/detect.py``
left ``detect``'s cached batch calling the old layout of a table: wrong numbers or a
segmentation fault at the first contact.  Here each module's kernels stand on a hash of the
module and of every package module it imports, directly or through others (imports inside
functions included: :func:`module_hashes`).  Each cache folder holds the hashes of its
modules in :data:`STAMP`; where a module's hash differs, its ``<module>.*.nbi`` / ``.nbc``
files are deleted before any kernel loads (numba compiles them again on first use, once),
and the kernels of the other modules stay.

A module's hash is that of its syntax tree (``ast.dump``) without docstrings: an edit of a
comment, a docstring or the layout changes no compiled code, so the kernels of the modules
importing it stay (numba itself still recompiles the kernels of the edited file: its index
checks the file's time stamp).  The bytes of all sources are hashed first
(:func:`sources_hash`, milliseconds); the trees are parsed only when those changed.

The folders are the ones numba's cache locators choose (``numba.core.caching``), without
importing numba (``import nurbsdem`` stays light): ``$NUMBA_CACHE_DIR/<dir>_<sha1 of the
dir>`` when that variable is set, else the source folder's ``__pycache__`` when it is
writable, else the user-wide cache (``~/.cache/numba/<dir>_<sha1>`` on Linux).
"""
from __future__ import annotations

import ast
import hashlib
import os
import sys
import tempfile
from pathlib import Path

#: the file in each cache folder that holds the hashes of the sources its kernels came from:
#: a line ``sources <sources_hash>``, then one line ``<module> <module hash>`` per module
STAMP = "nurbsdem-sources.sha1"
PACKAGE = Path(__file__).resolve().parent


def sources_hash(package: Path = PACKAGE) -> str:
    """SHA-1 of every ``.py`` file of ``package`` (relative path and bytes, sorted): where
    the stamps hold it, no module changed.  numba's own index checks its version, and the
    files' names carry Python's."""
    h = hashlib.sha1()
    for path in _sources(package):
        h.update(str(path.relative_to(package)).encode() + b"\0")
        h.update(path.read_bytes())
    return h.hexdigest()


def _sources(package: Path) -> list[Path]:
    return sorted(p for p in package.rglob("*.py") if "__pycache__" not in p.parts)


def _without_docstrings(tree: ast.AST) -> ast.AST:
    """``tree`` with the docstring of the module and of each class and function removed."""
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if (body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant)
                    and isinstance(body[0].value.value, str)):
                node.body = body[1:]
    return tree


def code_hash(source: bytes) -> str:
    """SHA-1 of the code of one module: its syntax tree without docstrings (comments and
    layout are not in the tree)."""
    return _tree_hash(ast.parse(source))


def _tree_hash(tree: ast.AST) -> str:
    return hashlib.sha1(ast.dump(_without_docstrings(tree)).encode()).hexdigest()


def _module_file(package: Path, parts: list[str]) -> Path | None:
    """The file of the package module ``parts`` (relative to the package), if there is one."""
    if not parts:
        return package / "__init__.py" if (package / "__init__.py").is_file() else None
    for path in (package.joinpath(*parts).with_suffix(".py"),
                 package.joinpath(*parts, "__init__.py")):
        if path.is_file():
            return path
    return None


def imported_modules(path: Path, tree: ast.AST, package: Path) -> set[Path]:
    """The files of the package modules that the module ``path`` imports (anywhere in it:
    at the top, inside functions), absolute (``package.x.y``) or relative (``..x``).  For
    ``from m import n`` that is ``n`` where it is a module, else ``m``."""
    here = list(path.relative_to(package).parent.parts)
    found: set[Path | None] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                names = alias.name.split(".")
                if names[0] == package.name:
                    found.add(_module_file(package, names[1:]))
        elif isinstance(node, ast.ImportFrom):
            names = node.module.split(".") if node.module else []
            if node.level == 0 and names[:1] == [package.name]:
                parts = names[1:]
            elif 0 < node.level <= len(here) + 1:
                parts = here[:len(here) + 1 - node.level] + names
            else:
                continue                    # another package's module
            found.update(_from_import(package, parts, node.names))
    found.discard(None)
    found.discard(path)
    return found                                          # type: ignore[return-value]


def _from_import(package: Path, parts: list[str], names: list[ast.alias]) -> set[Path | None]:
    """The files ``from <parts> import <names>`` reads: each name that is a module, and
    ``parts`` itself where any name is not."""
    found: set[Path | None] = set()
    for alias in names:
        sub = _module_file(package, parts + [alias.name]) if alias.name != "*" else None
        found.add(sub if sub is not None else _module_file(package, parts))
    return found


def module_hashes(package: Path = PACKAGE) -> dict[Path, str]:
    """Source file -> SHA-1 of its code (:func:`code_hash`) and of the code of every package
    module it imports, directly or through others: what its compiled kernels were built
    from."""
    own: dict[Path, str] = {}
    deps: dict[Path, set[Path]] = {}
    for path in _sources(package):
        source = path.read_bytes()
        try:
            tree = ast.parse(source)
        except (SyntaxError, ValueError):   # a file being edited: its bytes stand for it
            deps[path], own[path] = set(), "bytes " + hashlib.sha1(source).hexdigest()
            continue
        deps[path] = imported_modules(path, tree, package)   # before the docstrings go
        own[path] = _tree_hash(tree)
    hashes = {}
    for path in own:
        closure, todo = {path}, [path]
        while todo:
            for dep in deps.get(todo.pop(), ()):
                if dep not in closure and dep in own:
                    closure.add(dep)
                    todo.append(dep)
        h = hashlib.sha1()
        for dep in sorted(closure):
            h.update(str(dep.relative_to(package)).encode() + b"\0" + own[dep].encode())
        hashes[path] = h.hexdigest()
    return hashes


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


def read_stamp(folder: Path) -> tuple[str, dict[str, str]]:
    """The sources' hash and the module hashes (module name -> hash) that ``folder``'s
    :data:`STAMP` holds (``""`` and none where it is missing or unreadable)."""
    try:
        lines = (folder / STAMP).read_text().splitlines()
    except OSError:
        return "", {}
    digest, modules = "", {}
    for line in lines:
        key, _, value = line.partition(" ")
        if key == "sources" and not digest:
            digest = value.strip()
        elif value and key != "sources":
            modules[key] = value.strip()
    return digest, modules


def drop_stale(folder: Path, digest: str, modules: dict[str, str]) -> int:
    """Delete the numba cache files (``<module>.*.nbi`` / ``.nbc``) of each module of
    ``modules`` (module name -> hash) whose hash ``folder``'s :data:`STAMP` does not hold,
    then write ``digest`` (:func:`sources_hash`) and ``modules`` there (atomically); returns
    the number of files deleted."""
    _, stamped = read_stamp(folder)
    dropped = 0
    for name in sorted(modules):
        if stamped.get(name) == modules[name]:
            continue
        for pattern in (f"{name}.*.nbi", f"{name}.*.nbc"):
            for path in folder.glob(pattern):
                try:
                    path.unlink()
                    dropped += 1
                except OSError:             # another process took it first
                    pass
    text = f"sources {digest}\n" + "".join(f"{name} {modules[name]}\n" for name in sorted(modules))
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=STAMP)
    with os.fdopen(fd, "w") as f:
        f.write(text)
    os.replace(tmp, folder / STAMP)
    return dropped


def compiles_first(package: Path = PACKAGE) -> bool:
    """Whether the compiled deck loop is missing from numba's cache: the next run compiles
    the kernels before it starts (minutes, once per install or upgrade; tell the user)."""
    folder = cache_folder(package / "dynamics")
    return folder is None or not any(folder.glob("deck_steps.run_deck_steps-*.nbi"))


def check_caches(package: Path = PACKAGE) -> int:
    """:func:`drop_stale` in the cache folder of every source folder of ``package`` whose
    stamp does not hold the sources' hash; returns the files deleted.  Errors of the file
    system leave the caches as they are (numba's own per-file check still applies)."""
    try:
        digest = sources_hash(package)
        by_dir: dict[Path, list[Path]] = {}
        for path in _sources(package):
            by_dir.setdefault(path.parent, []).append(path)
        hashes: dict[Path, str] | None = None
        dropped = 0
        for source_dir in sorted(by_dir):
            folder = cache_folder(source_dir)
            if folder is None or read_stamp(folder)[0] == digest:
                continue
            if hashes is None:
                hashes = module_hashes(package)
            modules = {p.stem: hashes[p] for p in by_dir[source_dir]}
            dropped += drop_stale(folder, digest, modules)
        return dropped
    except OSError:
        return 0

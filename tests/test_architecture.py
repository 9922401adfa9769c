"""The package's import structure: no import cycles (imports inside functions included), and
the readers of file formats stand below the solver (they import nothing from ``contact/`` or
``dynamics/``).

The graph is built from the syntax trees (:mod:`ast`), without importing anything: an edge
``m -> t`` for each module ``t`` of the package that ``m`` imports anywhere in its file, and
for each package ``__init__`` that importing ``t`` runs first (the ancestors of ``t`` that are
not ancestors of ``m``: those already run before ``m``)."""
from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "nurbsdem"
ROOT = "nurbsdem"

#: the modules of file formats (YAML shapes, Giraffe, Rhino, mesh files; VTU) and what they may
#: not use
READERS = ("nurbsdem.io.shapefile", "nurbsdem.io.giraffe", "nurbsdem.io.rhino",
           "nurbsdem.io.meshfile", "nurbsdem.io.vtu")
SOLVER_PARTS = ("nurbsdem.contact", "nurbsdem.dynamics")


def _modules() -> dict[str, Path]:
    """Dotted name -> file of every module of the package (a package is its ``__init__``)."""
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        if "__pycache__" in path.parts:
            continue
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def _is_package(name: str, modules: dict[str, Path]) -> bool:
    return modules[name].name == "__init__.py"


def _type_checking_only(tree: ast.AST) -> set[int]:
    """ids of the import nodes under ``if TYPE_CHECKING:`` (never run)."""
    out: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If):
            test = node.test
            name = test.id if isinstance(test, ast.Name) else getattr(test, "attr", None)
            if name == "TYPE_CHECKING":
                out.update(id(n) for stmt in node.body for n in ast.walk(stmt))
    return out


def _targets(name: str, tree: ast.AST, modules: dict[str, Path]) -> set[str]:
    """The package modules that module ``name`` imports (anywhere in its file, except under
    ``if TYPE_CHECKING:``).  ``from p import m`` of a submodule m runs p's ``__init__`` only
    where p is not a package the module itself lies in."""
    here = name if _is_package(name, modules) else name.rpartition(".")[0]
    skip = _type_checking_only(tree)
    found: set[str] = set()
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            bases = [alias.name for alias in node.names]
            subs: list[str] = []
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = here.split(".")
                base = base[:len(base) - (node.level - 1)]
                bases = [".".join(base + ([node.module] if node.module else []))]
            else:
                bases = [node.module or ""]
            subs = [f"{bases[0]}.{alias.name}" for alias in node.names]
            if subs and all(s in modules for s in subs):
                found.update(subs)     # the package's __init__: an ancestor edge, if any
                found.update(a for a in [bases[0]] if a in modules and not
                             (name == a or name.startswith(a + ".")))
                continue
        else:
            continue
        for b in bases:
            if b in modules:
                found.add(b)
            else:   # `import a.b.c` of a name below a module: the deepest module it names
                parts = b.split(".")
                while parts and ".".join(parts) not in modules:
                    parts.pop()
                if parts:
                    found.add(".".join(parts))
        found.update(s for s in subs if s in modules)
    return {t for t in found if t == ROOT or t.startswith(ROOT + ".")}


def _ancestors(name: str) -> list[str]:
    parts = name.split(".")
    return [".".join(parts[:i]) for i in range(1, len(parts))]


@functools.lru_cache(maxsize=1)
def import_graph() -> dict[str, frozenset[str]]:
    """Module -> the package modules its import statements run (module docstring); parsed
    once per session (the tests only read it)."""
    modules = _modules()
    graph: dict[str, frozenset[str]] = {}
    for name, path in modules.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        own = set(_ancestors(name))
        edges = set()
        for t in _targets(name, tree, modules):
            edges.add(t)
            edges.update(a for a in _ancestors(t) if a not in own and a in modules)
        edges.discard(name)
        graph[name] = frozenset(edges)
    return graph


def find_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def reachable(graph: dict[str, set[str]], start: str) -> set[str]:
    seen, todo = set(), [start]
    while todo:
        for w in graph.get(todo.pop(), ()):
            if w not in seen:
                seen.add(w)
                todo.append(w)
    return seen


def test_graph_sees_function_local_and_relative_imports():
    """The parser finds imports inside functions and resolves relative ones (a check of the
    check: without these edges the cycle test below could not fail)."""
    graph = import_graph()
    # simulation.py imports the solver inside a method
    assert "nurbsdem.solver" in graph["nurbsdem.simulation"]
    assert "nurbsdem.dynamics.forces" in graph["nurbsdem.dynamics.system"]
    cyclic = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert find_cycles(cyclic) == [["a", "b", "c"]]


def test_no_import_cycles():
    cycles = find_cycles(import_graph())
    assert cycles == [], "import cycles: " + "; ".join(" <-> ".join(c) for c in cycles)


@pytest.mark.parametrize("reader", READERS)
def test_file_readers_do_not_import_the_solver(reader):
    """A reader of a file format needs the geometry, not the contact search or the dynamics
    (whatever it reaches through its imports, transitively)."""
    graph = import_graph()
    assert reader in graph, f"{reader} is not a module of the package"
    bad = sorted(m for m in reachable(graph, reader)
                 if any(m == p or m.startswith(p + ".") for p in SOLVER_PARTS))
    assert bad == [], f"{reader} imports {bad}"


# --------------------------------------------------------------------------- internal kernels
#: decorators that compile a function (its body runs compiled, so it may call an internal one)
COMPILED = {"njit", "jit", "kernel", "internal", "vectorize", "guvectorize", "stencil"}


def _decorator_names(func: ast.AST) -> set[str]:
    names = set()
    for d in getattr(func, "decorator_list", []):
        d = d.func if isinstance(d, ast.Call) else d
        names.add(d.attr if isinstance(d, ast.Attribute) else getattr(d, "id", ""))
    return names


def _internal_kernels() -> set[tuple[str, str]]:
    """(module, name) of every kernel compiled with :func:`nurbsdem.jit.internal`."""
    out = set()
    for name, path in _modules().items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef) and "internal" in _decorator_names(node):
                out.add((name, node.name))
    return out


def _python_calls(path: Path, module: str, internal: set[tuple[str, str]]) -> list[str]:
    """Calls in ``path`` (module ``module``; "" outside the package) of internal kernels made
    by Python code: outside any function compiled by numba."""
    tree = ast.parse(path.read_text())
    bound = {n for (m, n) in internal if m == module}
    aliases: dict[str, str] = {}        # a module's name here -> its dotted name
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module is not None:
            base = node.module
            if node.level:
                pkg = module.split(".")[:-node.level] if module else []
                base = ".".join(pkg + [node.module])
            bound |= {a.asname or a.name for a in node.names if (base, a.name) in internal}
            aliases.update({a.asname or a.name: f"{base}.{a.name}" for a in node.names})
        elif isinstance(node, ast.Import):
            for a in node.names:
                aliases[a.asname or a.name.split(".")[0]] = a.name if a.asname else \
                    a.name.split(".")[0]
    bad = []

    def dotted(node) -> str | None:
        """``x.y.z`` of a chain of names, its first name resolved through the imports."""
        if isinstance(node, ast.Name):
            return aliases.get(node.id)
        if isinstance(node, ast.Attribute):
            head = dotted(node.value)
            return None if head is None else f"{head}.{node.attr}"
        return None

    def calls_internal(call) -> str | None:
        f = call.func
        if isinstance(f, ast.Name) and f.id in bound:
            return f.id
        if isinstance(f, ast.Attribute) and (dotted(f.value), f.attr) in internal:
            return f.attr
        return None

    def visit(node, compiled):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            compiled = bool(_decorator_names(node) & COMPILED)
        name = calls_internal(node) if isinstance(node, ast.Call) and not compiled else None
        if name is not None:
            bad.append(f"{path.name}:{node.lineno} {name}")
        for child in ast.iter_child_nodes(node):
            visit(child, compiled)
    visit(tree, False)
    return bad


def test_python_code_never_calls_an_internal_kernel():
    """A kernel compiled by :func:`nurbsdem.jit.internal` has no entry for Python: called
    from Python it would crash the process, so only compiled code calls it (package, tests,
    benchmarks and examples are checked)."""
    internal = _internal_kernels()
    assert ("nurbsdem.dynamics.deck_steps", "_evaluate") in internal    # the scan sees them
    files = [(m, p) for m, p in _modules().items()]
    top = PACKAGE.parent
    files += [("", p) for d in ("tests", "benchmarks", "examples") for p in (top / d).rglob("*.py")]
    bad = [b for m, p in files for b in _python_calls(p, m, internal)]
    assert not bad, f"internal kernels called from Python: {bad}"


def test_the_internal_kernel_check_sees_a_python_call(tmp_path):
    internal = {("nurbsdem.dynamics.deck_steps", "_kept")}
    f = tmp_path / "t.py"
    f.write_text("from numba import njit\nfrom nurbsdem.dynamics.deck_steps import _kept\n"
                 "import nurbsdem.dynamics.deck_steps as ds\nfrom nurbsdem.dynamics import "
                 "deck_steps\n@njit\ndef ok(a):\n    return _kept(a) + ds._kept(a)\n"
                 "def bad(a):\n    return _kept(a) + ds._kept(a) + deck_steps._kept(a)\n")
    assert _python_calls(f, "", internal) == ["t.py:9 _kept", "t.py:9 _kept", "t.py:9 _kept"]

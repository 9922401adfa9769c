"""pytest set-up shared by the tests.

``benchmarks/`` holds references that are not part of the package (``polyhedral.py``, the
GJK/EPA contact of tessellated hulls); the benchmark scripts import them as plain modules
from their own folder, and so do the tests: the folder goes on ``sys.path`` here.

Several pytest processes can share one run (``tests/run_parallel.py``, what ``make test``
runs): each takes whole test files, claiming a file when it reaches its first test (a file
created in the folder ``NURBSDEM_TEST_CLAIMS``), and leaves the files another process claimed.
Worker k of n (``NURBSDEM_TEST_WORKER`` "k/n") starts at the k-th n-th of the files and wraps
around, so the workers meet wherever the work divides.  Without those variables pytest runs
every test, as usual.
"""
from __future__ import annotations

import os
import re
import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
BENCHMARKS = TESTS.parent / "benchmarks"
if str(BENCHMARKS) not in sys.path:
    sys.path.append(str(BENCHMARKS))

CLAIMS = os.environ.get("NURBSDEM_TEST_CLAIMS")
_mine: set[str] = set()
_theirs: set[str] = set()


def _worker() -> tuple[int, int]:
    k, n = os.environ.get("NURBSDEM_TEST_WORKER", "0/1").split("/")
    return int(k), int(n)


def _file_key(item) -> str:
    return str(Path(item.path).relative_to(TESTS))


#: words of a test file that may run the compiled time loop (a deck, a simulation, the
#: command line, a benchmark's scene, another process)
_TIME_LOOP_WORDS = re.compile(r"Simulation|DemSystem|from_deck|DeckSteps|run_deck|Solver|"
                              r"\.inp|\bcli\b|subprocess|warm_up|bench_|importlib|nurbsdem\.api")


def _may_drive_time_loop(path: Path) -> bool:
    """Whether the test file ``path`` may run the compiled time loop.  A worker started while
    the runner's warm-up still compiles the loop (``NURBSDEM_TEST_EARLY``) takes the other
    files first, so that it does not compile the loop a second time meanwhile.  An order
    only: a file taken too early compiles what it needs, with the same results."""
    return bool(_TIME_LOOP_WORDS.search(path.read_text(encoding="utf-8")))


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config, items):
    """In a shared run: the test files in this worker's order (each file's tests in theirs),
    and the list of files with selected tests written for the runner's check."""
    if not CLAIMS:
        return
    files = list(dict.fromkeys(_file_key(it) for it in items))
    k, n = _worker()
    start = len(files) * k // n
    order = files[start:] + files[:start]
    if os.environ.get("NURBSDEM_TEST_EARLY"):
        order.sort(key=lambda f: _may_drive_time_loop(TESTS / f))     # stable: False first
    rank = {f: i for i, f in enumerate(order)}
    items.sort(key=lambda it: rank[_file_key(it)])
    if k == 0:
        (Path(CLAIMS) / "files.txt").write_text("\n".join(sorted(files)) + "\n")


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_protocol(item, nextitem):
    """In a shared run: run the tests of the files this worker claims; the others' are left
    (reported by the worker that runs them)."""
    if not CLAIMS:
        return None
    key = _file_key(item)
    if key in _mine:
        return None
    if key not in _theirs:
        claim = Path(CLAIMS) / (key.replace(os.sep, "__") + ".claim")
        try:
            os.close(os.open(claim, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
            _mine.add(key)
            return None
        except FileExistsError:
            _theirs.add(key)
    return True

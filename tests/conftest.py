"""pytest set-up shared by the tests.

``benchmarks/`` holds references that are not part of the package (``polyhedral.py``, the
GJK/EPA contact of tessellated hulls); the benchmark scripts import them as plain modules
from their own folder, and so do the tests: the folder goes on ``sys.path`` here.
"""
from __future__ import annotations

import sys
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
if str(BENCHMARKS) not in sys.path:
    sys.path.append(str(BENCHMARKS))

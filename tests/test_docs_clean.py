"""The documentation, comments and docstrings state what is true, not a diary: no numbered
milestones of the work, no labels of run orders, no remarks on the machine's slower or faster
moods, no issue numbers, and no references to the retired developer notes, in the README,
docs/ (the changelog aside), the package, the tests and the benchmarks (whose text goes into
the generated reports)."""
from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

# built from pieces so that this file does not match itself
PATTERNS = {
    "a 'stop N' milestone": re.compile(r"\bst" + r"op \d", re.I),
    "a run-order label": re.compile(r"\bAB" + r"BA\b"),
    "a 'spell' of the machine": re.compile(
        r"\b(?:slow|slower|fast|faster|quiet|busy|short|long|good|bad)\s+sp" + r"ells?\b"
        r"|\bsp" + r"ells? of (?:the|this|a) ", re.I),
    "the retired developer notes": re.compile(r"DEV" + r"NOTES"),
    "an issue's number": re.compile(r"\biss" + r"ues? *#?\d", re.I),
}


def _files() -> list[Path]:
    files = [REPO / "README.md"]
    files += sorted((REPO / "docs").rglob("*.md"))
    for folder in ("nurbsdem", "tests", "benchmarks"):
        files += sorted((REPO / folder).rglob("*.py"))
    return [f for f in files if f.is_file() and f.name != "CHANGELOG.md"]


def hits(files: list[Path]) -> list[tuple[Path, int, str, str]]:
    """Every line of the files that matches a pattern: (file, line number, what, text)."""
    out = []
    for f in files:
        for n, line in enumerate(f.read_text(encoding="utf-8").splitlines(), 1):
            out += [(f, n, what, line.strip()) for what, pattern in PATTERNS.items()
                    if pattern.search(line)]
    return out


def test_the_patterns_catch_diary_and_spare_ordinary_words(tmp_path):
    diary = ["as before st" + "op 31", "Report (a slow sp" + "ell of the VM)",
             "alternated AB" + "BA", "see DEV" + "NOTES", "in a faster sp" + "ell",
             "the scripting API (iss" + "ue #14)", "as iss" + "ue 42 asks"]
    plain = ["the deck's spelling", "the spelled-out array", "Step 3 of the deck",
             "the LCP stops at 1e-11", "the copy that spells the rows out", "a stop at 3 m",
             "a known issue of numba", "issues a warning"]
    f = tmp_path / "x.md"
    f.write_text("\n".join(diary + plain), encoding="utf-8")
    assert sorted({n for _, n, _, _ in hits([f])}) == list(range(1, len(diary) + 1))


def test_no_diary_in_docs_code_tests_and_benchmarks():
    found = [f"{f.relative_to(REPO)}:{n}: {what}: {text[:120]}"
             for f, n, what, text in hits(_files())]
    assert not found, "state what is true and why instead:\n" + "\n".join(found)

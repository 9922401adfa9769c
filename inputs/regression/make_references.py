"""Regenerate the reference monitors of the regression decks (run after a deliberate change
of results, and say why in the commit):

    .venv/bin/python inputs/regression/make_references.py

Each deck in this folder is solved into a temporary folder and its ``monitors/*.csv`` are
copied to ``reference/<deck>/``. ``tests/test_regression_decks.py`` compares new runs with
them within tolerances.
"""
from __future__ import annotations

import shutil
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
DECKS = ("drop_one", "two_spheres", "deposition_small", "lid_press")


def main(names=DECKS) -> None:
    from nurbsdem.io.deck import parse_deck
    from nurbsdem.solver import Solver

    for name in names:
        with tempfile.TemporaryDirectory() as tmp:
            model = parse_deck(HERE / f"{name}.inp")
            Solver(model, output=tmp, quiet=True).run()
            dest = HERE / "reference" / name
            if dest.exists():
                shutil.rmtree(dest)
            shutil.copytree(Path(tmp) / "monitors", dest)
            print(f"{name}: references written to {dest}")


if __name__ == "__main__":
    main(sys.argv[1:] or DECKS)

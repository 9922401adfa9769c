"""Error types that the command line turns into one-line messages (no traceback)."""
from __future__ import annotations

import numpy as np


class NurbsdemError(Exception):
    """Base class of every error that is the user's input's fault.

    The message is the whole one-line report, e.g. ``"case.inp:12: unknown keyword 'Foo'"``.
    """


class InputError(NurbsdemError):
    """A problem in an input file, located by file and (when known) line or patch.

    Parameters
    ----------
    message: what is wrong.
    path: the file (as the user named it).
    line: 1-based line number, if known.
    where: another locator (e.g. ``"patch 3"``) when there is no line.
    """

    def __init__(self, message: str, path: str | None = None, line: int | None = None,
                 where: str | None = None) -> None:
        self.path = path
        self.line = line
        self.where = where
        self.detail = message
        loc = ""
        if path is not None:
            loc = str(path)
            if line is not None:
                loc += f":{line}"
            loc += ": "
        if where:
            loc += f"{where}: "
        super().__init__(loc + message)


class GeometryError(InputError):
    """A shape that is not a valid closed, outward-oriented, convex NURBS particle."""


def vector_text(v) -> str:
    """A vector as messages and summaries write it: each component to 6 significant digits,
    separated by spaces, without "-0"."""
    return " ".join(f"{float(x) + 0.0:g}" for x in np.asarray(v, float))

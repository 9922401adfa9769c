"""The rule for wall names, shared by the deck (``Wall … Name``) and the Python API
(:meth:`nurbsdem.simulation.Simulation.add_wall`).

A wall's name is part of a file name (``monitors/wall_<name>.csv``) and a word of the deck
(``Name <name>``, ``MoveWall <name>``) that :attr:`Simulation.deck_text` and ``results.h5``
store, so it must be both a safe file name and a deck word that reads back as itself:
letters, digits, ``_``, ``-`` and ``.``, not starting with ``.`` (no ``/``, no ``..``, no
``#`` that starts a comment, no quotes), and not a keyword of the deck lines that hold a
wall name (``Duration``, ``Name``, ..., in any case: the deck's keywords are
case-insensitive).
"""
from __future__ import annotations

import re
from typing import Any, Mapping

#: what a wall name may be made of
_NAME_RE = re.compile(r"[A-Za-z0-9_-][A-Za-z0-9_.-]*\Z")
#: the longest name (a file name component is at most 255 bytes; ``wall_`` + ``.csv`` +
#: a temporary's prefix and suffix take the rest)
NAME_MAX = 200
RULE = ("letters, digits, '_', '-' and '.', not starting with '.', at most "
        f"{NAME_MAX} characters, and not a keyword such as Duration")


#: the deck entries whose lines hold a wall name as a value (``Wall … Name n``,
#: ``Step … MoveWall n``): a name equal to one of their keys reads back as that key
NAME_ENTRIES = (("Walls", "Wall"), ("Walls", "Mesh"), ("Walls", "Surface"), ("Steps", "Step"))


def keywords(schema: Mapping[str, Mapping[str, Any]]) -> set[str]:
    """The keys of the entries of :data:`NAME_ENTRIES` in a deck schema
    (:data:`nurbsdem.io.deck_schema.SCHEMA`), lower case (the deck's keywords are case-insensitive)."""
    return {k.lower() for block, entry in NAME_ENTRIES for k in schema[block][entry].keys}


def wall_name_problem(name: object, schema: Mapping[str, Mapping[str, Any]]) -> str | None:
    """None when ``name`` is a valid wall name of a deck with ``schema`` (its keywords are
    not names), else what is wrong with it (one line, the same text for the deck and the
    API)."""
    if not isinstance(name, str):
        return f"a wall name must be text, got {type(name).__name__}"
    if not _NAME_RE.match(name) or len(name) > NAME_MAX:
        return f"bad wall name {name!r}: a name is {RULE}"
    if name.lower() in keywords(schema):
        return (f"bad wall name {name!r}: it is a keyword of the deck's Wall and Step lines "
                f"(a name is {RULE})")
    return None

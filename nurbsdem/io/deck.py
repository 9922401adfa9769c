"""The input deck: a Giraffe-like text format.

Grammar
-------
* A block opens with its keyword alone on a line: ``Environment``, ``Materials``,
  ``Shapes``, ``Particles``, ``Walls``, ``Contact``, ``Steps``, ``Output`` (any order; a
  block may appear more than once).
* Inside a block, one entry per line: ``Keyword [id] Key value... Key value...``.
  Numbered entries (``Material 1 ...``) carry an integer id; settings (``Gravity 0 0 -9.81``,
  ``Directory results``) do not.
* ``#`` starts a comment anywhere; ``//`` starts one at the start of a line or after a
  blank. Values may be quoted (``File "my shapes/A.yaml"``).
* Keywords are case-insensitive; names (wall names, files) are kept as written.
* SI units (m, kg, s, N); paths are relative to the deck's folder.

Every mistake raises :class:`~nurbsdem.errors.InputError` whose ``str()`` is one line
``deck.inp:LINE: what is wrong``. :func:`parse_deck` returns a :class:`~nurbsdem.model.Model`
and, by default, also places the particles (``model.bodies``) so that placement problems
are reported at check time.

Entries: every block, entry and key the parser accepts is
:data:`~nurbsdem.io.deck_schema.SCHEMA`; their units, defaults and meaning are in
``docs/deck-reference.md``, generated from it by :mod:`nurbsdem.io.deck_reference` (a test
fails when a key is undocumented). :func:`lex_deck` reads the text into entries,
:func:`~nurbsdem.io.deck_build.build_entries` builds the model from them, and
:func:`~nurbsdem.io.deck_format.format_model` writes a model back as deck text.
"""
from __future__ import annotations

import difflib
import math
import re
import shlex
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..model import Model
# the supported magnitudes of the values (below the solver: the geometry and scene checks read
# them too)
from ..ranges import ID_MAX, RANGES
from .deck_build import build_entries
from .deck_schema import SCHEMA, Arg, Entry, LineError

_BLOCKS = {b.lower(): b for b in SCHEMA}


def _fmt_num(x: float) -> str:
    return f"{x:g}" if isinstance(x, float) else (str(x) if abs(x) < 10 ** 15 else f"{float(x):g}")


def check_range(key: str, value: Any, label: str) -> None:
    """Raise ``_DeckError`` when a value of ``key`` lies outside :data:`RANGES` (with why)."""
    rng = RANGES.get(key)
    if rng is None or isinstance(value, (bool, str)) or value is None:
        return
    unit = f" {rng.unit}" if rng.unit else ""
    for x in np.ravel(np.asarray(value, dtype=object)):
        if rng.nonnegative and x < 0:
            continue
        if abs(x) > rng.hi or (0 < x < rng.lo):
            span = (f"at most {_fmt_num(rng.hi)}{unit}" if not rng.lo
                    else f"between {_fmt_num(rng.lo)} and {_fmt_num(rng.hi)}{unit}")
            raise _DeckError(f"{label}{key} {_fmt_num(x)}{unit} is out of range: it must be "
                             f"{span} ({rng.reason})")


_NUMBER_RE = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")
_INT_RE = re.compile(r"^[-+]?\d+$")
_TRUE = {"yes", "true", "on", "1"}
_FALSE = {"no", "false", "off", "0"}


class _DeckError(Exception):
    """Internal: a message for the current line."""


# ---------------------------------------------------------------------------- lexing


def strip_comment(text: str) -> str:
    """The line without its comment (``#`` anywhere, ``//`` at start or after a blank),
    ignoring comment marks inside double quotes."""
    quote = False
    for i, ch in enumerate(text):
        if ch == '"':
            quote = not quote
        elif not quote and ch == "#":
            return text[:i]
        elif (not quote and ch == "/" and text[i:i + 2] == "//"
              and (i == 0 or text[i - 1].isspace())):
            return text[:i]
    return text


def split_tokens(text: str) -> list[str]:
    """Whitespace-separated tokens of a comment-free line (double quotes group)."""
    if '"' not in text:
        return text.split()
    try:
        lex = shlex.shlex(text, posix=True)
        lex.whitespace_split = True
        lex.commenters = ""
        lex.quotes = '"'
        lex.escape = ""
        return list(lex)
    except ValueError:
        raise _DeckError("unbalanced double quote") from None


def _suggest(word: str, choices: list[str]) -> str:
    close = difflib.get_close_matches(word.lower(), [c.lower() for c in choices], n=1)
    if close:
        name = next(c for c in choices if c.lower() == close[0])
        return f" (did you mean {name!r}?)"
    return ""


def _canonical(word: str, choices: dict[str, Any]) -> str | None:
    low = word.lower()
    for key in choices:
        if key.lower() == low:
            return key
    return None


# ---------------------------------------------------------------------------- values


def parse_float(token: str, what: str) -> float:
    """A finite real number, else an error naming ``what``."""
    if not _NUMBER_RE.match(token):
        raise _DeckError(f"{what}: bad number {token!r}")
    value = float(token)
    if not math.isfinite(value):
        raise _DeckError(f"{what}: number out of range {token!r}")
    return value


def parse_int(token: str, what: str) -> int:
    """An integer, else an error naming ``what``."""
    if not _INT_RE.match(token):
        raise _DeckError(f"{what}: bad integer {token!r}")
    if len(token.lstrip("+-")) > 19:
        raise _DeckError(f"{what}: integer {token[:12]}... is too large (at most 19 digits)")
    return int(token)


def _looks_numeric(token: str) -> bool:
    return bool(_NUMBER_RE.match(token))


def _convert(kind: str, token: str, what: str) -> Any:
    if kind == "float":
        return parse_float(token, what)
    if kind == "int":
        return parse_int(token, what)
    if kind == "bool":
        low = token.lower()
        if low in _TRUE:
            return True
        if low in _FALSE:
            return False
        raise _DeckError(f"{what}: expected yes or no, got {token!r}")
    return token


def _take(arg: Arg, tokens: list[str], pos: int, what: str,
          keys: dict[str, Arg]) -> tuple[Any, int]:
    """Read the values of one keyword from tokens[pos:]; returns (value, new pos)."""
    if arg.kind == "flag":
        return True, pos
    if arg.count is None:  # one or more numbers
        vals = []
        while pos < len(tokens) and _looks_numeric(tokens[pos]):
            vals.append(_convert(arg.kind, tokens[pos], what))
            pos += 1
        if not vals:
            got = f", got {tokens[pos]!r}" if pos < len(tokens) else ""
            raise _DeckError(f"{what} needs at least one {'integer' if arg.kind == 'int' else 'number'}{got}")
        return tuple(vals), pos
    vals = []
    numeric = arg.kind in ("float", "int")
    for _ in range(arg.count):
        if pos >= len(tokens) or (not _looks_numeric(tokens[pos])
                                  and _canonical(tokens[pos], keys) is not None):
            if arg.count == 1:
                raise _DeckError(f"{what} needs a value")
            raise _DeckError(f"{what} needs {arg.count} numbers, got {len(vals)}")
        vals.append(_convert(arg.kind, tokens[pos], what))
        pos += 1
    if numeric and pos < len(tokens) and _looks_numeric(tokens[pos]):
        n = arg.count
        raise _DeckError(f"{what} takes {n} number{'s' if n > 1 else ''}, "
                         f"got more ({tokens[pos]!r})")
    if arg.count == 1:
        return vals[0], pos
    if numeric:
        return np.array(vals, dtype=float) if arg.kind == "float" else tuple(vals), pos
    return tuple(vals), pos


def _unknown_first_word(block: str | None, tokens: list[str]) -> str:
    """The message for a line whose first word is neither a block nor an entry keyword."""
    word = tokens[0]
    blocks = list(SCHEMA)
    if block is None:
        if len(tokens) == 1:
            return f"unknown block {word!r}{_suggest(word, blocks)}"
        return (f"{word!r} outside a block (a block keyword comes first: "
                f"{', '.join(blocks)})")
    specs = list(SCHEMA[block])
    if len(tokens) == 1:
        return f"unknown block or keyword {word!r}{_suggest(word, blocks + specs)}"
    return (f"unknown keyword {word!r} in block {block} (expected "
            f"{' or '.join(specs)}){_suggest(word, specs)}")


def parse_entry(block: str, tokens: list[str], line: int) -> Entry:
    """Parse the tokens of one entry line of ``block``."""
    specs = SCHEMA[block]
    kw = _canonical(tokens[0], specs)
    if kw is None:
        raise _DeckError(_unknown_first_word(block, tokens))
    spec = specs[kw]
    entry = Entry(block, kw, line)
    pos = 1
    if spec.numbered:
        if pos >= len(tokens):
            raise _DeckError(f"{kw} needs an id number")
        entry.id = parse_int(tokens[pos], f"{kw} id")
        if entry.id < 1:
            raise _DeckError(f"{kw} id must be >= 1, got {entry.id}")
        if entry.id > ID_MAX:
            raise _DeckError(f"{kw} id {entry.id} is too large: ids are at most {ID_MAX:g} "
                             f"(ids are 64-bit integers and copies are numbered after them)")
        pos += 1
        label = f"{kw} {entry.id}: "
    else:
        label = f"{kw}: "
    if spec.head is not None:
        entry.head, pos = _take(spec.head, tokens, pos, kw, spec.keys)
        check_range(kw, entry.head, "")
    while pos < len(tokens):
        tok = tokens[pos]
        key = _canonical(tok, spec.keys)
        if key is None:
            if _looks_numeric(tok):
                raise _DeckError(f"{label}unexpected number {tok!r}")
            raise _DeckError(f"{label}unknown keyword {tok!r}{_suggest(tok, list(spec.keys))}")
        if key in entry.values:
            raise _DeckError(f"{label}{key} given twice")
        entry.values[key], pos = _take(spec.keys[key], tokens, pos + 1, f"{label}{key}",
                                       spec.keys)
        check_range(key, entry.values[key], label)
    return entry


def lex_deck(text: str) -> list[Entry]:
    """All entries of a deck text, in order (errors carry the line number)."""
    entries: list[Entry] = []
    block: str | None = None
    for lineno, raw in enumerate(text.splitlines(), start=1):
        try:
            tokens = split_tokens(strip_comment(raw))
            if not tokens:
                continue
            low = tokens[0].lower()
            if low in _BLOCKS:
                if len(tokens) > 1:
                    raise _DeckError(f"block keyword {_BLOCKS[low]!r} must be alone on its "
                                     f"line (got {tokens[1]!r} after it)")
                block = _BLOCKS[low]
                continue
            if block is None:
                raise _DeckError(_unknown_first_word(None, tokens))
            entries.append(parse_entry(block, tokens, lineno))
        except _DeckError as exc:
            raise LineError(str(exc), lineno) from None
    return entries




def build_model(text: str, path: str) -> Model:
    """Parse deck text into a :class:`Model` (no particle placement).

    ``path`` locates errors and anchors relative paths. Raises :class:`InputError`.
    """
    try:
        return build_entries(lex_deck(text), path, text)
    except LineError as exc:
        raise InputError(str(exc), path=path, line=exc.line) from None


def parse_deck(path: str | Path, place: bool = True) -> Model:
    """Read an input deck.

    Parameters
    ----------
    path: the deck file; error messages name it as given.
    place: also place the particles (:func:`nurbsdem.placement.initial_bodies`) into
        ``model.bodies``, so that impossible placements and overlaps are input errors.

    Raises
    ------
    InputError: one line ``deck:LINE: message``.
    """
    spath = str(path)
    try:
        text = read_deck_text(path)
    except OSError as exc:
        raise InputError(f"cannot read deck: {exc.strerror or exc}", path=spath) from None
    model = build_model(text, spath)
    if place:
        from ..placement import initial_bodies
        from ..validation import check_model, validate_scene
        check_model(model)
        model.bodies = initial_bodies(model)
        validate_scene(model)
    return model


def read_deck_text(path: str | Path) -> str:
    """The text of a deck file: UTF-8, with or without a byte-order mark; universal
    newlines. Raises :class:`InputError` for a binary (non-UTF-8) file."""
    data = Path(path).read_bytes()
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[:exc.start].count(b"\n") + 1
        raise InputError(f"the deck is not a UTF-8 text file (byte 0x{data[exc.start]:02x} at "
                         f"offset {exc.start})", path=str(path), line=line) from None
    if "\x00" in text:
        raise InputError("the deck is not a text file (it contains NUL bytes)",
                         path=str(path), line=text[:text.index("\x00")].count("\n") + 1)
    return text.replace("\r\n", "\n").replace("\r", "\n")

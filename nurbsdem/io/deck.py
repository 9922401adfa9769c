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

Entries: every block, entry and key the parser accepts is :data:`SCHEMA`; their units,
defaults and meaning are in ``docs/deck-reference.md``, generated from :data:`SCHEMA` by
:mod:`nurbsdem.io.deck_reference` (a test fails when a key is undocumented).
"""
from __future__ import annotations

import difflib
import math
import re
import shlex
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..errors import InputError
from ..model import (DAMPING_SCHEMES, DynamicStep, Material, Model, MoveWallStep, Output,
                     ParticleSpec, RandomGroup, ReplicateStep, ShapeEntry, Step, WallSpec)
# the supported magnitudes of the values (below the solver: the geometry and scene checks read
# them too)
from ..ranges import ASPECT_MAX, ID_MAX, RANGES, Range  # noqa: F401

# ---------------------------------------------------------------------------- schema


@dataclass(frozen=True)
class Arg:
    """What follows a keyword: ``count`` values of ``kind`` (``None`` = one or more).

    kind: ``float``, ``int``, ``str``, ``bool`` or ``flag`` (no value).
    """

    kind: str
    count: int | None = 1


F1, F2, F3, F6 = Arg("float", 1), Arg("float", 2), Arg("float", 3), Arg("float", 6)
I1, IN, S1, B1, FLAG = Arg("int", 1), Arg("int", None), Arg("str", 1), Arg("bool", 1), Arg("flag", 0)


@dataclass(frozen=True)
class EntrySpec:
    """An entry kind: numbered (integer id after the keyword) or a setting whose own values
    (``head``) follow the keyword directly; then ``Key value`` pairs from ``keys``."""

    numbered: bool
    keys: dict[str, Arg] = field(default_factory=dict)
    head: Arg | None = None


SCHEMA: dict[str, dict[str, EntrySpec]] = {
    "Environment": {"Gravity": EntrySpec(False, head=F3)},
    "Materials": {"Material": EntrySpec(True, {"Density": F1, "YoungModulus": F1,
                                               "PoissonRatio": F1})},
    "Shapes": {"Shape": EntrySpec(True, {
        "File": S1, "Sphere": FLAG, "Ellipsoid": FLAG, "Radius": F1, "SemiAxes": F3,
        "Volume": F1, "Inertia": F6, "ConvexityTolerance": F1})},
    "Particles": {
        "Random": EntrySpec(True, {"Shapes": IN, "Counts": IN, "Material": I1, "Region": F6,
                                   "Seed": I1, "MaxAttempts": I1}),
        "Particle": EntrySpec(True, {"Shape": I1, "Material": I1, "Position": F3,
                                     "Rotation": F3, "Velocity": F3, "AngularVelocity": F3}),
    },
    "Walls": {
        "Box": EntrySpec(True, {"Min": F3, "Max": F3, "Top": B1, "Material": I1}),
        "Wall": EntrySpec(True, {"Name": S1, "Point": F3, "Normal": F3, "Size": F2, "Axis": F3,
                                 "Material": I1}),
        "Mesh": EntrySpec(True, {"Name": S1, "File": S1, "Scale": F1, "Position": F3,
                                 "Rotation": F3, "Material": I1, "OneSided": B1}),
        "Surface": EntrySpec(True, {"Name": S1, "File": S1, "Position": F3, "Rotation": F3,
                                    "Material": I1}),
    },
    "Contact": {"Interface": EntrySpec(True, {
        "NormalPenalty": F1, "TangentialPenalty": F1, "NormalDamping": F1,
        "TangentialDamping": F1, "Friction": F1, "Between": S1, "Materials": IN,
        "Model": S1, "Restitution": F1})},
    "Steps": {"Step": EntrySpec(True, {
        "Dynamic": FLAG, "Replicate": FLAG, "MoveWall": S1, "Duration": F1, "TimeStep": F1,
        "Layers": I1, "Height": F1, "ToContact": FLAG, "Gap": F1, "Direction": F3,
        "Displacement": F3, "Damping": S1, "Accuracy": F1, "Safety": F1, "Rotate": FLAG,
        "AngularVelocity": F3, "Center": F3})},
    "Output": {
        "Directory": EntrySpec(False, head=S1),
        "VTK": EntrySpec(False, {"Every": F1, "Resolution": I1}),
        "Monitors": EntrySpec(False, {"Every": F1}),
        "Results": EntrySpec(False, {"Every": F1}),
        "Checkpoint": EntrySpec(False, {"Every": F1}),
    },
}

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


@dataclass
class Entry:
    """One parsed deck line: keyword, id (numbered entries), head values, key values."""

    block: str
    keyword: str
    line: int
    id: int | None = None
    head: Any = None
    values: dict[str, Any] = field(default_factory=dict)

    def get(self, key: str, default: Any = None) -> Any:
        return self.values.get(key, default)

    def has(self, key: str) -> bool:
        return key in self.values


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
            raise _LineError(str(exc), lineno) from None
    return entries


class _LineError(Exception):
    def __init__(self, msg: str, line: int | None) -> None:
        super().__init__(msg)
        self.line = line


# ---------------------------------------------------------------------------- building


class _Builder:
    """Turns entries into a :class:`Model`, checking values and cross-references."""

    def __init__(self, path: str, text: str) -> None:
        self.model = Model(path=path, text=text)
        self.base = Path(path).resolve().parent
        self._shape_cache: dict[Path, Any] = {}
        self._settings: dict[str, int] = {}
        self._wall_ids: dict[int, int] = {}
        self._particle_ids: list[tuple[int, int, str, int]] = []  # (first, last, label, line)

    # -- helpers ---------------------------------------------------------------
    def fail(self, msg: str, line: int | None) -> None:
        raise _LineError(msg, line)

    def require(self, e: Entry, *keys: str) -> None:
        for k in keys:
            if not e.has(k):
                self.fail(f"{e.keyword} {e.id}: missing {k}" if e.id is not None
                          else f"{e.keyword}: missing {k}", e.line)

    def positive(self, e: Entry, key: str, value: float, strict: bool = True) -> float:
        if (strict and not value > 0) or (not strict and value < 0):
            self.fail(f"{self.label(e)}: {key} must be {'> 0' if strict else '>= 0'}, "
                      f"got {value:g}", e.line)
        return value

    @staticmethod
    def label(e: Entry) -> str:
        return f"{e.keyword} {e.id}" if e.id is not None else e.keyword

    def only(self, e: Entry, allowed: set[str], what: str) -> None:
        for k in e.values:
            if k not in allowed:
                self.fail(f"{self.label(e)}: {k} does not apply to {what}", e.line)

    def unique(self, table: dict, e: Entry, what: str) -> None:
        if e.id in table:
            prev = table[e.id]
            prev_line = prev if isinstance(prev, int) else prev.line
            self.fail(f"duplicate {what} id {e.id} (first at line {prev_line})", e.line)

    # -- blocks ----------------------------------------------------------------
    def setting_once(self, e: Entry) -> None:
        key = f"{e.block}.{e.keyword}"
        if key in self._settings:
            self.fail(f"{e.keyword} given twice (first at line {self._settings[key]})", e.line)
        self._settings[key] = e.line

    def environment(self, e: Entry) -> None:
        self.setting_once(e)
        self.model.gravity = np.asarray(e.head, float)

    def material(self, e: Entry) -> None:
        self.unique(self.model.materials, e, "material")
        self.require(e, "Density")
        rho = self.positive(e, "Density", e.get("Density"))
        E = e.get("YoungModulus")
        if E is not None:
            self.positive(e, "YoungModulus", E)
        nu = e.get("PoissonRatio", 0.0)
        if not -1.0 < nu < 0.5:
            self.fail(f"{self.label(e)}: PoissonRatio must lie in (-1, 0.5), got {nu:g}", e.line)
        self.model.materials[e.id] = Material(e.id, rho, e.line, E, float(nu))

    def shape(self, e: Entry) -> None:
        self.unique(self.model.shapes, e, "shape")
        kinds = [k for k in ("File", "Sphere", "Ellipsoid") if e.has(k)]
        if len(kinds) != 1:
            self.fail(f"Shape {e.id}: give exactly one of File, Sphere, Ellipsoid"
                      + (f" (got {' and '.join(kinds)})" if kinds else ""), e.line)
        kind = kinds[0]
        common = {"Volume", "Inertia"}
        from ..geometry import generators as gen
        from ..geometry.shape import Shape
        if kind == "File":
            self.only(e, common | {"File", "ConvexityTolerance"}, "a File shape")
            source = e.get("File")
            file = (self.base / source) if not Path(source).is_absolute() else Path(source)
            tol = e.get("ConvexityTolerance") if e.has("ConvexityTolerance") else None
            if tol is not None and not tol >= 0:
                self.fail(f"Shape {e.id}: ConvexityTolerance must be >= 0 (a fraction of the "
                          f"particle size), got {tol:g}", e.line)
            shape = self.load_shape_file(file, source, e.line, tol)
            entry = ShapeEntry(e.id, "file", shape, source=source, file=file, line=e.line)
        elif kind == "Sphere":
            self.only(e, common | {"Sphere", "Radius"}, "a Sphere shape")
            self.require(e, "Radius")
            r = self.positive(e, "Radius", e.get("Radius"))
            shape = self.generated(e, lambda: Shape(gen.sphere_patches(r), name=f"sphere r={r:g}"))
            entry = ShapeEntry(e.id, "sphere", shape, params=(r,), line=e.line)
        else:
            self.only(e, common | {"Ellipsoid", "SemiAxes"}, "an Ellipsoid shape")
            self.require(e, "SemiAxes")
            abc = e.get("SemiAxes")
            if np.any(abc <= 0):
                self.fail(f"Shape {e.id}: SemiAxes must be > 0", e.line)
            if abc.max() > ASPECT_MAX * abc.min():
                self.fail(f"Shape {e.id}: SemiAxes {abc.max() / abc.min():.3g} times longer than "
                          f"wide is beyond the {ASPECT_MAX:g} the contact search resolves", e.line)
            shape = self.generated(e, lambda: Shape(
                gen.ellipsoid_patches(*abc), name=f"ellipsoid {abc[0]:g}x{abc[1]:g}x{abc[2]:g}"))
            entry = ShapeEntry(e.id, "ellipsoid", shape, params=tuple(map(float, abc)),
                               line=e.line)
        if e.has("Volume"):
            entry.volume_override = self.positive(e, "Volume", e.get("Volume"))
        if e.has("Inertia"):
            entry.inertia_override = self.inertia_matrix(e, e.get("Inertia"))
        self.model.shapes[e.id] = entry

    def generated(self, e: Entry, make: Callable[[], Any]) -> Any:
        """A shape generated from the deck's numbers; its errors carry this entry's line."""
        try:
            return make()
        except (InputError, ValueError, ArithmeticError) as exc:
            detail = getattr(exc, "detail", None) or str(exc)
            self.fail(f"Shape {e.id}: {detail}", e.line)

    def load_shape_file(self, file: Path, source: str, line: int,
                        convexity_tol: float | None = None):
        from .shapefile import load_shape
        key = (file.resolve(), convexity_tol)
        if key in self._shape_cache:
            return self._shape_cache[key]
        from .shapefile import not_a_file
        why = not_a_file(file)
        if why is not None:
            self.fail(f"shape file {source}: {why}", line)
        try:
            shape = load_shape(file, convexity_tol=convexity_tol)
        except InputError as exc:
            loc = f"shape file {source}"
            if exc.line is not None:
                loc += f":{exc.line}"
            if exc.where:
                loc += f": {exc.where}"
            self.fail(f"{loc}: {exc.detail}", line)
        self._shape_cache[key] = shape
        return shape

    def inertia_matrix(self, e: Entry, j: np.ndarray) -> np.ndarray:
        jxx, jyy, jzz, jxy, jxz, jyz = j
        J = np.array([[jxx, jxy, jxz], [jxy, jyy, jyz], [jxz, jyz, jzz]])
        eig = np.linalg.eigvalsh(J)
        if eig.min() <= 0:
            self.fail(f"Shape {e.id}: Inertia is not positive definite "
                      f"(principal moments {', '.join(f'{x:.4g}' for x in eig)})", e.line)
        if eig[0] + eig[1] < eig[2] * (1 - 1e-9):
            self.fail(f"Shape {e.id}: Inertia violates the triangle inequality of a rigid "
                      f"body's principal moments", e.line)
        return J

    def claim_particle_ids(self, first: int, last: int, label: str, line: int) -> None:
        for a, b, other, oline in self._particle_ids:
            if first <= b and a <= last:
                clash = max(first, a)
                self.fail(f"{label}: particle id {clash} already used by {other} "
                          f"(line {oline})", line)
        self._particle_ids.append((first, last, label, line))

    def random(self, e: Entry) -> None:
        self.require(e, "Shapes", "Counts", "Material", "Region")
        shapes, counts = e.get("Shapes"), e.get("Counts")
        if len(shapes) != len(counts):
            self.fail(f"Random {e.id}: Shapes lists {len(shapes)} shapes but Counts "
                      f"{len(counts)} numbers", e.line)
        if any(c < 0 for c in counts) or sum(counts) == 0:
            self.fail(f"Random {e.id}: Counts must be >= 0 with at least one particle", e.line)
        reg = e.get("Region")
        lo, hi = reg[:3], reg[3:]
        if np.any(hi <= lo):
            self.fail(f"Random {e.id}: Region must be x0 y0 z0 x1 y1 z1 with x1 > x0, "
                      f"y1 > y0, z1 > z0", e.line)
        attempts = e.get("MaxAttempts", 20000)
        if attempts < 1:
            self.fail(f"Random {e.id}: MaxAttempts must be >= 1", e.line)
        g = RandomGroup(e.id, tuple(shapes), tuple(counts), e.get("Material"), lo.copy(),
                        hi.copy(), seed=e.get("Seed", 0), max_attempts=attempts, line=e.line)
        if g.seed < 0:
            self.fail(f"Random {e.id}: Seed must be >= 0", e.line)
        self.claim_particle_ids(g.id, g.id + g.total - 1, f"Random {e.id}", e.line)
        self.model.random_groups.append(g)

    def particle(self, e: Entry) -> None:
        self.require(e, "Shape", "Material", "Position")
        self.claim_particle_ids(e.id, e.id, f"Particle {e.id}", e.line)
        z = np.zeros(3)
        self.model.particles.append(ParticleSpec(
            e.id, e.get("Shape"), e.get("Material"), e.get("Position"),
            rotation=e.get("Rotation", z.copy()), velocity=e.get("Velocity", z.copy()),
            angular_velocity=e.get("AngularVelocity", z.copy()), line=e.line))

    def claim_wall_id(self, wid: int, label: str, line: int) -> None:
        if wid in self._wall_ids:
            self.fail(f"{label}: wall id {wid} already used (line {self._wall_ids[wid]})", line)
        self._wall_ids[wid] = line

    def add_wall(self, w: WallSpec, label: str) -> None:
        from .wallname import wall_name_problem
        problem = wall_name_problem(w.name, SCHEMA)
        if problem is not None:
            self.fail(f"{label}: {problem}", w.line)
        for other in self.model.walls + self.model.curved_walls:
            if other.name == w.name:
                self.fail(f"{label}: duplicate wall name {w.name!r} (first at line "
                          f"{other.line})", w.line)
        self.claim_wall_id(w.id, label, w.line)
        if isinstance(w, WallSpec):
            self.model.walls.append(w)
        else:
            self.model.curved_walls.append(w)

    def add_curved_wall(self, w, label: str) -> None:
        """A Mesh or Surface wall (:mod:`nurbsdem.io.deck_curved`), with the flat walls'
        name and id rules."""
        self.add_wall(w, label)

    def box(self, e: Entry) -> None:
        from ..geometry.generators import box_walls
        self.require(e, "Min", "Max")
        lo, hi = e.get("Min"), e.get("Max")
        if np.any(hi <= lo):
            self.fail(f"Box {e.id}: Max must exceed Min in x, y and z", e.line)
        for k, (name, patch) in enumerate(box_walls(lo, hi, top=e.get("Top", False)).items()):
            self.add_wall(WallSpec(e.id + k, name, patch, kind="box", line=e.line,
                                   material_id=e.get("Material")), f"Box {e.id}")

    def wall(self, e: Entry) -> None:
        from ..geometry.generators import flat_wall
        self.require(e, "Point", "Normal", "Size")
        n = e.get("Normal")
        if not np.linalg.norm(n) > 0:
            self.fail(f"Wall {e.id}: Normal must not be zero", e.line)
        size = e.get("Size")
        if np.any(size <= 0):
            self.fail(f"Wall {e.id}: Size must be > 0", e.line)
        axis = e.get("Axis")
        if axis is not None:
            t = axis - n * (axis @ n) / (n @ n)
            if np.linalg.norm(t) < 1e-12 * max(1.0, np.linalg.norm(axis)):
                self.fail(f"Wall {e.id}: Axis must not be parallel to Normal", e.line)
        patch = flat_wall(e.get("Point"), n, size, axis)
        name = e.get("Name", f"wall{e.id}")
        self.add_wall(WallSpec(e.id, name, patch, kind="wall", line=e.line,
                               material_id=e.get("Material")), f"Wall {e.id}")

    def interface(self, e: Entry) -> None:
        """``Interface``: the one front-end of the laws
        (:func:`~nurbsdem.dynamics.laws.interface.build_interface`), deck spelling, file:line."""
        from ..dynamics.laws.interface import COMMON_KEYS, Front, build_interface
        self.unique({i.id: i for i in self.model.interfaces}, e, "interface")
        front = Front(f"Interface {e.id}", str, lambda msg: self.fail(msg, e.line))
        values = {k: v for k, v in e.values.items() if k not in COMMON_KEYS}
        self.model.interfaces.append(build_interface(
            e.id, e.get("Model"), values, e.get("Between"), e.get("Materials"), front,
            line=e.line))

    def step(self, e: Entry) -> None:
        steps = self.model.steps
        self.unique({s.id: s for s in steps}, e, "step")
        if steps and e.id < steps[-1].id:
            self.fail(f"step ids must increase (Step {e.id} after Step {steps[-1].id})", e.line)
        types = [k for k in ("Dynamic", "Replicate", "MoveWall") if e.has(k)]
        if len(types) != 1:
            self.fail(f"Step {e.id}: give exactly one of Dynamic, Replicate, MoveWall"
                      + (f" (got {' and '.join(types)})" if types else ""), e.line)
        kind = types[0]
        if kind == "Dynamic":
            self.only(e, {"Dynamic", "Duration", "TimeStep", "Damping", "Accuracy",
                          "Safety"}, "a Dynamic step")
            self.require(e, "Duration", "TimeStep")
            step: Step = DynamicStep(e.id, e.line, *self.timing(e), damping=self.damping(e),
                                     accuracy=self.optional_positive(e, "Accuracy"),
                                     safety=self.optional_positive(e, "Safety"))
        elif kind == "Replicate":
            self.only(e, {"Replicate", "Layers", "Height"}, "a Replicate step")
            self.require(e, "Layers", "Height")
            if e.get("Layers") < 1:
                self.fail(f"Step {e.id}: Layers must be >= 1, got {e.get('Layers')}", e.line)
            step = ReplicateStep(e.id, e.line, e.get("Layers"),
                                 self.positive(e, "Height", e.get("Height")))
        else:
            step = self.move_wall(e)
        steps.append(step)

    def timing(self, e: Entry) -> tuple[float, float]:
        dur = self.positive(e, "Duration", e.get("Duration"))
        dt = self.positive(e, "TimeStep", e.get("TimeStep"))
        if dt > dur:
            self.fail(f"Step {e.id}: TimeStep {dt:g} s exceeds Duration {dur:g} s", e.line)
        return dur, dt

    def move_wall(self, e: Entry) -> MoveWallStep:
        modes = [k for k in ("ToContact", "Displacement", "Rotate") if e.has(k)]
        if len(modes) != 1:
            self.fail(f"Step {e.id}: MoveWall needs exactly one of ToContact, Displacement, "
                      f"Rotate", e.line)
        name = e.get("MoveWall")
        if modes[0] == "Rotate":
            return rotate_step(self, e, name)
        if modes[0] == "ToContact":
            self.only(e, {"MoveWall", "ToContact", "Gap", "Direction"}, "MoveWall ToContact")
            gap = self.positive(e, "Gap", e.get("Gap", 0.0), strict=False)
            d = e.get("Direction")
            if d is not None:
                if not np.linalg.norm(d) > 0:
                    self.fail(f"Step {e.id}: Direction must not be zero", e.line)
                d = d / np.linalg.norm(d)
            return MoveWallStep(e.id, e.line, wall=name, to_contact=True, gap=gap, direction=d)
        self.only(e, {"MoveWall", "Displacement", "Duration", "TimeStep", "Damping",
                      "Accuracy", "Safety"}, "MoveWall Displacement")
        self.require(e, "Duration", "TimeStep")
        dur, dt = self.timing(e)
        return MoveWallStep(e.id, e.line, wall=name, displacement=e.get("Displacement"),
                            duration=dur, time_step=dt, damping=self.damping(e),
                            accuracy=self.optional_positive(e, "Accuracy"),
                            safety=self.optional_positive(e, "Safety"))

    def damping(self, e: Entry) -> str:
        """The step's ``Damping`` scheme (lower case; default explicit)."""
        value = e.get("Damping", "explicit")
        if value.lower() not in DAMPING_SCHEMES:
            self.fail(f"Step {e.id}: Damping must be Explicit or Implicit, got {value!r}",
                      e.line)
        return value.lower()

    def optional_positive(self, e: Entry, key: str) -> float | None:
        """A step's optional positive number: ``Accuracy`` η (:mod:`nurbsdem.dynamics.accuracy`;
        None: off) or ``Safety`` f, the fraction of the contact network's stability limit the
        sub-step takes (:mod:`nurbsdem.dynamics.stepcontrol`; None: the solver's, 0.5)."""
        value = e.get(key)
        return None if value is None else self.positive(e, key, value)

    def output(self, entries: list[Entry]) -> None:
        out = Output(directory=self.base / "results")
        for e in entries:
            self.setting_once(e)
            if e.keyword == "Directory":
                d = Path(e.head)
                out.directory = d if d.is_absolute() else self.base / d
            elif e.keyword == "VTK":
                if e.has("Every"):
                    out.vtk_every = self.positive(e, "Every", e.get("Every"))
                if e.has("Resolution"):
                    res = e.get("Resolution")
                    if res < 1:
                        self.fail(f"VTK: Resolution must be >= 1, got {res}", e.line)
                    out.vtk_resolution = res
            elif e.has("Every"):
                val = self.positive(e, "Every", e.get("Every"))
                attr = {"Monitors": "monitors_every", "Results": "results_every",
                        "Checkpoint": "checkpoint_every"}[e.keyword]
                setattr(out, attr, val)
        self.model.output = out

    # -- cross references ------------------------------------------------------
    def check_references(self) -> None:
        m = self.model
        for g in m.random_groups:
            for sid in g.shape_ids:
                if sid not in m.shapes:
                    self.fail(f"Random {g.id}: unknown shape {sid}{self.known(m.shapes, 'shapes')}", g.line)
            if g.material_id not in m.materials:
                self.fail(f"Random {g.id}: unknown material {g.material_id}"
                          f"{self.known(m.materials, 'materials')}", g.line)
        for p in m.particles:
            if p.shape_id not in m.shapes:
                self.fail(f"Particle {p.id}: unknown shape {p.shape_id}{self.known(m.shapes, 'shapes')}", p.line)
            if p.material_id not in m.materials:
                self.fail(f"Particle {p.id}: unknown material {p.material_id}"
                          f"{self.known(m.materials, 'materials')}", p.line)
        for itf in m.interfaces:
            for mid in itf.materials or ():
                if mid not in m.materials:
                    self.fail(f"Interface {itf.id}: unknown material {mid}", itf.line)
        names = m.wall_names
        for s in m.steps:
            if isinstance(s, MoveWallStep) and s.wall not in names:
                known = f" (walls: {', '.join(names)})" if names else " (no walls defined)"
                self.fail(f"Step {s.id}: no wall named {s.wall!r}{known}", s.line)
        check_curved_walls(self, m)
        self.check_interfaces()

    @staticmethod
    def known(table: dict, what: str) -> str:
        return f" (defined {what}: {', '.join(map(str, sorted(table)))})" if table else f" (no {what} defined)"

    def check_interfaces(self) -> None:
        """Every pair is covered by an Interface, with the constants its law needs
        (:func:`~nurbsdem.dynamics.laws.interface.check_coverage`)."""
        from ..dynamics.laws.interface import check_coverage
        if not self.model.particle_materials():
            return
        check_coverage(self.model, self.fail, self.first_use)
        self.check_wall_materials()

    def check_wall_materials(self) -> None:
        """Box/Wall ``Material m``: defined, with a YoungModulus (a wall's material matters only
        to Hertz–Mindlin interfaces; walls without one are rigid)."""
        m = self.model
        named = [w for w in m.walls + m.curved_walls if w.material_id is not None]
        for w in named:
            if w.material_id not in m.materials:
                self.fail(f"wall {w.name}: unknown material {w.material_id}"
                          f"{self.known(m.materials, 'materials')}", w.line)
            if m.materials[w.material_id].young_modulus is None:
                self.fail(f"wall {w.name}: Material {w.material_id} needs a YoungModulus to be "
                          f"a wall material", w.line)

    def first_use(self, material: int) -> int:
        """Line of the first particle entry of that material."""
        lines = [g.line for g in self.model.random_groups if g.material_id == material]
        lines += [p.line for p in self.model.particles if p.material_id == material]
        return min(lines)


from .deck_curved import check_curved_walls, curved_entry, rotate_step  # noqa: E402  (it needs the model's classes only)

_HANDLERS: dict[tuple[str, str], Callable[[_Builder, Entry], None]] = {
    ("Environment", "Gravity"): _Builder.environment,
    ("Materials", "Material"): _Builder.material,
    ("Shapes", "Shape"): _Builder.shape,
    ("Particles", "Random"): _Builder.random,
    ("Particles", "Particle"): _Builder.particle,
    ("Walls", "Box"): _Builder.box,
    ("Walls", "Wall"): _Builder.wall,
    ("Walls", "Mesh"): lambda b, e: curved_entry(b, e, "mesh"),
    ("Walls", "Surface"): lambda b, e: curved_entry(b, e, "surface"),
    ("Contact", "Interface"): _Builder.interface,
    ("Steps", "Step"): _Builder.step,
}


def build_model(text: str, path: str) -> Model:
    """Parse deck text into a :class:`Model` (no particle placement).

    ``path`` locates errors and anchors relative paths. Raises :class:`InputError`.
    """
    try:
        entries = lex_deck(text)
        b = _Builder(path, text)
        order = ["Environment", "Materials", "Shapes", "Particles", "Walls", "Contact", "Steps"]
        for block in order:  # definitions before uses, whatever the deck's order
            for e in entries:
                if e.block == block:
                    _HANDLERS[(block, e.keyword)](b, e)
        b.output([e for e in entries if e.block == "Output"])
        b.check_references()
    except _LineError as exc:
        raise InputError(str(exc), path=path, line=exc.line) from None
    return b.model


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

"""Giraffe CAD files (multi-patch NURBS particle surfaces): reader and writer.

Giraffe (the authors' C++ solver) reads a particle's surface from a text file with one
record per patch (``NURBSMultipatchSurface::ReadCADFile``)::

    ID 1
    Subdivisions 2 2
    Connectivity 6 5 3 4
    UDim 5
    UOrder 4
    UKnotVector 0 0 0 0 0 1 1 1 1 1
    VDim 5
    VOrder 4
    VKnotVector 0 0 0 0 0 1 1 1 1 1
    Weights w_00 w_10 w_20 ... (UDim * VDim numbers)
    ControlPoints x_00 y_00 z_00  x_10 y_10 z_10 ... (3 * UDim * VDim numbers)
    ID 2
    ...

Interpretation (checked against Giraffe's reader, which allocates ``UDim + UOrder + 1``
knots and fills ``weights[i][j]`` in a loop over j (v) outside i (u)):

* ``UDim`` / ``VDim``: number of control points along u / v (n_u, n_v);
* ``UOrder`` / ``VOrder``: the polynomial **degree** p, q (despite the name);
* ``UKnotVector`` / ``VKnotVector``: the full clamped knot vectors, n + p + 1 numbers;
* ``Weights`` and ``ControlPoints``: u varies fastest, i.e. the k-th entry is (i, j) =
  (k mod n_u, k div n_u); control points are Euclidean (not multiplied by the weight);
* ``Subdivisions nu nv``: how many sub-patches Giraffe cuts the patch into for its
  bounding boxes; not used by nurbsdem (it is read, kept in :class:`GiraffeRecord`, and
  written back as given, default 1 1);
* ``Connectivity c0 c1 c2 c3``: the IDs of the neighbour patches across the edges u_min,
  u_max, v_min, v_max (0 = none, e.g. a pole). nurbsdem finds connectivity from the
  geometry itself; :func:`connectivity_mismatches` compares the file's list with it and the
  command line prints a warning for each difference. The writer stores the patch's own ID
  for a seam and 0 for a pole or an open edge.

The patches are returned in file order. The reader accepts any whitespace (including line
breaks anywhere) and ``//`` comments to the end of a line; numbers are read with Python's
``float`` (so ``1e-3``, ``.5`` and ``1E+3`` all work). Every error is an
:class:`~nurbsdem.errors.InputError` naming the file and line. Units: whatever the CAD file
uses; nurbsdem treats them as metres.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from ..errors import GeometryError, InputError
from ..geometry.kernel import MAX_DEGREE
from ..geometry.nurbs import Patch
from .shapefile import MAX_CONTROL_POINTS, check_patch_numbers, shape_or_input_error


@dataclass
class GiraffeRecord:
    """One patch record of a Giraffe CAD file.

    id: the record's ID; subdivisions: (nu, nv); connectivity: neighbour IDs across
    (u_min, u_max, v_min, v_max); patch: the NURBS patch; line: the line of its ``ID``.
    """

    id: int
    subdivisions: tuple[int, int]
    connectivity: tuple[int, int, int, int]
    patch: Patch
    line: int


def _clip(tok: str, n: int = 40) -> str:
    return tok if len(tok) <= n else tok[:n] + "..."


def _as_integer(tok: str) -> int | None:
    """The integer a token denotes (``6``, ``+6``, ``6.0``, ``6e0``), else None."""
    try:
        return int(tok) if len(tok) <= 30 else None
    except ValueError:
        pass
    try:
        x = float(tok)
    except ValueError:
        return None
    if math.isfinite(x) and x.is_integer() and abs(x) < 2 ** 53:
        return int(x)
    return None


#: Most control points along one direction of a patch, and in all (memory).
MAX_DIM = 10 ** 4


class _Tokens:
    """Whitespace-separated tokens with their line numbers; ``//`` starts a comment."""

    def __init__(self, text: str, path: str) -> None:
        self.path = path
        self.items: list[tuple[str, int]] = []
        for ln, line in enumerate(text.splitlines(), start=1):
            line = line.split("//", 1)[0]
            self.items.extend((tok, ln) for tok in line.split())
        self.pos = 0
        self.last_line = len(text.splitlines()) or 1

    def done(self) -> bool:
        return self.pos >= len(self.items)

    def line(self) -> int:
        if self.pos < len(self.items):
            return self.items[self.pos][1]
        return self.last_line

    def next(self, what: str) -> tuple[str, int]:
        if self.pos >= len(self.items):
            raise InputError(f"unexpected end of file: expected {what}", path=self.path,
                             line=self.last_line)
        tok = self.items[self.pos]
        self.pos += 1
        return tok

    def keyword(self, word: str) -> int:
        tok, ln = self.next(f"'{word}'")
        if tok != word:
            raise InputError(f"expected '{word}', got '{tok}'", path=self.path, line=ln)
        return ln

    def integer(self, what: str, lo: int = -2 ** 31, hi: int = 2 ** 31 - 1) -> int:
        """An integer token; like Giraffe's stream reader, ``6.0`` or ``6e0`` reads as 6.
        Values outside [lo, hi] are refused."""
        tok, ln = self.next(what)
        value = _as_integer(tok)
        if value is None:
            raise InputError(f"{what} must be an integer, got '{_clip(tok)}'", path=self.path,
                             line=ln)
        if not lo <= value <= hi:
            raise InputError(f"{what} must be between {lo} and {hi}, got {value}",
                             path=self.path, line=ln)
        return value

    def floats(self, n: int, what: str) -> np.ndarray:
        out = np.empty(n)
        for k in range(n):
            if self.pos >= len(self.items):
                raise InputError(f"unexpected end of file: {what} needs {n} numbers, got {k}",
                                 path=self.path, line=self.last_line)
            tok, ln = self.items[self.pos]
            try:
                out[k] = float(tok)
            except ValueError:
                raise InputError(f"{what} needs {n} numbers, got '{_clip(tok)}' at number "
                                 f"{k + 1}", path=self.path, line=ln) from None
            self.pos += 1
        return out


def read_giraffe(path: str | Path, warnings: list[str] | None = None) -> list[GiraffeRecord]:
    """Read every patch record of a Giraffe CAD file (format: module docstring).

    Lenient like Giraffe's own reader where that is harmless: integers may be written as
    reals (``6.0``), and text after the last complete record that does not start another
    record (``ID``) is ignored (a note is appended to ``warnings``).

    Raises :class:`InputError` (file and line) for unreadable files, syntax errors and bad
    patch data (degree, knots, weights, numbers nurbsdem cannot compute with).
    """
    from .shapefile import read_text_file

    path = str(path)
    text = read_text_file(path)
    tk = _Tokens(text, path)
    if tk.done():
        raise InputError("no patch records (expected 'ID ...')", path=path, line=1)
    records: list[GiraffeRecord] = []
    seen: dict[int, int] = {}
    while not tk.done():
        if records and tk.items[tk.pos][0] != "ID":
            if warnings is not None:
                tok, ln = tk.items[tk.pos]
                warnings.append(f"line {ln}: text after the last patch record ignored "
                                f"(starting with '{_clip(tok)}')")
            break
        line = tk.keyword("ID")
        pid = tk.integer("ID")
        if pid in seen:
            raise InputError(f"duplicate patch ID {pid} (first at line {seen[pid]})",
                             path=path, line=line)
        seen[pid] = line
        tk.keyword("Subdivisions")
        sub = (tk.integer("Subdivisions", 0), tk.integer("Subdivisions", 0))
        tk.keyword("Connectivity")
        con = tuple(tk.integer("Connectivity") for _ in range(4))
        dims = {}
        knots = {}
        for d in ("U", "V"):
            ln = tk.keyword(f"{d}Dim")
            n = tk.integer(f"{d}Dim", 1, MAX_DIM)
            ln_order = tk.keyword(f"{d}Order")
            p = tk.integer(f"{d}Order (the degree)")
            if not 1 <= p <= MAX_DEGREE:
                raise InputError(f"{d}Order (the degree) {p} is not supported: it must be "
                                 f"from 1 to {MAX_DEGREE}, the highest degree nurbsdem "
                                 f"evaluates", path=path, line=ln_order)
            if n < p + 1:
                raise InputError(f"{d}Dim = {n} control points is fewer than degree + 1 = {p + 1}",
                                 path=path, line=ln)
            tk.keyword(f"{d}KnotVector")
            knots[d] = tk.floats(n + p + 1, f"{d}KnotVector ({d}Dim + {d}Order + 1)")
            dims[d] = (n, p)
        (nu, p), (nv, q) = dims["U"], dims["V"]
        if nu * nv > MAX_CONTROL_POINTS:
            raise InputError(f"UDim x VDim = {nu * nv} control points are more than "
                             f"{MAX_CONTROL_POINTS:g}", path=path, line=line)
        tk.keyword("Weights")
        w = tk.floats(nu * nv, f"Weights (UDim * VDim = {nu * nv})")
        tk.keyword("ControlPoints")
        cp = tk.floats(3 * nu * nv, f"ControlPoints (3 * UDim * VDim = {3 * nu * nv})")
        # u fastest: entry k is (i, j) = (k % nu, k // nu)
        weights = w.reshape(nv, nu).T.copy()
        pts = cp.reshape(nv, nu, 3).transpose(1, 0, 2).copy()
        patch = Patch(p, q, knots["U"], knots["V"], pts, weights)
        try:
            patch.validate(path, len(records))
        except GeometryError as exc:
            raise InputError(exc.detail, path=path, line=line,
                             where=f"patch ID {pid}") from None
        records.append(GiraffeRecord(pid, sub, con, patch, line))  # type: ignore[arg-type]
    return records


def read_giraffe_patches(path: str | Path) -> list[Patch]:
    """The patches of a Giraffe CAD file, in file order."""
    return [r.patch for r in read_giraffe(path)]


def _num(x: float) -> str:
    """Shortest round-trip text of a float (``repr``), integers without '.0'."""
    x = float(x)
    if x.is_integer() and abs(x) < 1e15:
        return ("-" if math.copysign(1.0, x) < 0 and x == 0 else "") + str(int(x))
    return repr(x)


def giraffe_connectivity(patches: Sequence[Patch],
                         ids: Sequence[int]) -> list[tuple[int, int, int, int]]:
    """Giraffe connectivity lists (neighbour IDs; own ID on a seam; 0 on a pole or open
    edge) found from the geometry."""
    from ..geometry.connectivity import find_connectivity

    nbr = find_connectivity(patches).neighbours
    out = []
    for i in range(len(patches)):
        out.append(tuple(int(ids[j]) if j >= 0 else 0 for j in nbr[i, :, 0]))
    return out  # type: ignore[return-value]


def connectivity_mismatches(records: Sequence[GiraffeRecord]) -> list[str]:
    """Messages for each edge whose file connectivity differs from the geometry's."""
    from ..geometry.connectivity import EDGE_NAMES

    ids = [r.id for r in records]
    found = giraffe_connectivity([r.patch for r in records], ids)
    msgs = []
    for r, f in zip(records, found):
        for e in range(4):
            if r.connectivity[e] != f[e]:
                msgs.append(f"patch ID {r.id} (line {r.line}): Connectivity gives neighbour "
                            f"{r.connectivity[e]} across {EDGE_NAMES[e]}, the geometry gives "
                            f"{f[e]}; using the geometry")
    return msgs


def giraffe_text(patches: Sequence[Patch], ids: Sequence[int] | None = None,
                 subdivisions: Sequence[tuple[int, int]] | None = None,
                 connectivity: Sequence[tuple[int, int, int, int]] | None = None) -> str:
    """The Giraffe CAD text of a list of patches (IDs 1..P by default; connectivity from
    the geometry by default; subdivisions 1 1 by default)."""
    P = len(patches)
    ids = list(ids) if ids is not None else list(range(1, P + 1))
    if subdivisions is None:
        subdivisions = [(1, 1)] * P
    if connectivity is None:
        connectivity = giraffe_connectivity(patches, ids)
    lines = []
    for k, p in enumerate(patches):
        nu, nv = p.shape
        lines.append(f"ID {ids[k]}")
        lines.append("Subdivisions {} {}".format(*subdivisions[k]))
        lines.append("Connectivity {} {} {} {}".format(*connectivity[k]))
        lines.append(f"UDim {nu}")
        lines.append(f"UOrder {p.degree_u}")
        lines.append("UKnotVector " + " ".join(_num(t) for t in p.knots_u))
        lines.append(f"VDim {nv}")
        lines.append(f"VOrder {p.degree_v}")
        lines.append("VKnotVector " + " ".join(_num(t) for t in p.knots_v))
        lines.append("Weights")
        for j in range(nv):
            lines.append(" ".join(_num(p.weights[i, j]) for i in range(nu)))
        lines.append("ControlPoints")
        for j in range(nv):
            for i in range(nu):
                lines.append(" ".join(_num(c) for c in p.control_points[i, j]))
    return "\n".join(lines) + "\n"


def write_giraffe(path: str | Path, patches, **kwargs) -> None:
    """Write patches (or a Shape) as a Giraffe CAD file (atomically); keyword arguments as
    in :func:`giraffe_text`."""
    from .atomic import atomic_write_text

    patches = getattr(patches, "patches", patches)
    atomic_write_text(path, giraffe_text(patches, **kwargs))


def import_giraffe(path: str | Path, out: str | Path | None = None, name: str | None = None,
                   check: bool = True):
    """Read a Giraffe CAD file into a checked :class:`~nurbsdem.geometry.shape.Shape`
    (optionally written to the shape file ``out``).

    Returns (shape, warnings) where warnings are the connectivity differences.
    """
    from ..geometry.shape import Shape
    from .shapefile import save_shape

    notes: list[str] = []
    records = read_giraffe(path, notes)
    for r in records:
        check_patch_numbers(r.patch, str(path), f"patch ID {r.id}", r.line)
    shape = shape_or_input_error(
        lambda: Shape([r.patch for r in records], name=name if name is not None else Path(path).stem,
                      source=str(path), check=check), str(path))
    warnings = notes + connectivity_mismatches(records)
    if out is not None:
        save_shape(out, shape)
    return shape, warnings


__all__ = ["GiraffeRecord", "read_giraffe", "read_giraffe_patches", "giraffe_text",
           "write_giraffe", "import_giraffe", "connectivity_mismatches", "giraffe_connectivity"]


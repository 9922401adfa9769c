"""VTK XML unstructured grids (.vtu): zlib-compressed arrays appended as raw bytes, with the
compressed form of arrays that do not change between samples kept.

Why not meshio's writer
-----------------------
A sample of the paper example's particles holds 67 200 points; meshio compresses every array
of every sample and base64-encodes it, and three quarters of those bytes never change while the
bodies stay the same (the connectivity, cell offsets and types, particle and shape ids, patch
ids), on the one worker thread that competes with the LCP threads for the cores.
:class:`Reuse` keeps each such array's encoded bytes for as long as its owner's key (the
bodies' ids and shapes) stays the same, so only the points and velocities are compressed
again.  The arrays are stored in the file's ``AppendedData`` section as raw
bytes (``encoding="raw"``), each a UInt32 header of block count, block size, last block size
and compressed sizes followed by its zlib blocks of 32768 bytes: the layout of VTK's own
writer (``vtkXMLUnstructuredGridWriter`` in its default appended mode), read by ParaView and
meshio (tests).  Raw instead of base64 (meshio's ``format="binary"``, which earlier versions
wrote): a quarter smaller files and no encoding pass (a quarter of a particles sample's
writing time); the pieces are written one after the other, never joined.  The
points are stored in zlib's uncompressed blocks (:data:`POINTS_LEVEL`): float coordinates
hardly compress, and compressing them was most of what was left.
"""
from __future__ import annotations

import zlib
from typing import Callable, Hashable, Mapping, Sequence

import numpy as np

from .deflate import encode_repeated

#: uncompressed bytes per zlib block (meshio's and VTK's choice)
BLOCK = 32768
#: zlib level: 1 is ~4 x faster than the default 6 for files ~15 % larger
LEVEL = 1
#: the points' coordinates are stored (level 0: zlib's stored blocks): float32 coordinates
#: shrink by only ~24 % at level 1, for three quarters of a particles sample's writing time
POINTS_LEVEL = 0
#: VTK cell type codes of the cells the writers produce
CELL_TYPES = {"vertex": 1, "line": 3, "triangle": 5, "quad": 9}
_VTK_TYPE = {np.dtype(np.float32): "Float32", np.dtype(np.float64): "Float64",
             np.dtype(np.int32): "Int32", np.dtype(np.int64): "Int64",
             np.dtype(np.uint8): "UInt8"}


def encode(data: np.ndarray, level: int = LEVEL) -> list[bytes]:
    """The bytes of one appended DataArray, in pieces (written one after the other, never
    joined): its UInt32 header (block count, block size, last block's size, compressed
    sizes), then its zlib blocks."""
    raw = memoryview(np.ascontiguousarray(data).reshape(-1).view(np.uint8))
    blocks = [zlib.compress(raw[k:k + BLOCK], level) for k in range(0, len(raw), BLOCK)]
    last = len(raw) - (len(blocks) - 1) * BLOCK if blocks else 0
    header = np.array([len(blocks), BLOCK, last] + [len(b) for b in blocks], np.uint32)
    return [header.tobytes()] + blocks


#: an encoded array: its VTK type, number of components (0: a plain list) and pieces
Encoded = tuple[str, int, list[bytes]]


def _encoded(data: np.ndarray, level: int = LEVEL) -> Encoded:
    return _VTK_TYPE[data.dtype], (data.shape[1] if data.ndim == 2 else 0), encode(data, level)


class Repeated:
    """An array whose rows repeat: row k of ``values`` (n, ...) ``counts[k]`` times (a body's
    velocity at each of its points).  Written by :func:`nurbsdem.io.deflate.encode_repeated`
    without spelling the rows out; ``np.asarray`` gives the array."""

    def __init__(self, values: np.ndarray, counts: np.ndarray) -> None:
        self.values = np.asarray(values)
        self.counts = np.asarray(counts, np.int64)
        self.shape = (int(self.counts.sum()),) + self.values.shape[1:]
        self.ndim = len(self.shape)

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        a = np.repeat(self.values, self.counts, axis=0)
        return a if dtype is None else a.astype(dtype)

    def encoded(self) -> Encoded:
        """Its VTK type, components and pieces (floats as Float32, like :func:`_normalised`)."""
        v = _normalised(self.values)
        return (_VTK_TYPE[v.dtype], (v.shape[1] if v.ndim == 2 else 0),
                encode_repeated(v, self.counts, BLOCK))


class Reuse:
    """Encoded arrays that repeat from one sample to the next: :meth:`encoded` encodes the
    array ``name`` once per ``key`` (the caller's promise: the same key, the same array; it
    is built by ``make()`` only when needed).  Used by one thread at a time (a series'
    writer)."""

    def __init__(self, names: Sequence[str]) -> None:
        self.names = frozenset(names)
        self._key: Hashable = None
        self._encoded: dict[str, Encoded] = {}

    def encoded(self, key: Hashable, name: str, make: Callable[[], np.ndarray]) -> Encoded:
        if key != self._key:
            self._key, self._encoded = key, {}
        if name not in self._encoded:
            self._encoded[name] = _encoded(make())
        return self._encoded[name]


class _Appended:
    """The DataArray tags of a file and the pieces of its AppendedData they point to."""

    def __init__(self) -> None:
        self.parts: list[bytes] = []
        self.size = 0

    def tag(self, name: str, encoded: Encoded) -> str:
        vtk_type, comps, pieces = encoded
        n_comps = f' NumberOfComponents="{comps}"' if comps else ""
        offset = self.size
        self.parts += pieces
        self.size += sum(len(p) for p in pieces)
        return (f'<DataArray type="{vtk_type}" Name="{name}"{n_comps} format="appended" '
                f'offset="{offset}"/>\n')

    def section(self) -> list[bytes]:
        return [b'<AppendedData encoding="raw">\n_', *self.parts, b"\n</AppendedData>\n"]


def _normalised(data) -> np.ndarray:
    """float64 → float32 (what ParaView renders with), other dtypes as they are."""
    a = np.asarray(data)
    if a.dtype.kind == "f":
        return a.astype(np.float32)
    if a.dtype.kind in "iu" and a.dtype not in _VTK_TYPE:
        return a.astype(np.int64)
    return a


def _cell_rows(c) -> np.ndarray:
    """A block of cells as (n, k) point indices (a flat list: one point per cell)."""
    c = np.asarray(c, np.int64)
    if c.ndim == 2:
        return c
    return c.reshape(len(c), -1) if c.size else c.reshape(0, 1)


def _cell_arrays(cells: Sequence[tuple[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """VTK's connectivity, offsets and types of the cell blocks [(type, (n, k) ints)]."""
    if not cells:
        return {"connectivity": np.zeros(0, np.int64), "offsets": np.zeros(0, np.int64),
                "types": np.zeros(0, np.uint8)}
    blocks = [_cell_rows(c) for _, c in cells]
    return {"connectivity": np.concatenate([c.ravel() for c in blocks]),
            "offsets": np.cumsum(np.concatenate([np.full(len(c), c.shape[1], np.int64)
                                                 for c in blocks])),
            "types": np.concatenate([np.full(len(c), CELL_TYPES[t], np.uint8)
                                     for (t, _), c in zip(cells, blocks)])}


def vtu_parts(points: np.ndarray, cells: Sequence[tuple[str, np.ndarray]],
              point_data: Mapping[str, np.ndarray] | None = None,
              cell_data: Mapping[str, Sequence[np.ndarray]] | None = None,
              reuse: Reuse | None = None, key: Hashable = None) -> list[bytes]:
    """The file content of an unstructured grid, in pieces to be written one after the other:
    points (P, 3), cells [(type, (n, k) ints)], point data (P, ...) and cell data (one array
    per cell block, like meshio; point data may be :class:`Repeated`).  Floats are written as
    Float32.  With ``reuse``, the arrays it names ("connectivity", "offsets", "types" and data
    names) are taken from it for ``key`` (and not even built while it holds them)."""
    appended = _Appended()
    cell_arrays: dict[str, np.ndarray] = {}

    def tag(name: str, make: Callable[[], np.ndarray], data=None, section: str = "") -> str:
        # cached per section: a point array and a cell array may share a name (wall_id)
        if reuse is not None and name in reuse.names:
            return appended.tag(name, reuse.encoded(key, section + name, make))
        if isinstance(data, Repeated):
            return appended.tag(name, data.encoded())
        return appended.tag(name, _encoded(make()))

    def cell_array(name: str) -> np.ndarray:
        if not cell_arrays:
            cell_arrays.update(_cell_arrays(cells))
        return cell_arrays[name]

    pts = np.asarray(points, np.float32).reshape(-1, 3)
    n_cells = sum(len(c) for _, c in cells)
    out = ['<?xml version="1.0"?>\n'
           '<VTKFile type="UnstructuredGrid" version="0.1" byte_order="LittleEndian" '
           'header_type="UInt32" compressor="vtkZLibDataCompressor">\n<UnstructuredGrid>\n'
           f'<Piece NumberOfPoints="{len(pts)}" NumberOfCells="{n_cells}">\n<Points>\n',
           appended.tag("Points", _encoded(pts, POINTS_LEVEL)), '</Points>\n<Cells>\n',
           *(tag(name, lambda name=name: cell_array(name))
             for name in ("connectivity", "offsets", "types")), '</Cells>\n']
    if point_data:
        out.append("<PointData>\n")
        for name, data in point_data.items():
            out.append(tag(name, lambda data=data: _normalised(data), data))
        out.append("</PointData>\n")
    if cell_data:
        out.append("<CellData>\n")
        for name, blocks in cell_data.items():
            out.append(tag(name, lambda blocks=blocks: _normalised(
                np.concatenate([np.asarray(b) for b in blocks])), section="cell:"))
        out.append("</CellData>\n")
    out.append("</Piece>\n</UnstructuredGrid>\n")
    return ["".join(out).encode(), *appended.section(), b"</VTKFile>\n"]


def vtu_bytes(*args, **kwargs) -> bytes:
    """:func:`vtu_parts` joined: the whole file content."""
    return b"".join(vtu_parts(*args, **kwargs))

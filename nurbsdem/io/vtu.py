"""VTK XML unstructured grids (.vtu): binary inline arrays, zlib-compressed, as meshio writes
them, but with the compressed form of arrays that do not change between samples kept.

Why not meshio's writer
-----------------------
A sample of the paper example's particles holds 67 200 points; meshio compresses every array
of every sample, and three quarters of those bytes never change while the bodies stay the
same (the connectivity, cell offsets and types, particle and shape ids, patch ids): 57 ms per
sample, 650 samples, on the one worker thread that competes with the LCP threads for the two
cores.  :class:`Reuse` keeps each such array's encoded text for as long as its owner's key
(the bodies' ids and shapes) stays the same, so only the points and velocities are compressed
again.  The files are the VTK format meshio writes (``format="binary"``: a UInt32 header of
block count, block size, last block size and compressed sizes, then the zlib blocks of
32768 bytes, each part base64-encoded), read back by meshio and by ParaView (tests).  The
points are stored in zlib's uncompressed blocks (:data:`POINTS_LEVEL`): float coordinates
hardly compress, and compressing them was most of what was left.
"""
from __future__ import annotations

import base64
import zlib
from typing import Hashable, Mapping, Sequence

import numpy as np

#: uncompressed bytes per zlib block (meshio's and VTK's choice)
BLOCK = 32768
#: zlib level: 1 is ~4 x faster than the default 6 for files ~15 % larger
LEVEL = 1
#: the points' coordinates are stored (level 0: zlib's stored blocks): float32 coordinates
#: shrink by only ~24 % at level 1, for 28 ms of the 37 ms a particles sample took
POINTS_LEVEL = 0
#: VTK cell type codes of the cells the writers produce
CELL_TYPES = {"vertex": 1, "line": 3, "triangle": 5, "quad": 9}
_VTK_TYPE = {np.dtype(np.float32): "Float32", np.dtype(np.float64): "Float64",
             np.dtype(np.int32): "Int32", np.dtype(np.int64): "Int64",
             np.dtype(np.uint8): "UInt8"}


def encode(data: np.ndarray, level: int = LEVEL) -> str:
    """The text of a binary inline DataArray: base64(UInt32 header) + base64(zlib blocks)."""
    raw = np.ascontiguousarray(data).tobytes()
    blocks = [zlib.compress(raw[k:k + BLOCK], level) for k in range(0, len(raw), BLOCK)]
    last = len(raw) - (len(blocks) - 1) * BLOCK if blocks else 0
    header = np.array([len(blocks), BLOCK, last] + [len(b) for b in blocks], np.uint32)
    return (base64.b64encode(header.tobytes()).decode()
            + base64.b64encode(b"".join(blocks)).decode())


class Reuse:
    """Encoded arrays that repeat from one sample to the next: :meth:`text` encodes the array
    ``name`` once per ``key`` (the caller's promise: the same key, the same array).  Used by
    one thread at a time (a series' writer)."""

    def __init__(self, names: Sequence[str]) -> None:
        self.names = frozenset(names)
        self._key: Hashable = None
        self._text: dict[str, str] = {}

    def text(self, key: Hashable, name: str, data: np.ndarray) -> str:
        if key != self._key:
            self._key, self._text = key, {}
        if name not in self._text:
            self._text[name] = encode(data)
        return self._text[name]


def _data_array(name: str | None, data: np.ndarray, text: str) -> str:
    vtk_type = _VTK_TYPE[data.dtype]
    comps = f' NumberOfComponents="{data.shape[1]}"' if data.ndim == 2 else ""
    label = f' Name="{name}"' if name else ""
    return (f'<DataArray type="{vtk_type}"{label}{comps} format="binary">\n{text}\n'
            '</DataArray>\n')


def _normalised(data) -> np.ndarray:
    """float64 → float32 (what ParaView renders with), other dtypes as they are."""
    a = np.asarray(data)
    if a.dtype.kind == "f":
        return a.astype(np.float32)
    if a.dtype.kind in "iu" and a.dtype not in _VTK_TYPE:
        return a.astype(np.int64)
    return a


def vtu_text(points: np.ndarray, cells: Sequence[tuple[str, np.ndarray]],
             point_data: Mapping[str, np.ndarray] | None = None,
             cell_data: Mapping[str, Sequence[np.ndarray]] | None = None,
             reuse: Reuse | None = None, key: Hashable = None) -> str:
    """The file text of an unstructured grid: points (P, 3), cells [(type, (n, k) ints)],
    point data (P, ...) and cell data (one array per cell block, like meshio).  Floats are
    written as Float32.  With ``reuse``, the arrays it names ("connectivity", "offsets",
    "types" and data names) are taken from it for ``key``."""
    def text(name: str, data: np.ndarray) -> str:
        if reuse is not None and name in reuse.names:
            return reuse.text(key, name, data)
        return encode(data)

    pts = np.asarray(points, np.float32).reshape(-1, 3)
    conn = np.concatenate([np.asarray(c, np.int64).reshape(len(c), -1).ravel()
                           for _, c in cells]) if cells else np.zeros(0, np.int64)
    sizes = np.concatenate([np.full(len(c), np.asarray(c).reshape(len(c), -1).shape[1],
                                    np.int64) for _, c in cells]) if cells else np.zeros(0, np.int64)
    offsets = np.cumsum(sizes)
    types = np.concatenate([np.full(len(c), CELL_TYPES[t], np.uint8) for t, c in cells]) \
        if cells else np.zeros(0, np.uint8)
    out = ['<?xml version="1.0"?>\n'
           '<VTKFile type="UnstructuredGrid" version="0.1" byte_order="LittleEndian" '
           'header_type="UInt32" compressor="vtkZLibDataCompressor">\n<UnstructuredGrid>\n'
           f'<Piece NumberOfPoints="{len(pts)}" NumberOfCells="{len(types)}">\n<Points>\n',
           _data_array("Points", pts, encode(pts, POINTS_LEVEL)), '</Points>\n<Cells>\n',
           _data_array("connectivity", conn, text("connectivity", conn)),
           _data_array("offsets", offsets, text("offsets", offsets)),
           _data_array("types", types, text("types", types)), '</Cells>\n']
    if point_data:
        out.append("<PointData>\n")
        for name, data in point_data.items():
            a = _normalised(data)
            out.append(_data_array(name, a, text(name, a)))
        out.append("</PointData>\n")
    if cell_data:
        out.append("<CellData>\n")
        for name, blocks in cell_data.items():
            a = _normalised(np.concatenate([np.asarray(b) for b in blocks]))
            out.append(_data_array(name, a, text(name, a)))
        out.append("</CellData>\n")
    out.append("</Piece>\n</UnstructuredGrid>\n</VTKFile>\n")
    return "".join(out)

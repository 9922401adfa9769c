"""Export a shape: STL (tessellated triangles) and Rhino ``.3dm`` (NURBS surfaces).

* **STL** (binary): every patch tessellated on a parameter grid that follows its knot spans
  (:func:`~nurbsdem.geometry.tessellate.tessellate_shape`, ``n`` quads per direction), each
  quad split into two triangles along its shorter diagonal, vertices shared across patch
  edges merged (the edges coincide exactly, so the mesh is closed), triangles collapsed at
  poles dropped. Triangles are outward (counter-clockwise seen from outside), in metres.
  For other DEM codes and 3D printers.
* **3dm**: one NURBS surface object per patch (through the optional package rhino3dm,
  :func:`~nurbsdem.io.rhino.write_3dm`), so a particle can be edited in a CAD tool and
  imported again with ``nurbsdem import-3dm`` (the round trip is exact).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError

#: Export formats by file suffix.
FORMATS = {".stl": "stl", ".3dm": "3dm"}
#: Default quads per patch and direction for STL.
DEFAULT_STL_RESOLUTION = 24


def shape_triangles(shape, n: int = DEFAULT_STL_RESOLUTION) -> tuple[np.ndarray, np.ndarray]:
    """Closed triangle mesh of a shape: (vertices (M, 3) m, triangles (T, 3) int64), outward.

    Vertices that coincide (shared patch edges, poles) within 1e-9 x size are merged."""
    from ..geometry.tessellate import tessellate_shape

    pts, quads, _ = tessellate_shape(shape, n)
    size = float(np.linalg.norm(pts.max(0) - pts.min(0)))
    key = np.round(pts / max(1e-9 * size, 1e-300)).astype(np.int64)
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    verts = pts[first]
    q = inv.reshape(-1)[quads]
    a, b, c, d = q.T
    # split along the shorter diagonal
    ac = np.linalg.norm(verts[a] - verts[c], axis=1)
    bd = np.linalg.norm(verts[b] - verts[d], axis=1)
    use_ac = ac <= bd
    t1 = np.where(use_ac[:, None], np.stack([a, b, c], 1), np.stack([a, b, d], 1))
    t2 = np.where(use_ac[:, None], np.stack([a, c, d], 1), np.stack([b, c, d], 1))
    tris = np.concatenate([t1, t2])
    ok = (tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 0] != tris[:, 2])
    return verts, tris[ok].astype(np.int64)


def write_stl(path: str | Path, shape, n: int = DEFAULT_STL_RESOLUTION) -> tuple[int, int]:
    """Write a binary STL of the shape (atomically); returns (vertices, triangles)."""
    from .atomic import atomic_write_bytes

    verts, tris = shape_triangles(shape, n)
    v = verts[tris]                                          # (T, 3, 3)
    nrm = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1), 1e-300)[:, None]
    rec = np.zeros(len(tris), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["n"] = nrm
    rec["v"] = v
    name = (getattr(shape, "name", None) or "nurbsdem shape")
    header = f"nurbsdem STL: {name}"[:80].encode("ascii", "replace").ljust(80, b" ")
    data = header + np.uint32(len(tris)).tobytes() + rec.tobytes()
    atomic_write_bytes(path, data)
    return len(verts), len(tris)


def export_shape(shape, path: str | Path, n: int = DEFAULT_STL_RESOLUTION) -> str:
    """Export to the format named by the suffix of ``path`` (.stl or .3dm); returns a
    one-line description of what was written."""
    path = str(path)
    fmt = FORMATS.get(Path(path).suffix.lower())
    if fmt is None:
        raise InputError(f"unknown export format {Path(path).suffix!r}: expected .stl "
                         "(triangles) or .3dm (Rhino NURBS surfaces)", path=path)
    if fmt == "stl":
        nv, nt = write_stl(path, shape, n)
        return f"wrote {path}: STL, {nt} triangles, {nv} vertices ({n} x {n} quads per patch)"
    from .rhino import write_3dm
    write_3dm(path, shape.patches)
    return f"wrote {path}: Rhino 3dm, {len(shape.patches)} NURBS surfaces"

"""Triangle meshes of equipment from STL, OBJ or PLY files (read through trimesh).

:func:`read_wall_mesh` returns the vertices and triangles of a file, scaled, rotated and
moved as the deck or the API asks (``x = R(rotation) (scale · x_file) + position``), after
the checks that a contact search needs:

* the file exists, is a file, and trimesh reads one or more triangles from it;
* every vertex is finite (trimesh drops a NaN vertex from a PLY silently: the raw file is
  checked here first);
* no triangle is degenerate (its three vertices on a line: it has no normal);
* an edge shared by more than two triangles (a non-manifold fold) and a mesh with
  duplicate triangles are reported as warnings: each triangle still acts, but the file is
  usually not what its author meant.

trimesh is the library here because it reads the three formats (binary and ASCII STL,
OBJ with groups, PLY) robustly and is already a dependency (``nurbsdem fit``); its
``process`` step merges duplicate vertices so that edges are shared, which the contact
rule of :mod:`nurbsdem.contact.mesh_wall` (one contact per smooth or convex region) needs.

Lengths in metres (after ``scale``); the rotation is a rotation vector (rad).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError

#: the file types read as meshes
MESH_SUFFIXES = (".stl", ".obj", ".ply")


@dataclass(frozen=True)
class WallMesh:
    """What a mesh file gave: vertices (V,3) m, triangles (T,3), and one-line warnings."""

    vertices: np.ndarray
    faces: np.ndarray
    warnings: list[str] = field(default_factory=list)


def _rotation_matrix(rotvec) -> np.ndarray:
    """The rotation of a rotation vector (rad), by scipy's well-tested Rotation."""
    from scipy.spatial.transform import Rotation
    return Rotation.from_rotvec(np.asarray(rotvec, float)).as_matrix()


def _load(path: Path, where: str):
    """The file's mesh, read once: its raw vertices checked finite (trimesh's processing
    drops a NaN vertex of a PLY silently), then processed (duplicate vertices merged)."""
    import trimesh

    try:
        obj = trimesh.load(str(path), force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for unreadable files
        raise InputError(f"{where}: cannot read the mesh {path.name}: {exc}") from None
    if not isinstance(obj, trimesh.Trimesh) or len(obj.faces) == 0:
        raise InputError(f"{where}: {path.name} holds no triangles")
    verts = np.asarray(obj.vertices, float)
    bad = np.flatnonzero(~np.isfinite(verts).all(axis=1))
    if len(bad):
        raise InputError(f"{where}: {path.name}: vertex {int(bad[0])} is not finite "
                         f"({verts[bad[0]].tolist()}); {len(bad)} such vertices")
    obj.process()
    return obj


def _topology_warnings(faces: np.ndarray, name: str) -> list[str]:
    """Non-manifold edges and duplicate triangles, one line each."""
    warnings = []
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]),
                    axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    if np.any(counts > 2):
        warnings.append(f"{name}: {int(np.sum(counts > 2))} edges are shared by more than two "
                        f"triangles (a non-manifold fold); every triangle still acts")
    _, tri_counts = np.unique(np.sort(faces, axis=1), axis=0, return_counts=True)
    if np.any(tri_counts > 1):
        warnings.append(f"{name}: {int(np.sum(tri_counts - 1))} duplicate triangles; each "
                        f"acts once")
    return warnings


def read_wall_mesh(path: str | Path, scale: float = 1.0, position=(0.0, 0.0, 0.0),
                   rotation=(0.0, 0.0, 0.0), where: str | None = None) -> WallMesh:
    """The triangles of the mesh file ``path``, placed (module docstring).  ``where`` names
    the place that asked for the file in messages (a deck's ``file:line``); errors are
    :class:`~nurbsdem.errors.InputError`."""
    path = Path(path)
    where = where or str(path)
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise InputError(f"{where}: {path.name} is not a mesh file (expected "
                         f"{', '.join(MESH_SUFFIXES)})")
    if path.is_dir():
        raise InputError(f"{where}: {path} is a folder, not a mesh file")
    if not path.exists():
        raise InputError(f"{where}: no such mesh file: {path}")
    if not (np.isfinite(scale) and scale > 0):
        raise InputError(f"{where}: Scale must be positive, got {scale!r}")
    mesh = _load(path, where)
    vertices = np.asarray(mesh.vertices, float) * float(scale)
    faces = np.asarray(mesh.faces, np.int64)
    vertices = vertices @ _rotation_matrix(rotation).T + np.asarray(position, float)
    size = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))
    twice_area = np.linalg.norm(np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]],
                                         vertices[faces[:, 2]] - vertices[faces[:, 0]]), axis=1)
    tiny = np.flatnonzero(~(twice_area > 2e-12 * size * size))
    if len(tiny):
        raise InputError(f"{where}: {path.name}: triangle {int(tiny[0])} is degenerate (its "
                         f"vertices are on a line); {len(tiny)} such triangles")
    return WallMesh(vertices, faces, _topology_warnings(faces, path.name))


def size_mismatch(mesh_size: float, particle_size: float, where: str) -> str | None:
    """A one-line warning when a mesh is more than 1e3 times larger than the particles or
    smaller than them (sizes in m: bounding-box diagonal, particle diameter): the usual sign
    of a file drawn in millimetres read as metres, or the reverse; None otherwise."""
    ratio = mesh_size / particle_size
    if ratio > 1e3:
        return (f"{where}: the mesh is {ratio:.3g} times the particles' size: drawn in "
                f"millimetres? (Scale 0.001 reads millimetres as metres)")
    if ratio < 1.0:
        return (f"{where}: the mesh is smaller than one particle ({ratio:.3g} of its size): "
                f"drawn in metres where the particles are in millimetres, or the reverse?")
    return None

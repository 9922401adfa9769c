"""Triangle meshes of equipment from STL, OBJ or PLY files (read through trimesh).

:func:`read_wall_mesh` returns the vertices and triangles of a file, scaled, rotated and
moved as the deck or the API asks (``x = R(rotation) (scale · x_file) + position``), after
the checks that a contact search needs:

* the file exists, is a file, and trimesh reads one or more triangles from it;
* every vertex is finite (trimesh drops a NaN vertex from a PLY silently: the raw file is
  checked here first);
* duplicate vertices are merged without a word (an STL repeats each vertex in every triangle
  that has it; merged, neighbouring triangles share their edges);
* degenerate triangles (area below 1e-12 of the squared bounding-box diagonal: their vertices
  on a line, no normal) are dropped with a warning giving their count: they add no surface;
* an edge shared by more than two triangles (a non-manifold fold) is an error for a one-sided
  wall (``one_sided``: which side of the fold is the front is undefined there) and a warning
  for a two-sided shell, where each triangle still acts; duplicate triangles are a warning,
  and so, for a one-sided wall, are neighbouring triangles whose vertex orders make their
  fronts face opposite ways.

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


#: the meshes :func:`_load` read last: (resolved path, modification time ns, size) ->
#: (vertices, faces); a deck's mesh is read when the deck is parsed, when the solver builds
#: the wall and when the writers draw it, the same file each time
_LOADED: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
#: how many meshes :data:`_LOADED` keeps (a deck reads each of its meshes at three places in
#: turn; a mesh of 10^6 triangles keeps about 36 MB)
LOADED_KEPT = 4


def _load(path: Path, where: str) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (V,3), faces (T,3) int64) of the file's mesh (copies of those kept from an
    earlier read of the unchanged file, :data:`_LOADED`)."""
    stat = path.stat()
    key = (str(path.resolve()), stat.st_mtime_ns, stat.st_size)
    if key not in _LOADED:
        mesh = _read(path, where)
        if len(_LOADED) >= LOADED_KEPT:
            _LOADED.pop(next(iter(_LOADED)))
        _LOADED[key] = (np.array(mesh.vertices, float), np.array(mesh.faces, np.int64))
    vertices, faces = _LOADED[key]
    return vertices.copy(), faces.copy()


def _read(path: Path, where: str):
    """The file's mesh, read: its raw vertices checked finite (trimesh's processing drops a
    NaN vertex of a PLY silently), then processed (duplicate vertices merged)."""
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


def edge_use(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(edges (E,2) with the lower vertex first, how many triangles have each edge (E,),
    how many of them run along it from the lower vertex to the higher (E,)) of triangles
    ``faces`` (T,3): a closed, consistently oriented surface has every count 2 and every
    forward count 1."""
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    forward = directed[:, 0] < directed[:, 1]
    edges, inverse, counts = np.unique(np.sort(directed, axis=1), axis=0, return_inverse=True,
                                       return_counts=True)
    return edges, counts, np.bincount(inverse.ravel(), weights=forward, minlength=len(edges))


def _topology_warnings(faces: np.ndarray, name: str, one_sided: bool, where: str) -> list[str]:
    """Non-manifold edges (an InputError for a one-sided wall), duplicate triangles and, for a
    one-sided wall, neighbours whose fronts face opposite ways: one line each."""
    warnings = []
    _, counts, forward = edge_use(faces)
    folds = int(np.sum(counts > 2))
    if folds and one_sided:
        raise InputError(f"{where}: {name}: {folds} edges are shared by more than two "
                         f"triangles (a non-manifold fold): a one-sided wall needs a front side, "
                         f"which such a fold does not have; repair the file or make the wall "
                         f"two-sided (OneSided no)")
    if folds:
        warnings.append(f"{name}: {folds} edges are shared by more than two triangles (a "
                        f"non-manifold fold); every triangle still acts")
    _, tri_counts = np.unique(np.sort(faces, axis=1), axis=0, return_counts=True)
    if np.any(tri_counts > 1):
        warnings.append(f"{name}: {int(np.sum(tri_counts - 1))} duplicate triangles; each "
                        f"acts once")
    flipped = int(np.sum((counts == 2) & (forward != 1)))
    if one_sided and flipped:
        warnings.append(f"{name}: {flipped} edges join triangles whose fronts (vertex order) "
                        f"face opposite ways; a one-sided wall acts on each triangle's front "
                        f"only, so part of it faces away from the rest")
    return warnings


def read_wall_mesh(path: str | Path, scale: float = 1.0, position=(0.0, 0.0, 0.0),
                   rotation=(0.0, 0.0, 0.0), where: str | None = None,
                   one_sided: bool = False) -> WallMesh:
    """The triangles of the mesh file ``path``, placed (module docstring), for a one-sided
    wall when ``one_sided``.  ``where`` names the place that asked for the file in messages
    (a deck's ``file:line``); errors are :class:`~nurbsdem.errors.InputError`."""
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
    vertices, faces = _load(path, where)
    vertices = vertices * float(scale)
    vertices = vertices @ _rotation_matrix(rotation).T + np.asarray(position, float)
    size = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))
    twice_area = np.linalg.norm(np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]],
                                         vertices[faces[:, 2]] - vertices[faces[:, 0]]), axis=1)
    keep = twice_area > 2e-12 * size * size
    warnings = []
    if not keep.all():
        if not keep.any():
            raise InputError(f"{where}: {path.name}: all its {len(faces)} triangles are "
                             f"degenerate (their vertices are on a line): no surface")
        warnings.append(f"{path.name}: {int(np.sum(~keep))} degenerate triangles (zero area, "
                        f"their vertices on a line) dropped")
        faces = faces[keep]
        used = np.unique(faces)
        renumber = np.full(len(vertices), -1, np.int64)
        renumber[used] = np.arange(len(used))
        vertices, faces = vertices[used], renumber[faces]
    warnings += _topology_warnings(faces, path.name, one_sided, where)
    return WallMesh(vertices, faces, warnings)


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

"""The deck's mesh and surface walls (``Walls`` block, ``Mesh`` and ``Surface`` entries) and
their geometry for the solver.

``Mesh ID Name n File f.stl [Scale s] [Position x y z] [Rotation rx ry rz] [Material m]
[OneSided yes|no]`` and ``Surface ID Name n File f.yaml [Position x y z] [Rotation rx ry rz]
[Material m]`` make a :class:`~nurbsdem.model.CurvedWallSpec`; the file is read at parse time
(so that a missing or broken file is reported at its deck line); a surface file's patches are
kept for the solver (:func:`curved_wall_geometry`) and the checks until the file changes.
Placement: ``x_world = R(rotation) (scale x_file) + position``, rotation a rotation vector
(rad).  ``MoveWall NAME Displacement`` steps translate them as they do flat walls, ``MoveWall
NAME Rotate`` steps (:func:`rotate_step`) turn them (and translate them too with a
``Displacement``); :func:`curved_tessellation` draws them in ``walls.pvd``.
"""
from __future__ import annotations

import functools
import logging
import weakref
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..errors import InputError
from ..model import CurvedWallSpec


def _resolve(base: Path, source: str) -> Path:
    return Path(source) if Path(source).is_absolute() else base / source


@functools.lru_cache(maxsize=16)
def _file_patches(path: str, mtime_ns: int, size: int) -> tuple:
    """The patches of a shape file as read (the file's time and size in the key: the parse,
    the checks and the solver read a file once between its edits)."""
    from .shapefile import read_patches
    return tuple(read_patches(Path(path))[0])


def surface_patches(spec: CurvedWallSpec, where: str) -> list:
    """The placed patches of a ``Surface`` wall's shape file (InputError naming ``where``)."""
    from .meshfile import _rotation_matrix
    path = spec.path
    if path is None or not path.is_file():
        raise InputError(f"{where}: no such surface file: {path}")
    try:
        st = path.stat()
        patches = _file_patches(str(path), st.st_mtime_ns, st.st_size)
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from None
    if not patches:
        raise InputError(f"{where}: {path.name} holds no patches")
    R = _rotation_matrix(spec.rotation)
    return [p.transformed(R, np.asarray(spec.position, float)) for p in patches]


def mesh_triangles(spec: CurvedWallSpec, where: str):
    """The placed :class:`~nurbsdem.io.meshfile.WallMesh` of a ``Mesh`` wall (one-sided as the
    wall is: a non-manifold edge is an error then)."""
    from .meshfile import read_wall_mesh
    return read_wall_mesh(spec.path, spec.scale, spec.position, spec.rotation, where=where,
                          one_sided=spec.one_sided)


def _mesh_geometry(spec: CurvedWallSpec, where: str):
    """The mesh's triangle grid (:func:`~nurbsdem.contact.mesh_wall.build_mesh_wall`)."""
    from ..contact.mesh_wall import build_mesh_wall
    mesh = mesh_triangles(spec, where)
    return build_mesh_wall(mesh.vertices, mesh.faces, not spec.one_sided, source=where)


def _surface_geometry(spec: CurvedWallSpec, where: str):
    """The surface's patch tables (:func:`~nurbsdem.contact.surface_wall.build_surface_wall`)."""
    from ..contact.surface_wall import build_surface_wall
    return build_surface_wall(surface_patches(spec, where))


def _mesh_warnings(spec: CurvedWallSpec, where: str) -> list[str]:
    return list(mesh_triangles(spec, where).warnings)


def _surface_warnings(spec: CurvedWallSpec, where: str) -> list[str]:
    surface_patches(spec, where)
    return []


def _mesh_triangles(spec: CurvedWallSpec, where: str, resolution: int) -> tuple:
    mesh = mesh_triangles(spec, where)
    return mesh.vertices, mesh.faces


def _surface_triangles(spec: CurvedWallSpec, where: str, resolution: int) -> tuple:
    from ..geometry.tessellate import tessellate_patch
    pts, tris, off = [], [], 0
    for patch in surface_patches(spec, where):
        p, quads = tessellate_patch(patch, resolution)
        q = np.asarray(quads, np.int64) + off
        pts.append(np.asarray(p, float))
        tris += [q[:, [0, 1, 2]], q[:, [0, 2, 3]]]
        off += len(p)
    return np.concatenate(pts), np.concatenate(tris)


@dataclass(frozen=True)
class CurvedWallFile:
    """How a deck (and :class:`~nurbsdem.simulation.Simulation`) gives one kind of curved wall
    (:mod:`nurbsdem.contact.wall_kinds`, whose ``name`` is its
    :attr:`~nurbsdem.model.CurvedWallSpec.kind`): its ``Walls`` entry ``keyword``, the keys
    it takes beside ``Name File Position Rotation Material``, and, from its file (``where``
    names the wall in errors): ``geometry`` (the kind's geometry in the world at rest),
    ``warnings`` (the file read once: its warnings) and ``triangles`` (points (P,3) m,
    triangles (T,3) for ``walls.pvd``, curved patches cut into ``resolution`` quads per
    direction)."""

    name: str
    keyword: str
    keys: frozenset
    geometry: Callable[[CurvedWallSpec, str], Any]
    warnings: Callable[[CurvedWallSpec, str], list]
    triangles: Callable[[CurvedWallSpec, str, int], tuple]


#: the curved wall kinds' files, by :attr:`~nurbsdem.model.CurvedWallSpec.kind`
CURVED_WALL_FILES = {f.name: f for f in (
    CurvedWallFile("mesh", "Mesh", frozenset({"Scale", "OneSided"}), _mesh_geometry,
                   _mesh_warnings, _mesh_triangles),
    CurvedWallFile("surface", "Surface", frozenset(), _surface_geometry, _surface_warnings,
                   _surface_triangles))}


def curved_wall_geometry(spec: CurvedWallSpec, where: str):
    """(kind code, geometry) of a wall for :class:`~nurbsdem.contact.curved_walls.CurvedWall`:
    its kind's geometry in the world at rest (a mesh's triangle grid, a surface's patch
    tables)."""
    from ..contact.wall_kinds import kind_named
    return kind_named(spec.kind).code, CURVED_WALL_FILES[spec.kind].geometry(spec, where)


def curved_entry(builder, e, kind: str) -> None:
    """A curved wall's entry of the Walls block (``Mesh``: kind ``"mesh"``, ``Surface``:
    ``"surface"``, :data:`CURVED_WALL_FILES`)."""
    label = f"{e.keyword} {e.id}"
    keys = {"Name", "File", "Position", "Rotation", "Material"} | CURVED_WALL_FILES[kind].keys
    builder.only(e, keys, f"a {e.keyword} wall")
    builder.require(e, "File")
    scale = float(e.get("Scale", 1.0))
    builder.positive(e, "Scale", scale)
    spec = CurvedWallSpec(e.id, e.get("Name", f"wall{e.id}"), kind, e.get("File"),
                          path=_resolve(builder.base, e.get("File")), scale=scale,
                          position=np.asarray(e.get("Position", np.zeros(3)), float),
                          rotation=np.asarray(e.get("Rotation", np.zeros(3)), float),
                          material_id=e.get("Material"), one_sided=bool(e.get("OneSided", False)),
                          line=e.line)
    try:
        for warning in _read_check(spec, label):
            logging.getLogger("nurbsdem").warning("%s:%d: %s", builder.model.path, e.line,
                                                  warning)
    except InputError as exc:
        builder.fail(str(exc), e.line)
    builder.add_curved_wall(spec, label)


def _read_check(spec: CurvedWallSpec, label: str) -> list[str]:
    """Read the wall's file once (errors at the deck line); its warnings."""
    return CURVED_WALL_FILES[spec.kind].warnings(spec, label)


def sphere_radii(model, shape_ids) -> tuple[np.ndarray, np.ndarray]:
    """(radius (N,) m, is an exact sphere centred on its centroid (N,) bool) of particles of
    the shapes ``shape_ids``, from :func:`~nurbsdem.geometry.analytic.exact_sphere` (once
    per shape: a run with inlets or outlets asks at each exchange of particles)."""
    ids = np.asarray(shape_ids, np.int64).reshape(-1)
    kinds, which = np.unique(ids, return_inverse=True)
    radius, spheres = np.zeros(len(kinds)), np.zeros(len(kinds), bool)
    for k, sid in enumerate(kinds.tolist()):
        entry = model.shapes[sid]
        found = _exact_sphere(entry.shape)
        radius[k] = found[1] if found is not None else 0.0
        spheres[k] = found is not None and np.allclose(found[0], entry.centroid, rtol=0,
                                                       atol=1e-9 * found[1])
    return radius[np.ravel(which)], spheres[np.ravel(which)]


#: shape -> :func:`~nurbsdem.geometry.analytic.exact_sphere` of it (a shape does not change)
_SPHERES: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def _exact_sphere(shape):
    """:func:`~nurbsdem.geometry.analytic.exact_sphere` of ``shape``, found once per shape."""
    from ..geometry.analytic import exact_sphere
    if shape not in _SPHERES:
        _SPHERES[shape] = exact_sphere(shape)
    return _SPHERES[shape]


def check_curved_walls(builder, model) -> None:
    """Cross-checks of a deck's mesh and surface walls: only they turn, and their
    ``ToContact`` needs a ``Direction`` (a flat wall's default is its normal)."""
    from ..model import MoveWallStep
    curved = {w.name for w in model.curved_walls}
    for s in model.steps:
        if isinstance(s, MoveWallStep) and s.rotate and s.wall not in curved:
            builder.fail(f"Step {s.id}: MoveWall {s.wall} Rotate: only mesh and surface walls "
                         f"turn (flat walls translate: Displacement)", s.line)
    if not model.curved_walls:
        return
    for s in model.steps:
        if (isinstance(s, MoveWallStep) and s.wall in curved and s.to_contact
                and s.direction is None):
            builder.fail(f"Step {s.id}: MoveWall {s.wall} ToContact: a mesh or surface wall "
                         f"needs a Direction (it has no normal)", s.line)


def rotate_step(builder, e, name: str):
    """``Step ID MoveWall NAME Rotate AngularVelocity wx wy wz Center cx cy cz [Displacement dx
    dy dz] Duration T TimeStep DT [Damping ..] [Accuracy ..] [Safety ..]``: a
    :class:`~nurbsdem.model.MoveWallStep` that turns a mesh or surface wall at a constant
    angular velocity (rad/s) about a point (m), which translates with the wall by the
    displacement (m, at constant velocity over the step) when one is given."""
    from ..model import MoveWallStep
    builder.only(e, {"MoveWall", "Rotate", "AngularVelocity", "Center", "Displacement",
                     "Duration", "TimeStep", "Damping", "Accuracy", "Safety"}, "MoveWall Rotate")
    builder.require(e, "AngularVelocity", "Duration", "TimeStep")
    dur, dt = builder.timing(e)
    if not np.linalg.norm(e.get("AngularVelocity")) > 0:
        builder.fail(f"Step {e.id}: AngularVelocity must not be zero", e.line)
    damping = builder.damping(e)
    accuracy = builder.optional_positive(e, "Accuracy")
    safety = builder.optional_positive(e, "Safety")
    return MoveWallStep(e.id, e.line, wall=name, rotate=True,
                        angular_velocity=np.asarray(e.get("AngularVelocity"), float),
                        center=np.asarray(e.get("Center", np.zeros(3)), float),
                        displacement=e.get("Displacement"), duration=dur, time_step=dt, damping=damping, accuracy=accuracy,
                        safety=safety)


def curved_tessellation(model, resolution: int = 16) -> list:
    """[(wall id, points (P,3) m, triangles (T,3))] of the model's mesh and surface walls at
    rest, for ``walls.pvd``: a mesh's own triangles; a surface's patches tessellated
    (``resolution`` quads per direction, each cut into two triangles)."""
    out = []
    for w in model.curved_walls:
        where = f"{model.path}:{w.line}" if w.line else w.name
        out.append((w.id, *CURVED_WALL_FILES[w.kind].triangles(w, where, resolution)))
    return out

"""Result writers. File names are fixed so that scripts can rely on them.

In the output directory (``Output Directory``, default ``results`` next to the deck)::

    particles.pvd  walls.pvd  contacts.pvd     ParaView time collections of ...
    vtk/particles_000000.vtu ...               ... one .vtu per sample (zlib, raw: io/vtu.py)
    monitors/energy.csv                        time,kinetic,potential,elastic,dissipated,
                                               external_work,mechanical,balance_error
    monitors/contacts.csv                      time,monitored,active,degenerated,failed
    monitors/hertz.csv (Hertz-Mindlin runs)    time,active,fallback_radius,radius_min,radius_median,radius_max,stiffness_normal_max
    monitors/wall_<name>.csv                   time,displacement_x,displacement_y,
                                               displacement_z,reaction_x,reaction_y,reaction_z
    results.h5                                 every sample's body states (see ResultsWriter)

Crash safety: every .vtu, the .pvd files and results.h5 are replaced atomically (temporary
file, fsync, rename), so a run killed at any moment leaves each of them complete (old or
new) or absent. CSV rows are appended and flushed one whole line at a time; on a restart
(``restart_time=t``) every writer drops what lies after t (samples, rows, an incomplete last
line) and carries on, so the files continue seamlessly from the checkpoint.

A fresh start (``restart_time=None``) empties the series, monitors and results.h5.

Typical use by the solver (see :class:`OutputWriters`)::

    out = OutputWriters(model, restart_time=None)
    out.paraview.write(t, bodies, wall_displacement=dW, contacts=c)   # every VTK Every
    out.monitors.energy(t, kinetic=..., potential=..., elastic=..., dissipated=...,
                        external_work=...)                              # every Monitors Every
    out.monitors.contacts(t, monitored, active, degenerated, failed)
    out.monitors.wall("lid", t, displacement, reaction)
    out.results.append(t, bodies)                                       # every Results Every
    out.checkpoint(save, *args)   # results.h5 flushed, CSVs fsynced, then save(*args)
    out.close()
"""
from __future__ import annotations

import errno
from contextlib import contextmanager, nullcontext
import math
import os
import shutil
from time import monotonic as time_now
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import TYPE_CHECKING, Any, Hashable, Mapping, Sequence

import numpy as np

from ..geometry.rotation import place_points_into
from . import lock as output_lock
from .background import BackgroundWriter
from .atomic import (atomic_write_bytes, atomic_write_text, ensure_space,
                     remove_stale_temporaries, write_hdf5_atomically)
from . import restartcheck
from .vtu import Repeated, Reuse, vtu_parts

if TYPE_CHECKING:  # pragma: no cover
    from ..geometry.nurbs import Patch
    from ..geometry.shape import Shape
    from ..model import Bodies, Model, WallSpec

#: the .pvd files are rewritten when this old (s of wall time), and at every checkpoint and
#: the end of the run: ParaView opened on a running case sees samples at most this late, a
#: killed run's .pvd lists every sample up to its last checkpoint (a restart removes later
#: .vtu files)
PVD_INTERVAL = 1.0

#: Column names of the monitor files (fixed).
ENERGY_COLUMNS = ("time", "kinetic", "potential", "elastic", "dissipated", "external_work",
                  "mechanical", "balance_error")
CONTACT_COLUMNS = ("time", "monitored", "active", "degenerated", "failed")
HERTZ_COLUMNS = ("time", "active", "fallback_radius", "radius_min", "radius_median",
                 "radius_max", "stiffness_normal_max")
WALL_COLUMNS = ("time", "displacement_x", "displacement_y", "displacement_z",
                "reaction_x", "reaction_y", "reaction_z")
#: Series names (``<name>.pvd``, ``vtk/<name>_NNNNNN.vtu``).
SERIES = ("particles", "walls", "contacts")
RESULTS_NAME = "results.h5"
MONITOR_DIR = "monitors"
VTK_DIR = "vtk"

#: arrays of each series that stay the same while its bodies do (encoded once: io/vtu.py)
REUSED = {"particles": ("connectivity", "offsets", "types", "particle_id", "shape_id",
                        "patch_id"),
          "walls": ("connectivity", "offsets", "types", "wall_id")}


def _time_tol(t: float) -> float:
    """Tolerance (s) for comparing sample times with a restart time."""
    return 1e-9 * max(1.0, abs(t))


_float_repr = float.__repr__


def _fmt(x: Any) -> str:
    """A CSV field: integers as integers, floats by repr (shortest exact round trip)."""
    if isinstance(x, float):            # Python and NumPy floats (float.__repr__: no "np.")
        return float.__repr__(x)
    if isinstance(x, (int, np.integer)) and not isinstance(x, bool):
        return str(int(x))
    return repr(float(x))


# ---------------------------------------------------------------------------- tessellation


def tessellate(patch: "Patch", n: int) -> tuple[np.ndarray, np.ndarray]:
    """Points (M, 3) and quads (K, 4) of a patch (n quads per direction, about)."""
    try:
        from ..geometry.tessellate import tessellate_patch
    except ImportError:  # pragma: no cover - local uniform grid fallback
        return _grid_tessellation(patch, n)
    return tessellate_patch(patch, n)


def _grid_tessellation(patch: "Patch", n: int) -> tuple[np.ndarray, np.ndarray]:
    u0, u1, v0, v1 = patch.domain
    U, V = np.meshgrid(np.linspace(u0, u1, n + 1), np.linspace(v0, v1, n + 1), indexing="ij")
    pts = patch.points(U, V).reshape(-1, 3)
    m = n + 1
    i, j = (a.ravel() for a in np.meshgrid(np.arange(n), np.arange(n), indexing="ij"))
    quads = np.stack([i * m + j, (i + 1) * m + j, (i + 1) * m + j + 1, i * m + j + 1], 1)
    return pts, quads.astype(np.int64)


def tessellate_patches(patches: Sequence["Patch"], n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points (M, 3), quads (K, 4) and the patch index of each quad (K,) of several patches."""
    P, Q, ids = [], [], []
    off = 0
    for ip, p in enumerate(patches):
        pts, quads = tessellate(p, n)
        P.append(np.asarray(pts, float))
        Q.append(np.asarray(quads, np.int64) + off)
        ids.append(np.full(len(quads), ip, np.int64))
        off += len(pts)
    if not P:
        return np.zeros((0, 3)), np.zeros((0, 4), np.int64), np.zeros(0, np.int64)
    return np.concatenate(P), np.concatenate(Q), np.concatenate(ids)


# ---------------------------------------------------------------------------- vtu files


def _empty_vtu(point_data: Mapping[str, int]) -> str:
    """An UnstructuredGrid with no points (meshio cannot write one that it can read back).
    point_data: name -> number of components (declared, empty)."""
    arrays = "".join(f'<DataArray type="Float64" Name="{name}" NumberOfComponents="{k}" '
                     f'format="ascii"></DataArray>\n' for name, k in point_data.items())
    return ('<?xml version="1.0"?>\n'
            '<VTKFile type="UnstructuredGrid" version="0.1" byte_order="LittleEndian">\n'
            '<UnstructuredGrid>\n<Piece NumberOfPoints="0" NumberOfCells="0">\n'
            '<Points>\n<DataArray type="Float64" NumberOfComponents="3" format="ascii">'
            '</DataArray>\n</Points>\n<Cells>\n'
            '<DataArray type="Int64" Name="connectivity" format="ascii"></DataArray>\n'
            '<DataArray type="Int64" Name="offsets" format="ascii"></DataArray>\n'
            '<DataArray type="UInt8" Name="types" format="ascii"></DataArray>\n</Cells>\n'
            f'<PointData>\n{arrays}</PointData>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n')


def write_vtu(path: str | Path, points: np.ndarray, cells: list[tuple[str, np.ndarray]],
              point_data: Mapping[str, np.ndarray] | None = None,
              cell_data: Mapping[str, list[np.ndarray]] | None = None,
              reuse: Reuse | None = None, key: Hashable = None) -> None:
    """Write an unstructured grid atomically (:mod:`nurbsdem.io.vtu`: float32 points and
    data, zlib; ``reuse``/``key``: arrays encoded once for as long as ``key`` holds)."""
    point_data = dict(point_data or {})
    points = np.asarray(points, float).reshape(-1, 3)
    if points.shape[0] == 0:
        comps = {k: (1 if np.ndim(v) < 2 else int(np.shape(v)[1])) for k, v in point_data.items()}
        atomic_write_text(path, _empty_vtu(comps))
        return
    atomic_write_bytes(path, vtu_parts(points, cells, point_data, cell_data, reuse, key))


def pvd_text(entries: Sequence[tuple[float, str]]) -> str:
    """The XML of a ParaView collection of (time, relative file) entries."""
    lines = ['<?xml version="1.0"?>',
             '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
             "  <Collection>"]
    for t, f in entries:
        lines.append(f'    <DataSet timestep="{float(t)!r}" group="" part="0" file="{f}"/>')
    lines += ["  </Collection>", "</VTKFile>", ""]
    return "\n".join(lines)


def read_pvd(path: str | Path) -> list[tuple[float, str]]:
    """The (time, file) entries of a .pvd file (files relative to its folder)."""
    from ..errors import InputError
    try:
        root = ET.parse(str(path)).getroot()
        return [(float(ds.get("timestep")), str(ds.get("file"))) for ds in root.iter("DataSet")]
    except (ET.ParseError, TypeError, ValueError, UnicodeDecodeError) as exc:
        raise InputError(f"not a readable ParaView collection ({' '.join(str(exc).split())}); "
                         f"move it away to continue (its series restarts)", path=str(path)) from None


class PvdSeries:
    """One time series ``<outdir>/<name>.pvd`` of ``<outdir>/vtk/<name>_NNNNNN.vtu`` files.

    restart_time: ``None`` for a fresh series (old files of this name are removed), else
    the entries after that time (s) are dropped (and their files deleted).
    background: a :class:`BackgroundWriter` that writes the samples (None: at once).
    """

    def __init__(self, outdir: str | Path, name: str, restart_time: float | None = None,
                 background: BackgroundWriter | None = None,
                 reuse: Sequence[str] = ()) -> None:
        self.outdir = Path(outdir)
        self.name = name
        self.background = background
        #: the arrays of this series that repeat while a sample's ``key`` does (used by the
        #: one thread that writes the series)
        self.reuse = Reuse(reuse) if reuse else None
        self.pvd = self.outdir / f"{name}.pvd"
        self.vtkdir = self.outdir / VTK_DIR
        self.vtkdir.mkdir(parents=True, exist_ok=True)
        self.entries: list[tuple[float, str]] = []
        if restart_time is not None and self.pvd.exists():
            kept = [(t, f) for t, f in read_pvd(self.pvd) if t <= restart_time + _time_tol(restart_time)]
            keep_files = {f for _, f in kept}
            for _, f in read_pvd(self.pvd):
                if f not in keep_files:
                    (self.outdir / f).unlink(missing_ok=True)
            self.entries = kept
        else:
            for old in self.vtkdir.glob(f"{name}_*.vtu"):
                old.unlink()
        self._next = 1 + max((self._index(f) for _, f in self.entries), default=-1)
        for late in self.vtkdir.glob(f"{name}_*.vtu"):   # written after the last .pvd
            if self._index(f"{VTK_DIR}/{late.name}") >= self._next:
                late.unlink()
        atomic_write_text(self.pvd, pvd_text(self.entries))
        self._unlisted = 0          # samples written since the .pvd was, and when it was
        self._indexed_at = time_now()

    def _index(self, rel: str) -> int:
        stem = Path(rel).stem
        try:
            return int(stem.rsplit("_", 1)[1])
        except (IndexError, ValueError):
            return len(self.entries)

    def next_path(self) -> tuple[Path, str]:
        """(absolute path, path relative to outdir) of the next sample's .vtu."""
        rel = f"{VTK_DIR}/{self.name}_{self._next:06d}.vtu"
        return self.outdir / rel, rel

    def commit(self, time: float, rel: str) -> None:
        """Record a written sample; the .pvd is rewritten (atomically) when it is
        :data:`PVD_INTERVAL` old, and by :meth:`write_index`."""
        self.entries.append((float(time), rel))
        self._unlisted += 1
        if time_now() - self._indexed_at >= PVD_INTERVAL:
            self.write_index()

    def write_index(self) -> None:
        """Rewrite the .pvd with every sample written so far (if it lacks some)."""
        if self._unlisted:
            atomic_write_text(self.pvd, pvd_text(self.entries))
            self._unlisted = 0
        self._indexed_at = time_now()

    def write(self, time: float, points, cells, point_data=None, cell_data=None,
              key: Hashable = None) -> Path:
        """Write one sample (see :func:`write_vtu`) and add it to the collection (in the
        background when the series has a :class:`BackgroundWriter`: the .pvd lists a sample
        only once its file is complete).  ``key``: while it stays the same, the arrays the
        series' :attr:`reuse` names are the same (their encoding is kept)."""
        return self.write_built(time, _as_given, (points, cells, dict(point_data or {}),
                                                  dict(cell_data or {})), key)

    def write_built(self, time: float, build, args: tuple, key: Hashable = None) -> Path:
        """:meth:`write` of the grid ``build(*args)`` -> (points, cells, point_data,
        cell_data), built where the sample is written (on the worker in the background;
        ``args`` must not change afterwards)."""
        path, rel = self.next_path()
        self._next += 1
        if self.background is None:
            self._write(path, rel, time, build, args, key)
        else:
            self.background.submit(self._write, path, rel, time, build, args, key)
        return path

    def _write(self, path, rel, time, build, args, key) -> None:
        points, cells, point_data, cell_data = build(*args)
        write_vtu(path, points, cells, point_data, cell_data, self.reuse, key)
        self.commit(time, rel)


def _as_given(points, cells, point_data, cell_data) -> tuple:
    return points, cells, point_data, cell_data


class _BodyState:
    """A copy of what :meth:`ParaViewWriter.particle_mesh` reads of the bodies."""

    def __init__(self, id, shape_id, position, R, velocity, angular_velocity) -> None:
        self.id, self.shape_id, self.position = id, shape_id, position
        self.velocity, self.angular_velocity, self._R = velocity, angular_velocity, R

    @classmethod
    def of(cls, bodies: "Bodies") -> "_BodyState":
        return cls(np.array(bodies.id, np.int64), np.array(bodies.shape_id, np.int64),
                   np.array(bodies.position, float), np.array(bodies.rotation_matrices(), float),
                   np.array(bodies.velocity, float), np.array(bodies.angular_velocity, float))

    def __len__(self) -> int:
        return len(self.id)

    def rotation_matrices(self) -> np.ndarray:
        return self._R


class ParaViewWriter:
    """The three ParaView series: particles, walls, contacts.

    Parameters
    ----------
    outdir: output directory.
    shapes: shape id -> :class:`~nurbsdem.geometry.shape.Shape` (file frame).
    walls: the walls (objects with ``.name``, ``.id`` and ``.patch`` in the world at their
        initial place, e.g. ``model.walls``).
    resolution: quads per patch direction for the particles (walls of degree 1 use 1).
    restart_time: see :class:`PvdSeries`.

    Point data of ``particles``: ``particle_id``, ``shape_id`` (ints), ``velocity`` (m/s,
    the body's centroid velocity), ``angular_velocity`` (rad/s) — constant over a body;
    cell data ``patch_id``. ``walls``: point data ``wall_id``, ``displacement`` (m); cell
    data ``wall_id``. ``contacts``: one vertex per active contact at the midpoint of its two
    contact points, point data ``force_normal``, ``force_tangential`` (N, the force on body
    B, the second body of the pair — for a particle–wall contact the wall: the particle's push),
    ``penetration`` (m), ``degenerated`` (level), ``body_a``, ``body_b``.
    """

    def __init__(self, outdir: str | Path, shapes: Mapping[int, "Shape"],
                 walls: Sequence["WallSpec"] = (), resolution: int = 8,
                 restart_time: float | None = None, background: bool = False) -> None:
        self.outdir = Path(outdir)
        self.resolution = int(resolution)
        #: the worker that writes the samples when ``background`` (None: written at once)
        self.background = BackgroundWriter() if background else None
        self.series = {name: PvdSeries(self.outdir, name, restart_time, self.background,
                                       REUSED.get(name, ()))
                       for name in SERIES}
        self._shape_mesh: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        for sid, shape in shapes.items():
            pts, quads, pid = tessellate_patches(shape.patches, self.resolution)
            self._shape_mesh[int(sid)] = (pts - np.asarray(shape.centroid, float), quads, pid)
        self.walls = list(walls)
        self._wall_mesh = self._mesh_walls()
        #: mesh and surface walls: (wall id, points (P,3) m at rest, triangles (T,3)), drawn at
        #: the poses :meth:`write_walls` is given (:meth:`add_curved_walls`)
        self.curved: list[tuple[int, np.ndarray, np.ndarray]] = []
        #: the particles' grid arrays of the last body set (:meth:`_particle_cells`; used by
        #: the one thread that writes the series)
        self._cells_key: tuple | None = None
        self._cells: dict = {}

    def _mesh_walls(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        P, Q, wid, pw = [], [], [], []
        off = 0
        for k, w in enumerate(self.walls):
            n = 1 if (w.patch.degree_u == 1 and w.patch.degree_v == 1) else self.resolution
            pts, quads = tessellate(w.patch, n)
            P.append(pts)
            Q.append(np.asarray(quads, np.int64) + off)
            wid.append(np.full(len(quads), w.id, np.int64))
            pw.append(np.full(len(pts), k, np.int64))
            off += len(pts)
        if not P:
            z = np.zeros(0, np.int64)
            return np.zeros((0, 3)), np.zeros((0, 4), np.int64), z, z
        return np.concatenate(P), np.concatenate(Q), np.concatenate(wid), np.concatenate(pw)

    # -- particles ---------------------------------------------------------------
    def particle_mesh(self, bodies: "Bodies") -> tuple[np.ndarray, np.ndarray, dict, dict]:
        """World points, quads, point data and cell data of all particles (the velocities
        as :class:`~nurbsdem.io.vtu.Repeated`: one row per body, repeated at its points)."""
        n = len(bodies)
        if not n:
            return (np.zeros((0, 3)), np.zeros((0, 4), np.int64),
                    {"particle_id": np.zeros(0), "shape_id": np.zeros(0),
                     "velocity": np.zeros((0, 3)), "angular_velocity": np.zeros((0, 3))}, {})
        R = bodies.rotation_matrices()
        shape_id = np.asarray(bodies.shape_id, np.int64)
        ids = np.asarray(bodies.id, np.int64)
        static = self._particle_cells(ids, shape_id)
        counts, offsets = static["counts"], static["offsets"]
        points = np.empty((int(counts.sum()), 3))
        position = np.asarray(bodies.position, float)
        for sid, idx in static["groups"]:       # the bodies of one shape at once
            place_points_into(self._shape_mesh[sid][0], position, R, idx, offsets[idx], points)
        point_data = {"particle_id": static["particle_id"], "shape_id": static["shape_id"],
                      "velocity": Repeated(np.asarray(bodies.velocity, float), counts),
                      "angular_velocity": Repeated(np.asarray(bodies.angular_velocity, float),
                                                   counts)}
        return points, static["quads"], point_data, {"patch_id": [static["patch_id"]]}

    def _particle_cells(self, ids: np.ndarray, shape_id: np.ndarray) -> dict:
        """What the particles' grid keeps while the bodies stay the same (ids and shapes):
        quads, patch and body ids, each body's point count and first point, the bodies of
        each shape (kept for the last body set)."""
        key = (ids.tobytes(), shape_id.tobytes())
        if self._cells_key == key:
            return self._cells
        meshes = [self._shape_mesh[int(s)] for s in shape_id]
        counts = np.array([len(rel) for rel, _, _ in meshes], np.int64)
        offsets = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
        groups = [(int(sid), np.nonzero(shape_id == sid)[0]) for sid in np.unique(shape_id)]
        self._cells = {
            "counts": counts, "offsets": offsets, "groups": groups,
            "quads": np.concatenate([quads + off for (_, quads, _), off in zip(meshes, offsets)]),
            "patch_id": np.concatenate([pid for _, _, pid in meshes]),
            "particle_id": np.repeat(ids, counts), "shape_id": np.repeat(shape_id, counts)}
        self._cells_key = key
        return self._cells

    def write_particles(self, time: float, bodies: "Bodies") -> Path:
        """One sample of ``particles.pvd`` (time in s); its grid is built by the worker (in
        the background) from a copy of the bodies' state."""
        state = _BodyState.of(bodies)
        key = (state.id.tobytes(), state.shape_id.tobytes())     # fixes the REUSED arrays
        return self.series["particles"].write_built(time, self._particle_grid, (state,), key)

    def _particle_grid(self, bodies) -> tuple:
        pts, quads, pd, cd = self.particle_mesh(bodies)
        return pts, [("quad", quads)], pd, cd

    # -- walls -------------------------------------------------------------------
    def add_curved_walls(self, items) -> None:
        """Draw mesh and surface walls too: items [(wall id, points (P,3) m, triangles
        (T,3))] in the world at rest (:func:`nurbsdem.io.deck_curved.curved_tessellation`)."""
        self.curved = [(int(i), np.asarray(p, float), np.asarray(t, np.int64))
                       for i, p, t in items]

    def write_walls(self, time: float, displacement: np.ndarray | None = None,
                    poses=None) -> Path:
        """One sample of ``walls.pvd``; displacement (W, 3) m of each flat wall from its deck
        position (flat walls translate only), in ``walls`` order; poses [(R (3,3), t (3,))]:
        where each mesh or surface wall is (``x = R x_rest + t``; None: at rest)."""
        pts, quads, wid, pw = self._wall_mesh
        disp = np.zeros((len(self.walls), 3)) if displacement is None else np.asarray(displacement, float).reshape(-1, 3)
        d = disp[pw] if len(pw) else np.zeros((0, 3))
        ids = np.array([w.id for w in self.walls], np.int64)
        pd = {"wall_id": ids[pw] if len(pw) else np.zeros(0, np.int64), "displacement": d}
        if self.curved:
            return self._write_with_curved(time, pts + d, quads, wid, pd, poses)
        return self.series["walls"].write(time, pts + d, [("quad", quads)], pd, {"wall_id": [wid]},
                                          key=0)       # the walls never change their mesh

    def _write_with_curved(self, time, pts, quads, wid, pd, poses) -> Path:
        """:meth:`write_walls` with the triangles of the mesh and surface walls after the
        flat walls' quads (their displacement: the move of each point from its rest)."""
        P, T, cid, pid, disp = [pts], [], [], [pd["wall_id"]], [pd["displacement"]]
        off = len(pts)
        for k, (w_id, rest, tris) in enumerate(self.curved):
            R, t = poses[k] if poses is not None else (np.eye(3), np.zeros(3))
            moved = rest @ np.asarray(R, float).T + np.asarray(t, float)
            P.append(moved)
            T.append(tris + off)
            cid.append(np.full(len(tris), w_id, np.int64))
            pid.append(np.full(len(rest), w_id, np.int64))
            disp.append(moved - rest)
            off += len(rest)
        cells = [("quad", quads), ("triangle", np.concatenate(T))]
        point_data = {"wall_id": np.concatenate(pid), "displacement": np.concatenate(disp)}
        return self.series["walls"].write(time, np.concatenate(P), cells, point_data,
                                          {"wall_id": [wid, np.concatenate(cid)]}, key=0)

    # -- contacts ----------------------------------------------------------------
    def write_contacts(self, time: float, contacts: Mapping[str, np.ndarray] | None) -> Path:
        """One sample of ``contacts.pvd``.

        contacts: mapping (or object with attributes) with ``point`` (K, 3) or both
        ``point_a``, ``point_b`` (K, 3) (world, m); ``force_normal``, ``force_tangential``
        (K, 3) N; ``penetration`` (K,) m; ``degenerated`` (K,) int; optional ``body_a``,
        ``body_b`` (K,) int, ``stiffness_normal`` (K,) N/m (the normal stiffness used: the
        penalty, or Hertz's tangent stiffness) and ``contact_radius`` (K,) m (Hertz's
        equivalent radius of curvature; NaN for the linear law). ``None``: no contacts.
        """
        c = contacts
        if c is None or (_get(c, "point") is None and _get(c, "point_a") is None):
            pts = np.zeros((0, 3))
        elif _get(c, "point") is not None:
            pts = np.asarray(_get(c, "point"), float).reshape(-1, 3)
        else:
            pts = 0.5 * (np.asarray(_get(c, "point_a"), float) + np.asarray(_get(c, "point_b"), float)).reshape(-1, 3)
        k = len(pts)
        pd = {"force_normal": _arr(c, "force_normal", (k, 3), float),
              "force_tangential": _arr(c, "force_tangential", (k, 3), float),
              "penetration": _arr(c, "penetration", (k,), float),
              "degenerated": _arr(c, "degenerated", (k,), np.int64),
              "body_a": _arr(c, "body_a", (k,), np.int64),
              "body_b": _arr(c, "body_b", (k,), np.int64)}
        for key in ("stiffness_normal", "contact_radius"):
            if _get(c, key) is not None:
                pd[key] = _arr(c, key, (k,), float)
        cells = [("vertex", np.arange(k, dtype=np.int64).reshape(-1, 1))]
        return self.series["contacts"].write(time, pts, cells, pd)

    def write(self, time: float, bodies: "Bodies", wall_displacement: np.ndarray | None = None,
              contacts: Mapping[str, np.ndarray] | None = None, curved_poses=None) -> None:
        """One sample of all three series (in the background: one job of the worker);
        curved_poses: those of :meth:`write_walls`."""
        with self.background.held() if self.background is not None else nullcontext():
            self.write_particles(time, bodies)
            self.write_walls(time, wall_displacement, curved_poses)
            self.write_contacts(time, contacts if self.background is None else _copied(contacts))

    def write_index(self) -> None:
        """Rewrite each series' .pvd that lacks written samples (on the thread that writes
        the series: the worker's job in background mode)."""
        for series in self.series.values():
            series.write_index()

    def sync(self) -> None:
        """Wait until every sample is written and listed (raises a write's error)."""
        if self.background is not None:
            self.background.wait()
        self.write_index()

    def close(self) -> None:
        """Write what is queued, stop the background worker and list every sample."""
        if self.background is not None:
            self.background.close()
        self.write_index()

    def abandon(self) -> None:
        """Stop the background worker after its queued writes, ignoring their errors, and
        list the samples written (if that can be done)."""
        if self.background is not None:
            self.background.abandon()
        try:
            self.write_index()
        except OSError:
            pass


def _copied(contacts: Any) -> Any:
    """A mapping's arrays copied (a background write must not see them change)."""
    if contacts is None or not isinstance(contacts, Mapping):
        return contacts
    return {k: np.array(v, copy=True) for k, v in contacts.items()}


def _get(obj: Any, key: str) -> Any:
    if obj is None:
        return None
    if isinstance(obj, Mapping):
        return obj.get(key)
    return getattr(obj, key, None)


def _arr(obj: Any, key: str, shape: tuple[int, ...], dtype) -> np.ndarray:
    v = _get(obj, key)
    if v is None:
        return np.zeros(shape, dtype)
    return np.asarray(v, dtype).reshape(shape)


# ---------------------------------------------------------------------------- CSV monitors


class CsvMonitor:
    """A CSV file with a fixed header, one row per sample, each row flushed when written.

    restart_time: ``None`` (fresh file, header only) or a time (s): rows after it, and an
    incomplete or malformed trailing row, are removed (atomic rewrite) before appending.
    """

    def __init__(self, path: str | Path, columns: Sequence[str],
                 restart_time: float | None = None) -> None:
        self.path = Path(path)
        self.columns = tuple(columns)
        self.header = ",".join(self.columns)
        rows: list[str] = []
        if restart_time is not None and self.path.exists():
            rows = self._kept_rows(restart_time)
        atomic_write_text(self.path, "".join(line + "\n" for line in [self.header] + rows))
        self.rows_at_start = [list(map(float, r.split(","))) for r in rows]
        #: rows are flushed by the batch that holds them (MonitorWriter.batch)
        self.batched = False
        self._fh = open(self.path, "a", newline="", buffering=1 << 20)

    def _kept_rows(self, restart_time: float) -> list[str]:
        text = self.path.read_text(encoding="utf-8", errors="replace")
        lines = text.split("\n")
        if not lines or lines[0].strip() != self.header:
            return []
        complete = lines[1:-1] if not text.endswith("\n") else lines[1:]
        kept = []
        limit = restart_time + _time_tol(restart_time)
        for line in complete:
            parts = line.split(",")
            if len(parts) != len(self.columns):
                break
            try:
                vals = [float(p) for p in parts]
            except ValueError:
                break
            if vals[0] > limit:
                break
            kept.append(line)
        return kept

    def append(self, values: Sequence[Any]) -> None:
        """Write one row (len(columns) values; time first) and flush it (in a
        :meth:`MonitorWriter.batch`: at its end, whole rows at once)."""
        self._write_row(len(values), ",".join(_fmt(v) for v in values))

    def append_floats(self, values: Sequence[float]) -> None:
        """:meth:`append` of a row of floats (Python or NumPy; the same text, without the
        per-field type dispatch: the monitors write one row per deck step)."""
        self._write_row(len(values), ",".join(map(_float_repr, values)))

    def _write_row(self, n_values: int, text: str) -> None:
        """The row ``text`` of ``n_values`` fields, checked against the header, written and
        flushed unless a batch holds it."""
        if n_values != len(self.columns):
            raise ValueError(f"{self.path.name}: expected {len(self.columns)} values, got {n_values}")
        self._fh.write(text + "\n")
        if not self.batched:
            self._fh.flush()

    def sync(self) -> None:
        """Flush and fsync (call before writing a checkpoint)."""
        if not self._fh.closed:
            self._fh.flush()
            os.fsync(self._fh.fileno())

    def flush(self) -> None:
        """Hand the rows written so far to the operating system (whole rows)."""
        if not self._fh.closed:
            self._fh.flush()

    def fsync(self) -> None:
        """Make the rows the last :meth:`flush` handed over durable (safe from the output
        worker while the time loop appends: the file stays open until the worker is done)."""
        if not self._fh.closed:
            os.fsync(self._fh.fileno())

    def close(self) -> None:
        if not self._fh.closed:
            self.sync()
            self._fh.close()


def _file_in(folder: Path, name: str) -> Path:
    """``folder / name``, refused (InputError) unless it is a plain file name of ``folder``:
    names come from the deck (wall names), and no output goes outside the output folder
    (the deck and the API check the names first; this is the writer's own guard)."""
    path = folder / name
    if Path(name).name != name or name in (".", "..") or \
            path.resolve().parent != folder.resolve():
        from ..errors import InputError
        raise InputError(f"refusing to write {name!r}: it is not a file name inside the "
                         f"output folder {folder}")
    return path


class MonitorWriter:
    """``monitors/energy.csv``, ``monitors/contacts.csv`` and ``monitors/wall_<name>.csv``.

    Energies in J, times in s, displacements in m, reactions in N (the total force the
    particles exert on the wall, world frame).
    """

    def __init__(self, outdir: str | Path, wall_names: Sequence[str] = (),
                 restart_time: float | None = None) -> None:
        self.dir = Path(outdir) / MONITOR_DIR
        self.dir.mkdir(parents=True, exist_ok=True)
        self.energy_csv = CsvMonitor(self.dir / "energy.csv", ENERGY_COLUMNS, restart_time)
        self.contacts_csv = CsvMonitor(self.dir / "contacts.csv", CONTACT_COLUMNS, restart_time)
        self.wall_csv = {name: CsvMonitor(_file_in(self.dir, f"wall_{name}.csv"), WALL_COLUMNS,
                                          restart_time)
                         for name in wall_names}
        self.hertz_csv: CsvMonitor | None = None       # made by the first hertz() row
        self._restart_time = restart_time
        self._reference: float | None = None
        if self.energy_csv.rows_at_start:
            r = self.energy_csv.rows_at_start[0]
            # balance_error = mechanical + dissipated - external_work - reference
            self._reference = r[6] + r[4] - r[5] - r[7]

    def energy(self, time: float, kinetic: float, potential: float, elastic: float,
               dissipated: float, external_work: float,
               balance_error: float | None = None) -> float:
        """Append an energy row; returns the balance error written.

        kinetic (translational + rotational), potential (gravity), elastic (contact springs),
        dissipated (cumulative, >= 0), external_work (cumulative work done on the system by
        moving walls and anything else external, e.g. energy added by a Replicate step).
        mechanical = kinetic + potential + elastic. balance_error, unless given, is
        ``mechanical + dissipated - external_work`` minus its value at the first row.
        """
        mech = float(kinetic) + float(potential) + float(elastic)
        total = mech + float(dissipated) - float(external_work)
        if balance_error is None:
            if self._reference is None:
                self._reference = total
            balance_error = total - self._reference
        self.energy_csv.append_floats([float(time), float(kinetic), float(potential),
                                       float(elastic), float(dissipated),
                                       float(external_work), mech, float(balance_error)])
        return float(balance_error)

    def contacts(self, time: float, monitored: int, active: int, degenerated: int,
                 failed: int) -> None:
        """Append a contact-count row (numbers of monitored LCPs, active, degenerated and
        failed contacts, paper Fig. 5)."""
        self.contacts_csv.append([time, int(monitored), int(active), int(degenerated), int(failed)])

    def hertz(self, time: float, active: int, fallback: int, radius: np.ndarray,
              stiffness: np.ndarray) -> None:
        """Append a row to ``monitors/hertz.csv`` (runs with Hertz–Mindlin interfaces): active
        contacts, how many took the bounding-sphere radius (degenerated contact or curvature),
        the smallest / median / largest equivalent radius (m) and the largest normal tangent
        stiffness (N/m) used (NaN without contacts)."""
        if self.hertz_csv is None:
            self.hertz_csv = CsvMonitor(self.dir / "hertz.csv", HERTZ_COLUMNS, self._restart_time)
        r = np.asarray(radius, float)
        k = np.asarray(stiffness, float)
        stats = ([float(r.min()), float(np.median(r)), float(r.max()), float(k.max())]
                 if r.size else [math.nan] * 4)
        self.hertz_csv.append([time, int(active), int(fallback), *stats])

    def wall(self, name: str, time: float, displacement: Sequence[float],
             reaction: Sequence[float]) -> None:
        """Append a row to ``wall_<name>.csv``: displacement from the deck position (m) and
        reaction (N): the force that holds the wall on its prescribed path, i.e. minus the
        sum of the contact forces the particles exert on it."""
        d = np.asarray(displacement, float).reshape(3).tolist()
        r = np.asarray(reaction, float).reshape(3).tolist()
        self.wall_csv[name].append_floats([float(time), *d, *r])

    def walls(self, time: float, displacement: np.ndarray, reaction: np.ndarray) -> None:
        """:meth:`wall` rows of every wall at once: displacement, reaction (W, 3) in the
        order of the wall names given at construction."""
        t = float(time)
        for csv, d, r in zip(self.wall_csv.values(), np.asarray(displacement, float).tolist(),
                             np.asarray(reaction, float).tolist()):
            csv.append_floats([t, *d, *r])

    def _all(self) -> list[CsvMonitor]:
        return [self.energy_csv, self.contacts_csv, *self.wall_csv.values(),
                *([self.hertz_csv] if self.hertz_csv is not None else [])]

    @contextmanager
    def batch(self):
        """Rows appended inside are flushed together at the end (whole rows: a run killed
        meanwhile leaves at most an incomplete last row, which a restart drops)."""
        files = self._all()
        for m in files:
            m.batched = True
        try:
            yield self
        finally:
            for m in self._all():
                m.batched = False
                if not m._fh.closed:
                    m._fh.flush()

    def sync(self) -> None:
        for m in self._all():
            m.sync()

    def flush(self) -> None:
        """:meth:`CsvMonitor.flush` of every file."""
        for m in self._all():
            m.flush()

    def fsync(self) -> None:
        """:meth:`CsvMonitor.fsync` of every file."""
        for m in self._all():
            m.fsync()

    def close(self) -> None:
        for m in self._all():
            m.close()


# ---------------------------------------------------------------------------- results.h5

RESULTS_FIELDS = {"particle_id": ((), np.int64), "shape_id": ((), np.int64),
                  "position": ((3,), np.float64), "quaternion": ((4,), np.float64),
                  "velocity": ((3,), np.float64), "angular_velocity": ((3,), np.float64)}


class ResultsWriter:
    """``results.h5``: every sample's body states, ragged by sample (N may change).

    Layout::

        attrs: deck (text), deck_path, nurbsdem_version, format = "nurbsdem-results-1",
               conventions (str)
        time        (S,)   float64  sample times, s
        count       (S,)   int64    bodies in each sample
        offset      (S+1,) int64    sample k's rows are offset[k]:offset[k+1]
        particle_id (R,)   int64    deck body id
        shape_id    (R,)   int64
        position    (R, 3) float64  centroid, world, m
        quaternion  (R, 4) float64  (w, x, y, z), file frame -> world
        velocity    (R, 3) float64  m/s
        angular_velocity (R, 3) float64 rad/s, world frame

    Samples are buffered and written ``flush_every`` at a time (and by :meth:`flush`,
    :meth:`close`): each flush copies the file, appends, fsyncs and renames it into place,
    so the file is always complete. Read with :func:`read_results_sample`.

    background: a :class:`BackgroundWriter` (the ParaView series' worker) that writes the
    buffered samples while the time loop goes on; every write of the file is then one of its
    jobs, in order, and a write the caller waits for waits for the jobs queued before it.
    """

    def __init__(self, path: str | Path, deck_text: str = "", deck_path: str = "",
                 restart_time: float | None = None, flush_every: int = 20,
                 after_append=None, background: BackgroundWriter | None = None) -> None:
        self.path = Path(path)
        self.flush_every = int(flush_every)
        self.after_append = after_append   # called after each append (OutputWriters' commit)
        self.background = background
        self._pending: list[tuple[float, dict[str, np.ndarray]]] = []
        if restart_time is not None and self.path.exists():
            self._truncate(restart_time)
        else:
            self._create(deck_text, deck_path)

    def _create(self, deck_text: str, deck_path: str) -> None:
        from .. import __version__

        def fill(f) -> None:
            f.attrs["deck"] = deck_text
            f.attrs["deck_path"] = str(deck_path)
            f.attrs["nurbsdem_version"] = __version__
            f.attrs["format"] = "nurbsdem-results-1"
            f.attrs["conventions"] = ("SI units; position = centroid in the world; "
                                      "quaternion (w, x, y, z) maps the shape file frame "
                                      "to the world; velocities in the world frame; "
                                      "sample k = rows offset[k]:offset[k+1]")
            f.create_dataset("time", (0,), np.float64, maxshape=(None,), chunks=(1024,))
            f.create_dataset("count", (0,), np.int64, maxshape=(None,), chunks=(1024,))
            f.create_dataset("offset", data=np.zeros(1, np.int64), maxshape=(None,),
                             chunks=(1024,))
            for name, (tail, dt) in RESULTS_FIELDS.items():
                f.create_dataset(name, (0, *tail), dt, maxshape=(None, *tail),
                                 chunks=(4096, *tail))
        write_hdf5_atomically(self.path, fill)

    def _rewrite(self, edit, adding: int = 0) -> None:
        """Copy the file, apply ``edit(h5file)`` (which adds ``adding`` bytes), fsync, rename
        into place."""
        ensure_space(self.path.parent, 2 * (self.path.stat().st_size + adding) + 1024 * 1024)
        write_hdf5_atomically(self.path, edit, source=self.path)

    def set_deck(self, text: str) -> None:
        """Replace the deck text the file records (after the queued writes)."""
        if self.background is not None:
            self.background.wait()
        self._rewrite(lambda f: f.attrs.__setitem__("deck", text))

    def _truncate(self, restart_time: float) -> None:
        try:
            self._truncate_file(restart_time)
        except (OSError, KeyError, ValueError, TypeError, IndexError) as exc:
            from ..errors import InputError
            raise InputError(f"cannot continue the results file: it is corrupted "
                             f"({' '.join(str(exc).split())[:120]}); move it away to restart "
                             f"(a new one starts at the checkpoint's time)",
                             path=str(self.path)) from None

    def _truncate_file(self, restart_time: float) -> None:
        def edit(f) -> None:
            t = f["time"][:]
            s = int(np.searchsorted(t, restart_time + _time_tol(restart_time), side="right"))
            r = int(f["offset"][s])
            f["time"].resize((s,))
            f["count"].resize((s,))
            f["offset"].resize((s + 1,))
            for name in RESULTS_FIELDS:
                f[name].resize((r, *f[name].shape[1:]))
        self._rewrite(edit)

    def append(self, time: float, bodies: "Bodies") -> None:
        """Queue one sample (time in s) of the bodies' state; flushes every ``flush_every``."""
        data = {"particle_id": bodies.id, "shape_id": bodies.shape_id,
                "position": bodies.position, "quaternion": bodies.quaternion,
                "velocity": bodies.velocity, "angular_velocity": bodies.angular_velocity}
        self._pending.append((float(time), {k: np.array(v, RESULTS_FIELDS[k][1])
                                            for k, v in data.items()}))
        if len(self._pending) >= self.flush_every:
            self.flush(wait=False)
        if self.after_append is not None:
            self.after_append()

    def flush(self, wait: bool = True) -> None:
        """Write the buffered samples (atomic replace of the file): on the background worker
        if there is one (``wait``: and wait until it is written)."""
        pending, self._pending = self._pending, []
        if pending:
            if self.background is None:
                self._write_samples(pending)
            else:
                self.background.submit(self._write_samples, pending)
        if wait and self.background is not None:
            self.background.wait()

    def _write_samples(self, pending: list) -> None:
        """Append the samples ``pending`` [(time, arrays)] to the file."""
        def edit(f) -> None:
            s0 = f["time"].shape[0]
            r0 = int(f["offset"][s0])
            counts = np.array([len(d["particle_id"]) for _, d in pending], np.int64)
            s1, r1 = s0 + len(pending), r0 + int(counts.sum())
            f["time"].resize((s1,))
            f["time"][s0:s1] = [t for t, _ in pending]
            f["count"].resize((s1,))
            f["count"][s0:s1] = counts
            f["offset"].resize((s1 + 1,))
            f["offset"][s0 + 1:s1 + 1] = r0 + np.cumsum(counts)
            for name in RESULTS_FIELDS:
                ds = f[name]
                ds.resize((r1, *ds.shape[1:]))
                if r1 > r0:
                    ds[r0:r1] = np.concatenate([d[name] for _, d in pending])
        self._rewrite(edit, sum(d[k].nbytes for _, d in pending for k in d))

    def close(self) -> None:
        self.flush()


def read_results_times(path: str | Path) -> np.ndarray:
    """Sample times (s) of a results.h5."""
    import h5py
    with h5py.File(path, "r") as f:
        return f["time"][:]


def read_results_sample(path: str | Path, k: int) -> dict[str, Any]:
    """Sample k (negative counts from the end) of a results.h5: ``time`` and the arrays of
    :data:`RESULTS_FIELDS`."""
    import h5py
    with h5py.File(path, "r") as f:
        s = f["time"].shape[0]
        if k < 0:
            k += s
        if not 0 <= k < s:
            raise IndexError(f"sample {k} out of range ({s} samples)")
        a, b = int(f["offset"][k]), int(f["offset"][k + 1])
        out: dict[str, Any] = {"time": float(f["time"][k])}
        for name in RESULTS_FIELDS:
            out[name] = f[name][a:b]
        return out


# ---------------------------------------------------------------------------- bundle


#: Result files and folders of a run in its output directory (what a new run replaces).
RUN_FILES = tuple(f"{name}.pvd" for name in SERIES) + (VTK_DIR, MONITOR_DIR, RESULTS_NAME,
                                                       "checkpoint.h5")
#: Where a fresh run keeps the previous run's results until it has its first complete sample.
PREVIOUS_DIR = ".previous-run"


def restore_previous_run(directory: str | Path) -> bool:
    """Put back the results a fresh run set aside (``.previous-run``) when that run ended
    before writing a complete sample (killed, disk full, ...); returns whether it did.
    The unfinished run's files of the same names are discarded."""
    directory = Path(directory)
    prev = directory / PREVIOUS_DIR
    if not prev.is_dir():
        return False
    for name in RUN_FILES:
        if (prev / name).exists():
            _remove(directory / name)
            os.replace(prev / name, directory / name)
    shutil.rmtree(prev, ignore_errors=True)
    return True


def set_previous_run_aside(directory: str | Path) -> bool:
    """Move a previous run's result files into ``.previous-run`` (renames: no copy, no
    space needed); returns whether there were any."""
    directory = Path(directory)
    found = [name for name in RUN_FILES if (directory / name).exists()]
    if not found:
        return False
    prev = directory / PREVIOUS_DIR
    prev.mkdir(exist_ok=True)
    for name in found:
        os.replace(directory / name, prev / name)
    return True


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif path.exists() or path.is_symlink():
        path.unlink()


def clean_output_directory(directory: str | Path) -> None:
    """What a start does first: temporaries of killed writers are removed, and results a
    fresh run had set aside are put back if that run never completed a sample.  Done under
    the folder's lock (:mod:`nurbsdem.io.lock`); while another process holds it (a run still
    writing there, or rank 0 of this MPI run) nothing is touched: that run's temporaries are
    not stale, and a run that goes on to write there is refused when it opens its writers."""
    from ..errors import InputError
    directory = Path(directory)
    try:
        key = output_lock.acquire(directory)
    except InputError:
        return
    try:
        restore_previous_run(directory)
        for folder in (directory, directory / VTK_DIR, directory / MONITOR_DIR):
            remove_stale_temporaries(folder)
    finally:
        output_lock.release(key)


def _output_series(directory: Path, model: "Model"):
    """(file, the time of its last sample or None if unreadable, the deck setting that paces
    it, its interval in s) of each output file in ``directory``, for
    :func:`~nurbsdem.io.restartcheck.check_restart_outputs`."""
    out = model.output
    results = directory / RESULTS_NAME
    if results.is_file():
        yield (results, restartcheck.results_last_time(results), "Results Every",
               out.results_interval)
    csvs = [("energy.csv", ENERGY_COLUMNS), ("contacts.csv", CONTACT_COLUMNS),
            ("hertz.csv", HERTZ_COLUMNS)]
    csvs += [(f"wall_{name}.csv", WALL_COLUMNS) for name in model.wall_names]
    for name, columns in csvs:
        path = directory / MONITOR_DIR / name
        if path.is_file():
            yield (path, restartcheck.csv_last_time(path, len(columns)), "Monitors Every",
                   out.monitors_every)
    for name in SERIES:
        path = directory / f"{name}.pvd"
        if path.is_file():
            from ..errors import InputError
            try:
                last = max((t for t, _ in read_pvd(path)), default=-math.inf)
            except InputError:
                last = None                 # the series reports it when it reads the file
            yield path, last, "VTK Every", out.vtk_every


class OutputWriters:
    """All writers of a run, from the model's ``Output`` block.

    restart_time: ``None`` for a fresh run, or the checkpoint's time (s) on a restart.
    Attributes: ``directory``, ``paraview`` (:class:`ParaViewWriter`), ``monitors``
    (:class:`MonitorWriter`), ``results`` (:class:`ResultsWriter`).

    Safety of earlier results: on every start, temporaries of killed writers are removed
    (:func:`clean_output_directory`). A fresh run first moves the previous run's files into
    ``.previous-run`` and deletes them only once it has a complete sample of its own (its
    first ``results.append``, or a :meth:`sync` before a checkpoint); if it fails before
    that (:meth:`abort`, or killed: the next start), the previous files are put back.
    """

    def __init__(self, model: "Model", restart_time: float | None = None,
                 flush_every: int = 20, background: bool = False) -> None:
        assert model.output is not None
        self.directory = Path(model.output.directory)
        if self.directory.exists() and not self.directory.is_dir():
            raise OSError(errno.ENOTDIR, "the output directory is a file", str(self.directory))
        self.directory.mkdir(parents=True, exist_ok=True)
        self._lock = output_lock.acquire(self.directory)      # before touching anything
        self._committed = True
        try:
            clean_output_directory(self.directory)
            if restart_time is not None:
                restartcheck.check_restart_outputs(_output_series(self.directory, model),
                                                   restart_time)
        except BaseException:
            self._release()
            raise
        self._committed = restart_time is not None
        if restart_time is None:
            set_previous_run_aside(self.directory)
        try:
            shapes = {sid: e.shape for sid, e in model.shapes.items()}
            self.paraview = ParaViewWriter(self.directory, shapes, model.walls,
                                           model.output.vtk_resolution, restart_time,
                                           background)
            if getattr(model, "curved_walls", None):
                from .deck_curved import curved_tessellation
                self.paraview.add_curved_walls(curved_tessellation(model))
            self.monitors = MonitorWriter(self.directory, model.wall_names, restart_time)
            self.results = ResultsWriter(self.directory / RESULTS_NAME, model.text, model.path,
                                         restart_time, flush_every, after_append=self._commit,
                                         background=self.paraview.background)
        except BaseException:
            self._restore()
            self._release()
            raise

    def _release(self) -> None:
        lock, self._lock = getattr(self, "_lock", None), None
        output_lock.release(lock)

    @property
    def committed(self) -> bool:
        """Whether this run's results have replaced the previous run's."""
        return self._committed

    def _commit(self) -> None:
        """The first complete sample is on disk: the previous run's results can go."""
        if self._committed:
            return
        self.results.flush()
        self.monitors.sync()
        self._committed = True
        shutil.rmtree(self.directory / PREVIOUS_DIR, ignore_errors=True)

    def _restore(self) -> None:
        if not self._committed:
            restore_previous_run(self.directory)

    def sync(self) -> None:
        """Make everything written so far durable (call before saving a checkpoint)."""
        self.paraview.sync()
        self.results.flush()
        self.monitors.sync()
        self._commit()

    def checkpoint(self, save, *args) -> None:
        """Make everything written so far durable, then call ``save(*args)`` (write the
        checkpoint that refers to it), in this order.  With a background worker both happen
        on it, after the writes queued before, while the caller goes on: ``args`` must not
        change afterwards (hand over copies); the monitor rows written so far are handed to
        the operating system here and fsynced there.  An error is raised at the next write
        or :meth:`sync`, as a background write's."""
        bg = self.paraview.background
        if bg is None or not self._committed:
            self.sync()
            save(*args)
            return
        self.monitors.flush()
        self.results.flush(wait=False)
        bg.submit(self._durable_then_save, save, args)

    def _durable_then_save(self, save, args: tuple) -> None:
        self.paraview.write_index()
        self.monitors.fsync()
        save(*args)

    def abort(self) -> None:
        """The run failed: close the files and, if this run has no complete sample yet, put
        the previous run's results back. Never raises."""
        pv = getattr(self, "paraview", None)
        if pv is not None:
            pv.abandon()
        for m in (getattr(self, "monitors", None),):
            try:
                if m is not None:
                    m.close()
            except OSError:
                pass
        if not self._committed:
            try:
                restore_previous_run(self.directory)
            except OSError:
                pass
            self._aborted = True
            self._release()             # nothing more is written (close() does nothing)

    def close(self) -> None:
        """Flush and close (after :meth:`abort`: nothing more is written); the folder's lock
        is given back either way."""
        if getattr(self, "_aborted", False):
            self._release()
            return
        try:
            self.results.close()            # its last samples are a job of the worker too
            self.paraview.close()
            self.monitors.close()
            self._commit()
        finally:
            self._release()


def is_multiple(t: float, every: float, tol: float = 1e-9) -> bool:
    """Whether time t (s) falls on a multiple of ``every`` (s), within tol * every."""
    k = round(t / every)
    return math.isclose(t, k * every, rel_tol=0.0, abs_tol=tol * every)

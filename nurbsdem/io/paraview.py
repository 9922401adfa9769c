"""The ParaView output: the time series ``particles.pvd``, ``walls.pvd`` and ``contacts.pvd``
(:class:`ParaViewWriter`), each a collection of ``vtk/<name>_NNNNNN.vtu`` files
(:class:`PvdSeries`; the .vtu encoding: :mod:`nurbsdem.io.vtu`)."""
from __future__ import annotations

from contextlib import nullcontext
from time import monotonic as time_now
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import TYPE_CHECKING, Any, Hashable, Mapping, Sequence

import numpy as np

from ..geometry.rotation import place_points_into
from .atomic import atomic_write_bytes, atomic_write_text
from .background import BackgroundWriter
from .layout import SERIES, VTK_DIR, time_tol
from .vtu import Repeated, Reuse, vtu_parts

if TYPE_CHECKING:  # pragma: no cover
    from ..geometry.nurbs import Patch
    from ..geometry.shape import Shape
    from ..model import Bodies, WallSpec

#: the .pvd files are rewritten when this old (s of wall time), and at every checkpoint and
#: the end of the run: ParaView opened on a running case sees samples at most this late, a
#: killed run's .pvd lists every sample up to its last checkpoint (a restart removes later
#: .vtu files)
PVD_INTERVAL = 1.0

#: arrays of each series that stay the same while its bodies do (encoded once: io/vtu.py)
REUSED = {"particles": ("connectivity", "offsets", "types", "particle_id", "shape_id",
                        "patch_id"),
          "walls": ("connectivity", "offsets", "types", "wall_id")}


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
            kept = [(t, f) for t, f in read_pvd(self.pvd) if t <= restart_time + time_tol(restart_time)]
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
        state = bodies.copy()
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

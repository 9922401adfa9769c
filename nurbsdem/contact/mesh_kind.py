"""The triangle-mesh wall as a geometry kind (:data:`~nurbsdem.contact.kinds.MESH_WALL`):
everything the step's contact provider (:class:`~nurbsdem.contact.curved_walls.
CurvedWallContacts`), the pre-run checks (:mod:`nurbsdem.wall_checks`) and ``MoveWall
ToContact`` (:mod:`nurbsdem.curved_to_contact`) ask of a mesh wall, answered in one place
(the protocol: :class:`~nurbsdem.contact.wall_kinds.WallKind`).

The pieces it calls: the geometry, its triangle grid and the spheres' contacts per triangle
(one per flat or convex region) in :mod:`.mesh_wall`, the NURBS particles' support-mapping
kernel per face, edge and vertex in :mod:`.mesh_particle_compiled`, and the spheres swept
against the triangles in closed form in :mod:`.mesh_sweep`.  The compiled deck steps reach
the same kernels through :mod:`.curved_compiled`.  Lengths in metres; a pose (R, t) places
the wall: ``x_world = R x_wall + t``.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numba import njit

from .kinds import MAX_PER_WALL, MESH_WALL
from .lcp import F_N, F_SD, I_PB, NF, NI
from .mesh_particle_compiled import make_mesh_particle_work, mesh_rows, mesh_work
from .mesh_topology import pack_topology
from .mesh_wall import (LIST_ROOM, NO_LIST, MeshWall, make_lists, make_workspace,
                        mesh_rows_listed, sphere_mesh_rows)
from .packing import joined, offsets, own, per_wall


@njit(cache=True)
def _mesh_rows_of(idx, x, r, R, t, vertices, faces, normals, two_sided, size, grid_origin,
                  grid_cell, grid_dims, cell_start, cell_tris, stamp, mark0, tris, cand_q,
                  cand_d, cand_f, rows_f, rows_i, owner, rank):
    """The contact rows of spheres ``idx`` (centres x, radii r) with one mesh wall at (R, t)
    into rows_f / rows_i from row 0, each row's sphere in ``owner`` and its rank among that
    sphere's contacts with the wall in ``rank``; returns the count (at most
    ``MAX_PER_WALL`` per sphere)."""
    n = 0
    one_f = np.zeros((MAX_PER_WALL, NF))
    one_i = np.zeros((MAX_PER_WALL, NI), np.int64)
    for m in range(idx.shape[0]):
        i = idx[m]
        k = sphere_mesh_rows(x[i], r[i], R, t, vertices, faces, normals, two_sided, size,
                             grid_origin, grid_cell, grid_dims, cell_start, cell_tris, stamp,
                             mark0 + m, tris, cand_q, cand_d, cand_f, one_f, one_i)
        for j in range(min(k, MAX_PER_WALL)):
            rows_f[n, :] = one_f[j, :]
            rows_i[n, :] = one_i[j, :]
            owner[n] = i
            rank[n] = j
            n += 1
    return n


@dataclass
class MeshState:
    """What a provider keeps of one mesh wall between evaluations: the spheres' workspaces
    (:func:`~nurbsdem.contact.mesh_wall.make_workspace`), their kept lists of nearby
    triangles (:func:`~nurbsdem.contact.mesh_wall.make_lists`, one per particle: made at the
    first spheres' query and again when the particle count changes), the NURBS particles'
    workspace (:func:`~nurbsdem.contact.mesh_particle_compiled.mesh_work`, made at their
    first query) and the next query's stamp (each sphere's query marks the triangles it
    visited with a stamp of its own)."""

    work: tuple
    lists: tuple | None = None
    particle_work: object = None
    mark: int = 0


class MeshKind:
    """The mesh wall's answers (:class:`~nurbsdem.contact.wall_kinds.WallKind`)."""

    code = MESH_WALL
    name = "mesh"
    geometry_type = MeshWall
    #: what makes a triangle's front (messages of one-sided walls), and how to make the wall
    #: act on both sides
    front_rule = "its triangles' vertex order"
    two_sided_hint = " or make the wall two-sided (OneSided no)"

    @staticmethod
    def box_points(g: MeshWall) -> tuple[np.ndarray, float]:
        """(points (P,3) m, pad m) whose box, widened by pad, holds the wall: its vertices."""
        return g.vertices, 0.0

    @staticmethod
    def size(g: MeshWall) -> float:
        """The diagonal (m) of the wall's bounding box."""
        return float(g.size)

    @staticmethod
    def new_state(g: MeshWall) -> MeshState:
        """A provider's state of the wall."""
        return MeshState(make_workspace(g))

    @staticmethod
    def sphere_rows(state: MeshState, g: MeshWall, idx: np.ndarray, x: np.ndarray,
                    radii: np.ndarray, R: np.ndarray, t: np.ndarray) -> tuple:
        """(rows_f, owner, rank) of the touching contacts of the spheres ``idx`` (centres x
        (N,3), radii (N,)) with the wall at (R, t), at most
        :data:`~nurbsdem.contact.kinds.MAX_PER_WALL` each
        (:func:`~nurbsdem.contact.mesh_wall.mesh_rows_listed`: each sphere's kept list of
        nearby triangles)."""
        if state.lists is None or len(state.lists[1]) != len(radii):
            state.lists = make_lists(g, len(radii))
        cap = MAX_PER_WALL * len(idx)
        rf, ri = np.zeros((cap, NF)), np.zeros((cap, NI), np.int64)
        owner, rank = np.zeros(cap, np.int64), np.zeros(cap, np.int64)
        n = mesh_rows_listed(idx, x, radii, R, t, g.vertices, g.faces, g.normals, g.two_sided,
                             g.size, g.grid_origin, g.grid_cell, g.grid_dims, g.cell_start,
                             g.cell_tris, g.tri_cells, state.work[0], state.mark,
                             *state.work[1:], *state.lists, MAX_PER_WALL, rf, ri,
                             owner, rank)
        state.mark += len(idx)
        return rf[:n], owner[:n], rank[:n]

    @staticmethod
    def particle_rows(state: MeshState, g: MeshWall, table, idx: np.ndarray,
                      body_shape: np.ndarray, pose_origin: np.ndarray, rot: np.ndarray,
                      R: np.ndarray, t: np.ndarray, label: str) -> tuple:
        """(rows_f, owner, rank) of the touching contacts of the NURBS particles ``idx``
        (shapes ``body_shape`` in the :class:`~nurbsdem.contact.detect.ContactTable`
        ``table``, poses pose_origin (N,3) m, rot (N,3,3)) with the wall at (R, t), at most
        :data:`~nurbsdem.contact.kinds.MAX_PER_WALL` each, in one compiled call
        (:func:`~nurbsdem.contact.mesh_particle_compiled.mesh_rows`)."""
        if state.particle_work is None:
            state.particle_work = mesh_work(g)
        rf, _, owner, rank = mesh_rows(table, g, idx, body_shape, pose_origin, rot, R, t,
                                       MAX_PER_WALL, state.particle_work)
        return rf, owner, rank

    @staticmethod
    def _rest_rows(g: MeshWall, x: np.ndarray, r: np.ndarray, idx: np.ndarray) -> tuple:
        """(rows_f, rows_i, owner) of every contact (touching or not) of the spheres ``idx``
        with the wall at rest: the solver's kernel
        (:func:`_mesh_rows_of`)."""
        work = make_workspace(g)
        cap = MAX_PER_WALL * len(idx)
        rf, ri = np.zeros((cap, NF)), np.zeros((cap, NI), np.int64)
        owner, rank = np.zeros(cap, np.int64), np.zeros(cap, np.int64)
        n = _mesh_rows_of(np.ascontiguousarray(idx, np.int64), x, r, np.eye(3), np.zeros(3),
                          g.vertices, g.faces, g.normals, g.two_sided, g.size, g.grid_origin,
                          g.grid_cell, g.grid_dims, g.cell_start, g.cell_tris, work[0], 0,
                          *work[1:], rf, ri, owner, rank)
        return rf[:n], ri[:n], owner[:n]

    def sphere_crossings(self, g: MeshWall, x: np.ndarray, r: np.ndarray,
                         idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(front (N,), back (N,)): the depth (m, 0: none) by which each sphere of ``idx``
        (centres x (N,3), radii r (N,)) crosses the wall at rest from a side it acts on (the
        contact law's deepest contact), and from behind a one-sided mesh
        (:func:`_crossings`)."""
        if not len(idx):
            return np.zeros(len(x)), np.zeros(len(x))
        return _crossings(g, len(x), lambda mesh: self._rest_rows(mesh, x, r, idx))

    @staticmethod
    def particle_crossings(g: MeshWall, shapes, x: np.ndarray,
                           rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(front (N,), back (N,)) as :meth:`sphere_crossings` for NURBS particles (``shapes``
        (N,), centroids x (N,3) m, rotations rot (N,3,3)) against the wall at rest: the
        compiled contact rows of all of them in one call (:func:`_crossings`)."""
        from .detect import ContactTable
        kinds: dict = {}                 # each distinct shape once, in the order first met
        for s in shapes:
            kinds.setdefault(id(s), (len(kinds), s))
        body_shape = np.array([kinds[id(s)][0] for s in shapes], np.int64)
        table = ContactTable([s for _, s in kinds.values()])
        pos = np.array([x[k] - rot[k] @ np.asarray(s.centroid, float)
                        for k, s in enumerate(shapes)])
        idx = np.arange(len(shapes), dtype=np.int64)

        def rows(mesh):
            rf, ri, owner, _ = mesh_rows(table, mesh, idx, body_shape, pos, rot, np.eye(3),
                                         np.zeros(3), 4 * MAX_PER_WALL)   # the deepest counts
            return rf, ri, owner
        return _crossings(g, len(x), rows)

    @staticmethod
    def sphere_travels(g: MeshWall, x: np.ndarray, reach: np.ndarray, R: np.ndarray,
                       t: np.ndarray, d: np.ndarray) -> np.ndarray:
        """The travel (N,) m along the unit direction d that brings the wall at (R, t) within
        ``reach`` (N,) m of each centre x (N,3) (inf: never), in closed form
        (:func:`~nurbsdem.contact.mesh_sweep.sweep_entries`)."""
        from .mesh_sweep import sweep_entries
        centres = np.ascontiguousarray((x - t) @ R)          # Rᵀ (x − t), row by row
        return sweep_entries(centres, reach, np.ascontiguousarray(R.T @ d), g.vertices,
                             g.faces, g.normals, bool(g.two_sided))

    @staticmethod
    def particle_row(g: MeshWall, table, pos: np.ndarray, Rb: np.ndarray, R: np.ndarray,
                     t: np.ndarray, reach: float, where: str, work=None):
        """The contact row (NF,) of least signed distance of the NURBS particle (shape 0 of
        ``table``, pose pos (3,) m, Rb (3,3)) with the wall at (R, t) among its features
        within ``reach`` (m) of the centroid (the Python reference,
        :func:`~nurbsdem.contact.mesh_particle.particle_mesh_contacts`); None with none
        there.  ``work``: the wall's :func:`~nurbsdem.contact.mesh_wall.make_workspace`."""
        from .mesh_particle import particle_mesh_contacts
        rows_f, _ = particle_mesh_contacts(table, 0, pos, Rb, g, R, t, work=work,
                                           active_only=False, reach=reach)
        if not len(rows_f):
            return None
        return rows_f[int(np.argmin(rows_f[:, F_SD]))]

    @staticmethod
    def row_work(g: MeshWall):
        """The workspace :meth:`particle_row` reuses across calls."""
        return make_workspace(g)

    @staticmethod
    def packed(geometries: list, nurbs: bool) -> dict:
        """The mesh walls' fields of the compiled deck steps' packed walls
        (:data:`~nurbsdem.contact.curved_compiled.CurvedConst`) among the curved walls'
        ``geometries`` (a wall of another kind has an empty slice and zeros): offsets,
        joined vertices, faces, normals and triangle grids, per-wall figures, and with
        ``nurbs`` (NURBS particles meet the walls) the features of each mesh
        (:func:`~nurbsdem.contact.mesh_topology.pack_topology`)."""
        W = len(geometries)
        mine = own(geometries, MeshWall)
        meshes = [g for g in mine if g is not None]

        def sizes(get):
            return offsets(per_wall(mine, get, np.int64))
        tops = [_topology(g, nurbs) for g in mine]
        return dict(
            vo=sizes(lambda g: len(g.vertices)), fo=sizes(lambda g: len(g.faces)),
            co=sizes(lambda g: len(g.cell_start)), to=sizes(lambda g: len(g.cell_tris)),
            vertices=joined([g.vertices for g in meshes], (0, 3)),
            faces=joined([g.faces for g in meshes], (0, 3), np.int64),
            normals=joined([g.normals for g in meshes], (0, 3)),
            two_sided=per_wall(mine, lambda g: g.two_sided, np.bool_),
            msize=per_wall(mine, lambda g: g.size),
            grid_origin=joined([np.zeros(3) if g is None else g.grid_origin for g in mine],
                               (0, 3)).reshape(W, 3),
            grid_cell=per_wall(mine, lambda g: g.grid_cell),
            grid_dims=joined([np.zeros(3, np.int64) if g is None else g.grid_dims
                              for g in mine], (0, 3), np.int64).reshape(W, 3),
            cell_start=joined([g.cell_start for g in meshes], (0,), np.int64),
            cell_tris=joined([g.cell_tris for g in meshes], (0,), np.int64),
            tri_cells=joined([g.tri_cells for g in meshes], (0, 6), np.int64),
            mfo=offsets([len(t[0]) for t in tops]), mlo=offsets([len(t[1]) for t in tops]),
            mto=offsets([len(t[3]) for t in tops]),
            feat=joined([t[0] for t in tops], (0, 4), np.int64),
            feat_tris=joined([t[1] for t in tops], (0,), np.int64),
            tri_feat_range=joined([t[2] for t in tops], (0, 2), np.int64),
            tri_feat=joined([t[3] for t in tops], (0,), np.int64))

    @staticmethod
    def packed_work(geometries: list, n: int, const: dict) -> dict:
        """The mesh walls' fields of the compiled deck steps' workspaces
        (:data:`~nurbsdem.contact.curved_compiled.CurvedWork`) for n particles: the spheres'
        kernel workspaces over all meshes' triangles, their kept lists per mesh
        (:func:`~nurbsdem.contact.mesh_wall.make_lists`) and the NURBS particles' workspace
        for the largest mesh (``const``: the packed fields, :meth:`packed`'s among them)."""
        meshes = [g for g in geometries if isinstance(g, MeshWall)]
        T, M = len(const["faces"]), len(meshes)
        return dict(
            stamp=np.full(T, -1, np.int64), tris=np.empty(T, np.int64), cand_q=np.empty((T, 3)),
            cand_d=np.empty(T), cand_f=np.empty(T, np.int64), keys=np.zeros(T, np.int64),
            near_p=np.zeros((M, n, 5)), near_n=np.full((M, n), NO_LIST, np.int64),
            near_t=np.zeros((M, n, LIST_ROOM), np.int64), near_d=np.zeros((M, n, LIST_ROOM)),
            particle_work=make_mesh_particle_work(
                max([0] + [len(g.faces) for g in meshes]),
                int(np.diff(const["mfo"]).max(initial=0))))


def _topology(g: MeshWall | None, nurbs: bool) -> tuple:
    """(feat, feat_tris, tri_feat_range, tri_feat) of mesh ``g``
    (:func:`~nurbsdem.contact.mesh_topology.pack_topology`) when NURBS particles meet it
    (``nurbs``), else none (every triangle without features); none for a wall of another
    kind (None)."""
    if nurbs and g is not None:
        return pack_topology(g)
    T = 0 if g is None else len(g.faces)
    return (np.zeros((0, 4), np.int64), np.zeros(0, np.int64), np.zeros((T, 2), np.int64),
            np.zeros(0, np.int64))


def _crossings(g: MeshWall, n: int, rows_of) -> tuple[np.ndarray, np.ndarray]:
    """(front (n,), back (n,)) depths (m) of n particles crossing mesh ``g`` at rest from the
    rows ``rows_of(mesh)`` = (rows_f, rows_i, owner) of their contacts with a mesh: the
    deepest of each against ``g``, and, behind a one-sided mesh, the deepest of the contacts
    with the same mesh made two-sided whose normal points along the triangle's front."""
    front, back = np.zeros(n), np.zeros(n)
    rf, _, owner = rows_of(g)
    np.maximum.at(front, owner, -rf[:, F_SD])
    if not g.two_sided:
        rf, ri, owner = rows_of(replace(g, two_sided=True))
        behind = np.einsum("ij,ij->i", rf[:, F_N:F_N + 3], g.normals[ri[:, I_PB]]) > 0
        np.maximum.at(back, owner[behind], -rf[behind, F_SD])
    return front, back


#: the mesh wall kind
MESH = MeshKind()

"""Mesh and NURBS-surface walls inside the compiled deck steps: the contacts of exact spheres
and of NURBS particles with them (:mod:`nurbsdem.contact.mesh_particle_compiled`,
:mod:`nurbsdem.contact.surface_particle_compiled`), as the provider of
:mod:`nurbsdem.contact.curved_walls` finds them, from packed arrays.

The compiled loop (:mod:`nurbsdem.dynamics.deck_steps`) cannot hold a list of wall objects,
so :func:`pack_curved` packs the walls of a
:class:`~nurbsdem.contact.curved_walls.CurvedWallContacts` into one :data:`CurvedConst` of
flat arrays whose types do not depend on how many walls there are (each wall's share is a
slice given by offsets): the meshes' vertices, faces, normals and grids; the surfaces' patch
pools (knot and power-form offsets shifted into the joint arrays) and samples; each wall's
pose in time (:func:`~nurbsdem.contact.curved_walls.wall_pose_at`) and bounding-box corners;
the particles' kinds and reach and the contact table of their shapes.  :data:`CurvedWork`
holds what changes: the mesh kernels' workspaces and the surfaces' gap certificates
(:mod:`nurbsdem.contact.wall_skin`).

:func:`curved_contacts` then gives, at time t, the contacts of the particles with every wall
in the provider's order, keys and rows (wall by wall; spheres in index order, then the
wall's NURBS particles in index order; a mesh's rows per particle in the kernel's order,
those touching kept with their rank), so that the loop's contact part sees the arrays the
Python driver sees, bit for bit (the same kernels on both).  Units: metres, seconds, radians;
global body indices (particles 0..N-1, walls N..N+W-1).
"""
from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit

from ..jit import PointerKernel, internal

from .curved_walls import wall_contact_key, wall_pose_at, world_box
from .kinds import MAX_PER_WALL, MESH_WALL
from .lcp import F_N, F_PA, F_PB, F_SD, I_ACTIVE, NF, NI
from .mesh_particle_compiled import particle_mesh_rows_ptr
from .mesh_wall import mesh_rows_listed
from .packing import joined
from .surface_kind import _surface_rows_of
from .surface_particle_compiled import (CONTACT, NOT_CONVERGED, NOT_UNIQUE,
                                        particle_surface_rows_ptr)
from .wall_kinds import WALL_KINDS
from .wall_skin import due_spheres, pose_travel

#: the packed walls (W curved walls, N particles): n, first (the first curved wall's index
#: among the system's W_all walls), nb = N + W_all, radius (N,) the spheres' radii; per wall
#: kind (W,), the pose in time (omega, center (W,3), t0 (W,), R0 (W,3,3), shift0 (W,3)) and
#: corners (W,8,3) of its wall-frame box; meshes: offsets (W+1,) into vertices, faces (and
#: the triangles' cells tri_cells), cell starts and cell triangles, the arrays, per-wall
#: two_sided, size, grid origin, cell and dims, and offsets (W+1,) mfo, mlo, mto into the
#: features (edges and vertices that are not flat) of the meshes met by NURBS particles,
#: their triangles and the triangles' features: feat, feat_tris, tri_feat_range (per face)
#: and tri_feat (:func:`~nurbsdem.contact.mesh_topology.pack_topology`; empty
#: without NURBS particles); surfaces: offsets (W+1,) into patches and samples, the joint pool and samples, and
#: per-wall spacing and size; the particles: reach (N,) m (bounding radius about the
#: centroid), which are exact spheres and which NURBS particles (N,) bool, their shapes
#: body_shape (N,) and the NURBS particles' count, and the contact table's arrays (ptab …
#: pseeds: tab, info, centroid, radius, seeds of
#: :class:`~nurbsdem.contact.detect.ContactTable`)
CurvedConst = namedtuple(
    "CurvedConst", "n_walls first nb radius kind omega center t0 R0 shift0 corners "
    "vo fo co to vertices faces normals two_sided msize grid_origin grid_cell grid_dims "
    "cell_start cell_tris tri_cells mfo mlo mto feat feat_tris tri_feat_range tri_feat "
    "po so deg ncp koff knots pw poff dom periodic seed_x seed_p seed_uv spacing ssize reach "
    "sphere nurbs body_shape n_nurbs ptab pinfo pcen prad pseeds")
#: what the search changes: the mesh kernels' workspaces over all meshes' triangles (stamp,
#: tris, cand_q, cand_d, cand_f, keys) and the query mark (1,); the spheres' kept lists of
#: nearby triangles per mesh wall (M meshes: near_p (M,N,5), near_n (M,N), near_t and
#: near_d (M,N,LIST_ROOM), :func:`~nurbsdem.contact.mesh_wall.make_lists`); the surfaces'
#: certificates per wall: gap (W,N) m, x0 (W,N,3), odo0 (W,N), the odometer (W,) m and the
#: pose it was last advanced at (prev_R (W,3,3), prev_t (W,3), posed (W,)), the surfaces'
#: extents (W,) m and centres (W,3) m (wall frame); the last call's contacts (count (1,) of
#: them): bodies out_a, out_b, points on the sphere and on the wall out_pa, out_pb (m),
#: normals, depths (m) and keys, each of room W·N·MAX_PER_WALL; the NURBS particles'
#: workspace against the meshes, particle_work
#: (:data:`~nurbsdem.contact.mesh_particle_compiled.MeshParticleWork`, for the largest mesh)
CurvedWork = namedtuple("CurvedWork", "stamp tris cand_q cand_d cand_f keys mark near_p near_n "
                        "near_t near_d gap x0 odo0 odo prev_R prev_t posed extent centre "
                        "out_a out_b out_pa out_pb out_normal out_depth out_key count "
                        "particle_work")


def pack_curved(provider, n_all_walls: int, table) -> tuple:
    """(:data:`CurvedConst`, :data:`CurvedWork`) of the walls of ``provider`` (a
    :class:`~nurbsdem.contact.curved_walls.CurvedWallContacts`; None: no walls) in a system
    of ``n_all_walls`` walls whose particles' shapes are those of ``table`` (the scene's
    :class:`~nurbsdem.contact.detect.ContactTable`); the poses are those the walls hold now.
    The walls' poses, boxes and the particles are packed here; each kind packs its own
    geometry and workspaces (:meth:`~nurbsdem.contact.wall_kinds.WallKind.packed`)."""
    walls = [] if provider is None else provider.walls
    radius = (np.zeros(0) if provider is None else np.ascontiguousarray(provider.radii, float))
    n, W = len(radius), len(walls)
    geo = [w.geometry for w in walls]
    nurbs = provider is not None and bool(provider.nurbs.any())
    const = dict(
        n_walls=W, first=n_all_walls - W, nb=n + n_all_walls, radius=radius,
        kind=np.array([w.kind for w in walls], np.int64),
        omega=joined([w.pose.omega for w in walls], (0, 3)).reshape(W, 3),
        center=joined([w.pose.center for w in walls], (0, 3)).reshape(W, 3),
        t0=np.array([w.pose.t0 for w in walls], float),
        R0=joined([w.pose.R0 for w in walls], (0, 3)).reshape(W, 3, 3),
        shift0=joined([w.pose.shift0 for w in walls], (0, 3)).reshape(W, 3),
        corners=joined([w.corners for w in walls], (0, 3)).reshape(W, 8, 3),
        **_particles(provider, n), ptab=table.tab, pinfo=table.info, pcen=table.centroid,
        prad=table.radius, pseeds=table.seeds)
    for kind in WALL_KINDS:
        _add_fields(const, kind.packed(geo, nurbs), kind.name)
    room = W * n * MAX_PER_WALL
    work = dict(mark=np.zeros(1, np.int64), out_a=np.zeros(room, np.int64),
                out_b=np.zeros(room, np.int64), out_pa=np.zeros((room, 3)),
                out_pb=np.zeros((room, 3)), out_normal=np.zeros((room, 3)),
                out_depth=np.zeros(room), out_key=np.zeros(room, np.int64),
                count=np.zeros(1, np.int64))
    for kind in WALL_KINDS:
        _add_fields(work, kind.packed_work(geo, n, const), kind.name)
    return CurvedConst(**const), CurvedWork(**work)


def _add_fields(fields: dict, part: dict, kind: str) -> None:
    """``part`` (a kind's packed fields) added to ``fields``; a field packed twice is a bug
    of the kind's packing, not a value to overwrite."""
    twice = fields.keys() & part.keys()
    if twice:
        raise ValueError(f"the {kind} wall kind packs fields already packed: {sorted(twice)}")
    fields.update(part)


def _particles(provider, n: int) -> dict:
    """reach, sphere, nurbs, body_shape and n_nurbs of :data:`CurvedConst` for the provider's
    n particles (empty: no provider)."""
    if provider is None:
        return dict(reach=np.zeros(0), sphere=np.zeros(0, np.bool_), nurbs=np.zeros(0, np.bool_),
                    body_shape=np.zeros(0, np.int64), n_nurbs=0)
    shape = (np.zeros(n, np.int64) if provider.body_shape is None
             else np.ascontiguousarray(provider.body_shape, np.int64))
    return dict(reach=np.ascontiguousarray(provider.reach, float),
                sphere=np.ascontiguousarray(provider.spheres, np.bool_),
                nurbs=np.ascontiguousarray(provider.nurbs, np.bool_), body_shape=shape,
                n_nurbs=int(provider.nurbs.sum()))


@internal
def _candidates(x, r, kind, lo, hi):
    """The particles of ``kind`` (N,) bool (ascending) whose bounding boxes (centre ± r) meet
    the box [lo, hi]."""
    out = np.empty(x.shape[0], np.int64)
    n = 0
    for i in range(x.shape[0]):
        if not kind[i]:
            continue
        inside = True
        for a in range(3):
            if x[i, a] + r[i] < lo[a] or x[i, a] - r[i] > hi[a]:
                inside = False
        if inside:
            out[n] = i
            n += 1
    return out[:n]


@internal
def _advance(wk, w, R, t):
    """Surface wall w's odometer moved on by its motion to pose (R, t) (wall_skin)."""
    if wk.posed[w]:
        wk.odo[w] += pose_travel(wk.prev_R[w], wk.prev_t[w], R, t, wk.centre[w], wk.extent[w])
    wk.prev_R[w] = R
    wk.prev_t[w] = t
    wk.posed[w] = True


@internal
def _surface_due(wk, w, idx, x):
    """The spheres of idx whose certificate against surface wall w fails."""
    out = np.empty(idx.shape[0], np.int64)
    return out[:due_spheres(idx, x, wk.gap[w], wk.x0[w], wk.odo0[w], wk.odo[w], out)]


@internal
def _mesh_contacts(cc, wk, w, mesh, idx, x, R, t, c):
    """The touching contacts of spheres idx with mesh wall w (the ``mesh``-th mesh) as the
    provider keeps them (the kernel's rows with negative signed distance, keyed by their rank
    among the sphere's rows) into ``wk``'s contacts from c on; returns the new count."""
    v0, v1, f0, f1 = cc.vo[w], cc.vo[w + 1], cc.fo[w], cc.fo[w + 1]
    vertices, faces, normals = cc.vertices[v0:v1], cc.faces[f0:f1], cc.normals[f0:f1]
    tri_cells = cc.tri_cells[f0:f1]
    cell_start = cc.cell_start[cc.co[w]:cc.co[w + 1]]
    cell_tris = cc.cell_tris[cc.to[w]:cc.to[w + 1]]
    stamp, tris, keys = wk.stamp[f0:f1], wk.tris[f0:f1], wk.keys[f0:f1]
    cand_q, cand_d, cand_f = wk.cand_q[f0:f1], wk.cand_d[f0:f1], wk.cand_f[f0:f1]
    near_p, near_n = wk.near_p[mesh], wk.near_n[mesh]
    near_t, near_d = wk.near_t[mesh], wk.near_d[mesh]
    # room for every row a sphere can have: one call, no retry loop (docs/design-notes.md);
    # only the rows written are touched, mostly one a sphere
    room = idx.shape[0] * MAX_PER_WALL
    rows_f, rows_i = np.empty((room, NF)), np.empty((room, NI), np.int64)
    owner, rank = np.empty(room, np.int64), np.empty(room, np.int64)
    n = mesh_rows_listed(idx, x, cc.radius, R, t, vertices, faces, normals, cc.two_sided[w],
                         cc.msize[w], cc.grid_origin[w], cc.grid_cell[w], cc.grid_dims[w],
                         cell_start, cell_tris, tri_cells, stamp, wk.mark[0] + 1, tris, cand_q,
                         cand_d, cand_f, near_p, near_n, near_t, near_d, keys, MAX_PER_WALL,
                         rows_f, rows_i, owner, rank)
    wk.mark[0] += idx.shape[0]
    return _put(cc, wk, w, x.shape[0] + cc.first + w, c, n, rows_f, owner, rank)


@internal
def _put(cc, wk, w, body, c, n, rows_f, owner, rank):
    """The n rows of rows_f (owner, rank) with wall w (body ``body``) as ``wk``'s contacts
    from c on; returns the new count."""
    for r in range(n):
        wk.out_a[c] = owner[r]
        wk.out_b[c] = body
        for k in range(3):
            wk.out_pa[c, k] = rows_f[r, F_PA + k]
            wk.out_pb[c, k] = rows_f[r, F_PB + k]
            wk.out_normal[c, k] = rows_f[r, F_N + k]
        wk.out_depth[c] = -rows_f[r, F_SD]
        wk.out_key[c] = wall_contact_key(cc.nb, owner[r], w, cc.n_walls, rank[r])
        c += 1
    return c


@internal
def _surface_rows(cc, wk, w, idx, x, R, t, rows_f, owner, rank):
    """The active rows of the spheres idx not certified apart from surface wall w into
    rows_f, owner, rank (their certificates renewed); returns their count."""
    p0, p1, s0, s1 = cc.po[w], cc.po[w + 1], cc.so[w], cc.so[w + 1]
    _advance(wk, w, R, t)
    due = _surface_due(wk, w, idx, x)
    gap = np.zeros(due.shape[0])
    n = _surface_rows_of(due, x, cc.radius, R, t, cc.deg[p0:p1], cc.ncp[p0:p1],
                         cc.koff[p0:p1], cc.knots, cc.pw, cc.poff[p0:p1], cc.dom[p0:p1],
                         cc.periodic[p0:p1], cc.seed_x[s0:s1], cc.seed_p[s0:s1],
                         cc.seed_uv[s0:s1], cc.spacing[w], cc.ssize[w], rows_f, owner, gap)
    for m in range(due.shape[0]):
        i = due[m]
        wk.gap[w, i] = gap[m]
        wk.x0[w, i, 0], wk.x0[w, i, 1], wk.x0[w, i, 2] = x[i, 0], x[i, 1], x[i, 2]
        wk.odo0[w, i] = wk.odo[w]
    rank[:n] = 0
    return n


@internal
def _nurbs_rows(cc, w, idx, pos, rot, R, t, rows_f, owner, rank, n):
    """The active rows of the NURBS particles idx (poses pos, rot) with surface wall w
    appended to rows_f, owner, rank from row n
    (:func:`~nurbsdem.contact.surface_particle_compiled.particle_surface_rows`); returns
    the new count, or −1 where a contact is refused (the Python driver raises)."""
    p0, p1, s0, s1 = cc.po[w], cc.po[w + 1], cc.so[w], cc.so[w + 1]
    K = idx.shape[0]
    rf, ri = np.zeros((K, NF)), np.zeros((K, NI), np.int64)
    status = np.zeros((K, 2), np.int64)
    particle_surface_rows_ptr(idx, cc.body_shape, pos, rot, R, t, cc.ptab, cc.pinfo, cc.pcen,
                              cc.prad, cc.pseeds, cc.deg[p0:p1], cc.ncp[p0:p1],
                              cc.koff[p0:p1], cc.knots, cc.pw, cc.poff[p0:p1], cc.dom[p0:p1],
                              cc.periodic[p0:p1], cc.seed_x[s0:s1], cc.seed_p[s0:s1],
                              cc.seed_uv[s0:s1], cc.spacing[w], cc.ssize[w], rf, ri, status)
    for m in range(K):
        if status[m, 0] == NOT_CONVERGED or status[m, 0] == NOT_UNIQUE:
            return -1
        if status[m, 0] == CONTACT and ri[m, I_ACTIVE] == 1:
            rows_f[n, :] = rf[m, :]
            owner[n] = idx[m]
            rank[n] = 0
            n += 1
    return n


@internal
def _mesh_nurbs_contacts(cc, wk, w, idx, pos, rot, R, t, c):
    """The touching contacts of the NURBS particles idx (poses pos, rot) with mesh wall w
    (:func:`~nurbsdem.contact.mesh_particle_compiled.particle_mesh_rows`, at most
    ``MAX_PER_WALL`` each, keyed by their rank) into ``wk``'s contacts from c on; returns the
    new count."""
    v0, v1, f0, f1 = cc.vo[w], cc.vo[w + 1], cc.fo[w], cc.fo[w + 1]
    room = idx.shape[0] * MAX_PER_WALL
    rows_f, rows_i = np.zeros((room, NF)), np.zeros((room, NI), np.int64)
    owner, rank, count = (np.zeros(room, np.int64), np.zeros(room, np.int64),
                          np.zeros(1, np.int64))
    particle_mesh_rows_ptr(idx, cc.body_shape, pos, rot, R, t, cc.ptab, cc.pinfo, cc.pcen,
                           cc.prad, cc.pseeds, cc.vertices[v0:v1], cc.faces[f0:f1],
                           cc.normals[f0:f1], cc.two_sided[w], cc.msize[w], cc.grid_origin[w],
                           cc.grid_cell[w], cc.grid_dims[w], cc.cell_start[cc.co[w]:cc.co[w + 1]],
                           cc.cell_tris[cc.to[w]:cc.to[w + 1]],
                           cc.feat[cc.mfo[w]:cc.mfo[w + 1]],
                           cc.feat_tris[cc.mlo[w]:cc.mlo[w + 1]], cc.tri_feat_range[f0:f1],
                           cc.tri_feat[cc.mto[w]:cc.mto[w + 1]], MAX_PER_WALL, wk.particle_work,
                           rows_f, rows_i, owner, rank, count)
    return _put(cc, wk, w, pos.shape[0] + cc.first + w, c, count[0], rows_f, owner, rank)


@njit(cache=True)
def curved_contacts(cc, wk, time, x, rot, pos, wall_d) -> None:
    """The particles' contacts with the curved walls at time (s) (centroids x (N,3) m, pose
    rotations rot (N,3,3) and origins pos (N,3) m), the walls displaced by wall_d (W_all,3)
    m, into ``wk``: bodies, points, normals, depths (m) and keys, wall by wall in the
    provider's order (module docstring; a wall's NURBS particles after its spheres),
    ``wk.count[0]`` of them, −1 where a NURBS particle's contact with a surface wall is
    refused (called through a lazy pointer, :data:`curved_contacts_ptr`)."""
    N = x.shape[0]
    c = 0
    mesh = 0
    for w in range(cc.n_walls):
        R, t = wall_pose_at(cc.omega[w], cc.center[w], cc.t0[w], cc.R0[w], cc.shift0[w],
                            time, wall_d[cc.first + w])
        lo, hi = world_box(cc.corners[w], R, t)
        idx = _candidates(x, cc.reach, cc.sphere, lo, hi)
        if cc.kind[w] == MESH_WALL:
            c = _mesh_contacts(cc, wk, w, mesh, idx, x, R, t, c)
            mesh += 1
            more = _candidates(x, cc.reach, cc.nurbs, lo, hi) if cc.n_nurbs else idx[:0]
            if more.shape[0]:
                c = _mesh_nurbs_contacts(cc, wk, w, more, pos, rot, R, t, c)
            continue
        more = _candidates(x, cc.reach, cc.nurbs, lo, hi) if cc.n_nurbs else idx[:0]
        rows_f = np.zeros((idx.shape[0] + more.shape[0] + 1, NF))
        owner = np.zeros(rows_f.shape[0], np.int64)
        rank = np.zeros(rows_f.shape[0], np.int64)
        n = _surface_rows(cc, wk, w, idx, x, R, t, rows_f, owner, rank)
        if more.shape[0]:
            n = _nurbs_rows(cc, w, more, pos, rot, R, t, rows_f, owner, rank, n)
            if n < 0:
                wk.count[0] = -1
                return
        c = _put(cc, wk, w, N + cc.first + w, c, n, rows_f, owner, rank)
    wk.count[0] = c


#: :func:`curved_contacts` through a lazy pointer (group "curved",
#: :func:`~nurbsdem.jit.fill_lazy_kernels`): a scene without mesh or surface walls does not
#: compile it
curved_contacts_ptr = PointerKernel(curved_contacts, "curved_contacts", lazy="curved").call

def with_curved_contacts(cs, wk):
    """The ContactSet ``cs`` of the scene followed by the curved walls' contacts of the last
    :func:`curved_contacts` (in ``wk``), as the provider of
    :mod:`nurbsdem.contact.curved_walls` merges them."""
    from .curved_walls import _merged
    k = int(wk.count[0])
    if k == 0:
        return cs
    rows = np.zeros((k, NF))
    rows[:, F_PA:F_PA + 3] = wk.out_pa[:k]
    rows[:, F_PB:F_PB + 3] = wk.out_pb[:k]
    rows[:, F_N:F_N + 3] = wk.out_normal[:k]
    rows[:, F_SD] = -wk.out_depth[:k]
    return _merged(cs, [(wk.out_a[:k].copy(), wk.out_b[:k].copy(), rows, wk.out_key[:k].copy())])

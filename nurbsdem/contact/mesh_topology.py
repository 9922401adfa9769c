"""The features of a triangle mesh that can hold a contact of their own: its edges and
vertices that are not flat.

An edge whose two triangles lie in one plane on either side of it, and a vertex all of whose
edges are such, have that plane's normal only as their normal cone, so the faces around them
hold every contact; every other edge (a fold, or the mesh's boundary) and every vertex on
one is a feature.  :func:`topology` lists them as the reference solver
(:mod:`nurbsdem.contact.mesh_particle`) walks them; :func:`pack_topology` packs them into
arrays for the compiled one (:mod:`nurbsdem.contact.mesh_particle_compiled`).  Both are
computed once per mesh and dropped with it.  The compiled solver's predicates over the packed
features (a boundary edge; a particle passing the plane beyond one; a vertex that is the
deepest point of one) are here too.
"""
from __future__ import annotations

import math
import weakref
from typing import Callable

import numpy as np

from ..jit import kernel
from .mesh_wall import MeshWall

#: per mesh (by id, with a weak reference to it; dropped with the mesh): its topology, and
#: its packed features
_TOPOLOGY: dict = {}
_PACKED: dict = {}


def _once_per_mesh(cache: dict, mesh: MeshWall, make: Callable[[MeshWall], tuple]) -> tuple:
    """``make(mesh)``, kept in ``cache`` while the mesh lives."""
    hit = cache.get(id(mesh))
    if hit is not None and hit[0]() is mesh:
        return hit[1]
    data = make(mesh)
    cache[id(mesh)] = (weakref.ref(mesh), data)
    weakref.finalize(mesh, cache.pop, id(mesh), None)
    return data


def inward(mesh: MeshWall, tri: int, i: int, j: int) -> np.ndarray:
    """The unit in-plane normal of edge (i, j) of triangle ``tri`` pointing into it."""
    f = mesh.faces[tri]
    x = mesh.vertices[[k for k in f.tolist() if k != i and k != j][0]]
    p0, p1 = mesh.vertices[i], mesh.vertices[j]
    t = (p1 - p0) / np.linalg.norm(p1 - p0)
    w = (x - p0) - ((x - p0) @ t) * t
    return w / np.linalg.norm(w)


def topology(mesh: MeshWall) -> tuple[dict, dict, list, list]:
    """(edges {(i, j) i < j: [triangles]}, vertices {i: [triangles]}, per triangle its keys
    of both) of the mesh's edges and vertices that are not flat (module docstring)."""
    return _once_per_mesh(_TOPOLOGY, mesh, _topology)


def _topology(mesh: MeshWall) -> tuple[dict, dict, list, list]:
    edges: dict = {}
    verts: dict = {}
    for tri, f in enumerate(mesh.faces.tolist()):
        for k in range(3):
            i, j = f[k], f[(k + 1) % 3]
            edges.setdefault((min(i, j), max(i, j)), []).append(tri)
            verts.setdefault(f[k], []).append(tri)
    sharp = {e: tris for e, tris in edges.items()
             if not (len(tris) == 2 and float(inward(mesh, tris[0], *e)
                                              @ inward(mesh, tris[1], *e)) <= -1.0 + 1e-12)}
    bent = {i for e in sharp for i in e}
    corners = {v: tris for v, tris in verts.items() if v in bent}
    tri_edges: list = [[] for _ in range(len(mesh.faces))]
    tri_verts: list = [[] for _ in range(len(mesh.faces))]
    for e, tris in sharp.items():
        for tri in tris:
            tri_edges[tri].append(e)
    for v, tris in corners.items():
        for tri in tris:
            tri_verts[tri].append(v)
    return sharp, corners, tri_edges, tri_verts


def pack_topology(mesh: MeshWall) -> tuple:
    """(feat (F,4), feat_tris (L,), tri_feat_range (T,2), tri_feat (L2,)) int64 arrays of the
    mesh's features (:func:`topology`), in the reference's orders: ``feat`` rows (v0, v1,
    start, end), an edge (v0 < v1) or a vertex (v1 = −1) and the range of its triangles in
    ``feat_tris``; ``tri_feat_range`` the range in ``tri_feat`` of each triangle's features
    (its edges, then its vertices)."""
    return _once_per_mesh(_PACKED, mesh, _packed)


def _packed(mesh: MeshWall) -> tuple:
    sharp, corners, tri_edges, tri_verts = topology(mesh)
    feat, feat_tris, index = [], [], {}
    for key, tris in list(sharp.items()) + list(corners.items()):
        index[key] = len(feat)
        v0, v1 = key if isinstance(key, tuple) else (key, -1)
        feat.append((v0, v1, len(feat_tris), len(feat_tris) + len(tris)))
        feat_tris.extend(tris)
    tri_range, tri_feat = [], []
    for tri in range(len(mesh.faces)):
        ids = [index[e] for e in tri_edges[tri]] + [index[v] for v in tri_verts[tri]]
        tri_range.append((len(tri_feat), len(tri_feat) + len(ids)))
        tri_feat.extend(ids)
    return (np.array(feat, np.int64).reshape(-1, 4), np.array(feat_tris, np.int64),
            np.array(tri_range, np.int64).reshape(-1, 2), np.array(tri_feat, np.int64))


# ------------------------------------------------- predicates over the packed features
@kernel(inline="always")
def is_border(feat, tri_feat_range, tri_feat, tri, i, j):
    """Whether the edge (i, j) of triangle ``tri`` is an edge of the mesh's boundary (a
    feature with one triangle)."""
    lo, hi = min(i, j), max(i, j)
    for r in range(tri_feat_range[tri, 0], tri_feat_range[tri, 1]):
        f = tri_feat[r]
        if feat[f, 0] == lo and feat[f, 1] == hi:
            return feat[f, 3] - feat[f, 2] == 1
    return False


@kernel(inline="always")
def crosses_beyond_border(vertices, faces, normals, feat, tri_feat_range, tri_feat, tri, c, p):
    """The reference's ``_crosses_beyond_border`` (:mod:`nurbsdem.contact.mesh_particle`):
    whether the segment from the centroid c to the deepest point p crosses the plane of
    triangle ``tri`` beyond a border edge."""
    n = normals[tri]
    a = vertices[faces[tri, 0]]
    sc = n[0] * (c[0] - a[0]) + n[1] * (c[1] - a[1]) + n[2] * (c[2] - a[2])
    sp = n[0] * (p[0] - a[0]) + n[1] * (p[1] - a[1]) + n[2] * (p[2] - a[2])
    if not sc * sp < 0.0:
        return False
    s = sc / (sc - sp)
    r0, r1, r2 = c[0] + s * (p[0] - c[0]), c[1] + s * (p[1] - c[1]), c[2] + s * (p[2] - c[2])
    for k in range(3):
        i, j = faces[tri, k], faces[tri, (k + 1) % 3]
        if not is_border(feat, tri_feat_range, tri_feat, tri, i, j):
            continue
        x, y, z = vertices[i], vertices[j], vertices[faces[tri, (k + 2) % 3]]
        e0, e1, e2 = y[0] - x[0], y[1] - x[1], y[2] - x[2]
        w0, w1, w2 = n[1] * e2 - n[2] * e1, n[2] * e0 - n[0] * e2, n[0] * e1 - n[1] * e0
        if w0 * (z[0] - x[0]) + w1 * (z[1] - x[1]) + w2 * (z[2] - x[2]) < 0.0:
            w0, w1, w2 = -w0, -w1, -w2
        if w0 * (r0 - x[0]) + w1 * (r1 - x[1]) + w2 * (r2 - x[2]) < 0.0:
            return True
    return False


@kernel(inline="always")
def deepest_of_a_border_edge(vertices, faces, feat, tri_feat_range, tri_feat, feat_tris, t0,
                              t1, v, d):
    """The reference's ``_deepest_of_a_border_edge`` (:mod:`nurbsdem.contact.mesh_particle`):
    whether vertex v with the contact normal d is the deepest point of a boundary edge
    (v, x) of a triangle of feat_tris[t0:t1] (d · (x − V) ≥ 0) with d in that edge's normal
    arc (d · w ≥ 0, w the unit in-plane normal from the edge into its triangle)."""
    V = vertices[v]
    for m in range(t0, t1):
        tri = feat_tris[m]
        for k in range(3):
            x = faces[tri, k]
            if x == v or not is_border(feat, tri_feat_range, tri_feat, tri, v, x):
                continue
            X = vertices[x]
            e0, e1, e2 = X[0] - V[0], X[1] - V[1], X[2] - V[2]
            if d[0] * e0 + d[1] * e1 + d[2] * e2 < 0.0:
                continue
            ne = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
            w0, w1, w2 = inward_normal(V, e0 / ne, e1 / ne, e2 / ne,
                                       vertices[faces[tri, 0] + faces[tri, 1] + faces[tri, 2]
                                                - v - x])
            if d[0] * w0 + d[1] * w1 + d[2] * w2 >= 0.0:
                return True
    return False


@kernel(inline="always")
def inward_normal(p0, t0, t1, t2, x):
    """The unit in-plane normal of the edge through p0 along the unit (t0, t1, t2) that
    points to x, the triangle's third vertex (the compiled :func:`inward`)."""
    s = t0 * (x[0] - p0[0]) + t1 * (x[1] - p0[1]) + t2 * (x[2] - p0[2])
    w0, w1, w2 = (x[0] - p0[0]) - s * t0, (x[1] - p0[1]) - s * t1, (x[2] - p0[2]) - s * t2
    nw = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    return w0 / nw, w1 / nw, w2 / nw

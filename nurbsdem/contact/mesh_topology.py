"""The features of a triangle mesh that can hold a contact of their own: its edges and
vertices that are not flat.

An edge whose two triangles lie in one plane on either side of it, and a vertex all of whose
edges are such, have that plane's normal only as their normal cone, so the faces around them
hold every contact; every other edge (a fold, or the mesh's boundary) and every vertex on
one is a feature.  :func:`topology` lists them as the reference solver
(:mod:`nurbsdem.contact.mesh_particle`) walks them; :func:`pack_topology` packs them into
arrays for the compiled one (:mod:`nurbsdem.contact.mesh_particle_compiled`).  Both are
computed once per mesh and dropped with it.
"""
from __future__ import annotations

import weakref
from typing import Callable

import numpy as np

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

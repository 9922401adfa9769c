"""Kept lists of nearby triangles (nurbsdem.contact.mesh_wall.mesh_rows_listed): over a
random walk of spheres about a tessellated, bumped plane and a sphere mesh (inside: concave
folds, outside: convex ones), both turning and shifting, the rows found from the lists are
those of the grid at every evaluation, bit for bit and in the same order, whether the lists
are kept, made anew (a restart), or too small to hold the triangles near a sphere; the lists
are kept across most evaluations."""
from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from nurbsdem.contact.kinds import MAX_PER_WALL
from nurbsdem.contact.lcp import F_SD, NF, NI
from nurbsdem.contact.mesh_kind import _mesh_rows_of
from nurbsdem.contact.mesh_wall import (build_mesh_wall, make_lists, make_workspace,
                                        mesh_rows_listed)

from test_mesh_wall import plane_mesh


def _rows(g, idx, x, r, R, t, work, mark, lists=None):
    cap = MAX_PER_WALL * len(idx)
    rf, ri = np.zeros((cap, NF)), np.zeros((cap, NI), np.int64)
    owner, rank = np.zeros(cap, np.int64), np.zeros(cap, np.int64)
    mesh = (g.vertices, g.faces, g.normals, g.two_sided, g.size, g.grid_origin, g.grid_cell,
            g.grid_dims, g.cell_start, g.cell_tris)
    if lists is None:                 # the grid's rows, those touching kept (the provider)
        n = _mesh_rows_of(idx, x, r, R, t, *mesh, work[0], mark, *work[1:], rf, ri, owner,
                          rank)
        keep = rf[:n, F_SD] < 0.0
        return rf[:n][keep], ri[:n][keep], owner[:n][keep], rank[:n][keep]
    n = mesh_rows_listed(idx, x, r, R, t, *mesh, g.tri_cells, work[0], mark, *work[1:], *lists,
                         MAX_PER_WALL, rf, ri, owner, rank)
    return rf[:n], ri[:n], owner[:n], rank[:n]


def test_rows_from_kept_lists_equal_the_grids():
    verts, faces = plane_mesh(16, half=0.5)
    verts[:, 2] = 0.03 * np.sin(9 * verts[:, 0]) * (verts[:, 1] > 0)
    ico = trimesh.creation.icosphere(subdivisions=2, radius=0.4)
    rng = np.random.default_rng(7)
    for g, spread in ((build_mesh_wall(verts, faces, two_sided=False), (0.45, 0.45, 0.09)),
                      (build_mesh_wall(ico.vertices, ico.faces), (0.5, 0.5, 0.5))):
        n = 120
        x = rng.uniform(-1.0, 1.0, (n, 3)) * spread
        r = rng.uniform(0.04, 0.08, n)
        work = make_workspace(g)
        kept, small = make_lists(g, n), make_lists(g, n, room=2)
        mark = made = rows = multi = 0
        for k in range(80):
            if k == 40:
                kept = make_lists(g, n)                            # a restart
            R = Rotation.from_rotvec([0.0005 * k, 0.001 * k, -0.0003 * k]).as_matrix()
            t = np.array([0.0001 * k, -0.0002 * k, 0.0001 * k])
            x = x + rng.normal(0.0, 0.0003, x.shape)
            idx = np.flatnonzero(rng.random(n) < 0.9).astype(np.int64)
            ref = _rows(g, idx, x, r, R, t, work, mark)
            before = kept[0].copy()
            for lists in (kept, small):
                mark += len(idx)
                got = _rows(g, idx, x, r, R, t, work, mark, lists)
                for a, b in zip(got, ref):
                    np.testing.assert_array_equal(a, b)
            made += int(np.any(kept[0][idx] != before[idx], axis=1).sum())
            rows += len(ref[2])
            multi += int((ref[3] > 0).sum())
            mark += len(idx)
        assert rows > 1000 and (multi > 50 or not g.two_sided)   # concave folds inside
        assert 0 < made < 0.2 * 80 * 0.9 * n                      # the lists are kept
        assert (small[1] == -1).any()                             # some overflow the room

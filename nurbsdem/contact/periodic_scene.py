"""A scene's neighbour list and contact rows through the faces of a periodic cell
(:mod:`nurbsdem.contact.periodic`), on the compiled list and dispatch of
:mod:`nurbsdem.contact.listed` with no kernel of their own.

* **List** (:func:`periodic_list`): at each build the centroids are wrapped into the cell
  (:func:`~nurbsdem.contact.periodic.wrap`) and the bodies within the contact reach of a
  periodic face get ghost images (:func:`~nurbsdem.contact.periodic.ghost_images`); the
  compiled :func:`~nurbsdem.contact.listed.scene_list` runs over the bodies and their ghosts
  as one scene of N + G particles (the ghosts take their owners' shapes), and each pair it
  lists becomes (i, j, s): body j's image x_j + s∘L touches body i (L the cell's lengths).
  A pair has one image at most, as the cell is at least twice the reach
  (:func:`~nurbsdem.contact.periodic.check_cell`), so its key stays i·(N+W) + j.
* **Rows** (:func:`image_scene`): the pairs whose body B is an image are solved as pairs with
  an extra particle, B's pose translated by s∘L; the rows (points, normal) are those of the
  image, so body A's frame.  Walls are not repeated: a wall's plane must contain the periodic
  axes (:func:`nurbsdem.wall_checks.check_periodic_walls`).

Units: metres; global body indices particles 0..N-1, walls N..N+W-1.
"""
from __future__ import annotations

import numpy as np

from .listed import scene_list
from .periodic import PeriodicCell, ghost_images


def extended_tables(st, own: np.ndarray):
    """The scene's tables (:class:`~nurbsdem.contact.listed.SceneTables`) with G extra
    particles after the N bodies: copies of the particles ``own`` (G,) (their shapes, sphere
    flags and bounding radii); the walls follow them (indices N+G ...).  Same field types: the
    compiled list and dispatch take them without compiling again."""
    own = np.asarray(own, np.int64)
    G = int(own.shape[0])
    return st._replace(n=st.n + G, nb=st.nb + G,
                       body_shape=np.concatenate((st.body_shape, st.body_shape[own])),
                       is_sphere=np.concatenate((st.is_sphere, st.is_sphere[own])),
                       body_radius=np.concatenate((st.body_radius, st.body_radius[own])))


def periodic_list(st, cell: PeriodicCell, x, pos, R, wall_d, m: float):
    """The neighbour list of wrapped poses (centroids x (N,3), pose positions pos (N,3),
    rotations R (N,3,3), wall displacements wall_d (W,3)) within m (margin plus skin, m):
    (a, b, keys, mask_a, mask_b, shift) sorted by key a·(N+W) + b, shift (L,3) int the image
    of body b that touches body a (module docstring).  Always a full build."""
    N, nb = st.n, st.nb
    L = cell.length
    reach = 2.0 * float(st.body_radius.max()) + m if N else m
    gx, gown, gsft = ghost_images(x, reach, cell)
    G = int(gown.shape[0])
    ext = extended_tables(st, gown)
    x_e = np.ascontiguousarray(np.concatenate((x, gx)))
    pos_e = np.ascontiguousarray(np.concatenate((pos, pos[gown] + gsft * L)))
    R_e = np.ascontiguousarray(np.concatenate((R, R[gown])))
    P = st.n_patches
    a, b, _, ma, mb = scene_list(ext, x_e, pos_e, R_e, np.ascontiguousarray(wall_d, float),
                                 np.ones(N + G, np.bool_), m, np.zeros(0, np.int64),
                                 np.zeros((0, P), np.bool_), np.zeros((0, P), np.bool_),
                                 np.ones(nb + G, np.bool_))
    owner = np.concatenate((np.arange(N), gown))
    shift = np.concatenate((np.zeros((N, 3), np.int64), gsft))
    wall = b >= N + G
    keep = (a < N) | (~wall & (b < N))       # a pair of two ghosts, or a ghost and a wall: a repeat
    a, b, ma, mb, wall = a[keep], b[keep], ma[keep], mb[keep], wall[keep]
    bw = np.where(wall, 0, b)
    i, j = owner[a], np.where(wall, b - G, owner[bw])
    s = np.where(wall[:, None], 0, shift[bw] - shift[a])
    swap = ~wall & (i > j)
    i, j = np.where(swap, j, i), np.where(swap, i, j)
    s = np.where(swap[:, None], -s, s)
    ma, mb = np.where(swap[:, None], mb, ma), np.where(swap[:, None], ma, mb)
    keys = i * nb + j
    ok = i != j
    order = np.lexsort((s[:, 2], s[:, 1], s[:, 0], keys))
    order = order[ok[order]]
    keys = keys[order]
    first = np.ones(keys.shape[0], bool)        # one image per pair (module docstring)
    first[1:] = keys[1:] != keys[:-1]
    sel = order[first]
    return (i[sel], j[sel], keys[first], np.ascontiguousarray(ma[sel]),
            np.ascontiguousarray(mb[sel]), np.ascontiguousarray(s[sel]))


def image_scene(st, cell: PeriodicCell, b: np.ndarray, shift: np.ndarray, pos, R):
    """The dispatch's view of a periodic list (bodies b (L,), image shifts (L,3)): each pair
    whose body B is an image gets an extra particle at B's pose translated by s∘L.  Returns
    (tables, b in the extended numbering, pose positions, rotations)."""
    N = st.n
    img = np.flatnonzero(np.any(shift != 0, axis=1) & (b < N))
    own = b[img]
    G = int(img.shape[0])
    b_e = np.where(b >= N, b + G, b)
    b_e[img] = N + np.arange(G)
    pos_e = np.concatenate((pos, pos[own] + shift[img] * cell.length))
    R_e = np.concatenate((R, R[own]))
    return (extended_tables(st, own), np.ascontiguousarray(b_e, np.int64),
            np.ascontiguousarray(pos_e), np.ascontiguousarray(R_e))

"""Periodic cells in the compiled deck steps (:mod:`nurbsdem.dynamics.deck_steps`): the wrap and
the list build through the cell's faces, the rows of pairs with images, and the image bodies
of the step's parts, compiled, with the operations of the Python driver's scene
(:mod:`nurbsdem.contact.periodic`, :mod:`nurbsdem.contact.periodic_scene`) and system
(:mod:`nurbsdem.dynamics.images`, ``InternalSteps._apply_wrap``) in their order, so that both
drivers give the same bits.

* **Wrap and build** (:func:`wrapped`, :func:`periodic_list`): when the list is stale the
  centroids and pose positions are wrapped into the cell, the list is built over the bodies
  and their ghost images (:func:`ghost_images`) by the compiled
  :func:`~nurbsdem.contact.listed.scene_list`, and each pair keeps the image s∘L of its body B
  (m, L the cell's lengths).  The loop builds inside itself: a periodic pack rebuilds as
  often as an open one, and the build is the compiled list over N + G bodies.
* **Rows** (:func:`image_scene`): pairs whose B is an image are solved with B's pose
  translated by s∘L as an extra particle.
* **Image bodies** (:func:`image_contact_part`, :func:`image_step_start`,
  :func:`image_kick_part`): a contact with an image of B gives that image a row of its own,
  loaded as its owner (:class:`~nurbsdem.dynamics.images.ImageBodies`), so that lever arms and
  the kick's exact work see the image (paper §2.3).

Units: SI (m, kg, s); global body indices particles 0..N-1, walls N..N+W-1.
"""
from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit, types

from ..contact.listed import SceneTables, scene_list_ptr, solve_due_into_ptr
from ..contact.lcp import F_PA, F_PB
from ..jit import PointerKernel, internal
from .images import fold_images as _fold, image_particles as _particles, \
    image_positions as _positions, image_rows as _bodies
from .rigid import omega_world
from .step import (BodyConst, L_EXTERNAL, book_terms, contact_part_kernel,
                   contact_part_ptr, kick_part_ptr, step_start_ptr)

#: a periodic cell as the compiled loop takes it: ``on`` (False: no cell, the other fields
#: unused), the box [lo, hi) (3,) m, its lengths (3,) m and which axes repeat (3,) bool
PeriodicConst = namedtuple("PeriodicConst", "on lo hi length periodic")


def periodic_const(cell) -> PeriodicConst:
    """The :class:`PeriodicConst` of a :class:`~nurbsdem.contact.periodic.PeriodicCell` (None:
    none)."""
    if cell is None:
        return PeriodicConst(False, np.zeros(3), np.ones(3), np.ones(3), np.zeros(3, np.bool_))
    return PeriodicConst(True, np.asarray(cell.lo, float).copy(), np.asarray(cell.hi, float).copy(),
                         np.asarray(cell.length, float).copy(),
                         np.asarray(cell.periodic, np.bool_).copy())


def stored_images(system, cell, K: int, cs) -> tuple[np.ndarray, np.ndarray]:
    """The translations (m) of B's images of a system's stored contacts (K,3) and of the
    separated pairs of its ContactSet ``cs``, as the loop's Evaluation holds them ((0,3) each
    without a periodic cell)."""
    if cell is None:
        return np.zeros((0, 3)), np.zeros((0, 3))
    image = system.contacts.image
    near = np.asarray(getattr(cs, "near_image", np.zeros((0, 3))), float).reshape(-1, 3)
    return (np.ascontiguousarray(image, float) if len(image) == K else np.zeros((K, 3)),
            np.ascontiguousarray(near))


# --------------------------------------------------------------------------- wrap and build
@internal
def wrapped(cell, x: np.ndarray, pos: np.ndarray):
    """Centroids x (N,3) and pose positions pos (N,3) m wrapped into the cell, and the
    translation d (N,3) m taken off them (:func:`~nurbsdem.contact.periodic.wrap`: d = s∘L,
    s the integer shifts)."""
    n = x.shape[0]
    d = np.zeros((n, 3))
    for i in range(n):
        for k in range(3):
            if cell.periodic[k]:
                s = np.int64(np.floor((x[i, k] - cell.lo[k]) / cell.length[k]))
                if x[i, k] - s * cell.length[k] >= cell.hi[k]:   # round-off left it at hi
                    s += 1
                d[i, k] = s * cell.length[k]
    return x - d, pos - d, d


@njit(cache=True)
def wrap_work(mass: np.ndarray, d: np.ndarray, gravity: np.ndarray) -> float:
    """The potential's jump Σ m g·d (J) of the translations d (N,3) m taken off the centroids
    (masses kg, gravity m/s²), summed in body order (both drivers book it)."""
    total = 0.0
    for i in range(mass.shape[0]):
        total += mass[i] * (d[i, 0] * gravity[0] + d[i, 1] * gravity[1] + d[i, 2] * gravity[2])
    return total


@internal
def apply_wrap(x: np.ndarray, d: np.ndarray, mass: np.ndarray, gravity: np.ndarray,
               initial: float, exact: np.ndarray) -> bool:
    """The build's wrap d (N,3) m applied to the centroids x in place and its jump booked as
    external work in the ledger's accumulators ``exact``
    (:func:`~nurbsdem.dynamics.step.book_terms`, ``InternalSteps._apply_wrap``).  False
    (nothing changed) before the initial mechanical energy ``initial`` (J) is taken (NaN):
    the Python driver books it."""
    if d.shape[0] == 0 or not np.any(d != 0.0):
        return True
    if initial != initial:
        return False
    jump = wrap_work(mass, d, gravity)
    for i in range(x.shape[0]):
        for k in range(3):
            x[i, k] -= d[i, k]
    book_terms(exact, L_EXTERNAL, np.array([jump]))
    return True


@internal
def ghost_images(x: np.ndarray, reach: float, cell):
    """The images of wrapped centroids x (N,3) within ``reach`` (m) of a periodic face: their
    positions (M,3), owners (M,) and shifts (M,3) int, in the order of
    :func:`~nurbsdem.contact.periodic.ghost_images`."""
    n = x.shape[0]
    total = 0
    choices = np.zeros((3, 3), np.int64)
    count = np.ones(3, np.int64)
    for a in range(3):
        if cell.periodic[a]:
            choices[a, 0], choices[a, 1], choices[a, 2] = -1, 0, 1
            count[a] = 3
    keep = np.empty((27, n), np.bool_)
    shifts = np.zeros((27, 3), np.int64)
    m = 0
    for i0 in range(count[0]):
        for i1 in range(count[1]):
            for i2 in range(count[2]):
                s = np.array([choices[0, i0], choices[1, i1], choices[2, i2]])
                if s[0] == 0 and s[1] == 0 and s[2] == 0:
                    continue
                shifts[m] = s
                for i in range(n):
                    k = True
                    for a in range(3):
                        if s[a] > 0:
                            k = k and x[i, a] < cell.lo[a] + reach
                        elif s[a] < 0:
                            k = k and x[i, a] >= cell.hi[a] - reach
                    keep[m, i] = k
                    if k:
                        total += 1
                m += 1
    gx = np.empty((total, 3))
    gown = np.empty(total, np.int64)
    gsft = np.empty((total, 3), np.int64)
    g = 0
    for c in range(m):
        for i in range(n):
            if keep[c, i]:
                for a in range(3):
                    gx[g, a] = x[i, a] + shifts[c, a] * cell.length[a]
                    gsft[g, a] = shifts[c, a]
                gown[g] = i
                g += 1
    return gx, gown, gsft


@internal
def extended_tables(st, own: np.ndarray):
    """The scene's tables with G extra particles after the N bodies, copies of the particles
    ``own`` (G,) (:func:`~nurbsdem.contact.periodic_scene.extended_tables`)."""
    G = own.shape[0]
    return SceneTables(st.tab, st.info, st.centroid, st.radius, st.seeds, st.nonconvexity,
                       np.concatenate((st.body_shape, st.body_shape[own])),
                       np.concatenate((st.is_sphere, st.is_sphere[own])), st.sphere_center,
                       st.sphere_radius, st.wall_origin, st.wall_a, st.wall_b, st.wall_dom,
                       st.n + G, st.point_surface,
                       np.concatenate((st.body_radius, st.body_radius[own])), st.boxes,
                       st.box_offsets, st.n_patches, st.wall_center, st.wall_axes, st.wall_half,
                       st.depth_wall, st.nb + G)


@internal
def _lexsorted(keys: np.ndarray, s: np.ndarray) -> np.ndarray:
    """``np.lexsort((s[:, 2], s[:, 1], s[:, 0], keys))``: stable, keys first."""
    order = np.arange(keys.shape[0])
    for c in (2, 1, 0):
        col = s[:, c].copy()
        order = order[np.argsort(col[order], kind="mergesort")]
    return order[np.argsort(keys[order], kind="mergesort")]


@internal
def periodic_list(st, cell, x, pos, R, wall_d, m: float):
    """The neighbour list through the cell at the wrapped poses (centroids x, pose positions
    pos (N,3) m, rotations R, walls wall_d (W,3) m) within m (margin plus skin, m):
    (a, b, keys, mask_a, mask_b, shift (L,3) int), sorted by key
    (:func:`~nurbsdem.contact.periodic_scene.periodic_list`, the same operations)."""
    N, nb = st.n, st.nb
    L = cell.length
    reach = 2.0 * st.body_radius.max() + m if N else m
    gx, gown, gsft = ghost_images(x, reach, cell)
    G = gown.shape[0]
    ext = extended_tables(st, gown)
    pos_g = np.empty((G, 3))
    for g in range(G):
        for k in range(3):
            pos_g[g, k] = pos[gown[g], k] + gsft[g, k] * L[k]
    P = st.n_patches
    a, b, _, ma, mb = scene_list_ptr(ext, np.concatenate((x, gx)),
                                     np.concatenate((pos, pos_g)),
                                     np.concatenate((R, R[gown])), wall_d,
                                     np.ones(N + G, np.bool_), m, np.zeros(0, np.int64),
                                     np.zeros((0, P), np.bool_), np.zeros((0, P), np.bool_),
                                     np.ones(nb + G, np.bool_))
    # a pair of two ghosts, or a ghost and a wall, repeats a real one
    keep = np.flatnonzero((a < N) | ((b < N + G) & (b < N)))
    K = keep.shape[0]
    i = np.empty(K, np.int64)
    j = np.empty(K, np.int64)
    s = np.zeros((K, 3), np.int64)
    ma2 = np.empty((K, ma.shape[1]), np.bool_)
    mb2 = np.empty((K, mb.shape[1]), np.bool_)
    for r in range(K):
        c = keep[r]
        ac, bc = a[c], b[c]
        wall = bc >= N + G
        i[r] = ac if ac < N else gown[ac - N]
        j[r] = bc - G if wall else (bc if bc < N else gown[bc - N])
        if not wall:
            for k in range(3):
                sb = gsft[bc - N, k] if bc >= N else 0
                sa = gsft[ac - N, k] if ac >= N else 0
                s[r, k] = sb - sa
        ma2[r], mb2[r] = ma[c], mb[c]
        if not wall and i[r] > j[r]:
            i[r], j[r] = j[r], i[r]
            for k in range(3):
                s[r, k] = -s[r, k]
            ma2[r], mb2[r] = mb[c], ma[c]
    keys = i * nb + j
    order = _lexsorted(keys, s)
    order = order[(i != j)[order]]
    keys = keys[order]
    first = np.ones(keys.shape[0], np.bool_)        # one image per pair
    first[1:] = keys[1:] != keys[:-1]
    sel = order[first]
    return (i[sel], j[sel], keys[first], ma2[sel], mb2[sel], s[sel])


@internal
def shift_rows(rows_f: np.ndarray, a: np.ndarray, d: np.ndarray) -> None:
    """The rows' points moved with body A by the wrap d (N,3) m (a row's points lie in A's
    frame), in place."""
    for r in range(a.shape[0]):
        for k in range(3):
            rows_f[r, F_PA + k] -= d[a[r], k]
        for k in range(3):
            rows_f[r, F_PB + k] -= d[a[r], k]


@internal
def image_scene(st, cell, b: np.ndarray, shift: np.ndarray, pos: np.ndarray, R: np.ndarray):
    """The dispatch's view of the periodic list (bodies b (L,), image shifts (L,3) int): each
    pair whose B is an image has an extra particle at B's pose translated by s∘L (m).  Returns
    (tables, b in the extended numbering, pose positions, rotations)
    (:func:`~nurbsdem.contact.periodic_scene.image_scene`)."""
    N = st.n
    img = np.flatnonzero(((shift[:, 0] != 0) | (shift[:, 1] != 0) | (shift[:, 2] != 0))
                         & (b < N))
    own = b[img]
    G = img.shape[0]
    b_e = np.where(b >= N, b + G, b)
    pos_g = np.empty((G, 3))
    for g in range(G):
        b_e[img[g]] = N + g
        for k in range(3):
            pos_g[g, k] = pos[own[g], k] + shift[img[g], k] * cell.length[k]
    return (extended_tables(st, own), b_e, np.concatenate((pos, pos_g)),
            np.concatenate((R, R[own])))


@internal
def solve_images(st, cell, a, b, mask_a, mask_b, rows_f, rows_i, due, shift, pos, R, wall_d,
                 threads: int):
    """The rows ``due`` of the periodic list solved in place with B's images as extra
    particles (:func:`image_scene`).  Returns (pairs solved by the point solver, whether an
    LCP failed)."""
    st_e, b_e, pos_e, R_e = image_scene(st, cell, b, shift, pos, R)
    return solve_due_into_ptr(st_e, a, b_e, mask_a, mask_b, rows_f, rows_i, due, pos_e, R_e,
                              wall_d, threads)


@internal
def pair_images(cell, shift: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """The translation s∘L (m) of B's image for the list positions ``rows`` ((0,3) without a
    cell)."""
    if not cell.on:
        return np.zeros((0, 3))
    out = np.empty((rows.shape[0], 3))
    for r in range(rows.shape[0]):
        for k in range(3):
            out[r, k] = shift[rows[r], k] * cell.length[k]
    return out


# --------------------------------------------------------------------------- image bodies
@internal
def has_images(image: np.ndarray) -> bool:
    """Whether a contact touches an image (a non-zero translation)."""
    for c in range(image.shape[0]):
        for k in range(3):
            if image[c, k] != 0.0:
                return True
    return False


@internal
def image_bodies(n: int, b: np.ndarray, image: np.ndarray):
    """(own (G,), offset (G,3) m, body B of each contact in the extended numbering) of the
    contacts whose B is a particle's image (:class:`~nurbsdem.dynamics.images.ImageBodies`)."""
    idx = np.flatnonzero(((image[:, 0] != 0.0) | (image[:, 1] != 0.0) | (image[:, 2] != 0.0))
                         & (b < n))
    own = b[idx]
    offset = np.empty((idx.shape[0], 3))
    for g in range(idx.shape[0]):
        offset[g] = image[idx[g]]
    G = idx.shape[0]
    b_ext = np.where(b >= n, b + G, b)
    for g in range(G):
        b_ext[idx[g]] = n + g
    return own, offset, b_ext


@internal
def _const(bc, own, n: int):
    """The step's constants with the image bodies' rows."""
    return BodyConst(_particles(bc.mass, own), _particles(bc.inv_mass, own),
                     _particles(bc.inv_I, own), _particles(bc.P, own),
                     _particles(bc.centroid, own), _particles(bc.ell, own),
                     _bodies(bc.inv_mass_all, own, n), _bodies(bc.material, own, n), bc.table,
                     bc.gravity, bc.g_norm, _particles(bc.alt_floor_x, own),
                     _particles(bc.alt_floor_L, own), _particles(bc.sq_m, own),
                     _particles(bc.sq_I, own))


@internal
def image_contact_part(bc, implicit, a, b, pa, pb, nrm, dep, key, radius, hist_keys,
                       hist_springs, pos, vel, omg, q, L, h, solves, image):
    """:func:`~nurbsdem.dynamics.step.contact_part` (bodies' pos, vel, omg (B,3)), with the
    image bodies of the contacts whose B is an image (``image`` (K,3) m, some non-zero: the
    compiled loop's evaluation calls ``contact_part`` itself when none is), their loads
    folded onto their owners (the Python driver's ``_evaluate``)."""
    n = q.shape[0]
    own, offset, b_ext = image_bodies(n, b, image)
    pos_e = np.concatenate((pos[:n], pos[own] + offset, pos[n:]))
    (force, torque, point, ftot, fdn, fdt, fet, fn, eel, stick, coeffs, slip, keys, springs,
     repeated) = contact_part_ptr(_const(bc, own, n), implicit, a, b_ext, pa, pb, nrm, dep,
                                  key, radius, hist_keys, hist_springs, pos_e,
                                  _bodies(vel, own, n), _bodies(omg, own, n),
                                  _particles(q, own), _particles(L, own), h, solves,
                                  np.zeros(0), own)
    return (_fold(force, own, n), _fold(torque, own, n), point, ftot, fdn, fdt, fet, fn, eel,
            stick, coeffs, slip, keys, springs, repeated)


@internal
def image_step_start(bc, ev, x, v, q, L, wall_d, u_mean, h, exact,
                     alt_prev_v, alt_prev_L, alt_count, watch):
    """:func:`~nurbsdem.dynamics.step.step_start` with the stored contacts' image bodies
    (walls that do not turn): the particles and their images kicked, watched and drifted
    together, the particles' rows written back (``InternalSteps._step_start_images``).
    Returns (ω (N,3) rad/s after the drift, the particle with the longest run of reversals or
    −1, that run)."""
    n = x.shape[0]
    own, offset, b_ext = image_bodies(n, ev.b, ev.image)
    bc_e = _const(bc, own, n)
    x_e, v_e, q_e, L_e = _positions(x, own, offset), _particles(v, own), _particles(q, own), \
        _particles(L, own)
    pv, pL, count = _particles(alt_prev_v, own), _particles(alt_prev_L, own), \
        _particles(alt_count, own)
    omega, worst, run = step_start_ptr(
        bc_e, ev.a, b_ext, ev.point, ev.ftot, ev.fdn, ev.fdt, ev.fet, _bodies(ev.force, own, n),
        _bodies(ev.torque, own, n), x_e, v_e, q_e, L_e, omega_world(q_e, L_e, bc_e.inv_I), b_ext,
        wall_d, u_mean, np.zeros((wall_d.shape[0], 3)), h, exact,
        np.zeros(0, np.bool_), pv, pL, count, watch)
    x[:] = x_e[:n]
    v[:] = v_e[:n]
    q[:] = q_e[:n]
    L[:] = L_e[:n]
    alt_prev_v[:] = pv[:n]
    alt_prev_L[:] = pL[:n]
    alt_count[:] = count[:n]
    if worst >= n:
        worst = own[worst - n]
    return omega[:n].copy(), worst, run


@internal
def image_kick_part(bc, ev, x, v, q, L, wall_d, u_mean, hk, exact):
    """:func:`~nurbsdem.dynamics.step.kick_part` of length hk (s) with the stored contacts'
    image bodies, the particles' velocities and momenta written back.  Returns ω (N,3)
    rad/s after the kick."""
    n = x.shape[0]
    own, offset, b_ext = image_bodies(n, ev.b, ev.image)
    bc_e = _const(bc, own, n)
    v_e, q_e, L_e = _particles(v, own), _particles(q, own), _particles(L, own)
    omega = kick_part_ptr(bc_e, ev.a, b_ext, ev.point, ev.ftot, ev.fdn, ev.fdt, ev.fet,
                          _bodies(ev.force, own, n), _bodies(ev.torque, own, n),
                          _positions(x, own, offset), v_e, q_e, L_e,
                          omega_world(q_e, L_e, bc_e.inv_I), b_ext, wall_d, u_mean,
                          np.zeros((wall_d.shape[0], 3)), hk, exact,
                          np.zeros(0, np.bool_))
    v[:] = v_e[:n]
    L[:] = L_e[:n]
    return omega[:n].copy()


@internal
def network_images(image, near_image, near_a, near_b, a, b) -> np.ndarray:
    """The translation (M,3) m of B's image for each pair (a, b) of the time-step control's
    network: its K contacts (``image``) then the separated pairs it took, a subsequence of
    (near_a, near_b) (``near_image``) (the Python driver's ``_network_images``; zeros where
    there is no image, which subtract nothing from a lever arm)."""
    M = a.shape[0]
    out = np.zeros((M, 3))
    K = image.shape[0]
    if K == 0 and near_image.shape[0] == 0:
        return out
    for c in range(min(K, M)):
        out[c] = image[c]
    r = 0
    for c in range(K, M):
        while near_a[r] != a[c] or near_b[r] != b[c]:
            r += 1
        out[c] = near_image[r]
        r += 1
    return out


# --------------------------------------------------------------------------- called lazily
# The compiled loop calls the cell's larger kernels through pointers of the lazy group
# "periodic" (:class:`~nurbsdem.jit.PointerKernel`): a scene without a cell never compiles
# them, and the loop and its evaluation are typed with the results declared here.
_I1, _I2 = types.int64[::1], types.int64[:, ::1]
_F2, _B2 = types.float64[:, ::1], types.boolean[:, ::1]


def _contact_part_result(argtypes: tuple) -> types.Type:
    """What :func:`image_contact_part` returns: :func:`~nurbsdem.dynamics.step.contact_part`'s
    result for its arguments without images."""
    return contact_part_kernel.fill(argtypes[:-1] + (types.float64[::1], _I1))


#: :func:`periodic_list` through a lazy pointer: (a, b, keys, mask_a, mask_b, shift)
periodic_list_ptr = PointerKernel(
    periodic_list, "periodic_list", lazy="periodic",
    result=lambda argtypes: types.Tuple((_I1, _I1, _I1, _B2, _B2, _I2))).call
#: :func:`solve_images` through a lazy pointer: (pairs of the point solver, an LCP failed)
solve_images_ptr = PointerKernel(
    solve_images, "solve_images", lazy="periodic",
    result=lambda argtypes: types.Tuple((types.int64, types.boolean))).call
#: :func:`image_contact_part` through a lazy pointer
image_contact_part_ptr = PointerKernel(image_contact_part, "image_contact_part",
                                       lazy="periodic", result=_contact_part_result).call
#: :func:`image_step_start` through a lazy pointer: (ω, particle, run)
image_step_start_ptr = PointerKernel(
    image_step_start, "image_step_start", lazy="periodic",
    result=lambda argtypes: types.Tuple((_F2, types.int64, types.int64))).call
#: :func:`image_kick_part` through a lazy pointer: ω
image_kick_part_ptr = PointerKernel(image_kick_part, "image_kick_part", lazy="periodic",
                                    result=lambda argtypes: _F2).call

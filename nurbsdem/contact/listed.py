"""The neighbour list of a scene and the contact rows of its pairs due at an evaluation, in
compiled code (shared by :class:`nurbsdem.contact.scene.SceneContacts` and the compiled deck
steps of :mod:`nurbsdem.dynamics.deck_steps`).

:func:`scene_list` builds the list with its skin (paper 3.1, levels 1–2): bounding spheres,
then for each pair of NURBS bodies the patch boxes, whose overlaps become the pair's candidate
patches (masks that direct a cold start); exact spheres need no boxes.

Then the pairs of the list that are not certified apart (``due``) get their rows from
:func:`solve_due_into`, in place in the list's rows (:func:`solve_due`: the scene's entry
to it), each by what its shapes are (the scene's module docstring):

* exact sphere against exact sphere or a flat wall: the closed forms
  (:mod:`nurbsdem.contact.sphere`);
* exact sphere against a NURBS particle: the point-to-surface problem of the same module
  (when the scene allows it); the pairs it leaves go to
  the LCP, a row of the point solver not counting as its warm start;
* NURBS against NURBS: the LCP batch of :mod:`nurbsdem.contact.detect` (paper Sec. 3.2), warm
  started from the previous row, directed by the pair's candidate patches (paper 3.1);
* NURBS against a flat wall: the support-mapping kernel of :mod:`nurbsdem.contact.flat_wall`.

A warm-started LCP that did not converge is solved once more from a cold start before it
counts as failed (a warm start can stall in the flat valley of a near-touching pair).  The
failed rows that remain are left to the scene (moved solution or left out, once).

The kernels and their inputs are those of the per-pair functions (``detect_batch``,
``detect_wall_batch``, ``sphere_nurbs_rows``): the rows are the same to the bit; only the
Python around them, per pair kind and evaluation, is gone.  Units: metres; rows in the
column layout of :mod:`nurbsdem.contact.lcp`; global body indices (particles 0..N-1, walls
N..N+W-1).
"""
from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit, types

from ..jit import PointerKernel
from .boxes import candidate_patch_masks_batch_jit, candidate_patches_wall_batch_jit
from .broadphase import ALL_PAIRS_MAX, sphere_pairs_jit, sphere_pairs_of
from .detect import solve_rows
from .flat_wall import solve_wall_rows, sphere_wall_pairs_jit
from .kinds import (CLOSED_FORM, FLAT_WALL, LCP, NURBS_PARTICLE, POINT_SURFACE, SPHERE,
                    WALL_SUPPORT, pair_solver)
from .lcp import I_FAIL, NF, NI, bounding_spheres_apart, warm_start
from .sphere import closed_form_into, sphere_centres, sphere_nurbs_rows
from .verlet import merge_find

#: the scene's constant tables: the packed shapes (:class:`~nurbsdem.contact.detect.ContactTable`:
#: tab, info, centroid, radius, seeds, nonconvexity), the bodies' shapes, the exact spheres
#: and the flat walls' frames; n particles; point_surface: spheres against NURBS by the point
#: solver
SceneTables = namedtuple("SceneTables", "tab info centroid radius seeds nonconvexity body_shape "
                         "is_sphere sphere_center sphere_radius wall_origin wall_a wall_b "
                         "wall_dom n point_surface body_radius boxes box_offsets n_patches "
                         "wall_center wall_axes wall_half depth_wall nb")


def scene_tables(scene) -> SceneTables:
    """The :class:`SceneTables` of a :class:`~nurbsdem.contact.scene.SceneContacts`."""
    t = scene.table
    return SceneTables(t.tab, t.info, t.centroid, t.radius, t.seeds, t.nonconvexity,
                       scene.body_shape, np.ascontiguousarray(scene.is_sphere, np.bool_),
                       np.ascontiguousarray(scene.sphere_center, float),
                       np.ascontiguousarray(scene.sphere_radius, float), scene.wall_origin,
                       scene.wall_a, scene.wall_b, scene.wall_dom, scene.n,
                       scene.point_surface, np.ascontiguousarray(scene.radius, float),
                       np.ascontiguousarray(scene.boxes, float),
                       np.ascontiguousarray(scene.box_offsets, np.int64), scene.P,
                       np.ascontiguousarray(scene.wall_center, float),
                       np.ascontiguousarray(scene.wall_axes, float),
                       np.ascontiguousarray(scene.wall_half[:, :2], float),
                       float(scene.depth_wall), scene.nb)


# --------------------------------------------------------------------------- the list
#: a rebuild searches the bounding spheres of the renewed bodies only while they are at most
#: this fraction of the bodies (beyond it the grid's own half-shell pass over all is faster)
PARTIAL_SEARCH_MAX = 0.3


@njit(cache=True)
def _kept_body_pairs(old_keys, nb, n, fresh):
    """The body pairs (rows (a, b), sorted) of the old list whose two bodies are not
    ``fresh``."""
    count = 0
    for key in old_keys:
        a, b = key // nb, key % nb
        if b < n and not fresh[a] and not fresh[b]:
            count += 1
    out = np.empty((count, 2), np.int64)
    k = 0
    for key in old_keys:
        a, b = key // nb, key % nb
        if b < n and not fresh[a] and not fresh[b]:
            out[k, 0], out[k, 1] = a, b
            k += 1
    return out


@njit(cache=True)
def _merge_pairs(p, q):
    """Two disjoint sorted lists of pairs (rows (a, b)) as one sorted list."""
    out = np.empty((p.shape[0] + q.shape[0], 2), np.int64)
    i = j = 0
    for k in range(out.shape[0]):
        take_p = j == q.shape[0] or (i < p.shape[0] and (p[i, 0] < q[j, 0] or (
            p[i, 0] == q[j, 0] and p[i, 1] < q[j, 1])))
        if take_p:
            out[k, 0], out[k, 1] = p[i, 0], p[i, 1]
            i += 1
        else:
            out[k, 0], out[k, 1] = q[j, 0], q[j, 1]
            j += 1
    return out


@njit(cache=True)
def _body_pairs(st, x, m, old_keys, fresh):
    """The body pairs whose bounding spheres at the built centroids x (N,3) are within m of
    each other (:func:`~nurbsdem.contact.broadphase.sphere_pairs_jit`, sorted) — or, where a
    rebuild renews few bodies (``fresh``, at most :data:`PARTIAL_SEARCH_MAX` of them), those
    that :func:`scene_list` can still list: the pairs with a renewed body, searched anew, and
    the old list's pairs of two kept bodies, whose verdict stands (their built poses and m
    are those of the old list's build; a sphere pair of two kept bodies missing from the old
    list was left out there, by its boxes, and would be again)."""
    N = st.n
    n_fresh = 0
    for i in range(N):
        n_fresh += fresh[i]
    if N <= ALL_PAIRS_MAX or n_fresh > PARTIAL_SEARCH_MAX * N:
        return sphere_pairs_jit(x, st.body_radius, m) if N > 1 else np.zeros((0, 2), np.int64)
    return _merge_pairs(sphere_pairs_of(x, st.body_radius, m, fresh[:N]),
                        _kept_body_pairs(old_keys, st.nb, N, fresh))


@njit(cache=True)
def _directed(st, pairs, pos, R, m, old_keys, old_mask_a, old_mask_b, fresh):
    """The NURBS body pairs (sorted, as :func:`~nurbsdem.contact.broadphase.sphere_pairs_jit`
    gives them) whose patch boxes overlap (within m), with their candidate patches as (K, P)
    masks (paper 3.1).  Only the pairs with a ``fresh`` body are tested; the others keep the
    old list's masks, or stay out of it (:func:`scene_list`)."""
    K, P = pairs.shape[0], st.n_patches
    keep = np.zeros(K, np.bool_)
    mask_a = np.zeros((K, P), np.bool_)
    mask_b = np.zeros((K, P), np.bool_)
    tested = np.empty(K, np.int64)
    n_tested = 0
    o = np.int64(0)             # pairs and old keys both sorted: a merge
    for r in range(K):
        i, j = pairs[r, 0], pairs[r, 1]
        if fresh[i] or fresh[j]:
            tested[n_tested] = r
            n_tested += 1
            continue
        o, listed = merge_find(old_keys, o, i * st.nb + j)
        if listed:
            keep[r] = True
            mask_a[r, :] = old_mask_a[o, :]
            mask_b[r, :] = old_mask_b[o, :]
    if n_tested:
        tested = tested[:n_tested]
        kt, mat, mbt = candidate_patch_masks_batch_jit(st.boxes, st.box_offsets, st.body_shape,
                                                       pos, R, pairs[tested], m, P)
        for s in range(n_tested):
            r = tested[s]
            keep[r] = kt[s]
            mask_a[r, :] = mat[s, :]
            mask_b[r, :] = mbt[s, :]
    return pairs[keep], mask_a[keep], mask_b[keep]


@njit(cache=True)
def _wall_candidates(st, x, pos, R, wall_d, owned, m, old_keys, fresh):
    """(body, wall) pairs within reach of each other: exact spheres by their bounding sphere,
    NURBS bodies when a patch box reaches the wall (tested for the pairs with a ``fresh``
    body or wall only; the others as in the old list, :func:`scene_list`)."""
    N = st.n
    wc = st.wall_center + wall_d
    wp = sphere_wall_pairs_jit(x, st.body_radius, wc, st.wall_axes, st.wall_half, m)
    mine = np.zeros(wp.shape[0], np.bool_)
    for r in range(wp.shape[0]):
        mine[r] = owned[wp[r, 0]]
    wp = wp[mine]
    ball = np.zeros(wp.shape[0], np.bool_)
    for r in range(wp.shape[0]):
        ball[r] = st.is_sphere[wp[r, 0]]
    balls, wp = wp[ball], wp[~ball]
    keep = np.zeros(wp.shape[0], np.bool_)
    test = np.zeros(wp.shape[0], np.bool_)
    o = np.int64(0)             # pairs (body-major) and old keys both sorted: a merge
    for r in range(wp.shape[0]):
        i, w = wp[r, 0], wp[r, 1]
        test[r] = fresh[i] or fresh[N + w]
        if not test[r]:
            o, listed = merge_find(old_keys, o, i * st.nb + N + w)
            keep[r] = listed
    tested = wp[test]
    if tested.shape[0]:
        cand = candidate_patches_wall_batch_jit(st.boxes, st.box_offsets, st.body_shape, pos, R,
                                                wc, st.wall_axes, st.wall_half, tested, m,
                                                st.depth_wall)
        idx = np.nonzero(test)[0]
        for c in range(cand.shape[0]):
            keep[idx[cand[c, 0]]] = True
    return np.concatenate((wp[keep], balls))


@njit(cache=True)
def scene_list(st, x, pos, R, wall_d, owned, m, old_keys, old_mask_a, old_mask_b, fresh):
    """The neighbour list: (a, b, keys, mask_a, mask_b) sorted by key a·(N+W) + b, of the
    pairs within m (the margin plus the skin, m) of each other with a body this rank owns
    (``owned`` (N,) bool; all True on one rank), at the poses x (N,3) centroids, pos (N,3) and
    R (N,3,3), wall_d (W,3) the walls' displacements (m): each body's built pose.

    A rebuild tests the patch boxes (level 2) only of the pairs with a ``fresh`` body (N+W,)
    bool, those whose built pose changed (:func:`~nurbsdem.contact.verlet.reposed_bodies`):
    any other pair has the poses and m of the old list's build (old_keys sorted, old_mask_a,
    old_mask_b), so it is listed with the old masks if the old list held it and left out if
    not, the same bits as testing it again; the bounding spheres (level 1) likewise, where
    few bodies are fresh (:func:`_body_pairs`).  A full build: ``fresh`` all True.  (An MPI
    rank builds in full after its owned particles changed: its old list lacks the pairs of
    particles it did not own.)"""
    N, P = st.n, st.n_patches
    pairs = _body_pairs(st, x, m, old_keys, fresh)
    mine = np.zeros(pairs.shape[0], np.bool_)
    both = np.zeros(pairs.shape[0], np.bool_)
    for r in range(pairs.shape[0]):
        mine[r] = owned[pairs[r, 0]] or owned[pairs[r, 1]]
        both[r] = st.is_sphere[pairs[r, 0]] and st.is_sphere[pairs[r, 1]]
    spheres, pairs = pairs[mine & both], pairs[mine & ~both]
    mask_a = np.zeros((0, P), np.bool_)
    mask_b = np.zeros((0, P), np.bool_)
    if pairs.shape[0]:
        pairs, mask_a, mask_b = _directed(st, pairs, pos, R, m, old_keys, old_mask_a,
                                          old_mask_b, fresh)
    wpairs = np.zeros((0, 2), np.int64)
    if st.wall_center.shape[0] and N:
        wpairs = _wall_candidates(st, x, pos, R, wall_d, owned, m, old_keys, fresh)
    K, S, W = pairs.shape[0], spheres.shape[0], wpairs.shape[0]
    a = np.empty(K + S + W, np.int64)
    b = np.empty(K + S + W, np.int64)
    a[:K], b[:K] = pairs[:, 0], pairs[:, 1]
    a[K:K + S], b[K:K + S] = spheres[:, 0], spheres[:, 1]
    a[K + S:], b[K + S:] = wpairs[:, 0], N + wpairs[:, 1]
    ma = np.ones((K + S + W, P), np.bool_)
    mb = np.ones((K + S + W, P), np.bool_)
    ma[:K], mb[:K] = mask_a, mask_b
    keys = a * st.nb + b
    order = np.argsort(keys, kind="mergesort")
    return a[order], b[order], keys[order], ma[order], mb[order]


# --------------------------------------------------------------------------- the due rows
@njit(cache=True, inline="always")
def _solve_into(st, list_a, list_b, mask_a, mask_b, pos, R, wall_d, rows_f, rows_i, idx, nt,
                walls) -> None:
    """The rows idx of the list (bodies list_a[j], list_b[j], candidate patches mask_a[j],
    mask_b[j]) solved in place from the previous rows they hold: the LCP batch
    (:func:`nurbsdem.contact.detect.solve_rows`), or with ``walls`` the particles against the
    walls list_b[j] − n (:func:`nurbsdem.contact.flat_wall.solve_wall_rows`; masks unused)."""
    if walls:
        solve_wall_rows(st.tab, st.info, st.centroid, st.radius, st.seeds, st.body_shape, pos,
                        R, list_a, list_b, st.n, idx, st.wall_origin + wall_d, st.wall_a,
                        st.wall_b, st.wall_dom, rows_f, rows_i, nt)
    else:
        solve_rows(st.tab, st.info, st.centroid, st.radius, st.seeds, st.nonconvexity,
                   st.body_shape, pos, R, list_a, list_b, idx, mask_a, mask_b, rows_f, rows_i,
                   nt)


@njit(cache=True)
def _retry_cold(rows_i, idx, warm):
    """The rows of idx whose warm start (``warm`` (K,): the row held a previous solution)
    failed: list positions, to be solved again from a cold start."""
    again = np.empty(idx.shape[0], np.int64)
    n = 0
    for k in range(idx.shape[0]):
        if rows_i[idx[k], I_FAIL] == 1 and warm[k]:
            again[n] = idx[k]
            n += 1
    return again[:n]


@njit(cache=True)
def _take_converged(rows_f, rows_i, again, cf, ci) -> None:
    """Rows of the cold retry (cf, ci: one per list position in ``again``) that converged
    replace the failed warm ones."""
    for r in range(again.shape[0]):
        if ci[r, I_FAIL] == 0:
            rows_f[again[r]] = cf[r]
            rows_i[again[r]] = ci[r]


@njit(cache=True, inline="always")
def _solve_retried_into(st, list_a, list_b, mask_a, mask_b, pos, R, wall_d, rows_f, rows_i,
                        idx, nt, walls) -> None:
    """:func:`_solve_into`, then the rows whose warm start failed solved once more cold (a
    warm start can stall where a cold one does not, e.g. in the flat valley of a
    near-touching pair): a cold solution that converged replaces the failed one."""
    warm = np.empty(idx.shape[0], np.bool_)
    for k in range(idx.shape[0]):
        warm[k] = warm_start(rows_i[idx[k]])
    _solve_into(st, list_a, list_b, mask_a, mask_b, pos, R, wall_d, rows_f, rows_i, idx, nt,
                walls)
    again = _retry_cold(rows_i, idx, warm)
    n = again.shape[0]
    if n:
        cf, ci = np.zeros((n, NF)), np.zeros((n, NI), np.int64)    # cold: no previous rows
        _solve_into(st, list_a[again], list_b[again], mask_a[again], mask_b[again], pos, R,
                    wall_d, cf, ci, np.arange(n), nt, walls)
        _take_converged(rows_f, rows_i, again, cf, ci)


@njit(cache=True)
def _kinds(st, a, b):
    """Per due pair: its pair solver (:mod:`nurbsdem.contact.kinds`: CLOSED_FORM,
    POINT_SURFACE, LCP, WALL_SUPPORT) from the kinds of its bodies (body a is a particle,
    body b a particle or a flat wall)."""
    N = st.n
    kind = np.empty(a.shape[0], np.int64)
    for r in range(a.shape[0]):
        ka = SPHERE if st.is_sphere[a[r]] else NURBS_PARTICLE
        if b[r] >= N:
            kb = FLAT_WALL
        else:
            kb = SPHERE if st.is_sphere[b[r]] else NURBS_PARTICLE
        kind[r] = pair_solver(ka, kb, st.point_surface)
    return kind


@njit(cache=True)
def _sphere_nurbs(st, a, b, pos, R, prev_f, prev_i, rf, ri):
    """Rows of the sphere–NURBS pairs (a[k], b[k]) into rf/ri: those whose bounding spheres
    are apart as the LCP answers them (:func:`~nurbsdem.contact.lcp.bounding_spheres_apart`),
    the others by the point solver; returns the flags of the rows given (False: the LCP's)."""
    K = a.shape[0]
    ok = np.zeros(K, np.bool_)
    near = np.empty(K, np.int64)
    n_near = 0
    cA, cB, d = np.empty(3), np.empty(3), np.empty(3)
    for k in range(K):
        rf[k] = 0.0
        ri[k] = 0
        sa, sb = st.body_shape[a[k]], st.body_shape[b[k]]
        ok[k] = bounding_spheres_apart(pos[a[k]], R[a[k]], st.centroid[sa], st.radius[sa],
                                       pos[b[k]], R[b[k]], st.centroid[sb], st.radius[sb],
                                       cA, cB, d, rf[k], ri[k])
        if not ok[k]:
            near[n_near] = k
            n_near += 1
    near = near[:n_near]
    if n_near:
        f = np.empty((n_near, NF))
        i = np.empty((n_near, NI), np.int64)
        solved = _point_rows(st, a[near], b[near], pos, R, prev_f[near], prev_i[near], f, i)
        for r in range(n_near):
            rf[near[r]] = f[r]
            ri[near[r]] = i[r]
            ok[near[r]] = solved[r]
    return ok


#: :func:`_sphere_nurbs` through a pointer of the lazy group "sphere_nurbs" (its point solver
#: and the bounding-sphere test), filled where a scene holds exact spheres and other
#: particles (:class:`~nurbsdem.contact.detect.ContactTable`): a scene without such pairs
#: does not compile it
_sphere_nurbs_ptr = PointerKernel(_sphere_nurbs, "sphere_nurbs", lazy="sphere_nurbs",
                                  result=lambda argtypes: types.boolean[::1]).call


@njit(cache=True)
def _point_rows(st, a, b, pos, R, prev_f, prev_i, rf, ri):
    """Rows of the sphere–NURBS pairs (a[k], b[k]) by the point solver, into rf/ri; returns
    the converged flags."""
    sphere_is_a = st.is_sphere[a]
    ball = np.where(sphere_is_a, a, b)
    body = np.where(sphere_is_a, b, a)
    c = sphere_centres(ball, pos, R, st.body_shape, st.sphere_center)
    r = st.sphere_radius[st.body_shape[ball]]
    return sphere_nurbs_rows(st.tab, st.info, st.centroid, st.radius, st.seeds,
                             st.body_shape[body], c, r, pos[body], R[body], sphere_is_a,
                             prev_f, prev_i, rf, ri)


@njit(cache=True)
def solve_due_into(st, list_a, list_b, mask_a, mask_b, rows_f, rows_i, due, pos, R, wall_d,
                   nt) -> tuple[int, bool]:
    """The rows of the listed pairs ``due`` (indices into the list: bodies list_a/list_b,
    candidate patch masks (L, P), rows (L, NF/NI)) solved in place from the previous rows
    they hold, each by what its shapes are; poses pos (N,3) m, R (N,3,3); wall displacements
    wall_d (W,3) m; nt threads.  A pair that failed keeps its previous row, flagged
    ``I_FAIL`` (:func:`~nurbsdem.contact.detect.kept_on_failure`).  Returns (pairs solved by
    the point solver, whether one of them failed).  No copies of the rows: a pack of 10^5
    particles solves 3·10^5 of them per evaluation."""
    a = list_a[due]
    b = list_b[due]
    kind = _kinds(st, a, b)
    closed_form_into(rows_f, rows_i, due[kind == CLOSED_FORM], list_a, list_b, st.n, pos, R, wall_d,
                     st.body_shape, st.sphere_center, st.sphere_radius, st.wall_origin,
                     st.wall_a, st.wall_b, st.wall_dom)
    mixed = np.nonzero(kind == POINT_SURFACE)[0]
    point_solved = 0
    rows = due[mixed]
    if mixed.shape[0]:
        f = np.empty((mixed.shape[0], NF))
        i = np.empty((mixed.shape[0], NI), np.int64)
        ok = _sphere_nurbs_ptr(st, a[mixed], b[mixed], pos, R, rows_f[rows], rows_i[rows], f, i)
        for k in range(mixed.shape[0]):
            j = rows[k]
            if ok[k]:
                rows_f[j] = f[k]
                rows_i[j] = i[k]
                point_solved += 1
            else:
                kind[mixed[k]] = LCP    # from a cold start (lcp.warm_start)
    for walls in (False, True):          # NURBS pairs (LCP), then NURBS–wall pairs
        part = due[kind == (WALL_SUPPORT if walls else LCP)]
        if part.shape[0]:
            _solve_retried_into(st, list_a, list_b, mask_a, mask_b, pos, R, wall_d, rows_f,
                                rows_i, part, nt, walls)
    failed = False
    for r in range(due.shape[0]):
        failed = failed or rows_i[due[r], I_FAIL] != 0
    return point_solved, failed


@njit(cache=True)
def solve_due(st, list_a, list_b, mask_a, mask_b, rows_f, rows_i, due, pos, R, wall_d, nt):
    """The listed pairs ``due`` solved in place in the list's rows rows_f (L,NF), rows_i (L,NI)
    by :func:`solve_due_into` (the scene's entry to it; the compiled loop calls that
    directly).  Returns the pairs solved by the point solver."""
    points, _ = solve_due_into_ptr(st, list_a, list_b, mask_a, mask_b, rows_f, rows_i, due,
                                   pos, R, wall_d, nt)
    return points


#: :func:`scene_list` and :func:`solve_due_into` compiled once and called by the compiled
#: loop and :func:`solve_due` through pointers (:class:`~nurbsdem.jit.PointerKernel`)
scene_list_ptr = PointerKernel(scene_list, "scene_list").call
solve_due_into_ptr = PointerKernel(solve_due_into, "solve_due_into").call

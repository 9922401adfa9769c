"""Compiled bookkeeping of the neighbour list with a skin (Verlet list) and the separation
certificates of :mod:`nurbsdem.contact.scene`: odometers, the carry-over of per-pair rows on a
rebuild, the renewal of certificates, and the split of the listed pairs into active contacts
and separated ("near") pairs.

These are plain functions over arrays, shared by the scene's Python orchestration and the
compiled deck steps of :mod:`nurbsdem.dynamics.deck_steps`, so that both paths see the same
bits.  Units: metres; rows in the column layout of :mod:`nurbsdem.contact.lcp`.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..jit import ROW_CHUNK, THREADED_ROWS, n_chunks, pack_chunks
from .lcp import (F_N, F_PA, F_PAR, F_PB, F_SD, I_ACTIVE, I_DEG, I_FAIL, I_PA, I_PB, I_VALID, NF,
                  NI)

#: a certificate is kept this fraction short of the distance it was solved for (round-off)
CERTIFICATE_SHRINK = 1.0 - 1e-9
#: at a rebuild, the bodies that have moved more than this fraction of the half skin since
#: their built pose take their present pose (:func:`reposed_bodies`); the others keep theirs
REPOSE_FRACTION = 0.5


@njit(cache=True)
def _displacements_range(x, x0, R, R0, radius, out, lo: int, hi: int) -> None:
    """:func:`largest_displacements` of the particles lo .. hi-1."""
    for i in range(lo, hi):
        s = 0.0
        for j in range(3):
            for k in range(3):
                d = R[i, j, k] - R0[i, j, k]
                s += d * d
        chord = math.sqrt(s / 2.0)                    # 2 sin(θ/2) = ‖R − R0‖_F / √2
        dx0, dx1, dx2 = x[i, 0] - x0[i, 0], x[i, 1] - x0[i, 1], x[i, 2] - x0[i, 2]
        out[i] = math.sqrt(dx0 * dx0 + dx1 * dx1 + dx2 * dx2) + chord * radius[i]


@njit(cache=True, parallel=True)
def _displacements_threads(x, x0, R, R0, radius, out) -> None:
    n = x.shape[0]
    for t in prange(n_chunks(n)):
        _displacements_range(x, x0, R, R0, radius, out, t * ROW_CHUNK,
                             min(n, (t + 1) * ROW_CHUNK))


@njit(cache=True)
def largest_displacements(x: np.ndarray, x0: np.ndarray, R: np.ndarray, R0: np.ndarray,
                          radius: np.ndarray, wall: np.ndarray, wall0: np.ndarray) -> np.ndarray:
    """(N+W,) m: the largest displacement of any point of each body between two poses,
    |Δx| + 2 sin(Δθ/2)·r for particles (centroids x, x0 (N,3), rotations R, R0 (N,3,3),
    bounding radii r (N,)), |Δd| for walls (displacements wall, wall0 (W,3)); the particles
    on threads from :data:`~nurbsdem.jit.THREADED_ROWS` of them (the same bits)."""
    n = x.shape[0]
    out = np.empty(n + wall.shape[0])
    if n >= THREADED_ROWS:
        _displacements_threads(x, x0, R, R0, radius, out)
    else:
        _displacements_range(x, x0, R, R0, radius, out, np.int64(0), n)
    for w in range(wall.shape[0]):
        d0, d1, d2 = wall[w, 0] - wall0[w, 0], wall[w, 1] - wall0[w, 1], wall[w, 2] - wall0[w, 2]
        out[n + w] = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    return out


@njit(cache=True)
def advance_odometers(odo: np.ndarray, x: np.ndarray, x0: np.ndarray, R: np.ndarray,
                      R0: np.ndarray, radius: np.ndarray, wall: np.ndarray,
                      wall0: np.ndarray) -> np.ndarray:
    """New odometers (B,) m: odo + each body's :func:`largest_displacements` since the
    previous poses (x0, R0, wall0)."""
    return odo + largest_displacements(x, x0, R, R0, radius, wall, wall0)


@njit(cache=True)
def list_is_stale(built_x: np.ndarray, built_R: np.ndarray, built_wall: np.ndarray,
                  x: np.ndarray, R: np.ndarray, wall: np.ndarray, radius: np.ndarray,
                  skin: float) -> bool:
    """Whether some body has moved more than half the skin (m) since the list was built at
    the poses (built_x, built_R, built_wall): its :func:`largest_displacements` between the
    two poses.  The displacement, not the path: a body that jiggles in a pack does not make
    the list stale (a pair left out was at least s apart, and the distance of two sets
    shrinks by at most the two displacements)."""
    if skin <= 0.0:
        return True
    moved = largest_displacements(x, built_x, R, built_R, radius, wall, built_wall)
    for i in range(moved.shape[0]):
        if moved[i] > 0.5 * skin:
            return True
    return False


@njit(cache=True)
def reposed_bodies(built_x: np.ndarray, built_R: np.ndarray, built_wall: np.ndarray,
                   x: np.ndarray, R: np.ndarray, wall: np.ndarray, radius: np.ndarray,
                   skin: float) -> np.ndarray:
    """(N+W,) bool: the bodies that take their present pose at a rebuild of the list, those
    whose :func:`largest_displacements` since their own built pose exceeds
    :data:`REPOSE_FRACTION` of half the skin s (m); every body that moved when s = 0.

    Each body keeps its own built pose: the list holds every pair that can touch while every
    body stays within s/2 of *its* built pose (two sets listed at poses at least s apart get
    closer by at most the two displacements), so a rebuild only needs new poses for the bodies
    that moved, and the patch boxes of the other bodies' pairs are not tested again
    (:func:`~nurbsdem.contact.listed.scene_list`).  Renewing only the bodies past s/2 (4 of
    up to 112 on average in the paper deck) made 7 times more rebuilds, those just short of
    s/2 triggering the next ones; renewing those past s/4: 30 on average, 1.1 times the
    rebuilds of full builds."""
    moved = largest_displacements(x, built_x, R, built_R, radius, wall, built_wall)
    return moved > REPOSE_FRACTION * 0.5 * skin


@njit(cache=True)
def repose(built_x: np.ndarray, built_R: np.ndarray, built_wall: np.ndarray,
           built_pos: np.ndarray, x: np.ndarray, R: np.ndarray, wall: np.ndarray,
           pos: np.ndarray, fresh: np.ndarray):
    """The built poses after a rebuild (new arrays): centroids (N,3), rotations (N,3,3), wall
    displacements (W,3) and pose positions (N,3) (m) of the ``fresh`` bodies (N+W,) from their
    present pose, the others' kept."""
    bx, bR, bw, bp = built_x.copy(), built_R.copy(), built_wall.copy(), built_pos.copy()
    n = x.shape[0]
    for i in range(n):          # entry by entry: no views of the rows in the loop
        if fresh[i]:
            for k in range(3):
                bx[i, k] = x[i, k]
                bp[i, k] = pos[i, k]
                for m in range(3):
                    bR[i, k, m] = R[i, k, m]
    for w in range(wall.shape[0]):
        if fresh[n + w]:
            for k in range(3):
                bw[w, k] = wall[w, k]
    return bx, bR, bw, bp


@njit(cache=True)
def merge_find(old_keys: np.ndarray, o: int, key: int) -> tuple[int, bool]:
    """One step of a merge that looks up increasing keys in the sorted ``old_keys``: the first
    position from o whose key is >= key (their length if none), and whether it holds key."""
    M = old_keys.shape[0]
    while o < M and old_keys[o] < key:
        o += 1
    return o, o < M and old_keys[o] == key


@njit(cache=True)
def _carry_range(old_keys, old_f, old_i, old_budget, old_reused, keys, rows_f, rows_i, budget,
                 reused, lo: int, hi: int) -> None:
    """:func:`carry_rows` of the new rows lo .. hi-1: a merge from the first old key >=
    keys[lo] (a binary search; 0 for the first row, where the merge starts anyway)."""
    if lo >= hi:
        return
    j = np.int64(0) if lo == 0 else np.int64(np.searchsorted(old_keys, keys[lo]))
    for r in range(lo, hi):
        j, listed = merge_find(old_keys, j, keys[r])
        if listed:              # entry by entry: no views of the rows in the loop
            for k in range(NF):
                rows_f[r, k] = old_f[j, k]
            for k in range(NI):
                rows_i[r, k] = old_i[j, k]
            budget[r] = old_budget[j]
            reused[r] = old_reused[j]
        else:
            for k in range(NF):
                rows_f[r, k] = 0.0
            for k in range(NI):
                rows_i[r, k] = 0
            budget[r] = -np.inf
            reused[r] = False


@njit(cache=True, parallel=True)
def _carry_threads(old_keys, old_f, old_i, old_budget, old_reused, keys, rows_f, rows_i, budget,
                   reused) -> None:
    L = keys.shape[0]
    for t in prange(n_chunks(L)):
        _carry_range(old_keys, old_f, old_i, old_budget, old_reused, keys, rows_f, rows_i,
                     budget, reused, t * ROW_CHUNK, min(L, (t + 1) * ROW_CHUNK))


@njit(cache=True)
def carry_rows(old_keys: np.ndarray, old_f: np.ndarray, old_i: np.ndarray,
               old_budget: np.ndarray, old_reused: np.ndarray, keys: np.ndarray):
    """Rows, certificates and reused flags of a new sorted list ``keys`` (L,): carried over
    from the old sorted list where a key was listed before (zeros / −inf / False otherwise);
    on threads from :data:`~nurbsdem.jit.THREADED_ROWS` rows (the same arrays)."""
    L = keys.shape[0]
    rows_f = np.empty((L, NF))
    rows_i = np.empty((L, NI), np.int64)
    budget = np.empty(L)
    reused = np.empty(L, np.bool_)
    if L >= THREADED_ROWS:
        _carry_threads(old_keys, old_f, old_i, old_budget, old_reused, keys, rows_f, rows_i,
                       budget, reused)
    else:
        _carry_range(old_keys, old_f, old_i, old_budget, old_reused, keys, rows_f, rows_i,
                     budget, reused, np.int64(0), L)
    return rows_f, rows_i, budget, reused


@njit(cache=True)
def _due_range(a, b, odo, budget, certificates, reach, due, lo: int, hi: int) -> int:
    """:func:`due_rows` of the listed pairs lo .. hi-1: their reach, and those due written
    to due[lo:] in order; returns how many."""
    n = lo
    for j in range(lo, hi):
        reach[j] = odo[a[j]] + odo[b[j]]
        if not (certificates and budget[j] > reach[j]):
            due[n] = j
            n += 1
    return n - lo


@njit(cache=True, parallel=True)
def _due_threads(a, b, odo, budget, certificates, reach, due, counts) -> None:
    L = a.shape[0]
    for t in prange(counts.shape[0]):
        counts[t] = _due_range(a, b, odo, budget, certificates, reach, due, t * ROW_CHUNK,
                               min(L, (t + 1) * ROW_CHUNK))


@njit(cache=True)
def due_rows(a: np.ndarray, b: np.ndarray, odo: np.ndarray, budget: np.ndarray,
             certificates: bool) -> tuple[np.ndarray, np.ndarray]:
    """(reach (L,) m, due): each listed pair's reach, the sum of its bodies' odometers
    odo[a] + odo[b], and the list positions (ascending) of the pairs to solve, those whose
    certificate ``budget`` does not exceed their reach (every pair without
    ``certificates``); on threads from :data:`~nurbsdem.jit.THREADED_ROWS` pairs (the same
    arrays)."""
    L = a.shape[0]
    reach = np.empty(L)
    due = np.empty(L, np.int64)
    if L >= THREADED_ROWS:
        counts = np.empty(n_chunks(L), np.int64)
        _due_threads(a, b, odo, budget, certificates, reach, due, counts)
        return reach, pack_chunks(due, counts)
    n = _due_range(a, b, odo, budget, certificates, reach, due, np.int64(0), L)
    return reach, due[:n]


@njit(cache=True)
def _renew_range(budget, due, rows_f, rows_i, reach, lo: int, hi: int) -> None:
    """:func:`renew_certificates` of due[lo:hi]."""
    for r in range(lo, hi):
        j = due[r]
        sd = rows_f[j, F_SD]
        apart = (rows_i[j, I_VALID] == 1 and rows_i[j, I_ACTIVE] == 0 and rows_i[j, I_FAIL] == 0
                 and sd > 0.0)
        budget[j] = sd * CERTIFICATE_SHRINK + reach[j] if apart else -np.inf


@njit(cache=True, parallel=True)
def _renew_threads(budget, due, rows_f, rows_i, reach) -> None:
    n = due.shape[0]
    for t in prange(n_chunks(n)):
        _renew_range(budget, due, rows_f, rows_i, reach, t * ROW_CHUNK,
                     min(n, (t + 1) * ROW_CHUNK))


@njit(cache=True)
def renew_certificates(budget: np.ndarray, due: np.ndarray, rows_f: np.ndarray,
                       rows_i: np.ndarray, reach: np.ndarray) -> None:
    """Certificates (in place) of the listed pairs ``due`` just solved (their rows
    rows_f[j], rows_i[j] of the whole list): a pair found apart by d cannot touch until its
    bodies' odometers have grown by d together; on threads from
    :data:`~nurbsdem.jit.THREADED_ROWS` pairs (the same bits)."""
    if due.shape[0] >= THREADED_ROWS:
        _renew_threads(budget, due, rows_f, rows_i, reach)
    else:
        _renew_range(budget, due, rows_f, rows_i, reach, np.int64(0), due.shape[0])


@njit(cache=True)
def active_and_near(rows_f: np.ndarray, rows_i: np.ndarray, budget: np.ndarray,
                    reach: np.ndarray):
    """Indices of the listed pairs in contact (valid and active) and of the separated ones
    (valid, gap > 0), and the gaps of the latter: the row's distance, or for a certified pair
    the lower bound its certificate leaves, whichever is smaller (m)."""
    L = rows_f.shape[0]
    sel = np.empty(L, np.int64)
    near = np.empty(L, np.int64)
    ns = nn = 0
    for j in range(L):
        if rows_i[j, I_VALID] != 1:
            continue
        if rows_i[j, I_ACTIVE] == 1:
            sel[ns] = j
            ns += 1
        elif rows_f[j, F_SD] > 0.0:
            near[nn] = j
            nn += 1
    gap = np.empty(nn)
    for r in range(nn):
        j = near[r]
        gap[r] = min(rows_f[j, F_SD], max(budget[j] - reach[j], 0.0))
    return sel[:ns].copy(), near[:nn].copy(), gap


@njit(cache=True)
def _active_rows_range(rows_i, due, sel, lo: int, hi: int) -> int:
    """:func:`active_rows` among due[lo:hi], written to sel[lo:] in order; returns how
    many."""
    n = lo
    for r in range(lo, hi):
        j = due[r]
        if rows_i[j, I_VALID] == 1 and rows_i[j, I_ACTIVE] == 1:
            sel[n] = j
            n += 1
    return n - lo


@njit(cache=True, parallel=True)
def _active_rows_threads(rows_i, due, sel, counts) -> None:
    n = due.shape[0]
    for t in prange(counts.shape[0]):
        counts[t] = _active_rows_range(rows_i, due, sel, t * ROW_CHUNK,
                                       min(n, (t + 1) * ROW_CHUNK))


@njit(cache=True)
def active_rows(rows_i: np.ndarray, due: np.ndarray) -> np.ndarray:
    """The listed pairs in contact (valid and active) among the rows just solved, ``due``
    (ascending list positions): a pair skipped by its certificate was apart when last solved,
    so these are all the active pairs of the list, in list order (those of
    :func:`active_and_near`), found without reading the other rows; the scan on threads from
    :data:`~nurbsdem.jit.THREADED_ROWS` due rows (the same array)."""
    sel = np.empty(due.shape[0], np.int64)
    if due.shape[0] >= THREADED_ROWS:
        counts = np.empty(n_chunks(due.shape[0]), np.int64)
        _active_rows_threads(rows_i, due, sel, counts)
        return pack_chunks(sel, counts).copy()
    n = _active_rows_range(rows_i, due, sel, np.int64(0), due.shape[0])
    return sel[:n].copy()


@njit(cache=True)
def near_pairs(rows_f: np.ndarray, rows_i: np.ndarray, budget: np.ndarray,
               reach: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The separated pairs of the list and their gaps (m), as :func:`active_and_near`."""
    _, near, gap = active_and_near(rows_f, rows_i, budget, reach)
    return near, gap


@njit(cache=True)
def _active_range(rows_f: np.ndarray, rows_i: np.ndarray, a: np.ndarray, b: np.ndarray,
                  keys: np.ndarray, sel: np.ndarray, ca: np.ndarray, cb: np.ndarray,
                  key: np.ndarray, pa: np.ndarray, pb: np.ndarray, nrm: np.ndarray,
                  params: np.ndarray, depth: np.ndarray, deg: np.ndarray, patch_a: np.ndarray,
                  patch_b: np.ndarray, lo: int, hi: int) -> None:
    """:func:`active_arrays`' rows lo .. hi-1 from the listed rows sel[lo:hi]."""
    for r in range(lo, hi):
        j = sel[r]
        ca[r] = a[j]
        cb[r] = b[j]
        key[r] = keys[j]
        for c in range(3):
            pa[r, c] = rows_f[j, F_PA + c]
            pb[r, c] = rows_f[j, F_PB + c]
            nrm[r, c] = rows_f[j, F_N + c]
        for c in range(4):
            params[r, c] = rows_f[j, F_PAR + c]
        depth[r] = -rows_f[j, F_SD]
        deg[r] = rows_i[j, I_DEG]
        patch_a[r] = rows_i[j, I_PA]
        patch_b[r] = rows_i[j, I_PB]


@njit(cache=True, parallel=True)
def _active_threads(rows_f, rows_i, a, b, keys, sel, ca, cb, key, pa, pb, nrm, params, depth,
                    deg, patch_a, patch_b) -> None:
    n = sel.shape[0]
    for t in prange(n_chunks(n)):
        _active_range(rows_f, rows_i, a, b, keys, sel, ca, cb, key, pa, pb, nrm, params, depth,
                      deg, patch_a, patch_b, t * ROW_CHUNK, min(n, (t + 1) * ROW_CHUNK))


@njit(cache=True)
def active_arrays(rows_f: np.ndarray, rows_i: np.ndarray, a: np.ndarray, b: np.ndarray,
                  keys: np.ndarray, sel: np.ndarray, room: int):
    """Per active contact (the list positions ``sel``): body_a, body_b, point_a, point_b (m),
    normal, depth (m), key, degeneration level, params (uA, vA, uB, vB), patch_a, patch_b
    (gathered on threads from :data:`~nurbsdem.jit.THREADED_ROWS` contacts), each array with
    ``room`` rows more at its end, not written (where the compiled loop puts the contacts with
    mesh and surface walls: no second copy of the arrays)."""
    K = sel.shape[0]
    T = K + room
    ca, cb, key = np.empty(T, np.int64), np.empty(T, np.int64), np.empty(T, np.int64)
    pa, pb, nrm, params = np.empty((T, 3)), np.empty((T, 3)), np.empty((T, 3)), np.empty((T, 4))
    depth = np.empty(T)
    deg, patch_a, patch_b = np.empty(T, np.int64), np.empty(T, np.int64), np.empty(T, np.int64)
    if K >= THREADED_ROWS:
        _active_threads(rows_f, rows_i, a, b, keys, sel, ca, cb, key, pa, pb, nrm, params,
                        depth, deg, patch_a, patch_b)
    else:
        _active_range(rows_f, rows_i, a, b, keys, sel, ca, cb, key, pa, pb, nrm, params, depth,
                      deg, patch_a, patch_b, np.int64(0), K)
    return ca, cb, pa, pb, nrm, depth, key, deg, params, patch_a, patch_b


@njit(cache=True)
def near_arrays(rows_f: np.ndarray, a: np.ndarray, b: np.ndarray, near: np.ndarray,
                gap: np.ndarray):
    """Per separated pair (the list positions ``near``, gaps ``gap`` m): near_a, near_b,
    near_point (midpoint of the closest points, m), near_normal, near_gap."""
    M = near.shape[0]
    near_point, near_normal = np.empty((M, 3)), np.empty((M, 3))
    for r in range(M):
        j = near[r]
        for c in range(3):
            near_point[r, c] = 0.5 * (rows_f[j, F_PA + c] + rows_f[j, F_PB + c])
            near_normal[r, c] = rows_f[j, F_N + c]
    return a[near], b[near], near_point, near_normal, gap


@njit(cache=True)
def contact_arrays(rows_f: np.ndarray, rows_i: np.ndarray, a: np.ndarray, b: np.ndarray,
                   keys: np.ndarray, budget: np.ndarray, reach: np.ndarray):
    """The arrays of a :class:`~nurbsdem.contact.contactset.ContactSet` from the listed
    pairs' rows (:func:`active_and_near`): per active contact body_a, body_b, point_a,
    point_b (m), normal, depth (m), key, degeneration level, params (uA, vA, uB, vB), patch_a,
    patch_b (:func:`active_arrays`); per separated pair near_a, near_b, near_point (midpoint
    of the closest points, m), near_normal, near_gap (m) (:func:`near_arrays`)."""
    sel, near, gap = active_and_near(rows_f, rows_i, budget, reach)
    return (active_arrays(rows_f, rows_i, a, b, keys, sel, np.int64(0))
            + near_arrays(rows_f, a, b, near, gap))

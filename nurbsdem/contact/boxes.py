"""Global contact search, level 2 of the paper (Section 3.1): oriented boxes per patch.

Each patch gets, in its shape's file frame, the axis-aligned box of its control points
(``Shape.patch_boxes``, (P, 2, 3) min/max corners; with positive weights the patch lies in
the convex hull of its control points, hence in the box). The box moves with the body, so in
the world it is an oriented box (OBB): for a pose ``(position, R)`` with
``x_world = position + R @ x_file`` its centre is ``position + R @ (lo + hi) / 2``, its axes
are the columns of ``R`` and its half sizes ``(hi - lo) / 2``.

Two boxes are tested by the separating-axis test over 15 axes (3 face normals of each box
and the 9 edge cross products), as in C. Ericson, *Real-Time Collision Detection*, §4.4.1,
with a small epsilon added to ``|R|`` so that near-parallel edges (cross product ~ 0) never
report a false separation. Touching boxes count as overlapping (conservative).

``margin`` (m) everywhere means: report boxes closer than ``margin`` (each box is inflated by
``margin / 2`` on every side), matching the ``margin`` of
:func:`nurbsdem.contact.broadphase.sphere_pairs` (r_i + r_j + margin, Eq. 3).

Units: metres. Hot kernels are numba ``@njit(cache=True)`` functions.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
from numba import njit, prange

#: Added to |R_ij| in the separating-axis test (Ericson §4.4.1): guards the edge-edge axes
#: against round-off when two edges are (nearly) parallel. Dimensionless (a cosine).
SAT_EPS = 1e-9


# --------------------------------------------------------------------------- SAT core
@njit(cache=True, inline='always')
def _relative(axes_a, axes_b, R, AbsR):
    """R = A^T B (B's axes in A's frame) and AbsR = |R| + SAT_EPS, in place."""
    for i in range(3):
        for j in range(3):
            s = 0.0
            for k in range(3):
                s += axes_a[k, i] * axes_b[k, j]
            R[i, j] = s
            AbsR[i, j] = abs(s) + SAT_EPS


@njit(cache=True, inline='always')
def _sat(t, R, AbsR, ha, hb):
    """Separating-axis test of two boxes given in A's frame.

    t: (3,) centre of B minus centre of A, in A's axes (m).  R, AbsR: from :func:`_relative`.
    ha, hb: (3,) half sizes (m). Returns True when no separating axis exists (overlap).
    """
    # face normals of A
    for i in range(3):
        rb = hb[0] * AbsR[i, 0] + hb[1] * AbsR[i, 1] + hb[2] * AbsR[i, 2]
        if abs(t[i]) > ha[i] + rb:
            return False
    # face normals of B
    for j in range(3):
        ra = ha[0] * AbsR[0, j] + ha[1] * AbsR[1, j] + ha[2] * AbsR[2, j]
        if abs(t[0] * R[0, j] + t[1] * R[1, j] + t[2] * R[2, j]) > ra + hb[j]:
            return False
    # edge-edge axes A_i x B_j
    for i in range(3):
        i1 = (i + 1) % 3
        i2 = (i + 2) % 3
        for j in range(3):
            j1 = (j + 1) % 3
            j2 = (j + 2) % 3
            ra = ha[i1] * AbsR[i2, j] + ha[i2] * AbsR[i1, j]
            rb = hb[j1] * AbsR[i, j2] + hb[j2] * AbsR[i, j1]
            if abs(t[i2] * R[i1, j] - t[i1] * R[i2, j]) > ra + rb:
                return False
    return True


@njit(cache=True)
def obb_overlap_jit(center_a, axes_a, half_a, center_b, axes_b, half_b):
    """Compiled :func:`obb_overlap` (no input checks)."""
    R = np.empty((3, 3))
    AbsR = np.empty((3, 3))
    _relative(axes_a, axes_b, R, AbsR)
    t = np.empty(3)
    for i in range(3):
        s = 0.0
        for k in range(3):
            s += (center_b[k] - center_a[k]) * axes_a[k, i]
        t[i] = s
    return _sat(t, R, AbsR, half_a, half_b)


def obb_overlap(center_a: np.ndarray, axes_a: np.ndarray, half_a: np.ndarray,
                center_b: np.ndarray, axes_b: np.ndarray, half_b: np.ndarray) -> bool:
    """Do two oriented boxes overlap? Separating-axis test, 15 axes (Ericson §4.4.1).

    Parameters
    ----------
    center_a, center_b: (3,) box centres (m, world).
    axes_a, axes_b: (3, 3) orthonormal box axes as *columns* (world).
    half_a, half_b: (3,) half sizes along those axes (m, >= 0; 0 gives a flat box).

    Returns True when the closed boxes intersect (touching counts; near-parallel edges are
    inflated by ``SAT_EPS`` relative to the box sizes, conservatively).
    """
    f = lambda x, s: np.ascontiguousarray(x, dtype=np.float64).reshape(s)  # noqa: E731
    return bool(obb_overlap_jit(f(center_a, 3), f(axes_a, (3, 3)), f(half_a, 3),
                                f(center_b, 3), f(axes_b, (3, 3)), f(half_b, 3)))


# --------------------------------------------------------------------------- patch boxes
@njit(cache=True, inline='always')
def _frame_of_b(pos_a, Ra, pos_b, Rb, R, AbsR, d0) -> None:
    """B's file frame in A's (in place): R = Ra^T Rb and AbsR from :func:`_relative`, d0 (3,)
    the origin of B's file frame in A's file frame (m)."""
    _relative(Ra, Rb, R, AbsR)
    for i in range(3):
        s = 0.0
        for k in range(3):
            s += (pos_b[k] - pos_a[k]) * Ra[k, i]
        d0[i] = s


@njit(cache=True, inline='always')
def _box_of_b(boxes, jb, d0, R, hm, cb, hb) -> float:
    """B's box jb in A's frame (in place): its centre cb (3,) and half sizes hb (3,),
    inflated by hm (m); returns its squared half diagonal (m²)."""
    nb = 0.0
    for i in range(3):
        hb[i] = 0.5 * (boxes[jb, 1, i] - boxes[jb, 0, i]) + hm
        nb += hb[i] * hb[i]
    for i in range(3):
        s = d0[i]
        for k in range(3):
            s += R[i, k] * 0.5 * (boxes[jb, 0, k] + boxes[jb, 1, k])
        cb[i] = s
    return nb


@njit(cache=True, inline='always')
def _box_overlaps_b(boxes, ia, cb, hb, nb, R, AbsR, hm, ha, t) -> bool:
    """Whether A's box ia (inflated by hm) overlaps B's box (cb, hb, nb of
    :func:`_box_of_b`): the boxes' bounding spheres first (a cheap reject), then
    :func:`_sat`; ha, t (3,) workspaces."""
    na = 0.0
    tt = 0.0
    for i in range(3):
        ha[i] = 0.5 * (boxes[ia, 1, i] - boxes[ia, 0, i]) + hm
        na += ha[i] * ha[i]
        t[i] = cb[i] - 0.5 * (boxes[ia, 0, i] + boxes[ia, 1, i])
        tt += t[i] * t[i]
    rs = np.sqrt(na) + np.sqrt(nb)
    if tt > rs * rs * (1.0 + 1e-12):
        return False
    return _sat(t, R, AbsR, ha, hb)


@njit(cache=True)
def _pair_boxes(boxes, a0, a1, pos_a, Ra, b0, b1, pos_b, Rb, margin, tag, buf, n):
    """Append (tag, patch_a, patch_b) for overlapping boxes of one body pair to buf[n:].

    boxes: (P, 2, 3) file-frame AABBs; rows a0:a1 are A's patches, b0:b1 B's.
    Returns (buf, n) (buf grows by doubling).
    """
    R, AbsR = np.empty((3, 3)), np.empty((3, 3))
    d0, ha, hb, cb, t = np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    _frame_of_b(pos_a, Ra, pos_b, Rb, R, AbsR, d0)
    hm = 0.5 * margin
    for jb in range(b0, b1):
        nb = _box_of_b(boxes, jb, d0, R, hm, cb, hb)
        for ia in range(a0, a1):
            if _box_overlaps_b(boxes, ia, cb, hb, nb, R, AbsR, hm, ha, t):
                if n >= buf.shape[0]:
                    nbuf = np.empty((2 * buf.shape[0], 3), dtype=np.int64)
                    nbuf[:n] = buf[:n]
                    buf = nbuf
                buf[n, 0] = tag
                buf[n, 1] = ia - a0
                buf[n, 2] = jb - b0
                n += 1
    return buf, n


@njit(cache=True)
def _mark_patches(boxes, box_offsets, body_shape, positions, rotations, pairs, hm, p0, p1,
                  keep, mask_a, mask_b) -> None:
    """:func:`candidate_patch_masks_batch_jit` for the pairs p0:p1 (in place), boxes
    inflated by hm (m), with one set of workspaces."""
    R, AbsR = np.empty((3, 3)), np.empty((3, 3))
    d0, ha, hb, cb, t = np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    for p in range(p0, p1):
        a, b = pairs[p, 0], pairs[p, 1]
        a0, a1 = box_offsets[body_shape[a]], box_offsets[body_shape[a] + 1]
        b0, b1 = box_offsets[body_shape[b]], box_offsets[body_shape[b] + 1]
        _frame_of_b(positions[a], rotations[a], positions[b], rotations[b], R, AbsR, d0)
        for jb in range(b0, b1):
            nb = _box_of_b(boxes, jb, d0, R, hm, cb, hb)
            for ia in range(a0, a1):
                if mask_a[p, ia - a0] and mask_b[p, jb - b0]:
                    continue
                if _box_overlaps_b(boxes, ia, cb, hb, nb, R, AbsR, hm, ha, t):
                    mask_a[p, ia - a0] = True
                    mask_b[p, jb - b0] = True
                    keep[p] = True


#: body pairs per share of :func:`candidate_patch_masks_batch_jit` (fewer: one thread)
MASK_CHUNK = 64


@njit(cache=True, parallel=True)
def candidate_patch_masks_batch_jit(boxes, box_offsets, body_shape, positions, rotations,
                                    pairs, margin, n_patches):
    """The candidate patches of many body pairs as masks: (keep (K,) bool — some pair of
    boxes overlaps —, mask_a (K, n_patches), mask_b (K, n_patches) bool — the patches of A,
    of B in some overlapping pair), the same as the rows of
    :func:`candidate_patch_pairs_batch_jit` marked into masks.  A pair of boxes whose patches
    are both marked already is not tested (its result would change nothing); no rows, no
    sorting;
    shares of :data:`MASK_CHUNK` pairs on the threads."""
    K = pairs.shape[0]
    keep = np.zeros(K, np.bool_)
    mask_a = np.zeros((K, n_patches), np.bool_)
    mask_b = np.zeros((K, n_patches), np.bool_)
    shares = (K + MASK_CHUNK - 1) // MASK_CHUNK
    if shares < 2:
        _mark_patches(boxes, box_offsets, body_shape, positions, rotations, pairs,
                      0.5 * margin, np.int64(0), K, keep, mask_a, mask_b)
        return keep, mask_a, mask_b
    for c in prange(shares):
        _mark_patches(boxes, box_offsets, body_shape, positions, rotations, pairs,
                      0.5 * margin, c * MASK_CHUNK, min(K, (c + 1) * MASK_CHUNK), keep,
                      mask_a, mask_b)
    return keep, mask_a, mask_b


@njit(cache=True)
def _sort_rows3(buf, n):
    """Rows (tag, a, b) sorted lexicographically."""
    idx = np.argsort(buf[:n, 2], kind="mergesort")
    out = buf[:n][idx]
    idx = np.argsort(out[:, 1], kind="mergesort")
    out = out[idx]
    idx = np.argsort(out[:, 0], kind="mergesort")
    return out[idx].copy()


@njit(cache=True)
def candidate_patch_pairs_batch_jit(boxes, box_offsets, body_shape, positions, rotations,
                                    pairs, margin):
    """Compiled :func:`candidate_patch_pairs_batch` (no input checks)."""
    buf = np.empty((max(16, 4 * pairs.shape[0]), 3), dtype=np.int64)
    n = np.int64(0)
    for p in range(pairs.shape[0]):
        a = pairs[p, 0]
        b = pairs[p, 1]
        sa = body_shape[a]
        sb = body_shape[b]
        buf, n = _pair_boxes(boxes, box_offsets[sa], box_offsets[sa + 1], positions[a],
                             rotations[a], box_offsets[sb], box_offsets[sb + 1], positions[b],
                             rotations[b], margin, p, buf, n)
    return _sort_rows3(buf, n)


def _pose(pose) -> tuple[np.ndarray, np.ndarray]:
    position, R = pose
    return (np.ascontiguousarray(position, dtype=np.float64).reshape(3),
            np.ascontiguousarray(R, dtype=np.float64).reshape(3, 3))


def _check_margin(margin: float) -> float:
    margin = float(margin)
    if not (np.isfinite(margin) and margin >= 0):
        raise ValueError("margin must be finite and >= 0")
    return margin


def candidate_patch_pairs(shape_a, pose_a, shape_b, pose_b, margin: float = 0.0) -> np.ndarray:
    """Candidate patch pairs of one body pair (second global level, paper Section 3.1).

    Parameters
    ----------
    shape_a, shape_b: :class:`~nurbsdem.geometry.shape.Shape` (uses ``patch_boxes``).
    pose_a, pose_b: ``(position (3,), R (3, 3))`` with ``x_world = position + R @ x_file``
        (position is the file-frame origin in the world, m; R a rotation).
    margin: report patch boxes closer than this (m, >= 0).

    Returns
    -------
    int64 (K, 2) of (patch of A, patch of B) whose oriented boxes overlap, sorted
    lexicographically.
    """
    margin = _check_margin(margin)
    pa, Ra = _pose(pose_a)
    pb, Rb = _pose(pose_b)
    ba = np.asarray(shape_a.patch_boxes, dtype=np.float64)
    bb = np.asarray(shape_b.patch_boxes, dtype=np.float64)
    boxes = np.ascontiguousarray(np.concatenate([ba, bb]))
    buf = np.empty((16, 3), dtype=np.int64)
    buf, n = _pair_boxes(boxes, np.int64(0), len(ba), pa, Ra, len(ba), len(boxes), pb, Rb, margin,
                         0, buf, 0)
    return _sort_rows3(buf, n)[:, 1:].copy()


def pack_boxes(shapes: Sequence) -> tuple[np.ndarray, np.ndarray]:
    """Patch boxes of several shapes packed for the batch kernels.

    Returns ``boxes`` float64 (P_total, 2, 3) (file-frame min/max corners, m) and
    ``box_offsets`` int64 (S + 1,): shape s owns rows ``box_offsets[s]:box_offsets[s+1]``.
    """
    bx = [np.asarray(s.patch_boxes, dtype=np.float64).reshape(-1, 2, 3) for s in shapes]
    offsets = np.zeros(len(bx) + 1, dtype=np.int64)
    offsets[1:] = np.cumsum([len(b) for b in bx])
    boxes = np.ascontiguousarray(np.concatenate(bx)) if bx else np.zeros((0, 2, 3))
    return boxes, offsets


def candidate_patch_pairs_batch(boxes: np.ndarray, box_offsets: np.ndarray,
                                body_shape: np.ndarray, positions: np.ndarray,
                                rotations: np.ndarray, pairs: np.ndarray,
                                margin: float = 0.0) -> np.ndarray:
    """Candidate patch pairs of many body pairs at once (compiled).

    Parameters
    ----------
    boxes, box_offsets: from :func:`pack_boxes` (file-frame boxes of all shapes).
    body_shape: int64 (N,) shape index of each body.
    positions: (N, 3) pose positions (file-frame origins in the world, m).
    rotations: (N, 3, 3) pose rotations (``x_world = position + R @ x_file``).
    pairs: int64 (K, 2) body pairs (A, B), e.g. from
        :func:`~nurbsdem.contact.broadphase.sphere_pairs`.
    margin: report boxes closer than this (m, >= 0).

    Returns
    -------
    int64 (M, 3) rows (pair index k, patch of A, patch of B) (patch indices local to each
    shape), sorted lexicographically, so each pair's candidates are contiguous.
    """
    margin = _check_margin(margin)
    pairs = np.ascontiguousarray(pairs, dtype=np.int64).reshape(-1, 2)
    return candidate_patch_pairs_batch_jit(
        np.ascontiguousarray(boxes, dtype=np.float64),
        np.ascontiguousarray(box_offsets, dtype=np.int64),
        np.ascontiguousarray(body_shape, dtype=np.int64),
        np.ascontiguousarray(positions, dtype=np.float64).reshape(-1, 3),
        np.ascontiguousarray(rotations, dtype=np.float64).reshape(-1, 3, 3),
        pairs, margin)


# --------------------------------------------------------------------------- walls
@njit(cache=True)
def _wall_boxes(boxes, a0, a1, pos, Rot, wc, wax, wh, margin, depth, tag, buf, n):
    """Append (tag, patch) for patches of one body whose boxes overlap one wall's box.

    The wall box: centre ``wc - n depth / 2``, axes ``wax`` (columns t1, t2, n), half sizes
    ``(wh0, wh1, depth / 2)``; everything inflated by margin / 2.
    """
    R = np.empty((3, 3))
    AbsR = np.empty((3, 3))
    _relative(Rot, wax, R, AbsR)  # wall axes in the body frame
    hm = 0.5 * margin
    hw = np.empty(3)
    hw[0] = wh[0] + hm
    hw[1] = wh[1] + hm
    hw[2] = 0.5 * depth + hm
    cw = np.empty(3)  # wall box centre in the body's file frame
    for i in range(3):
        s = 0.0
        for k in range(3):
            s += (wc[k] - 0.5 * depth * wax[k, 2] - pos[k]) * Rot[k, i]
        cw[i] = s
    ha = np.empty(3)
    t = np.empty(3)
    for ia in range(a0, a1):
        for i in range(3):
            ha[i] = 0.5 * (boxes[ia, 1, i] - boxes[ia, 0, i]) + hm
            t[i] = cw[i] - 0.5 * (boxes[ia, 0, i] + boxes[ia, 1, i])
        if _sat(t, R, AbsR, ha, hw):
            if n >= buf.shape[0]:
                nbuf = np.empty((2 * buf.shape[0], 2), dtype=np.int64)
                nbuf[:n] = buf[:n]
                buf = nbuf
            buf[n, 0] = tag
            buf[n, 1] = ia - a0
            n += 1
    return buf, n


@njit(cache=True)
def candidate_patches_wall_batch_jit(boxes, box_offsets, body_shape, positions, rotations,
                                     wall_centers, wall_axes, wall_half, pairs, margin, depth):
    """Compiled :func:`candidate_patches_wall_batch` (no input checks)."""
    buf = np.empty((max(16, 2 * pairs.shape[0]), 2), dtype=np.int64)
    n = np.int64(0)             # not a literal: one specialisation of _wall_boxes
    for p in range(pairs.shape[0]):
        a = pairs[p, 0]
        w = pairs[p, 1]
        s = body_shape[a]
        buf, n = _wall_boxes(boxes, box_offsets[s], box_offsets[s + 1], positions[a],
                             rotations[a], wall_centers[w], wall_axes[w], wall_half[w],
                             margin, depth, p, buf, n)
    return buf[:n].copy()


def _wall(wall_center, wall_axes, wall_half):
    wc = np.ascontiguousarray(wall_center, dtype=np.float64).reshape(3)
    wa = np.ascontiguousarray(wall_axes, dtype=np.float64).reshape(3, 3)
    wh = np.ascontiguousarray(np.asarray(wall_half, dtype=np.float64).reshape(-1)[:2])
    return wc, wa, wh


def candidate_patches_wall(shape, pose, wall_center: np.ndarray, wall_axes: np.ndarray,
                           wall_half: np.ndarray, margin: float = 0.0,
                           depth: float = 0.0) -> np.ndarray:
    """Patches of a body whose oriented boxes reach a flat rectangular wall.

    The wall (see :func:`nurbsdem.contact.flat_wall.wall_geometry`) is a thin oriented box:
    the rectangle ``wall_center + s t1 + r t2``, ``|s| <= half[0]``, ``|r| <= half[1]``,
    extended ``depth`` (m, default 0: just the rectangle) behind its active side (along -n),
    so that patches of a body that has sunk deeper than a patch box into the wall stay
    candidates when ``depth`` is set.

    Parameters
    ----------
    shape: the body's :class:`~nurbsdem.geometry.shape.Shape`.
    pose: ``(position, R)``, ``x_world = position + R @ x_file``.
    wall_center: (3,) m.  wall_axes: (3, 3) columns (t1, t2, n).  wall_half: (2,) m
        (a third entry is ignored).
    margin: report boxes closer than this (m, >= 0).  depth: see above (m, >= 0).

    Returns
    -------
    int64 (K,) patch indices, increasing.
    """
    margin = _check_margin(margin)
    depth = _check_margin(depth)
    pos, R = _pose(pose)
    wc, wa, wh = _wall(wall_center, wall_axes, wall_half)
    boxes = np.ascontiguousarray(shape.patch_boxes, dtype=np.float64)
    buf = np.empty((8, 2), dtype=np.int64)
    buf, n = _wall_boxes(boxes, 0, len(boxes), pos, R, wc, wa, wh, margin, depth, 0, buf, 0)
    return buf[:n, 1].copy()


def candidate_patches_wall_batch(boxes: np.ndarray, box_offsets: np.ndarray,
                                 body_shape: np.ndarray, positions: np.ndarray,
                                 rotations: np.ndarray, wall_centers: np.ndarray,
                                 wall_axes: np.ndarray, wall_half: np.ndarray,
                                 pairs: np.ndarray, margin: float = 0.0,
                                 depth: float = 0.0) -> np.ndarray:
    """Body-vs-wall patch candidates of many (body, wall) pairs at once (compiled).

    Parameters as in :func:`candidate_patch_pairs_batch` and :func:`candidate_patches_wall`;
    ``wall_centers`` (W, 3), ``wall_axes`` (W, 3, 3), ``wall_half`` (W, 2), ``pairs`` int64
    (K, 2) of (body, wall index 0..W-1), e.g. from
    :func:`~nurbsdem.contact.flat_wall.sphere_wall_pairs`.

    Returns int64 (M, 2) rows (pair index k, patch of the body), sorted.
    """
    margin = _check_margin(margin)
    depth = _check_margin(depth)
    wc = np.ascontiguousarray(wall_centers, dtype=np.float64).reshape(-1, 3)
    wh = np.ascontiguousarray(
        np.asarray(wall_half, dtype=np.float64).reshape(wc.shape[0], -1)[:, :2])
    return candidate_patches_wall_batch_jit(
        np.ascontiguousarray(boxes, dtype=np.float64),
        np.ascontiguousarray(box_offsets, dtype=np.int64),
        np.ascontiguousarray(body_shape, dtype=np.int64),
        np.ascontiguousarray(positions, dtype=np.float64).reshape(-1, 3),
        np.ascontiguousarray(rotations, dtype=np.float64).reshape(-1, 3, 3),
        wc, np.ascontiguousarray(wall_axes, dtype=np.float64).reshape(-1, 3, 3), wh,
        np.ascontiguousarray(pairs, dtype=np.int64).reshape(-1, 2), margin, depth)

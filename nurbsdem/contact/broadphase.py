"""Global contact search, level 1 of the paper (Section 3.1): bounding spheres.

Every particle is wrapped in the sphere centred at its centroid whose radius reaches the
farthest control point (valid because all weights are positive). Two particles are a
candidate pair when their spheres overlap, i.e. when (paper Eq. 3)

    delta = r_A + r_B - dist_G > 0,

here with an optional Verlet-like ``margin`` (m): a pair is kept when
``|c_i - c_j| < r_i + r_j + margin``, so a list built with ``margin > 0`` stays valid while
no body moves more than ``margin / 2``.

Neighbour search: linked cells over a *hashed* uniform grid (cells are keyed by their
integer coordinates in an open-addressing table sized by N, never a dense array over the
bounding box, so very spread-out domains cost nothing extra); particles are sorted by cell
(cells in (z, y, x) order for memory locality). Polydisperse sets are split into size
levels (radius ratio ``LEVEL_RATIO`` = 4 between levels, at most ``MAX_LEVELS``); each level
has its own grid with cell size ``2 R_L + margin`` (R_L the level's largest radius). A cell
meets its own level through the half shell (itself + 13 neighbours, each pair once) and the
coarser levels through the cells its spheres' bounding box reaches (each cross-level pair is
found once, from its smaller member). The cost is ~linear in N. A rebuild that renews few
bodies asks :func:`sphere_pairs_of` for their pairs only: the same grid, queried from those
bodies (each pair by the same comparison, so the same verdicts).

Flat walls: :func:`~nurbsdem.contact.flat_wall.sphere_wall_pairs` (the flat wall's module)
tests each bounding sphere against each wall rectangle.

Units: metres. Arrays are float64 / int64. Hot kernels are numba ``@njit(cache=True)``
functions (``*_jit``) that can be called from other compiled code; the public wrappers
check and convert their input.
"""
from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit

#: At most this many size levels; radii below the smallest level share level 0.
MAX_LEVELS = 8

#: Radius ratio between consecutive size levels (within a level radii differ by less).
LEVEL_RATIO = 4.0

_EMPTY = -1


# --------------------------------------------------------------------------- hashing
@njit(cache=True)
def _hash4(lv, ix, iy, iz, mask):
    """Slot of the cell (level, ix, iy, iz) in an open-addressing table of size mask + 1."""
    h = (ix * 73856093) ^ (iy * 19349663) ^ (iz * 83492791) ^ (lv * 2654435761)
    h ^= h >> 29
    return h & mask


@njit(cache=True)
def _insert(tab, mask, lv, ix, iy, iz, cid):
    """Put cell id cid under the key (lv, ix, iy, iz) into the open-addressing table tab
    (rows: key, key, key, key, value)."""
    s = _hash4(lv, ix, iy, iz, mask)
    while tab[s, 4] != _EMPTY:
        s = (s + 1) & mask
    tab[s, 0] = lv
    tab[s, 1] = ix
    tab[s, 2] = iy
    tab[s, 3] = iz
    tab[s, 4] = cid


@njit(cache=True)
def _lookup(tab, mask, lv, ix, iy, iz):
    """Cell id of (lv, ix, iy, iz) in the hash table tab, or -1 when that cell is empty
    (keys stored inline: one probe reads one memory line)."""
    s = _hash4(lv, ix, iy, iz, mask)
    while True:
        c = tab[s, 4]
        if c == _EMPTY:
            return -1
        if tab[s, 0] == lv and tab[s, 1] == ix and tab[s, 2] == iy and tab[s, 3] == iz:
            return c
        s = (s + 1) & mask


@njit(cache=True)
def _push(buf, n, a, b):
    """Append (a, b) to the growing pair buffer; returns the (possibly new) buffer."""
    if n >= buf.shape[0]:
        nb = np.empty((2 * buf.shape[0], 2), dtype=np.int64)
        nb[:n] = buf[:n]
        buf = nb
    buf[n, 0] = a
    buf[n, 1] = b
    return buf


@njit(cache=True)
def _sort_pairs(buf, n, nmax):
    """The first n pairs sorted lexicographically (key a * nmax + b)."""
    keys = np.empty(n, dtype=np.int64)
    for k in range(n):
        keys[k] = buf[k, 0] * nmax + buf[k, 1]
    keys.sort()
    out = np.empty((n, 2), dtype=np.int64)
    for k in range(n):
        out[k, 0] = keys[k] // nmax
        out[k, 1] = keys[k] % nmax
    return out


# --------------------------------------------------------------------------- level 1
#: up to this many bodies the all-pairs test is faster than the grid (same pairs, same order)
ALL_PAIRS_MAX = 160


@njit(cache=True)
def _near_each_other(centers, radii, margin, i, j) -> bool:
    """The comparison of :func:`sphere_pairs_jit` for bodies i, j."""
    ex = centers[j, 0] - centers[i, 0]
    ey = centers[j, 1] - centers[i, 1]
    ez = centers[j, 2] - centers[i, 2]
    t = (radii[i] + 0.5 * margin) + (radii[j] + 0.5 * margin)
    return t > 0.0 and ex * ex + ey * ey + ez * ez < t * t


@njit(cache=True)
def _sphere_pairs_all(centers, radii, margin):
    """All-pairs version of :func:`sphere_pairs_jit` for few bodies: the same comparison in
    the same floating-point operations, so the same pairs, in lexicographic order (counted
    first, then written: a growing buffer in the inner loop costs more than the test)."""
    n = centers.shape[0]
    count = 0
    for i in range(n):
        for j in range(i + 1, n):
            if _near_each_other(centers, radii, margin, i, j):
                count += 1
    out = np.empty((count, 2), dtype=np.int64)
    k = 0
    for i in range(n):
        for j in range(i + 1, n):
            if _near_each_other(centers, radii, margin, i, j):
                out[k, 0] = i
                out[k, 1] = j
                k += 1
    return out


#: the linked cells of :func:`sphere_pairs_jit` over n bodies: nlev size levels (the largest
#: radius lev_rmax and whether used, per level); cells of size 1/inv_h (per level) from the
#: lower corner lo, in the hash table tab (mask) keyed (level, ix, iy, iz); ckey (ncell, 4)
#: each cell's key; the bodies sorted by cell (start: each cell's first slot, sidx: the body
#: in each slot), with their centres sc and radii + margin/2 sr by slot
SphereGrid = namedtuple("SphereGrid", "nlev lev_rmax lev_used lo inv_h tab mask ckey ncell "
                        "start sidx sc sr")


@njit(cache=True)
def _sphere_grid(centers, radii, margin) -> SphereGrid:
    """The :class:`SphereGrid` of n ≥ 1 bounding spheres, for pairs closer than margin (m)."""
    n = centers.shape[0]
    # ---- size levels: level k holds radii in [rb 2^k, rb 2^(k+1)), rb = rmax 2^-(L-1)
    rmax = 0.0
    rmin = np.inf
    for i in range(n):
        rmax = max(rmax, radii[i])
        rmin = min(rmin, radii[i])
    nlev = 1
    if rmin > 0.0:
        while nlev < MAX_LEVELS and rmax > rmin * LEVEL_RATIO ** nlev:
            nlev += 1
    else:
        nlev = MAX_LEVELS if rmax > 0.0 else 1
    rb = rmax * LEVEL_RATIO ** (1 - nlev)
    level = np.zeros(n, dtype=np.int64)
    lev_rmax = np.zeros(nlev)
    for i in range(n):
        k = 0
        if rb > 0.0:
            while k < nlev - 1 and radii[i] >= rb * LEVEL_RATIO ** (k + 1):
                k += 1
        level[i] = k
        lev_rmax[k] = max(lev_rmax[k], radii[i])

    # ---- per-level cell size; integer cell coordinates relative to the lower corner
    lo = np.empty(3)
    hi = np.empty(3)
    for d in range(3):
        lo[d] = centers[0, d]
        hi[d] = centers[0, d]
    for i in range(1, n):
        for d in range(3):
            lo[d] = min(lo[d], centers[i, d])
            hi[d] = max(hi[d], centers[i, d])
    ext = max(hi[0] - lo[0], max(hi[1] - lo[1], hi[2] - lo[2]))
    h = np.empty(nlev)
    for k in range(nlev):
        hk = 2.0 * lev_rmax[k] + margin
        # any positive size is correct; keep the coordinates well inside int64
        h[k] = max(hk, ext * 1e-15, 1e-300)
    inv_h = 1.0 / h

    # ---- cells: hash table (level, ix, iy, iz) -> cell id, ids in order of appearance
    cell_of = np.empty(n, dtype=np.int64)
    tsize = 1
    while tsize < 2 * n:
        tsize *= 2
    mask = tsize - 1
    tab = np.full((tsize, 5), _EMPTY, dtype=np.int64)
    ckey = np.empty((n, 4), dtype=np.int64)
    ncell = 0
    for i in range(n):
        k = level[i]
        ix = np.int64(np.floor((centers[i, 0] - lo[0]) * inv_h[k]))
        iy = np.int64(np.floor((centers[i, 1] - lo[1]) * inv_h[k]))
        iz = np.int64(np.floor((centers[i, 2] - lo[2]) * inv_h[k]))
        s = _hash4(k, ix, iy, iz, mask)
        while True:
            c = tab[s, 4]
            if c == _EMPTY:
                tab[s, 0] = k
                tab[s, 1] = ix
                tab[s, 2] = iy
                tab[s, 3] = iz
                tab[s, 4] = ncell
                ckey[ncell, 0] = k
                ckey[ncell, 1] = ix
                ckey[ncell, 2] = iy
                ckey[ncell, 3] = iz
                cell_of[i] = ncell
                ncell += 1
                break
            if tab[s, 0] == k and tab[s, 1] == ix and tab[s, 2] == iy and tab[s, 3] == iz:
                cell_of[i] = c
                break
            s = (s + 1) & mask

    # ---- renumber cells in (level, z, y, x) order (memory locality of neighbours)
    mx = np.zeros(3, dtype=np.int64)
    for c in range(ncell):
        for d in range(3):
            mx[d] = max(mx[d], ckey[c, d + 1] + 1)
    if float(nlev) * float(mx[0]) * float(mx[1]) * float(mx[2]) < 4.0e18:
        skey = np.empty(ncell, dtype=np.int64)
        for c in range(ncell):
            skey[c] = ((ckey[c, 0] * mx[2] + ckey[c, 3]) * mx[1] + ckey[c, 2]) * mx[0] + ckey[c, 1]
        corder = np.argsort(skey)
        rank = np.empty(ncell, dtype=np.int64)
        for q in range(ncell):
            rank[corder[q]] = q
        ck2 = np.empty((ncell, 4), dtype=np.int64)
        for c in range(ncell):
            ck2[rank[c]] = ckey[c]
        ckey = ck2
        for i in range(n):
            cell_of[i] = rank[cell_of[i]]
        tab[:, 4] = _EMPTY
        for c in range(ncell):
            _insert(tab, mask, ckey[c, 0], ckey[c, 1], ckey[c, 2], ckey[c, 3], c)

    # ---- linked cells: particles sorted by cell (stable counting sort), data copied in order
    start = np.zeros(ncell + 1, dtype=np.int64)
    for i in range(n):
        start[cell_of[i] + 1] += 1
    for c in range(ncell):
        start[c + 1] += start[c]
    fill = start[:ncell].copy()
    sidx = np.empty(n, dtype=np.int64)
    for i in range(n):
        c = cell_of[i]
        sidx[fill[c]] = i
        fill[c] += 1
    sc = np.empty((n, 3))
    sr = np.empty(n)
    for q in range(n):
        i = sidx[q]
        sc[q, 0] = centers[i, 0]
        sc[q, 1] = centers[i, 1]
        sc[q, 2] = centers[i, 2]
        sr[q] = radii[i] + 0.5 * margin
    lev_used = np.zeros(nlev, dtype=np.bool_)
    for i in range(n):
        lev_used[level[i]] = True

    return SphereGrid(nlev, lev_rmax, lev_used, lo, inv_h, tab, mask, ckey, ncell, start, sidx,
                      sc, sr)


@njit(cache=True, inline="always")
def _slots_near(sc, sr, a, b) -> bool:
    """The comparison of :func:`_near_each_other` for the bodies in grid slots a, b (sr holds
    radius + margin/2: the same floating-point operations)."""
    ex = sc[b, 0] - sc[a, 0]
    ey = sc[b, 1] - sc[a, 1]
    ez = sc[b, 2] - sc[a, 2]
    t = sr[a] + sr[b]
    return t > 0.0 and ex * ex + ey * ey + ez * ez < t * t


@njit(cache=True)
def sphere_pairs_jit(centers, radii, margin):
    """Compiled core of :func:`sphere_pairs` (no input checks). Returns int64 (K, 2)."""
    n = centers.shape[0]
    if n < 2:
        return np.empty((0, 2), dtype=np.int64)
    if n <= ALL_PAIRS_MAX:
        return _sphere_pairs_all(centers, radii, margin)
    g = _sphere_grid(centers, radii, margin)
    nlev, lev_rmax, lev_used, lo, inv_h = g.nlev, g.lev_rmax, g.lev_used, g.lo, g.inv_h
    tab, mask, ckey, ncell, start, sidx, sc, sr = (g.tab, g.mask, g.ckey, g.ncell, g.start,
                                                   g.sidx, g.sc, g.sr)

    # ---- per cell: own level by the half shell (13 neighbours + itself), coarser levels by
    #      the cells that the cell's inflated bounding box reaches
    buf = np.empty((max(16, 4 * n), 2), dtype=np.int64)
    npair = np.int64(0)         # not a literal: one specialisation of _push
    for c in range(ncell):
        kc = ckey[c, 0]
        cx = ckey[c, 1]
        cy = ckey[c, 2]
        cz = ckey[c, 3]
        p0 = start[c]
        p1 = start[c + 1]
        for dz in range(-1, 2):
            for dy in range(-1, 2):
                for dx in range(-1, 2):
                    if dz < 0 or (dz == 0 and (dy < 0 or (dy == 0 and dx < 0))):
                        continue
                    same = dx == 0 and dy == 0 and dz == 0
                    if same:
                        nc = c
                    else:
                        nc = _lookup(tab, mask, kc, cx + dx, cy + dy, cz + dz)
                        if nc < 0:
                            continue
                    for a in range(p0, p1):
                        b0 = a + 1 if same else start[nc]
                        for b in range(b0, start[nc + 1]):
                            if _slots_near(sc, sr, a, b):
                                i = sidx[a]
                                j = sidx[b]
                                if i < j:
                                    buf = _push(buf, npair, i, j)
                                else:
                                    buf = _push(buf, npair, j, i)
                                npair += 1
        if kc == nlev - 1:
            continue
        # bounding box of the cell's inflated spheres
        b_lo0 = np.inf
        b_lo1 = np.inf
        b_lo2 = np.inf
        b_hi0 = -np.inf
        b_hi1 = -np.inf
        b_hi2 = -np.inf
        for a in range(p0, p1):
            b_lo0 = min(b_lo0, sc[a, 0] - sr[a])
            b_lo1 = min(b_lo1, sc[a, 1] - sr[a])
            b_lo2 = min(b_lo2, sc[a, 2] - sr[a])
            b_hi0 = max(b_hi0, sc[a, 0] + sr[a])
            b_hi1 = max(b_hi1, sc[a, 1] + sr[a])
            b_hi2 = max(b_hi2, sc[a, 2] + sr[a])
        for k in range(kc + 1, nlev):
            if not lev_used[k]:
                continue
            w = lev_rmax[k] + 0.5 * margin
            x0 = np.int64(np.floor((b_lo0 - w - lo[0]) * inv_h[k]))
            x1 = np.int64(np.floor((b_hi0 + w - lo[0]) * inv_h[k]))
            y0 = np.int64(np.floor((b_lo1 - w - lo[1]) * inv_h[k]))
            y1 = np.int64(np.floor((b_hi1 + w - lo[1]) * inv_h[k]))
            z0 = np.int64(np.floor((b_lo2 - w - lo[2]) * inv_h[k]))
            z1 = np.int64(np.floor((b_hi2 + w - lo[2]) * inv_h[k]))
            for iz in range(z0, z1 + 1):
                for iy in range(y0, y1 + 1):
                    for ix in range(x0, x1 + 1):
                        nc = _lookup(tab, mask, k, ix, iy, iz)
                        if nc < 0:
                            continue
                        for a in range(p0, p1):
                            for b in range(start[nc], start[nc + 1]):
                                if _slots_near(sc, sr, a, b):
                                    i = sidx[a]
                                    j = sidx[b]
                                    if i < j:
                                        buf = _push(buf, npair, i, j)
                                    else:
                                        buf = _push(buf, npair, j, i)
                                    npair += 1
    return _sort_pairs(buf, npair, n)


@njit(cache=True)
def _pairs_of_slot(g, a, margin, fresh, buf, npair):
    """The pairs (i, j), i < j, of the body in grid slot a with every other body, except
    those with a fresh body of lower index (found from that one), appended to buf; returns
    (buf, npair).  Each level's cells that the body's sphere, inflated by the level's largest
    reach, touches (about 27 of its own level)."""
    i = g.sidx[a]
    for k in range(g.nlev):
        if not g.lev_used[k]:
            continue
        # the farthest a partner's centre can be (slack: the cells only need to cover it)
        w = (g.sr[a] + g.lev_rmax[k] + 0.5 * margin) * (1.0 + 1e-12)
        lo, inv_h = g.lo, g.inv_h[k]
        x0 = np.int64(np.floor((g.sc[a, 0] - w - lo[0]) * inv_h))
        x1 = np.int64(np.floor((g.sc[a, 0] + w - lo[0]) * inv_h))
        y0 = np.int64(np.floor((g.sc[a, 1] - w - lo[1]) * inv_h))
        y1 = np.int64(np.floor((g.sc[a, 1] + w - lo[1]) * inv_h))
        z0 = np.int64(np.floor((g.sc[a, 2] - w - lo[2]) * inv_h))
        z1 = np.int64(np.floor((g.sc[a, 2] + w - lo[2]) * inv_h))
        for iz in range(z0, z1 + 1):
            for iy in range(y0, y1 + 1):
                for ix in range(x0, x1 + 1):
                    nc = _lookup(g.tab, g.mask, k, ix, iy, iz)
                    if nc < 0:
                        continue
                    for b in range(g.start[nc], g.start[nc + 1]):
                        j = g.sidx[b]
                        if j == i or (fresh[j] and j < i) or not _slots_near(g.sc, g.sr, a, b):
                            continue
                        buf = _push(buf, npair, min(i, j), max(i, j))
                        npair += 1
    return buf, npair


@njit(cache=True)
def sphere_pairs_of(centers, radii, margin, fresh):
    """The pairs of :func:`sphere_pairs_jit` that hold a ``fresh`` (n,) bool body, sorted
    lexicographically: the grid over all bodies, queried from the fresh ones only (each pair
    tested by the same comparison, so it is in both results or in neither).  Cost ~ n for the
    grid plus the fresh bodies' neighbours."""
    n = centers.shape[0]
    if n < 2:
        return np.empty((0, 2), dtype=np.int64)
    g = _sphere_grid(centers, radii, margin)
    buf = np.empty((16, 2), dtype=np.int64)
    npair = np.int64(0)
    for a in range(n):
        if fresh[g.sidx[a]]:
            buf, npair = _pairs_of_slot(g, a, margin, fresh, buf, npair)
    return _sort_pairs(buf, npair, n)


def _as_centers_radii(centers, radii) -> tuple[np.ndarray, np.ndarray]:
    c = np.ascontiguousarray(centers, dtype=np.float64).reshape(-1, 3) if np.size(centers) \
        else np.zeros((0, 3))
    r = np.ascontiguousarray(radii, dtype=np.float64).reshape(-1)
    if c.shape[0] != r.shape[0]:
        raise ValueError(f"centers has {c.shape[0]} rows but radii has {r.shape[0]} entries")
    if not (np.all(np.isfinite(c)) and np.all(np.isfinite(r))):
        raise ValueError("centers and radii must be finite")
    if np.any(r < 0):
        raise ValueError("radii must be >= 0")
    return c, r


def sphere_pairs(centers: np.ndarray, radii: np.ndarray, margin: float = 0.0) -> np.ndarray:
    """Candidate body pairs of the first global level (bounding spheres, paper Eq. 3).

    Parameters
    ----------
    centers: (N, 3) sphere centres (m), i.e. the bodies' world centroids.
    radii: (N,) bounding radii (m), ``Shape.bounding_radius``.
    margin: Verlet-like skin (m), >= 0: pairs with ``|c_i - c_j| < r_i + r_j + margin``
        (Eq. 3 with ``delta + margin > 0``) are returned.

    Returns
    -------
    int64 array (K, 2) of pairs (i, j), i < j, sorted lexicographically (deterministic,
    independent of the input order of equal keys).
    """
    c, r = _as_centers_radii(centers, radii)
    margin = float(margin)
    if not (np.isfinite(margin) and margin >= 0):
        raise ValueError("margin must be finite and >= 0")
    return sphere_pairs_jit(c, r, margin)


def sphere_pairs_brute(centers: np.ndarray, radii: np.ndarray, margin: float = 0.0) -> np.ndarray:
    """O(N^2) reference of :func:`sphere_pairs` (same comparison), for tests and small N."""
    c, r = _as_centers_radii(centers, radii)
    n = c.shape[0]
    if n < 2:
        return np.empty((0, 2), dtype=np.int64)
    i, j = np.triu_indices(n, 1)
    d = c[j] - c[i]
    s = r[i] + r[j] + margin
    keep = (s > 0) & (np.einsum("ij,ij->i", d, d) < s * s)
    return np.stack([i[keep], j[keep]], axis=1).astype(np.int64)

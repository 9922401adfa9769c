"""A hashed grid of spheres that answers whether another sphere is clear of them: the
placement of ``Random`` groups (:mod:`nurbsdem.placement`) and of the particles an inlet
creates (:mod:`nurbsdem.dynamics.flow`) test their bounding spheres with it.

The grid is a tuple (keys, used, head, spheres, nxt, cell) made by :func:`sphere_grid`: an
open-addressing hash table of cells of side ``cell`` (m; at least the sum of any two radii
it will hold, so that a sphere meets only spheres of its 27 neighbouring cells), each with a
linked list of its spheres (centre and radius, m).  Compiled, since placement tries many
positions one after another.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def _slot(keys: np.ndarray, used: np.ndarray, i: int, j: int, k: int) -> int:
    """The slot of cell (i, j, k) in the open-addressing table (keys (cap,3), used (cap,);
    cap a power of two): where it is, or the free slot where it goes."""
    mask = used.shape[0] - 1
    h = ((i * 73856093) ^ (j * 19349663) ^ (k * 83492791)) & mask
    while used[h] and not (keys[h, 0] == i and keys[h, 1] == j and keys[h, 2] == k):
        h = (h + 1) & mask
    return h


@njit(cache=True)
def add_sphere(grid, s: int, x: float, y: float, z: float, r: float) -> None:
    """Sphere s (centre m, radius m) into the grid: its cell's list."""
    keys, used, head, spheres, nxt, cell = grid
    i, j, k = math.floor(x / cell), math.floor(y / cell), math.floor(z / cell)
    h = _slot(keys, used, i, j, k)
    if not used[h]:
        used[h] = True
        keys[h, 0], keys[h, 1], keys[h, 2] = i, j, k
        head[h] = -1
    spheres[s, 0], spheres[s, 1], spheres[s, 2], spheres[s, 3] = x, y, z, r
    nxt[s] = head[h]
    head[h] = s


@njit(cache=True)
def add_spheres(grid, centres: np.ndarray, radii: np.ndarray) -> None:
    """The spheres (centres (K,3), radii (K,), m) into the grid as spheres 0 .. K-1."""
    for s in range(radii.shape[0]):
        add_sphere(grid, s, centres[s, 0], centres[s, 1], centres[s, 2], radii[s])


@njit(cache=True)
def is_clear(grid, x: float, y: float, z: float, r: float) -> bool:
    """Whether a sphere (x, y, z, r) is clear of every sphere in the grid, |c − c_j| ≥ r_j + r:
    the spheres of its 27 neighbouring cells (the cells are at least as large as any two
    radii together, so no other sphere can overlap it)."""
    keys, used, head, spheres, nxt, cell = grid
    i, j, k = math.floor(x / cell), math.floor(y / cell), math.floor(z / cell)
    for di in range(-1, 2):
        for dj in range(-1, 2):
            for dk in range(-1, 2):
                h = _slot(keys, used, i + di, j + dj, k + dk)
                s = head[h] if used[h] else -1
                while s >= 0:
                    dx, dy, dz = spheres[s, 0] - x, spheres[s, 1] - y, spheres[s, 2] - z
                    if math.sqrt(dx * dx + dy * dy + dz * dz) < spheres[s, 3] + r:
                        return False
                    s = nxt[s]
    return True


def sphere_grid(n_spheres: int, cell: float) -> tuple:
    """An empty grid for n_spheres spheres with cells of side ``cell`` (m): a hash table of
    cells (at most one per sphere, at most half full) with a list of spheres each."""
    cap = 1 << max(4, int(2 * max(n_spheres, 1) - 1).bit_length())
    return (np.zeros((cap, 3), np.int64), np.zeros(cap, np.bool_), np.full(cap, -1, np.int64),
            np.zeros((n_spheres, 4)), np.full(n_spheres, -1, np.int64), float(cell))


@njit(cache=True)
def first_clear(grid, candidates: np.ndarray, r: float) -> int:
    """The first of the positions ``candidates`` (K,3) m where a sphere of radius r is clear
    of the grid's spheres (:func:`is_clear`), or −1 where none is."""
    for k in range(candidates.shape[0]):
        if is_clear(grid, candidates[k, 0], candidates[k, 1], candidates[k, 2], r):
            return k
    return -1

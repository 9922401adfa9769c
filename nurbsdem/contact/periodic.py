"""Periodic cells: positions wrapped into the cell, and the bounding-sphere search across its faces.

A periodic cell is the box [lo, hi) repeated along one, two or three axes (``periodic``), so
that a few thousand particles stand for a bulk (a shear cell, a chute section).  A body at x
is the same body at every image x + s ∘ L (L = hi − lo, s an integer vector, zero on the
axes that are not periodic).

The search runs the ordinary linked-cell search of :mod:`nurbsdem.contact.broadphase` over
the bodies and their *ghost images*: copies shifted by ±L of the bodies within ``reach`` of a
periodic face (and, for two or three periodic axes, across the cell's edges and corners), as
LIGGGHTS and Yade's periodic cells do.  ``reach`` is the largest sum of two bounding radii
plus the margin, so a body within reach of a face sees every partner across it.  Each pair is
returned once, as (i, j, s) with i < j: the partner's image is x_j + s ∘ L.  A pair can have
only one touching image when every periodic length is at least twice the reach
(:func:`check_cell` refuses a shorter cell: a particle would touch its own image or a
partner twice).

Lengths in metres.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from .broadphase import sphere_pairs


@dataclass(frozen=True)
class PeriodicCell:
    """The box [lo, hi) (m) and which of its axes repeat (bool (3,))."""

    lo: np.ndarray
    hi: np.ndarray
    periodic: np.ndarray

    @property
    def length(self) -> np.ndarray:
        """Edge lengths L = hi − lo (m)."""
        return self.hi - self.lo


def make_cell(lo, hi, periodic) -> PeriodicCell:
    """A :class:`PeriodicCell`; ValueError when an edge is not positive and finite or no axis
    repeats."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    periodic = np.asarray(periodic, bool)
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(hi > lo)):
        raise ValueError(f"a periodic cell needs lo < hi on every axis, got {lo} .. {hi}")
    if not periodic.any():
        raise ValueError("a periodic cell repeats along one axis at least")
    return PeriodicCell(lo, hi, periodic)


def check_cell(cell: PeriodicCell, reach: float) -> None:
    """ValueError when a periodic length is under twice ``reach`` (m): the largest sum of two
    bounding radii plus the search margin (module docstring)."""
    short = cell.periodic & (cell.length < 2.0 * reach)
    if short.any():
        axis = "xyz"[int(np.flatnonzero(short)[0])]
        raise ValueError(f"the periodic length along {axis} ({cell.length[short][0]:.6g} m) is "
                         f"under twice the contact reach ({2 * reach:.6g} m): a particle would "
                         f"touch its own image")


def wrap(x: np.ndarray, cell: PeriodicCell) -> tuple[np.ndarray, np.ndarray]:
    """Positions (N,3) brought into [lo, hi) on the periodic axes, and the integer shifts
    (N,3) taken off them (x = wrapped + shift ∘ L)."""
    x = np.asarray(x, float)
    shift = np.zeros(x.shape, np.int64)
    axes = cell.periodic
    shift[:, axes] = np.floor((x[:, axes] - cell.lo[axes]) / cell.length[axes]).astype(np.int64)
    wrapped = x - shift * cell.length
    # round-off can leave a wrapped coordinate at hi: it belongs at lo
    at_hi = axes & (wrapped >= cell.hi)
    wrapped = np.where(at_hi, wrapped - cell.length, wrapped)
    shift = shift + at_hi.astype(np.int64)
    return wrapped, shift


def minimum_image(d: np.ndarray, cell: PeriodicCell) -> np.ndarray:
    """Separation vectors (…,3) brought to their shortest image on the periodic axes."""
    d = np.array(d, float)
    axes = cell.periodic
    d[..., axes] -= cell.length[axes] * np.round(d[..., axes] / cell.length[axes])
    return d


def ghost_images(x: np.ndarray, reach: float,
                 cell: PeriodicCell) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The images of wrapped positions x (N,3) within ``reach`` of a periodic face: their
    positions (M,3), owners (M,) and shifts (M,3) (image = x[owner] + shift ∘ L)."""
    near_lo = x < cell.lo + reach
    near_hi = x >= cell.hi - reach
    pos, own, sft = [], [], []
    choices = [(-1, 0, 1) if p else (0,) for p in cell.periodic]
    for s in itertools.product(*choices):
        s = np.array(s, np.int64)
        if not s.any():
            continue
        # an image shifted by +L along an axis copies a body near the low face, and so on
        keep = np.ones(len(x), bool)
        for a in range(3):
            if s[a] > 0:
                keep &= near_lo[:, a]
            elif s[a] < 0:
                keep &= near_hi[:, a]
        idx = np.flatnonzero(keep)
        pos.append(x[idx] + s * cell.length)
        own.append(idx)
        sft.append(np.repeat(s[None], len(idx), axis=0))
    if not pos:
        return np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros((0, 3), np.int64)
    return np.concatenate(pos), np.concatenate(own), np.concatenate(sft)


def periodic_sphere_pairs(centers: np.ndarray, radii: np.ndarray, margin: float,
                          cell: PeriodicCell) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (K,2) i < j of bounding spheres (wrapped centres (N,3), radii (N,) m) within
    ``margin`` of touching through the cell, and each pair's shift (K,3): the partner's image
    is centers[j] + shift ∘ L (module docstring)."""
    centers = np.asarray(centers, float)
    radii = np.asarray(radii, float)
    n = len(centers)
    if n == 0:
        return np.zeros((0, 2), np.int64), np.zeros((0, 3), np.int64)
    reach = 2.0 * float(radii.max()) + margin
    check_cell(cell, reach)
    gx, gown, gshift = ghost_images(centers, reach, cell)
    allx = np.concatenate([centers, gx])
    allr = np.concatenate([radii, radii[gown]])
    owner = np.concatenate([np.arange(n), gown])
    shift = np.concatenate([np.zeros((n, 3), np.int64), gshift])
    pairs = sphere_pairs(allx, allr, margin)
    a, b = pairs[:, 0], pairs[:, 1]
    real = (a < n) | (b < n)              # a pair of two ghosts repeats a real one
    a, b = a[real], b[real]
    i, j = owner[a], owner[b]
    s = shift[b] - shift[a]
    swap = i > j
    i, j = np.where(swap, j, i), np.where(swap, i, j)
    s = np.where(swap[:, None], -s, s)
    keys = np.column_stack([i, j, s])
    keys = np.unique(keys[i != j], axis=0)
    return keys[:, :2].copy(), keys[:, 2:].copy()

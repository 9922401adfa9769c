"""Regular lattices of particle positions (dense packs for verification and benchmarks)."""
from __future__ import annotations

import numpy as np


def fcc_positions(cells: int, spacing: float, origin=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Centres (M,3) of a face-centred cubic block of ``cells``³ unit cells, nearest neighbours
    ``spacing`` apart (m): the points (i, j, k)·spacing/√2 with 0 <= i, j, k <= 2·cells and
    i + j + k even.  Interior points have the 12 neighbours of the FCC lattice."""
    if cells < 1 or not spacing > 0:
        raise ValueError("fcc_positions needs cells >= 1 and spacing > 0")
    g = np.arange(2 * cells + 1)
    i, j, k = np.meshgrid(g, g, g, indexing="ij")
    even = ((i + j + k) % 2) == 0
    pts = np.stack([i[even], j[even], k[even]], axis=1).astype(float)
    return pts * (spacing / np.sqrt(2.0)) + np.asarray(origin, float)[None]

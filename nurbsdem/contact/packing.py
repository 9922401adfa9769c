"""Joining the curved walls' arrays for the compiled deck steps
(:data:`~nurbsdem.contact.curved_compiled.CurvedConst`): each wall's share of a joined array
is the slice between two offsets, so that the packed types do not depend on the walls.  A
kind packs every wall's entry of a per-wall array, zero for a wall of another kind."""
from __future__ import annotations

import numpy as np


def offsets(sizes) -> np.ndarray:
    """(len(sizes) + 1,) int64: where each part starts in the joined array, then the total."""
    return np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)


def joined(parts, empty_shape: tuple, dtype=float) -> np.ndarray:
    """The parts concatenated along their first axis (contiguous, ``dtype``); without parts an
    empty array of ``empty_shape``."""
    return (np.ascontiguousarray(np.concatenate(parts), dtype) if parts
            else np.zeros(empty_shape, dtype))


def own(geometries: list, geometry_type: type) -> list:
    """The walls' ``geometries`` where they are of ``geometry_type``, None elsewhere."""
    return [g if isinstance(g, geometry_type) else None for g in geometries]


def per_wall(mine: list, get, dtype=float) -> np.ndarray:
    """``get(g)`` of each geometry of ``mine`` (:func:`own`), 0 for a wall of another kind."""
    return np.array([0 if g is None else get(g) for g in mine], dtype)

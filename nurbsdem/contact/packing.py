"""Joining the curved walls' arrays for the compiled deck steps
(:data:`~nurbsdem.contact.curved_compiled.CurvedConst`): each wall's share of a joined array
is the slice between two offsets, so that the packed types do not depend on the walls."""
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

"""Patch connectivity and shape checks (placeholder: being written)."""
from __future__ import annotations

import numpy as np


class Connectivity:
    def __init__(self, neighbours: np.ndarray) -> None:
        self.neighbours = neighbours


def find_connectivity(patches, source=None) -> Connectivity:
    return Connectivity(np.full((len(patches), 4, 3), -1, np.int64))


def check_shape(shape, source=None) -> None:
    return None

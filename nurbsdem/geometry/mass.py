"""Mass properties (placeholder: being written)."""
from __future__ import annotations

import numpy as np


def mass_properties(patches):
    pts = np.concatenate([p.control_points.reshape(-1, 3) for p in patches])
    return 0.0, pts.mean(0), np.zeros((3, 3))

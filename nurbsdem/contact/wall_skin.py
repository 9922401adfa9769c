"""Gap certificates of exact spheres against one NURBS surface wall: which spheres need their
closest point solved at an evaluation.

A sphere found apart from the wall keeps its distance to the wall's surface less its radius,
``gap`` (m), with its centre ``x0`` and the wall's odometer ``odo0`` at that time.  The
distance from a point to a surface changes by at most the point's displacement plus the
largest displacement of a surface point, so while

    |x − x0| + (odo − odo0) < gap

the sphere is still apart and its closest point is not solved (its row would be inactive).
The odometer ``odo`` (m) adds up, at each evaluation, a bound of the largest displacement of
any wall point since the previous one: for the pose change (R₀, t₀) → (R, t) of points
within ``extent`` of the wall-frame centre c,

    ‖R − R₀‖_F · extent + |(R − R₀) c + t − t₀|.

The distance is that of the closest point the wall kernel finds
(:func:`~nurbsdem.contact.surface_wall.sphere_surface_row`), the kernel's own premise: the
nearest point, unique where the wall's radius of curvature exceeds the distance.
Certificates only skip work: the rows are those of solving every sphere at every
evaluation, bit for bit.  Lengths in metres.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


class WallSkin:
    """The certificates of the spheres (N of them) against one surface wall whose samples
    ``seed_x`` (S,3) (wall frame) are at most ``spacing`` (m) apart (their extent bounds the
    wall's)."""

    def __init__(self, n: int, seed_x: np.ndarray, spacing: float) -> None:
        self.gap = np.full(n, -1.0)                 # no certificate yet
        self.x0 = np.zeros((n, 3))
        self.odo0 = np.zeros(n)
        self.odo = 0.0
        self.centre, self.extent = wall_reach(seed_x, spacing)
        self.pose: tuple[np.ndarray, np.ndarray] | None = None

    def advance(self, R: np.ndarray, t: np.ndarray) -> None:
        """The odometer moved on by the wall's motion to pose (R, t) (module docstring)."""
        R, t = np.ascontiguousarray(R, float), np.ascontiguousarray(t, float)
        if self.pose is not None:
            self.odo += pose_travel(self.pose[0], self.pose[1], R, t, self.centre, self.extent)
        self.pose = (R.copy(), t.copy())

    def due(self, idx: np.ndarray, x: np.ndarray) -> np.ndarray:
        """The spheres of ``idx`` (centres x (N,3) m) whose certificate does not hold."""
        out = np.empty(len(idx), np.int64)
        return out[:due_spheres(idx, x, self.gap, self.x0, self.odo0, self.odo, out)]

    def certify(self, idx: np.ndarray, x: np.ndarray, gap: np.ndarray) -> None:
        """Spheres ``idx`` found at least ``gap`` (m, ≤ 0: touching, no certificate) apart
        with centres x (N,3) now."""
        self.gap[idx] = gap
        self.x0[idx] = x[idx]
        self.odo0[idx] = self.odo


def wall_reach(seed_x: np.ndarray, spacing: float) -> tuple[np.ndarray, float]:
    """The wall-frame centre (3,) m of a surface wall's samples ``seed_x`` (S,3) and the
    radius (m) about it within which its surface lies (the samples' plus their spacing)."""
    centre = 0.5 * (seed_x.min(axis=0) + seed_x.max(axis=0))
    return centre, float(np.linalg.norm(seed_x - centre, axis=1).max()) + spacing


@njit(cache=True)
def pose_travel(R0, t0, R, t, centre, extent) -> float:
    """A bound (m) of the largest displacement of a wall point within ``extent`` (m) of the
    wall-frame ``centre`` (3,) when the wall moves from pose (R0, t0) to (R, t) (module
    docstring): ‖R − R₀‖_F · extent + |(R − R₀) c + t − t₀|."""
    fro, lin = 0.0, 0.0
    for a in range(3):
        s = t[a] - t0[a]
        for c in range(3):
            d = R[a, c] - R0[a, c]
            fro += d * d
            s += d * centre[c]
        lin += s * s
    return math.sqrt(fro) * extent + math.sqrt(lin)


@njit(cache=True)
def due_spheres(idx, x, gap, x0, odo0, odo, out) -> int:
    """The spheres of idx whose certificate (module docstring) fails, into out; their count."""
    n = 0
    for m in range(idx.shape[0]):
        i = idx[m]
        moved = math.sqrt((x[i, 0] - x0[i, 0]) ** 2 + (x[i, 1] - x0[i, 1]) ** 2
                          + (x[i, 2] - x0[i, 2]) ** 2)
        if gap[i] <= 0.0 or moved + (odo - odo0[i]) >= gap[i]:
            out[n] = i
            n += 1
    return n

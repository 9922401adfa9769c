"""Support points of one convex NURBS body at one pose, from Python: the flat-wall kernel's
support mapping (:func:`nurbsdem.contact.flat_wall.solve_wall`, paper Eq. 8–9) asked along any
direction, with its derivative dp/de (the Hessian of the support function, paper Eq. 14–15).

The pose and every point and direction are in one frame chosen by the caller (a wall's own
frame: ``x = pos + R x_file``).  A query along a unit direction d is the flat-wall problem of
the plane through the body's centroid with normal −d (the support point along d is the
deepest point below that plane); the rows of each query warm-start the next (the kernel's
first-order prediction of the parameters for a new direction).

Lengths in metres.
"""
from __future__ import annotations

import numpy as np

from .detect import _work
from .lcp import F_PA, I_FAIL, I_VALID, NF, NI
from .stage2 import _MA
from .flat_wall import solve_wall

__all__ = ["SupportOracle"]

#: the parameter rectangle of the query planes: (u_min, u_max, v_min, v_max)
UNIT_DOMAIN = np.array([0.0, 1.0, 0.0, 1.0])


def _perpendicular(d: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to the unit vector d."""
    k = int(np.argmin(np.abs(d)))
    e = np.zeros(3)
    e[k] = 1.0
    a = e - d * d[k]
    return a / np.linalg.norm(a)


class SupportOracle:
    """Support mapping of shape ``shape`` of ``table`` (a
    :class:`~nurbsdem.contact.detect.ContactTable`) at the pose (pos (3,) m, R (3,3)) in the
    caller's frame."""

    def __init__(self, table, shape: int, pos: np.ndarray, R: np.ndarray) -> None:
        self.table = table
        self.shape = int(shape)
        self.info = table.info[self.shape]
        self.cen = np.ascontiguousarray(table.centroid[self.shape], float)
        self.radius = float(table.radius[self.shape])
        self.pos = np.ascontiguousarray(pos, float)
        self.R = np.ascontiguousarray(R, float)
        #: the body's centroid in the caller's frame (m)
        self.centroid = self.pos + self.R @ self.cen
        self.prev_f = np.zeros(NF)
        self.prev_i = np.zeros(NI, np.int64)
        self.res_f = np.zeros(NF)
        self.res_i = np.zeros(NI, np.int64)
        self.no_mask = np.zeros(0, np.bool_)
        self._M = np.zeros((3, 3))
        self.calls = 0

    def plane(self, origin: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray,
                                                                               np.ndarray]:
        """The flat-wall rows (res_f (NF,), res_i (NI,), views reused by the next call) of the
        parallelogram ``origin + α a + β b`` (normal a × b towards the body): the support point
        along −n (``F_PA``), its signed distance to the plane (``F_SD``), its projection
        (``F_PB``) and its coordinates (α, β) in ``F_PAR + 2:4``
        (:func:`~nurbsdem.contact.flat_wall.solve_wall`)."""
        ws, (wf, wi, wfs, _) = _work()
        solve_wall(self.table.tab, self.info, self.cen, self.radius, self.table.seeds,
                   self.pos, self.R, np.ascontiguousarray(origin, float),
                   np.ascontiguousarray(a, float), np.ascontiguousarray(b, float), UNIT_DOMAIN,
                   self.prev_f, self.prev_i, ws, wf, wi, wfs, self.no_mask, self.res_f,
                   self.res_i)
        self.calls += 1
        if self.res_i[I_VALID] == 1 and self.res_i[I_FAIL] == 0:
            self.prev_f[:] = self.res_f
            self.prev_i[:] = self.res_i
        self._M = wf[_MA:_MA + 3].copy()
        return self.res_f, self.res_i

    def point(self, d: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
        """(p (3,) m, M (3,3) m, ok): the support point along the unit direction d (the point
        of the surface farthest along d) and its derivative dp/dd (symmetric, positive
        semi-definite, on the plane normal to d), in the caller's frame."""
        d = np.asarray(d, float)
        a = _perpendicular(d)
        b = np.cross(a, d)                 # a × b = −d: the plane's normal is −d
        rf, ri = self.plane(self.centroid, a, b)
        M = self.R @ self._M @ self.R.T
        ok = bool(ri[I_FAIL] == 0 and ri[I_VALID] == 1)
        return rf[F_PA:F_PA + 3].copy(), M, ok

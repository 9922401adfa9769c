"""A particle shape: a closed, convex surface made of NURBS patches, with what every later
stage needs from it — connectivity, mass properties, bounding volumes and packed arrays.

Frames: everything here is in the *file frame* (the coordinates of the shape file, metres).
A body's pose maps the file frame to the world: ``x_world = position + R @ x_file``.
"""
from __future__ import annotations

import logging
from functools import cached_property
from typing import Sequence

import numpy as np

from .kernel import PatchPool
from .nurbs import Patch


class Shape:
    """A closed multi-patch (or single-patch) NURBS particle.

    Parameters
    ----------
    patches: the patches (validated here).
    name: optional label.
    source: the file it came from (used in error messages).
    check: verify closed / outward / convex and raise :class:`~nurbsdem.errors.GeometryError`
        with the location when it is not.
    convexity_tol: accepted non-convexity relative to the size (default
        :data:`~nurbsdem.geometry.connectivity.DEFAULT_CONVEXITY_TOL`); a shape that is not
        convex but within it is accepted with one warning on the ``nurbsdem`` logger.

    Attributes
    ----------
    patches: list of :class:`Patch`.
    connectivity: :class:`~nurbsdem.geometry.connectivity.Connectivity`.
    volume: m^3.  centroid: m (file frame).  inertia: 3x3 volume inertia about the centroid
        in the file frame, m^5 (times density gives the mass inertia, kg m^2).
    bounding_radius: m, distance from the centroid to the farthest control point (paper Eq. 3).
    convexity: :class:`~nurbsdem.geometry.connectivity.Convexity` (None when not checked).
    warnings: one-line warnings issued while checking (e.g. nearly convex).
    """

    def __init__(self, patches: Sequence[Patch], name: str | None = None,
                 source: str | None = None, check: bool = True,
                 convexity_tol: float | None = None) -> None:
        from .connectivity import check_shape, convexity_warning, find_connectivity
        from .mass import mass_properties

        self.patches = list(patches)
        self.name = name
        self.source = source
        for i, pt in enumerate(self.patches):
            pt.validate(source, i)
        self.connectivity = find_connectivity(self.patches, source=source)
        self.volume, self.centroid, self.inertia = mass_properties(self.patches)
        self.convexity = None
        self.convexity_tol = convexity_tol
        self.warnings: list[str] = []
        if check:
            self.convexity = check_shape(self, source=source, convexity_tol=convexity_tol)
            msg = convexity_warning(self.convexity, source, convexity_tol)
            if msg is not None:
                self.warnings.append(msg)
                logging.getLogger("nurbsdem").warning(msg)

    # ------------------------------------------------------------------ derived data
    @property
    def size(self) -> float:
        """Characteristic length (m): diameter of the control points' bounding box."""
        pts = self.control_point_cloud
        return float(np.linalg.norm(pts.max(0) - pts.min(0)))

    @cached_property
    def control_point_cloud(self) -> np.ndarray:
        """All control points, array (N, 3), file frame."""
        return np.concatenate([p.control_points.reshape(-1, 3) for p in self.patches])

    @cached_property
    def bounding_radius(self) -> float:
        """Radius of the bounding sphere centred at the centroid (paper Eq. 3), m."""
        return float(np.linalg.norm(self.control_point_cloud - self.centroid, axis=1).max())

    @cached_property
    def patch_boxes(self) -> np.ndarray:
        """Per patch an axis-aligned box in the file frame from its control points:
        array (P, 2, 3) of (min corner, max corner). With positive weights the patch lies in
        the convex hull of its control points, hence in this box."""
        return np.array([[p.control_points.reshape(-1, 3).min(0),
                          p.control_points.reshape(-1, 3).max(0)] for p in self.patches])

    @cached_property
    def pool(self) -> PatchPool:
        """The patches packed into flat arrays for the compiled kernel."""
        return PatchPool.from_patches(self.patches)

    def evaluate(self, patch: int, u, v, order: int = 2) -> np.ndarray:
        """Point and derivatives of one patch at (u, v); see :meth:`Patch.evaluate`."""
        return self.patches[patch].evaluate(u, v, order)

    def transformed(self, matrix: np.ndarray, offset=None, name: str | None = None) -> "Shape":
        """The shape under x -> matrix @ x + offset (a proper affine map keeps convexity)."""
        return Shape([p.transformed(matrix, offset) for p in self.patches],
                     name=name if name is not None else self.name, source=self.source,
                     convexity_tol=getattr(self, "convexity_tol", None))

    def scaled(self, factor: float, name: str | None = None) -> "Shape":
        """The shape scaled about the file origin."""
        return self.transformed(np.eye(3) * factor, name=name)

    def __repr__(self) -> str:
        return (f"Shape(name={self.name!r}, patches={len(self.patches)}, "
                f"volume={self.volume:.6g} m^3, bounding_radius={self.bounding_radius:.6g} m)")

"""nurbsdem: discrete element method for convex rigid particles bounded by exact NURBS surfaces."""
from __future__ import annotations

__version__ = "0.1.0"

from .errors import GeometryError, InputError, NurbsdemError  # noqa: E402
from .geometry.nurbs import Patch  # noqa: E402
from .geometry.shape import Shape  # noqa: E402
from .io.shapefile import load_shape, save_shape  # noqa: E402

__all__ = ["__version__", "Patch", "Shape", "load_shape", "save_shape",
           "NurbsdemError", "InputError", "GeometryError"]

"""Geometry: the NURBS kernel, particle shapes, connectivity, mass properties, tessellation."""
from .nurbs import Patch

__all__ = ["Patch"]

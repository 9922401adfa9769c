"""Shape generators (public API): exact spheres and ellipsoids, the paper's particles, walls.

``nurbsdem.shapes.sphere(r)``, ``.ellipsoid(a, b, c)``, ``.single_patch_sphere(r)`` return
:class:`~nurbsdem.geometry.shape.Shape` objects; ``.flat_wall`` and ``.box_walls`` return
patches. See :mod:`nurbsdem.geometry.generators` and :mod:`nurbsdem.geometry.particles`.
"""
from .geometry.generators import (box_walls, ellipsoid, ellipsoid_patches, flat_wall,
                                  single_patch_sphere, single_patch_sphere_patches, sphere,
                                  sphere_patches)
from .geometry.particles import paper_particle, paper_particle_shape

__all__ = ["sphere", "ellipsoid", "single_patch_sphere", "sphere_patches", "ellipsoid_patches",
           "single_patch_sphere_patches", "flat_wall", "box_walls", "paper_particle",
           "paper_particle_shape"]

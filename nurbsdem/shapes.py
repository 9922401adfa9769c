"""Shape generators (public API): exact spheres and ellipsoids, the paper's particles, walls.

``nurbsdem.shapes.sphere(r)``, ``.ellipsoid(a, b, c)``, ``.single_patch_sphere(r)`` return
:class:`~nurbsdem.geometry.shape.Shape` objects; ``.flat_wall`` and ``.box_walls`` return
patches. See :mod:`nurbsdem.geometry.generators` and :mod:`nurbsdem.geometry.particles`.
"""
from .geometry.generators import (box_walls, ellipsoid, ellipsoid_patches, flat_wall,  # noqa: F401
                                  single_patch_sphere, single_patch_sphere_patches, sphere,
                                  sphere_patches)

try:  # the paper's particles (A, B, C)
    from .geometry.particles import paper_particle  # noqa: F401
except ImportError:  # pragma: no cover - module being written
    pass

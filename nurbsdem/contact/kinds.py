"""Geometry kinds of the bodies and the pair solver of each pair of kinds: one place for the
names (numba reads module-level integers and arrays as compile-time constants, so the names
cost nothing in the kernels).

Where each kind's pieces live (docs/extending.md): the exact sphere in
:mod:`nurbsdem.geometry.analytic` (which shapes are spheres) and :mod:`nurbsdem.contact.sphere`
(its pair solvers: against a sphere in closed form, against a NURBS particle by the
point-to-surface problem), the NURBS particle in :mod:`nurbsdem.geometry` and
:mod:`nurbsdem.contact.detect` (the LCP of paper Sec. 3.2), the flat wall
in :mod:`nurbsdem.contact.flat_wall` (its frame, broad phase and both pair solvers), the
mesh and surface walls each an object of its own module, :mod:`nurbsdem.contact.mesh_kind`
and :mod:`nurbsdem.contact.surface_kind` (what they answer: :mod:`nurbsdem.contact.wall_kinds`);
the dispatch of a scene's due pairs is :func:`nurbsdem.contact.listed.solve_due_into`, that
of the mesh and surface walls :class:`nurbsdem.contact.curved_walls.CurvedWallContacts`.
"""
from __future__ import annotations

import numpy as np
from numba import njit

#: geometry kinds: an exact sphere, a NURBS particle, a flat rectangle wall, a triangle-mesh
#: wall (:mod:`nurbsdem.contact.mesh_wall`), an open NURBS surface wall
#: (:mod:`nurbsdem.contact.surface_wall`)
SPHERE, NURBS_PARTICLE, FLAT_WALL, MESH_WALL, SURFACE_WALL = 0, 1, 2, 3, 4
N_KINDS = 5

#: pair solvers: the closed forms and the point-to-surface problem of
#: :mod:`nurbsdem.contact.sphere`, the LCP batch of
#: :mod:`nurbsdem.contact.detect`, the support-mapping kernel of :mod:`nurbsdem.contact.flat_wall`;
#: NO_SOLVER: the two kinds never meet (two walls)
CLOSED_FORM, POINT_SURFACE, LCP, WALL_SUPPORT = 0, 1, 2, 3
#: a sphere against a mesh wall: per triangle in closed form, one contact per flat or convex
#: region (:func:`~nurbsdem.contact.mesh_wall.sphere_mesh_rows`); against a surface wall: its
#: closest point by projected Newton (:func:`~nurbsdem.contact.surface_wall.sphere_surface_row`);
#: both run by :class:`~nurbsdem.contact.curved_walls.CurvedWallContacts`
MESH_ROWS, SURFACE_POINT = 4, 5
#: a NURBS particle against a mesh wall: per face, edge and vertex by its support mapping
#: (:func:`~nurbsdem.contact.mesh_particle_compiled.particle_mesh_into`, the Python
#: :func:`~nurbsdem.contact.mesh_particle.particle_mesh_contacts` its reference); against a
#: surface wall: Newton over the wall's parameters on the support point along the wall's normal
#: (:func:`~nurbsdem.contact.surface_particle.particle_surface_row`); run by the same provider
MESH_SUPPORT, SURFACE_SUPPORT = 6, 7
NO_SOLVER = -1
#: most contacts one particle keeps with one mesh or surface wall per evaluation (the faces of
#: a concave fold); the keys of those contacts leave room for as many
#: (:func:`~nurbsdem.contact.curved_walls.wall_contact_key`)
MAX_PER_WALL = 8

#: (kind, kind) -> pair solver (symmetric).  A sphere against a NURBS particle takes the LCP
#: where the scene does not allow the point solver (:func:`pair_solver`).
PAIR_SOLVER = np.full((N_KINDS, N_KINDS), NO_SOLVER, np.int64)
for _a, _b, _solver in ((SPHERE, SPHERE, CLOSED_FORM), (SPHERE, FLAT_WALL, CLOSED_FORM),
                        (SPHERE, NURBS_PARTICLE, POINT_SURFACE),
                        (NURBS_PARTICLE, NURBS_PARTICLE, LCP),
                        (NURBS_PARTICLE, FLAT_WALL, WALL_SUPPORT),
                        (SPHERE, MESH_WALL, MESH_ROWS), (SPHERE, SURFACE_WALL, SURFACE_POINT),
                        (NURBS_PARTICLE, MESH_WALL, MESH_SUPPORT),
                        (NURBS_PARTICLE, SURFACE_WALL, SURFACE_SUPPORT)):
    PAIR_SOLVER[_a, _b] = PAIR_SOLVER[_b, _a] = _solver
del _a, _b, _solver


@njit(cache=True, inline="always")
def pair_solver(kind_a: int, kind_b: int, point_surface: bool) -> int:
    """The pair solver of two kinds; POINT_SURFACE only where the scene allows it
    (``point_surface``), else the LCP."""
    solver = PAIR_SOLVER[kind_a, kind_b]
    if solver == POINT_SURFACE and not point_surface:
        return LCP
    return solver

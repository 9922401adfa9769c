"""``MoveWall NAME ToContact [Gap g] Direction d`` of a mesh or NURBS surface wall: translate
the wall along the unit direction d until its smallest distance to the particles is g.

The travel s* (m) is the first s, coming from far behind along d, at which the wall moved by
s d comes within g of a particle, the wall standing where earlier steps left it (its pose
``R``, ``t``; the travel is added to the wall's displacement, as a ``Displacement`` step's
is).  The distance is to the wall's surface, from either side of a two-sided mesh or a
surface wall and from the front of a one-sided mesh (``OneSided``: a particle the wall meets
from behind passes through it, as in the wall's contacts); it is the flat wall's
``ToContact`` on a planar mesh.

* Exact spheres against a mesh: a sphere swept along the line against the triangles, in
  closed form (:mod:`nurbsdem.contact.mesh_sweep`).
* Everything else (spheres against a surface wall; NURBS particles, by their support mapping,
  paper Eq. 8–9, from where their bounding sphere comes within g: no contact before): a
  safeguarded root find on the exact gap G(s) of each particle (:func:`first_crossing`).

**Why the root find does not step over the first contact.**  Translating the wall by δ moves
every wall point by |δ|, so G is 1-Lipschitz in s: from a point with G(s) − g = r > 0 no
contact is possible before s + r (the conservative advance).  Each step is a Newton step on
G (its slope n · d from the contact normal), never shorter than that advance; a step that
lands at G ≤ g gives a bracket, refined by the Illinois variant of regula falsi to ~1e-13 of
the scale.  Against one convex piece of the wall (a triangle, a convex patch) the distance
is convex in s (the distance between two convex sets along a translation), and a Newton step
from the left of a convex function's first root never passes it; a step can pass over a
root only where another piece, not the nearest at the step's start, comes within g and
leaves again inside that step.

Lengths in metres.
"""
from __future__ import annotations

import math

import numpy as np

from .errors import InputError

#: relative tolerance (of the scale: the wall's box and the particle's size) of the travel
REL_TOL = 1e-13
#: Newton or conservative steps before a particle's root find gives up
MAX_IT = 200


def first_crossing(gap, s0: float, s1: float, tol: float) -> float:
    """First s in [s0, s1] with ``gap(s)[0]`` ≤ 0, ``gap(s)`` = (G(s) − g, dG/ds) of a
    1-Lipschitz G (module docstring), s0 clear (G(s0) > g); inf when there is none."""
    s = s0
    G, slope = gap(s)
    if not G > 0.0:
        return s
    for _ in range(MAX_IT):
        if G <= tol:
            return s
        step = G / -slope if slope < -1e-3 else G        # Newton, or the plain advance
        sn = min(s + max(step, G), s1)
        Gn, slope_n = gap(sn)
        if Gn <= 0.0:
            return _illinois(gap, s, G, sn, Gn, tol)
        if sn >= s1:
            return math.inf
        s, G, slope = sn, Gn, slope_n
    raise RuntimeError("ToContact: the root find did not converge")


def _illinois(gap, a: float, ga: float, b: float, gb: float, tol: float) -> float:
    """A root of gap in [a, b] (ga > 0 ≥ gb) by the Illinois regula falsi."""
    side = 0
    for _ in range(MAX_IT):
        x = b - gb * (b - a) / (gb - ga)
        if not a < x < b:
            x = 0.5 * (a + b)
        gx = gap(x)[0]
        if abs(gx) <= tol or b - a <= tol:
            return x
        if gx > 0.0:
            a, ga = x, gx
            if side == 1:
                gb *= 0.5
            side = 1
        else:
            b, gb = x, gx
            if side == -1:
                ga *= 0.5
            side = -1
    return 0.5 * (a + b)


def curved_to_contact(model, bodies, wall_offset: np.ndarray, step, curved,
                      time: float) -> float:
    """Translate mesh or surface wall ``step.wall`` (its row of ``wall_offset`` (walls, 3) m
    replaced) along ``step.direction`` until its gap to the nearest particle is
    ``step.gap``; returns the travel (m).  ``curved``: the model's
    :class:`~nurbsdem.curved_wall_motion.CurvedWallMotion` (the wall's rest pose and
    geometry) at time ``time`` (s)."""
    from .contact.curved_walls import CurvedWall
    from .contact.surface_particle import ContactNotUnique
    from .io.deck_curved import sphere_radii
    k = model.wall_names.index(step.wall)
    c = k - len(model.walls)
    where = f"Step {step.id}: MoveWall {step.wall} ToContact"
    if step.direction is None:
        raise model.error(f"{where}: a mesh or surface wall needs a Direction", step.line)
    if len(bodies) == 0:
        raise InputError(f"{where} needs particles")
    d = np.asarray(step.direction, float)
    d = d / np.linalg.norm(d)
    kind, geom = curved.geometry()[c]
    R, t = curved.pose(c).at(time, wall_offset[k])
    lo, hi = CurvedWall(kind, geom).world_box(R, t)
    corners = np.array([[(lo, hi)[i][0], (lo, hi)[j][1], (lo, hi)[m][2]]
                        for i in (0, 1) for j in (0, 1) for m in (0, 1)])
    along = corners @ d
    radius, spheres = sphere_radii(model, bodies.shape_id)
    travel = math.inf
    if spheres.any():
        travel = _spheres(geom, bodies.position[spheres], radius[spheres], step.gap, R, t, d,
                          along)
    if not spheres.all():
        try:
            travel = min(travel, _nurbs(model, bodies, ~spheres, geom, step.gap, R, t, d,
                                        along, f"{where}: surface wall {step.wall!r}"))
        except ContactNotUnique as exc:      # the wall curves more tightly than a particle
            raise model.error(f"{exc}; move the wall by a Displacement instead",
                              step.line) from None
    if not math.isfinite(travel):
        raise model.error(f"{where}: the wall meets no particle along the direction "
                          f"{np.round(d, 6).tolist()}", step.line)
    wall_offset[k] = wall_offset[k] + travel * d
    return travel


def _spheres(geom, x: np.ndarray, r: np.ndarray, g: float, R, t, d, along) -> float:
    """The least travel (m) bringing the wall (at pose R, t) within g of the spheres (centres
    x (N,3) m, radii r (N,)): in closed form where the wall's kind has one
    (:meth:`~nurbsdem.contact.wall_kinds.WallKind.sphere_travels`), else the root find on
    each sphere's exact gap (:meth:`~nurbsdem.contact.wall_kinds.WallKind.sphere_row`)."""
    from .contact.lcp import F_N, F_SD
    from .contact.wall_kinds import kind_of
    kind = kind_of(geom)
    travels = kind.sphere_travels(geom, x, r + g, R, t, d)
    if travels is not None:
        return float(travels.min())

    def gap_of(i):
        def gap(s):
            f = kind.sphere_row(geom, x[i], r[i], R, t + s * d)
            if f is None:
                raise RuntimeError(f"ToContact: no closest point on the {kind.name} wall")
            return f[F_SD] - g, float(f[F_N:F_N + 3] @ d)
        return gap
    return _least(gap_of, x @ d, r + g, along, kind.size(geom))


def _least(gap_of, centre_along: np.ndarray, reach: np.ndarray, along: np.ndarray,
           size: float) -> float:
    """The least first crossing over the particles: particle i's window of travel is where
    the wall's box (corners projected on the direction: ``along`` (8,)) meets its ball of
    radius ``reach[i]`` about its centre (at ``centre_along[i]`` m along it); the particles
    go in the order of their windows' starts and stop once a start lies past the best."""
    start = centre_along - reach - along.max()
    end = centre_along + reach - along.min()
    best = math.inf
    for i in np.argsort(start, kind="stable"):
        if start[i] >= best:
            break
        scale = size + reach[i]
        s0 = start[i] - 1e-3 * scale
        best = min(best, first_crossing(gap_of(i), s0, min(end[i] + 1e-3 * scale, best),
                                        REL_TOL * scale))
    return best


def _nurbs(model, bodies, mask, geom, g: float, R, t, d, along, where: str) -> float:
    """The least travel (m) bringing the wall (at pose R, t) within g of the NURBS particles
    ``mask``: from where each one's bounding sphere comes within g (the sphere's own first
    crossing: no contact before it), the root find on the particle's exact distance
    (:func:`_nurbs_gap`)."""
    from .contact.detect import ContactTable
    from .contact.wall_kinds import kind_of
    idx = np.flatnonzero(mask)
    tables = {}
    for sid in np.unique(bodies.shape_id[idx]).tolist():
        tables[sid] = ContactTable([model.shapes[sid].shape])
    Rs = bodies.rotation_matrices()
    centre = bodies.position[idx]
    radius = np.array([tables[int(bodies.shape_id[i])].radius[0] for i in idx])
    best = math.inf
    for m, i in enumerate(idx.tolist()):
        table = tables[int(bodies.shape_id[i])]
        pos = bodies.position[i] - Rs[i] @ table.centroid[0]
        scale = kind_of(geom).size(geom) + radius[m]
        s0 = _spheres(geom, centre[m:m + 1], radius[m:m + 1], g, R, t, d, along)
        if not s0 < best:
            continue
        end = float(centre[m] @ d + radius[m] + g - along.min()) + 1e-3 * scale
        gap = _nurbs_gap(table, pos, Rs[i], geom, g, R, t, d, radius[m] * 1.25 + g, where)
        best = min(best, first_crossing(gap, s0, min(end, best), REL_TOL * scale))
    return best


def _nurbs_gap(table, pos, Rb, geom, g: float, R, t, d, reach: float, where: str):
    """gap(s) = (G(s) − g, dG/ds) of the NURBS particle (pose pos, Rb; shape 0 of ``table``)
    and the wall moved by s d: the least signed distance over the wall's features within
    ``reach`` (m) of its centroid (paper Eq. 8–9 through the support mapping,
    :meth:`~nurbsdem.contact.wall_kinds.WallKind.particle_row`), its slope the contact
    normal's component along d; with none there, G − g ≥ reach − radius − g (the bounding
    sphere), a safe advance with slope 0."""
    from .contact.lcp import F_N, F_SD
    from .contact.wall_kinds import kind_of
    clear = reach - float(table.radius[0]) - g
    kind = kind_of(geom)
    work = kind.row_work(geom)

    def gap(s):
        f = kind.particle_row(geom, table, pos, Rb, R, t + s * d, reach, where, work)
        if f is None:
            return clear, 0.0
        return float(f[F_SD]) - g, float(f[F_N:F_N + 3] @ d)
    return gap

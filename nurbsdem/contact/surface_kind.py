"""The open NURBS surface wall as a geometry kind (:data:`~nurbsdem.contact.kinds.
SURFACE_WALL`): everything the step's contact provider (:class:`~nurbsdem.contact.
curved_walls.CurvedWallContacts`), the pre-run checks (:mod:`nurbsdem.wall_checks`) and
``MoveWall ToContact`` (:mod:`nurbsdem.curved_to_contact`) ask of a surface wall, answered in
one place (the protocol: :class:`~nurbsdem.contact.wall_kinds.WallKind`).

The pieces it calls: the patch tables, start samples and the spheres' closest point by
projected Newton in :mod:`.surface_wall`, the spheres' gap certificates in :mod:`.wall_skin`,
and the NURBS particles' Newton over the wall's parameters on their support point in
:mod:`.surface_particle` (the kernel in :mod:`.surface_particle_compiled`).  The compiled
deck steps reach the same kernels through :mod:`.curved_compiled`.  Lengths in metres; a
pose (R, t) places the wall: ``x_world = R x_wall + t``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .kinds import SURFACE_WALL
from .lcp import F_SD, I_ACTIVE, NF, NI
from .surface_particle import (particle_surface_row, particle_surface_row_reference, refusal,
                               surface_rows)
from .surface_particle_compiled import CONTACT, NOT_CONVERGED, NOT_UNIQUE
from .surface_wall import SurfaceWall, sphere_contact, sphere_surface_row
from .packing import joined, offsets, own, per_wall
from .wall_skin import WallSkin, wall_reach


@njit(cache=True)
def _surface_rows_of(idx, x, r, R, t, deg, ncp, koff, knots, pw, poff, dom, periodic, seed_x,
                     seed_p, seed_uv, spacing, size, rows_f, owner, gap):
    """The active contact rows of spheres ``idx`` (centres x, radii r) with one surface wall
    at (R, t) into rows_f from row 0, each row's sphere in ``owner``; returns the count (one
    row per sphere at most: the closest point of :func:`sphere_surface_row`).  ``gap`` (m)
    gets, for each sphere of idx, its distance to the wall less its radius where it is
    apart, else 0 (the certificates of :mod:`nurbsdem.contact.wall_skin`)."""
    n = 0
    ev = np.zeros((6, 3))
    one_f = np.zeros(NF)
    one_i = np.zeros(NI, np.int64)
    for m in range(idx.shape[0]):
        i = idx[m]
        ok = sphere_surface_row(x[i], r[i], R, t, deg, ncp, koff, knots, pw, poff, dom,
                                periodic, seed_x, seed_p, seed_uv, spacing, size, ev, one_f,
                                one_i)
        gap[m] = 0.0
        if ok and one_i[I_ACTIVE]:
            rows_f[n, :] = one_f
            owner[n] = i
            n += 1
        elif ok and one_f[F_SD] > 0.0:
            gap[m] = one_f[F_SD]
    return n


@dataclass
class SurfaceState:
    """What a provider keeps of one surface wall between evaluations: the spheres' gap
    certificates (:class:`~nurbsdem.contact.wall_skin.WallSkin`, one per particle: made at
    the first spheres' query and again when the particle count changes; a sphere certified
    apart is not solved again until it or the wall has moved by its gap)."""

    skin: WallSkin | None = None


class SurfaceKind:
    """The surface wall's answers (:class:`~nurbsdem.contact.wall_kinds.WallKind`)."""

    code = SURFACE_WALL
    name = "surface"
    geometry_type = SurfaceWall
    #: what makes the surface's front (messages of one-sided walls; every surface is), and
    #: how to make it act on both sides (it cannot)
    front_rule = "S_u x S_v"
    two_sided_hint = ""

    @staticmethod
    def box_points(g: SurfaceWall) -> tuple[np.ndarray, float]:
        """(points (P,3) m, pad m) whose box, widened by pad, holds the wall: its start
        samples, widened by their spacing."""
        return g.seed_x, g.spacing

    @staticmethod
    def size(g: SurfaceWall) -> float:
        """The diagonal (m) of the control points' bounding box."""
        return float(g.size)

    @staticmethod
    def new_state(g: SurfaceWall) -> SurfaceState:
        """A provider's state of the wall."""
        return SurfaceState()

    @staticmethod
    def sphere_rows(state: SurfaceState, g: SurfaceWall, idx: np.ndarray, x: np.ndarray,
                    radii: np.ndarray, R: np.ndarray, t: np.ndarray) -> tuple:
        """(rows_f, owner, rank) of the touching contacts of the spheres ``idx`` (centres x
        (N,3), radii (N,)) with the wall at (R, t): one per sphere at most (its closest
        point, :func:`_surface_rows_of`), for the spheres whose certificates have expired."""
        if state.skin is None or len(state.skin.gap) != len(radii):
            state.skin = WallSkin(len(radii), g.seed_x, g.spacing)
        skin = state.skin
        skin.advance(R, t)
        idx = skin.due(idx, x)
        rf, owner = np.zeros((len(idx), NF)), np.zeros(len(idx), np.int64)
        gap = np.zeros(len(idx))
        n = _surface_rows_of(idx, x, radii, R, t, g.deg, g.ncp, g.koff, g.knots, g.pw,
                             g.poff, g.dom, g.periodic, g.seed_x, g.seed_p, g.seed_uv,
                             g.spacing, g.size, rf, owner, gap)
        skin.certify(idx, x, gap)
        return rf[:n], owner[:n], np.zeros(n, np.int64)

    @staticmethod
    def particle_rows(state: SurfaceState, g: SurfaceWall, table, idx: np.ndarray,
                      body_shape: np.ndarray, pose_origin: np.ndarray, rot: np.ndarray,
                      R: np.ndarray, t: np.ndarray, label: str) -> tuple:
        """(rows_f, owner, rank) of the touching contacts of the NURBS particles ``idx``
        (shapes ``body_shape`` in the :class:`~nurbsdem.contact.detect.ContactTable`
        ``table``, poses pose_origin (N,3) m, rot (N,3,3)) with the wall at (R, t), in one
        compiled call (:func:`~nurbsdem.contact.surface_particle.surface_rows`); the first
        refusal in ``idx``'s order raises
        :class:`~nurbsdem.contact.surface_particle.ContactNotUnique` naming ``label``."""
        rf, ri, status = surface_rows(table, g, idx, body_shape, pose_origin, rot, R, t)
        bad = np.flatnonzero((status[:, 0] == NOT_CONVERGED) | (status[:, 0] == NOT_UNIQUE))
        if len(bad):
            m, i = bad[0], idx[bad[0]]
            raise refusal(label, pose_origin[i] + rot[i] @ table.centroid[body_shape[i]],
                          int(status[m, 1]), int(status[m, 0]))
        keep = (status[:, 0] == CONTACT) & (ri[:, I_ACTIVE] == 1)
        return rf[keep], idx[keep], np.zeros(int(keep.sum()), np.int64)

    @staticmethod
    def sphere_crossings(g: SurfaceWall, x: np.ndarray, r: np.ndarray,
                         idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(front (N,), back (N,)): the depth (m, 0: none) by which each sphere of ``idx``
        (centres x (N,3), radii r (N,)) crosses the wall at rest, in front of it or behind
        it: the exact closest point of its patches
        (:func:`~nurbsdem.contact.surface_wall.sphere_contact`)."""
        front, back = np.zeros(len(x)), np.zeros(len(x))
        for k in np.asarray(idx, np.int64).tolist():
            res_f, res_i, ok = sphere_contact(g, x[k], r[k])
            if ok and res_f[F_SD] < 0:
                (front if res_i[I_ACTIVE] else back)[k] = -res_f[F_SD]
        return front, back

    @staticmethod
    def particle_crossings(g: SurfaceWall, shapes, x: np.ndarray,
                           rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(front (N,), back (N,)) as :meth:`sphere_crossings` for NURBS particles (``shapes``
        (N,), centroids x (N,3) m, rotations rot (N,3,3)) against the wall at rest: the
        solver's kernel (:func:`~nurbsdem.contact.surface_particle.particle_surface_row`)."""
        from .detect import table_of
        front, back = np.zeros(len(x)), np.zeros(len(x))
        for k, shape in enumerate(shapes):
            pos = x[k] - rot[k] @ np.asarray(shape.centroid, float)
            res_f, res_i, ok = particle_surface_row(table_of(shape), 0, pos, rot[k], g)
            if ok and res_f[F_SD] < 0:
                (front if res_i[I_ACTIVE] else back)[k] = -res_f[F_SD]
        return front, back

    @staticmethod
    def sphere_travels(g: SurfaceWall, x, reach, R, t, d) -> None:
        """No closed form: ``ToContact`` finds the travel on :meth:`sphere_row`."""
        return None

    @staticmethod
    def sphere_row(g: SurfaceWall, x: np.ndarray, r: float, R: np.ndarray, t: np.ndarray):
        """The contact row (NF,) of the sphere (centre x (3,) m, radius r m) with the wall at
        (R, t): its exact closest point (:func:`~nurbsdem.contact.surface_wall.
        sphere_contact`); None where the projected Newton finds none."""
        f, _, ok = sphere_contact(g, x, r, R, t)
        return f if ok else None

    @staticmethod
    def particle_row(g: SurfaceWall, table, pos: np.ndarray, Rb: np.ndarray, R: np.ndarray,
                     t: np.ndarray, reach: float, where: str, work=None):
        """The contact row (NF,) of the NURBS particle (shape 0 of ``table``, pose pos (3,) m,
        Rb (3,3)) with the wall at (R, t) among its patches within ``reach`` (m) of the
        centroid (the Python reference, :func:`~nurbsdem.contact.surface_particle.
        particle_surface_row_reference`, whose refusals name ``where``); None with none
        there."""
        f, _, found = particle_surface_row_reference(table, 0, pos, Rb, g, R, t, where=where,
                                                     reach=reach)
        return f if found else None

    @staticmethod
    def row_work(g: SurfaceWall) -> None:
        """:meth:`particle_row` needs no workspace."""
        return None

    @staticmethod
    def packed(geometries: list, nurbs: bool) -> dict:
        """The surface walls' fields of the compiled deck steps' packed walls
        (:data:`~nurbsdem.contact.curved_compiled.CurvedConst`) among the curved walls'
        ``geometries`` (a wall of another kind has an empty slice and zeros): offsets into
        the joined patch pool (each surface's knot and power-form offsets shifted into it)
        and samples, and per-wall spacing and size.  ``nurbs`` changes nothing here."""
        mine = own(geometries, SurfaceWall)
        surfs = [g for g in mine if g is not None]
        koff, poff = [], []
        k0 = p0 = 0
        for g in surfs:
            koff.append(g.koff + k0)
            poff.append(g.poff + p0)
            k0 += len(g.knots)
            p0 += len(g.pw)
        return dict(
            po=offsets(per_wall(mine, lambda g: len(g.dom), np.int64)),
            so=offsets(per_wall(mine, lambda g: len(g.seed_x), np.int64)),
            deg=joined([g.deg for g in surfs], (0, 2), np.int64),
            ncp=joined([g.ncp for g in surfs], (0, 2), np.int64),
            koff=joined(koff, (0, 2), np.int64), knots=joined([g.knots for g in surfs], (0,)),
            pw=joined([g.pw for g in surfs], (0, 4)), poff=joined(poff, (0,), np.int64),
            dom=joined([g.dom for g in surfs], (0, 4)),
            periodic=joined([g.periodic for g in surfs], (0, 2), np.bool_),
            seed_x=joined([g.seed_x for g in surfs], (0, 3)),
            seed_p=joined([g.seed_p for g in surfs], (0,), np.int64),
            seed_uv=joined([g.seed_uv for g in surfs], (0, 2)),
            spacing=per_wall(mine, lambda g: g.spacing), ssize=per_wall(mine, lambda g: g.size))

    @staticmethod
    def packed_work(geometries: list, n: int, const: dict) -> dict:
        """The surface walls' fields of the compiled deck steps' workspaces
        (:data:`~nurbsdem.contact.curved_compiled.CurvedWork`) for n particles: the spheres'
        gap certificates per wall (:mod:`nurbsdem.contact.wall_skin`), none granted yet,
        and each surface's extent and centre (``const`` is not needed)."""
        W = len(geometries)
        extent, centre = np.zeros(W), np.zeros((W, 3))
        for k, g in enumerate(geometries):
            if isinstance(g, SurfaceWall):
                centre[k], extent[k] = wall_reach(g.seed_x, g.spacing)
        return dict(gap=np.full((W, n), -1.0), x0=np.zeros((W, n, 3)), odo0=np.zeros((W, n)),
                    odo=np.zeros(W), prev_R=np.zeros((W, 3, 3)), prev_t=np.zeros((W, 3)),
                    posed=np.zeros(W, np.bool_), extent=extent, centre=centre)


#: the surface wall kind
SURFACE = SurfaceKind()

"""Mesh and NURBS-surface walls in the step: a contact provider that adds the contacts of the
particles with triangle-mesh walls and open NURBS surface walls to those of another provider
(the scene of the particles and the flat walls, :class:`~nurbsdem.contact.scene.SceneContacts`):
the contacts of the exact spheres and of the NURBS particles (by their support mapping) with
a wall are its kind's answers (:mod:`nurbsdem.contact.wall_kinds`: the mesh,
:mod:`nurbsdem.contact.mesh_kind`, and the surface, :mod:`nurbsdem.contact.surface_kind`).

Each curved wall is a body of the system (global index ``N + first_wall + w``) held in its own
frame and placed by a pose ``x_world = R(t) x_wall + t(t) + d(t)`` (:class:`WallPose`: fixed,
or a rotation at a constant angular velocity about a centre, plus the body's prescribed
displacement d(t) (m) from :class:`~nurbsdem.dynamics.rigid.Walls`, which carries the centre
with it); the kernels bring the particle's pose into the wall frame, so the wall's own
broad-phase grid stays valid as it moves.

Per evaluation and wall: the world box of the wall's points at its pose is tested against
each particle's bounding box (centroid ± bounding radius; a sphere's own radius); a particle
that overlaps it is handed to the wall's kind (the mesh's triangle grid, or the surface's
nearest samples and projected Newton).  The pair solver of each (particle kind, wall kind)
comes from :data:`nurbsdem.contact.kinds.PAIR_SOLVER`.

**Keys (tangential history).**  A particle has one contact with a wall across a flat or
convex region (the mesh kernels' rule), so the contact is keyed by the pair (body, wall), not
by the triangle: a particle sliding from one triangle to the next of a flat region keeps its
spring.
Where it has several (a concave fold: one per face) the k-th (in triangle order) takes its
own key.  The keys lie above ``(N+W)^2``, clear of the ``a·(N+W) + b`` keys of the other
provider.

Units: metres, seconds, radians.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numba import njit

from ..geometry.rotation import quat_matrix
from .contactset import ContactSet
from .kinds import (MAX_PER_WALL, MESH_ROWS, MESH_SUPPORT, NURBS_PARTICLE, SPHERE,
                    SURFACE_POINT, SURFACE_SUPPORT, pair_solver)
from .lcp import F_N, F_PA, F_PB, F_SD
from .wall_kinds import kind_of


@njit(cache=True)
def wall_contact_key(nb: int, owner, wall, n_walls: int, rank):
    """The key of the ``rank``-th contact of particle ``owner`` with curved wall ``wall`` (of
    ``n_walls``) in a system of ``nb`` bodies: above ``nb²``, clear of the pair keys."""
    return nb * nb + ((owner * n_walls + wall) * MAX_PER_WALL + rank)


def split_wall_contact_key(key, nb: int, n_walls: int):
    """(owner, wall, rank) of keys made by :func:`wall_contact_key`."""
    off = key - nb * nb
    rest = off // MAX_PER_WALL
    return rest // n_walls, rest % n_walls, off % MAX_PER_WALL


def serial_order(keys, nb: int, n_walls: int, nurbs: np.ndarray) -> np.ndarray:
    """Sort values (int64) that put contacts with keys ``keys`` in the order
    :class:`CurvedWallContacts` gives them: the pair keys (below nb²) ascending, then the mesh
    and surface walls' contacts wall by wall, the exact spheres' before the NURBS particles'
    (``nurbs`` (N,) bool), each by particle and rank.  Several MPI ranks merge their contacts
    by it into the serial order (:mod:`nurbsdem.parallel.domain`)."""
    keys = np.asarray(keys, np.int64)
    out = keys.copy()
    curved = keys >= nb * nb
    if n_walls and curved.any():
        owner, wall, rank = split_wall_contact_key(keys[curved], nb, n_walls)
        group = 2 * wall + np.asarray(nurbs, bool)[owner]
        out[curved] = nb * nb + ((group * nb + owner) * MAX_PER_WALL + rank)
    return out


@njit(cache=True)
def wall_pose_at(omega, center, t0, R0, shift0, t, d):
    """(R (3,3), t (3,) m) of a wall at time t (s): its rest pose (R0, shift0 m) turned by the
    rotation vector ω (t − t0) (rad; ω (3,) rad/s, none before t0) about ``center`` (3,) m
    (the rotation's matrix from its unit quaternion), then translated by d (3,) m.  Loops,
    not BLAS: the Python and compiled callers get the same bits."""
    rv = omega * max(t - t0, 0.0)
    angle = math.sqrt(rv[0] * rv[0] + rv[1] * rv[1] + rv[2] * rv[2])
    k = math.sin(0.5 * angle) / angle if angle > 1e-8 else 0.5 - angle * angle / 48.0
    m = quat_matrix(math.cos(0.5 * angle), k * rv[0], k * rv[1], k * rv[2])
    R = np.empty((3, 3))
    shift = np.empty(3)
    for r in range(3):
        for c in range(3):
            R[r, c] = (m[3 * r] * R0[0, c] + m[3 * r + 1] * R0[1, c]
                       + m[3 * r + 2] * R0[2, c])
        shift[r] = (m[3 * r] * (shift0[0] - center[0]) + m[3 * r + 1] * (shift0[1] - center[1])
                    + m[3 * r + 2] * (shift0[2] - center[2])) + center[r] + d[r]
    return R, shift


@njit(cache=True)
def world_box(corners, R, t):
    """(lo, hi) of the world box of the wall-frame box ``corners`` (8,3) at pose (R, t)."""
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for c in range(8):
        for a in range(3):
            w = R[a, 0] * corners[c, 0] + R[a, 1] * corners[c, 1] + R[a, 2] * corners[c, 2] + t[a]
            lo[a] = min(lo[a], w)
            hi[a] = max(hi[a], w)
    return lo, hi


@dataclass(frozen=True)
class WallPose:
    """A wall's pose in time: at rest (``omega`` = 0) or turning at the constant angular
    velocity ``omega`` (3,) rad/s about the point ``center`` (3,) m from time ``t0`` (s) on,
    with the rest pose ``R0`` (3,3), ``shift0`` (3,) m at ``t0``; the wall's displacement d
    (its prescribed translation, m) is added after the turn, so ``center`` is the centre
    before that translation and ``center + d`` the centre at time t."""

    omega: np.ndarray = field(default_factory=lambda: np.zeros(3))
    center: np.ndarray = field(default_factory=lambda: np.zeros(3))
    t0: float = 0.0
    R0: np.ndarray = field(default_factory=lambda: np.eye(3))
    shift0: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def at(self, t: float, d: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(R (3,3), t (3,) m): ``x_world = R x_wall + t`` at time t (s): the rest pose turned
        by the rotation vector ω (t − t0) about the centre, then translated by the wall's
        displacement d (3,) m at t (None: none) (:func:`wall_pose_at`, which the compiled
        deck steps call too)."""
        return wall_pose_at(np.asarray(self.omega, float), np.asarray(self.center, float),
                            float(self.t0), np.asarray(self.R0, float),
                            np.asarray(self.shift0, float), float(t),
                            np.zeros(3) if d is None else np.asarray(d, float))


@dataclass
class CurvedWall:
    """One mesh or surface wall: its kind's code (:data:`~nurbsdem.contact.kinds.MESH_WALL`
    or ``SURFACE_WALL``), geometry (that kind's, :mod:`nurbsdem.contact.wall_kinds`), pose
    and name."""

    kind: int
    geometry: object
    pose: WallPose = field(default_factory=WallPose)
    #: the wall's name (in messages; empty: its index)
    name: str = ""
    corners: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        pts, pad = kind_of(self.geometry).box_points(self.geometry)
        lo, hi = pts.min(axis=0) - pad, pts.max(axis=0) + pad
        self.corners = np.array([[(lo, hi)[i][0], (lo, hi)[j][1], (lo, hi)[k][2]]
                                 for i in (0, 1) for j in (0, 1) for k in (0, 1)])

    def world_box(self, R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The world box (lo, hi) of the wall's bounding box at pose (R, t)."""
        return world_box(self.corners, np.ascontiguousarray(R, float),
                         np.ascontiguousarray(t, float))


class CurvedWallContacts:
    """A contact provider: ``base``'s contacts (None: none) and those of the particles with
    ``walls`` (:class:`CurvedWall`), the walls being bodies ``N + first_wall + w``: the exact
    spheres (``spheres`` (N,) bool; radii (N,) m, centred on the centroids) and, given
    ``table`` (the :class:`~nurbsdem.contact.detect.ContactTable` of the particles' shapes)
    and ``body_shape`` (N,) (each particle's shape in it), the NURBS particles (the others);
    without a table only the spheres meet the walls."""

    def __init__(self, base, radii, spheres, walls: list[CurvedWall], first_wall: int,
                 table=None, body_shape=None) -> None:
        self.base = base
        self.radii = np.ascontiguousarray(radii, float)
        self.spheres = np.asarray(spheres, bool)
        self.walls = list(walls)
        self.first_wall = int(first_wall)
        self.table = table
        self.body_shape = None if body_shape is None else np.asarray(body_shape, np.int64)
        #: the radius (m) of each particle's bounding sphere about its centroid (the broad
        #: phase); 0 for a NURBS particle without a table (it meets no wall)
        self.reach = self.radii.copy()
        self.nurbs = ~self.spheres if table is not None else np.zeros_like(self.spheres)
        if table is not None:
            self.reach[self.nurbs] = np.asarray(table.radius, float)[self.body_shape[self.nurbs]]
        #: id(wall): (its geometry, its kind's state: :meth:`WallKind.new_state
        #: <nurbsdem.contact.wall_kinds.WallKind.new_state>`)
        self._states: dict[int, tuple] = {}
        for w in self.walls:
            if pair_solver(SPHERE, w.kind, True) not in (MESH_ROWS, SURFACE_POINT):
                raise ValueError(f"no pair solver for a sphere and wall kind {w.kind}")
            if pair_solver(NURBS_PARTICLE, w.kind, True) not in (MESH_SUPPORT, SURFACE_SUPPORT):
                raise ValueError(f"no pair solver for a NURBS particle and wall kind {w.kind}")

    def __getattr__(self, name):               # the base scene's counters, timers and state
        base = self.__dict__.get("base")
        if base is None:
            raise AttributeError(name)
        return getattr(base, name)

    def _base_kinematics(self, kin):
        """``kin`` as the base provider knows the scene: the walls before the curved ones."""
        if len(self.walls) == 0:
            return kin
        first = self.first_wall
        return replace(kin, wall_displacement=kin.wall_displacement[:first],
                       wall_velocity=kin.wall_velocity[:first],
                       n_bodies=kin.n_particles + first)

    def serial_order(self, keys: np.ndarray, nb: int) -> np.ndarray:
        """Sort values of contact keys in this provider's order (:func:`serial_order`)."""
        return serial_order(keys, nb, len(self.walls), self.nurbs)

    def particles_of(self, keys: np.ndarray, nb: int) -> np.ndarray:
        """The particle (body A) of each contact key: pair keys a·nb + b, wall keys
        (:func:`wall_contact_key`) their owner."""
        keys = np.asarray(keys, np.int64)
        out = keys // nb
        curved = keys >= nb * nb
        if curved.any():
            out[curved] = split_wall_contact_key(keys[curved], nb, len(self.walls))[0]
        return out

    def _candidates(self, x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """The particles whose bounding spheres meet the box [lo, hi] (m) of a wall; on
        several MPI ranks only the owned ones (each contact with a wall is solved by the owner
        of its particle, whose loads reach the ghosts' holders)."""
        r = self.reach[:, None]
        near = np.all((x + r >= lo) & (x - r <= hi), axis=1) & (self.spheres | self.nurbs)
        domain = getattr(self.base, "domain", None)
        if domain is not None:
            near &= domain.owned
        return np.flatnonzero(near).astype(np.int64)

    def _state(self, w: CurvedWall):
        """(kind, state) of wall w (:mod:`nurbsdem.contact.wall_kinds`), the state made again
        when the wall's geometry changes."""
        g = w.geometry
        kind = kind_of(g)
        held = self._states.get(id(w))
        if held is None or held[0] is not g:
            held = self._states[id(w)] = (g, kind.new_state(g))
        return kind, held[1]

    def _wall_rows(self, w: CurvedWall, kin, w_i: int, d: np.ndarray):
        """(rows_f, owner, rank) of the particles' contacts with wall ``w`` (the w_i-th) at
        the time of ``kin``, displaced by d (3,) m: the exact spheres', then the NURBS
        particles' (the first refusal of a contact raises naming the wall)."""
        x = np.ascontiguousarray(kin.x, float)
        R, tv = w.pose.at(kin.t, d)
        near = self._candidates(x, *w.world_box(R, tv))
        kind, state = self._state(w)
        rows = kind.sphere_rows(state, w.geometry, near[self.spheres[near]], x, self.radii, R,
                                tv)
        if not self.nurbs[near].any():
            return rows
        more = kind.particle_rows(state, w.geometry, self.table, near[self.nurbs[near]],
                                  self.body_shape, kin.pose_origin, kin.R, R, tv,
                                  f"{kind.name} wall {w.name or w_i!r}")
        return tuple(np.concatenate([a, b]) for a, b in zip(rows, more))

    def __call__(self, kin) -> ContactSet:
        cs = self.base(self._base_kinematics(kin)) if self.base is not None else None
        cs = ContactSet.empty() if cs is None else cs
        N, nb = kin.n_particles, kin.n_bodies
        shift = np.asarray(cs.wrap, float)
        if shift.shape[0] == N and N and np.any(shift != 0.0):
            # the base scene wrapped the centroids into its periodic cell at this build: the
            # walls meet the particles where the system puts them (it applies the wrap)
            kin = replace(kin, x=np.asarray(kin.x, float) - shift,
                          pose_origin=np.asarray(kin.pose_origin, float) - shift)
        parts = []
        for w_i, w in enumerate(self.walls):
            d = kin.wall_displacement[self.first_wall + w_i]
            rf, owner, rank = self._wall_rows(w, kin, w_i, d)
            if len(owner) == 0:
                continue
            body = N + self.first_wall + w_i
            key = wall_contact_key(nb, owner, w_i, len(self.walls), rank)
            parts.append((owner, np.full(len(owner), body, np.int64), rf, key))
        if not parts:
            return cs
        return _merged(cs, parts)


def _merged(cs: ContactSet, parts: list) -> ContactSet:
    """``cs`` with the contact rows of ``parts`` [(a, b, rows_f, key)] appended (patch −1:
    closed forms, no surface parameters)."""
    a = np.concatenate([cs.body_a] + [p[0] for p in parts]).astype(np.int64)
    b = np.concatenate([cs.body_b] + [p[1] for p in parts]).astype(np.int64)
    rf = np.concatenate([p[2] for p in parts])
    k_new = len(rf)
    pa = np.concatenate([np.asarray(cs.point_a, float).reshape(-1, 3), rf[:, F_PA:F_PA + 3]])
    pb = np.concatenate([np.asarray(cs.point_b, float).reshape(-1, 3), rf[:, F_PB:F_PB + 3]])
    nrm = np.concatenate([np.asarray(cs.normal, float).reshape(-1, 3), rf[:, F_N:F_N + 3]])
    dep = np.concatenate([np.asarray(cs.depth, float), -rf[:, F_SD]])
    key = np.concatenate([np.asarray(cs.key, np.int64)] + [p[3] for p in parts])
    deg = np.concatenate([np.asarray(cs.degenerated, np.int64), np.zeros(k_new, np.int64)])
    out = ContactSet(a, b, pa, pb, nrm, dep, key, deg, monitored=cs.monitored + k_new,
                     active=cs.active + k_new, degenerated_count=cs.degenerated_count,
                     failed=cs.failed, reused=cs.reused, dropped=cs.dropped,
                     dropped_keys=cs.dropped_keys, near_a=cs.near_a, near_b=cs.near_b,
                     near_point=cs.near_point, near_normal=cs.near_normal, near_gap=cs.near_gap)
    # a periodic cell's wrap and images go with the scene's rows (the walls' touch no image)
    out.wrap, out.near_image = cs.wrap, cs.near_image
    if len(cs.image) == len(cs.body_a):
        out.image = np.concatenate([np.asarray(cs.image, float).reshape(-1, 3),
                                    np.zeros((k_new, 3))])
    if len(cs.params) == len(cs.body_a):
        out.params = np.concatenate([np.asarray(cs.params, float).reshape(-1, 4),
                                     np.zeros((k_new, 4))])
        out.patch_a = np.concatenate([np.asarray(cs.patch_a, np.int64),
                                      np.full(k_new, -1, np.int64)])
        out.patch_b = np.concatenate([np.asarray(cs.patch_b, np.int64),
                                      np.full(k_new, -1, np.int64)])
    return out

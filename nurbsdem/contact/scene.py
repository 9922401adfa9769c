"""Contact detection for a whole scene: the hierarchy of paper Section 3 for N bodies and W
flat walls, as a *contact provider* of :class:`nurbsdem.dynamics.DemSystem`.

The global search (levels 1–2) builds a **neighbour list with a skin** (a Verlet list):

1. level 0/1 — bounding spheres (paper Eq. 3) on a cell grid
   (:func:`~nurbsdem.contact.broadphase.sphere_pairs`), bodies against wall rectangles
   (:func:`~nurbsdem.contact.flat_wall.sphere_wall_pairs`), both widened by the skin s;
2. level 2 — oriented patch boxes by the separating-axis test
   (:func:`~nurbsdem.contact.boxes.candidate_patch_pairs_batch`), each box inflated by s/2; a
   body pair with no overlapping boxes is dropped.

A pair left out of the list at its build was at least s apart, so the list stays valid (it
holds every pair that can touch) until some body's largest point displacement since the
build, |Δx| + 2 sin(Δθ/2)·r (r its bounding radius; walls: |Δd|), exceeds s/2: the
displacement between the two poses, not the path, so that a body jiggling in a pack does not
make the list stale; then it is built again.  With s = 0 it is built at every evaluation.
Each body keeps its own built pose: a rebuild renews those of the bodies that moved
(:func:`~nurbsdem.contact.verlet.reposed_bodies`) and tests the patch boxes of their pairs
only; the other pairs keep their candidate patches (a list that equals a full build at the
bodies' built poses).
Each body also carries an **odometer**, the sum over force evaluations of that displacement
(the certificates' measure, below).

Per force evaluation (:meth:`SceneContacts.__call__`) the LCP of each listed pair is solved in
compiled code, in parallel, dispatched by kind without per-pair Python
(:func:`~nurbsdem.contact.listed.solve_due`), warm-started from the pair's previous solution —
**unless the pair holds a separation certificate**: a pair solved as separated by a distance d
cannot touch until the odometers of its two bodies have grown by d together (the distance
between two sets shrinks by at most the largest displacements of their points), so its LCP is
skipped until then.  Both devices are exact: they change which LCPs are solved, not the contacts
found (up to the round-off of a different warm start).

**Only the work a scene needs**: a pair of exact spheres (recognised from their NURBS
surfaces, :func:`~nurbsdem.geometry.analytic.exact_sphere`) and an exact sphere against a
flat wall are solved in closed form, an exact sphere against a NURBS particle as a
point-to-surface problem in 2 parameters (both in :mod:`nurbsdem.contact.sphere`; the LCP
where that does not apply: the sphere's centre
inside the particle, a closest point on a crease or another patch), NURBS against NURBS or
a flat wall by the LCP.

Bookkeeping is in flat arrays aligned with the list (sorted pair keys a·(N+W) + b): previous
solutions, certificates, reused flags; a rebuild carries them over by a merge of sorted keys.

The counters follow the paper's Fig. 5: ``monitored`` = LCPs solved (pairs left by the global
search and not certified apart), ``active`` = penetrating pairs, ``degenerated`` = active pairs solved with the
degeneration technique (Eq. 10–15), ``failed`` = LCPs that did not converge.

A failed LCP never acts for more than one evaluation (never abort, never linger): a pair whose
LCP fails right after a converged solution reuses that solution once, **moved rigidly with the
two bodies** (the surface points follow their bodies, the normal turns with body A, the depth is
measured again between the moved points); if the next LCP of that pair fails too, or there was
no converged solution to move, the pair is left out of the force evaluation (and its tangential
history ends).  Each case is logged once per pair, naming the pair.

Besides the active contacts, each ContactSet reports the separated listed pairs (``near_*``:
their closest points, normal and gap — for a certified pair a lower bound of it) so that the
time-step control can see the contacts about to close.

In a **periodic cell** (``cell``, :mod:`nurbsdem.contact.periodic`) each build wraps the
centroids into the cell and lists every pair with the image of its body B that it touches
(:mod:`nurbsdem.contact.periodic_scene`); the rows are solved with B's image as an extra
particle, and the ContactSet carries each pair's image translation (``image``) and the
build's wrap (``wrap``), which the system applies to its state.

On several MPI ranks (``domain``, :mod:`nurbsdem.parallel.domain`) the list holds the pairs
with a particle the rank owns, a rebuild is decided by all ranks together and starts from every
particle's state sent by its owner, and the counters count the pairs whose body A it owns.

Units: metres, seconds. Global body indices: particles 0..N-1, walls N..N+W-1 (docs/conventions.md).
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Sequence

import numba
import numpy as np

from .contactset import ContactSet
from .boxes import pack_boxes
from .detect import ContactTable
from .lcp import F_N, F_PA, F_PB, F_SD, I_ACTIVE, I_FAIL, I_VALID, NF, NI, full_rows
from .listed import SceneTables, scene_list, scene_tables, solve_due
from .periodic import PeriodicCell, minimum_image, wrap
from .periodic_scene import image_scene, periodic_list
from .verlet import (advance_odometers, carry_rows, contact_arrays, due_rows, list_is_stale,
                     renew_certificates, repose, reposed_bodies)
from .flat_wall import wall_frame, wall_geometry

log = logging.getLogger("nurbsdem")

#: the names of the built poses in a scene's state (``SceneContacts.built_pose``)
BUILT_POSE = ("built_x", "built_R", "built_wall", "built_pos")


@dataclass
class SceneTimers:
    """Wall-clock seconds spent in each part of the contact search."""

    global_search: float = 0.0
    lcp: float = 0.0
    calls: int = 0
    lcps: int = 0

    def as_dict(self) -> dict[str, float]:
        return {"global_search": self.global_search, "lcp": self.lcp,
                "calls": float(self.calls), "lcps": float(self.lcps)}


#: the default skin, as a fraction of the smallest bounding radius (Yade's ``verletDist`` is
#: one too): on the paper example 0.05 -> 0.2 built the list 3.8 x less often (search
#: 7.5 -> 2.9 s) for 17 % more LCPs, on separated pairs, at the same LCP time (0.35: more LCP
#: time than the search saves)
SKIN_FRACTION = 0.2


class SceneContacts:
    """Contact provider for N particles of given shapes and W flat walls.

    Parameters
    ----------
    shapes: the distinct shapes (index = shape index used in ``body_shape``).
    body_shape: int (N,) shape index of each particle.
    walls: W flat wall patches (degree 1, 2×2 control points) in the world at zero
        displacement; their displacements come with the kinematics.
    margin: extra margin added to the bounding volumes (m), on top of the skin.
    skin: Verlet skin s (m) of the neighbour list; None: :data:`SKIN_FRACTION` of the smallest
        bounding radius;
        0: the list is built at every evaluation.
    certificates: skip the LCPs of pairs certified apart (module docstring).
    point_surface: solve an exact sphere against a NURBS particle as a point-to-surface
        problem (module docstring); False: by the LCP.
    cell: a periodic cell (:class:`~nurbsdem.contact.periodic.PeriodicCell`): the list is
        built over the bodies and their images through its faces, the centroids wrapped into
        it at each build (:mod:`nurbsdem.contact.periodic_scene`); None: none.
    table: the :class:`~nurbsdem.contact.detect.ContactTable` of ``shapes`` (they in its
        order), when the caller keeps one across scenes (a run whose particle count changes
        builds a scene at each exchange; the table depends on the shapes only); None: made.
    """

    def __init__(self, shapes: Sequence, body_shape: np.ndarray, walls: Sequence = (),
                 margin: float = 0.0, skin: float | None = None, certificates: bool = True,
                 point_surface: bool = True, cell: PeriodicCell | None = None,
                 table: ContactTable | None = None) -> None:
        self.shapes = list(shapes)
        self.table = ContactTable(self.shapes) if table is None else table
        self.boxes, self.box_offsets = pack_boxes(self.shapes)
        self.body_shape = np.ascontiguousarray(body_shape, dtype=np.int64)
        self.radius = np.asarray(self.table.radius, float)[self.body_shape]
        self.margin = float(margin)
        self.n = int(self.body_shape.shape[0])
        self.walls = list(walls)
        W = len(self.walls)
        self.nb = self.n + W
        self.skin = ((SKIN_FRACTION * float(self.radius.min()) if self.n else 0.0) if skin is None
                     else float(skin))
        self.certificates = bool(certificates)
        self.point_surface = bool(point_surface)
        #: pairs solved by the point-to-surface problem (the rest of ``timers.lcps``: LCPs)
        self.point_solves = 0
        self.wall_center = np.zeros((W, 3))
        self.wall_axes = np.zeros((W, 3, 3))
        self.wall_half = np.zeros((W, 2))
        self.wall_origin = np.zeros((W, 3))
        self.wall_a = np.zeros((W, 3))
        self.wall_b = np.zeros((W, 3))
        self.wall_dom = np.zeros((W, 4))
        for k, w in enumerate(self.walls):
            self.wall_center[k], self.wall_axes[k], self.wall_half[k] = wall_geometry(w)
            self.wall_origin[k], self.wall_a[k], self.wall_b[k], self.wall_dom[k] = wall_frame(w)
        self.depth_wall = 2.0 * float(self.radius.max()) if self.n else 0.0
        # exact spheres take the closed forms of .analytic (module docstring)
        spheres = self.table.spheres
        self.sphere_center = np.array([c if c is not None else np.zeros(3)
                                       for c, _ in (sp or (None, None) for sp in spheres)]).reshape(-1, 3)
        self.sphere_radius = np.array([sp[1] if sp is not None else np.nan for sp in spheres])
        self.is_sphere = np.isfinite(self.sphere_radius)[self.body_shape] if self.n else np.zeros(0, bool)
        self.P = int(np.diff(self.box_offsets).max()) if len(self.shapes) else 1
        #: the neighbour list and the per-pair arrays aligned with it (module docstring)
        self.pairs = _PairState.empty(self.P)
        #: odometer of every body (m, the certificates' measure)
        self.odo = np.zeros(self.nb)
        #: each body's pose at the list's builds (:func:`~nurbsdem.contact.verlet.reposed_bodies`):
        #: centroids (N,3), rotations (N,3,3), walls (W,3), pose positions (N,3)
        self.built_pose: tuple | None = None
        #: poses of the previous call: pose positions (N,3), rotations (N,3,3), walls (W,3),
        #: centroids (N,3)
        self.prev_pose: tuple | None = None
        self.warned: set[tuple[int, str]] = set()
        self.timers = SceneTimers()
        self.builds = 0
        self.last: ContactSet = ContactSet.empty()
        #: the domain decomposition of a run on several MPI ranks (:mod:`nurbsdem.parallel`):
        #: the list holds the pairs with an owned particle; None: a serial run
        self.domain = None
        #: the constant tables of the compiled dispatch (:mod:`nurbsdem.contact.listed`)
        self._tables: SceneTables | None = None
        #: the periodic cell (None: none) and, aligned with the list, the image (L,3) int of
        #: each pair's body B (:mod:`nurbsdem.contact.periodic_scene`)
        self.cell = cell
        self.pair_shift = np.zeros((0, 3), np.int64)
        #: on several ranks, the owned particles (N,) bool the list holds the pairs of (None:
        #: not known, the next build is a full one)
        self._list_owned: np.ndarray | None = None
        #: the list's (rows_f, rows_i, budget) the last evaluation wrote, while nobody else
        #: holds them (:meth:`_writable_rows`)
        self._rows_written: tuple | None = None

    # ------------------------------------------------------------------ state
    def state(self) -> dict[str, np.ndarray]:
        """Everything a restart needs to continue bit for bit, as arrays (on several ranks:
        the serial state, gathered; collective)."""
        st = self.local_state()
        return st if self.domain is None else self.domain.global_scene_state(st)

    def set_state(self, st: dict) -> None:
        """Restore :meth:`state` (on several ranks: this rank's part of it; collective)."""
        if self.domain is None:
            self.set_local_state(st)
            return
        self.set_local_state(self.domain.local_scene_state(st))
        self.domain.after_build(self.pairs.a, self.pairs.b)

    def local_state(self) -> dict[str, np.ndarray]:
        """This rank's list and per-body arrays (the whole state on one rank; the caller may
        keep them: the next evaluation writes its rows into copies)."""
        self._rows_written = None
        st = self.pairs.as_dict()
        st["odo"] = self.odo
        if self.built_pose is not None:
            st.update(built_x=self.built_pose[0], built_R=self.built_pose[1],
                      built_wall=self.built_pose[2], built_pos=self.built_pose[3])
        if self.prev_pose is not None:
            st.update(prev_pos=self.prev_pose[0], prev_R=self.prev_pose[1],
                      prev_wall=self.prev_pose[2], prev_x=self.prev_pose[3])
        if self.cell is not None:
            st["pair_shift"] = self.pair_shift
        return st

    def carry_rows(self, keys: np.ndarray, rows_f: np.ndarray, rows_i: np.ndarray,
                   budget: np.ndarray, odo: np.ndarray) -> None:
        """Start this (new, unbuilt) scene from another scene's last LCP rows and
        certificates, under their pair keys (L,) here (sorted; an exchange of particles
        renumbered them, :mod:`nurbsdem.flow_run`), with the bodies' odometers (nb,) the
        certificates count against: the first list build carries them over, so that a
        certified pair stays unsolved and the others start warm instead of from cold."""
        L = len(keys)
        keys = np.asarray(keys, np.int64)
        no = np.zeros((L, self.P), np.bool_)
        self.pairs = _PairState(keys // self.nb, keys % self.nb, keys, no, no.copy(),
                                np.ascontiguousarray(rows_f, float),
                                np.ascontiguousarray(rows_i, np.int64),
                                np.ascontiguousarray(budget, float), np.zeros(L, bool))
        self.odo = np.array(odo, float)

    def set_local_state(self, st: dict) -> None:
        """Restore :meth:`local_state`."""
        self.pairs = _PairState.from_dict(st, self.P)
        self._list_owned = None
        self.odo = np.array(st.get("odo", np.zeros(self.nb)), float)
        # (a checkpoint of an older version has "built_odo", "built_pose" or no "built_pos":
        # the list is built again)
        self.built_pose = (tuple(np.array(st[k], float) for k in BUILT_POSE)
                           if "built_pos" in st else None)
        self.prev_pose = ((np.array(st["prev_pos"]), np.array(st["prev_R"]),
                           np.array(st["prev_wall"]), np.array(st["prev_x"]))
                          if "prev_x" in st else None)
        if self.cell is not None:
            self.pair_shift = np.array(st.get("pair_shift", np.zeros((len(self.pairs.a), 3))),
                                       np.int64).reshape(-1, 3)

    def snapshot(self):
        """What a rolled-back time step must restore (cheap: a call replaces these objects,
        never mutates them; the list's rows it holds are written into copies, once, by the
        next evaluation: :meth:`_writable_rows`)."""
        self._rows_written = None
        plan = self.domain.plan if self.domain is not None else None
        return (self.pairs, self.odo, self.built_pose, self.prev_pose, self.last, plan,
                self.pair_shift)

    def restore(self, snap) -> None:
        """Undo the calls made since :meth:`snapshot`."""
        (self.pairs, self.odo, self.built_pose, self.prev_pose, self.last, plan,
         self.pair_shift) = snap
        if self.domain is not None:
            self.domain.plan = plan

    # ------------------------------------------------------------------ neighbour list
    def _advance_odometers(self, pose) -> None:
        """odometer += largest displacement of any point of each body since the last call."""
        if self.prev_pose is None:
            return
        _, R, wall, x = pose
        _, R0, wall0, x0 = self.prev_pose
        self.odo = advance_odometers(self.odo, x, x0, R, R0, self.radius, wall, wall0)

    def _list_is_stale(self, pose) -> bool:
        """Whether some body has moved more than half the skin since the list was built
        (pose: this call's (pose positions, rotations, walls, centroids))."""
        _, R, wall, x = pose
        return self.built_pose is None or list_is_stale(*self.built_pose[:3], x, R, wall,
                                                        self.radius, self.skin)

    def _build_list(self, kin, pos: np.ndarray, R: np.ndarray) -> None:
        """Neighbour list with the skin (levels 1–2, :func:`~nurbsdem.contact.listed.scene_list`)
        at the bodies' built poses, the moved ones' renewed
        (:func:`~nurbsdem.contact.verlet.reposed_bodies`), carrying over the per-pair arrays."""
        x = np.ascontiguousarray(kin.x, float)
        wall = np.ascontiguousarray(kin.wall_displacement, float)
        if self.built_pose is None:
            fresh = np.ones(self.nb, np.bool_)
            built = (x.copy(), np.array(R, float), wall.copy(), np.array(pos, float))
        else:
            fresh = reposed_bodies(*self.built_pose[:3], x, R, wall, self.radius, self.skin)
            built = repose(*self.built_pose, x, R, wall, pos, fresh)
        if self.domain is None:
            owned = np.ones(self.n, np.bool_)
        else:
            owned = np.ascontiguousarray(self.domain.owned, np.bool_)
            if self._list_owned is None or not np.array_equal(self._list_owned, owned):
                fresh = np.ones(self.nb, np.bool_)   # the old list lacks the newly owned pairs
            self._list_owned = owned.copy()
        ps = self.pairs
        a, b, keys, mask_a, mask_b = scene_list(
            self.tables(), built[0], built[3], built[1], built[2], owned, self.margin + self.skin,
            ps.keys, ps.mask_a, ps.mask_b, fresh)
        self.pairs = ps.rebuilt(a, b, keys, mask_a, mask_b)
        self.built_pose = built
        self.builds += 1

    def _wrapped(self, pose):
        """The pose (pose positions, rotations, walls, centroids) with the centroids wrapped
        into the periodic cell, and the translation (N,3) m taken off them."""
        pos, R, wall, x = pose
        _, shift = wrap(x, self.cell)
        d = shift * self.cell.length
        return (pos - d, R, wall, x - d), d

    def _build_periodic(self, pose, moved: np.ndarray) -> None:
        """The neighbour list through the periodic cell at the wrapped ``pose``: a full build
        (:func:`~nurbsdem.contact.periodic_scene.periodic_list`), the per-pair arrays carried
        over by key, their points moved with body A by the wrap (``moved`` (N,3) m taken off
        the centroids): a row's points lie in A's frame (a certified pair's row is not solved
        again, and its closest points feed the time-step control)."""
        pos, R, wall, x = pose
        a, b, keys, mask_a, mask_b, shift = periodic_list(
            self.tables(), self.cell, np.ascontiguousarray(x), np.ascontiguousarray(pos),
            np.ascontiguousarray(R), np.ascontiguousarray(wall), self.margin + self.skin)
        if self.domain is not None:              # a rank lists the pairs with an owned body
            keep = self.domain.involves_owned(a, b)
            a, b, keys, mask_a, mask_b, shift = (np.ascontiguousarray(v[keep]) for v in
                                                 (a, b, keys, mask_a, mask_b, shift))
        ps = self.pairs.rebuilt(a, b, keys, mask_a, mask_b)
        rows_f = ps.rows_f.copy()
        rows_f[:, F_PA:F_PA + 3] -= moved[ps.a]
        rows_f[:, F_PB:F_PB + 3] -= moved[ps.a]
        self.pairs = ps.replaced(rows_f, ps.rows_i, ps.budget, ps.reused)
        self.pair_shift = shift            # periodic_list gives them sorted by key already
        self.built_pose = (x.copy(), np.array(R, float), wall.copy(), pos.copy())
        self.builds += 1

    def tables(self) -> SceneTables:
        """The scene's constant tables for the compiled list and dispatch."""
        if self._tables is None:
            self._tables = scene_tables(self)
        return self._tables

    # ------------------------------------------------------------------ the provider
    def __call__(self, kin) -> ContactSet:
        """Active contacts for the kinematics of a :class:`~nurbsdem.dynamics.DemSystem`."""
        t0 = time.perf_counter()
        pos, R = np.ascontiguousarray(kin.pose_origin), np.ascontiguousarray(kin.R)
        pose = (pos, R, np.array(kin.wall_displacement, float), np.array(kin.x, float))
        self._advance_odometers(pose)
        dom = self.domain
        stale = self._list_is_stale(pose) if dom is None else dom.any(self._list_is_stale(pose))
        wrap_shift = np.zeros((0, 3))
        if stale and dom is not None:
            kin = dom.sync_for_build(kin)            # every particle's state from its owner
            pos, R = np.ascontiguousarray(kin.pose_origin), np.ascontiguousarray(kin.R)
            pose = (pos, R, pose[2], np.array(kin.x, float))
        if stale and self.cell is not None:      # wrapped into the cell, then built
            pose, wrap_shift = self._wrapped(pose)
            pos = pose[0]
            self._build_periodic(pose, wrap_shift)
        elif stale:
            self._build_list(kin, pos, R)
        if stale and dom is not None:
            dom.after_build(self.pairs.a, self.pairs.b)
        ps = self.pairs
        reach, due = due_rows(ps.a, ps.b, self.odo, ps.budget, np.bool_(self.certificates))
        t1 = time.perf_counter()
        rows = self._solve(due, pos, R, pose[2])
        t2 = time.perf_counter()
        cs = self._assemble(due, rows, reach, pose)
        cs.wrap = wrap_shift
        self.timers.global_search += t1 - t0
        self.timers.lcp += t2 - t1
        self.timers.calls += 1
        if dom is None:
            self.timers.lcps += int(due.shape[0])
        else:           # each pair counted by one rank (the owner of body A), summed per deck step
            dom.count_work(ps.a, ps.b, due)
            dom.lcps += cs.monitored
            dom.failed += cs.failed
        self.last = cs
        return cs

    def _solve(self, due: np.ndarray, pos: np.ndarray, R: np.ndarray, wall_d: np.ndarray):
        """The listed pairs ``due`` solved in place in the list's rows (:meth:`_writable_rows`),
        each by what its shapes are, warm-started, failed warm starts retried cold
        (:func:`~nurbsdem.contact.listed.solve_due`; a pair that fails keeps its previous
        row, flagged: what it falls back on).  Returns the rows (rows_f, rows_i, budget)."""
        ps = self.pairs
        rows = self._writable_rows(ps)
        st, list_b = self.tables(), ps.b
        if self.cell is not None:          # images of B as extra particles (periodic_scene)
            st, list_b, pos, R = image_scene(st, self.cell, ps.b, self.pair_shift, pos, R)
        self.point_solves += solve_due(st, ps.a, list_b, ps.mask_a, ps.mask_b, rows[0], rows[1],
                                       np.ascontiguousarray(due, np.int64), pos, R,
                                       np.ascontiguousarray(wall_d, float),
                                       numba.get_num_threads())
        return rows

    def _assemble(self, due, rows, reach, pose) -> ContactSet:
        """Store the new rows (a failed pair answered by its previous solution, which its row
        kept, moved rigidly, once, or left out: module docstring), renew the certificates, and
        make the ContactSet."""
        ps = self.pairs
        keys = ps.keys
        rows_f, rows_i, budget = rows
        failed = rows_i[due, I_FAIL] != 0
        reused = np.zeros(ps.a.shape[0], bool)
        dropped = []
        for r in np.nonzero(failed)[0].tolist():
            j = int(due[r])
            a, b, k = int(ps.a[j]), int(ps.b[j]), int(keys[j])
            if rows_i[j, I_VALID] and not ps.reused[j] and self.prev_pose is not None:
                rows_f[j], rows_i[j] = self._moved(rows_f[j], rows_i[j], a, b, pose)
                reused[j] = True
                self._warn(k, a, b, "its last converged solution, moved rigidly "
                           "with the two bodies, is used for this evaluation only")
            else:
                rows_i[j, I_ACTIVE] = 0
                rows_i[j, I_VALID] = 0
                dropped.append(k)
                self._warn(k, a, b, "no fresh converged solution to fall back on: "
                           "the pair is left out of the force evaluation")
        renew_certificates(budget, due, rows_f, rows_i, reach)
        self.pairs = ps.replaced(rows_f, rows_i, budget, reused)
        self.prev_pose = pose
        if self.domain is not None:     # the counters count the pairs this rank counts
            mine = self.domain.counted(ps.a[due])
            return self.contact_set(reach, monitored=int(mine.sum()),
                                    failed=int((failed & mine).sum()),
                                    dropped=np.array(dropped, np.int64))
        return self.contact_set(reach, monitored=int(due.shape[0]), failed=int(failed.sum()),
                                dropped=np.array(dropped, np.int64))

    def _writable_rows(self, ps: "_PairState") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The list's rows, rows_i and certificate budgets for an evaluation to write into:
        the arrays themselves when this scene's last evaluation made them and nobody took
        them since (:meth:`snapshot`, :meth:`local_state`), else copies, which the next
        evaluations then write into in place.  A deck step thus copies the list's rows once,
        not at each of its internal steps."""
        own = self._rows_written
        if (own is not None and own[0] is ps.rows_f and own[1] is ps.rows_i
                and own[2] is ps.budget):
            return own
        self._rows_written = (ps.rows_f.copy(), ps.rows_i.copy(), ps.budget.copy())
        return self._rows_written

    def contact_set(self, reach: np.ndarray, monitored: int, failed: int = 0,
                    dropped: np.ndarray | None = None) -> ContactSet:
        """The ContactSet of the listed pairs' current rows (reach (L,): the sums of the pairs'
        odometers, for the gaps certified pairs leave)."""
        ps = self.pairs
        dropped = np.zeros(0, np.int64) if dropped is None else dropped
        (a, b, pa, pb, nrm, depth, key, deg, params, patch_a, patch_b, near_a, near_b,
         near_point, near_normal, gap) = contact_arrays(ps.rows_f, ps.rows_i, ps.a, ps.b,
                                                        ps.keys, ps.budget, reach)
        image, near_image = np.zeros((0, 3)), np.zeros((0, 3))
        if self.cell is not None:
            image = self.pair_shift[np.searchsorted(ps.keys, key)] * self.cell.length
            near_image = (self.pair_shift[np.searchsorted(ps.keys, near_a * self.nb + near_b)]
                          * self.cell.length)
        return ContactSet(body_a=a, body_b=b, point_a=pa, point_b=pb, normal=nrm, depth=depth,
                          key=key, degenerated=deg, monitored=monitored, active=int(a.shape[0]),
                          degenerated_count=int(np.count_nonzero(deg)), failed=failed,
                          reused=int(ps.reused.sum() if self.domain is None
                                     else (ps.reused & self.domain.counted(ps.a)).sum()),
                          dropped=int(len(dropped) if self.domain is None
                                      else self.domain.counted(dropped // self.nb).sum()),
                          dropped_keys=dropped, near_a=near_a, near_b=near_b,
                          near_point=near_point, near_normal=near_normal, near_gap=gap,
                          params=params, patch_a=patch_a, patch_b=patch_b, image=image,
                          near_image=near_image)

    def _moved(self, row_f: np.ndarray, row_i: np.ndarray, a: int, b: int, pose):
        """A previous LCP row moved rigidly from the previous call's poses to ``pose``: the
        surface points follow their bodies (walls translate), the normal turns with body A and
        the signed distance is measured again between the moved points, (p_B − p_A)·n."""
        N = self.n
        pos, R, wall, _ = pose
        ppos, pR, pwall, _ = self.prev_pose

        def move(i: int, p: np.ndarray, image: np.ndarray) -> np.ndarray:
            if i < N:
                arm = p - ppos[i]
                if self.cell is not None:      # a point of an image, or a body since wrapped
                    arm = minimum_image(arm, self.cell)
                return R[i] @ (pR[i].T @ arm) + pos[i] + image
            return p + (wall[i - N] - pwall[i - N])
        image = np.zeros(3)
        if self.cell is not None:
            image = self.pair_shift[np.searchsorted(self.pairs.keys, a * self.nb + b)] \
                * self.cell.length
        f, iv = row_f.copy(), row_i.copy()
        f[F_PA:F_PA + 3] = move(a, row_f[F_PA:F_PA + 3], np.zeros(3))
        f[F_PB:F_PB + 3] = move(b, row_f[F_PB:F_PB + 3], image)
        n = row_f[F_N:F_N + 3]
        f[F_N:F_N + 3] = R[a] @ (pR[a].T @ n) if a < N else n
        f[F_SD] = float((f[F_PB:F_PB + 3] - f[F_PA:F_PA + 3]) @ f[F_N:F_N + 3])
        iv[I_ACTIVE] = 1 if f[F_SD] < 0 else 0
        iv[I_VALID] = 1
        iv[I_FAIL] = 1
        return f, iv

    def _warn(self, key: int, a: int, b: int, what: str) -> None:
        """Log a failed LCP once per pair and kind of answer."""
        if (key, what) in self.warned:
            return
        self.warned.add((key, what))
        pair = (f"particles {a} and {b}" if b < self.n else f"particle {a} and wall {b - self.n}")
        log.warning("the contact problem (LCP) of %s did not converge: %s (counted as failed in "
                    "monitors/contacts.csv)", pair, what)


@dataclass(frozen=True)
class _PairState:
    """The neighbour list and the arrays aligned with it (L pairs, sorted by key).

    a, b (L,) body indices (b >= N: a wall); keys (L,) a·(N+W) + b; mask_a, mask_b (L, P)
    candidate patches; rows_f (L, NF), rows_i (L, NI) the last LCP row of each pair (zeros:
    none); budget (L,) the certificate: the pair cannot touch while the sum of its bodies'
    odometers stays below it (−inf: none); reused (L,) the row is a failed LCP's moved solution.
    """

    a: np.ndarray
    b: np.ndarray
    keys: np.ndarray
    mask_a: np.ndarray
    mask_b: np.ndarray
    rows_f: np.ndarray
    rows_i: np.ndarray
    budget: np.ndarray
    reused: np.ndarray

    @classmethod
    def empty(cls, P: int) -> "_PairState":
        z = np.zeros(0, np.int64)
        m = np.zeros((0, P), np.bool_)
        return cls(z, z.copy(), z.copy(), m, m.copy(), np.zeros((0, NF)), np.zeros((0, NI), np.int64),
                   np.zeros(0), np.zeros(0, bool))

    def rebuilt(self, a, b, keys, mask_a, mask_b) -> "_PairState":
        """A new list; the arrays of pairs already listed are carried over (sorted merge)."""
        order = np.argsort(keys, kind="stable")
        a, b, keys, mask_a, mask_b = a[order], b[order], keys[order], mask_a[order], mask_b[order]
        rows_f, rows_i, budget, reused = carry_rows(self.keys, self.rows_f, self.rows_i,
                                                    self.budget, self.reused, keys)
        return _PairState(a, b, keys, mask_a, mask_b, rows_f, rows_i, budget, reused)

    def replaced(self, rows_f, rows_i, budget, reused) -> "_PairState":
        return _PairState(self.a, self.b, self.keys, self.mask_a, self.mask_b, rows_f, rows_i,
                          budget, reused)

    def as_dict(self) -> dict[str, np.ndarray]:
        return {"list_a": self.a, "list_b": self.b, "keys": self.keys, "mask_a": self.mask_a,
                "mask_b": self.mask_b, "rows_f": self.rows_f, "rows_i": self.rows_i,
                "budget": self.budget, "reused": self.reused}

    @classmethod
    def from_dict(cls, st: dict, P: int) -> "_PairState":
        if "list_a" not in st:
            return cls.empty(P)
        fields = [np.array(st[k]) for k in ("list_a", "list_b", "keys", "mask_a", "mask_b",
                                             "rows_f", "rows_i", "budget", "reused")]
        fields[5] = full_rows(fields[5])     # a checkpoint of a version with fewer columns
        return cls(*fields)

"""Domain decomposition of a :class:`~nurbsdem.dynamics.DemSystem` over the ranks of an MPI
communicator, **bit for bit equal to the serial run**.

Ownership
---------
Space is cut by recursive coordinate bisection (:func:`~nurbsdem.parallel.cut.decompose`):
the particles are split across the longest extent of their centroids, recursively, into P
groups of equal weight (ties broken by particle index, so every rank computes the same cut).
A rank *owns* the particles of its group: it integrates them and decides everything about
them.  The first cut weighs every particle alike.  Then each rank counts the contact work of
its pairs (each solve at its solver's cost, :data:`~nurbsdem.parallel.cut.SOLVE_COST`, to
both its particles) and the cut is redone (particles *migrate*) with those weights after an
accepted deck step when the most loaded rank's share exceeds the even share by more than
:data:`~nurbsdem.parallel.cut.WORK_IMBALANCE` and the weighted cut lowers that by as much
(scenes whose contacts crowd in one part: a heap, a hopper, a half-filled drum), when the
ghost count has grown by half since the last cut, or every :data:`REBALANCE_EVERY` deck
steps.  The cut changes who computes what, never a result's bits.

Contacts and ghosts
-------------------
A rank lists (neighbour list of :class:`~nurbsdem.contact.scene.SceneContacts`) only the pairs
with at least one owned particle; a pair across the cut is listed and solved on both its
ranks, from the same inputs, so with the same bits.  Its *ghosts* are the other bodies of its
pairs: exactly the particles within reach (bounding radii + skin) of an owned one, the
minimal ghost layer.  A ghost is advanced on every rank that holds it from the same state by
the same kernels, with the loads its owner computed: after each force evaluation the owners
send their ghosts' force and torque (non-blocking point-to-point messages of NumPy buffers,
:meth:`Domain.exchange_loads`), so a ghost's state equals its owner's bit for bit without
sending it.  Particles that are neither owned nor ghosts are frozen on a rank (no velocity,
no load) until the next synchronisation.

Synchronisation
---------------
* At a neighbour-list rebuild (decided by all ranks together: some particle moved more than
  half the skin) every rank receives the owners' state of all particles (allgather), builds
  its list and plans its ghosts anew (an all-to-all of the ghost requests).
* At the end of each deck step (:meth:`Domain.end_of_deck_step`) the owners' state of every
  particle and every rank's *counted* contacts (those whose body A it owns: each contact is
  counted by exactly one rank) are gathered and merged in the serial order (their pair keys';
  with mesh and surface walls the provider's order, :meth:`Domain.order`); the walls' loads
  are summed from them in that order.  Each rank books the exact work of its counted
  contacts' half kicks in the ledger's exact accumulators
  (:func:`~nurbsdem.dynamics.forces.add_kick_work`, :mod:`~nurbsdem.dynamics.exact_sum`); the
  deck end adds the ranks' shares exactly, so the ledger is the serial run's to the bit.
  After it, every rank holds the serial system's state bit for bit: energies, guards, the
  time-step control (Lanczos over the whole network), monitors, output and checkpoints run
  unchanged.

Periodic cells
--------------
At a list build every rank wraps every particle into the cell (all of them synchronised
from their owners first, so every rank takes the same wrap) and lists the pairs with an
owned particle, a pair with the image of its body B across a face among them.  The merged
rows, contacts and list carry each contact's image translation (:data:`PERIODIC_ROW_FIELDS`
and the others); rank 0 books a wrap's potential jump (every rank takes the same wrap); the
implicit dashpots of the gathered network form its image bodies as the serial solve does.

Global decisions (the period-2 and finite-state guards after every internal step, the rebuild
of the neighbour list) are reduced over the ranks, so every rank takes the serial run's
decision at the same point.  A checkpoint holds the gathered (serial) state: it restarts on any
number of ranks.

Memory and communication: state arrays keep global indices (O(N) memory per rank, sized for
10^6 particles per node); per internal step the messages are the ghosts' loads (6 doubles per
ghost) and three small reductions; per deck step and per rebuild an O(N + K) gather.  The model
of the report (section 8, benchmarks/mpi_model.py) gives the volume per step and the
efficiency it predicts.
"""
from __future__ import annotations

import functools
import time
from dataclasses import dataclass, replace
from typing import Any, Callable

import numpy as np

from ..contact.contactset import ContactSet
from ..dynamics.contact_state import ContactState
from ..dynamics.exact_sum import SPECIAL, exact_add_rows
from ..dynamics.forces import match_history, wall_loads
from ..dynamics.images import ImageBodies
from ..dynamics.rigid import omega_world
from ..dynamics.rolling import NSPRING
from ..dynamics.step import all_kinematics
from ..geometry.rotation import quats_to_matrices
from .cut import WORK_IMBALANCE, ContactWork, decompose, imbalance

#: deck steps between re-cuts at the latest; a re-cut also happens when the ghosts have grown
#: by GHOST_GROWTH since the last cut
REBALANCE_EVERY = 200
GHOST_GROWTH = 1.5

#: the fields of a DemSystem's last contacts (:class:`~nurbsdem.dynamics.contact_state.
#: ContactState`) merged by pair key at each deck end (the images: in a periodic cell only)
ROW_FIELDS = tuple(f for f in ContactState._fields if f != "image")
#: per-particle arrays of a DemSystem that a rank receives from the owners
BODY_FIELDS = ("x", "q", "v", "L")
SYSTEM_BODY_FIELDS = ("alt_count", "alt_prev_v", "alt_prev_L")
#: ContactSet arrays over the active contacts and over the separated ("near") pairs
CS_ACTIVE = ("body_a", "body_b", "point_a", "point_b", "normal", "depth", "key", "degenerated",
             "params", "patch_a", "patch_b")
CS_NEAR = ("near_a", "near_b", "near_point", "near_normal", "near_gap")
#: counters of a ContactSet that ranks count for their counted pairs (summed over ranks)
CS_COUNTERS = ("monitored", "failed", "reused", "dropped")
#: _PairState arrays of the scene's neighbour list
PAIR_FIELDS = ("list_a", "list_b", "keys", "mask_a", "mask_b", "rows_f", "rows_i", "budget",
               "reused")

#: the same in a periodic cell: each contact's (and separated pair's) image translation of
#: body B (m), and each listed pair's image (int)
PERIODIC_ROW_FIELDS = ("image",)
PERIODIC_CS_ACTIVE = ("image",)
PERIODIC_CS_NEAR = ("near_image",)
PERIODIC_PAIR_FIELDS = ("pair_shift",)

_TAG_LOADS = 11


def _timed(kind: str) -> Callable:
    """Add the wall time of a method (its communication, and the wait for the slowest rank
    in it) to ``self.seconds[kind]``."""
    def wrap(method: Callable) -> Callable:
        @functools.wraps(method)
        def timed(self, *args, **kwargs):
            t0 = time.perf_counter()
            try:
                return method(self, *args, **kwargs)
            finally:
                self.seconds[kind] += time.perf_counter() - t0
        return timed
    return wrap


def _nbytes(obj: Any) -> int:
    """Bytes of the NumPy arrays in a nest of tuples, lists and dicts."""
    if isinstance(obj, np.ndarray):
        return int(obj.nbytes)
    if isinstance(obj, dict):
        return sum(_nbytes(v) for v in obj.values())
    if isinstance(obj, (list, tuple)):
        return sum(_nbytes(v) for v in obj)
    return 8


@dataclass
class GhostPlan:
    """Who holds what between two list rebuilds: tracked (N,) owned or ghost particles;
    recv {rank: ghost indices it owns}; send {rank: owned indices that are ghosts there}."""

    tracked: np.ndarray
    recv: dict
    send: dict

    @property
    def ghosts(self) -> int:
        return int(sum(v.size for v in self.recv.values()))


def merge_by_key(pieces: list[dict], key: str, order: Callable | None = None) -> dict:
    """Concatenate the arrays of per-rank dicts and sort them by ``key`` (unique keys: each
    row counted by one rank), or by ``order(keys)`` (sort values of the keys: the provider's
    order where it is not the keys' own, :meth:`Domain.order`): the serial row order."""
    out = {name: np.concatenate([p[name] for p in pieces]) for name in pieces[0]}
    values = out[key] if order is None else order(out[key])
    rank = np.argsort(values, kind="stable")
    return {name: arr[rank] for name, arr in out.items()}


def positions_of(keys_in_order: np.ndarray, keys: np.ndarray) -> np.ndarray:
    """The rows of ``keys`` (each present, unique) in ``keys_in_order`` (any order)."""
    by_key = np.argsort(keys_in_order, kind="stable")
    return by_key[np.searchsorted(keys_in_order[by_key], keys)]


class Domain:
    """The decomposition of one DemSystem (and its scene) over ``comm`` (module docstring).

    owner: (N,) ranks to start from (a scene carried over from the previous solution step
    keeps its cut); None: :func:`decompose` of the current centroids."""

    def __init__(self, comm: Any, system: Any, scene: Any, owner: np.ndarray | None = None,
                 plan: GhostPlan | None = None) -> None:
        from mpi4py import MPI
        from mpi4py.util import pkl5
        self._MPI = MPI
        self.comm = comm
        #: allgather of the large payloads (states, contacts, logs): pickle protocol 5 with
        #: the arrays sent as out-of-band buffers (``mpi4py.util.pkl5``), not copied into and
        #: out of the pickled bytes; the same objects in the same order as ``comm.allgather``
        self._gather = pkl5.Intracomm(comm).allgather
        self.rank = int(comm.rank)
        self.size = int(comm.size)
        self.system = system
        self.scene = scene
        self.n = int(system.n_particles)
        self.nb = int(system.n_bodies)
        self._set_owner(decompose(system.bodies.x, self.size) if owner is None
                        else np.asarray(owner, np.int64))
        #: the contact provider's order of contact keys (mesh and surface walls:
        #: :meth:`~nurbsdem.contact.curved_walls.CurvedWallContacts.serial_order`); None: the
        #: keys' own order
        self._provider_order = getattr(system.provider, "serial_order", None)
        self._provider_particles = getattr(system.provider, "particles_of", None)
        self.plan = plan if plan is not None else GhostPlan(self.owned.copy(), {}, {})
        self._ghosts_at_cut = -1
        self._steps_since_cut = 0
        self.cuts = 1
        #: the system's exact ledger accumulators at the start of the deck step (None: no
        #: deck step begun; nothing booked yet): what this rank booked since is its share
        self._exact_start: np.ndarray | None = None
        #: each particle's counted contact work since the last cut (:meth:`count_work`)
        self.work = ContactWork(self.owned, scene)
        self.lcps = 0                  # counted LCPs since the last deck end
        self.failed = 0                # counted failed LCPs since the last deck end
        #: bytes this rank sent: ghosts' loads (point-to-point) and its part of the gathers
        self.sent = dict(loads=0, gathers=0, evaluations=0)
        #: seconds in the ghosts' loads exchange, the reductions, and the gathers with their
        #: merges (each including the wait for the slowest rank)
        self.seconds = dict(loads=0.0, reductions=0.0, gathers=0.0)
        #: whether the scene is a periodic cell (:mod:`nurbsdem.contact.periodic`)
        self.periodic = periodic = getattr(scene, "cell", None) is not None
        #: the per-contact, per-separated-pair and per-listed-pair arrays merged by key
        #: (a periodic cell adds the images)
        self.row_fields = ROW_FIELDS + (PERIODIC_ROW_FIELDS if periodic else ())
        self.cs_active = CS_ACTIVE + (PERIODIC_CS_ACTIVE if periodic else ())
        self.cs_near = CS_NEAR + (PERIODIC_CS_NEAR if periodic else ())
        self.pair_fields = PAIR_FIELDS + (PERIODIC_PAIR_FIELDS if periodic else ())

    def order(self, keys: np.ndarray) -> np.ndarray:
        """Sort values of contact keys that give the serial run's contact order."""
        keys = np.asarray(keys, np.int64)
        return keys if self._provider_order is None else self._provider_order(keys, self.nb)

    def particles_of(self, keys: np.ndarray) -> np.ndarray:
        """The particle (body A) of each contact key."""
        keys = np.asarray(keys, np.int64)
        if self._provider_particles is None:
            return keys // self.nb
        return self._provider_particles(keys, self.nb)

    def _set_owner(self, owner: np.ndarray) -> None:
        self.owner = owner
        self.owned = owner == self.rank
        self.owned_ids = np.nonzero(self.owned)[0]

    # ------------------------------------------------------------------ reductions
    @_timed("reductions")
    def any(self, flag: bool) -> bool:
        """Whether ``flag`` holds on some rank."""
        return bool(self.comm.allreduce(bool(flag), op=self._MPI.LOR))

    @_timed("reductions")
    def all(self, flag: bool) -> bool:
        """Whether ``flag`` holds on every rank."""
        return bool(self.comm.allreduce(bool(flag), op=self._MPI.LAND))

    @_timed("reductions")
    def total(self, count: int) -> int:
        return int(self.comm.allreduce(int(count), op=self._MPI.SUM))

    @_timed("reductions")
    def worst_alternation(self, worst: int, count: int, amplitude: float) -> tuple[int, int, float]:
        """The serial period-2 verdict: the particle with the longest run of reversals (lowest
        index on ties) over all ranks, its count and its displacement per step (m)."""
        code = count * (self.n + 1) + (self.n - worst) if worst >= 0 else 0
        best = max(self.comm.allgather((code, amplitude)))
        if best[0] == 0:
            return -1, 0, 0.0
        return self.n - best[0] % (self.n + 1), best[0] // (self.n + 1), best[1]

    @_timed("reductions")
    def on_root(self, fn: Callable, *args: Any) -> Any:
        """``fn(*args)`` computed by rank 0 alone and sent to all (the same bits everywhere):
        for a replicated computation that ranks sharing a node's memory would slow each other
        down in (the Lanczos estimate of the whole network)."""
        return self.comm.bcast(fn(*args) if self.rank == 0 else None, root=0)

    # ------------------------------------------------------------------ rows
    def counted(self, a: np.ndarray) -> np.ndarray:
        """Rows this rank counts: those whose body A (always a particle) it owns."""
        return self.owned[np.asarray(a, np.int64)]

    def involves_owned(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Pairs with an owned body (b may be a wall, index >= N)."""
        own_b = np.zeros(b.shape[0], bool)
        part = b < self.n
        own_b[part] = self.owned[b[part]]
        return self.owned[a] | own_b

    def count_work(self, a: np.ndarray, b: np.ndarray, due: np.ndarray) -> None:
        """Count an evaluation's solves: the rows ``due`` of the scene's list (a, b)
        (:meth:`~nurbsdem.parallel.cut.ContactWork.count`)."""
        self.work.count(a, b, due)

    def _weights(self) -> np.ndarray:
        """Every particle's work since the last cut, summed over the ranks (collective; the
        same integers on every rank)."""
        mine = self.work.folded()
        total = np.empty_like(mine)
        self.comm.Allreduce(mine, total, op=self._MPI.SUM)
        self.sent["gathers"] += mine.nbytes
        return self.work.weights(total)

    # ------------------------------------------------------------------ ghosts
    def plan_ghosts(self, a: np.ndarray, b: np.ndarray) -> None:
        """Ghosts of the listed pairs (a, b) and who sends their loads (collective)."""
        partners = np.concatenate([a, b[b < self.n]])
        tracked = self.owned.copy()
        tracked[partners] = True
        ghosts = np.nonzero(tracked & ~self.owned)[0]
        wanted = [ghosts[self.owner[ghosts] == r] for r in range(self.size)]
        asked = self.comm.alltoall(wanted)
        self.plan = GhostPlan(tracked,
                              {r: w for r, w in enumerate(wanted) if w.size},
                              {r: np.asarray(s, np.int64) for r, s in enumerate(asked) if len(s)})

    def begin_deck_step(self) -> None:
        """Before the internal steps of a deck step (also when one is repeated): the ledger's
        accumulators noted (every rank holds the serial ones), and the idle particles
        frozen."""
        self._exact_start = self.system.exact_ledger.copy()
        self.failed = 0
        self.freeze()

    def freeze(self) -> None:
        """Stop the particles this rank neither owns nor holds as ghosts (no velocity, no load):
        their copies wait, unchanged, for the next synchronisation."""
        s = self.system
        b = s.bodies
        idle = ~self.plan.tracked
        b.v[idle] = 0.0
        b.L[idle] = 0.0
        s.force[:self.n][idle] = 0.0
        s.torque[:self.n][idle] = 0.0

    @_timed("loads")
    def exchange_loads(self, force: np.ndarray, torque: np.ndarray) -> None:
        """After a force evaluation: the owners' force and torque (B,3) of this rank's ghosts
        (non-blocking point-to-point), and none on the idle particles."""
        MPI = self._MPI
        idle = ~self.plan.tracked
        force[:self.n][idle] = 0.0
        torque[:self.n][idle] = 0.0
        requests, inbox, outbox = [], {}, []
        for r, idx in self.plan.recv.items():
            buf = np.empty((idx.size, 6))
            requests.append(self.comm.Irecv(buf, source=r, tag=_TAG_LOADS))
            inbox[r] = buf
        self.sent["evaluations"] += 1
        for r, idx in self.plan.send.items():
            buf = np.ascontiguousarray(np.concatenate([force[idx], torque[idx]], axis=1))
            outbox.append(buf)
            self.sent["loads"] += buf.nbytes
            requests.append(self.comm.Isend(buf, dest=r, tag=_TAG_LOADS))
        MPI.Request.Waitall(requests)
        for r, buf in inbox.items():
            idx = self.plan.recv[r]
            force[idx] = buf[:, :3]
            torque[idx] = buf[:, 3:]

    def _from_owners(self, arrays: list[np.ndarray]) -> None:
        """Fill every particle's row of each (N, ...) array with its owner's (allgather)."""
        mine = self.owned_ids
        payload = (mine, [arr[mine] for arr in arrays])
        self.sent["gathers"] += _nbytes(payload)
        for ids, rows in self._gather(payload):
            for arr, r in zip(arrays, rows):
                arr[ids] = r

    @_timed("gathers")
    def sync_for_build(self, kin: Any) -> Any:
        """Before a neighbour-list rebuild (inside a force evaluation, after the drift): every
        particle's state and odometer from its owner; returns the kinematics recomputed, with
        the walls of ``kin`` (the scene sees the flat walls only where a provider of mesh and
        surface walls wraps it)."""
        s = self.system
        b = s.bodies
        self._from_owners([getattr(b, f) for f in BODY_FIELDS]
                          + [getattr(s, f) for f in SYSTEM_BODY_FIELDS]
                          + [self.scene.odo[:self.n]])
        return replace(s._kinematics(kin.t), wall_displacement=kin.wall_displacement,
                       wall_velocity=kin.wall_velocity, n_bodies=kin.n_bodies)

    def after_build(self, a: np.ndarray, b: np.ndarray) -> None:
        """After a rebuild: the ghosts of the new list, and the others frozen."""
        self.plan_ghosts(a, b)
        bodies = self.system.bodies
        idle = ~self.plan.tracked
        bodies.v[idle] = 0.0
        bodies.L[idle] = 0.0

    # ------------------------------------------------------------------ implicit dashpots
    @_timed("gathers")
    def implicit_dashpots(self, a: np.ndarray, b: np.ndarray, pa: np.ndarray, pb: np.ndarray,
                          normal: np.ndarray, depth: np.ndarray, key: np.ndarray,
                          radius: np.ndarray, h: float, solves: np.ndarray,
                          image: np.ndarray | None = None) -> np.ndarray:
        """The implicit normal dashpot forces (K,) N of this rank's contacts (a, b, their
        points, normals, depths, keys and Hertz radii), solved over the whole contact network
        as the serial run solves it (collective, every internal step with ``Damping
        Implicit``): the counted contacts of all ranks merged in the serial order
        (:meth:`order`) and every particle's state from its owner, then the serial kernel
        (:func:`~nurbsdem.dynamics.implicit.dashpots_of_evaluation`, or its copy for laws
        registered at run time: ``DemSystem._kernels``) on every rank, each
        taking its contacts' forces by key.  The solve's figures are added to ``solves``
        (solves, active-set rounds, CG iterations) as the serial run counts them.  In a
        periodic cell ``image`` (K,3) m is each contact's translation of B's image: the
        gathered network's image bodies are formed as the serial run forms them
        (:class:`~nurbsdem.dynamics.images.ImageBodies`)."""
        s = self.system
        spring = match_history(s.hist_keys, s.hist_springs, key)
        sel = self.counted(a)
        mine = dict(key=key[sel], a=a[sel], b=b[sel], pa=pa[sel], pb=pb[sel], n=normal[sel],
                    d=depth[sel], r=radius[sel], s=spring[sel])
        if image is not None:
            mine["im"] = image[sel]
        pieces = self._gather(mine)
        self.sent["gathers"] += _nbytes(mine)
        net = merge_by_key(pieces, "key", self.order)
        if net["key"].shape[0] == 0:
            return np.zeros(0)
        bodies = s.bodies
        x, q, v, L = (np.array(getattr(bodies, f)) for f in BODY_FIELDS)
        self._from_owners([x, q, v, L])
        omega = omega_world(q, L, s._inv_I)
        pos, vel, omg = all_kinematics(x, v, omega, s.wall_d, s.wall_u)
        if s.wall_spin is not None:      # turning walls, as the serial driver's kinematics
            pos[len(x):] += s.wall_spin[:, 3:]
            omg[len(x):] = s.wall_spin[:, :3]
        bc, net_b, own = s._bc, net["b"], np.zeros(0, np.int64)
        im = None if image is None else ImageBodies.of(self.n, net_b,
                                                        net["im"].reshape(-1, 3))
        if im is not None:               # contacts with periodic images, as the serial run
            bc, net_b, own, q, L = im.const(bc), im.b, im.own, im.particles(q), im.particles(L)
            pos, vel, omg = im.bodies(pos, True), im.bodies(vel), im.bodies(omg)
        f, rounds, iterations = s._kernels.dashpots_of_evaluation(   # laws added at run time too
            net["a"], net_b, net["pa"].reshape(-1, 3), net["pb"].reshape(-1, 3),
            net["n"].reshape(-1, 3), net["d"], pos, vel, omg, bc.material, bc.table,
            net["s"].reshape(-1, NSPRING), h, bc.inv_mass_all, net["r"], bc.mass, bc.gravity, q, L,
            bc.inv_I, quats_to_matrices(q), bc.sq_m, bc.sq_I, own)
        solves[0] += 1
        solves[1] += rounds
        solves[2] += iterations
        return np.ascontiguousarray(f[positions_of(net["key"], key)])

    # ------------------------------------------------------------------ the energy ledger
    def books(self) -> bool:
        """Whether this rank books the amounts every rank computes alike (a wrap's jump):
        rank 0 alone."""
        return self.rank == 0

    def _ledger_share(self) -> np.ndarray:
        """What this rank booked in the ledger's exact accumulators since the deck step began
        (limb by limb; the non-finite flags as they are)."""
        s = self.system
        if self._exact_start is None:
            return np.zeros_like(s.exact_ledger)
        share = s.exact_ledger - self._exact_start
        share[:, SPECIAL] = s.exact_ledger[:, SPECIAL]
        return share

    def _add_ledger_shares(self, shares: list[np.ndarray]) -> None:
        """The serial ledger: the accumulators at the deck step's start plus every rank's share,
        added exactly (:func:`~nurbsdem.dynamics.exact_sum.exact_add_rows`)."""
        s = self.system
        start = s.exact_ledger if self._exact_start is None else self._exact_start
        exact = start.copy()
        for share in shares:
            exact_add_rows(exact, share)
        s.exact_ledger = exact
        self._exact_start = None

    # ------------------------------------------------------------------ deck ends
    @_timed("gathers")
    def end_of_deck_step(self) -> None:
        """Give every rank the serial system's state (module docstring; collective)."""
        s = self.system
        sc = self.scene
        N = self.n
        self._from_owners([getattr(s.bodies, f) for f in BODY_FIELDS]
                          + [getattr(s, f) for f in SYSTEM_BODY_FIELDS]
                          + [s.force[:N], s.torque[:N]])
        sel = self.counted(s.contacts.a)
        rows = {f: getattr(s.contacts, f)[sel] for f in self.row_fields}
        hsel = self.counted(self.particles_of(s.hist_keys))
        hist = dict(key=s.hist_keys[hsel], spring=s.hist_springs[hsel])
        cs = s.last_contacts
        mine = (rows, hist, self._counted_contacts(cs), self._ledger_share(),
                (self.lcps, self.failed))
        self.sent["gathers"] += _nbytes(mine)
        gathered = self._gather(mine)
        rows = merge_by_key([g[0] for g in gathered], "key", self.order)
        if "image" not in rows:
            rows["image"] = np.zeros((rows["a"].shape[0], 3))
        s.contacts = s.contacts._replace(**rows)
        hist = merge_by_key([g[1] for g in gathered], "key")
        s.hist_keys, s.hist_springs = hist["key"], hist["spring"].reshape(-1, NSPRING)
        s.force[N:] = 0.0
        s.torque[N:] = 0.0
        c = s.contacts
        wall_loads(c.b, c.point, c.ftot, c.fet, s.wall_d, N, s.force, s.torque)
        merged = self._merged_contacts([g[2] for g in gathered])
        s.last_contacts = merged
        sc.last = merged
        if s.needs_radius:
            # the serial count of contacts whose curvature fell back (the radii are the
            # merged rows' again: per contact, the same bits)
            from ..geometry.curvature import contact_radii_for
            radius, s.hertz_fallback = contact_radii_for(sc, merged, s.bodies, c.a.shape[0])
            s.contacts = c._replace(radius=radius)
        self._add_ledger_shares([g[3] for g in gathered])
        counts = np.sum([g[4] for g in gathered], axis=0)
        sc.timers.lcps += int(counts[0])
        s.failed_in_step = int(counts[1])
        self.lcps = self.failed = 0

    def _counted_contacts(self, cs: ContactSet | None) -> dict:
        if cs is None:
            cs = ContactSet.empty()
        sel = self.counted(cs.body_a)
        near = self.counted(cs.near_a)
        drop = self.counted(self.particles_of(cs.dropped_keys))
        return dict(active={f: np.asarray(getattr(cs, f))[sel] for f in self.cs_active},
                    near={f: np.asarray(getattr(cs, f))[near] for f in self.cs_near},
                    dropped=np.asarray(cs.dropped_keys, np.int64)[drop],
                    counters=[int(getattr(cs, f)) for f in CS_COUNTERS])

    def _merged_contacts(self, pieces: list[dict]) -> ContactSet:
        """The serial ContactSet of the last evaluation, from every rank's counted pairs."""
        act = [dict(p["active"]) for p in pieces]
        active = merge_by_key(act, "key", self.order)
        near = [dict(p["near"], near_key=p["near"]["near_a"] * self.nb + p["near"]["near_b"])
                for p in pieces]
        near = merge_by_key(near, "near_key")
        near.pop("near_key")
        counters = np.sum([p["counters"] for p in pieces], axis=0)
        dropped = np.sort(np.concatenate([p["dropped"] for p in pieces]))
        deg = active["degenerated"]
        return ContactSet(**active, **near, dropped_keys=dropped,
                          **{f: int(c) for f, c in zip(CS_COUNTERS, counters)},
                          active=int(active["key"].shape[0]),
                          degenerated_count=int(np.count_nonzero(deg)))

    # ------------------------------------------------------------------ the scene's list
    def global_scene_state(self, local: dict) -> dict:
        """The serial scene state (:meth:`SceneContacts.state`) from every rank's counted pairs
        and its owned particles' odometers and poses (collective)."""
        sel = self.counted(local["list_a"]) if "list_a" in local else None
        mine = self.owned_ids
        pairs = {f: local[f][sel] for f in self.pair_fields} if sel is not None else None
        per_body = {f: local[f][mine] for f in ("prev_pos", "prev_R", "prev_x") if f in local}
        gathered = self._gather((pairs, mine, per_body, local["odo"][mine]))
        out = dict(local)
        if sel is not None:
            out.update(merge_by_key([g[0] for g in gathered], "keys"))
        out["odo"] = local["odo"].copy()
        for f in per_body:
            out[f] = local[f].copy()
        for _, ids, body, odo in gathered:
            out["odo"][ids] = odo
            for f, rows in body.items():
                out[f][ids] = rows
        return out

    def local_scene_state(self, full: dict) -> dict:
        """This rank's part of a serial scene state: the pairs with an owned body."""
        if "list_a" not in full:
            return full
        keep = self.involves_owned(np.asarray(full["list_a"], np.int64),
                                   np.asarray(full["list_b"], np.int64))
        out = dict(full)
        out.update({f: np.asarray(full[f])[keep] for f in self.pair_fields})
        return out

    def figures(self) -> dict:
        """This rank's figures: owned particles, ghosts, cuts, bytes sent per internal step
        (loads point-to-point, gathers at rebuilds and deck ends)."""
        ev = max(self.sent["evaluations"], 1)
        return dict(owned=int(self.owned_ids.size), ghosts=self.plan.ghosts, cuts=self.cuts,
                    load_bytes_per_internal_step=self.sent["loads"] / ev,
                    gather_bytes_per_internal_step=self.sent["gathers"] / ev,
                    bytes_per_internal_step=(self.sent["loads"] + self.sent["gathers"]) / ev,
                    internal_steps=self.sent["evaluations"], seconds=dict(self.seconds))

    def describe(self) -> str:
        """One line on the cut: particles and ghosts per rank (collective)."""
        counts = self.comm.allgather((int(self.owned_ids.size), self.plan.ghosts))
        return (f"{self.n} particles on {self.size} MPI ranks (cut {self.cuts}): owned "
                f"{[c[0] for c in counts]}, ghosts {[c[1] for c in counts]}")

    def after_deck_step(self) -> None:
        """After an accepted deck step: re-cut by the counted work when it is uneven over the
        ranks (module docstring), when the ghosts have grown, or after REBALANCE_EVERY deck
        steps (particles migrate with their pairs' histories; collective)."""
        self._steps_since_cut += 1
        ghosts = self.total(self.plan.ghosts)
        if self._ghosts_at_cut < 0:
            self._ghosts_at_cut = ghosts
        weight = self._weights()
        if (self._steps_since_cut >= REBALANCE_EVERY
                or ghosts > GHOST_GROWTH * self._ghosts_at_cut + self.size):
            self.recut(decompose(self.system.bodies.x, self.size, weight))
            return
        now = imbalance(self.owner, weight, self.size)
        if now <= WORK_IMBALANCE:
            return
        owner = decompose(self.system.bodies.x, self.size, weight)
        if now - imbalance(owner, weight, self.size) > WORK_IMBALANCE:
            self.recut(owner)

    @_timed("gathers")
    def recut(self, owner: np.ndarray) -> None:
        """Cut the domain anew to ``owner`` (N,) ranks, the same on every rank (collective);
        the work counts start again."""
        sc = self.scene
        full = self.global_scene_state(sc.local_state())
        self._set_owner(owner)
        sc.set_local_state(self.local_scene_state(full))
        self.plan_ghosts(sc.pairs.a, sc.pairs.b)
        self._ghosts_at_cut = self.total(self.plan.ghosts)
        self._steps_since_cut = 0
        self.work = ContactWork(self.owned, sc)
        self.cuts += 1

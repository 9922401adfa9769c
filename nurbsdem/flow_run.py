"""Inlets and outlets in a run (:class:`FlowRun`): a timed step of a model with inlets or
outlets runs in segments of ``Every`` seconds (the smallest of its inlets' and outlets',
rounded to a whole number of the step's TimeStep, at least one, counted from the step's
start); at the end of each segment and at the end of the step (:func:`exchange`) the
solver's bodies lose the particles in an outlet and gain the particles an inlet owes (placed
clear of the bounding spheres present, :meth:`nurbsdem.dynamics.flow.Inlet.insert`), and
the system is built anew for the new set.  An inlet's rate counts from the start of each
timed step (:meth:`FlowRun.begin_step`) on top of what it owed at that moment (waiting
particles and the fraction of one included): by the end of a step of T seconds it has owed
Rate × T more particles, and over several steps floor(Rate × their total time).

Between two systems the step engine is of fixed size: the tangential springs of the
surviving contacts go to the new system under their keys renumbered for the new particle
count (:func:`remap_history`), so do the last LCP rows and certificates of the listed pairs
with the bodies' odometers (the new scene's warm starts, :func:`_carried_rows`), and its
time-step control goes on from the last one's state
(the exact estimate is taken again only when the gate asks for it,
:meth:`~nurbsdem.dynamics.substep_control.SubstepControl._first_control_step`); the
mechanical energy of the new system less that of the last one (the kinetic and potential
energy the new particles bring in, less that of the particles removed and the elastic
energy of their contacts) is booked as external work, so that the energy balance of
``monitors/energy.csv`` stays closed.  Monitors:
``monitors/inlet_<name>.csv`` (time, inserted, mass, waiting) and
``monitors/outlet_<name>.csv`` (time, count, mass, mass_rate), one row per segment end and
step end; cumulative counts and masses (kg), mass rate in kg/s.  The state of
the inlets (counts, random streams, waiting particles) and outlets is kept in checkpoints.

On several MPI ranks every rank holds the serial system's state at the end of a deck step
(:mod:`nurbsdem.parallel.domain`), so each runs the same exchange with the same random
streams and builds the same new system; the new system is cut anew over the ranks, so a new
particle is owned by the rank whose region it lies in, and the run equals the serial one bit
for bit.  Units: SI."""
from __future__ import annotations

import json
import logging
import time

import numpy as np

from .contact.curved_walls import split_wall_contact_key, wall_contact_key
from .dynamics.flow import Inlet, Outlet
from .dynamics.rolling import NSPRING
from .model import Bodies, Model

log = logging.getLogger("nurbsdem")

INLET_COLUMNS = ("time", "inserted", "mass", "waiting")
OUTLET_COLUMNS = ("time", "count", "mass", "mass_rate")


class FlowRun:
    """The inlets and outlets of ``model`` as the solver runs them (module docstring)."""

    def __init__(self, model: Model) -> None:
        self.model = model
        self.inlets = [self._inlet(s) for s in model.inlets]
        self.outlets = [Outlet(s.name, lo=s.lo, hi=s.hi, point=s.point, normal=s.normal)
                        for s in model.outlets]
        self.every = min((s.every for s in model.inlets + model.outlets), default=0.0)
        #: the id the next inserted particle takes (None: one more than the largest present)
        self.next_id: int | None = None
        self._told_waiting: set[str] = set()

    def _inlet(self, spec) -> Inlet:
        rho = self.model.materials[spec.material_id].density
        entries = [self.model.shapes[s] for s in spec.shapes]
        return Inlet(spec.region(), np.array(spec.shapes, np.int64),
                     np.array(spec.fractions, float),
                     np.array([e.bounding_radius for e in entries], float),
                     np.array([e.mass(rho) for e in entries], float), spec.rate,
                     velocity=np.asarray(spec.velocity, float), count=spec.count,
                     seed=spec.seed,
                     cell=None if self.model.periodic is None else self.model.periodic.cell())

    @property
    def active(self) -> bool:
        """Whether the model has inlets or outlets."""
        return bool(self.inlets or self.outlets)

    def begin_step(self, t: float) -> None:
        """A timed step begins at t (s): each inlet's rate counts from t
        (:meth:`~nurbsdem.dynamics.flow.Inlet.restart_clock`)."""
        for inlet in self.inlets:
            inlet.restart_clock(t)

    def segment_steps(self, dt: float) -> int:
        """Deck time steps of ``dt`` s in one segment."""
        return max(1, int(round(self.every / dt)))

    def steps_to_segment_end(self, progress: int, dt: float) -> int:
        """Deck time steps from ``progress`` (done in the step) to the end of its segment."""
        seg = self.segment_steps(dt)
        return seg - progress % seg

    # ------------------------------------------------------------------ the exchange
    def _radii(self, shape_id: np.ndarray) -> np.ndarray:
        """Bounding radii (m) of bodies of the shapes ``shape_id`` (N,)."""
        ids = np.array(sorted(self.model.shapes), np.int64)
        r = np.array([self.model.shapes[int(s)].bounding_radius for s in ids], float)
        return r[np.searchsorted(ids, shape_id)]

    def _masses(self, bodies: Bodies) -> np.ndarray:
        """Masses (kg) of ``bodies``, by their shape and material."""
        m = self.model
        if not len(bodies):
            return np.zeros(0)
        stride = int(bodies.material_id.max()) + 1       # one integer per (shape, material)
        kinds, which = np.unique(np.asarray(bodies.shape_id, np.int64) * stride
                                 + bodies.material_id, return_inverse=True)
        mass = np.array([m.shapes[int(k // stride)].mass(m.materials[int(k % stride)].density)
                         for k in kinds], float)
        return mass[np.ravel(which)]

    def remove(self, t: float, bodies: Bodies) -> np.ndarray:
        """Bool (N,): the bodies no outlet caught at time t (s) (each outlet counts its own)."""
        keep = np.ones(len(bodies), bool)
        masses = self._masses(bodies)
        for outlet in self.outlets:
            idx = np.flatnonzero(keep)
            gone = outlet.remove(t, bodies.position[idx], masses[idx])
            keep[idx[gone]] = False
        return keep

    def insert(self, t: float, bodies: Bodies) -> Bodies:
        """The particles the inlets owe at time t (s), clear of ``bodies`` and of each other."""
        centers, radii = bodies.position, self._radii(bodies.shape_id)
        if self.next_id is None:
            self.next_id = int(bodies.id.max()) + 1 if len(bodies) else 1
        added = []
        for spec, inlet in zip(self.model.inlets, self.inlets):
            new = inlet.insert(t, centers, radii)
            k = len(new.shapes)
            if inlet.waiting and spec.name not in self._told_waiting:
                self._told_waiting.add(spec.name)
                log.warning("inlet %s: no room for %d particle(s) at t = %.6g s; they wait",
                            spec.name, inlet.waiting, t)
            if k == 0:
                continue
            ids = np.arange(self.next_id, self.next_id + k, dtype=np.int64)
            self.next_id += k
            added.append(Bodies(ids, new.shapes, np.full(k, spec.material_id),
                                new.positions, new.quaternions, new.velocities,
                                np.zeros((k, 3)), np.full(k, spec.line or 0)))
            centers = np.concatenate([centers, new.positions])
            radii = np.concatenate([radii, inlet.radii[np.searchsorted(inlet.shapes,
                                                                        new.shapes)]])
        return Bodies.concatenate(added)

    def rows(self, t: float) -> list[tuple[str, tuple, list]]:
        """The monitor rows of time t (s): (file name, columns, values) per inlet and outlet."""
        out = [(f"inlet_{s.name}.csv", INLET_COLUMNS,
                [t, inlet.inserted, inlet.inserted_mass, inlet.waiting])
               for s, inlet in zip(self.model.inlets, self.inlets)]
        out += [(f"outlet_{o.name}.csv", OUTLET_COLUMNS, list(o.rows[-1]))
                for o in self.outlets if o.rows]
        return out

    # ------------------------------------------------------------------ checkpoints
    def state(self) -> dict:
        """What a checkpoint keeps of the inlets and outlets."""
        return {
            "next_id": -1 if self.next_id is None else int(self.next_id),
            "inlets": [{"inserted": int(i.inserted), "inserted_mass": float(i.inserted_mass),
                        "waiting": int(i.waiting), "queue": np.asarray(i._queue, np.int64),
                        "start": float(i.start), "base": float(i.base),
                        "rng": json.dumps(i._rng.bit_generator.state)} for i in self.inlets],
            "outlets": [{"count": int(o.count), "mass": float(o.mass),
                         "rows": np.array(o.rows, float).reshape(-1, 4)} for o in self.outlets],
            "told": sorted(self._told_waiting),
        }

    def restore(self, st: dict | None) -> None:
        """Set the state a checkpoint kept (:meth:`state`; None or empty: nothing)."""
        if not st:
            return
        self.next_id = None if int(st["next_id"]) < 0 else int(st["next_id"])
        for inlet, s in zip(self.inlets, st["inlets"]):
            inlet.inserted, inlet.inserted_mass = int(s["inserted"]), float(s["inserted_mass"])
            inlet.waiting = int(s["waiting"])
            inlet.start, inlet.base = float(s.get("start", 0.0)), float(s.get("base", 0.0))
            inlet._queue = np.asarray(s["queue"], np.int64)
            inlet._rng.bit_generator.state = json.loads(s["rng"])
        for outlet, s in zip(self.outlets, st["outlets"]):
            outlet.count, outlet.mass = int(s["count"]), float(s["mass"])
            outlet.rows = [(float(r[0]), int(r[1]), float(r[2]), float(r[3]))
                           for r in np.asarray(s["rows"], float).reshape(-1, 4)]
        self._told_waiting = set(st.get("told", []))


def remap_history(keys: np.ndarray, springs: np.ndarray, new_index: np.ndarray,
                  n_new: int, n_walls: int, n_curved: int) -> tuple[np.ndarray, np.ndarray]:
    """The tangential springs (keys (H,), springs (H,3)) of a system of N = len(new_index)
    particles and ``n_walls`` walls (the last ``n_curved`` of them mesh or surface walls)
    under the keys of a system of ``n_new`` particles and the same walls: particle i becomes
    ``new_index[i]`` (-1: removed, its springs dropped).  Pair keys are a·(N+W) + b (b >= N:
    wall b − N); mesh and surface wall keys lie above (N+W)²
    (:func:`~nurbsdem.contact.curved_walls.wall_contact_key`).
    Returned sorted by key, as the systems keep them."""
    keys = np.asarray(keys, np.int64)
    springs = np.asarray(springs, float)     # a row per key, of any width (rolling.NSPRING)
    springs = springs.reshape(len(keys), -1) if len(keys) else springs.reshape(0, NSPRING)
    n_old = len(new_index)
    nb_old, nb_new = n_old + n_walls, n_new + n_walls
    pair = keys < nb_old * nb_old
    out = np.full(len(keys), -1, np.int64)
    a, b = keys[pair] // nb_old, keys[pair] % nb_old
    a2 = new_index[a]
    b2 = np.where(b < n_old, new_index[np.minimum(b, n_old - 1)], b - n_old + n_new)
    ok = (a2 >= 0) & (b2 >= 0)
    out[np.flatnonzero(pair)[ok]] = a2[ok] * nb_new + b2[ok]
    if n_curved and np.any(~pair):
        owner, wall, rank = split_wall_contact_key(keys[~pair], nb_old, n_curved)
        o2 = new_index[owner]
        ok = o2 >= 0
        out[np.flatnonzero(~pair)[ok]] = wall_contact_key(nb_new, o2[ok], wall[ok], n_curved,
                                                          rank[ok])
    kept = out >= 0
    order = np.argsort(out[kept], kind="stable")
    return out[kept][order], springs[kept][order]


def _carried_rows(scene, new_index: np.ndarray, n_new: int, n_walls: int) -> tuple | None:
    """The last LCP rows and certificates of the scene's listed pairs (its whole list: on
    several ranks the gathered one, collective) under the keys of the new system
    (:func:`remap_history`: the scene's keys count its flat walls only), and the bodies'
    odometers renumbered (a new particle's at 0), for the new scene
    (:meth:`~nurbsdem.contact.scene.SceneContacts.carry_rows`); None without a scene."""
    if scene is None:
        return None
    st = scene.state()
    if "keys" not in st or not len(st["keys"]):
        return None
    rows = np.arange(len(st["keys"]), dtype=float)[:, None]
    keys, idx = remap_history(st["keys"], rows, new_index, n_new, n_walls, 0)
    idx = idx[:, 0].astype(np.int64)
    n_old = len(new_index)
    odo_old = np.asarray(st["odo"], float)
    odo = np.zeros(n_new + n_walls)
    kept = new_index >= 0
    odo[new_index[kept]] = odo_old[:n_old][kept]
    odo[n_new:] = odo_old[n_old:n_old + n_walls]
    return (keys, np.asarray(st["rows_f"])[idx], np.asarray(st["rows_i"])[idx],
            np.asarray(st["budget"])[idx], odo)


def exchange(solver, writers) -> None:
    """The end of a segment or step: bodies out through the outlets and in through the
    inlets, the monitor rows written, and the system built anew when the set changed
    (:attr:`solver.rebuild <nurbsdem.solver.Solver.rebuild>`), the mechanical energy it
    gained or lost booked as external work.  Its wall time (s), the rebuilt system's set-up
    included (taken out of ``timers["setup"]``: it is part of the time loop), is booked in
    ``solver.timers["inlets + outlets"]``."""
    t_start, setup = time.perf_counter(), solver.timers["setup"]
    try:
        _exchange(solver, writers)
    finally:
        solver.timers["setup"] = setup
        solver.timers["inlets + outlets"] = (solver.timers.get("inlets + outlets", 0.0)
                                             + time.perf_counter() - t_start)


def _exchange(solver, writers) -> None:
    """:func:`exchange` itself (untimed)."""
    flow, t = solver.flow, solver.time
    solver._sync_bodies_from_system()
    bodies = solver.bodies
    keep = flow.remove(t, bodies)
    survivors = bodies.take(keep)
    added = flow.insert(t, survivors)
    for name, columns, row in flow.rows(t):
        writers.monitors.flow(name, columns, row)
    if keep.all() and len(added) == 0:
        return
    model = solver.model
    sysm = solver.system
    before = sysm.energy().mechanical
    solver.summary.accuracy_repeats += sysm.accuracy_repeats
    clock = (sysm.t0, sysm.step_count, sysm._warned_heavy, sysm.control_state())
    solver._close_system()
    new_index = np.full(len(bodies), -1, np.int64)
    new_index[keep] = np.arange(int(keep.sum()))
    n_new = len(survivors) + len(added)
    keys, springs = solver.carry_hist
    solver.carry_hist = remap_history(keys, springs, new_index, n_new,
                                      len(model.walls) + len(model.curved_walls),
                                      len(model.curved_walls))
    solver.carry_rows = _carried_rows(solver.scene, new_index, n_new, len(model.walls))
    solver.bodies = Bodies.concatenate([survivors, added])
    solver.scene = None
    solver.rebuild(*clock)
    solver.ledger.book_external(solver.system.energy().mechanical - before)
    log.debug("t = %.6g s: %d particle(s) out, %d in: %d particles%s", t,
              int((~keep).sum()), len(added), n_new,
              "" if solver.domain is None else f"; {solver.domain.describe()}")

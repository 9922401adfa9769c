"""What a DEM system gives its writers and checkpoints: samples of its state.

Positions are centroids (m), orientations file->world quaternions (w, x, y, z), velocities
m/s and rad/s, forces N, energies J, world frame.
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import InputError
from ..geometry.rotation import matrix_to_quat
from .contact_state import checkpoint_arrays, from_checkpoint
from .energy import EnergyLedger, EnergySample, energy_terms
from .exact_sum import exact_of
from .laws import needs_contact_radius, rolls
from .monitor import MonitorSample, StateSample, contact_output_of, energy_sample
from .rigid import body_poses, omega_world
from .rolling import widened
from .step import EXACT_WALLS, L_INITIAL, ledger_of, wall_work_of

#: the system's arrays a checkpoint holds besides the body state, the contacts
#: (:func:`~nurbsdem.dynamics.contact_state.checkpoint_arrays`) and the ledger (its array and
#: the walls' work are written as read from ``exact_ledger``, for a reader of the file)
_STATE_KEYS = ("force", "torque", "hist_keys", "hist_springs", "wall_d", "wall_u",
               "exact_ledger", "alt_count", "alt_prev_v", "alt_prev_L")


class SystemState:
    """What a :class:`~nurbsdem.dynamics.system.DemSystem` gives its writers and checkpoints
    (a base class of it): monitor samples, the particles' state in the file frame, the
    contacts for ParaView, the walls' loads, and the complete dynamic state as arrays
    (:meth:`get_state`, :meth:`set_state`: a restart continues bit for bit)."""

    def monitor_sample(self) -> MonitorSample:
        """The monitors' sample of the present state (:mod:`nurbsdem.dynamics.monitor`)."""
        cs = self.last_contacts
        hertz = None
        if self.uses_hertz:
            c = self.contacts
            hertz = (int(c.a.shape[0]), int(getattr(self, "hertz_fallback", 0)),
                     np.asarray(c.radius, float), np.asarray(c.coeffs[:, 0], float))
        return MonitorSample(self.time, self.energy(), int(getattr(cs, "monitored", 0) or 0),
                             int(getattr(cs, "active", 0) or 0),
                             int(getattr(cs, "degenerated_count", 0) or 0),
                             int(getattr(cs, "failed", 0) or 0), self.wall_displacement,
                             self.wall_reaction, self.wall_torque, self.wall_work,
                             hertz)

    def body_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The particles' state as the model and the writers hold it (copies): centroids
        (N,3) m, file->world quaternions (N,4) (w, x, y, z), velocities (N,3) m/s and angular
        velocities (N,3) rad/s, world frame."""
        b = self.bodies
        return self._body_state_of(b.x.copy(), b.q, b.v.copy(), b.L)

    def _body_state_of(self, x: np.ndarray, q: np.ndarray, v: np.ndarray,
                       L: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`body_state` of the centroids x, principal quaternions q, velocities v and
        angular momenta L (N,·) given (x and v are returned as they are)."""
        b = self.bodies
        R, _ = body_poses(q, b.P, x, b.centroid_file)
        return x, matrix_to_quat(R).reshape(-1, 4), v, omega_world(q, L, self._inv_I)

    def contact_output(self) -> dict | None:
        """The last evaluation's contacts as the ParaView writer takes them
        (:func:`~nurbsdem.dynamics.monitor.contact_output_of`; None without any)."""
        cs = self.last_contacts
        active = int(getattr(cs, "active", 0) or 0)
        c = self.contacts
        if active == 0 or c.a.shape[0] != active:
            return None
        return self._contacts_for_output(cs.body_a, cs.body_b, c.point, c.ftot, c.fn,
                                         cs.normal, cs.depth, cs.degenerated, c.coeffs,
                                         c.radius)

    def _contacts_for_output(self, a, b, point, ftot, fn, normal, depth, deg, coeffs,
                             radius) -> dict | None:
        """:func:`~nurbsdem.dynamics.monitor.contact_output_of` of the contacts a, b (None
        without any), with the Hertz–Mindlin columns (coeffs, radius) only under those laws."""
        active = a.shape[0]
        if active == 0:
            return None
        hertz = self.uses_hertz and coeffs.shape[0] == active
        return contact_output_of(a, b, point, ftot, fn, normal, depth, deg,
                                 coeffs if hertz else None, radius if hertz else None)

    def state_sample(self) -> StateSample:
        """The present state for the ParaView and results output (copies)."""
        return StateSample(self.time, *self.body_state(), self.wall_displacement,
                           self.contact_output())

    def _state_of_loop(self, time: float, kept: tuple) -> StateSample:
        """The StateSample of a state the compiled loop kept at a deck step's end
        (:func:`~nurbsdem.dynamics.deck_steps.run_deck_steps`): the same arrays
        :meth:`state_sample` takes live."""
        _, x, q, v, L, wall_d, *contacts = kept
        return StateSample(time, *self._body_state_of(x, q, v, L), wall_d,
                           self._contacts_for_output(*contacts))

    def state_sample_bytes(self, contacts: int | None = None) -> int:
        """Bytes of one state the compiled loop keeps for the output (at most; the particles'
        state, the walls' displacements and the contacts' arrays of
        :func:`~nurbsdem.dynamics.deck_steps._kept`, 8 bytes a number), with ``contacts``
        contacts (default: the last evaluation's): what the solver budgets the states kept in
        one call by (tested against the arrays' nbytes)."""
        k = int(self.contacts.a.shape[0]) if contacts is None else int(contacts)
        return 8 * (16 * self.n_particles + 24 * k + 3 * self.walls.n)

    @property
    def wall_contact_force(self) -> np.ndarray:
        """(W,3) sum of the contact forces the particles exert on each wall (N), last evaluation."""
        return self.force[self.n_particles:].copy()

    @property
    def wall_reaction(self) -> np.ndarray:
        """(W,3) force that holds each wall on its prescribed path (N) = −wall_contact_force."""
        return -self.wall_contact_force

    @property
    def wall_torque(self) -> np.ndarray:
        """(W,3) torque (N m) of the contact forces the particles exert on each wall, last
        evaluation, about the wall's reference point: while a wall turns, its rotation centre
        (carried by its displacement); otherwise the point its displacement carries from the
        world origin (``wall_displacement``)."""
        return self.torque[self.n_particles:].copy()

    @property
    def wall_displacement(self) -> np.ndarray:
        """(W,3) current wall displacements (m)."""
        return self.wall_d.copy()

    @property
    def ledger(self) -> EnergyLedger:
        """The energy ledger (J): its entries read from their exact sums (``exact_ledger``,
        :func:`~nurbsdem.dynamics.step.ledger_of`) and the initial mechanical energy."""
        return EnergyLedger.from_array(ledger_of(self.exact_ledger, self.initial_mechanical))

    @property
    def wall_work(self) -> np.ndarray:
        """(W,) the work (J) each wall did on the particles, read from its exact sum
        (:func:`~nurbsdem.dynamics.step.wall_work_of`)."""
        return wall_work_of(self.exact_ledger)

    def get_state(self) -> dict[str, np.ndarray]:
        """Complete dynamic state as a dict of numpy arrays (copies; np.savez-friendly): body
        state, last loads, tangential histories, last contact data, energy ledger, counters.
        Restoring it into a system built the same way continues bit-for-bit."""
        self.initialize()
        st = {k: np.array(getattr(self, k), copy=True) for k in _STATE_KEYS}
        st.update(checkpoint_arrays(self.contacts))
        b = self.bodies
        st.update(x=b.x.copy(), q=b.q.copy(), v=b.v.copy(), L=b.L.copy(),
                  ledger=self.ledger.to_array(), wall_work=self.wall_work,
                  counters=np.array([self.step_count, self.substeps, self.refine,
                                     self.calm_steps, self.acc_refine, self.acc_calm],
                                    dtype=np.int64),
                  scalars=np.array([self.t0, self.dt, self._peak, self.dt_bound,
                                    self.dt_network, self.dt_critical, self.acc_last_growth]))
        return st

    def set_state(self, st: dict[str, np.ndarray]) -> None:
        """Restore a state from :meth:`get_state` (the system must have the same bodies/walls)."""
        self.initialize()
        b = self.bodies
        if st["x"].shape != b.x.shape or st["wall_d"].shape != (self.walls.n, 3):
            raise InputError("checkpoint does not match the system's bodies and walls")
        b.x, b.q, b.v, b.L = (np.array(st[k], dtype=float, copy=True) for k in ("x", "q", "v", "L"))
        for k in _STATE_KEYS:
            if k in st:
                setattr(self, k, np.array(st[k], copy=True))
        self.contacts = from_checkpoint(st, self.contacts)
        self.hist_springs = widened(self.hist_springs)   # a checkpoint without rolling springs
        self.initial_mechanical = float(st["ledger"][L_INITIAL])
        if "exact_ledger" not in st:      # a checkpoint without the exact sums: its values
            self.exact_ledger = exact_of(np.concatenate([st["ledger"][:EXACT_WALLS],
                                                         st["wall_work"]]))
        self.step_count = int(st["counters"][0])
        if st["counters"].shape[0] >= 4:
            self.substeps, self.refine, self.calm_steps = (int(c) for c in st["counters"][1:4])
            self.dt_internal = self.dt / self.substeps
        acc = st["counters"][4:6] if st["counters"].shape[0] >= 6 else (1, 0)
        self.acc_refine, self.acc_calm = int(acc[0]), int(acc[1])
        self.t0 = float(st["scalars"][0])
        if float(st["scalars"][1]) != self.dt:
            raise InputError("checkpoint was written with a different deck time step")
        self._peak = float(st["scalars"][2])
        if st["scalars"].shape[0] >= 6:
            self.dt_bound, self.dt_network, self.dt_critical = (float(v) for v in st["scalars"][3:6])
        self.acc_last_growth = (float(st["scalars"][6]) if st["scalars"].shape[0] >= 7
                                else math.inf)

    # ------------------------------------------------------------------ energies, laws
    def energy(self) -> EnergySample:
        """Energies at the current state (J); see :mod:`nurbsdem.dynamics.energy`."""
        b = self.bodies
        terms = energy_terms(b.mass, b.x, b.v, b.q, b.L, self._inv_I, self.gravity,
                             np.ascontiguousarray(self.contacts.eel, float).reshape(-1, 2))
        return energy_sample(self.time, *terms, self.ledger)

    @property
    def uses_hertz(self) -> bool:
        """Whether the interfaces include a law that needs each contact's equivalent radius
        (Hertz–Mindlin: :func:`~nurbsdem.dynamics.laws.needs_contact_radius` of the interface
        table, fixed once the system is built; taken once)."""
        hertz = self.__dict__.get("_hertz_table")
        if hertz is None:
            hertz = self._hertz_table = needs_contact_radius(self._table)
        return hertz

    @property
    def needs_radius(self) -> bool:
        """Whether the force kernel needs each contact's equivalent radius: a Hertz–Mindlin
        law (:attr:`uses_hertz`) or a rolling friction (the rolling radius,
        :mod:`nurbsdem.dynamics.rolling`); taken once."""
        need = self.__dict__.get("_radius_table")
        if need is None:
            need = self._radius_table = self.uses_hertz or rolls(self._table)
        return need

"""Monitor samples: what ``monitors/*.csv`` record at a deck step's end (energies in J, wall
displacements in m, reactions in N, torques in N m, contact counts).

A sample is taken either live from a :class:`~nurbsdem.dynamics.system.DemSystem`
(:meth:`~nurbsdem.dynamics.system.DemSystem.monitor_sample`) or, inside the compiled deck
steps (:mod:`nurbsdem.dynamics.deck_steps`), as a row of floats (:func:`record_row`) that
:meth:`MonitorSample.from_row` turns into the same sample: both take the energies from
:func:`~nurbsdem.dynamics.energy.energy_terms` and the same ledger, counters and forces, so a
monitor row is the same to the bit whichever path took it (tested).  Recording rows in the
compiled loop lets it run many deck steps per call instead of returning to Python at every
monitor sample.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .energy import EnergyLedger, EnergySample, energy_terms

#: columns of a recorded row: the five energy terms of energy_terms, the five ledger entries
#: (EnergyLedger.to_array order), the monitored / active / degenerated counts, then W×3 wall
#: displacements, W×3 wall reactions, W×3 wall torques and the W walls' work
ROW_TERMS, ROW_LEDGER, ROW_MONITORED, ROW_ACTIVE, ROW_DEGENERATED, ROW_WALLS = 0, 5, 10, 11, 12, 13


def row_width(n_walls: int) -> int:
    """Length of a recorded row for ``n_walls`` walls."""
    return ROW_WALLS + 10 * n_walls


@dataclass(frozen=True)
class MonitorSample:
    """One sample of the monitors at time ``time`` (s): energies, contact counts (monitored
    pairs, active, degenerated and failed contacts of the last evaluation), wall displacements
    (W,3) m, reactions (W,3) N and torques (W,3) N m (of the particles' contact forces on each
    wall, about its reference point: :attr:`~nurbsdem.dynamics.system.DemSystem.wall_torque`),
    the work (W,) J each wall's motion has done on the particles since the start (the
    external work of the energy ledger, wall by wall: its contact forces and rolling
    torques);
    ``hertz`` (active, fallbacks, radii (K,) m, normal
    stiffnesses (K,) N/m) with Hertz–Mindlin interfaces, else None."""

    time: float
    energy: EnergySample
    monitored: int
    active: int
    degenerated: int
    failed: int
    wall_displacement: np.ndarray
    wall_reaction: np.ndarray
    wall_torque: np.ndarray
    wall_work: np.ndarray
    hertz: tuple | None = None

    @staticmethod
    def from_row(time: float, row: np.ndarray, n_walls: int) -> "MonitorSample":
        """The sample of a row written by :func:`record_row`."""
        et, er, pot, en, etan = (float(v) for v in row[ROW_TERMS:ROW_TERMS + 5])
        energy = energy_sample(time, et, er, pot, en, etan,
                               EnergyLedger.from_array(row[ROW_LEDGER:ROW_LEDGER + 5]))
        W = n_walls
        walls = row[ROW_WALLS:ROW_WALLS + 10 * W]
        return MonitorSample(time, energy, int(row[ROW_MONITORED]), int(row[ROW_ACTIVE]),
                             int(row[ROW_DEGENERATED]), 0, walls[:3 * W].reshape(W, 3).copy(),
                             walls[3 * W:6 * W].reshape(W, 3).copy(),
                             walls[6 * W:9 * W].reshape(W, 3).copy(), walls[9 * W:].copy())


def energy_sample(time: float, et: float, er: float, pot: float, en: float, etan: float,
                  ledger: EnergyLedger) -> EnergySample:
    """The EnergySample of the terms of :func:`~nurbsdem.dynamics.energy.energy_terms` and a
    ledger (the friction dissipation is the spring work minus the tangential energy stored)."""
    return EnergySample(time=time, kinetic_translational=float(et), kinetic_rotational=float(er),
                        potential=float(pot), elastic_normal=float(en),
                        elastic_tangential=float(etan),
                        dissipated_normal=ledger.dissipated_normal,
                        dissipated_tangential=ledger.dissipated_tangential,
                        dissipated_friction=ledger.tangential_spring_work - float(etan),
                        external_work=ledger.external_work,
                        initial_mechanical=ledger.initial_mechanical)


@njit(cache=True)
def record_row(row: np.ndarray, mass: np.ndarray, x: np.ndarray, v: np.ndarray, q: np.ndarray,
               L: np.ndarray, inv_I: np.ndarray, gravity: np.ndarray, eel: np.ndarray,
               ledger: np.ndarray, monitored: int, active: int, degenerated: int,
               wall_d: np.ndarray, force: np.ndarray, torque: np.ndarray,
               wall_work: np.ndarray) -> None:
    """Write the monitor row of the present state (columns ROW_*); force, torque (N+W,3):
    the last evaluation's loads, the walls' force rows negated are their reactions, their
    torque rows their torques; wall_work (W,) J."""
    et, er, pot, en, etan = energy_terms(mass, x, v, q, L, inv_I, gravity, eel)
    row[ROW_TERMS] = et
    row[ROW_TERMS + 1] = er
    row[ROW_TERMS + 2] = pot
    row[ROW_TERMS + 3] = en
    row[ROW_TERMS + 4] = etan
    for k in range(5):
        row[ROW_LEDGER + k] = ledger[k]
    row[ROW_MONITORED] = monitored
    row[ROW_ACTIVE] = active
    row[ROW_DEGENERATED] = degenerated
    W, N = wall_d.shape[0], x.shape[0]
    for w in range(W):
        for k in range(3):
            row[ROW_WALLS + 3 * w + k] = wall_d[w, k]
            row[ROW_WALLS + 3 * W + 3 * w + k] = -force[N + w, k]
            row[ROW_WALLS + 6 * W + 3 * w + k] = torque[N + w, k]
        row[ROW_WALLS + 9 * W + w] = wall_work[w]


@dataclass(frozen=True)
class StateSample:
    """The state the ParaView and ``results.h5`` writers take at the end of a deck step at
    time ``time`` (s): the particles' centroids (N,3) m, file->world quaternions (N,4),
    velocities (N,3) m/s and angular velocities (N,3) rad/s (as
    :meth:`~nurbsdem.dynamics.system.DemSystem.body_state` gives them), the walls'
    displacements (W,3) m and the contacts (:func:`contact_output_of`, None without any).
    The compiled deck steps record one at each deck step where output falls due, so that they
    need not return to Python for it (:mod:`nurbsdem.dynamics.deck_steps`)."""

    time: float
    position: np.ndarray
    quaternion: np.ndarray
    velocity: np.ndarray
    angular_velocity: np.ndarray
    wall_displacement: np.ndarray
    contacts: dict | None


def contact_output_of(body_a: np.ndarray, body_b: np.ndarray, point: np.ndarray,
                      force: np.ndarray, fn: np.ndarray, normal: np.ndarray, depth: np.ndarray,
                      degenerated: np.ndarray, coeffs: np.ndarray | None = None,
                      radius: np.ndarray | None = None) -> dict:
    """The contact points' arrays the ParaView writer takes (copies): point (K,3) m,
    force_normal fn·n and force_tangential (K,3) N (the force on B), penetration (K,) m,
    degenerated, body_a, body_b; with Hertz–Mindlin laws (coeffs (K,4), radius (K,) given)
    also stiffness_normal (N/m) and contact_radius (m)."""
    fn_vec = np.asarray(fn)[:, None] * normal
    out = dict(point=np.array(point, copy=True), force_normal=fn_vec,
               force_tangential=np.asarray(force) - fn_vec, penetration=depth,
               degenerated=degenerated, body_a=body_a, body_b=body_b)
    if coeffs is not None and radius is not None:
        out.update(stiffness_normal=coeffs[:, 0], contact_radius=radius)
    return out

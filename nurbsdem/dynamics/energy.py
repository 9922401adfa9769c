"""Energy accounting of a DEM system (all energies in J).

Per sample (:class:`EnergySample`):

* ``kinetic_translational`` Σ ½ m v²; ``kinetic_rotational`` Σ ½ πᵀ I⁻¹ π;
* ``potential`` gravitational, relative to the world origin: −Σ m g·x (g the gravity vector, so
  with g = (0, 0, −9.81) it is Σ m 9.81 z);
* ``elastic_normal`` Σ ½ εn d², ``elastic_tangential`` Σ ½ εt |s|² over the active contacts
  (plus the rolling springs' ½ k_r |θ|², :mod:`nurbsdem.dynamics.rolling`);
* ``dissipated_normal`` / ``dissipated_tangential``: work removed by the normal / tangential
  dashpots (incl. the no-tension clip of the normal force; the normal part also takes the
  elastic energy of a contact left out after its contact problem failed twice,
  :mod:`nurbsdem.contact.scene`), ``dissipated_friction``: work done on
  the tangential and rolling springs minus their elastic energy still stored (slip of the
  Coulomb return mapping, the rolling torque's plastic work, and springs dropped loaded when a
  contact ends; see :mod:`nurbsdem.dynamics.forces`);
* ``external_work``: work done on the particles by the prescribed-motion walls, ∫ reaction·u dt,
  and the potential energy Σ m g·Δx a wrap into a periodic cell takes off (Δx the
  translation, :mod:`nurbsdem.contact.periodic`);
* ``mechanical`` = kinetic + potential + elastic;
* ``balance_error`` = mechanical − mechanical(0) − external_work + dissipated (→ 0).

Consistency with the integrator: the dashpot dissipation and the wall work are accumulated as
the *exact discrete work* of the corresponding impulses in each velocity-Verlet half kick
(:func:`nurbsdem.dynamics.forces.kick_work_terms`), so they carry no quadrature error of their own.
The friction dissipation is defined from the exact discrete work on the tangential springs, so it
adds no error either.  What remains in ``balance_error`` is the difference between the discrete
work of the normal springs and gravity and the change of their potentials, plus the DLM
free-rotation energy error: of the Verlet kind, bounded and **second order, O(h²)** in the
internal step h (measured in tests/test_dynamics_energy.py and
benchmarks/bench_dynamics.py).  Free fall has zero balance error (to round-off).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from numba import njit

from .integrator import kinetic_energies


@dataclass(frozen=True)
class EnergySample:
    """Energies of the system at time ``time`` (s); all in J (see the module docstring)."""

    time: float
    kinetic_translational: float
    kinetic_rotational: float
    potential: float
    elastic_normal: float
    elastic_tangential: float
    dissipated_normal: float
    dissipated_tangential: float
    dissipated_friction: float
    external_work: float
    initial_mechanical: float

    @property
    def kinetic(self) -> float:
        return self.kinetic_translational + self.kinetic_rotational

    @property
    def elastic(self) -> float:
        return self.elastic_normal + self.elastic_tangential

    @property
    def mechanical(self) -> float:
        return self.kinetic + self.potential + self.elastic

    @property
    def dissipated(self) -> float:
        return self.dissipated_normal + self.dissipated_tangential + self.dissipated_friction

    @property
    def balance_error(self) -> float:
        """mechanical − initial mechanical − external work + dissipated (J); 0 for exact accounting."""
        return self.mechanical - self.initial_mechanical - self.external_work + self.dissipated

    def as_dict(self) -> dict[str, float]:
        """All fields plus the derived totals, for output tables."""
        d = asdict(self)
        d.update(kinetic=self.kinetic, elastic=self.elastic, mechanical=self.mechanical,
                 dissipated=self.dissipated, balance_error=self.balance_error)
        return d


@njit(cache=True)
def potential_energy(mass: np.ndarray, x: np.ndarray, gravity: np.ndarray) -> float:
    """Gravitational potential −Σ m g·x (J) relative to the world origin (summed in body
    order)."""
    pot = 0.0
    for i in range(x.shape[0]):
        pot -= mass[i] * (x[i, 0] * gravity[0] + x[i, 1] * gravity[1] + x[i, 2] * gravity[2])
    return pot


@njit(cache=True)
def energy_terms(mass: np.ndarray, x: np.ndarray, v: np.ndarray, q: np.ndarray,
                 L: np.ndarray, inv_I: np.ndarray, gravity: np.ndarray,
                 eel: np.ndarray) -> tuple[float, float, float, float, float]:
    """The state's energies (J): kinetic translational and rotational, potential, and the
    elastic energies of the normal and tangential springs (eel (K,2), summed in contact order).
    One function for every caller (the monitors, the energy guard of the Python and the
    compiled deck steps), so they agree to the bit."""
    et, er = kinetic_energies(mass, v, q, L, inv_I)
    en, etan = 0.0, 0.0
    for c in range(eel.shape[0]):
        en += eel[c, 0]
        etan += eel[c, 1]
    return et, er, potential_energy(mass, x, gravity), en, etan


@njit(cache=True)
def balance_terms(mass: np.ndarray, x: np.ndarray, v: np.ndarray, q: np.ndarray,
                  L: np.ndarray, inv_I: np.ndarray, gravity: np.ndarray, eel: np.ndarray,
                  ledger: np.ndarray) -> tuple[float, float, float]:
    """(mechanical energy, balance error, kinetic + elastic energy) in J of a state and its
    ledger (5,) (:meth:`EnergyLedger.to_array`): the figures of the energy guard and of the
    accuracy control (:mod:`nurbsdem.dynamics.accuracy`), one function for the Python and
    the compiled deck steps so that they decide alike to the bit."""
    et, er, pot, en, etan = energy_terms(mass, x, v, q, L, inv_I, gravity, eel)
    kinetic, elastic = et + er, en + etan
    mech = kinetic + pot + elastic
    dissipated = ledger[0] + ledger[1] + (ledger[2] - etan)
    return mech, mech - ledger[4] - ledger[3] + dissipated, kinetic + elastic


@dataclass
class EnergyLedger:
    """Running accumulators (J) updated by the integrator; part of the checkpoint state."""

    dissipated_normal: float = 0.0
    dissipated_tangential: float = 0.0
    tangential_spring_work: float = 0.0   # work done on the tangential springs (J)
    external_work: float = 0.0
    initial_mechanical: float = float("nan")

    def to_array(self) -> np.ndarray:
        return np.array([self.dissipated_normal, self.dissipated_tangential,
                         self.tangential_spring_work, self.external_work, self.initial_mechanical])

    @staticmethod
    def from_array(a: np.ndarray) -> "EnergyLedger":
        a = np.asarray(a, dtype=float)
        return EnergyLedger(float(a[0]), float(a[1]), float(a[2]), float(a[3]), float(a[4]))

"""Accuracy control of the internal step: more sub-steps only where the energy balance needs them.

Why
---
The time-step control (:mod:`nurbsdem.dynamics.stepcontrol`) keeps the integration *stable*.
Its *accuracy* is another matter: the energy-balance error (:mod:`nurbsdem.dynamics.energy`;
zero for an exact integration) comes almost entirely from impacts — a penalty contact starts
and ends between two internal steps — and falls as h² with the internal step h (measured on
the paper example: 0.28 → 0.16 → 0.10 J for 4.3 → 5.6 → 7.4 sub-steps per deck step, the
explicit and the implicit dashpots alike at equal h).  With ``Damping Implicit`` the springs
alone limit the step, and a calm pack runs at 3–4 sub-steps; an impact needs several times
more.  A fixed step pays the impacts' price everywhere.

The control
-----------
On a step with ``Accuracy η`` every deck step is checked after the guards of
:class:`~nurbsdem.dynamics.system.DemSystem` have passed it: the energy-balance error may grow
by at most the budget

    τ = η · max(E_peak, E_floor)                                                        (A1)

(E_peak the largest kinetic + elastic energy seen before this deck step, E_floor = Σ m|g| r,
the energy guard's scale).  A deck step whose |Δ balance error| exceeds τ is rolled back and
repeated with twice the internal steps (a factor ``acc_refine`` on the count the stability
control chose, up to :data:`ACCURACY_MAX_REFINE`, within the system's ``max_substeps``) —
as long as the repeats converge: a repeat whose growth did not fall below
:data:`ACCURACY_CONVERGENCE` × that of the attempt before it is accepted, for an error that
twice the sub-steps do not reduce is no error of the step size (a contact problem whose
solution jumps — a new contact found already deep, a change of patch at a crease — adds the
same energy whatever h; in the paper example's deposition such deck steps went on missing τ
at 16 × the sub-steps).  A step that still misses τ at the largest factor is accepted too
(accuracy is a goal, not a guard).
A deck step is *calm* when its growth is below :data:`ACCURACY_CALM` · τ (with the error ∝ h²
it would pass with half the sub-steps); after :data:`ACCURACY_DECAY_STEPS` calm deck steps in
a row the factor is halved.  The decisions are taken by the compiled functions below, from the
one :func:`~nurbsdem.dynamics.energy.balance_terms`, in the Python and in the compiled deck
steps alike, so both paths take the same steps to the bit; the factor and its calm count are
part of the checkpoint (a restart continues bit for bit).
"""
from __future__ import annotations

from numba import njit

#: the accuracy control multiplies the stability control's sub-steps by at most this
ACCURACY_MAX_REFINE = 16
#: a deck step is calm when its balance error grew by less than this fraction of the budget
ACCURACY_CALM = 0.25
#: calm deck steps in a row after which the accuracy factor is halved
ACCURACY_DECAY_STEPS = 5
#: a repeat goes on only while each one cut the growth to at most this fraction of the last
ACCURACY_CONVERGENCE = 0.5


@njit(cache=True)
def accuracy_budget(accuracy: float, peak: float, scale_floor: float) -> float:
    """Eq. (A1): the growth (J) of the balance error one deck step may add."""
    return accuracy * max(peak, scale_floor)


@njit(cache=True)
def repeat_for_accuracy(growth: float, budget: float, acc_refine: int, run_substeps: int,
                        max_substeps: int, last_growth: float) -> bool:
    """Whether a deck step whose balance error grew by ``growth`` (J, ≥ 0) is repeated with
    twice its ``run_substeps`` internal steps; ``last_growth`` (J): the growth of the attempt
    before (inf for a first attempt; module docstring)."""
    return (growth > budget and acc_refine < ACCURACY_MAX_REFINE
            and 2 * run_substeps <= max_substeps
            and growth <= ACCURACY_CONVERGENCE * last_growth)


@njit(cache=True)
def after_accepted(growth: float, budget: float, acc_refine: int,
                   acc_calm: int) -> tuple[int, int]:
    """(accuracy factor, calm count) after an accepted deck step whose balance error grew by
    ``growth`` (J): the factor is halved after ACCURACY_DECAY_STEPS calm deck steps."""
    calm = acc_calm + 1 if growth <= ACCURACY_CALM * budget else 0
    if acc_refine > 1 and calm >= ACCURACY_DECAY_STEPS:
        return acc_refine // 2, 0
    return acc_refine, calm

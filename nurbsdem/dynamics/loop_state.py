"""The compiled time loop's state (:mod:`nurbsdem.dynamics.deck_steps`): the status codes it
returns, the named tuples of arrays it carries (the scene's constants, the neighbour list,
the last force evaluation, the control settings, the snapshot a rejected deck step goes back
to) and the indices of its figures and counters.  Units: SI (m, s, kg, J)."""
from __future__ import annotations

from collections import namedtuple

from ..jit import internal


#: the loop did all its deck steps / stopped for the time-step control / a guard fired /
#: the accuracy control rolled deck step ``done`` back to repeat it with twice the internal
#: steps / the accuracy control halved its factor after deck step ``done - 1``
DONE, CONTROL, GUARD, REFINE, RECOUNT = 0, 1, 2, 3, 4

#: the scene's constants: the tables of :mod:`nurbsdem.contact.listed`, the skin, margin and
#: certificates, the contact law (Hertz), the first patch of each shape (curvature radii);
#: ``owned`` (N,) all True (one rank); the flat walls (the first ``flat_walls`` walls: the
#: mesh and surface walls follow them)
SceneConst = namedtuple("SceneConst", "tables n radius skin margin certificates hertz tab "
                        "first_patch body_shape sphere_radius owned threads all_spheres "
                        "flat_walls cell")
#: the neighbour list and its per-pair arrays, odometers, the poses it was built at and the
#: previous poses; in a periodic cell the image (L,3) int of each pair's body B
PairList = namedtuple("PairList", "a b keys mask_a mask_b rows_f rows_i budget odo built_x "
                      "built_R built_wall built_pos prev_pos prev_R prev_wall prev_x shift")
#: the last force evaluation: per-contact arrays (``depth`` (K,) m and ``deg`` (K,) the
#: contacts' penetrations and degeneration flags, for the ParaView samples), histories and
#: loads; the separated pairs (``near_*``) of the last internal step of a deck step only
#: (the time-step control's network; empty in between); in a periodic cell the translation
#: (K,3) m of the image of B each contact and separated pair touches (else (0,3))
Evaluation = namedtuple("Evaluation", "a b point normal ftot fdn fdt fet fn eel stick key coeffs "
                        "radius fallback hist_keys hist_springs force torque slip near_a near_b "
                        "near_point near_normal near_gap reach monitored degenerated depth deg "
                        "image near_image")
#: step-control and guard settings (floats and flags); ``heavy``: the sub-step count from which
#: the caller warns (once: afterwards larger than any count)
Control = namedtuple("Control", "dt refine_decay safety dt_apriori forced recheck fall "
                     "bound_slack energy_tolerance scale_floor check_energy watch_period2 "
                     "implicit accuracy max_substeps heavy")
#: the time-step control's figures (float64 array, s) of the last exact estimate, in this
#: order: the network's Gershgorin bound, its critical step (Lanczos), the critical step
#: (the smaller of that and the a-priori one)
DT_BOUND, DT_NETWORK, DT_CRITICAL = range(3)
#: ... then those of an exact estimate after which the count changes (the loop returns
#: CONTROL): the Gershgorin bound (s), λmax of the stiffness (ω², 1/s²) and damping (γ, 1/s)
#: operators, the body the stiffest mode centres on, and the deck step they belong to (−1:
#: none); :meth:`DemSystem._control_step <nurbsdem.dynamics.system.DemSystem>` takes them
#: instead of the same estimate again
RATES_BOUND, RATES_OMEGA2, RATES_GAMMA, RATES_BODY, RATES_STEP = range(3, 8)
ESTIMATE_SIZE = 8

#: counters (int64 array) of the loop's state, in this order
STEP_COUNT, REFINE, CALM, BUILDS, EVALS, MONITORED, ACTIVE_SUM, ACTIVE_MAX = range(8)
#: ... then the implicit dashpots' solves, active-set rounds and CG iterations
DASHPOT_SOLVES = 8
#: ... then the pairs the point-to-surface solver answered, and the CPU cycles spent in the
#: search (odometers, list, certificates) and in the contact rows
POINT_SOLVES, SEARCH_CYCLES, ROW_CYCLES = 11, 12, 13
#: ... the sum over deck steps of the degenerated contacts at their ends
DEGENERATED_SUM = 14
#: ... and the accuracy control's factor, calm deck steps in a row and repeated deck steps
#: (:mod:`nurbsdem.dynamics.accuracy`)
ACC_REFINE, ACC_CALM, ACC_REPEATS = 15, 16, 17
#: ... and the exact (Lanczos) estimates the loop took itself
NETWORK_ESTIMATES = 18
#: ... and the CPU cycles spent in the implicit dashpots and in the time-step control (two
#: parts of the solver's "forces + integration", :attr:`DemSystem.split
#: <nurbsdem.dynamics.system.DemSystem.split>`)
DASHPOT_CYCLES, CONTROL_CYCLES = 19, 20
#: ... and the CPU cycles of the integration (half kicks, the period-2 watch, drift, angular
#: velocities) and of the contact forces (the poses for the search, the contact arrays,
#: histories and loads; not the dashpots): two more parts of "forces + integration"
INTEGRATION_CYCLES, FORCES_CYCLES = 21, 22
N_COUNTERS = 23


#: what a deck step rolled back by the accuracy control restores: the body state, the
#: ledger's and the walls' exact accumulators, the period-2 watch, the pair list (its rows copied:
#: the loop updates them in place), the last evaluation, the walls' kinematics and the energy
#: peak (the angular velocities follow from q, L when the next call starts)
Snapshot = namedtuple("Snapshot", "x v q L exact alt_prev_v alt_prev_L "
                      "alt_count pl ev wall_d wall_u peak")


@internal
def _snapshot(x, v, q, L, exact, alt_prev_v, alt_prev_L, alt_count, pl,
              ev, wall_d, wall_u, peak):
    """The state at the start of a deck step (copies of what the loop changes in place)."""
    pl_copy = PairList(pl.a, pl.b, pl.keys, pl.mask_a, pl.mask_b, pl.rows_f.copy(),
                       pl.rows_i.copy(), pl.budget.copy(), pl.odo, pl.built_x, pl.built_R,
                       pl.built_wall, pl.built_pos, pl.prev_pos, pl.prev_R, pl.prev_wall,
                       pl.prev_x, pl.shift)
    return Snapshot(x.copy(), v.copy(), q.copy(), L.copy(), exact.copy(),
                    alt_prev_v.copy(), alt_prev_L.copy(),
                    alt_count.copy(), pl_copy, ev, wall_d, wall_u, peak[0])


@internal
def _restore(sn, x, v, q, L, exact, alt_prev_v, alt_prev_L, alt_count, peak):
    """Write a :class:`Snapshot` back into the arrays the caller holds."""
    x[:] = sn.x
    v[:] = sn.v
    q[:] = sn.q
    L[:] = sn.L
    exact[:] = sn.exact
    alt_prev_v[:] = sn.alt_prev_v
    alt_prev_L[:] = sn.alt_prev_L
    alt_count[:] = sn.alt_count
    peak[0] = sn.peak

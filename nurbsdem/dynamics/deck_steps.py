"""Compiled deck steps: the internal steps of :class:`~nurbsdem.dynamics.system.DemSystem`
with a :class:`~nurbsdem.contact.scene.SceneContacts` provider on one rank, in one compiled
loop over many deck steps.

Each internal step is the engine's one internal step (:mod:`nurbsdem.dynamics.step`): its
start (half kick with its work, the period-2 watch, drift), the scene's compiled contact
search (odometers, the neighbour list with its skin and the candidate patches,
:func:`~nurbsdem.contact.listed.scene_list`; certificates, :mod:`nurbsdem.contact.verlet`; the
rows of the pairs not certified apart, :func:`~nurbsdem.contact.listed.solve_due_into`: closed
forms, point-to-surface, LCP batches, in place), the Hertz radii of the contacts where a law
needs them (:func:`~nurbsdem.geometry.curvature.scene_contact_radii`), its contact part
(forces, histories, implicit dashpots, gravity) and its second half kick.  The driver in
Python (:mod:`nurbsdem.dynamics.internal_step`) calls the same parts around a provider call, so
the trajectory is the same to the bit whichever drives it (tested).  After each deck step
the loop runs the guards (finite state, energy) and the Gershgorin gate of the
time-step control; the energies used by the guard are summed in a different order from the
Python driver's (round-off only).  The time of the search and of the contact rows is taken
with the CPU's cycle counter (:func:`nurbsdem.jit.cycles`) for the run's time split.  In a
periodic cell the search wraps the centroids into it and builds the list through its faces
inside the loop, and the step's parts take the image bodies of the contacts with images
(:mod:`nurbsdem.dynamics.periodic_steps`).

The loop returns to Python

* after ``n_deck`` deck steps (the caller stops where VTK or results output or a checkpoint
  falls due; the monitor samples in between are rows the loop records,
  :mod:`nurbsdem.dynamics.monitor`),
* with :data:`CONTROL` after a deck step at which the time-step control changes the sub-step
  count (or finds more than the most allowed, or reaches the count that warns): the caller
  then runs :meth:`DemSystem._control_step` exactly as after a Python deck step, which takes
  the same figures (the loop's exact estimate, RATES_BOUND …, not computed again: the same
  kernels on the same arrays) and logs, warns or raises.  Where the Gershgorin gate calls for the exact
  (Lanczos) estimate of the network, or at a periodic re-estimate (every
  ``NETWORK_RECHECK_STEPS`` deck steps, when the count could fall), and the count stands, the
  loop takes the estimate itself (:func:`_step_control`; ~500 returns of the paper example's
  ~520 did nothing else);
* with :data:`REFINE` when the accuracy control (``Accuracy`` on the step,
  :mod:`nurbsdem.dynamics.accuracy`) rejects deck step ``done + 1``: the loop has rolled it
  back (a snapshot taken at the start of each deck step) and doubled its factor, and the
  caller goes on with the new count; with :data:`RECOUNT` after a deck step at whose end the
  factor fell (the walls' kinematics are tabulated per internal step for one count),
* with :data:`GUARD` when a guard fires, a contact between materials without an interface
  occurs or an LCP fails (even after its cold retry) in deck step ``done + 1``: the caller
  restores the state of the loop's start and runs the ``done`` deck steps before it in the
  loop again; the failed one, first in the next call, fails there at once and is repeated
  in Python alone, which repeats it with more sub-steps, answers the failed LCP once with
  its moved solution (:mod:`nurbsdem.contact.scene`), or raises.

Units: SI (m, s, kg); global body indices particles 0..N-1, walls N..N+W-1.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..contact.sphere import closed_form_into
from ..contact.curved_compiled import curved_contacts_ptr, pack_curved, with_curved_contacts
from ..contact.kinds import MESH_WALL, SURFACE_WALL
from ..contact.listed import scene_list_ptr, solve_due_into_ptr
from ..contact.verlet import (active_arrays, active_rows, advance_odometers, carry_rows,
                              due_rows, list_is_stale, near_arrays, near_pairs, renew_certificates,
                              repose, reposed_bodies)
from ..geometry.curvature import scene_contact_radii
from ..geometry.rotation import quats_to_matrices
from ..jit import PointerKernel, cycles, fill_lazy_kernels, internal, seconds_per_cycle
from .curved_turns import table_turns, turn_walls
from .accuracy import accuracy_budget, after_accepted, repeat_for_accuracy
from .contact_state import contacts_of
from .energy import balance_terms
from .loop_state import (ACC_CALM, ACC_REFINE, ACC_REPEATS, ACTIVE_MAX, ACTIVE_SUM, BUILDS, CALM,
                        CONTROL, CONTROL_CYCLES, Control, DASHPOT_CYCLES, DASHPOT_SOLVES,
                        DEGENERATED_SUM, DONE, DT_BOUND, DT_CRITICAL, DT_NETWORK, ESTIMATE_SIZE,
                        EVALS, Evaluation, FORCES_CYCLES, GUARD, INTEGRATION_CYCLES, MONITORED,
                        NETWORK_ESTIMATES, N_COUNTERS, POINT_SOLVES, PairList, RATES_BODY,
                        RATES_BOUND, RATES_GAMMA, RATES_OMEGA2, RATES_STEP, RECOUNT, REFINE,
                        ROW_CYCLES, SEARCH_CYCLES, STEP_COUNT, SceneConst, _restore, _snapshot)
from .monitor import record_row, row_width
from .periodic_steps import (apply_wrap, has_images, image_contact_part_ptr,
                             image_kick_part_ptr, image_step_start_ptr, network_images,
                             pair_images, periodic_const, periodic_list_ptr, shift_rows,
                             solve_images_ptr, stored_images, wrapped)
from .step import (all_kinematics, contact_part_kernel, contact_part_ptr, interfaces_defined,
                   kick_part_ptr, ledger_of, spun_contacts, step_start_ptr, wall_work_of)
from .rigid import body_poses, omega_world
from .stepcontrol import (ALTERNATION_STEPS, FALL_HYSTERESIS, HEAVY_SUBSTEPS,
                          NETWORK_BOUND_SLACK, NETWORK_RECHECK_STEPS, REFINE_DECAY_STEPS,
                          body_speeds, contact_network,
                          critical_step_from_rates, needed_substeps, network_count_stands,
                          network_gershgorin, network_rates_scaled, periodic_recheck)



# --------------------------------------------------------------------------- contact search
@internal(inline="always")
def _search(sc, pl, x: np.ndarray, R: np.ndarray, pos: np.ndarray, wall_d: np.ndarray,
            counters: np.ndarray):
    """One call of the scene's contact search (:meth:`SceneContacts.__call__`): returns the
    new PairList, the pairs' reach (sum of odometers), the list positions solved (ascending),
    whether an LCP failed (the Python path answers it: module docstring) and the wrap (N,3)
    m a build in a periodic cell took off the centroids (:mod:`.periodic_steps`; else (0,3))."""
    c0 = cycles()
    odo = advance_odometers(pl.odo, x, pl.prev_x, R, pl.prev_R, sc.radius, wall_d, pl.prev_wall)
    a, b, keys = pl.a, pl.b, pl.keys
    built_x, built_R, built_wall, built_pos = pl.built_x, pl.built_R, pl.built_wall, pl.built_pos
    mask_a, mask_b, shift, moved = pl.mask_a, pl.mask_b, pl.shift, np.zeros((0, 3))
    stale = list_is_stale(built_x, built_R, built_wall, x, R, wall_d, sc.radius, sc.skin)
    if stale and sc.cell.on:        # wrapped into the cell, then built through its faces
        x, pos, moved = wrapped(sc.cell, x, pos)
        a, b, keys, mask_a, mask_b, shift = periodic_list_ptr(sc.tables, sc.cell, x, pos, R,
                                                              wall_d, sc.margin + sc.skin)
        built_x, built_R, built_wall, built_pos = x.copy(), R, wall_d.copy(), pos.copy()
    elif stale:
        fresh = reposed_bodies(built_x, built_R, built_wall, x, R, wall_d, sc.radius, sc.skin)
        built_x, built_R, built_wall, built_pos = repose(built_x, built_R, built_wall, built_pos,
                                                         x, R, wall_d, pos, fresh)
        a, b, keys, mask_a, mask_b = scene_list_ptr(sc.tables, built_x, built_pos, built_R,
                                                    built_wall, sc.owned, sc.margin + sc.skin,
                                                    pl.keys, pl.mask_a, pl.mask_b, fresh)
    if stale:
        rows_f, rows_i, budget, _ = carry_rows(pl.keys, pl.rows_f, pl.rows_i, pl.budget,
                                               np.zeros(pl.keys.shape[0], np.bool_), keys)
        if moved.shape[0]:
            shift_rows(rows_f, a, moved)
        counters[BUILDS] += 1
    else:       # updated in place: the loop owns these arrays (copied at its start)
        rows_f, rows_i, budget = pl.rows_f, pl.rows_i, pl.budget
    reach, due = due_rows(a, b, odo, budget, sc.certificates)
    c1 = cycles()
    failed = False
    if sc.cell.on:          # B's images as extra particles
        points, failed = solve_images_ptr(sc.tables, sc.cell, a, b, mask_a, mask_b, rows_f,
                                          rows_i, due, shift, pos, R, wall_d, sc.threads)
        counters[POINT_SOLVES] += points
    elif sc.all_spheres:    # closed forms only (what solve_due_into does for them)
        t = sc.tables
        closed_form_into(rows_f, rows_i, due, a, b, t.n, pos, R, wall_d, t.body_shape,
                         t.sphere_center, t.sphere_radius, t.wall_origin, t.wall_a, t.wall_b,
                         t.wall_dom)
    else:                   # in place: the loop owns these arrays
        points, failed = solve_due_into_ptr(sc.tables, a, b, mask_a, mask_b, rows_f, rows_i,
                                            due, pos, R, wall_d, sc.threads)
        counters[POINT_SOLVES] += points
    c2 = cycles()
    renew_certificates(budget, due, rows_f, rows_i, reach)
    counters[SEARCH_CYCLES] += (c1 - c0) + (cycles() - c2)
    counters[ROW_CYCLES] += c2 - c1
    return (PairList(a, b, keys, mask_a, mask_b, rows_f, rows_i, budget, odo, built_x, built_R,
                     built_wall, built_pos, pos, R, wall_d, x, shift), reach, due, failed, moved)


# --------------------------------------------------------------------------- forces
@internal
def _hertz_radii(sc, a, b, patch_a, patch_b, params, nrm, deg, R):
    """Equivalent Hertz radii (K,) of the active contacts and the number of fallbacks
    (:func:`~nurbsdem.geometry.curvature.scene_contact_radii`, as the Python path calls it;
    zeros and 0 for linear laws)."""
    K = a.shape[0]
    r_eff = np.zeros(K)
    if not sc.hertz or K == 0:
        return r_eff, 0
    t = sc.tab
    n_fall = scene_contact_radii(t[0], t[1], t[2], t[3], t[4], t[5], t[6], sc.first_patch,
                                 sc.body_shape, sc.sphere_radius, sc.radius, R, a, b,
                                 patch_a, patch_b, params, nrm, deg, r_eff)
    return r_eff, n_fall


@internal
def _put_curved(cwork, K0, a, b, pa, pb, nrm, dep, key, deg, params, patch_a, patch_b):
    """The contacts of the particles with the mesh and surface walls (``cwork``'s, of
    :func:`~nurbsdem.contact.curved_compiled.curved_contacts`: no surface parameters, patch
    −1) into the rows K0 .. of the active contact arrays, after the scene's, as the Python
    driver's provider merges them."""
    for r in range(cwork.count[0]):
        c = K0 + r
        a[c], b[c], key[c] = cwork.out_a[r], cwork.out_b[r], cwork.out_key[r]
        for k in range(3):
            pa[c, k] = cwork.out_pa[r, k]
            pb[c, k] = cwork.out_pb[r, k]
            nrm[c, k] = cwork.out_normal[r, k]
        for k in range(4):
            params[c, k] = 0.0
        dep[c], deg[c], patch_a[c], patch_b[c] = cwork.out_depth[r], 0, -1, -1


@internal
def _evaluate(sc, bc, cc, pl, reach: np.ndarray, due: np.ndarray, full: bool, ev,
              x: np.ndarray, v: np.ndarray, q: np.ndarray, L: np.ndarray, omega: np.ndarray,
              R: np.ndarray, pos: np.ndarray, wall_d: np.ndarray, wall_u: np.ndarray, h: float,
              counters: np.ndarray, curved, cwork, spin: np.ndarray, time: float):
    """DemSystem._evaluate after the search: contact forces (Eq. 16–17, or Hertz–Mindlin with
    the contacts' equivalent radii) of the active pairs with their tangential histories, and
    gravity (omega (N,3): the particles' angular velocities, rad/s; implicit dashpots when
    ``cc.implicit``).  The active pairs are found among the rows just solved (``due``, list
    positions: :func:`~nurbsdem.contact.verlet.active_rows`); the separated pairs, which only
    the time-step control at the end of a deck step takes, with ``full`` only (else none).
    The contacts of the particles with mesh and surface walls ``curved`` at ``time`` (s) follow
    the scene's (:func:`_put_curved`; ``cwork``: their workspaces; ``spin`` (W,6): each
    wall's angular velocity, rad/s, and centre, m).  Returns (True, the new
    Evaluation), or (False, ev) when a contact has no interface (the Python path raises the
    error)."""
    act = active_rows(pl.rows_i, due)
    k = 0
    if curved.n_walls:             # the particles' contacts with the mesh and surface walls
        curved_contacts_ptr(curved, cwork, time, x, R, pos, wall_d)
        if cwork.count[0] < 0:     # a refused surface contact: the Python driver raises it
            return False, ev
        k = cwork.count[0]
    (a, b, pa, pb, nrm, dep, key, deg, params, patch_a,
     patch_b) = active_arrays(pl.rows_f, pl.rows_i, pl.a, pl.b, pl.keys, act, np.int64(k))
    if k:                          # after the scene's, as the Python driver's provider
        _put_curved(cwork, act.shape[0], a, b, pa, pb, nrm, dep, key, deg, params, patch_a,
                    patch_b)
    monitored = due.shape[0] + k   # the provider counts the curved walls' contacts monitored
    if full:
        near, gap = near_pairs(pl.rows_f, pl.rows_i, pl.budget, reach)
    else:
        near, gap = np.empty(0, np.int64), np.empty(0)
    near_a, near_b, near_point, near_normal, gap = near_arrays(pl.rows_f, pl.a, pl.b, near, gap)
    image, near_image = pair_images(sc.cell, pl.shift, act), pair_images(sc.cell, pl.shift, near)
    if not interfaces_defined(bc, a, b):
        return False, ev
    radius, n_fall = _hertz_radii(sc, a, b, patch_a, patch_b, params, nrm, deg, R)
    pos_all, vel_all, omg_all = all_kinematics(x, v, omega, wall_d, wall_u)
    if curved.n_walls:             # a wall turns about its centre: u + ω × (p − c − d)
        n = x.shape[0]
        for w in range(wall_d.shape[0]):
            for k in range(3):
                pos_all[n + w, k] += spin[w, 3 + k]
                omg_all[n + w, k] = spin[w, k]
    solves = np.zeros(4, np.int64)
    if has_images(image):          # a contact with a particle's image in a periodic cell
        part = image_contact_part_ptr(bc, cc.implicit, a, b, pa, pb, nrm, dep, key, radius,
                                      ev.hist_keys, ev.hist_springs, pos_all, vel_all,
                                      omg_all, q, L, h, solves, image)
    else:
        part = contact_part_ptr(bc, cc.implicit, a, b, pa, pb, nrm, dep, key, radius,
                                ev.hist_keys, ev.hist_springs, pos_all, vel_all, omg_all, q,
                                L, h, solves, np.zeros(0), np.zeros(0, np.int64))
    (force, torque, point, ftot, fdn, fdt, fet, fn, eel, stick, coeffs, slip, hist_keys,
     hist_springs, _) = part
    counters[DASHPOT_SOLVES] += solves[0]
    counters[DASHPOT_SOLVES + 1] += solves[1]
    counters[DASHPOT_SOLVES + 2] += solves[2]
    counters[DASHPOT_CYCLES] += solves[3]
    return True, Evaluation(a, b, point, nrm, ftot, fdn, fdt, fet, fn, eel, stick, key, coeffs,
                            radius, n_fall, hist_keys, hist_springs, force, torque, slip,
                            near_a, near_b, near_point, near_normal, gap, reach, monitored,
                            np.count_nonzero(deg), dep, deg, image, near_image)


# --------------------------------------------------------------------------- integration
@internal
def _all_finite(arr: np.ndarray) -> bool:
    """Whether every entry of the 2-D array is finite (a loop: ``np.isfinite(a).all()``
    makes a temporary array)."""
    for i in range(arr.shape[0]):
        for k in range(arr.shape[1]):
            if not math.isfinite(arr[i, k]):
                return False
    return True


@internal
def _finite(x, v, q, L, force) -> bool:
    return (_all_finite(x) and _all_finite(v) and _all_finite(q) and _all_finite(L)
            and _all_finite(force))


@internal
def _energy_ok(bc, cc, ev, x, v, q, L, ledger, peak: np.ndarray) -> tuple[bool, float]:
    """DemSystem._check_energy (the same energy_terms, the ledger's array (5,) J
    :func:`~nurbsdem.dynamics.step.ledger_of`), then the peak of kinetic + elastic energy is
    raised.  Returns (passed, the balance error in J, which the accuracy control
    takes too)."""
    mech, balance, moving = balance_terms(bc.mass, x, v, q, L, bc.inv_I, bc.gravity, ev.eel,
                                          ledger)
    ok = True
    if cc.check_energy:
        tol = cc.energy_tolerance * max(peak[0], abs(ledger[3]), cc.scale_floor)
        gain = mech - ledger[4] - ledger[3]
        ok = math.isfinite(mech) and math.isfinite(balance) and gain <= tol and abs(balance) <= tol
    if ok:
        peak[0] = max(peak[0], moving)
    return ok, balance


@internal
def _step_control(bc, cc, ev, x, v, q, omega, wall_u, substeps: int, counters,
                  estimate) -> bool:
    """DemSystem._control_step after a deck step: True when the present sub-step count stands
    — by the Gershgorin gate (the network no stiffer than at the last exact estimate, or
    allowing the count anyway), or by the exact estimate, taken here with the same kernels in
    the same order (its figures written into ``estimate``: DT_BOUND, DT_NETWORK, DT_CRITICAL,
    s).  False when the count is to change, exceeds ``cc.max_substeps`` or reaches
    ``cc.heavy``: the caller runs _control_step, which logs, warns or raises with the
    estimate's figures (written into ``estimate`` from RATES_BOUND on; not taken again)."""
    if cc.forced:
        return True
    recheck = periodic_recheck(counters[STEP_COUNT], cc.recheck, counters[REFINE], cc.fall,
                               substeps)
    speed = body_speeds(v, omega, bc.ell, wall_u)
    a, b, p, n, coeffs = contact_network(ev.a, ev.b, ev.point, ev.normal, ev.coeffs, ev.near_a,
                                         ev.near_b, ev.near_point, ev.near_normal, ev.near_gap,
                                         speed, cc.dt, bc.g_norm, bc.table, bc.material)
    if cc.implicit:
        coeffs[:, 1] = 0.0      # implicit normal dashpots do not limit the step
    img = network_images(ev.image, ev.near_image, ev.near_a, ev.near_b, a, b)
    Q = quats_to_matrices(q)
    if not recheck and network_count_stands(a, b, p, n, coeffs, x, Q, bc.inv_mass, bc.inv_I,
                                            cc.dt, cc.safety, cc.dt_apriori,
                                            estimate[DT_BOUND], cc.bound_slack,
                                            counters[REFINE], substeps, img):
        return True
    dt_bound, dt_network = math.inf, math.inf
    omega2, gamma, body = 0.0, 0.0, -1
    if a.shape[0]:
        wk, wc = network_gershgorin(a, b, p, n, coeffs, x, Q, bc.inv_mass, bc.inv_I,
                                    np.bool_(False), img)
        dt_bound = critical_step_from_rates(wk, wc)
        omega2, gamma, body = network_rates_scaled(a, b, p, n, coeffs, x, Q, bc.sq_m, bc.sq_I,
                                                   img)
        dt_network = critical_step_from_rates(omega2, gamma)
    dt_critical = min(cc.dt_apriori, dt_network)
    need = needed_substeps(cc.dt, cc.safety * dt_critical) * counters[REFINE]
    if (need > cc.max_substeps or need > substeps or need < cc.fall * substeps
            or substeps >= cc.heavy):
        estimate[RATES_BOUND], estimate[RATES_OMEGA2], estimate[RATES_GAMMA] = (dt_bound,
                                                                                omega2, gamma)
        estimate[RATES_BODY] = body
        estimate[RATES_STEP] = counters[STEP_COUNT] if a.shape[0] else -1
        return False
    estimate[DT_BOUND], estimate[DT_NETWORK], estimate[DT_CRITICAL] = (dt_bound, dt_network,
                                                                       dt_critical)
    counters[NETWORK_ESTIMATES] += 1
    return True


@internal
def _balance(bc, ev, x, v, q, L, exact, initial: float) -> float:
    """The energy-balance error (J) of the present state (DemSystem._balance) with the
    ledger's exact sums ``exact`` and the initial mechanical energy ``initial`` (J)."""
    return balance_terms(bc.mass, x, v, q, L, bc.inv_I, bc.gravity, ev.eel,
                         ledger_of(exact, initial))[1]


@internal(inline="always")
def _count_deck_step(counters, refine_decay: int, ev) -> int:
    """After an accepted deck step: a calm one more (the stability control's refinement
    halves after ``refine_decay`` of them) and the contacts' counts of the last evaluation;
    returns its active contacts."""
    counters[CALM] += 1
    if counters[REFINE] > 1 and counters[CALM] >= refine_decay:
        counters[REFINE] //= 2
        counters[CALM] = 0
    active = ev.a.shape[0]
    counters[ACTIVE_SUM] += active
    counters[ACTIVE_MAX] = max(counters[ACTIVE_MAX], active)
    counters[DEGENERATED_SUM] += ev.degenerated
    return active


@internal
def _kept(j: int, x, q, v, L, wall_d, ev):
    """What the loop keeps of deck step j's end for the ParaView and results output: the body
    state, the walls and the contact arrays the writers take (not the whole Evaluation: its
    histories and near pairs would stay alive too)."""
    return (j, x, q, v, L, wall_d, ev.a, ev.b, ev.point, ev.ftot, ev.fn, ev.normal, ev.depth,
            ev.deg, ev.coeffs, ev.radius)


@internal
def _kick_walls(n_curved: int, spin, ev, n: int, wall_d, u_mean):
    """(body_b, wall_d, u_mean, wall_w) of the stored contacts for a half kick's work terms: as
    they are (walls that do not turn), or with turning walls each contact with one at its
    point velocity (:func:`spun_contacts`; the Python driver's ``_kick_walls``)."""
    if n_curved and ev.a.shape[0]:
        return spun_contacts(ev.a, ev.b, ev.point, n, spin, wall_d, u_mean)
    return ev.b, wall_d, u_mean, np.zeros((wall_d.shape[0], 3))


# --------------------------------------------------------------------------- the loop
#: the loop's large parts compiled once and called through pointers
#: (:class:`~nurbsdem.jit.PointerKernel`): the loop does not compile them again
_evaluate_ptr = PointerKernel(_evaluate, "deck_evaluate").call
_step_control_ptr = PointerKernel(_step_control, "deck_step_control").call


@njit(cache=True, nogil=True)   # output writers run meanwhile (a worker thread)
def run_deck_steps(n_deck: int, substeps: int, sc, bc, cc, pl, ev, x, v, q, L, wall_d, wall_u,
                   walls_d, walls_u, exact, initial, alt_prev_v, alt_prev_L,
                   alt_count, counters, peak, acc_growth, estimate, sample_at, rows, state_at,
                   times, curved, cwork, spin, turns):
    """Up to n_deck deck steps of ``substeps`` × ``counters[ACC_REFINE]`` internal steps each
    (``substeps``: the stability control's count; module docstring).

    sample_at (n_deck,) bool: the deck steps at whose end a monitor row is written into rows
    (n_deck, row_width(W)) (:func:`~nurbsdem.dynamics.monitor.record_row`).  state_at
    (n_deck,) bool: the deck steps at whose end the state is kept for the ParaView and
    results output, in the list ``states``: (deck step, x, q, v, L, wall_d, and the
    Evaluation's a, b, point, ftot, fn, normal, depth, deg, coeffs, radius).

    walls_d, walls_u (n_deck·n_run, W, 3): the walls' displacements (m) and velocities
    (m/s) at the end of each internal step, times (n_deck·n_run,) s those ends (the poses of
    the mesh and surface walls ``curved``,
    :data:`~nurbsdem.contact.curved_compiled.CurvedConst`; ``cwork``: their workspaces; spin
    (W,6): each wall's angular velocity, rad/s, and centre, m; ``turns``: the poses and spin
    of the walls a table turns at those times, :mod:`~nurbsdem.dynamics.curved_turns`).
    Body state (x, v, q, L), the exact accumulators ``exact`` of the ledger and the walls'
    work (:data:`~nurbsdem.dynamics.forces.EXACT_WALLS`; ``initial``: the initial
    mechanical energy, J, :func:`~nurbsdem.dynamics.step.ledger_of`), the period-2 watch arrays,
    counters (int64, STEP_COUNT …), peak (1,) J,
    acc_growth (1,) J (DemSystem.acc_last_growth) and the time-step control's ``estimate``
    (DT_BOUND …, s) are updated in place.  With the accuracy
    control (``cc.accuracy`` > 0,
    :mod:`nurbsdem.dynamics.accuracy`) a deck step whose balance error grows beyond its
    budget is rolled back (REFINE, the state of its start) and one after which the factor
    falls ends the call (RECOUNT).  Returns (status, deck steps done, PairList, Evaluation,
    wall_d, wall_u, states).
    """
    n_run = substeps * counters[ACC_REFINE]
    h = cc.dt / n_run
    omega = omega_world(q, L, bc.inv_I)      # of the present state, kept up to date below
    accuracy = cc.accuracy > 0.0
    # the balance error at the start of the deck step (then carried from its end)
    balance0 = _balance(bc, ev, x, v, q, L, exact, initial) if accuracy else 0.0
    states = [_kept(np.int64(0), x, q, v, L, wall_d, ev) for _ in range(0)]   # typed by items
    every = np.zeros(0, np.bool_)   # one rank books the work of every contact
    status, done = DONE, n_deck     # one exit: the code of each return is large
    for j in range(n_deck):
        if accuracy:
            sn = _snapshot(x, v, q, L, exact, alt_prev_v, alt_prev_L, alt_count, pl, ev,
                           wall_d, wall_u, peak)
        for k in range(n_run):
            t = j * n_run + k
            d_new, u_new = walls_d[t], walls_u[t]
            u_mean = (d_new - wall_d) / h
            c0 = cycles()
            if has_images(ev.image):    # contacts with periodic images (.periodic_steps)
                omega, worst, run = image_step_start_ptr(bc, ev, x, v, q, L, wall_d, u_mean, h,
                                                         exact, alt_prev_v, alt_prev_L,
                                                         alt_count, cc.watch_period2)
            else:
                kick_b, kick_d, kick_u, kick_w = _kick_walls(curved.n_walls, spin, ev,
                                                             x.shape[0], wall_d, u_mean)
                omega, worst, run = step_start_ptr(
                    bc, ev.a, ev.b, ev.point, ev.ftot, ev.fdn, ev.fdt, ev.fet, ev.force,
                    ev.torque, x, v, q, L, omega, kick_b, kick_d, kick_u, kick_w, h, exact,
                    every, alt_prev_v, alt_prev_L, alt_count, cc.watch_period2)
            if worst >= 0 and run >= ALTERNATION_STEPS:
                status = GUARD
                break
            wall_d, wall_u = d_new.copy(), u_new.copy()
            c1 = cycles()
            R, pos = body_poses(q, bc.P, x, bc.centroid)
            c2 = cycles()
            pl, reach, due, failed, moved = _search(sc, pl, x.copy(), R, pos,  # the flat walls
                                                    wall_d[:sc.flat_walls].copy(), counters)
            if failed or not apply_wrap(x, moved, bc.mass, bc.gravity, initial, exact):
                status = GUARD
                break
            counters[EVALS] += 1
            counters[MONITORED] += due.shape[0]
            c3, dashpots = cycles(), counters[DASHPOT_CYCLES]
            turn_walls(curved, spin, turns, t)
            ok, ev = _evaluate_ptr(sc, bc, cc, pl, reach, due, k == n_run - 1, ev, x, v, q, L,
                                   omega, R, pos, wall_d, wall_u, h, counters, curved, cwork,
                                   spin, times[t])
            if not ok:
                status = GUARD
                break
            c4 = cycles()
            if has_images(ev.image):
                omega = image_kick_part_ptr(bc, ev, x, v, q, L, wall_d, u_mean, 0.5 * h,
                                            exact)
            else:
                kick_b, kick_d, kick_u, kick_w = _kick_walls(curved.n_walls, spin, ev,
                                                             x.shape[0], wall_d, u_mean)
                omega = kick_part_ptr(bc, ev.a, ev.b, ev.point, ev.ftot, ev.fdn, ev.fdt, ev.fet,
                                      ev.force, ev.torque, x, v, q, L, omega, kick_b, kick_d,
                                      kick_u, kick_w, 0.5 * h, exact, every)
            counters[INTEGRATION_CYCLES] += (c1 - c0) + (cycles() - c4)
            counters[FORCES_CYCLES] += (c2 - c1) + (c4 - c3) - (counters[DASHPOT_CYCLES] - dashpots)
            if not _finite(x, v, q, L, ev.force):
                status = GUARD
                break
        if status != DONE:          # a guard fired in deck step j
            done = j
            break
        counters[STEP_COUNT] += 1
        ok, balance = _energy_ok(bc, cc, ev, x, v, q, L, ledger_of(exact, initial), peak)
        if not ok:
            status, done = GUARD, j
            break
        acc = counters[ACC_REFINE]
        if accuracy:
            growth = abs(balance - balance0)
            budget = accuracy_budget(cc.accuracy, sn.peak, cc.scale_floor)
            if repeat_for_accuracy(growth, budget, acc, n_run, cc.max_substeps, acc_growth[0]):
                _restore(sn, x, v, q, L, exact, alt_prev_v, alt_prev_L, alt_count, peak)
                counters[STEP_COUNT] -= 1
                counters[ACC_REFINE] = 2 * acc
                counters[ACC_CALM] = 0
                counters[ACC_REPEATS] += 1
                acc_growth[0] = growth
                status, done = REFINE, j
                pl, ev, wall_d, wall_u = sn.pl, sn.ev, sn.wall_d, sn.wall_u
                break
            acc_growth[0] = np.inf
            balance0 = balance
            counters[ACC_REFINE], counters[ACC_CALM] = after_accepted(growth, budget, acc,
                                                                      counters[ACC_CALM])
        active = _count_deck_step(counters, cc.refine_decay, ev)
        if sample_at[j]:
            record_row(rows[j], bc.mass, x, v, q, L, bc.inv_I, bc.gravity, ev.eel,
                       ledger_of(exact, initial), ev.monitored, active, ev.degenerated, wall_d,
                       ev.force, ev.torque, wall_work_of(exact))
        if state_at[j]:
            states.append(_kept(j, x.copy(), q.copy(), v.copy(), L.copy(), wall_d.copy(), ev))
        c0 = cycles()
        stands = _step_control_ptr(bc, cc, ev, x, v, q, omega, wall_u, substeps, counters,
                                   estimate)
        counters[CONTROL_CYCLES] += cycles() - c0
        if not stands:
            status, done = CONTROL, j + 1
            break
        if counters[ACC_REFINE] != acc:
            status, done = RECOUNT, j + 1
            break
    return status, done, pl, ev, wall_d, wall_u, states


def _curved_provider(provider):
    """``provider`` when it is a mesh- and surface-wall provider
    (:class:`~nurbsdem.contact.curved_walls.CurvedWallContacts`) the compiled loop takes:
    exact spheres and NURBS particles with any of its walls, every wall at rest, turning at
    a constant rate (:class:`~nurbsdem.contact.curved_walls.WallPose`) or turned by a table
    (the provider that sets the table's spin hands over the one it wraps:
    :func:`~nurbsdem.dynamics.curved_turns.table_turns`); else None."""
    from ..contact.curved_walls import CurvedWallContacts, WallPose
    provider = getattr(provider, "inner", provider)
    if type(provider) is not CurvedWallContacts:
        return None
    if not all(isinstance(w.pose, WallPose) for w in provider.walls):
        return None
    return provider


# --------------------------------------------------------------------------- the Python side
class DeckSteps:
    """Compiled deck steps of a :class:`~nurbsdem.dynamics.system.DemSystem` whose contact
    provider is a :class:`~nurbsdem.contact.scene.SceneContacts` (see the module docstring);
    :meth:`for_system` says whether a system qualifies."""

    def __init__(self, system, scene, curved=None) -> None:
        import numba
        self.system, self.scene = system, scene
        s = system
        W = s.walls.n
        self.curved, self.cwork = pack_curved(curved, W, scene.table)
        self.provider = curved
        if scene.cell is not None:
            fill_lazy_kernels("periodic")    # the periodic cell's kernels
        if curved is not None:
            fill_lazy_kernels("curved")      # the mesh and surface walls' kernels
        kinds = set(self.curved.kind.tolist())
        if self.curved.n_nurbs and SURFACE_WALL in kinds:
            fill_lazy_kernels("surface_particles")
        if self.curved.n_nurbs and MESH_WALL in kinds:
            fill_lazy_kernels("mesh_particles")
        self.spin = (np.zeros((W, 6)) if s.wall_spin is None
                     else np.ascontiguousarray(s.wall_spin, float))
        self.sc = SceneConst(scene.tables(), scene.n, scene.radius, scene.skin, scene.margin,
                             scene.certificates, s.needs_radius, scene.table.tab[:7],
                             np.ascontiguousarray(scene.table.info[:, 0], np.int64),
                             scene.body_shape, np.ascontiguousarray(scene.sphere_radius),
                             np.ones(scene.n, np.bool_), numba.get_num_threads(),
                             bool(scene.is_sphere.all()), W - self.curved.n_walls,
                             periodic_const(scene.cell))
        self.bc = s._bc

    @staticmethod
    def for_system(system) -> "DeckSteps | None":
        """The compiled stepper when the provider is a scene on one rank, in a periodic cell
        or not (:mod:`.periodic_steps`), that has been called once (any contact law: the Hertz
        radii of NURBS contacts come from the curvature kernel the Python path calls,
        :func:`_hertz_radii`; a law registered at run time through the contact part's copy
        whose dispatch includes it, :meth:`_loop`), or such a scene without a periodic
        cell with mesh and surface walls (met by exact spheres and NURBS particles), at rest,
        turning at constant rates or turned by tables (:func:`_curved_provider`); else
        None."""
        from ..contact.scene import SceneContacts
        scene, curved = system.provider, _curved_provider(system.provider)
        if curved is not None:
            scene = curved.base
        if (not isinstance(scene, SceneContacts) or scene.n == 0 or scene.domain is not None
                or (scene.cell is not None      # the image bodies' kicks: walls at rest
                    and (curved is not None or system.wall_spin is not None))
                or scene.prev_pose is None or scene.built_pose is None):
            return None
        return DeckSteps(system, scene, curved)

    def _wall_tables(self, n_deck: int, n_sub: int) -> tuple[np.ndarray, ...]:
        """(n_deck·n_sub, W, 3) wall displacements and velocities at the ends of the internal
        steps, at the times the Python path uses: t_start + Δt·k/n, and those times (s)."""
        s = self.system
        j = np.repeat(np.arange(n_deck), n_sub)             # the same operations, on arrays
        k = np.tile(np.arange(1, n_sub + 1), n_deck)
        times = s.t0 + (s.step_count + j) * s.dt + s.dt * k / n_sub
        return (*s.walls.kinematics_at(times), np.ascontiguousarray(times, float))

    def _pair_list(self) -> PairList:
        sc = self.scene
        ps = sc.pairs
        pos, R, wall, x = (np.ascontiguousarray(a, float) for a in sc.prev_pose)
        built_x, built_R, built_wall, built_pos = (np.ascontiguousarray(a, float)
                                                   for a in sc.built_pose)
        return PairList(ps.a, ps.b, ps.keys, ps.mask_a, ps.mask_b, ps.rows_f.copy(),
                        ps.rows_i.copy(), ps.budget.copy(), sc.odo, built_x, built_R,
                        built_wall, built_pos, pos, R, wall, x,
                        np.ascontiguousarray(sc.pair_shift, np.int64).reshape(-1, 3))

    def _evaluation(self) -> Evaluation:
        s, cs = self.system, self.scene.last
        pl = self.scene.pairs
        reach = self.scene.odo[pl.a] + self.scene.odo[pl.b]
        c = s.contacts
        K = c.a.shape[0]
        coeffs = c.coeffs if (c.coeffs.ndim == 2 and c.coeffs.shape[0] == K) \
            else np.ascontiguousarray(s._table[s._mat_all[c.a], s._mat_all[c.b]][:, :4])
        return Evaluation(c.a, c.b, c.point, c.normal, c.ftot, c.fdn, c.fdt, c.fet, c.fn, c.eel,
                          c.stick, c.key, coeffs, np.ascontiguousarray(c.radius, float),
                          int(getattr(s, "hertz_fallback", 0)), s.hist_keys,
                          s.hist_springs, s.force, s.torque, float(s.last_slip_work),
                          np.asarray(cs.near_a, np.int64), np.asarray(cs.near_b, np.int64),
                          np.ascontiguousarray(cs.near_point, float),
                          np.ascontiguousarray(cs.near_normal, float),
                          np.asarray(cs.near_gap, float), reach, int(cs.monitored),
                          int(cs.degenerated_count), np.ascontiguousarray(cs.depth, float),
                          np.ascontiguousarray(cs.degenerated, np.int64),
                          *stored_images(s, self.scene.cell, K, cs))

    def _control(self) -> Control:
        s = self.system
        heavy = np.iinfo(np.int64).max if s._warned_heavy else HEAVY_SUBSTEPS
        return Control(s.dt, REFINE_DECAY_STEPS, s.safety, s.dt_apriori,
                       s.forced_substeps is not None, NETWORK_RECHECK_STEPS, FALL_HYSTERESIS,
                       NETWORK_BOUND_SLACK,
                       s.energy_tolerance, s._scale_floor, s.check_energy, s.watch_period2,
                       s.implicit_damping, s.accuracy or 0.0, s.max_substeps, heavy)

    def _estimate(self) -> np.ndarray:
        """The time-step control's figures (DT_BOUND, DT_NETWORK, DT_CRITICAL; s), a copy,
        and room for those of an estimate the loop leaves to the caller (RATES_BOUND …;
        none: RATES_STEP −1)."""
        s = self.system
        out = np.full(ESTIMATE_SIZE, np.nan)
        out[DT_BOUND], out[DT_NETWORK], out[DT_CRITICAL] = s.dt_bound, s.dt_network, s.dt_critical
        out[RATES_STEP] = -1.0
        return out

    def load(self) -> None:
        """Load the compiled loop (numba's on-disk cache: 0.34 s for the 112-sphere scene,
        once per process) without stepping: :meth:`_loop` for 0 deck steps, which changes
        nothing.  The solver calls it with its set-up, so that the time loop's figures hold
        the loop alone."""
        s = self.system
        walls_d, walls_u, times = self._wall_tables(0, 1)
        counters = np.zeros(N_COUNTERS, np.int64)
        counters[ACC_REFINE] = 1            # the loop divides the deck step by the count
        self._loop(0, max(int(s.substeps), 1), walls_d, walls_u, counters,
                   np.array([s._peak]), np.array([s.acc_last_growth]), self._estimate(),
                   np.zeros(0, np.bool_), np.zeros((0, row_width(s.walls.n))),
                   np.zeros(0, np.bool_), times)

    def _loop(self, n_deck: int, substeps: int, walls_d, walls_u, counters, peak,
              acc_growth, estimate, sample_at, rows, state_at, times):
        """:func:`run_deck_steps` on the system's state (the one call of the loop, so that
        :meth:`load` and :meth:`run` pass the same argument types), with the contact part of
        the system's laws (the cached kernel, or the copy that dispatches to laws registered
        at run time as well: :func:`~nurbsdem.dynamics.laws.engine.engine_kernels`)."""
        s, b = self.system, self.system.bodies
        contact_part_kernel.redirect(s._kernels.contact_part)
        return run_deck_steps(
            n_deck, substeps, self.sc, self.bc, self._control(), self._pair_list(),
            self._evaluation(), b.x, b.v, b.q, b.L, s.wall_d, s.wall_u, walls_d, walls_u,
            s.exact_ledger, float(s.initial_mechanical), s.alt_prev_v, s.alt_prev_L, s.alt_count,
            counters, peak,
            acc_growth, estimate, sample_at, rows, state_at, times, self.curved, self.cwork,
            self.spin, table_turns(self.provider, self.curved, self.spin, times))

    def run(self, n_deck: int, sample_at: np.ndarray,
            state_at: np.ndarray | None = None) -> tuple[int, int, np.ndarray, np.ndarray, list]:
        """Up to n_deck deck steps; returns (status, deck steps done, counters, the monitor
        rows (n_deck, row_width(W)) of the deck steps ``sample_at`` (n_deck,) bool, the states
        kept at the deck steps ``state_at`` (n_deck,) bool (:func:`run_deck_steps`)).  On
        GUARD the system and scene are left in an undefined state: the caller restores them."""
        s = self.system
        walls_d, walls_u, times = self._wall_tables(n_deck, s.substeps * s.acc_refine)
        counters = np.zeros(N_COUNTERS, np.int64)
        counters[STEP_COUNT], counters[REFINE], counters[CALM] = s.step_count, s.refine, s.calm_steps
        counters[ACC_REFINE], counters[ACC_CALM] = s.acc_refine, s.acc_calm
        peak = np.array([s._peak])
        acc_growth = np.array([s.acc_last_growth])
        estimate = self._estimate()
        sample_at = np.ascontiguousarray(sample_at[:n_deck], np.bool_)
        state_at = (np.zeros(n_deck, np.bool_) if state_at is None
                    else np.ascontiguousarray(state_at[:n_deck], np.bool_))
        rows = np.zeros((n_deck, row_width(s.walls.n)))
        status, done, pl, ev, wall_d, wall_u, states = self._loop(
            n_deck, s.substeps, walls_d, walls_u, counters, peak, acc_growth, estimate,
            sample_at, rows, state_at, times)
        if status == GUARD:
            return status, done, counters, rows, []
        if s.wall_spin is not None and s.wall_spin is not self.spin:
            s.wall_spin[:] = self.spin          # a table's spin at the last evaluation
        self._store(pl, ev, wall_d, wall_u, counters, peak)
        s.acc_last_growth = float(acc_growth[0])
        s.dt_bound, s.dt_network, s.dt_critical = (float(e) for e in estimate[:RATES_BOUND])
        s.network_estimates += int(counters[NETWORK_ESTIMATES])
        if status == CONTROL and estimate[RATES_STEP] == s.step_count:
            s.loop_rates = (s.step_count, float(estimate[RATES_BOUND]),
                            float(estimate[RATES_OMEGA2]), float(estimate[RATES_GAMMA]),
                            int(estimate[RATES_BODY]))
        return status, done, counters, rows, states

    def _store(self, pl, ev, wall_d, wall_u, counters, peak) -> None:
        """Write the loop's results back into the system and the scene."""
        from ..contact.scene import _PairState
        s, sc = self.system, self.scene
        sc.pairs = _PairState(pl.a, pl.b, pl.keys, pl.mask_a, pl.mask_b, pl.rows_f, pl.rows_i,
                              pl.budget, np.zeros(pl.a.shape[0], bool))
        if sc.cell is not None:
            sc.pair_shift = pl.shift
        sc.odo, sc.built_pose = pl.odo, (pl.built_x, pl.built_R, pl.built_wall, pl.built_pos)
        sc.prev_pose = (pl.prev_pos, pl.prev_R, pl.prev_wall, pl.prev_x)
        sc.builds += int(counters[BUILDS])
        sc.timers.calls += int(counters[EVALS])
        sc.timers.lcps += int(counters[MONITORED])
        sc.point_solves += int(counters[POINT_SOLVES])
        sc.timers.global_search += float(counters[SEARCH_CYCLES]) * seconds_per_cycle()
        sc.timers.lcp += float(counters[ROW_CYCLES]) * seconds_per_cycle()
        curved = int(self.cwork.count[0]) if self.curved.n_walls else 0
        sc.last = sc.contact_set(ev.reach, monitored=int(ev.monitored) - curved)
        s.last_contacts = with_curved_contacts(sc.last, self.cwork) if curved else sc.last
        s.contacts = contacts_of(ev)
        if self.sc.hertz:
            s.hertz_fallback = int(ev.fallback)
        s.hist_keys, s.hist_springs = ev.hist_keys, ev.hist_springs
        s.force, s.torque, s.last_slip_work = ev.force, ev.torque, ev.slip
        s.wall_d, s.wall_u = wall_d, wall_u
        s.step_count, s.refine, s.calm_steps = (int(counters[i]) for i in (STEP_COUNT, REFINE, CALM))
        s.acc_refine, s.acc_calm = int(counters[ACC_REFINE]), int(counters[ACC_CALM])
        s.accuracy_repeats += int(counters[ACC_REPEATS])
        s._peak = float(peak[0])
        s.failed_in_step = 0
        s.dashpot_solves += counters[DASHPOT_SOLVES:DASHPOT_SOLVES + 3]
        s.split["implicit dashpots"] += float(counters[DASHPOT_CYCLES]) * seconds_per_cycle()
        s.split["time-step control"] += float(counters[CONTROL_CYCLES]) * seconds_per_cycle()
        s.split["integration"] += float(counters[INTEGRATION_CYCLES]) * seconds_per_cycle()
        s.split["contact forces"] += float(counters[FORCES_CYCLES]) * seconds_per_cycle()

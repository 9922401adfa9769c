"""The internal step of the DEM engine, compiled, in the parts both of its drivers call.

One internal step of length h (s) (velocity Verlet on the bodies' centroids and angular
momenta, paper §2.3; the rotation is the exact free rotation of
:mod:`nurbsdem.dynamics.integrator`):

1. :func:`step_start`: the half kick from the stored loads with the exact discrete work of its
   contact impulses (booked in the energy ledger), the period-2 watch of the half-step
   velocities (:func:`~nurbsdem.dynamics.stepcontrol.alternation_update`) and the drift;
2. the contact search at the new poses: the scene's compiled search inside the compiled deck
   steps (:mod:`nurbsdem.dynamics.deck_steps`), or a contact provider called from Python
   (:mod:`nurbsdem.dynamics.internal_step`: several MPI ranks, turning walls, other providers);
3. :func:`contact_part`: the contact forces of the active contacts (paper Eq. 16–17 or
   Hertz–Mindlin, :mod:`nurbsdem.dynamics.laws`) with their tangential histories, the implicit
   normal dashpots with ``Damping Implicit`` (:mod:`nurbsdem.dynamics.implicit`), and gravity;
4. :func:`kick_part`: the second half kick, with its work.

Both drivers call these parts with the same arrays, so a run gives the same bits whichever
drives it (tested).  Units: SI; global body indices particles 0..N-1, walls N..N+W-1; the
parts book the energy ledger's entries and the walls' work in their exact sums only
(:data:`EXACT_WALLS`, :mod:`.exact_sum`): the ledger's array
(:meth:`~nurbsdem.dynamics.energy.EnergyLedger.to_array`) and the walls' work are read from
them where they are needed (:func:`ledger_of`, :func:`wall_work_of`).
"""
from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit

from ..geometry.rotation import quats_to_matrices
from ..jit import PointerKernel, cycles
from .exact_sum import exact_add, exact_normalize_all, exact_value
from .forces import EXACT_WALLS, add_kick_work, contact_loads, match_history
from .implicit import dashpots_of_evaluation
from .integrator import drift, kick_from
from .rigid import omega_world
from .stepcontrol import alternation_update

#: constants of the bodies and the contact laws: masses (N,) kg and their inverses, 1/I (N,3)
#: principal, the pose data (P, centroid in the file frame), the particles' sizes ell (N,) m,
#: 1/m of every body (walls 0), materials (B,), the interface table, gravity (3,) m/s² and its
#: norm, the period-2 watch's floors, √m and √I
BodyConst = namedtuple("BodyConst", "mass inv_mass inv_I P centroid ell inv_mass_all material "
                       "table gravity g_norm alt_floor_x alt_floor_L sq_m sq_I")

#: entries of the ledger array (J)
L_DISS_N, L_DISS_T, L_SPRING, L_EXTERNAL, L_INITIAL = range(5)


@njit(cache=True)
def book_kick(terms, a, b, n_particles, counted, exact) -> None:
    """Book a half kick's work terms (K, N_TERMS) of the contacts ``counted`` (K,) bool (empty:
    all) exactly in the accumulators ``exact``
    (:func:`~nurbsdem.dynamics.forces.add_kick_work`), normalised after."""
    if a.shape[0] == 0:
        return
    add_kick_work(terms, a, b, n_particles, counted, exact)
    exact_normalize_all(exact)


@njit(cache=True)
def ledger_of(exact, initial: float):
    """The ledger's array (5,) J: the entries L_DISS_N … L_EXTERNAL read from their exact
    accumulators (:data:`EXACT_WALLS`), then the initial mechanical energy ``initial`` (J;
    NaN before it is taken)."""
    ledger = np.empty(5)
    for k in range(EXACT_WALLS):
        ledger[k] = exact_value(exact, k)
    ledger[L_INITIAL] = initial
    return ledger


@njit(cache=True)
def wall_work_of(exact):
    """The walls' work (W,) J read from their exact accumulators (the rows after
    :data:`EXACT_WALLS`)."""
    work = np.empty(exact.shape[0] - EXACT_WALLS)
    for w in range(work.shape[0]):
        work[w] = exact_value(exact, EXACT_WALLS + w)
    return work


@njit(cache=True)
def book_terms(exact, row, amounts) -> None:
    """Book the amounts (n,) J exactly in accumulator ``row`` (the accumulators normalised
    after)."""
    for k in range(amounts.shape[0]):
        exact_add(exact, row, amounts[k])
    exact_normalize_all(exact)


@njit(cache=True)
def kick_part(bc, a, b, point, ftot, fdn, fdt, fet, force, torque, x, v, q, L, omega, body_b,
              wall_d, u_mean, wall_w, hk, exact, counted):
    """Half kick of length hk (s) from the loads force, torque (B,3) of the contacts a, b
    (their per-contact arrays: point, total, damping and tangential elastic forces (K,3)),
    from the angular velocities omega (N,3) rad/s of the state before it.  body_b (K,): the
    body B of each contact as the work terms see it (a turning wall's contacts each have a
    wall index of their own, moving at wall_d, u_mean (m, m/s) of that index and turning at
    wall_w (rad/s), :func:`spun_contacts`).  The work of the contacts ``counted`` (K,) bool
    (empty: all; several MPI ranks: each its own, :meth:`Domain.counted
    <nurbsdem.parallel.domain.Domain.counted>`) is booked exactly in ``exact``
    (:func:`book_kick`).  Returns the angular velocities after the kick."""
    terms, omega_after = kick_from(omega, v, L, x, q, bc.inv_I, bc.inv_mass, force, torque, hk,
                                   a, body_b, point, wall_d, u_mean, wall_w, ftot, fdn, fdt,
                                   fet)
    book_kick(terms, a, b, x.shape[0], counted, exact)
    return omega_after


@njit(cache=True)
def step_start(bc, a, b, point, ftot, fdn, fdt, fet, force, torque, x, v, q, L, omega, body_b,
               wall_d, u_mean, wall_w, h, exact, counted, alt_prev_v,
               alt_prev_L, alt_count, watch):
    """Parts 1 of the internal step (module docstring): the half kick (:func:`kick_part`), the
    period-2 watch (with ``watch``) and the drift by h (s).  Returns (the angular velocities
    after the drift, the particle with the longest run of reversals or −1, and that run's
    length: the caller's guard fires at
    :data:`~nurbsdem.dynamics.stepcontrol.ALTERNATION_STEPS`)."""
    omega = kick_part(bc, a, b, point, ftot, fdn, fdt, fet, force, torque, x, v, q, L, omega,
                      body_b, wall_d, u_mean, wall_w, 0.5 * h, exact, counted)
    worst, run = -1, 0
    if watch and x.shape[0]:
        worst = alternation_update(v, L, alt_prev_v, alt_prev_L, alt_count, bc.alt_floor_x,
                                   bc.alt_floor_L, 1.0 / h)
        if worst >= 0:
            run = alt_count[worst]
    drift(x, v, q, L, bc.inv_I, h)
    return omega_world(q, L, bc.inv_I), worst, run


@njit(cache=True)
def interfaces_defined(bc, a: np.ndarray, b: np.ndarray) -> bool:
    """Whether every contact's pair of materials has a contact interface."""
    for c in range(a.shape[0]):
        if np.isnan(bc.table[bc.material[a[c]], bc.material[b[c]], 0]):
            return False
    return True


@njit(cache=True)
def all_kinematics(x, v, omega, wall_d, wall_u):
    """Positions, velocities and angular velocities (B,3) of the particles then the walls
    (walls that do not turn)."""
    W = wall_d.shape[0]
    return (np.concatenate((x, wall_d)), np.concatenate((v, wall_u)),
            np.concatenate((omega, np.zeros((W, 3)))))


@njit(cache=True)
def spun_contacts(a, b, point, n: int, spin, wall_d, u_mean):
    """(body_b, wall_d, u_mean, wall_w) for a half kick's work terms with turning walls: each
    contact with a turning wall gets a wall of its own (index W + j) moving at that wall's
    point velocity u + ω × (p − c − d) at the contact point p and turning at its ω (wall_w,
    rad/s, the rolling torque's work: :func:`~nurbsdem.dynamics.forces.add_rolling_work`)
    (``spin`` (W,6): ω rad/s, c m; both drivers call it)."""
    W = wall_d.shape[0]
    wall_w = np.empty((W, 3))
    wall_w[:] = spin[:, :3]
    turning = np.zeros(b.shape[0], np.bool_)
    count = 0
    for c in range(b.shape[0]):
        w = b[c] - n
        if w >= 0 and (spin[w, 0] != 0.0 or spin[w, 1] != 0.0 or spin[w, 2] != 0.0):
            turning[c] = True
            count += 1
    if count == 0:
        return b, wall_d, u_mean, wall_w
    body_b = b.copy()
    d_out = np.empty((W + count, 3))
    u_out = np.empty((W + count, 3))
    w_out = np.empty((W + count, 3))
    d_out[:W] = wall_d
    u_out[:W] = u_mean
    w_out[:W] = wall_w
    j = 0
    for c in range(b.shape[0]):
        if not turning[c]:
            continue
        w = b[c] - n
        arm0 = point[c, 0] - spin[w, 3] - wall_d[w, 0]
        arm1 = point[c, 1] - spin[w, 4] - wall_d[w, 1]
        arm2 = point[c, 2] - spin[w, 5] - wall_d[w, 2]
        d_out[W + j] = wall_d[w]
        w_out[W + j] = wall_w[w]
        u_out[W + j, 0] = u_mean[w, 0] + (spin[w, 1] * arm2 - spin[w, 2] * arm1)
        u_out[W + j, 1] = u_mean[w, 1] + (spin[w, 2] * arm0 - spin[w, 0] * arm2)
        u_out[W + j, 2] = u_mean[w, 2] + (spin[w, 0] * arm1 - spin[w, 1] * arm0)
        body_b[c] = n + W + j
        j += 1
    return body_b, d_out, u_out, w_out


@njit(cache=True)
def stored_history(key: np.ndarray, spring: np.ndarray):
    """The tangential springs (K,3) of the contacts by ascending key: (keys, springs, whether
    a key repeats).  Keys already ascending (a scene's) are copied as they are."""
    ascending, repeated = True, False
    for c in range(1, key.shape[0]):
        if key[c] < key[c - 1]:
            ascending = False
        elif key[c] == key[c - 1]:
            repeated = True
    if ascending:
        return key.copy(), spring.copy(), repeated
    order = np.argsort(key, kind="mergesort")
    k = key[order]
    for c in range(1, k.shape[0]):
        if k[c] == k[c - 1]:
            repeated = True
    return k, spring[order], repeated


@njit(cache=True)
def contact_part(bc, implicit, a, b, pa, pb, nrm, dep, key, radius, hist_keys, hist_springs,
                 pos_all, vel_all, omg_all, q, L, h, solves, dashpot, own):
    """Part 3 of the internal step (module docstring) for the active contacts a, b (their
    surface points pa, pb, normals, depths and keys; Hertz–Mindlin radii, zeros for linear
    laws), from the stored springs (hist_keys ascending, hist_springs) and the kinematics of
    all bodies (:func:`all_kinematics`).  With ``implicit`` and h > 0 the normal dashpots are
    solved implicitly first; their solves, active-set rounds, CG iterations and cycles are
    added to ``solves`` (4,) int64; ``dashpot`` (K,) N gives them instead (solved over the
    whole network by the MPI ranks together: :meth:`~nurbsdem.parallel.domain.Domain.
    implicit_dashpots`; empty: solved here); ``own`` (G,): the owners of the last G
    particles, images in a periodic cell (empty: none; the dashpot solve takes an image as its
    owner, :func:`~nurbsdem.dynamics.implicit.implicit_dashpots`).  Returns (force, torque
    (B,3), point, f_total, f_damp_n, f_damp_t, f_el_t (K,3), fn (K,), e_el (K,2), stick (K,),
    coeffs (K,4), slip work J, the stored springs' keys and springs, whether a key
    repeats)."""
    spring = match_history(hist_keys, hist_springs, key)
    given = implicit and h > 0.0 and a.shape[0] > 0
    if given and dashpot.shape[0] != a.shape[0]:
        c0 = cycles()
        dashpot, rounds, iterations = dashpots_of_evaluation(
            a, b, pa, pb, nrm, dep, pos_all, vel_all, omg_all, bc.material, bc.table, spring, h,
            bc.inv_mass_all, radius, bc.mass, bc.gravity, q, L, bc.inv_I,
            quats_to_matrices(q), bc.sq_m, bc.sq_I, own)
        solves[0] += 1
        solves[1] += rounds
        solves[2] += iterations
        solves[3] += cycles() - c0
    force, torque, point, ftot, fdn, fdt, fet, fn, eel, stick, coeffs, slip = contact_loads(
        a, b, pa, pb, nrm, dep, pos_all, vel_all, omg_all, bc.material, bc.table, spring, h,
        bc.inv_mass_all, radius, bc.mass, bc.gravity, given, dashpot)
    keys, springs, repeated = stored_history(key, spring)
    return (force, torque, point, ftot, fdn, fdt, fet, fn, eel, stick, coeffs, slip, keys,
            springs, repeated)


#: the parts compiled once and called by the compiled deck steps through pointers
#: (:class:`~nurbsdem.jit.PointerKernel`): the loop does not compile them again
step_start_ptr = PointerKernel(step_start, "step_start").call
kick_part_ptr = PointerKernel(kick_part, "kick_part").call
#: the contact part's pointer kernel, which :meth:`~nurbsdem.jit.PointerKernel.redirect`
#: points at the copy whose dispatch includes laws registered at run time
contact_part_kernel = PointerKernel(contact_part, "contact_part")
contact_part_ptr = contact_part_kernel.call

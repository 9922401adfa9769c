"""Penalty contact forces (paper Eq. 16–17) over the K contacts of a ContactSet.

Conventions (docs/conventions.md): ``normal`` n is the unit normal from A towards B, ``depth``
d >= 0 the penetration.  The force acts at the contact point ``p = (point_a + point_b) / 2`` (the
midpoint of the two surface points: symmetric in A and B, and the points differ by only d·n).
``F`` below is the force on **B**; A receives ``-F``.  Torques are about each centroid (Eq. 16
applied at p): ``tau_B += (p - x_B) × F``, ``tau_A -= (p - x_A) × F``.

Relative velocity of B with respect to A at p:
``w = (v_B + ω_B × (p - x_B)) - (v_A + ω_A × (p - x_A))``; the approach (depth) rate is
``ḋ = -n·w`` and the tangential velocity ``w_t = w - (n·w) n``.

Normal force (Eq. 16)::

    f_n = εn d + cn ḋ,        clipped at 0 (no tension): f_n = max(f_n, 0)

The clip is a choice: a dashpot may not glue separating bodies.  While the clip is active the
elastic part εn d is cancelled by the damper, whose dissipation is then (f_n − εn d) ḋ >= 0.  The
damped-oscillator verification compares with the linear damped oscillator *with the force
clipped at 0* (tests/test_dynamics_contact.py).

Tangential force (Eq. 17) with an elastic spring with history ``s`` (the tangential relative
displacement accumulated while the contact persists).  Each evaluation (time increment h):

1. rotate the previous spring into the current tangent plane, keeping its length:
   ``s' = |s| (s - (s·n)n) / |s - (s·n)n|``;
2. trial ``s* = s' + h w_t``; trial force on B ``f_t* = -εt s* - ct w_t``;
3. Coulomb return mapping: stick when ``|f_t*| <= μ f_n`` (f_t = f_t*, s = s*); otherwise slip:
   ``α = μ f_n / |f_t*|``, ``f_t = α f_t*`` and the spring is scaled the same way, ``s = α s*``
   (so ``|f_t| = μ f_n`` exactly and the force stays on the Coulomb cone).

Friction dissipation (energy ledger) is *not* estimated from the return mapping: it is the exact
discrete work done on the tangential springs by the relative motion (:func:`kick_work_terms`) minus the
tangential elastic energy still stored, so it includes slip and the spring energy lost when a
contact ends with a loaded spring, and adds no error of its own to the energy balance.

History is keyed by ``ContactSet.key``: a new contact starts with s = 0, a contact absent from
the set drops its history (:func:`match_history`).  A contact's history row also holds its
rolling spring (:mod:`nurbsdem.dynamics.rolling`: the rolling resistance of an interface with
``RollingFriction``, whose torque enters the loads with the forces').

Contact laws are per interface: a dense table with one row per pair of materials
(:mod:`nurbsdem.dynamics.laws.table`); the kernel dispatches on the row's law
(:mod:`nurbsdem.dynamics.laws`: the linear penalty law above, Hertz–Mindlin) for the normal
force, the stiffnesses and the normal elastic energy, and applies the common tangential part.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..jit import ROW_CHUNK, THREADED_ROWS, n_chunks
from .exact_sum import exact_add
from .laws import law_normal, law_spring_scale
from .laws.linear_penalty import LinearPenalty
from .laws.table import MU, RD, RF, InterfaceTable
from .rolling import NSPRING, ROLL, no_rolling, rolling_geometry, rolling_result, spring_in_plane

#: the linear penalty law (:class:`~nurbsdem.dynamics.laws.linear_penalty.LinearPenalty`)
ContactLaw = LinearPenalty

__all__ = ["ContactLaw", "InterfaceTable", "contact_forces", "contact_loads", "match_history",
           "store_history", "kick_work_terms", "add_kick_work", "add_rolling_work", "wall_loads"]


@njit(cache=True)
def match_history(prev_keys: np.ndarray, prev_springs: np.ndarray, keys: np.ndarray) -> np.ndarray:
    """Springs (K, S) for the current contacts: the stored one for a persisting key, 0 for a
    new one (S the stored springs' width: :data:`~nurbsdem.dynamics.rolling.NSPRING` in the
    engine, the tangential spring then the rolling one).

    prev_keys must be sorted ascending (as stored by :func:`store_history`).  Current keys in
    ascending order (as the scene gives them: its pairs are sorted by key) are matched by one
    merge of the two lists, others by a binary search each.
    """
    k = keys.shape[0]
    width = prev_springs.shape[1]
    out = np.zeros((k, width))
    m = prev_keys.shape[0]
    if k == 0 or m == 0:
        return out
    if _ascending(keys):
        j = 0
        for c in range(k):
            while j < m and prev_keys[j] < keys[c]:
                j += 1
            if j < m and prev_keys[j] == keys[c]:
                for d in range(width):
                    out[c, d] = prev_springs[j, d]
        return out
    for c in range(k):
        j = min(np.searchsorted(prev_keys, keys[c]), m - 1)
        if prev_keys[j] == keys[c]:
            for d in range(width):
                out[c, d] = prev_springs[j, d]
    return out


@njit(cache=True)
def _ascending(keys: np.ndarray) -> bool:
    """Whether the keys are in non-decreasing order."""
    for c in range(1, keys.shape[0]):
        if keys[c] < keys[c - 1]:
            return False
    return True


def store_history(keys: np.ndarray, springs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sorted copy (keys, springs) of the current contacts' springs; ended contacts are dropped
    simply by not being in ``keys``.  Raises ValueError on duplicate keys (one contact per pair)."""
    order = np.argsort(keys, kind="stable")
    k = keys[order]
    if k.shape[0] > 1 and np.any(k[1:] == k[:-1]):
        raise ValueError("ContactSet has duplicate keys: one contact per body pair expected")
    return k.copy(), springs[order].copy()


@njit(cache=True)
def _cross(a0, a1, a2, b0, b1, b2):
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True, inline="always")
def _contact_start(c, body_a, body_b, point_a, point_b, normal, pos, vel, omg, point):
    """The kinematics of contact c: its point p (written to point[c]), its normal n and the
    relative velocity w of B with respect to A at p (module docstring).  Returns (n, w, n·w)
    as scalars."""
    a = body_a[c]
    b = body_b[c]
    n0, n1, n2 = normal[c, 0], normal[c, 1], normal[c, 2]
    p0 = 0.5 * (point_a[c, 0] + point_b[c, 0])
    p1 = 0.5 * (point_a[c, 1] + point_b[c, 1])
    p2 = 0.5 * (point_a[c, 2] + point_b[c, 2])
    point[c, 0], point[c, 1], point[c, 2] = p0, p1, p2
    ra0, ra1, ra2 = p0 - pos[a, 0], p1 - pos[a, 1], p2 - pos[a, 2]
    rb0, rb1, rb2 = p0 - pos[b, 0], p1 - pos[b, 1], p2 - pos[b, 2]
    wa0, wa1, wa2 = _cross(omg[a, 0], omg[a, 1], omg[a, 2], ra0, ra1, ra2)
    wb0, wb1, wb2 = _cross(omg[b, 0], omg[b, 1], omg[b, 2], rb0, rb1, rb2)
    w0 = vel[b, 0] + wb0 - vel[a, 0] - wa0
    w1 = vel[b, 1] + wb1 - vel[a, 1] - wa1
    w2 = vel[b, 2] + wb2 - vel[a, 2] - wa2
    wn = w0 * n0 + w1 * n1 + w2 * n2
    return n0, n1, n2, w0, w1, w2, wn


@njit(cache=True, inline="always")
def _rotated_spring(spring, c, n0, n1, n2):
    """Step 1 of the tangential force: the stored spring of contact c rotated into the
    current tangent plane, keeping its length."""
    return spring_in_plane(spring, c, 0, n0, n1, n2)


@njit(cache=True)
def _contact_laws_range(body_a, body_b, point_a, point_b, normal, depth, pos, vel, omg,
                        material, table, spring, h, inv_mass, radius, point, f_total, f_damp_n,
                        f_damp_t, f_el_t, fn_out, e_el, stick, coeffs, dashpot_given, dashpot,
                        slip_out, lo: int, hi: int) -> None:
    """The contact laws of contacts lo .. hi-1 (:func:`contact_forces`): their per-contact
    outputs, springs and slip-work estimates slip_out (J, 0 where they stick).  Reads the
    bodies, writes those rows only.  Per contact: the kinematics (:func:`_contact_start`), the
    law of its row (:func:`~nurbsdem.dynamics.laws.law_normal`,
    :func:`~nurbsdem.dynamics.laws.law_spring_scale`), then the part common to all laws: the
    clip, the spring, the Coulomb return mapping and the results, and the rolling spring
    (:mod:`nurbsdem.dynamics.rolling`) where the row has a rolling friction and the arrays
    its columns."""
    for c in range(lo, hi):
        a = body_a[c]
        b = body_b[c]
        ma, mb = material[a], material[b]     # the law table[ma, mb] read in place (no view)
        n0, n1, n2, w0, w1, w2, wn = _contact_start(c, body_a, body_b, point_a, point_b,
                                                    normal, pos, vel, omg, point)
        d = depth[c]
        ddot = -wn
        kn, cn, et, ct, fel, eel_n = law_normal(table, ma, mb, d, radius[c],
                                                inv_mass[a] + inv_mass[b])
        coeffs[c, 0], coeffs[c, 1], coeffs[c, 2], coeffs[c, 3] = kn, cn, et, ct
        fn = fel + (dashpot[c] if dashpot_given else cn * ddot)
        if fn < 0.0:
            fn = 0.0
        s0, s1, s2 = _rotated_spring(spring, c, n0, n1, n2)
        scaled, sc = law_spring_scale(table, ma, mb, d, ddot, h, radius[c])
        if scaled:
            s0, s1, s2 = s0 * sc, s1 * sc, s2 * sc
        wt0, wt1, wt2 = w0 - wn * n0, w1 - wn * n1, w2 - wn * n2
        s0, s1, s2 = s0 + h * wt0, s1 + h * wt1, s2 + h * wt2
        _tangential_result(c, table[ma, mb, MU], fn, fn - fel, eel_n, et, ct, n0, n1, n2,
                           s0, s1, s2, wt0, wt1, wt2, spring, f_total, f_damp_n, f_damp_t,
                           f_el_t, fn_out, e_el, stick, slip_out)
        mu_r = table[ma, mb, RF]
        if mu_r > 0.0 and spring.shape[1] >= NSPRING and f_el_t.shape[1] >= NSPRING:
            r_roll, i_roll = rolling_geometry(c, radius[c], a, b, point_a, point_b, pos,
                                              inv_mass)
            rolling_result(c, mu_r, table[ma, mb, RD], kn, fn, r_roll, i_roll, n0, n1, n2, a,
                           b, omg, h, spring, f_el_t, e_el)
        else:
            no_rolling(c, spring, f_el_t)


@njit(cache=True, inline="always")
def _tangential_result(c, mu, fn, fdn, eel_n, et, ct, n0, n1, n2, s0, s1, s2, wt0, wt1, wt2,
                       spring, f_total, f_damp_n, f_damp_t, f_el_t, fn_out, e_el, stick,
                       slip_out):
    """Steps 2–3 of the tangential force of contact c (trial force of the incremented spring
    s and the dashpot, Coulomb return mapping) and its results: the new spring, the total,
    normal-dissipative, tangential-dissipative and tangential-elastic forces on B, f_n, the
    elastic energies (the normal one ``eel_n`` from the law), stick and the slip work."""
    fe0, fe1, fe2 = -et * s0, -et * s1, -et * s2
    fd0, fd1, fd2 = -ct * wt0, -ct * wt1, -ct * wt2
    ft0, ft1, ft2 = fe0 + fd0, fe1 + fd1, fe2 + fd2
    ftm = math.sqrt(ft0 * ft0 + ft1 * ft1 + ft2 * ft2)
    flim = mu * fn
    slip = 0.0
    sliding = ftm > flim
    if sliding:
        alpha = flim / ftm if ftm > 0.0 else 0.0
        smag2 = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
        slip = et * alpha * smag2 * (1.0 - alpha) * smag2
        s0, s1, s2 = alpha * s0, alpha * s1, alpha * s2
        fd0, fd1, fd2 = alpha * fd0, alpha * fd1, alpha * fd2
        fe0, fe1, fe2 = alpha * fe0, alpha * fe1, alpha * fe2
        ft0, ft1, ft2 = alpha * ft0, alpha * ft1, alpha * ft2
    spring[c, 0], spring[c, 1], spring[c, 2] = s0, s1, s2
    f_total[c, 0], f_total[c, 1], f_total[c, 2] = fn * n0 + ft0, fn * n1 + ft1, fn * n2 + ft2
    f_damp_n[c, 0], f_damp_n[c, 1], f_damp_n[c, 2] = fdn * n0, fdn * n1, fdn * n2
    f_damp_t[c, 0], f_damp_t[c, 1], f_damp_t[c, 2] = fd0, fd1, fd2
    f_el_t[c, 0], f_el_t[c, 1], f_el_t[c, 2] = fe0, fe1, fe2
    fn_out[c] = fn
    e_el[c, 0] = eel_n
    e_el[c, 1] = 0.5 * et * (s0 * s0 + s1 * s1 + s2 * s2)
    slip_out[c] = slip
    # one store, after the branch: a store inside it made the compiled loop several times slower
    stick[c] = 0 if sliding else 1


@njit(cache=True, inline="always")
def _add_rolling_torque(c, a, b, f_el_t, torque) -> None:
    """Add contact c's rolling torque (f_el_t[c, 3:6], N m on B; −it on A) to the torques,
    where the array has the column and the torque is not zero (a zero adds nothing, not even
    the sign of a zero)."""
    if f_el_t.shape[1] < NSPRING:
        return
    m0, m1, m2 = f_el_t[c, ROLL], f_el_t[c, ROLL + 1], f_el_t[c, ROLL + 2]
    if m0 == 0.0 and m1 == 0.0 and m2 == 0.0:
        return
    torque[b, 0] += m0
    torque[b, 1] += m1
    torque[b, 2] += m2
    if a >= 0:
        torque[a, 0] -= m0
        torque[a, 1] -= m1
        torque[a, 2] -= m2


@njit(cache=True)
def _any_rolling_torque(f_el_t: np.ndarray) -> bool:
    """Whether a contact has a rolling torque that is not zero (f_el_t's columns 3–5, where
    the array has them)."""
    if f_el_t.shape[1] < NSPRING:
        return False
    for c in range(f_el_t.shape[0]):
        for k in range(ROLL, NSPRING):
            if f_el_t[c, k] != 0.0:
                return True
    return False


@njit(cache=True)
def _add_contact_loads(body_a: np.ndarray, body_b: np.ndarray, pos: np.ndarray,
                       point: np.ndarray, f_total: np.ndarray, f_el_t: np.ndarray,
                       force: np.ndarray, torque: np.ndarray) -> None:
    """Add each contact's force f_total (K,3) on B (−it on A) at its point, and its rolling
    torque (f_el_t's columns 3–5, :mod:`nurbsdem.dynamics.rolling`), to the loads (B,3) of its
    bodies, in contact order: the accumulation of :func:`contact_forces`.  (On one
    thread: split into ranges of bodies, each adding from the contacts that touch it, it was
    1.7 x slower on 2.4e5 contacts of 1e5 bodies, the contacts' rows read out of order.)
    The rolling torques' test runs only when a contact has one: the loop without it runs
    several times faster, and the sums are the same."""
    rolling = _any_rolling_torque(f_el_t)
    for c in range(body_a.shape[0]):
        a = body_a[c]
        b = body_b[c]
        p0, p1, p2 = point[c, 0], point[c, 1], point[c, 2]
        ra0, ra1, ra2 = p0 - pos[a, 0], p1 - pos[a, 1], p2 - pos[a, 2]
        rb0, rb1, rb2 = p0 - pos[b, 0], p1 - pos[b, 1], p2 - pos[b, 2]
        F0, F1, F2 = f_total[c, 0], f_total[c, 1], f_total[c, 2]
        force[b, 0] += F0
        force[b, 1] += F1
        force[b, 2] += F2
        force[a, 0] -= F0
        force[a, 1] -= F1
        force[a, 2] -= F2
        tb0, tb1, tb2 = _cross(rb0, rb1, rb2, F0, F1, F2)
        ta0, ta1, ta2 = _cross(ra0, ra1, ra2, F0, F1, F2)
        torque[b, 0] += tb0
        torque[b, 1] += tb1
        torque[b, 2] += tb2
        torque[a, 0] -= ta0
        torque[a, 1] -= ta1
        torque[a, 2] -= ta2
        if rolling:
            _add_rolling_torque(c, a, b, f_el_t, torque)


@njit(cache=True, parallel=True)
def _contact_laws_threads(body_a, body_b, point_a, point_b, normal, depth, pos, vel, omg,
                          material, table, spring, h, inv_mass, radius, point, f_total,
                          f_damp_n, f_damp_t, f_el_t, fn_out, e_el, stick, coeffs,
                          dashpot_given, dashpot, slip_out) -> None:
    n = body_a.shape[0]
    for t in prange(n_chunks(n)):
        _contact_laws_range(body_a, body_b, point_a, point_b, normal, depth, pos, vel, omg,
                            material, table, spring, h, inv_mass, radius, point, f_total,
                            f_damp_n, f_damp_t, f_el_t, fn_out, e_el, stick, coeffs,
                            dashpot_given, dashpot, slip_out, t * ROW_CHUNK,
                            min(n, (t + 1) * ROW_CHUNK))


@njit(cache=True)
def contact_forces(body_a, body_b, point_a, point_b, normal, depth, pos, vel, omg, material,
                      table, spring, h, inv_mass, radius, force, torque, point, f_total, f_damp_n,
                      f_damp_t, f_el_t, fn_out, e_el, stick, coeffs, dashpot_given,
                      dashpot) -> float:
    """Evaluate the contact law of each of K contacts and accumulate loads on the bodies:
    each row's law (:mod:`nurbsdem.dynamics.laws`: Eq. 16–17 of the module docstring for the
    linear penalty law, Hertz–Mindlin).

    Inputs (B = N particles + W walls): pos/vel/omg (B,3) centroid (wall: displacement), velocity,
    angular velocity; material (B,) ids; table (M,M,NCOL); spring (K,S) history from the previous
    evaluation (updated **in place** to the new spring; S = 6 with the rolling spring,
    :mod:`nurbsdem.dynamics.rolling`); h (s) the time since that evaluation
    (0 for the initial evaluation: no spring increment); inv_mass (B,) 1/kg (walls 0) and radius
    (K,) the equivalent contact radius (m), both used by the laws that need them (Hertz).

    Outputs: force/torque (B,3) are *added to*; per contact: point (K,3) application point,
    f_total (K,3) force on B, f_damp_n / f_damp_t (K,3) its normal/tangential dissipative parts
    (normal: (f_n − elastic) n, includes the clip), f_el_t (K,3) its tangential elastic (spring)
    part ((K,6): then the rolling torque on B (N m) in columns 3–5), fn_out (K,) f_n (N), e_el
    (K,2) normal and tangential elastic energies (J; the tangential one includes the rolling
    spring's), stick (K,)
    1 stick / 0 slip, coeffs (K,4) (k_n, c_n, k_t, c_t): the tangent stiffnesses (N/m) and
    damping (N s/m) for the time-step control.  Returns the return mapping's slip-work estimate
    (J) (a diagnostic; the energy ledger uses the exact spring work instead).

    dashpot_given: the normal dashpot force of contact c is dashpot[c] (N, along n on B; the
    implicit dashpots of :mod:`nurbsdem.dynamics.implicit`) instead of cn ġn from vel/omg.

    From :data:`~nurbsdem.jit.THREADED_ROWS` contacts the laws run on threads by chunks of
    contacts; the loads are added in contact order on the calling thread (the same bits).
    """
    K = body_a.shape[0]
    slip = np.empty(K)
    if K >= THREADED_ROWS:
        _contact_laws_threads(body_a, body_b, point_a, point_b, normal, depth, pos, vel, omg,
                              material, table, spring, h, inv_mass, radius, point, f_total,
                              f_damp_n, f_damp_t, f_el_t, fn_out, e_el, stick, coeffs,
                              dashpot_given, dashpot, slip)
    else:
        _contact_laws_range(body_a, body_b, point_a, point_b, normal, depth, pos, vel, omg,
                            material, table, spring, h, inv_mass, radius, point, f_total,
                            f_damp_n, f_damp_t, f_el_t, fn_out, e_el, stick, coeffs,
                            dashpot_given, dashpot, slip, np.int64(0), K)
    _add_contact_loads(body_a, body_b, pos, point, f_total, f_el_t, force, torque)
    slip_work = 0.0
    for c in range(K):
        slip_work += slip[c]
    return slip_work


@njit(cache=True)
def contact_loads(body_a, body_b, point_a, point_b, normal, depth, pos, vel, omg, material,
                  table, spring, h, inv_mass, radius, mass, gravity, dashpot_given,
                  dashpot):
    """:func:`contact_forces` of K contacts into fresh arrays, plus gravity on the N particles
    (mass (N,) kg, gravity (3,) m/s²; bodies ≥ N are walls): the loads of one force
    evaluation (dashpot_given, dashpot: as for contact_forces).  Returns (force, torque (B,3),
    point, f_total, f_damp_n, f_damp_t (K,3), f_el_t (K,6), fn (K,), e_el (K,2), stick (K,),
    coeffs (K,4), slip work)."""
    K = body_a.shape[0]
    B = pos.shape[0]
    force = np.zeros((B, 3))
    torque = np.zeros((B, 3))
    point, f_total = np.empty((K, 3)), np.empty((K, 3))
    f_damp_n, f_damp_t, f_el_t = np.empty((K, 3)), np.empty((K, 3)), np.empty((K, NSPRING))
    fn, e_el, stick = np.empty(K), np.empty((K, 2)), np.empty(K, np.int64)
    coeffs = np.empty((K, 4))
    slip = contact_forces(body_a, body_b, point_a, point_b, normal, depth, pos, vel, omg,
                          material, table, spring, h, inv_mass, radius, force, torque, point,
                          f_total, f_damp_n, f_damp_t, f_el_t, fn, e_el, stick, coeffs,
                          dashpot_given, dashpot)
    for i in range(mass.shape[0]):
        for k in range(3):
            force[i, k] += mass[i] * gravity[k]
    return (force, torque, point, f_total, f_damp_n, f_damp_t, f_el_t, fn, e_el, stick, coeffs,
            slip)


#: columns of the per-contact terms of one half-kick's work (:func:`kick_work_terms`)
T_DAMP_N, T_DAMP_T, T_SPRING, T_WALL_A, T_WALL_B, N_TERMS = 0, 1, 2, 3, 4, 5
#: the energy ledger's exact accumulators (:mod:`.exact_sum`, an array (EXACT_WALLS + W,
#: WIDTH)): rows 0 … 3 the ledger's entries (``L_DISS_N`` … ``L_EXTERNAL`` of
#: :mod:`.step`), then each wall's work from this row on
EXACT_WALLS = 4


@njit(cache=True)
def _work_range(body_a, body_b, n_particles, w_before, w_after, wall_vel, f_total, f_damp_n,
                f_damp_t, f_el_t, hk, out, lo: int, hi: int) -> None:
    """:func:`kick_work_terms` of contacts lo .. hi-1 (those rows of out)."""
    for c in range(lo, hi):
        m0 = 0.5 * (w_before[c, 0] + w_after[c, 0])
        m1 = 0.5 * (w_before[c, 1] + w_after[c, 1])
        m2 = 0.5 * (w_before[c, 2] + w_after[c, 2])
        out[c, T_DAMP_N] = hk * (f_damp_n[c, 0] * m0 + f_damp_n[c, 1] * m1
                                 + f_damp_n[c, 2] * m2)
        out[c, T_DAMP_T] = hk * (f_damp_t[c, 0] * m0 + f_damp_t[c, 1] * m1
                                 + f_damp_t[c, 2] * m2)
        out[c, T_SPRING] = hk * (f_el_t[c, 0] * m0 + f_el_t[c, 1] * m1 + f_el_t[c, 2] * m2)
        a = body_a[c]
        b = body_b[c]
        if a >= n_particles:   # wall A pushes B with F: work on the particles F·u_A
            k = a - n_particles
            out[c, T_WALL_A] = hk * (f_total[c, 0] * wall_vel[k, 0]
                                     + f_total[c, 1] * wall_vel[k, 1]
                                     + f_total[c, 2] * wall_vel[k, 2])
        if b >= n_particles:   # wall B pushes A with -F
            k = b - n_particles
            out[c, T_WALL_B] = -hk * (f_total[c, 0] * wall_vel[k, 0]
                                      + f_total[c, 1] * wall_vel[k, 1]
                                      + f_total[c, 2] * wall_vel[k, 2])


@njit(cache=True, parallel=True)
def _work_threads(body_a, body_b, n_particles, w_before, w_after, wall_vel, f_total, f_damp_n,
                  f_damp_t, f_el_t, hk, out) -> None:
    n = body_a.shape[0]
    for t in prange(n_chunks(n)):
        _work_range(body_a, body_b, n_particles, w_before, w_after, wall_vel, f_total,
                    f_damp_n, f_damp_t, f_el_t, hk, out, t * ROW_CHUNK,
                    min(n, (t + 1) * ROW_CHUNK))


@njit(cache=True)
def kick_work_terms(body_a: np.ndarray, body_b: np.ndarray, n_particles: int,
                    w_before: np.ndarray, w_after: np.ndarray, wall_vel: np.ndarray,
                    f_total: np.ndarray, f_damp_n: np.ndarray, f_damp_t: np.ndarray,
                    f_el_t: np.ndarray, hk: float) -> np.ndarray:
    """Per-contact terms (K, N_TERMS) J of the exact discrete work of one half-kick (length
    hk, s): a kick changes velocities linearly at fixed positions, so the kinetic energy change
    due to an impulse J at a contact equals J · (mean of the relative contact velocities before
    and after).  Columns: T_DAMP_N, T_DAMP_T normal and tangential damping (the dissipation is
    minus them), T_SPRING work on the tangential spring (minus it), T_WALL_A / T_WALL_B the work
    done by a wall that is body A / body B (the wall velocity enters through the relative
    velocity; its share J·u is external work), 0 for a particle.  On threads from
    :data:`~nurbsdem.jit.THREADED_ROWS` contacts (the same bits)."""
    K = body_a.shape[0]
    out = np.zeros((K, N_TERMS))
    if K >= THREADED_ROWS:
        _work_threads(body_a, body_b, n_particles, w_before, w_after, wall_vel, f_total,
                      f_damp_n, f_damp_t, f_el_t, hk, out)
        return out
    _work_range(body_a, body_b, n_particles, w_before, w_after, wall_vel, f_total, f_damp_n,
                f_damp_t, f_el_t, hk, out, np.int64(0), K)
    return out


@njit(cache=True)
def add_kick_work(terms: np.ndarray, body_a: np.ndarray, body_b: np.ndarray, n_particles: int,
                  counted: np.ndarray, exact: np.ndarray) -> None:
    """Add the terms of :func:`kick_work_terms` of the contacts ``counted`` (K,) bool (empty:
    all) exactly (:mod:`~nurbsdem.dynamics.exact_sum`) to the accumulators exact
    (:data:`EXACT_WALLS` + W, WIDTH): rows 0 the normal and 1 the tangential damping
    dissipation, 2 the work done on the tangential springs, 3 the external work by walls,
    then each wall's work (J).  The sums are exact, so their bits depend neither on the
    contacts' order nor on how ranks share them."""
    for c in range(terms.shape[0]):
        if counted.shape[0] and not counted[c]:
            continue
        exact_add(exact, 0, -terms[c, T_DAMP_N])
        exact_add(exact, 1, -terms[c, T_DAMP_T])
        exact_add(exact, 2, -terms[c, T_SPRING])
        if body_a[c] >= n_particles:
            exact_add(exact, 3, terms[c, T_WALL_A])
            exact_add(exact, EXACT_WALLS + body_a[c] - n_particles, terms[c, T_WALL_A])
        if body_b[c] >= n_particles:
            exact_add(exact, 3, terms[c, T_WALL_B])
            exact_add(exact, EXACT_WALLS + body_b[c] - n_particles, terms[c, T_WALL_B])


@njit(cache=True)
def add_rolling_work(body_a: np.ndarray, body_b: np.ndarray, n_particles: int,
                     omega: np.ndarray, omega_after: np.ndarray, f_el_t: np.ndarray, hk: float,
                     wall_w: np.ndarray, terms: np.ndarray) -> None:
    """Add to a half kick's terms (K, N_TERMS) the exact discrete work (J) of the contacts'
    rolling torques (f_el_t's columns 3–5, M N m on B, −M on A,
    :mod:`nurbsdem.dynamics.rolling`).  A kick at fixed orientation changes ω linearly in L,
    so with ω̄ the mean of a particle's angular velocities (N,3) rad/s before and after the
    kick, and ω_w the angular velocity of a wall (wall_w (W,3) rad/s, rows as body_b's wall
    indices), the torque's work on the rolling spring, in T_SPRING, is hk M·(ω_B − ω_A) (ω̄
    for a particle, ω_w for a wall), and a turning wall's drive does the external work
    −hk M·ω_w as body B (T_WALL_B), hk M·ω_w as body A (T_WALL_A): their sum is the kinetic
    energy the torque impulse gives the particles."""
    if f_el_t.shape[1] < NSPRING:
        return
    for c in range(body_a.shape[0]):
        m0, m1, m2 = f_el_t[c, ROLL], f_el_t[c, ROLL + 1], f_el_t[c, ROLL + 2]
        if m0 == 0.0 and m1 == 0.0 and m2 == 0.0:
            continue
        o0 = o1 = o2 = 0.0
        b = body_b[c]
        if b < n_particles:
            o0 += 0.5 * (omega[b, 0] + omega_after[b, 0])
            o1 += 0.5 * (omega[b, 1] + omega_after[b, 1])
            o2 += 0.5 * (omega[b, 2] + omega_after[b, 2])
        else:
            k = b - n_particles
            ww = m0 * wall_w[k, 0] + m1 * wall_w[k, 1] + m2 * wall_w[k, 2]
            o0, o1, o2 = o0 + wall_w[k, 0], o1 + wall_w[k, 1], o2 + wall_w[k, 2]
            terms[c, T_WALL_B] -= hk * ww
        a = body_a[c]
        if a < n_particles:
            o0 -= 0.5 * (omega[a, 0] + omega_after[a, 0])
            o1 -= 0.5 * (omega[a, 1] + omega_after[a, 1])
            o2 -= 0.5 * (omega[a, 2] + omega_after[a, 2])
        else:
            k = a - n_particles
            ww = m0 * wall_w[k, 0] + m1 * wall_w[k, 1] + m2 * wall_w[k, 2]
            o0, o1, o2 = o0 - wall_w[k, 0], o1 - wall_w[k, 1], o2 - wall_w[k, 2]
            terms[c, T_WALL_A] += hk * ww
        terms[c, T_SPRING] += hk * (m0 * o0 + m1 * o1 + m2 * o2)


@njit(cache=True)
def wall_loads(body_b: np.ndarray, point: np.ndarray, f_total: np.ndarray, f_el_t: np.ndarray,
               wall_d: np.ndarray, n_particles: int, force: np.ndarray,
               torque: np.ndarray) -> None:
    """Add to the rows of the walls (bodies >= n_particles) of force/torque (B,3) the loads of
    the contacts whose body B is a wall (point (K,3) application points m, f_total (K,3) N on
    B, f_el_t (K,3|6) whose columns 3–5 are the rolling torque on B, wall_d (W,3) wall
    displacements m), in contact order: the walls' part of the
    accumulation of :func:`contact_forces`, same bits (a domain decomposition assembles the
    walls' loads from the contacts of all ranks with it)."""
    rolling = _any_rolling_torque(f_el_t)      # as in :func:`_add_contact_loads`
    for c in range(body_b.shape[0]):
        b = body_b[c]
        if b < n_particles:
            continue
        k = b - n_particles
        p0, p1, p2 = point[c, 0], point[c, 1], point[c, 2]
        rb0, rb1, rb2 = p0 - wall_d[k, 0], p1 - wall_d[k, 1], p2 - wall_d[k, 2]
        F0, F1, F2 = f_total[c, 0], f_total[c, 1], f_total[c, 2]
        force[b, 0] += F0
        force[b, 1] += F1
        force[b, 2] += F2
        tb0, tb1, tb2 = _cross(rb0, rb1, rb2, F0, F1, F2)
        torque[b, 0] += tb0
        torque[b, 1] += tb1
        torque[b, 2] += tb2
        if rolling:
            _add_rolling_torque(c, np.int64(-1), b, f_el_t, torque)

"""The internal step's compiled parts (nurbsdem.dynamics.step), called directly: a free body
under gravity against the closed-form parabola, and the tangential histories' storage."""
from __future__ import annotations

import numpy as np

from nurbsdem.dynamics.exact_sum import exact_zeros
from nurbsdem.dynamics.step import (EXACT_WALLS, BodyConst, all_kinematics, contact_part,
                                    kick_part, ledger_of, step_start, stored_history)
from nurbsdem.jit import launch_threads

launch_threads()    # as DemSystem does before compiled work (nurbsdem.jit.launch_threads)


def _one_body(mass=2.0, inertia=(0.1, 0.2, 0.3), gravity=(0.0, 0.0, -9.81)):
    m = np.array([mass])
    I = np.array([inertia], float)
    table = np.zeros((1, 1, 16))
    return BodyConst(m, 1.0 / m, 1.0 / I, np.eye(3)[None], np.zeros((1, 3)), np.array([0.1]),
                     1.0 / m, np.zeros(1, np.int64), table, np.array(gravity, float),
                     float(np.linalg.norm(gravity)), np.array([1e-10]), np.array([1e-10]),
                     np.sqrt(m), np.sqrt(I))


def _no_contacts(B):
    e3, ei = np.zeros((0, 3)), np.zeros(0, np.int64)
    return ei, ei.copy(), e3, e3.copy(), e3.copy(), np.zeros(0), ei.copy()


def test_a_free_body_under_gravity_follows_the_parabola_and_books_no_work():
    """Kick-drift-kick is exact for a constant acceleration: after n internal steps the
    centroid is x0 + v0 t + g t²/2 and the velocity v0 + g t (round-off only), the spin is
    free rotation (|L| kept), and no contact work is booked."""
    bc = _one_body()
    x = np.array([[0.1, -0.2, 1.0]])
    v = np.array([[1.5, 0.5, 3.0]])
    q = np.array([[1.0, 0.0, 0.0, 0.0]])
    L = np.array([[0.03, -0.02, 0.05]])
    x0, v0, L0 = x.copy(), v.copy(), L.copy()
    exact = exact_zeros(EXACT_WALLS)
    every = np.zeros(0, np.bool_)
    alt_v, alt_L, alt_n = np.zeros((1, 3)), np.zeros((1, 3)), np.zeros(1, np.int64)
    no_walls = np.zeros((0, 3))
    a, b, pa, pb, nrm, dep, key = _no_contacts(1)
    keys, springs = np.zeros(0, np.int64), np.zeros((0, 3))
    h, n = 1e-3, 250
    force = np.array([bc.mass[0] * bc.gravity])
    torque = np.zeros((1, 3))
    e3 = np.zeros((0, 3))
    omega = np.zeros((1, 3))
    for _ in range(n):
        omega, worst, run = step_start(bc, a, b, e3, e3, e3, e3, e3, force, torque, x, v, q,
                                       L, omega, b, no_walls, no_walls, no_walls, h, exact,
                                       every, alt_v, alt_L, alt_n, True)
        pos, vel, omg = all_kinematics(x, v, omega, no_walls, no_walls)
        out = contact_part(bc, False, a, b, pa, pb, nrm, dep, key, np.zeros(0), keys, springs,
                           pos, vel, omg, q, L, h, np.zeros(4, np.int64), np.zeros(0),
                           np.zeros(0, np.int64))
        force, torque = out[0], out[1]
        omega = kick_part(bc, a, b, e3, e3, e3, e3, e3, force, torque, x, v, q, L, omega, b,
                          no_walls, no_walls, no_walls, 0.5 * h, exact, every)
    t = n * h
    g = bc.gravity
    np.testing.assert_allclose(x[0], x0[0] + v0[0] * t + 0.5 * g * t * t, rtol=0, atol=1e-12)
    np.testing.assert_allclose(v[0], v0[0] + g * t, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(L), np.linalg.norm(L0), rtol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(q), 1.0, rtol=1e-14)
    assert not ledger_of(exact, 0.0)[:4].any()
    assert worst == -1 or run < 2


def test_the_histories_are_stored_by_ascending_key_and_a_repeated_key_is_told():
    rng = np.random.default_rng(3)
    key = np.array([7, 3, 11, 5], np.int64)
    spring = rng.normal(size=(4, 3))
    k, s, repeated = stored_history(key, spring)
    order = np.argsort(key)
    np.testing.assert_array_equal(k, key[order])
    np.testing.assert_array_equal(s, spring[order])
    assert not repeated
    k, s, repeated = stored_history(np.sort(key), spring)
    np.testing.assert_array_equal(s, spring)        # already ascending: as it is
    assert not repeated
    assert stored_history(np.array([4, 2, 4], np.int64), spring[:3])[2]
    assert stored_history(np.array([2, 4, 4], np.int64), spring[:3])[2]

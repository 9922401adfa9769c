"""Implicit normal dashpots (nurbsdem.dynamics.implicit): the dashpot problem against a dense,
independent solution; the clipped law at the step's end velocity; stability beyond the
explicit limit; restitution against an ODE solution; the time-step control; energy balance and
restart; the deck's and the Python API's ``Damping``."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import minimize
from scipy.spatial.transform import Rotation

from nurbsdem.dynamics import (ContactLaw, DemSystem, InstabilityError, InterfaceTable,
                               SpherePlaneProvider, critical_step, sphere_inertia)
from nurbsdem.dynamics.implicit import lever_arms, normal_rows, solve_dashpots
from nurbsdem.dynamics.integrator import _relative_point_velocities
from nurbsdem.dynamics.rigid import omega_world

from test_dynamics_system import MASS, assert_restart_bit_for_bit, paper_box


# --------------------------------------------------------------------------- the QP (D1)
def _random_network(seed: int, n_bodies: int = 6, n_contacts: int = 14):
    """Bodies with random masses, principal moments and frames; contacts between random pairs
    (some with a wall, index >= N) with random points, normals, damping and loads."""
    rng = np.random.default_rng(seed)
    N = n_bodies
    mass = rng.uniform(0.05, 0.3, N)
    I = np.sort(rng.uniform(1e-5, 1e-4, (N, 3)), axis=1)
    Q = Rotation.random(N, random_state=seed).as_matrix()
    x = rng.uniform(-0.05, 0.05, (N, 3))
    a = rng.integers(0, N, n_contacts)
    b = (a + rng.integers(1, N + 1, n_contacts)) % (N + 1)   # N: a wall
    b = np.where(b == N, N, b)
    a, b = np.minimum(a, b), np.maximum(a, b)
    b = np.where(a == b, N, b).astype(np.int64)
    a = a.astype(np.int64)
    point = rng.uniform(-0.06, 0.06, (n_contacts, 3))
    normal = rng.normal(size=(n_contacts, 3))
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    cn = rng.uniform(20.0, 200.0, n_contacts)
    cn[::5] = 0.0                                  # contacts without a dashpot
    f_el = rng.uniform(0.0, 5.0, n_contacts)
    w0 = rng.normal(scale=0.3, size=n_contacts)
    return mass, I, Q, x, a, b, point, normal, cn, f_el, w0


def _dense_delassus(mass, I, Q, x, a, b, point, normal):
    """G = N M⁻¹ Nᵀ built row by row in world coordinates (independent of the kernels)."""
    N, K = mass.shape[0], a.shape[0]
    rows = np.zeros((K, 6 * N))
    for c in range(K):
        for body, sign in ((b[c], 1.0), (a[c], -1.0)):
            if body >= N:
                continue
            r = point[c] - x[body]
            rows[c, 6 * body:6 * body + 3] += sign * normal[c]
            rows[c, 6 * body + 3:6 * body + 6] += sign * np.cross(r, normal[c])
    minv = np.zeros((6 * N, 6 * N))
    for i in range(N):
        minv[6 * i:6 * i + 3, 6 * i:6 * i + 3] = np.eye(3) / mass[i]
        minv[6 * i + 3:6 * i + 6, 6 * i + 3:6 * i + 6] = Q[i] @ np.diag(1 / I[i]) @ Q[i].T
    return rows @ minv @ rows.T


@pytest.mark.parametrize("seed", range(6))
def test_dashpot_problem_matches_a_dense_solution(seed):
    mass, I, Q, x, a, b, point, normal, cn, f_el, w0 = _random_network(seed)
    h = 4e-4
    K = a.shape[0]
    r_a, r_b = np.empty((K, 3)), np.empty((K, 3))
    lever_arms(a, b, point, x, r_a, r_b)
    rows = np.empty((K, 2, 6))
    normal_rows(a, b, r_a, r_b, normal, Q, np.sqrt(mass), np.sqrt(I), rows)
    f = np.zeros(K)
    rounds, iterations = solve_dashpots(a, b, rows, mass.shape[0], cn, f_el, w0, h, f)
    assert rounds < 50 and iterations > 0
    assert np.all(f[cn == 0] == 0.0)
    on = cn > 0
    G = _dense_delassus(mass, I, Q, x, a, b, point, normal)[np.ix_(on, on)]
    A = np.diag(1 / cn[on]) + h * G
    lower = -f_el[on]
    # the unique minimiser of (D1), by a general bound-constrained optimiser
    res = minimize(lambda z: (0.5 * z @ A @ z + z @ w0[on], A @ z + w0[on]), np.zeros(on.sum()),
                   jac=True, method="L-BFGS-B", bounds=[(lo, None) for lo in lower],
                   options=dict(ftol=1e-15, gtol=1e-13, maxiter=10000))
    assert f[on] == pytest.approx(res.x, abs=1e-6 * np.abs(res.x).max())
    # and its KKT conditions to round-off: the clipped law
    mult = A @ f[on] + w0[on]
    at_bound = f[on] <= lower + 1e-12 * np.abs(lower).max()
    scale = np.abs(w0).max()
    assert np.all(f[on] >= lower)
    assert np.abs(mult[~at_bound]).max(initial=0) < 1e-9 * scale
    assert mult[at_bound].min(initial=0) > -1e-9 * scale
    assert at_bound.any() and (~at_bound).any()      # both kinds exercised


# --------------------------------------------------------------------------- in a system
def _box(implicit, substeps=None, law=ContactLaw(en=1e5, cn=1e2, et=1e4, ct=0.0, mu=0.5)):
    """Nine spheres with the paper's masses of C and A dropped into the paper's box."""
    return paper_box(substeps=substeps, n=9, law=law, kinds="CA", implicit=implicit)


def test_dashpots_follow_the_clipped_law_at_the_end_velocity():
    """After a step, each contact's dashpot force equals max(−f_el, −cn w(v⁺)) with v⁺ the
    velocities after the pending opening half kick (frictionless: the tangential loads do not
    move; a fixed sub-step h)."""
    s = _box(True, substeps=3, law=ContactLaw(en=1e5, cn=1e2, et=0.0, ct=0.0, mu=0.0))
    checked = clipped = 0
    for _ in range(400):
        s.step()
        K = s.contacts.a.shape[0]
        if not K:
            continue
        b = s.bodies
        hk = 0.5 * s.dt_internal
        v = b.v + hk * s.force[:b.n] / b.mass[:, None]
        L = b.L + hk * s.torque[:b.n]
        w = np.empty((K, 3))
        _relative_point_velocities(s.contacts.a, s.contacts.b, s.contacts.point, b.x, s.wall_d,
                                   v, omega_world(b.q, L, 1 / b.I), s.wall_u, w)
        wn = np.einsum("ij,ij->i", w, s.contacts.normal)
        f = np.einsum("ij,ij->i", s.contacts.fdn, s.contacts.normal)
        f_el = s.contacts.fn - f
        law = np.maximum(-f_el, -1e2 * wn)
        scale = 1e2 * np.abs(wn).max() + f_el.max()
        assert f == pytest.approx(law, abs=1e-9 * scale)
        checked += K
        clipped += int(np.sum(f <= -f_el))
    assert checked > 500 and clipped > 0


def _drop(implicit, c, substeps, dt=1e-3, m=0.1, r=0.02, k=1e5, v0=-1.0):
    law = ContactLaw(en=k, cn=c, et=0.0, ct=0.0, mu=0.0)
    s = DemSystem(dt=dt, gravity=(0, 0, 0), interfaces=InterfaceTable(default=law),
                  substeps=substeps, implicit_damping=implicit)
    s.add_particle(m, sphere_inertia(m, r), [0, 0, r], v=[0, 0, v0], radius=r)
    s.add_wall()
    s.set_contact_provider(SpherePlaneProvider([r], [([0, 0, 0], [0, 0, 1])]))
    return s


def _rebound_reference(m, r, k, c, v0):
    """The rebound velocity of the clipped spring–dashpot by an ODE solver."""
    def rhs(t, y):
        d, ddot = r - y[0], -y[1]
        return [y[1], max(0.0, k * d + c * ddot) / m]

    def leaves(t, y):
        return y[0] - r - 1e-9
    leaves.terminal, leaves.direction = True, 1
    sol = solve_ivp(rhs, (0, 1.0), [r, v0], events=leaves, rtol=1e-12, atol=1e-15,
                    method="DOP853")
    return sol.y_events[0][0][1]


def test_restitution_converges_to_the_ode_solution():
    m, r, k, c = 0.1, 0.02, 1e5, 60.0          # ζ = 0.3
    ref = _rebound_reference(m, r, k, c, -1.0)
    assert 0.3 < ref < 0.5
    errs = []
    for sub in (8, 16, 32, 64):
        s = _drop(True, c, sub)
        s.advance(20)
        assert s.bodies.x[0, 2] > r               # it has left the wall
        errs.append(abs(s.bodies.v[0, 2] - ref))
    # first order, as the explicit scheme (the contact starts and ends between samples)
    assert errs[-1] < 1e-2 * ref
    assert all(e0 / e1 > 1.8 for e0, e1 in zip(errs, errs[1:]))


def test_stable_beyond_the_explicit_limit():
    """ζ = 5: the explicit step limit is 20 × shorter than 2/ω; one sub-step of 1e-3 s
    (h ω = 1) blows up explicitly, and settles implicitly on the static overlap mg/k."""
    m, r, k = 0.1, 0.02, 1e5
    c = 2 * 5.0 * math.sqrt(k * m)
    omega, zeta, dt_cr = critical_step(k, c, m)
    assert zeta == pytest.approx(5.0) and 1e-3 > 4 * dt_cr and 1e-3 * omega < 2
    for implicit in (False, True):
        law = ContactLaw(en=k, cn=c, et=1e4, ct=0.0, mu=0.5)
        s = DemSystem(dt=1e-3, interfaces=InterfaceTable(default=law), substeps=1,
                      implicit_damping=implicit)
        s.add_particle(m, sphere_inertia(m, r), [0, 0, r + 1e-3], v=[0, 0, -0.5], radius=r)
        s.add_wall()
        s.set_contact_provider(SpherePlaneProvider([r], [([0, 0, 0], [0, 0, 1])]))
        if not implicit:
            with pytest.raises(InstabilityError):
                s.advance(300)
            continue
        z = []
        for _ in range(300):
            s.step()
            z.append(s.bodies.x[0, 2])
        e = s.energy()
        first = int(np.argmax(np.array(z) < r))
        assert max(z[first:]) < r          # no rebound: the dashpot stops the impact
        assert r - s.bodies.x[0, 2] == pytest.approx(m * 9.81 / k, rel=1e-6)
        assert e.kinetic < 1e-12 and abs(e.balance_error) < 0.05 * e.dissipated   # h ω = 1


def test_step_control_leaves_the_implicit_dashpots_out():
    ex, im = _box(False), _box(True)
    ex.initialize()
    im.initialize()
    m_cc = MASS["C"] / 2
    assert im.dt_apriori == pytest.approx(critical_step(1e5, 0.0, m_cc)[2], rel=1e-9)
    assert ex.dt_apriori == pytest.approx(critical_step(1e5, 1e2, m_cc)[2], rel=1e-9)
    assert im.substeps < ex.substeps
    ex.advance(300)
    im.advance(300)
    assert im.contacts.a.shape[0] > 0 and im.substeps < ex.substeps


def test_energy_balance_and_restart_with_implicit_dashpots(tmp_path):
    law = ContactLaw(en=1e5, cn=1e2, et=1e4, ct=0.1, mu=0.5)
    ref = _box(True, law=law)
    e = ref.advance(500)
    assert ref.substeps == 2          # the explicit dashpots would need 5 (test_dynamics_system)
    assert np.isfinite(ref.bodies.x).all() and e.kinetic < 0.05 * e.initial_mechanical
    assert abs(e.balance_error) < 0.05 * e.dissipated
    assert ref.dashpot_solves[0] > 0
    assert_restart_bit_for_bit(lambda: _box(True, law=law), 250, tmp_path)


# --------------------------------------------------------------------------- deck and API
def test_deck_and_python_api_run_implicit_damping_alike(tmp_path):
    """``Damping Implicit`` in a deck and ``damping="implicit"`` in Python: the same model
    (also through Simulation.deck_text) and the same trajectory; not the explicit one."""
    from test_simulation import DECK, build_scene
    from nurbsdem.io.deck import parse_deck
    from nurbsdem.simulation import Simulation

    text = DECK.replace("Step 1 Dynamic Duration 0.04 TimeStep 1e-3",
                        "Step 1 Dynamic Duration 0.04 TimeStep 1e-3 Damping Implicit")
    text = text[:text.index("  Step 2")] + "Output\n  Directory results\n"
    deck = tmp_path / "case.inp"
    deck.write_text(text)
    assert parse_deck(deck).steps[0].damping == "implicit"
    from_deck = Simulation.from_deck(deck, output=tmp_path / "out")
    from_deck.run()
    py = build_scene()
    py.run_dynamic(duration=0.04, time_step=1e-3, damping="Implicit")
    assert "Damping Implicit" in py.deck_text
    np.testing.assert_array_equal(from_deck.positions, py.positions)
    ex = build_scene()
    ex.run_dynamic(duration=0.04, time_step=1e-3)
    assert not np.array_equal(ex.positions, py.positions)


def test_bench_damping_deck_puts_implicit_on_every_timed_step():
    import bench_damping
    from nurbsdem.io.deck import parse_deck

    path = bench_damping.DECK.parent / "_bench_damping_check.inp"
    try:
        path.write_text(bench_damping.deck_text("Implicit", quick=True))
        steps = parse_deck(path).steps
    finally:
        path.unlink(missing_ok=True)
    timed = [s for s in steps if s.duration_s > 0]
    assert len(timed) == 4 and all(s.damping == "implicit" for s in timed)
    assert sum(s.duration_s for s in timed) == pytest.approx(0.65)
    assert all(s.safety == 0.7 for s in timed)          # the shipped deck's
    try:
        path.write_text(bench_damping.deck_text("Implicit", True, 3e-5, safety=0.5))
        timed = [s for s in parse_deck(path).steps if s.duration_s > 0]
    finally:
        path.unlink(missing_ok=True)
    assert all(s.safety == 0.5 and s.accuracy == 3e-5 for s in timed) and len(timed) == 4


def test_lid_press_with_implicit_dashpots_matches_the_explicit_reference(tmp_path):
    """inputs/regression/lid_press.inp (three particles C pressed by a lid) with ``Damping
    Implicit``: a quasi-static press, so the lid's reaction follows the explicit reference
    curve, and the balance closes."""
    from nurbsdem.io.deck import parse_deck
    from nurbsdem.solver import Solver
    from test_regression_decks import DECKS, REFS, read_csv

    text = (DECKS / "lid_press.inp").read_text().replace("../shapes/", str(
        DECKS.parent / "shapes") + "/")
    deck = tmp_path / "lid_press.inp"
    deck.write_text(text.replace("TimeStep 1e-3", "TimeStep 1e-3 Damping Implicit"))
    summary = Solver(parse_deck(deck), output=tmp_path / "out", quiet=True).run()
    lid = read_csv(tmp_path / "out" / "monitors" / "wall_lid.csv")
    ref = read_csv(REFS / "lid_press" / "wall_lid.csv")
    np.testing.assert_array_equal(lid["time"], ref["time"])
    peak = np.abs(ref["reaction_z"]).max()
    assert peak > 10.0
    # the pressing and lifting (the lid moves): the reaction within 2 % of its peak
    moving = np.abs(ref["displacement_z"] - ref["displacement_z"][0]) > 0
    assert np.abs(lid["reaction_z"] - ref["reaction_z"])[moving].max() < 0.02 * peak
    e = read_csv(tmp_path / "out" / "monitors" / "energy.csv")
    assert abs(e["balance_error"][-1]) < 1e-3 * e["external_work"].max()
    assert summary.failed == 0

"""Time-step control that sees the contact network, the period-2 guard, and failed contact
problems that may act for one evaluation at most (nurbsdem.dynamics.stepcontrol, the system's
sub-stepping, the scene's failure policy)."""
from __future__ import annotations

import logging
import math

import numpy as np
import pytest

from nurbsdem.contact.scene import SceneContacts
from nurbsdem.dynamics import ContactLaw, DemSystem, InstabilityError, InterfaceTable, sphere_inertia
from nurbsdem.dynamics.stepcontrol import (alternation_update, count_stands, critical_step,
                                           critical_step_from_rates, needed_substeps,
                                           network_apply, network_count_stands, network_lanczos,
                                           network_gershgorin, network_rates, period2_amplitude, shape_compliance,
                                           surface_compliance)
from nurbsdem.errors import InputError
from nurbsdem.geometry.rotation import quats_to_matrices, random_quaternions
from nurbsdem.io.deck import parse_deck
from nurbsdem.lattice import fcc_sphere_block
from nurbsdem.shapes import ellipsoid, sphere

PAPER = ContactLaw(en=1e5, cn=1e2, et=1e4, ct=0.0, mu=0.5)
R_C = (3 * 21.29e-6 / (4 * math.pi)) ** (1 / 3)        # particle C's volume-equivalent radius
M_C = 2700 * 21.29e-6


# --------------------------------------------------------------------------- the operators
def dense_network(a, b, p, n, coef, x, Q, m, I):
    """Independent assembly of Σ Jᵀ D J (mass-scaled, principal-frame rotations) as a matrix."""
    N = x.shape[0]
    A = np.zeros((6 * N, 6 * N))
    for c in range(a.shape[0]):
        J = np.zeros((3, 6 * N))
        for body, sign in ((b[c], 1.0), (a[c], -1.0)):
            if body >= N:
                continue
            r = p[c] - x[body]
            rx = np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])
            J[:, 6 * body:6 * body + 3] = sign * np.eye(3) / math.sqrt(m[body])
            # displacement of p from a rotation theta_w = Q t: theta_w x r = -[r]x Q t
            J[:, 6 * body + 3:6 * body + 6] = sign * (-rx @ Q[body]) / np.sqrt(I[body])[None]
        D = coef[c, 0] * np.outer(n[c], n[c]) + coef[c, 1] * (np.eye(3) - np.outer(n[c], n[c]))
        A += J.T @ D @ J
    return A


def random_network(rng, N=5, K=9, W=2):
    x = rng.uniform(-0.1, 0.1, (N, 3))
    Q = quats_to_matrices(random_quaternions(rng, N))
    m = rng.uniform(0.01, 0.1, N)
    I = np.sort(rng.uniform(1e-6, 1e-5, (N, 3)), axis=1)
    a = rng.integers(0, N, K)
    b = (a + rng.integers(1, N + W, K)) % (N + W)
    a, b = np.minimum(a, b), np.maximum(a, b)
    p = rng.uniform(-0.1, 0.1, (K, 3))
    n = rng.normal(size=(K, 3))
    n /= np.linalg.norm(n, axis=1)[:, None]
    coef = rng.uniform(1e3, 1e5, (K, 2))
    return a, b, p, n, coef, x, Q, m, I


def test_network_operator_equals_an_independent_dense_assembly():
    rng = np.random.default_rng(4)
    for _ in range(5):
        a, b, p, n, coef, x, Q, m, I = random_network(rng)
        A = dense_network(a, b, p, n, coef, x, Q, m, I)
        y = rng.normal(size=6 * x.shape[0])
        z = network_apply(y, a, b, p, n, coef[:, 0].copy(), coef[:, 1].copy(), x, Q,
                          np.sqrt(m), np.sqrt(I))
        np.testing.assert_allclose(z, A @ y, rtol=1e-12, atol=1e-12 * np.abs(A @ y).max())
        lam, vec = network_lanczos(a, b, p, n, coef[:, 0].copy(), coef[:, 1].copy(), x, Q,
                                   np.sqrt(m), np.sqrt(I), 30, 1e-12)
        exact = np.linalg.eigvalsh(A)[-1]
        assert lam == pytest.approx(exact, rel=1e-10)
        # the Gershgorin bound is an upper bound (stiffness: normal coef[:,0], tangential [:,1])
        coeffs = np.stack([coef[:, 0], coef[:, 0], coef[:, 1], coef[:, 1]], axis=1)
        g_k, g_c = network_gershgorin(a, b, p, n, coeffs, x, Q, 1 / m, 1 / I)
        assert exact <= g_k * (1 + 1e-12) and g_c == pytest.approx(g_k, rel=1e-12)


def test_coarse_gershgorin_bounds_the_exact_one_and_the_gate_decides_as_the_exact_bound():
    """The coarse bound (largest inverse moment, no body frames) is never below the exact
    Gershgorin bound; for bodies with equal moments (spheres) it equals it (to its 1e-9
    inflation); the gate that tries it first decides as the exact bound does, case by case."""
    rng = np.random.default_rng(11)
    decided_by = {True: 0, False: 0}
    for trial in range(300):
        a, b, p, n, coef, x, Q, m, I = random_network(rng, N=6, K=12)
        if trial % 2:
            I = np.repeat(I[:, :1], 3, axis=1)           # spheres
        coeffs = np.stack([coef[:, 0], rng.uniform(0, 1e2, len(a)), coef[:, 1],
                           rng.uniform(0, 10, len(a))], axis=1)
        exact = network_gershgorin(a, b, p, n, coeffs, x, Q, 1 / m, 1 / I)
        coarse = network_gershgorin(a, b, p, n, coeffs, x, Q, 1 / m, 1 / I, True)
        assert coarse[0] >= exact[0] and coarse[1] >= exact[1]
        if trial % 2:
            assert coarse == pytest.approx(exact, rel=2e-9)
        bound = critical_step_from_rates(*exact)
        dt, safety, refine, substeps = 1e-3, 0.5, 1, int(rng.integers(1, 6))
        dt_bound = bound * rng.uniform(0.9, 1.1)
        need = needed_substeps(dt, safety * bound)
        want = count_stands(bound, dt_bound, 0.05, need, refine, substeps)
        got = network_count_stands(a, b, p, n, coeffs, x, Q, 1 / m, 1 / I, dt, safety,
                                   math.inf, dt_bound, 0.05, refine, substeps)
        assert got == want
        decided_by[bool(want)] += 1
    assert min(decided_by.values()) > 30        # both decisions are exercised


def test_one_pair_gives_the_pair_formula_and_off_centre_contacts_their_effective_mass():
    m, r = M_C, R_C
    I = np.full(3, 0.4 * m * r * r)
    x = np.array([[0.0, 0, 0], [2 * r, 0, 0]])
    Q = np.repeat(np.eye(3)[None], 2, axis=0)
    coeffs = np.array([[1e5, 1e2, 0.0, 0.0]])
    w2, gam, body = network_rates(np.array([0]), np.array([1]), np.array([[r, 0, 0]]),
                                  np.array([[1.0, 0, 0]]), coeffs, x, Q, np.full(2, m),
                                  np.tile(I, (2, 1)))
    assert w2 == pytest.approx(2e5 / m, rel=1e-12) and gam == pytest.approx(2e2 / m, rel=1e-12)
    dt = critical_step_from_rates(w2, gam)
    assert dt == pytest.approx(critical_step(1e5, 1e2, m / 2)[2], rel=1e-12)
    assert dt == pytest.approx(4.7e-4, rel=0.01)             # the paper's C–C pair
    # a box-like body on a wall, touching 3 cm off its centre: 1/m* = 1/m + d²/I_y
    I_box = np.array([[1e-5, 2e-5, 2.5e-5]])
    d = 0.03
    w2, _, _ = network_rates(np.array([0]), np.array([1]), np.array([[d, 0, -0.01]]),
                             np.array([[0, 0, -1.0]]), np.array([[1e5, 0, 0, 0]]),
                             np.zeros((1, 3)), np.eye(3)[None], np.array([m]), I_box)
    assert w2 == pytest.approx(1e5 * (1 / m + d * d / I_box[0, 1]), rel=1e-12)


def test_surface_compliance_of_exact_shapes():
    m, r = M_C, R_C
    g_n, g_t = shape_compliance(sphere(r), m, 0.4 * m * r * r * np.eye(3), np.zeros(3))
    assert g_n == pytest.approx(1 / m, rel=1e-9)               # central contacts
    assert g_t == pytest.approx(3.5 / m, rel=1e-9)             # 1/m + r²/I = (1 + 5/2)/m
    # a flat ellipsoid: against a dense sampling of the analytic surface (independent of NURBS)
    a, c = 0.03, 0.0003
    mass = 2700 * 4 / 3 * math.pi * a * a * c
    J = np.diag([mass * (a * a + c * c) / 5, mass * (a * a + c * c) / 5, mass * 2 * a * a / 5])
    th, ph = np.meshgrid(np.linspace(0, math.pi, 401), np.linspace(0, 2 * math.pi, 400))
    s = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1).reshape(-1, 3)
    pts = s * [a, a, c]
    nrm = s / [a, a, c]
    nrm /= np.linalg.norm(nrm, axis=1)[:, None]
    ref = surface_compliance(pts, nrm, mass, J)
    got = shape_compliance(ellipsoid(a, a, c), mass, J, np.zeros(3))
    assert got[0] == pytest.approx(ref[0], rel=0.02) and got[1] == pytest.approx(ref[1], rel=0.02)
    assert 1 / got[0] < mass / 4                 # an off-centre contact: far below the mass


# --------------------------------------------------------------------------- period-2 guard
def test_alternation_counts_only_sustained_reversals_above_round_off():
    N = 3
    prev_v, prev_L = np.zeros((N, 3)), np.zeros((N, 3))
    count = np.zeros(N, np.int64)
    floor = np.full(N, 1e-12)
    worst = -1
    for k in range(12):
        v = np.zeros((N, 3))
        v[0, 0] = (-1) ** k * 1e-3                  # period 2, constant amplitude
        v[1, 0] = (-1) ** k * 1e-3 * 0.8 ** k       # period 2 but decaying: a stable mode
        v[2, 0] = 1e-3 * math.cos(0.5 * k)          # a resolved oscillation
        worst = alternation_update(v, np.zeros((N, 3)), prev_v, prev_L, count, floor, floor, 1e3)
    assert worst == 0 and count.tolist() == [11, 0, 0]


# --------------------------------------------------------------------------- dense pack
def fcc_block(dt, substeps=None, watch=True, safety=0.5, implicit=False):
    return fcc_sphere_block(dt, substeps=substeps, watch_period2=watch, safety=safety,
                            implicit_damping=implicit)


@pytest.mark.parametrize("dt, safety, implicit", [
    (5e-4, 0.5, False), (1e-3, 0.5, False), (2e-3, 0.5, False),
    # a step's Safety 0.8 (the paper example's decks take 0.7), with either dashpots
    (1e-3, 0.8, False), (1e-3, 0.8, True)])
def test_a_dense_fcc_block_settles_without_period_two_motion(dt, safety, implicit):
    s, trace = fcc_block(dt, safety=safety, implicit=implicit)
    s.initialize()
    # the network is much stiffer than a pair (implicit dashpots: the springs alone)
    assert s.dt_network < s.dt_apriori / (1.5 if implicit else 2.5)
    for _ in range(int(round(0.03 / dt))):
        s.step()
    assert s.contacts.a.shape[0] > 300                        # still packed: 12 contacts inside
    assert s.dt_internal <= safety * s.dt_network * (1 + 1e-9)
    # and the sub-step count that this fraction of the limit needs, no more
    assert s.substeps == needed_substeps(dt, safety * min(s.dt_network, s.dt_apriori))
    assert s.refine == 1                               # the guard never had to step in
    # the pair step rattled by ~1e-6 m; what is left is the start's ringing (implicit
    # dashpots damp the highest modes less than the explicit ones: 1.5e-10 m at 0.5 too)
    assert period2_amplitude(trace) < (1e-9 if implicit else 1e-10)
    assert s.energy().kinetic < 1e-7


def test_the_pair_estimate_rattles_the_block_unseen_by_the_monitors():
    """What the issue saw (the test above can fail): at the pair estimate's 5 sub-steps and
    without the guard the block oscillates with period 2 while the full-step kinetic energy,
    what the monitors show, stays small."""
    s, trace = fcc_block(1e-3, substeps=5, watch=False)
    for _ in range(20):
        s.step()
    assert period2_amplitude(trace) > 1e-7
    assert s.energy().kinetic < 1e-4 * s.energy().elastic


def test_the_guard_catches_period_two_motion_and_refines_the_step(caplog):
    # forced to the pair estimate: stopped with a message that names the motion
    s, _ = fcc_block(1e-3, substeps=5)
    with pytest.raises(InstabilityError, match="period-2 motion of particle"):
        for _ in range(20):
            s.step()
    # an automatic control that misjudged the network: the guard refines and the block settles
    s, trace = fcc_block(1e-3)
    s.initialize()
    s.substeps, s.dt_internal = 5, 2e-4
    s._needed_substeps = lambda dt_safe: 5
    with caplog.at_level(logging.WARNING, logger="nurbsdem"):
        for _ in range(30):
            s.step()
    assert s.refine >= 2 and s.substeps >= 10
    assert any("period-2" in r.getMessage() for r in caplog.records)
    assert period2_amplitude(trace) < 1e-9


def test_substeps_rise_with_the_network_and_fall_when_it_loosens():
    s, _ = fcc_block(1e-3)
    s.initialize()
    dense = s.substeps
    s.contacts = s.contacts._replace(**{f: v[:0] for f, v in s.contacts._asdict().items()})
    s.last_contacts = None
    s._control_step()
    assert s.substeps < dense and s.substeps == math.ceil(1e-3 / (0.5 * s.dt_apriori))


# --------------------------------------------------------------------------- flat particles
def test_flat_ellipsoids_run_at_the_deck_time_step(tmp_path, caplog):
    """Two 100:1 ellipsoids dropped in the box at the deck's 1e-3 s (the pair estimate with the
    bounding radius chose 13 sub-steps and the run stopped at 0.07 s)."""
    from nurbsdem.io.deck import parse_deck
    from nurbsdem.solver import Solver
    deck = tmp_path / "flat.inp"
    deck.write_text("""Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2700
Shapes
  Shape 1 Ellipsoid SemiAxes 0.03 0.03 0.0003
Particles
  Particle 1 Shape 1 Material 1 Position 0.08 0.08 0.012 Rotation 0.3 0.2 0
  Particle 2 Shape 1 Material 1 Position 0.15 0.15 0.03 Rotation -0.2 0.4 0.1
Walls
  Box 1 Min 0 0 0 Max 0.25 0.25 0.25
Contact
  Interface 1 NormalPenalty 1e5 TangentialPenalty 1e4 NormalDamping 1e2 TangentialDamping 0 Friction 0.5
Steps
  Step 1 Dynamic Duration 0.1 TimeStep 1e-3
Output
  Directory out
  Monitors Every 0.001
""")
    with caplog.at_level(logging.WARNING, logger="nurbsdem"):
        summary = Solver(parse_deck(deck), output=tmp_path / "out", quiet=True).run()
    assert summary.simulated_time == pytest.approx(0.1) and summary.failed == 0
    # a warning the user can act on: heavily sub-stepped, because of the damping
    assert any("sub-stepped" in r.getMessage() and "damping limits it" in r.getMessage()
               and "Damping Implicit" in r.getMessage()
               for r in caplog.records)
    assert summary.active_max >= 1                     # they reached the floor
    assert abs(summary.balance_error) < 1e-3 * summary.balance_scale


# --------------------------------------------------------------------------- failed LCPs
def failing(monkeypatch, when):
    """Make the scene's particle LCPs fail while ``when()``: as the solve kernels leave a
    failed pair (:func:`~nurbsdem.contact.detect.kept_on_failure`), its previous row flagged
    failed, whatever the solve found."""
    import nurbsdem.contact.scene as scene_mod
    from nurbsdem.contact.lcp import I_FAIL

    real = scene_mod.solve_due

    def solve(st, list_a, list_b, mask_a, mask_b, rows_f, rows_i, due, *args):
        before_f, before_i = rows_f[due].copy(), rows_i[due].copy()
        points = real(st, list_a, list_b, mask_a, mask_b, rows_f, rows_i, due, *args)
        if when():
            particles = list_b[due] < st.n       # particle pairs (their cold retries too)
            pair = due[particles]
            rows_f[pair] = before_f[particles]
            rows_i[pair] = before_i[particles]
            rows_i[pair, I_FAIL] = 1
        return points
    monkeypatch.setattr(scene_mod, "solve_due", solve)


def test_a_failed_solve_keeps_its_previous_row_unless_within_the_nonconvexity():
    """kept_on_failure, after each pair's solve in the LCP and wall batches: a converged row
    stays; a failed one gets its previous row back, flagged failed; a failed valid one within
    the shapes' non-convexity heights (tol > 0) of touching is accepted as it is."""
    from nurbsdem.contact.detect import kept_on_failure
    from nurbsdem.contact.lcp import F_SD, I_FAIL, I_VALID, NF, NI
    prev_f, prev_i = np.full(NF, 7.0), np.full(NI, 3, np.int64)
    prev_i[I_FAIL] = 0
    res_f, res_i = np.zeros((3, NF)), np.zeros((3, NI), np.int64)
    res_f[:, F_SD] = [-1e-3, -1e-3, 2e-6]
    res_i[:, I_VALID] = 1
    res_i[1:, I_FAIL] = 1
    new_f, new_i = res_f.copy(), res_i.copy()
    for j in range(3):
        kept_on_failure(res_f, res_i, j, prev_f, prev_i, 5e-6)
    assert res_f[0].tobytes() == new_f[0].tobytes() and res_i[0].tobytes() == new_i[0].tobytes()
    np.testing.assert_array_equal(res_f[1], prev_f)
    assert res_i[1, I_FAIL] == 1 and (np.delete(res_i[1], I_FAIL) == 3).all()
    assert res_f[2].tobytes() == new_f[2].tobytes() and res_i[2, I_FAIL] == 0
    kept_on_failure(new_f, new_i, 2, prev_f, prev_i, 0.0)     # a convex pair: no tolerance
    np.testing.assert_array_equal(new_f[2], prev_f)
    assert new_i[2, I_FAIL] == 1


def two_spheres_kin(gap_x, r=0.02):
    from types import SimpleNamespace
    x = np.array([[0.1, 0.1, 0.1], [0.1 + 2 * r + gap_x, 0.1, 0.1]])
    return SimpleNamespace(x=x, R=np.repeat(np.eye(3)[None], 2, 0), pose_origin=x.copy(),
                           wall_displacement=np.zeros((0, 3)))


def test_a_failed_lcp_reuses_the_moved_solution_once_then_drops_the_pair(monkeypatch, caplog):
    r = 0.02
    # not exact spheres (those take closed forms): the extent along x is r all the same
    scene = SceneContacts([ellipsoid(r, r, 0.9 * r)], np.zeros(2, np.int64))
    fail = [False]
    failing(monkeypatch, lambda: fail[0])
    cs = scene(two_spheres_kin(-1e-4))
    assert cs.active == 1 and cs.depth[0] == pytest.approx(1e-4, abs=1e-12)
    fail[0] = True
    with caplog.at_level(logging.WARNING, logger="nurbsdem"):
        cs = scene(two_spheres_kin(-5e-5))          # B moved 50 µm away, the LCP fails
    assert cs.failed == 1 and cs.reused == 1 and cs.active == 1
    assert cs.depth[0] == pytest.approx(5e-5, abs=1e-12)   # the old solution moved with B
    np.testing.assert_allclose(cs.normal[0], [1, 0, 0], atol=1e-10)
    cs = scene(two_spheres_kin(-4e-5))               # fails again: left out
    assert cs.failed == 1 and cs.dropped == 1 and cs.active == 0
    msgs = [rec.getMessage() for rec in caplog.records]
    assert any("particles 0 and 1" in m and "moved rigidly" in m for m in msgs)
    assert any("left out of the force evaluation" in m for m in msgs)
    fail[0] = False
    cs = scene(two_spheres_kin(-4e-5))               # converges again (cold): back in
    assert cs.active == 1 and cs.failed == 0 and cs.depth[0] == pytest.approx(4e-5, abs=1e-12)


def test_a_failing_pair_never_pushes_for_more_than_one_evaluation(monkeypatch):
    """Two spheres pressed together; from the 5th force evaluation on, every LCP of the pair
    fails.  Before, the last good row (1e-4 m deep) kept pushing them apart for as long as the
    failures lasted."""
    r, m = 0.02, 0.1
    s = DemSystem(dt=1e-4, gravity=(0, 0, 0), interfaces=InterfaceTable(default=PAPER))
    s.add_particle(m, sphere_inertia(m, r), [0.1, 0.1, 0.1], radius=r)
    s.add_particle(m, sphere_inertia(m, r), [0.1 + 2 * r - 1e-4, 0.1, 0.1], radius=r)
    scene = SceneContacts([ellipsoid(r, r, 0.9 * r)], np.zeros(2, np.int64))
    calls = [0]
    failing(monkeypatch, lambda: calls[0] >= 5)
    pushing = []

    def provider(kin):
        calls[0] += 1
        cs = scene(kin)
        if calls[0] >= 5:
            pushing.append(cs.active)
        return cs
    s.set_contact_provider(provider)
    for _ in range(20):
        s.step()
    assert len(pushing) > 10 and sum(pushing) == 1 and pushing[0] == 1
    assert np.all(s.force == 0)


# --------------------------------------------------------------------------- a step's Safety
SPHERE_ON_FLOOR = """\
Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2700
Shapes
  Shape 1 Sphere Radius 0.02
Particles
  Particle 1 Shape 1 Material 1 Position 0.05 0.05 0.0201
Walls
  Box 1 Min 0 0 0 Max 0.1 0.1 0.1
Contact
  Interface 1 NormalPenalty 1e5 TangentialPenalty 1e4 NormalDamping 1e2 Friction 0.5
Steps
  Step 1 Dynamic Duration 0.02 TimeStep 1e-3{safety}
Output
  VTK Every 0.02
"""


def test_a_steps_safety_sets_the_fraction_of_the_stability_limit(tmp_path):
    """A sphere resting on the floor: with ``Safety 0.25`` the deck steps take about twice
    the internal steps of the default 0.5 (the count is a ceiling)."""
    from nurbsdem.solver import Solver
    internal = {}
    for f in (None, 0.25):
        deck = tmp_path / f"s{f}.inp"
        deck.write_text(SPHERE_ON_FLOOR.format(safety="" if f is None else f" Safety {f}"))
        model = parse_deck(deck)
        assert model.steps[0].safety == f
        internal[f] = Solver(model, output=tmp_path / f"out{f}", quiet=True).run().substeps
    assert 1.5 * internal[None] < internal[0.25] <= 2 * internal[None]


@pytest.mark.parametrize("line, message", [
    ("Safety 0", "Step 1: Safety must be > 0, got 0"),
    ("Safety 1", "Step 1: Safety 1 is out of range"),
    ("Safety fast", "Step 1: Safety"),
])
def test_a_bad_safety_is_one_line_naming_the_file_and_line(tmp_path, line, message):
    deck = tmp_path / "bad.inp"
    deck.write_text(SPHERE_ON_FLOOR.format(safety=" " + line))
    with pytest.raises(InputError) as info:
        parse_deck(deck)
    text = str(info.value)
    assert message in text and "bad.inp:14:" in text and "\n" not in text


def test_safety_belongs_to_timed_steps_and_the_python_api_writes_it(tmp_path):
    import nurbsdem
    deck = tmp_path / "replicate.inp"
    deck.write_text(SPHERE_ON_FLOOR.format(
        safety="\n  Step 2 Replicate Layers 2 Height 0.05 Safety 0.5"))
    with pytest.raises(InputError, match="Safety does not apply to a Replicate step"):
        parse_deck(deck)
    sim = nurbsdem.Simulation()
    sim.add_material(1, 2700)
    sim.add_interface(normal_penalty=1e5, normal_damping=1e2)
    sim.add_box((0, 0, 0), (0.1, 0.1, 0.1))
    sim.add_particle(nurbsdem.shapes.sphere(0.01), 1, (0.05, 0.05, 0.03))
    sim.run_dynamic(0.01, 1e-3, damping="implicit", safety=0.7)
    assert sim.model.steps[-1].safety == 0.7
    assert "Damping Implicit Safety 0.7" in sim.deck_text
    with pytest.raises(InputError, match="Safety must be > 0"):
        sim.run_dynamic(0.01, 1e-3, safety=0)

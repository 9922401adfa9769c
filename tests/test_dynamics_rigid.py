"""Rigid-body integrator: free fall (exact), torque-free asymmetric top (DLM), principal frame."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

from nurbsdem.dynamics import DemSystem, principal_frame
from nurbsdem.errors import InputError


def _random_rotation(seed: int) -> np.ndarray:
    return Rotation.random(random_state=seed).as_matrix()


def test_free_fall_exact_to_round_off():
    g = np.array([0.3, -0.2, -9.81])
    s = DemSystem(dt=1e-3, gravity=g)
    x0, v0 = np.array([0.1, 0.2, 3.0]), np.array([1.0, -0.5, 2.0])
    s.add_particle(0.7, np.diag([0.01, 0.02, 0.025]), x0, v=v0, omega=[0.1, 0.2, 0.3])
    s.advance(1000)
    t = s.time
    assert t == pytest.approx(1.0, abs=1e-15)
    x_ex = x0 + v0 * t + 0.5 * g * t * t
    v_ex = v0 + g * t
    assert np.max(np.abs(s.bodies.x[0] - x_ex)) < 1e-12
    assert np.max(np.abs(s.bodies.v[0] - v_ex)) < 1e-12
    e = s.energy()
    assert abs(e.balance_error) < 1e-12 * abs(e.initial_mechanical)


def _top(I, omega_body, dt, seed=1, R0=None):
    """System with one body, J0 given in a rotated file frame (tests the principal frame)."""
    P = _random_rotation(seed)
    J0 = P @ np.diag(I) @ P.T
    _, P = principal_frame(J0)      # the axes (and signs) the system will use
    s = DemSystem(dt=dt, gravity=(0, 0, 0))
    R0 = np.eye(3) if R0 is None else R0
    # omega given in principal axes: world omega = R0 P omega_body
    s.add_particle(1.0, J0, [0, 0, 0], R=R0, omega=R0 @ P @ np.asarray(omega_body, float))
    return s, P


def test_torque_free_asymmetric_top_conserves_energy_and_angular_momentum():
    I = (1.0, 2.0, 3.0)
    s, P = _top(I, (0.4, 0.6, 0.8), dt=1e-2)
    s.initialize()
    L0 = s.bodies.L[0].copy()
    e0 = s.energy().kinetic
    emax = 0.0
    for _ in range(100):
        s.advance(100)
        emax = max(emax, abs(s.energy().kinetic - e0) / e0)
    assert s.step_count == 10_000
    assert emax < 1e-6
    # angular momentum recomputed from the orientation and omega (not the stored L)
    Lw = s.bodies.world_inertia()[0] @ s.bodies.omega()[0]
    assert np.linalg.norm(Lw - L0) / np.linalg.norm(L0) < 1e-6
    Q = s.bodies.principal_rotations()[0]
    assert np.max(np.abs(Q @ Q.T - np.eye(3))) < 1e-12


def _euler_reference(I, omega0, T):
    """High-accuracy reference: Euler's equations + rotation matrix kinematics in the principal frame."""
    I = np.asarray(I, float)

    def rhs(t, y):
        w = y[:3]
        Q = y[3:].reshape(3, 3)
        dw = np.array([(I[1] - I[2]) * w[1] * w[2] / I[0], (I[2] - I[0]) * w[2] * w[0] / I[1],
                       (I[0] - I[1]) * w[0] * w[1] / I[2]])
        W = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
        return np.concatenate([dw, (Q @ W).ravel()])
    y0 = np.concatenate([omega0, np.eye(3).ravel()])
    sol = solve_ivp(rhs, (0, T), y0, method="DOP853", rtol=1e-12, atol=1e-12)
    return sol.y[3:, -1].reshape(3, 3)


def test_top_orientation_matches_reference_second_order():
    I, w0, T = (1.0, 2.0, 3.0), np.array([0.4, 0.6, 0.8]), 4.0
    Qref = _euler_reference(I, w0, T)
    errs = []
    for dt in (4e-3, 2e-3):
        s, P = _top(I, w0, dt=dt)
        s.advance(int(round(T / dt)))
        Q = s.bodies.principal_rotations()[0]   # principal -> world, world = P frame at t=0
        errs.append(np.max(np.abs(P.T @ Q - Qref)))
    assert errs[1] < 1e-4
    assert 3.0 < errs[0] / errs[1] < 5.0     # second order


def _axis_component_history(I, omega_body, dt, n_steps, axis):
    s, P = _top(I, omega_body, dt=dt)
    s.initialize()
    out = []
    for _ in range(n_steps):
        s.step()
        Q = s.bodies.principal_rotations()[0]
        out.append((Q.T @ s.bodies.L[0])[axis])
    return np.array(out)


def test_intermediate_axis_flips_and_extreme_axes_are_stable():
    I = (1.0, 2.0, 3.0)
    pi2 = _axis_component_history(I, (1e-3, 1.0, 1e-3), 1e-2, 4000, axis=1)
    assert pi2[0] > 0 and pi2.min() < -0.9 * pi2[0]          # the body's axis 2 reverses
    pi1 = _axis_component_history(I, (1.0, 1e-3, 1e-3), 1e-2, 4000, axis=0)
    assert pi1.min() > 0.99 * pi1[0]                          # minor axis: stable
    pi3 = _axis_component_history(I, (1e-3, 1e-3, 1.0), 1e-2, 4000, axis=2)
    assert pi3.min() > 0.99 * pi3[0]                          # major axis: stable


def test_principal_frame_and_bad_inertia():
    P0 = _random_rotation(3)
    I, P = principal_frame(P0 @ np.diag([3.0, 1.0, 2.0]) @ P0.T)
    assert np.allclose(I, [1, 2, 3]) and np.linalg.det(P) == pytest.approx(1.0)
    assert np.allclose(P @ np.diag(I) @ P.T, P0 @ np.diag([3.0, 1.0, 2.0]) @ P0.T)
    with pytest.raises(InputError):
        principal_frame(np.diag([1.0, -1.0, 1.0]))
    with pytest.raises(InputError):
        principal_frame(np.diag([1.0, 1.0, 5.0]))


def test_isotropic_body_turns_exactly_about_its_angular_momentum():
    """A body with equal principal moments (a sphere) turns at constant ω = L/I: after n free
    steps its orientation is the rotation by n h |ω| about L (Rodrigues, scipy), whatever h."""
    from nurbsdem.dynamics.integrator import free_rotation
    from nurbsdem.geometry.rotation import quat_to_matrix
    rng = np.random.default_rng(3)
    q0 = rng.normal(size=(4, 4))
    q0 /= np.linalg.norm(q0, axis=1)[:, None]
    L = rng.normal(size=(4, 3)) * 0.3
    L[3] = 0.0                                   # at rest: stays
    inv_I = np.full((4, 3), 250.0)
    for h, n in ((1e-3, 1), (0.02, 50)):
        q = q0.copy()
        for _ in range(n):
            free_rotation(q, L, inv_I, h)
        for i in range(4):
            turn = Rotation.from_rotvec(n * h * L[i] * 250.0).as_matrix()
            assert np.abs(quat_to_matrix(q[i]) - turn @ quat_to_matrix(q0[i])).max() < 1e-13


def test_piecewise_linear_table_has_the_bits_of_the_function():
    """Walls.kinematics_at tabulates a piecewise-linear wall (the deck's MoveWall) at many
    times at once: the same bits as the motion called at each time, before, on and between
    the knots and after the last."""
    from nurbsdem.dynamics.rigid import PrescribedMotion, Walls
    motion = PrescribedMotion.piecewise_linear([0.3, 1.3, 1.7], [[0, 0, 0], [0.01, -0.08, 0.2],
                                                                 [0.0, 0.0, 1e-3]])
    times = np.concatenate([[0.0, 0.3, 1.3, 1.7, 2.0], 0.3 + np.arange(1, 1500) * 1e-3 / 3,
                            np.random.default_rng(0).uniform(0.2, 1.8, 300)])
    walls = Walls()
    walls.add(PrescribedMotion.fixed([0, 0, 0.5]))
    walls.add(motion)
    d, u = walls.kinematics_at(times)
    one_by_one = [motion(t) for t in times]
    np.testing.assert_array_equal(d[:, 1], [e[0] for e in one_by_one])      # bit for bit
    np.testing.assert_array_equal(u[:, 1], [e[1] for e in one_by_one])
    np.testing.assert_array_equal(d[:, 0], np.tile([0, 0, 0.5], (len(times), 1)))
    assert not u[:, 0].any()
    one_knot = PrescribedMotion.piecewise_linear([0.5], [[0.1, 0.2, 0.3]])
    d1, u1 = one_knot.table(times)
    np.testing.assert_array_equal(d1, [one_knot(t)[0] for t in times])
    assert not u1.any()


def _row_alone(mass, J0, x, R=None, v=None, omega=None, material=0, centroid_file=None,
               radius=0.0):
    """One particle's row formed alone, as RigidBodies did before its rows were stacked."""
    from nurbsdem.geometry.rotation import matrix_to_quat, quat_to_matrix_into
    I, P = principal_frame(J0)
    R = np.eye(3) if R is None else np.asarray(R, dtype=float)
    q = matrix_to_quat(R @ P)
    Qm = np.empty((3, 3))
    quat_to_matrix_into(q, Qm)
    omega = np.zeros(3) if omega is None else np.asarray(omega, dtype=float)
    J0 = np.asarray(J0, float)
    return dict(mass=mass, J0=0.5 * (J0 + J0.T), I=I, P=P, q=q, L=Qm @ (I * (Qm.T @ omega)),
                x=np.asarray(x, float), v=np.zeros(3) if v is None else np.asarray(v, float),
                centroid_file=np.zeros(3) if centroid_file is None else centroid_file,
                material=material, radius=radius)


def test_stacked_rows_have_the_bits_of_rows_formed_alone():
    """add_many forms the rows of all particles on stacks (one principal frame per distinct
    inertia tensor, stacked matmul): every array has the bits of forming each row alone."""
    from nurbsdem.dynamics.rigid import RigidBodies
    rng = np.random.default_rng(7)
    tensors = []
    for k in range(3):                  # three shapes: shared tensors, as a deck has
        A = rng.normal(size=(3, 3))
        tensors.append(0.1 * A @ A.T + 3 * np.eye(3))
    particles = []
    for i in range(300):
        p = dict(mass=float(rng.uniform(0.1, 2.0)), J0=tensors[i % 3] if i % 7 else
                 np.diag(rng.uniform(1.0, 1.5, 3)), x=rng.normal(size=3),
                 material=int(i % 2), radius=float(rng.uniform(0.01, 0.02)))
        if i % 5:
            p["R"] = _random_rotation(i)
        if i % 4:
            p["omega"], p["v"] = rng.normal(size=3), rng.normal(size=3)
        if i % 3:
            p["centroid_file"] = rng.normal(size=3)
        particles.append(p)
    b = RigidBodies()
    b.add_many(particles[:10])
    b.add_many(particles[10:])
    alone = [_row_alone(**p) for p in particles]
    for name in ("mass", "J0", "I", "P", "q", "L", "x", "v", "centroid_file", "radius"):
        got = getattr(b, name)
        want = np.array([r[name] for r in alone], float)
        assert got.shape == want.shape and np.array_equal(got.view(np.int64), want.view(np.int64)), name
    assert np.array_equal(b.material, [r["material"] for r in alone])


@pytest.mark.parametrize("bad, message", [
    (dict(mass=0.0), "mass must be positive"),
    (dict(J0=np.diag([1.0, 1.0, 3.0])), "triangle inequality"),
    (dict(J0=np.ones((2, 2))), "3x3"),
    (dict(R=np.diag([1.0, 1.0, -1.0])), "proper rotation"),
    (dict(R=2 * np.eye(3)), "proper rotation"),
])
def test_add_many_refuses_a_bad_row_among_good_ones(bad, message):
    from nurbsdem.dynamics.rigid import RigidBodies
    good = dict(mass=1.0, J0=np.diag([1.0, 1.2, 1.4]), x=np.zeros(3))
    b = RigidBodies()
    with pytest.raises(InputError, match=message):
        b.add_many([good, {**good, **bad}, good])
    assert b.n == 0                     # nothing added

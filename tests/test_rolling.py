"""Rolling resistance (``Interface ... RollingFriction mu_r``, nurbsdem/dynamics/rolling.py)
against the analytic motion of a sphere rolling without slip on a flat wall.

With the torque μ_r R f_n against the rolling (R_r = R, the sphere's radius against a flat
wall), m a = F and I α = −R F − M with a = R α and I = 2/5 m R² give a = −(5/7) μ_r g on a
level floor: a sphere rolling at v0 stops after v0 / a, at v0² / (2a), having dissipated its
whole kinetic energy 7/10 m v0².  On an incline θ the torque needed for rest is R m g sin θ
against the limit μ_r R m g cos θ: the sphere stays at rest iff tan θ <= μ_r (with Coulomb
friction above μ_r), else it rolls down at (5/7) g (sin θ − μ_r cos θ)."""
from __future__ import annotations

import math

import numpy as np
import pytest

import nurbsdem
from nurbsdem.errors import InputError
from nurbsdem.simulation import Simulation

R, RHO, G, KN = 0.01, 2700.0, 9.81, 1e5
MASS = RHO * 4.0 / 3.0 * math.pi * R ** 3
MU_R = 0.1


def _sphere_on_floor(gravity, mu_r, velocity=(0.0, 0.0, 0.0), law="LinearPenalty",
                     eta_r=None):
    """One sphere resting (at its static overlap) on a level floor, rolling at ``velocity``
    without slip; ``gravity`` (3,) m/s²."""
    sim = Simulation(gravity=gravity)
    if law == "HertzMindlin":
        sim.add_material(1, RHO, young_modulus=1e8, poisson_ratio=0.3)
        sim.add_interface(model=law, restitution=0.5, friction=0.5, rolling_friction=mu_r)
        d0 = 0.0
    else:
        sim.add_material(1, RHO)
        sim.add_interface(normal_penalty=KN, tangential_penalty=1e4, normal_damping=20,
                          tangential_damping=5, friction=0.5, rolling_friction=mu_r,
                          rolling_damping=eta_r)
        d0 = MASS * abs(gravity[2]) / KN
    sim.add_wall("floor", (0, 0, 0), (0, 0, 1), (1.0, 1.0))
    spin = (-velocity[1] / R, velocity[0] / R, 0.0)           # ω × (−R e_z) = −v: no slip
    sim.add_particle(nurbsdem.shapes.sphere(R), 1, (0, 0, R - d0), velocity=velocity,
                     angular_velocity=spin)
    return sim


@pytest.mark.parametrize("law", ["LinearPenalty", "HertzMindlin"])
def test_a_rolling_sphere_decelerates_at_five_sevenths_mu_r_g_and_stops_there(law):
    v0 = 0.2
    a = 5.0 / 7.0 * MU_R * G
    sim = _sphere_on_floor((0, 0, -G), MU_R, velocity=(v0, 0, 0), law=law)
    sim.run_dynamic(0.15, 1e-3)
    assert sim.velocities[0, 0] == pytest.approx(v0 - a * 0.15, rel=0.01)
    assert sim.angular_velocities[0, 1] * R == pytest.approx(v0 - a * 0.15, rel=0.01)
    sim.run_dynamic(0.2, 1e-3)                               # stops at 0.285 s
    assert sim.positions[0, 0] == pytest.approx(v0 ** 2 / (2 * a), rel=2e-3)
    assert abs(sim.velocities[0, 0]) < 0.01 * v0
    e = sim.energy()
    kinetic0 = 0.7 * MASS * v0 ** 2
    assert e["dissipated"] == pytest.approx(kinetic0, rel=2e-3)   # all of it, by the torque
    # the linear law's balance closes to round-off; Hertz's normal spring leaves its O(h²)
    # error (nurbsdem/dynamics/energy.py); without the rolling work it would be -kinetic0
    assert abs(e["balance_error"]) < (1e-9 if law == "LinearPenalty" else 1e-5) * kinetic0


@pytest.mark.parametrize("ratio", [0.8, 1.2])
def test_a_sphere_on_an_incline_rests_iff_tan_theta_is_below_mu_r(ratio):
    """The incline is the floor under gravity turned by θ (tan θ = ratio μ_r)."""
    theta = math.atan(ratio * MU_R)
    gravity = (G * math.sin(theta), 0.0, -G * math.cos(theta))
    sim = _sphere_on_floor(gravity, MU_R)
    sim.run_dynamic(0.15, 1e-3)
    v1 = sim.velocities[0, 0]
    sim.run_dynamic(0.15, 1e-3)
    x, v = sim.positions[0, 0], sim.velocities[0, 0]
    if ratio < 1.0:
        # the springs hold it: a few micrometres of their deflections (the gravity suddenly
        # applied overshoots the limit for a moment) and their oscillation, where rolling
        # freely it would be 25 mm down at 0.17 m/s
        assert abs(x) < 5e-5 and abs(v) < 2e-3
    else:
        # the slope of the velocity: the rigid-plastic analysis leaves out the first few
        # milliseconds, in which the rolling spring loads up to its limit (1.6 mm/s gained)
        a = 5.0 / 7.0 * G * (math.sin(theta) - MU_R * math.cos(theta))
        assert (v - v1) / 0.15 == pytest.approx(a, rel=0.01)
        assert x > 0.5 * a * 0.3 ** 2
    e = sim.energy()
    # the normal spring's O(h²) error only: the rolling torque's work down the incline
    # (μ_r m g cos θ x, 7e-5 J at 1.2) is booked
    assert abs(e["balance_error"]) < 1e-6 * MASS * G * R


def test_without_rolling_friction_the_sphere_keeps_rolling_and_the_deck_is_unchanged():
    """μ_r = 0 (the default) is no rolling resistance at all: the rolling sphere keeps its
    speed, and an Interface written with RollingFriction 0 gives the same bits and the same
    deck text as one without."""
    sim = _sphere_on_floor((0, 0, -G), 0.0, velocity=(0.2, 0, 0))
    ref = _sphere_on_floor((0, 0, -G), None, velocity=(0.2, 0, 0))
    for s in (sim, ref):
        s.run_dynamic(0.05, 1e-3)
    assert sim.velocities[0, 0] == pytest.approx(0.2, rel=1e-3)
    np.testing.assert_array_equal(sim.positions, ref.positions)
    np.testing.assert_array_equal(sim.angular_velocities, ref.angular_velocities)
    assert sim.energy() == ref.energy()
    assert "RollingFriction" not in sim.deck_text
    assert "RollingFriction 0.1" in _sphere_on_floor((0, 0, -G), MU_R).deck_text


def test_a_rolling_friction_out_of_its_range_is_refused_with_the_reason():
    with pytest.raises(InputError, match="rolling_friction must be >= 0, got -0.1 .*drive"):
        Simulation().add_interface(normal_penalty=1e5, rolling_friction=-0.1)
    with pytest.raises(InputError, match="RollingFriction 0.5 is out of range.*time-step"):
        Simulation().add_interface(normal_penalty=1e5, rolling_friction=0.5)


@pytest.mark.parametrize("wall", [True, False])
def test_the_rolling_radius_is_at_most_the_lever_arms(wall):
    """A contact whose equivalent radius is that of a nearly flat face (1 m) on a particle
    whose contact point lies 1 cm from its centroid: the yielded rolling torque is
    μ_r f_n × 1 cm (the lever arm; with a second particle, 2 cm away: the arms' combination
    1·2/(1 + 2) cm), not μ_r f_n × 1 m.  A sphere's arm is its radius: the same R_r."""
    from nurbsdem.dynamics.forces import ContactLaw, InterfaceTable, contact_forces
    from nurbsdem.dynamics.rolling import ROLL
    table = InterfaceTable(ContactLaw(en=1e5, cn=0.0, et=1e4, ct=0.0, mu=0.5, mu_r=MU_R)
                           ).as_array(1)
    depth = 1e-4
    pos = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -0.03 + depth]])   # B below A
    point_a, point_b = np.array([[0.0, 0.0, -0.01]]), np.array([[0.0, 0.0, -0.01 + depth]])
    inv_mass = np.array([1.0, 0.0 if wall else 1.0])
    omg = np.array([[2.0, 0.0, 0.0], [0.0, 0.0, 0.0]])     # A rolls: the spring yields
    K, B = 1, 2
    out = [np.zeros((B, 3)), np.zeros((B, 3))] + [np.empty((K, 3)) for _ in range(4)] + [
        np.empty((K, 6)), np.empty(K), np.empty((K, 2)), np.empty(K, np.int64), np.empty((K, 4))]
    contact_forces(np.array([0]), np.array([1]), point_a, point_b, np.array([[0.0, 0.0, -1.0]]),
                   np.array([depth]), pos, np.zeros((B, 3)), omg, np.zeros(B, np.int64), table,
                   np.zeros((K, 6)), 1.0, inv_mass, np.array([1.0]), *out, np.bool_(False),
                   np.zeros(0))
    fn = out[7][0]
    assert fn == pytest.approx(1e5 * depth, rel=1e-12)
    arm = 0.01 if wall else 0.01 * 0.02 / 0.03
    torque = np.linalg.norm(out[6][0, ROLL:ROLL + 3])
    assert torque == pytest.approx(MU_R * arm * fn, rel=1e-12)


def test_the_rolling_damper_adds_its_torque_while_the_spring_holds():
    """One contact of a particle (1 kg, its contact point 1 cm from its centroid) with a wall,
    turning at 2 rad/s over a step short enough that the rolling spring holds: the torque on
    the wall is −k_r θ − C_r ω_r with θ = h ω_r, C_r = 2 η_r √(I_r k_r), I_r = 1.4 m ℓ²."""
    from nurbsdem.dynamics.forces import ContactLaw, InterfaceTable, contact_forces
    from nurbsdem.dynamics.rolling import ROLL
    eta_r, kn, depth, h, arm = 0.25, 1e5, 1e-4, 1e-6, 0.01
    table = InterfaceTable(ContactLaw(en=kn, mu=0.5, mu_r=MU_R, eta_r=eta_r)).as_array(1)
    pos = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    point_a, point_b = np.array([[0.0, 0.0, -arm]]), np.array([[0.0, 0.0, -arm + depth]])
    omega = np.array([2.0, 0.0, 0.0])
    K, B = 1, 2
    out = [np.zeros((B, 3)), np.zeros((B, 3))] + [np.empty((K, 3)) for _ in range(4)] + [
        np.empty((K, 6)), np.empty(K), np.empty((K, 2)), np.empty(K, np.int64), np.empty((K, 4))]
    contact_forces(np.array([0]), np.array([1]), point_a, point_b, np.array([[0.0, 0.0, -1.0]]),
                   np.array([depth]), pos, np.zeros((B, 3)), np.array([omega, [0.0, 0.0, 0.0]]),
                   np.zeros(B, np.int64), table, np.zeros((K, 6)), h, np.array([1.0, 0.0]),
                   np.array([arm]), *out, np.bool_(False), np.zeros(0))
    k_r = 2.25 * MU_R ** 2 * arm ** 2 * kn
    w_r = -omega                                        # ω_B − ω_A, in the tangent plane
    c_r = 2.0 * eta_r * math.sqrt(1.4 * arm ** 2 * k_r)
    expected = -k_r * h * w_r - c_r * w_r
    assert np.linalg.norm(-k_r * h * w_r) < MU_R * arm * kn * depth      # the spring holds
    np.testing.assert_allclose(out[6][0, ROLL:ROLL + 3], expected, rtol=1e-12, atol=0)


def test_the_rolling_damper_stills_the_rocking_and_the_balance_closes():
    """The rolling sphere of the first test, stopped by its rolling torque, rocks on its
    rolling spring (no damper: it keeps rocking); with RollingDamping 0.3 the rocking dies
    out, the damper's work is dissipated, and the linear law's balance still closes."""
    rock = {}
    for eta_r in (0.0, 0.3):
        sim = _sphere_on_floor((0, 0, -G), MU_R, velocity=(0.2, 0, 0), eta_r=eta_r or None)
        sim.run_dynamic(0.3, 1e-3)                          # stopped at 0.285 s
        spins = []
        for _ in range(60):
            sim.run_dynamic(1e-3, 1e-3)
            spins.append(sim.angular_velocities[0, 1])
        rock[eta_r] = float(np.sqrt(np.mean(np.square(spins))))
        e = sim.energy()
        assert abs(e["balance_error"]) < 1e-9 * 0.7 * MASS * 0.2 ** 2
    assert rock[0.3] < 0.1 * rock[0.0]

"""Contact-force verification with analytic sphere/plane contacts (Eq. 16–17)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from nurbsdem.dynamics import (ContactLaw, DemSystem, InterfaceTable, SpherePlaneProvider,
                               sphere_inertia)


def _sphere_on_floor(law, m, r, z0, dt, gravity=(0, 0, -9.81), v0=None, omega=None, **kw):
    s = DemSystem(dt=dt, gravity=gravity, interfaces=InterfaceTable(default=law), **kw)
    s.add_particle(m, sphere_inertia(m, r), [0, 0, z0], v=v0, omega=omega, radius=r)
    s.add_wall()
    s.set_contact_provider(SpherePlaneProvider([r], [([0, 0, 0], [0, 0, 1])]))
    return s


def clipped_oscillator(m, k, c, g, v0):
    """Linear spring–dashpot with the force clipped at 0, loaded by gravity g (> 0, into the wall).

    Penetration x(t), x(0) = 0, x'(0) = v0 > 0.  Returns (restitution coefficient measured at the
    x = 0 crossings, contact duration = time with x > 0)."""
    w = math.sqrt(k / m)
    z = c / (2 * math.sqrt(k * m))
    wd = w * math.sqrt(1 - z * z)
    xs = m * g / k
    A = -xs
    B = (v0 + z * w * A) / wd

    def x(t):
        return xs + math.exp(-z * w * t) * (A * math.cos(wd * t) + B * math.sin(wd * t))

    def xd(t):
        e = math.exp(-z * w * t)
        return e * (-z * w * (A * math.cos(wd * t) + B * math.sin(wd * t))
                    + wd * (-A * math.sin(wd * t) + B * math.cos(wd * t)))

    f = lambda t: k * x(t) + c * xd(t)  # noqa: E731
    # the force becomes zero during restitution (before x returns to 0)
    ts = np.linspace(1e-9, 2 * math.pi / wd, 20001)
    fs = np.array([f(t) for t in ts])
    i = int(np.nonzero(fs < 0)[0][0])
    t1 = brentq(f, ts[i - 1], ts[i], xtol=1e-15)
    x1, v1 = x(t1), xd(t1)
    # free flight with gravity: x1 + v1 s + g s²/2 = 0, v1 < 0
    sflight = (-v1 - math.sqrt(v1 * v1 - 2 * g * x1)) / g
    vout = v1 + g * sflight
    return -vout / v0, t1 + sflight


def _crossings(ts, gaps, vz):
    """Times and velocities (linear interpolation) where the gap changes sign."""
    out = []
    for i in range(1, len(ts)):
        if (gaps[i - 1] > 0) != (gaps[i] > 0):
            s = gaps[i - 1] / (gaps[i - 1] - gaps[i])
            out.append((ts[i - 1] + s * (ts[i] - ts[i - 1]), vz[i - 1] + s * (vz[i] - vz[i - 1])))
    return out


@pytest.mark.parametrize("cn", [20.0, 100.0])
def test_drop_restitution_and_duration_match_clipped_damped_oscillator(cn):
    m, r, k, g, v0 = 0.1, 0.02, 1e5, 9.81, 0.5
    law = ContactLaw(en=k, cn=cn)
    gap0 = 2e-4
    # start gap0 above the wall moving down so that the speed at touch-down is v0
    vstart = math.sqrt(v0 * v0 - 2 * g * gap0)
    dt = 2e-6
    s = _sphere_on_floor(law, m, r, r + gap0, dt, v0=[0, 0, -vstart])
    s.initialize()
    assert s.substeps == 1
    ts, gaps, vz = [0.0], [gap0], [-vstart]
    while s.time < 6e-3:
        s.step()
        ts.append(s.time); gaps.append(s.bodies.x[0, 2] - r); vz.append(s.bodies.v[0, 2])
    cr = _crossings(ts, gaps, vz)
    (t_in, v_in), (t_out, v_out) = cr[0], cr[1]
    e_num, tc_num = -v_out / v_in, t_out - t_in
    e_ref, tc_ref = clipped_oscillator(m, k, cn, g, v0)
    assert v_in == pytest.approx(-v0, rel=1e-3)
    assert e_num == pytest.approx(e_ref, rel=0.01)
    assert tc_num == pytest.approx(tc_ref, rel=0.01)
    # the unclipped textbook value differs by more than the tolerance (so the test can fail)
    z = cn / (2 * math.sqrt(k * m))
    if z > 0.3:
        assert abs(math.exp(-z * math.pi / math.sqrt(1 - z * z)) - e_ref) > 0.02 * e_ref


def test_frictionless_undamped_spheres_in_a_box_conserve_energy():
    rng = np.random.default_rng(7)
    n, r, m, L = 6, 0.02, 0.1, 0.2
    law = ContactLaw(en=1e5)
    s = DemSystem(dt=5e-5, gravity=(0, 0, -9.81), interfaces=InterfaceTable(default=law))
    grid = np.array([[x, y, z] for x in (0.05, 0.15) for y in (0.05, 0.15) for z in (0.05, 0.15)])
    for i in range(n):
        s.add_particle(m, sphere_inertia(m, r), grid[i], v=rng.uniform(-1, 1, 3), radius=r)
    planes = []
    for ax in range(3):
        e = np.eye(3)[ax]
        planes += [(np.zeros(3), e), (L * e, -e)]
    for _ in planes:
        s.add_wall()
    s.set_contact_provider(SpherePlaneProvider([r] * n, planes))
    s.initialize()
    e0 = s.energy().mechanical
    ncontacts = 0
    drift = 0.0
    for _ in range(50):
        s.advance(200)
        ncontacts += len(s.contacts.a)
        drift = max(drift, abs(s.energy().mechanical - e0) / e0)
    assert s.energy().dissipated == 0.0
    assert ncontacts > 0                             # collisions did happen
    assert drift < 1e-3


def _incline(alpha_deg, mu, T=0.4, dt=5e-5):
    m, r, g = 0.1, 0.02, 9.81
    a = math.radians(alpha_deg)
    grav = np.array([g * math.sin(a), 0.0, -g * math.cos(a)])
    law = ContactLaw(en=1e5, cn=20.0, et=2e4, ct=0.0, mu=mu)
    d_eq = m * g * math.cos(a) / 1e5
    s = _sphere_on_floor(law, m, r, r - d_eq, dt, gravity=grav)
    s.advance(int(round(0.1 / dt)))
    t1, v1 = s.time, s.bodies.v[0, 0]
    s.advance(int(round(T / dt)))
    t2, v2 = s.time, s.bodies.v[0, 0]
    acc = (v2 - v1) / (t2 - t1)
    return acc, v2, s.bodies.omega()[0, 1] * r, g, a, s   # rolling in +x: v = omega_y r


def test_sphere_on_incline_rolls_without_slip_below_threshold():
    mu = 0.3
    acc, v, wr, g, a, s = _incline(30.0, mu)
    assert math.tan(a) < 3.5 * mu
    assert acc == pytest.approx(5 / 7 * g * math.sin(a), rel=0.01)
    assert wr == pytest.approx(v, rel=0.01)          # rolling: omega_y r = v_x
    assert s.contacts.stick.all()


def test_sphere_on_incline_slides_above_threshold():
    mu = 0.3
    acc, v, wr, g, a, s = _incline(60.0, mu)
    assert math.tan(a) > 3.5 * mu
    assert acc == pytest.approx(g * (math.sin(a) - mu * math.cos(a)), rel=0.01)
    assert wr < 0.9 * v                              # slipping
    assert not s.contacts.stick.any()
    assert s.energy().dissipated_friction > 0


def test_resting_sphere_comes_to_rest_with_contact_force_equal_to_weight():
    m, r, g = 0.2, 0.03, 9.81
    law = ContactLaw(en=1e5, cn=50.0, et=1e4, mu=0.5)
    s = _sphere_on_floor(law, m, r, r + 0.01, 1e-4)
    s.advance(int(1.0 / 1e-4))
    e = s.energy()
    assert e.kinetic_translational < 1e-9 * m * g * r
    assert s.wall_contact_force[0] == pytest.approx([0, 0, -m * g], abs=1e-6 * m * g)
    assert s.wall_reaction[0, 2] == pytest.approx(m * g, rel=1e-6)
    assert s.contacts.fn[0] == pytest.approx(m * g, rel=1e-6)
    assert abs(e.balance_error) < 1e-2 * e.dissipated


@pytest.mark.parametrize("order", ["ascending", "shuffled"])
def test_history_matching_by_key(order):
    """match_history: a persisting key gets its stored spring, a new key zero; ascending
    keys (the scene's order) by a merge, others by binary search: the same springs."""
    from nurbsdem.dynamics.forces import match_history
    rng = np.random.default_rng(3)
    prev = np.unique(rng.integers(0, 400, 150))
    springs = rng.normal(size=(prev.shape[0], 3))
    keys = np.unique(np.concatenate([rng.choice(prev, 60, replace=False),
                                     rng.integers(0, 500, 60)]))
    if order == "shuffled":
        keys = rng.permutation(keys)
    stored = dict(zip(prev.tolist(), springs))
    want = np.array([stored.get(k, np.zeros(3)) for k in keys.tolist()])
    got = match_history(prev, springs, keys)
    assert np.array_equal(got, want)
    assert 0 < np.count_nonzero(got[:, 0]) < keys.shape[0]
    assert match_history(prev, springs, keys[:0]).shape == (0, 3)
    assert not match_history(prev[:0], springs[:0], keys).any()

"""A contact law added through the registry (docs/extending.md): a linear spring without
damping, defined here, against the closed-form elastic bounce of a sphere on a wall (contact
duration π √(m/k), restitution 1), and the kernel check that its own compiled function runs."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest
from numba import njit

from nurbsdem.dynamics import DemSystem, InterfaceTable, SpherePlaneProvider, sphere_inertia
from nurbsdem.dynamics import forces, laws
from nurbsdem.dynamics.laws.engine import engine_kernels
from nurbsdem.dynamics.laws.keys import LawKey
from nurbsdem.dynamics.laws.table import EN, MODEL, NCOL, P0


@dataclass(frozen=True)
class UndampedSpring:
    """f_n = k d, no damping, no tangential force: k (N/m) kept in the law's own column P0;
    EN holds it too, as the linearisation of the time-step control."""

    k: float

    name = "UndampedSpring"
    model = "undampedspring"
    code = -1                        # set by laws.register
    needs_contact_radius = False
    uses_materials = False
    keys = (LawKey("Stiffness", "stiffness", "N/m", 0.0, "a spring needs a stiffness",
                   lo_open=True, required=True),)
    note = "a spring without damping"

    @classmethod
    def from_interface(cls, itf, pair):
        return cls(itf.params["stiffness"])

    def as_row(self) -> np.ndarray:
        row = np.zeros(NCOL)
        row[EN] = self.k
        row[MODEL] = self.code
        row[P0] = self.k
        return row


@njit(inline="always")
def spring_normal(table, ma, mb, d, radius, imass):
    k = table[ma, mb, P0]
    return k, 0.0, 0.0, 0.0, k * d, 0.5 * k * d * d


@njit(inline="always")
def spring_scale(table, ma, mb, d, ddot, h, radius):
    return False, 1.0


@pytest.fixture
def spring_law():
    code = laws.register(UndampedSpring, spring_normal, spring_scale)
    yield code
    laws.unregister(UndampedSpring.name)


def _crossings(ts, gaps, vz):
    out = []
    for i in range(1, len(ts)):
        if (gaps[i - 1] > 0) != (gaps[i] > 0):
            s = gaps[i - 1] / (gaps[i - 1] - gaps[i])
            out.append((ts[i - 1] + s * (ts[i] - ts[i - 1]), vz[i - 1] + s * (vz[i] - vz[i - 1])))
    return out


def test_registered_law_bounces_as_the_closed_form(spring_law):
    """No gravity: the sphere meets the wall at v0 and leaves it at v0 after half a period of
    the spring, π √(m/k)."""
    assert laws.LAWS_BY_CODE[spring_law] is UndampedSpring and spring_law not in (0, 1)
    m, r, k, v0, gap0 = 0.1, 0.02, 1e5, 0.5, 1e-4
    period = math.pi * math.sqrt(m / k)
    s = DemSystem(dt=period / 400, gravity=(0, 0, 0),
                  interfaces=InterfaceTable(default=UndampedSpring(k)))
    s.add_particle(m, sphere_inertia(m, r), [0, 0, r + gap0], v=[0, 0, -v0], radius=r)
    s.add_wall()
    s.set_contact_provider(SpherePlaneProvider([r], [([0, 0, 0], [0, 0, 1])]))
    s.initialize()
    ts, gaps, vz = [0.0], [gap0], [-v0]
    while s.time < 2 * gap0 / v0 + 1.5 * period:
        s.step()
        ts.append(s.time)
        gaps.append(s.bodies.x[0, 2] - r)
        vz.append(s.bodies.v[0, 2])
    (t_in, v_in), (t_out, v_out) = _crossings(ts, gaps, vz)[:2]
    assert v_in == pytest.approx(-v0, rel=1e-4)
    assert t_out - t_in == pytest.approx(period, rel=2e-3)
    assert -v_out / v_in == pytest.approx(1.0, abs=2e-3)


def test_registered_law_runs_its_own_kernel(spring_law):
    """The dispatch reaches the registered function: a row whose own column P0 differs from
    its linearisation EN gives the force P0·d (the linear law's kernel would give EN·d)."""
    table = InterfaceTable(default=UndampedSpring(3.0)).as_array(1)
    table[0, 0, EN] = 7.0
    kernels = engine_kernels(table)
    assert kernels.contact_loads is not forces.contact_loads
    d = 1e-3
    out = kernels.contact_loads(
        np.array([0]), np.array([1]), np.zeros((1, 3)), np.zeros((1, 3)),
        np.array([[0.0, 0.0, 1.0]]), np.array([d]), np.zeros((2, 3)), np.zeros((2, 3)),
        np.zeros((2, 3)), np.zeros(2, np.int64), table, np.zeros((1, 3)), 0.0, np.ones(2),
        np.zeros(1), np.ones(1), np.zeros(3), np.bool_(False), np.zeros(0))
    fn, coeffs = out[7], out[10]
    assert fn[0] == 3.0 * d and coeffs[0, 0] == 3.0
    # the built-in laws keep the cached kernels
    assert engine_kernels(InterfaceTable(default=laws.LinearPenalty(1.0)).as_array(1)) \
        .contact_loads is forces.contact_loads


def test_registered_law_goes_through_the_interface_front_end(spring_law):
    """The one front-end accepts the registered law's name and keys, checks its range with
    the reason, and the law reads its key back from the Interface."""
    from nurbsdem.dynamics.laws.interface import (Front, build_interface, interface_text,
                                                  python_name)
    from nurbsdem.errors import InputError

    def fail(message):
        raise InputError(message)
    front = Front("interface 1", python_name, fail)
    itf = build_interface(1, "UndampedSpring", {"Stiffness": 2e5}, None, None, front)
    assert itf.model == "undampedspring" and itf.params == {"stiffness": 2e5}
    assert laws.law_named(itf.model).from_interface(itf, None).k == 2e5
    text = interface_text(itf, "{:g}".format)
    assert text == "Interface 1 Model UndampedSpring Stiffness 200000"
    with pytest.raises(InputError, match=r"stiffness must be > 0, got -1 \(a spring needs"):
        build_interface(1, "UndampedSpring", {"Stiffness": -1.0}, None, None, front)
    with pytest.raises(InputError, match="normal_penalty does not apply to a UndampedSpring"):
        build_interface(1, "UndampedSpring", {"Stiffness": 1.0, "NormalPenalty": 1.0}, None,
                        None, front)


@dataclass(frozen=True)
class StiffLinearisation(UndampedSpring):
    """The spring with a linearisation 1.5 k in EN (the time-step control's, on the safe side):
    a kernel that fell back to the linear law would push with 1.5 k."""

    name = "StiffLinearisation"
    model = "stifflinearisation"

    def as_row(self) -> np.ndarray:
        row = super().as_row()
        row[EN] = 1.5 * self.k
        return row


def _spring_pack(compiled: bool):
    """Spheres and exact ellipsoids dropped into a box under the registered spring law (a
    scene on one rank), with the compiled deck steps or the Python driver; returns the
    solver after 0.06 s."""
    from nurbsdem import Simulation, shapes
    sim = Simulation(gravity=(0.0, 0.0, -9.81))
    sim._solver_options["compiled_steps"] = compiled
    sim.add_material(1, 2500.0)
    sim.add_interface(model="StiffLinearisation", stiffness=2e3)
    sim.add_box((0.0, 0.0, 0.0), (0.03, 0.03, 0.06))
    rng = np.random.default_rng(4)
    for k in range(8):
        shape = shapes.sphere(0.004) if k % 2 else shapes.ellipsoid(0.005, 0.004, 0.0035)
        sim.add_particle(shape, 1, (0.0075 + 0.015 * (k % 2), 0.0075 + 0.015 * (k // 2 % 2),
                                    0.006 + 0.011 * (k // 4)),
                         rotation=rng.normal(size=3), velocity=rng.normal(scale=0.05, size=3))
    sim.run_dynamic(0.06, 1e-3)
    return sim.solver


@pytest.fixture
def stiff_law():
    code = laws.register(StiffLinearisation, spring_normal, spring_scale)
    yield code
    laws.unregister(StiffLinearisation.name)


def test_registered_law_runs_in_the_compiled_deck_steps(stiff_law, monkeypatch):
    """A scene under a registered law runs in the compiled deck steps (through the contact
    part's copy that dispatches to it, ``contact_part_kernel.redirect``) and ends in the
    state of the Python driver's run bit for bit; the cached kernel is put back for the
    built-in laws."""
    from nurbsdem.dynamics.deck_steps import DeckSteps
    from nurbsdem.dynamics.step import contact_part, contact_part_kernel
    loops = []
    run = DeckSteps.run

    def counted(self, *args, **kwargs):
        loops.append(self.system._kernels.contact_part)
        return run(self, *args, **kwargs)
    monkeypatch.setattr(DeckSteps, "run", counted)
    fast = _spring_pack(True)
    assert loops and loops[0] is not contact_part           # the copy, in the compiled loop
    assert contact_part_kernel.target is loops[0]
    slow = _spring_pack(False)
    assert fast.summary.active_total > 0 and fast.summary.steps == slow.summary.steps == 60
    for name in ("position", "quaternion", "velocity", "angular_velocity"):
        np.testing.assert_array_equal(getattr(fast.bodies, name), getattr(slow.bodies, name),
                                      err_msg=name)
    laws.unregister(StiffLinearisation.name)
    try:
        builtin = _pack_with_builtin_law()
    finally:
        laws.register(StiffLinearisation, spring_normal, spring_scale)   # for the teardown
    assert contact_part_kernel.target is contact_part and builtin.summary.active_total > 0


def _pack_with_builtin_law():
    from nurbsdem import Simulation, shapes
    sim = Simulation(gravity=(0.0, 0.0, -9.81))
    sim.add_material(1, 2500.0)
    sim.add_interface(normal_penalty=2e3)
    sim.add_box((0.0, 0.0, 0.0), (0.03, 0.03, 0.06))
    sim.add_particle(shapes.sphere(0.004), 1, (0.015, 0.015, 0.00399))
    sim.run_dynamic(0.01, 1e-3)
    return sim.solver

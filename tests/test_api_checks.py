"""The Python API checks its arguments as the deck does: every value a deck key has a range
for is held to :data:`nurbsdem.io.deck.RANGES`, and every bad argument is one
:class:`~nurbsdem.errors.InputError` with a one-line message, never a raw TypeError /
ValueError / OverflowError (at the call or later, at the first step).

Hypothesis properties: for arbitrary arguments the call either succeeds with a value the
deck would accept, or raises InputError. Example counts are bounded and derandomized.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from nurbsdem import Simulation, shapes
from nurbsdem.errors import InputError
from nurbsdem.io.deck import ID_MAX, RANGES

PROPS = settings(max_examples=80, deadline=None, derandomize=True, database=None,
                 suppress_health_check=[HealthCheck.too_slow])

#: anything a user might pass where a number or a path is expected
ANYTHING = st.one_of(
    st.none(), st.booleans(), st.integers(min_value=-10 ** 400, max_value=10 ** 400),
    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=8),
    st.lists(st.floats(-10, 10), max_size=4), st.dictionaries(st.text(max_size=4),
                                                              st.integers(), max_size=2))


def _as_float(value) -> float | None:
    """The number a value stands for, or None (not a number, or beyond float)."""
    if isinstance(value, (bool, str, list, dict)) or value is None:
        return None
    try:
        return float(value)
    except OverflowError:
        return None


def _in_range(key: str, x: float) -> bool:
    r = RANGES[key]
    return math.isfinite(x) and abs(x) <= r.hi and not (0 < x < r.lo)


def _one_line(exc: InputError) -> None:
    assert "\n" not in str(exc) and str(exc)


# ---------------------------------------------------------------------------- solver arguments


def test_output_of_the_wrong_type_is_an_input_error():
    with pytest.raises(InputError, match="output must be a folder or file path"):
        Simulation(output=5)
    with pytest.raises(InputError, match="restart must be"):
        Simulation(restart=3.5)


def test_safety_is_held_to_the_decks_range():
    with pytest.raises(InputError, match=r"Safety 0.99 .* out of range: it must be between 0.01 "
                                         r"and 0.95"):
        Simulation(safety=0.99)
    with pytest.raises(InputError, match="Safety must be a number, got 'x'"):
        Simulation(safety="x")
    assert Simulation(safety=0.95)._solver_options["safety"] == 0.95


def test_bogus_contact_options_are_refused_before_the_run():
    with pytest.raises(InputError, match="unknown keyword 'bogus'"):
        Simulation(contact_options={"bogus": 1})
    with pytest.raises(InputError, match="must be a dict"):
        Simulation(contact_options=5)
    with pytest.raises(InputError, match="certificates must be True or False"):
        Simulation(contact_options={"certificates": "no"})
    with pytest.raises(InputError, match="skin must be >= 0"):
        Simulation(contact_options={"skin": -1e-3})
    sim = Simulation(contact_options={"skin": 0, "certificates": False})
    assert sim._solver_options["contact_options"] == {"skin": 0.0, "certificates": False}


def test_from_deck_checks_the_solver_options(tmp_path):
    with pytest.raises(InputError, match="Safety 2"):
        Simulation.from_deck(tmp_path / "none.inp", safety=2)
    with pytest.raises(InputError, match="output must be"):
        Simulation.from_deck(tmp_path / "none.inp", output=7)
    with pytest.raises(InputError, match="from_deck: unknown keyword 'saftey'"):
        Simulation.from_deck(tmp_path / "none.inp", saftey=0.5)


def test_huge_ids_are_refused_at_the_call():
    sim = Simulation()
    with pytest.raises(InputError, match="too large: ids are at most"):
        sim.add_material(10 ** 30, density=2000)
    with pytest.raises(InputError, match="too large"):
        sim.add_interface(normal_penalty=1e5, id=10 ** 19)


def test_shape_generators_raise_input_errors():
    with pytest.raises(InputError, match="sphere: Radius must be a finite number > 0"):
        shapes.sphere(-1)
    with pytest.raises(InputError, match="Radius must be a number"):
        shapes.sphere("a")
    with pytest.raises(InputError, match="out of range"):
        shapes.sphere(1e7)
    with pytest.raises(InputError, match="SemiAxes"):
        shapes.ellipsoid(1, 1, -1)
    with pytest.raises(InputError, match="times longer than wide"):
        shapes.ellipsoid(1e-5, 1, 1)
    with pytest.raises(InputError, match="unknown paper particle"):
        shapes.paper_particle_shape("Z")


# ---------------------------------------------------------------------------- properties


@PROPS
@given(ANYTHING)
def test_safety_property(value):
    """Simulation(safety=x) accepts exactly the deck's Safety values; else InputError."""
    try:
        sim = Simulation(safety=value)
    except InputError as exc:
        _one_line(exc)
        x = _as_float(value)
        assert x is None or not (_in_range("Safety", x) and x > 0), value
        return
    if value is not None:
        assert _in_range("Safety", float(value)) and float(value) > 0
        assert sim._solver_options["safety"] == float(value)


@PROPS
@given(st.dictionaries(st.sampled_from(["skin", "margin", "certificates", "point_surface",
                                        "bogus", "Skin"]), ANYTHING, max_size=3))
def test_contact_options_property(options):
    """Accepted contact options build the contact scene (no error at the first step)."""
    from nurbsdem.contact.scene import SceneContacts
    try:
        sim = Simulation(contact_options=options)
    except InputError as exc:
        _one_line(exc)
        return
    opts = sim._solver_options["contact_options"]
    scene = SceneContacts([_SPHERE], np.zeros(1, np.int64), **opts)
    assert scene.n == 1


_SPHERE = shapes.sphere(0.01)


@PROPS
@given(ANYTHING, ANYTHING, st.one_of(st.none(), ANYTHING), ANYTHING)
def test_add_material_property(mid, density, young, nu):
    """add_material accepts ids 1..ID_MAX and the deck's ranges; anything else InputError."""
    sim = Simulation()
    try:
        got = sim.add_material(mid, density, young, nu if nu is not None else 0.0)
    except InputError as exc:
        _one_line(exc)
        return
    assert 1 <= got <= ID_MAX
    m = sim.model.materials[got]
    assert _in_range("Density", m.density) and m.density > 0
    assert m.young_modulus is None or (_in_range("YoungModulus", m.young_modulus)
                                       and m.young_modulus > 0)
    assert -1.0 < m.poisson_ratio < 0.5


@settings(PROPS, max_examples=30)
@given(st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                 st.integers(-10, 10 ** 8), st.text(max_size=3), st.none()))
def test_sphere_property(radius):
    """shapes.sphere(r) gives a sphere of radius r for the deck's Radius range, else
    InputError."""
    try:
        s = shapes.sphere(radius)
    except InputError as exc:
        _one_line(exc)
        return
    r = float(radius)
    assert _in_range("Radius", r) and r > 0
    assert s.volume == pytest.approx(4 / 3 * math.pi * r ** 3, rel=1e-9)


@PROPS
@given(ANYTHING, ANYTHING)
def test_output_property(output, restart):
    """output/restart: a path or None, else InputError (never a TypeError)."""
    try:
        Simulation(output=output, restart=restart)
    except InputError as exc:
        _one_line(exc)
        return
    for v in (output, restart):
        assert v is None or isinstance(v, str)


VECTORS = st.one_of(ANYTHING, st.lists(st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                                                 st.integers(-10 ** 400, 10 ** 400)),
                                       min_size=3, max_size=3))


@PROPS
@given(VECTORS, st.one_of(st.none(), VECTORS), st.one_of(st.none(), VECTORS), VECTORS)
def test_add_particle_and_gravity_property(position, velocity, angular_velocity, gravity):
    """Vectors: three finite numbers in the deck's range of their key, else InputError."""
    try:
        sim = Simulation(gravity=gravity)
    except InputError as exc:
        _one_line(exc)
    else:
        g = np.asarray(sim.model.gravity)
        assert g.shape == (3,) and all(_in_range("Gravity", float(x)) for x in g)
    sim = Simulation()
    sim.add_material(1, 2000.0)
    try:
        pid = sim.add_particle(_SPHERE, 1, position, velocity=velocity,
                               angular_velocity=angular_velocity)
    except InputError as exc:
        _one_line(exc)
        return
    p = sim.model.particles[pid - 1]
    assert all(_in_range("Position", float(x)) for x in p.position)
    assert all(_in_range("Velocity", float(x)) for x in p.velocity)
    assert all(_in_range("AngularVelocity", float(x)) for x in p.angular_velocity)

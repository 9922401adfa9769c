"""Kernels called through pointers (:class:`nurbsdem.jit.PointerKernel`): the same results as
a direct call (named tuples of arrays among the arguments too), one compilation per
signature, and a lazy kernel whose slot is still empty raises instead of jumping to address
0."""
from __future__ import annotations

from collections import namedtuple

import numpy as np
import pytest
from numba import njit

from nurbsdem import jit


@njit
def _axpy(a, x, y):
    for i in range(x.shape[0]):
        y[i] += a * x[i]
    return y.sum()


AXPY = jit.PointerKernel(_axpy, "test_axpy")
_axpy_ptr = AXPY.call


@njit
def _twice(a, x, y):
    return _axpy_ptr(a, x, y) + _axpy_ptr(a, x, y)


_Pair = namedtuple("_Pair", "a b")


@njit
def _weighted(t, x):
    return (t.a * x).sum() + t.b[0]


_weighted_ptr = jit.PointerKernel(_weighted, "test_weighted").call


@njit
def _through_pointer(t, x):
    return _weighted_ptr(t, x)


@njit
def _axpy_lazy(a, x, y):
    for i in range(x.shape[0]):
        y[i] += a * x[i]


@pytest.fixture
def lazy_kernel(monkeypatch):
    """A lazy kernel and its caller in a process where no scene asked for lazy kernels."""
    monkeypatch.setattr(jit, "_LAZY_WANTED", set())
    pk = jit.PointerKernel(_axpy_lazy, "test_axpy_lazy", lazy=True)
    ptr = pk.call

    @njit
    def caller(a, x, y):
        ptr(a, x, y)
    return pk, caller


def test_a_pointer_call_returns_what_a_direct_call_does():
    x = np.arange(5.0)
    y1, y2 = np.ones(5), np.ones(5)
    s = _twice(0.5, x, y1)
    s_ref = _axpy(0.5, x, y2) + _axpy(0.5, x, y2)
    assert s == s_ref and np.array_equal(y1, y2)
    assert len(AXPY._slots) == 1 and len(_axpy.overloads) == 1     # compiled once


def test_a_pointer_call_takes_a_named_tuple_of_arrays_as_a_direct_call_does():
    t, x = _Pair(np.arange(3.0), np.array([2.5])), np.array([1.0, -2.0, 0.5])
    assert _through_pointer(t, x) == _weighted(t, x) == -1.0 + 2.5


def test_an_empty_lazy_slot_raises_until_filled(lazy_kernel):
    pk, caller = lazy_kernel
    x, y = np.arange(3.0), np.zeros(3)
    with pytest.raises(RuntimeError, match="test_axpy_lazy not loaded"):
        caller(2.0, x, y)
    assert not _axpy_lazy.overloads                               # not compiled
    jit.fill_lazy_kernels()
    caller(2.0, x, y)
    assert np.array_equal(y, 2.0 * x)


@njit
def _axmy(a, x, y):
    for i in range(x.shape[0]):
        y[i] -= a * x[i]
    return y.sum()


@njit
def _nothing(a, x, y):
    pass


def test_a_redirected_pointer_calls_the_other_kernel_from_compiled_callers():
    """``redirect`` puts another kernel of the same signature in the slots a caller already
    compiled holds; ``redirect()`` puts the kernel's own back; a kernel of another result
    type is refused."""
    x = np.arange(4.0)
    _twice(1.0, x, np.zeros(4))                      # the caller compiled, the slot filled
    try:
        AXPY.redirect(_axmy)
        y = np.zeros(4)
        assert _twice(1.0, x, y) == -(6.0 + 12.0) and np.array_equal(y, -2.0 * x)
        with pytest.raises(TypeError, match="returns none, not the float64"):
            AXPY.redirect(_nothing)
    finally:
        AXPY.redirect()
    y = np.zeros(4)
    assert _twice(1.0, x, y) == 6.0 + 12.0 and np.array_equal(y, 2.0 * x)


@njit
def _axpy_sum_lazy(a, x, y):
    for i in range(x.shape[0]):
        y[i] += a * x[i]
    return y.sum()


def test_a_lazy_kernel_with_a_declared_result_types_its_callers_without_compiling(
        monkeypatch):
    """A lazy kernel that declares its result (``result``): its caller compiles and returns
    that type while the kernel is not compiled; filled, the slot gives the kernel's results;
    a kernel whose compiled result differs from the declared one is refused."""
    from numba import types
    monkeypatch.setattr(jit, "_LAZY_WANTED", set())
    pk = jit.PointerKernel(_axpy_sum_lazy, "test_axpy_sum_lazy", lazy="test_declared",
                           result=lambda argtypes: types.float64)
    ptr = pk.call

    @njit
    def caller(a, x, y):
        return ptr(a, x, y) + 1.0

    x, y = np.arange(3.0), np.zeros(3)
    with pytest.raises(RuntimeError, match="test_axpy_sum_lazy not loaded"):
        caller(2.0, x, y)
    assert not _axpy_sum_lazy.overloads                           # typed, not compiled
    jit.fill_lazy_kernels("test_declared")
    assert caller(2.0, x, y) == 2.0 * x.sum() + 1.0

    wrong = jit.PointerKernel(_axpy_sum_lazy, "test_axpy_sum_wrong", lazy="test_wrong",
                              result=lambda argtypes: types.int64)
    wrong_ptr = wrong.call

    @njit
    def wrong_caller(a, x, y):
        return wrong_ptr(a, x, y)

    with pytest.raises(RuntimeError, match="not loaded"):
        wrong_caller(2.0, x, y)
    with pytest.raises(TypeError, match="returns float64, not the int64"):
        jit.fill_lazy_kernels("test_wrong")


_SCENE_KERNELS = r"""
import sys
from pathlib import Path
from nurbsdem.simulation import Simulation
from nurbsdem.contact import listed
from nurbsdem.dynamics import deck_steps, periodic_steps
inputs, tmp = Path(sys.argv[1]), Path(sys.argv[2])
text = (inputs / "regression" / "drop_one.inp").read_text()
text = text.replace("../shapes/A.yaml", str(inputs / "shapes" / "A.yaml"))
text = text.replace("Duration 0.8", "Duration 0.004").replace("results/drop_one",
                                                              str(tmp / "results"))
(tmp / "drop.inp").write_text(text)
sim = Simulation.from_deck(tmp / "drop.inp", quiet=True)
sim.solver.write_output = False
sim.run()
print(len(deck_steps.run_deck_steps.overloads), len(periodic_steps.image_step_start.overloads),
      len(periodic_steps.periodic_list.overloads), len(listed._sphere_nurbs.overloads))
"""


def test_a_scene_without_a_cell_or_spheres_compiles_none_of_their_kernels(tmp_path):
    """The compiled loop of a deck of one NURBS particle in a box: the periodic cell's kernels
    and the sphere–particle solver (lazy groups "periodic", "sphere_nurbs") are neither
    compiled nor loaded in its process."""
    import subprocess
    import sys
    from pathlib import Path
    inputs = Path(__file__).resolve().parent.parent / "inputs"
    out = subprocess.run([sys.executable, "-c", _SCENE_KERNELS, str(inputs), str(tmp_path)],
                         capture_output=True, text=True, check=True)
    loop, step_start, plist, sphere_nurbs = map(int, out.stdout.split())
    assert loop == 1 and (step_start, plist, sphere_nurbs) == (0, 0, 0)

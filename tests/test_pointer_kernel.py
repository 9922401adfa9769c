"""Kernels called through pointers (:class:`nurbsdem.jit.PointerKernel`): the same results as
a direct call, one compilation per signature, and a lazy kernel whose slot is still empty
raises instead of jumping to address 0."""
from __future__ import annotations

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
    return _axpy_ptr((a, x, y)) + _axpy_ptr((a, x, y))


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
        ptr((a, x, y))
    return pk, caller


def test_a_pointer_call_returns_what_a_direct_call_does():
    x = np.arange(5.0)
    y1, y2 = np.ones(5), np.ones(5)
    s = _twice(0.5, x, y1)
    s_ref = _axpy(0.5, x, y2) + _axpy(0.5, x, y2)
    assert s == s_ref and np.array_equal(y1, y2)
    assert len(AXPY._slots) == 1 and len(_axpy.overloads) == 1     # compiled once


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

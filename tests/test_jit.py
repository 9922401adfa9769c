"""How :mod:`nurbsdem.jit` sets numba up: a pointer call passes named tuples of arrays as a
direct call does, and an array assignment with mismatched shapes raises numba's plain message
without compiling the code that formats the shapes."""
from __future__ import annotations

from collections import namedtuple

import numpy as np
import pytest
from numba import njit

from nurbsdem import jit

_Pair = namedtuple("_Pair", "a b")


@njit
def _weighted(t, x):
    return (t.a * x).sum() + t.b[0]


_weighted_ptr = jit.PointerKernel(_weighted, "test_weighted").call


@njit
def _through_pointer(t, x):
    return _weighted_ptr(t, x)


def test_a_pointer_call_takes_a_named_tuple_of_arrays_as_a_direct_call_does():
    t, x = _Pair(np.arange(3.0), np.array([2.5])), np.array([1.0, -2.0, 0.5])
    assert _through_pointer(t, x) == _weighted(t, x) == -1.0 + 2.5


@njit
def _put_row(a, b):
    a[0] = b


def test_a_mismatched_row_assignment_raises_the_plain_message_and_compiles_no_formatting():
    with pytest.raises(ValueError, match="^cannot assign slice from input of different size$"):
        _put_row(np.zeros((2, 3)), np.ones(4))
    ir = _put_row.overloads[_put_row.signatures[0]].library.get_llvm_str()
    assert "unicode" not in ir and "integer_str" not in ir

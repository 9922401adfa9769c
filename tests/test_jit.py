"""How :mod:`nurbsdem.jit` sets numba up: an array assignment with mismatched shapes raises
numba's plain message without compiling the code that formats the shapes, and a package
kernel called with a constant argument from compiled code is compiled for the constant's plain
type, not once more for its value."""
from __future__ import annotations

import numpy as np
import pytest
from numba import njit, types

import nurbsdem.jit  # noqa: F401 - sets numba up
from nurbsdem.contact.curved_walls import wall_contact_key


@njit
def _put_row(a, b):
    a[0] = b


def test_a_mismatched_row_assignment_raises_the_plain_message_and_compiles_no_formatting():
    with pytest.raises(ValueError, match="^cannot assign slice from input of different size$"):
        _put_row(np.zeros((2, 3)), np.ones(4))
    ir = _put_row.overloads[_put_row.signatures[0]].library.get_llvm_str()
    assert "unicode" not in ir and "integer_str" not in ir


@njit
def _key_of_first_wall(nb, owner, rank):
    return wall_contact_key(nb, owner, 0, 3, rank)


@njit
def _key_of_wall(nb, owner, w, rank):
    return wall_contact_key(nb, owner, w, 3, rank)


def test_a_constant_argument_compiles_the_kernel_for_its_plain_type_only():
    """Two callers, one passing the constants 0 and 3, the other a variable wall and the
    constant 3: the kernel has one specialisation, of plain integers, and both callers give
    the Python function's keys."""
    assert _key_of_first_wall(10, 4, 1) == wall_contact_key.py_func(10, 4, 0, 3, 1)
    assert _key_of_wall(10, 4, 2, 1) == wall_contact_key.py_func(10, 4, 2, 3, 1)
    scalar = [sig for sig in wall_contact_key.signatures
              if not any(isinstance(t, types.Array) for t in sig)]
    assert scalar == [(types.int64,) * 5]

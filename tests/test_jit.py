"""How :mod:`nurbsdem.jit` sets numba up: an array assignment with mismatched shapes raises
numba's plain message without compiling the code that formats the shapes."""
from __future__ import annotations

import numpy as np
import pytest
from numba import njit

import nurbsdem.jit  # noqa: F401 - sets numba up


@njit
def _put_row(a, b):
    a[0] = b


def test_a_mismatched_row_assignment_raises_the_plain_message_and_compiles_no_formatting():
    with pytest.raises(ValueError, match="^cannot assign slice from input of different size$"):
        _put_row(np.zeros((2, 3)), np.ones(4))
    ir = _put_row.overloads[_put_row.signatures[0]].library.get_llvm_str()
    assert "unicode" not in ir and "integer_str" not in ir

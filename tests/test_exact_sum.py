"""The energy ledger's exact sums (:mod:`nurbsdem.dynamics.exact_sum`): the same bits in any
order and on any split over ranks, within about one unit in the last place of the correctly
rounded sum (``math.fsum``, an independent exact summation), and the half kicks' work booked by
two ranks, each its counted contacts, equal to one rank's booking to the bit."""
from __future__ import annotations

import math

import numpy as np
import pytest

from nurbsdem.dynamics.exact_sum import (SPECIAL, exact_add, exact_add_rows, exact_value,
                                         exact_zeros)
from nurbsdem.dynamics.forces import N_TERMS, T_WALL_A, T_WALL_B
from nurbsdem.dynamics.step import EXACT_WALLS, book_kick, ledger_of, wall_work_of


def _summed(values) -> float:
    acc = exact_zeros(1)
    for x in values:
        exact_add(acc, 0, float(x))
    return exact_value(acc, 0)


def _terms(rng: np.random.Generator, n: int) -> np.ndarray:
    """Terms over many binades, with some exact cancellations."""
    x = rng.normal(size=n) * 10.0 ** rng.uniform(-30, 30, size=n)
    x[: n // 4] = -x[n // 4: 2 * (n // 4)]
    return x


@pytest.mark.parametrize("seed", range(6))
def test_any_order_and_any_split_give_the_same_bits_as_fsum_within_an_ulp(seed):
    rng = np.random.default_rng(seed)
    x = _terms(rng, 500)
    once = _summed(x)
    assert _summed(rng.permutation(x)) == once
    parts = np.split(rng.permutation(x), [137, 301])
    shares = [exact_zeros(1) for _ in parts]
    for share, part in zip(shares, parts):
        for v in part:
            exact_add(share, 0, float(v))
    total = exact_zeros(1)
    for share in shares:
        exact_add_rows(total, share)
    assert exact_value(total, 0) == once
    ref = math.fsum(x)
    assert abs(once - ref) <= math.ulp(ref)


def test_cancellation_subnormals_and_the_largest_doubles_are_exact():
    assert _summed([1e300, 1.0, -1e300]) == 1.0
    assert _summed([0.1] * 10 + [-1.0]) == math.fsum([0.1] * 10 + [-1.0])
    assert _summed([5e-324, 5e-324]) == 1e-323
    assert _summed([-5e-324]) == -5e-324
    assert _summed([1.7e308, 1.7e308, -1.7e308]) == 1.7e308     # no overflow on the way
    assert _summed([]) == 0.0
    assert _summed([-0.75, 0.25]) == -0.5


def test_non_finite_terms_read_as_a_float_sum_would():
    assert _summed([math.inf, 1.0]) == math.inf
    assert _summed([-math.inf, 1.0]) == -math.inf
    assert math.isnan(_summed([math.inf, -math.inf]))
    assert math.isnan(_summed([math.nan, 2.0]))
    acc = exact_zeros(1)
    exact_add(acc, 0, math.inf)
    assert acc[0, SPECIAL] == 1


def test_two_ranks_booking_their_counted_contacts_give_one_ranks_ledger_to_the_bit():
    """book_kick over every contact against two ranks' bookings of their own (counted)
    contacts, added with exact_add_rows: the same accumulators, ledger and walls' work."""
    rng = np.random.default_rng(11)
    K, n, W = 400, 50, 3
    terms = rng.normal(size=(K, N_TERMS)) * 10.0 ** rng.uniform(-8, 2, size=(K, 1))
    a = rng.integers(0, n, size=K)
    b = rng.integers(0, n + W, size=K)
    terms[:, T_WALL_A] = 0.0
    terms[b < n, T_WALL_B] = 0.0

    def booked(counted):
        exact = exact_zeros(EXACT_WALLS + W)
        book_kick(terms, a, b, n, counted, exact)
        return exact

    one = booked(np.zeros(0, np.bool_))
    mine = rng.random(K) < 0.4
    total = exact_zeros(EXACT_WALLS + W)
    for share in (booked(mine), booked(~mine)):
        exact_add_rows(total, share)
    assert total.tobytes() == one.tobytes()
    ledger, wall_work = ledger_of(one, 0.0), wall_work_of(one)
    assert ledger[0] == pytest.approx(-terms[:, 0].sum(), rel=1e-12)
    walls = b >= n
    assert ledger[3] == pytest.approx(terms[walls, T_WALL_B].sum(), rel=1e-12)
    for w in range(W):
        assert wall_work[w] == pytest.approx(terms[b == n + w, T_WALL_B].sum(), rel=1e-12)

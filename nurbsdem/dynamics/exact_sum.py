"""Exact sums of float64 terms, whatever the order in which the terms arrive.

The energy ledger (paper §2.3: the dissipated energy and the external work of every half kick)
adds millions of terms.  A float sum depends on their order, so several MPI ranks, threads or
a GPU, each adding its own contacts' terms, would give other bits than one rank.  Here each
sum is kept exactly, as a fixed-point integer wide enough for every finite double, and only
its reading is rounded: the same terms give the same bits in any order and on any split over
ranks, and the ranks' partial sums add exactly (:func:`exact_add_rows`).

An accumulator is a row of :data:`WIDTH` int64 entries: :data:`N_LIMBS` limbs of
:data:`LIMB_BITS` bits (limb i is worth 2^(LIMB_BITS·i + LOW_EXP); the last limb carries the
sign) and a flag column (:data:`SPECIAL`) that records the non-finite terms (+inf, −inf, NaN:
a sum with NaN or both infinities reads NaN, as a float sum would).  A double is an integer
mantissa M (M < 2^53, read from its bits) times 2^e with e ≥ :data:`LOW_EXP` (subnormals
included), so every term is an integer multiple of the lowest bit.  Each term adds less than
2^LIMB_BITS to at most three limbs; :func:`exact_normalize` carries the limbs back into
[0, 2^LIMB_BITS) and must run before 2^31 terms have gone into one accumulator (the bookings
normalise after every call, :func:`exact_normalize_all`).  The canonical (normalised) form is unique for
each value, so its reading (:func:`exact_value`: the three leading limbs summed in floating
point, within about one unit in the last place of the exact sum) is the same bits for the
same exact sum.
"""
from __future__ import annotations

import math

import numpy as np
from numba import types
from numba.core import config
from numba.extending import intrinsic

from ..jit import kernel

#: bits per limb: a term's mantissa shifted into place spans at most three limbs, and an int64
#: limb has room for 2^31 such additions before it must be carried
LIMB_BITS = 32
_BASE = 1 << LIMB_BITS
_MASK = _BASE - 1
#: the exponent of bit 0 of limb 0: the smallest subnormal, 2^-1074 (the lowest bit of every
#: double's mantissa integer lies at or above it)
LOW_EXP = -1074
#: limbs per accumulator: bits from 2^LOW_EXP up to 2^1024 (the largest double's top bit is
#: 2^1023: 66 limbs), and two more for the carries of a sum of many large terms
N_LIMBS = 68
#: the column of the non-finite flags (1: +inf, 2: −inf, 4: NaN)
SPECIAL = N_LIMBS
#: int64 entries per accumulator
WIDTH = N_LIMBS + 1
#: the fields of a double's bits: the stored mantissa, its hidden bit, the biased exponent
_FRACTION = (1 << 52) - 1
_HIDDEN = 1 << 52
_EXPONENT = 0x7FF

if config.DISABLE_JIT:
    # plain Python (NUMBA_DISABLE_JIT=1): an intrinsic has no Python form
    def float_bits(x: float) -> int:
        """The IEEE 754 bits of the double x as a signed 64-bit integer."""
        return int(np.array(x, np.float64).view(np.int64))
else:
    @intrinsic
    def float_bits(typingctx, x):
        """The IEEE 754 bits of the double x as a signed 64-bit integer (a bit cast)."""
        sig = types.int64(types.float64)

        def codegen(context, builder, signature, args):
            return builder.bitcast(args[0], context.get_value_type(types.int64))
        return sig, codegen


@kernel(inline="always")
def exact_add(acc: np.ndarray, row: int, x: float) -> None:
    """Add the double x exactly to accumulator ``row`` of acc (R, WIDTH) int64."""
    bits = float_bits(x)
    biased = (bits >> 52) & _EXPONENT
    mant = bits & _FRACTION
    if biased == _EXPONENT:              # inf or NaN
        acc[row, SPECIAL] |= 4 if mant else (2 if bits < 0 else 1)
        return
    if biased == 0:                      # zero or subnormal: x = ±mant 2^-1074
        if mant == 0:
            return
        biased = 1
    else:                                # normal: x = ±(2^52 + mant) 2^(biased - 1075)
        mant |= _HIDDEN
    shift = biased - 1                   # the position of mant's bit 0 above 2^LOW_EXP
    limb = shift // LIMB_BITS
    off = shift - limb * LIMB_BITS
    neg = bits < 0
    lo = (mant & _MASK) << off           # < 2^63
    hi = (mant >> LIMB_BITS) << off      # < 2^52
    p0 = lo & _MASK
    p1 = (lo >> LIMB_BITS) + (hi & _MASK)
    p2 = hi >> LIMB_BITS
    if neg:
        acc[row, limb] -= p0
        acc[row, limb + 1] -= p1
        acc[row, limb + 2] -= p2
    else:
        acc[row, limb] += p0
        acc[row, limb + 1] += p1
        acc[row, limb + 2] += p2


@kernel(inline="always")
def exact_normalize(acc: np.ndarray, row: int) -> None:
    """Carry the limbs of accumulator ``row`` into [0, 2^LIMB_BITS), the last one signed: the
    canonical form (unique for each value)."""
    carry = np.int64(0)
    for i in range(N_LIMBS - 1):
        t = acc[row, i] + carry
        carry = t >> LIMB_BITS           # floor division: t - carry 2^LIMB_BITS in [0, 2^32)
        acc[row, i] = t - (carry << LIMB_BITS)
    acc[row, N_LIMBS - 1] += carry


@kernel
def exact_normalize_all(acc: np.ndarray) -> None:
    """Every accumulator of acc (R, WIDTH) in its canonical form (:func:`exact_normalize`):
    after each booking, so that no limb nears overflow and the stored accumulators are the
    same bits whatever the order and the split of the terms booked."""
    for r in range(acc.shape[0]):
        exact_normalize(acc, r)


@kernel(inline="always")
def _negate(acc: np.ndarray, row: int) -> None:
    """Accumulator ``row`` := −itself, normalised."""
    for i in range(N_LIMBS):
        acc[row, i] = -acc[row, i]
    exact_normalize(acc, row)


@kernel
def exact_value(acc: np.ndarray, row: int) -> float:
    """The value of accumulator ``row`` (normalised first, in place) as a double within about
    one unit in the last place of the exact sum (its three leading limbs summed): the same
    exact sum always gives the same bits."""
    flags = acc[row, SPECIAL]
    if flags & 4 or (flags & 3) == 3:
        return math.nan
    if flags & 1:
        return math.inf
    if flags & 2:
        return -math.inf
    exact_normalize(acc, row)
    negative = acc[row, N_LIMBS - 1] < 0
    if negative:                         # read |v| (limbs all in [0, 2^32)), then back
        _negate(acc, row)
    total = 0.0
    read = 0
    for i in range(N_LIMBS - 1, -1, -1):
        if read == 0 and acc[row, i] == 0:
            continue
        total += math.ldexp(float(acc[row, i]), LIMB_BITS * i + LOW_EXP)
        read += 1
        if read == 3:
            break
    if negative:
        _negate(acc, row)
        return -total
    return total


@kernel
def exact_add_rows(acc: np.ndarray, parts: np.ndarray) -> None:
    """Add the accumulators ``parts`` (R, WIDTH), row by row, to acc (R, WIDTH) (normalised
    after): a sum of exact sums, e.g. the ranks' shares of a deck step."""
    for r in range(acc.shape[0]):
        for i in range(N_LIMBS):
            acc[r, i] += parts[r, i]
        acc[r, SPECIAL] |= parts[r, SPECIAL]
        exact_normalize(acc, r)


def exact_zeros(rows: int) -> np.ndarray:
    """``rows`` accumulators holding zero."""
    return np.zeros((rows, WIDTH), np.int64)


def exact_of(values) -> np.ndarray:
    """Accumulators holding the doubles ``values`` (one row each), e.g. a ledger read from a
    checkpoint that has no accumulators."""
    values = np.asarray(values, float).reshape(-1)
    acc = exact_zeros(values.shape[0])
    for r, x in enumerate(values):
        exact_add(acc, r, float(x))
        exact_normalize(acc, r)
    return acc


def exact_values(acc: np.ndarray) -> np.ndarray:
    """The values of all accumulators of acc (R, WIDTH) (:func:`exact_value`)."""
    return np.array([exact_value(acc, r) for r in range(acc.shape[0])])

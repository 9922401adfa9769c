"""zlib streams of arrays whose rows repeat, written without a search (RFC 1950/1951).

Why
---
The particles' ParaView samples hold per-point arrays that are constant over each body (its
velocity and angular velocity: 600 equal rows per body in the paper example).  zlib finds
those repeats by hashing and comparing every byte, on the output worker that competes with
the LCP threads for the cores, after a copy that writes the rows out.  Here the repeats are
known beforehand, so the compressed stream is written directly: in each block, the first
row's bytes of a run as literals, then copies of the bytes
one row back (length ≤ 258, distance = row size), in deflate's fixed Huffman code; the
Adler-32 checksum is summed per run in closed form.  The work is per run and per 258 bytes,
not per byte.  Any inflater reads the result (zlib, VTK, ParaView, meshio: tests); the bytes
it inflates to are those of ``np.repeat(values, counts, axis=0)``.

Layout: :func:`encode_repeated` returns the pieces of one appended VTK DataArray, as
:func:`nurbsdem.io.vtu.encode` does (UInt32 header: block count, block size, last block's
size, compressed sizes; then the blocks, each a zlib stream of ``block`` uncompressed bytes).
"""
from __future__ import annotations

import numpy as np
from numba import njit

#: RFC 1951 3.2.5: length codes 257.. (base length, extra bits)
LENGTH_BASE = np.array([3, 4, 5, 6, 7, 8, 9, 10, 11, 13, 15, 17, 19, 23, 27, 31, 35, 43, 51,
                        59, 67, 83, 99, 115, 131, 163, 195, 227, 258], np.int64)
LENGTH_EXTRA = np.array([0] * 8 + [1] * 4 + [2] * 4 + [3] * 4 + [4] * 4 + [5] * 4 + [0],
                        np.int64)
#: distance codes 0.. (base distance, extra bits)
DIST_BASE = np.array([1, 2, 3, 4, 5, 7, 9, 13, 17, 25, 33, 49, 65, 97, 129, 193, 257, 385, 513,
                      769, 1025, 1537, 2049, 3073, 4097, 6145, 8193, 12289, 16385, 24577],
                     np.int64)
DIST_EXTRA = np.array([0, 0, 0, 0] + [k // 2 for k in range(2, 28)], np.int64)
#: Adler-32's modulus
ADLER_MOD = 65521
#: the longest copy deflate codes, the largest distance
MAX_MATCH, MAX_DIST = 258, 32768


# -- bits ---------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def _put(out: np.ndarray, state: np.ndarray, value: int, n: int) -> None:
    """Append the n low bits of value, least significant first (state: bit buffer, bits in
    it, bytes written)."""
    state[0] |= value << state[1]
    state[1] += n
    while state[1] >= 8:
        out[state[2]] = state[0] & 0xFF
        state[2] += 1
        state[0] >>= 8
        state[1] -= 8


@njit(cache=True, inline="always")
def _put_code(out: np.ndarray, state: np.ndarray, code: int, n: int) -> None:
    """Append a Huffman code of n bits (codes are sent most significant bit first)."""
    rev = 0
    for k in range(n):
        rev = (rev << 1) | ((code >> k) & 1)
    _put(out, state, rev, n)


@njit(cache=True, inline="always")
def _put_symbol(out: np.ndarray, state: np.ndarray, s: int) -> None:
    """A literal/length symbol (0..287) in the fixed Huffman code (RFC 1951 3.2.6)."""
    if s < 144:
        _put_code(out, state, 0x30 + s, 8)
    elif s < 256:
        _put_code(out, state, 0x190 + s - 144, 9)
    elif s < 280:
        _put_code(out, state, s - 256, 7)
    else:
        _put_code(out, state, 0xC0 + s - 280, 8)


@njit(cache=True)
def _put_copy(out: np.ndarray, state: np.ndarray, length: int, dist: int) -> None:
    """A copy of ``length`` (3..258) bytes from ``dist`` (1..32768) bytes back."""
    c = LENGTH_BASE.shape[0] - 1
    while LENGTH_BASE[c] > length:
        c -= 1
    _put_symbol(out, state, 257 + c)
    _put(out, state, length - LENGTH_BASE[c], LENGTH_EXTRA[c])
    d = DIST_BASE.shape[0] - 1
    while DIST_BASE[d] > dist:
        d -= 1
    _put_code(out, state, d, 5)
    _put(out, state, dist - DIST_BASE[d], DIST_EXTRA[d])


# -- one run of rows inside one block ---------------------------------------------------------
@njit(cache=True, inline="always")
def _adler_bytes(row: np.ndarray, phase: int, n: int, a: int, b: int) -> tuple[int, int]:
    """Adler-32 sums (a, b) after n bytes of the periodic ``row`` from byte ``phase``."""
    rec = row.shape[0]
    for t in range(n):
        a = (a + row[(phase + t) % rec]) % ADLER_MOD
        b = (b + a) % ADLER_MOD
    return a, b


@njit(cache=True)
def _adler_periods(row: np.ndarray, m: int, a: int, b: int) -> tuple[int, int]:
    """Adler-32 sums after m whole rows, in closed form: appending x_1..x_L adds Σx to a and
    L·a + Σ (L − i + 1) x_i to b."""
    rec = row.shape[0]
    s, j = 0, 0
    for k in range(rec):
        s += row[k]
        j += (k + 1) * row[k]
    length = m * rec
    w = m * (length + 1) * s - rec * s * (m * (m - 1) // 2) - m * j
    b = (b + (length % ADLER_MOD) * a + w % ADLER_MOD) % ADLER_MOD
    a = (a + (m * s) % ADLER_MOD) % ADLER_MOD
    return a, b


@njit(cache=True)
def _run_tokens(out: np.ndarray, state: np.ndarray, row: np.ndarray, phase: int,
                n: int) -> None:
    """The symbols of n bytes of the periodic ``row`` from byte ``phase``, at the start of
    their run in this block: one row of literals, then copies one row back."""
    rec = row.shape[0]
    lit = min(rec, n)
    for t in range(lit):
        _put_symbol(out, state, np.int64(row[(phase + t) % rec]))
    left = n - lit
    while left >= 3:
        length = min(MAX_MATCH, left)
        if 0 < left - length < 3:            # leave at least 3 bytes for the last copy
            length = left - 3
        _put_copy(out, state, length, rec)
        left -= length
    for t in range(left):                  # 1 or 2 bytes: literals
        _put_symbol(out, state, np.int64(row[(phase + n - left + t) % rec]))


@njit(cache=True)
def _block(out: np.ndarray, rows: np.ndarray, starts: np.ndarray, lo: int, hi: int,
           first: int) -> tuple[int, int]:
    """Write the zlib stream of bytes [lo, hi) of the repeated rows into ``out``; ``starts``
    (R+1,) the byte where each run begins, ``first`` the run holding byte lo.  Returns (bytes
    written, the run holding byte hi)."""
    rec = rows.shape[1]
    state = np.zeros(3, np.int64)
    out[0], out[1] = 0x78, 0x01            # deflate, 32 KiB window, fastest, no dictionary
    state[2] = 2
    _put(out, state, 1, 1)                 # the final block
    _put(out, state, 1, 2)                 # fixed Huffman codes
    a, b = np.int64(1), np.int64(0)     # not literals: one specialisation of the sums
    r = first
    pos = lo
    while pos < hi:
        while starts[r + 1] <= pos:        # runs of no rows
            r += 1
        end = min(hi, starts[r + 1])
        phase = (pos - starts[r]) % rec
        row = rows[r]
        _run_tokens(out, state, row, phase, end - pos)
        head = min(end - pos, (rec - phase) % rec)
        a, b = _adler_bytes(row, phase, head, a, b)
        m = (end - pos - head) // rec
        a, b = _adler_periods(row, m, a, b)
        a, b = _adler_bytes(row, 0, end - pos - head - m * rec, a, b)
        pos = end
    _put_symbol(out, state, 256)           # end of block
    _put(out, state, 0, (8 - state[1]) % 8)
    k = state[2]
    for shift in (24, 16, 8, 0):           # Adler-32, most significant byte first
        out[k] = ((b << 16 | a) >> shift) & 0xFF
        k += 1
    return k, r


@njit(cache=True)
def _blocks(rows: np.ndarray, counts: np.ndarray, block: int) -> tuple[np.ndarray, np.ndarray]:
    """All blocks one after the other (uint8) and each block's compressed size."""
    rec = rows.shape[1]
    n_runs = rows.shape[0]
    starts = np.zeros(n_runs + 2, np.int64)
    for r in range(n_runs):
        starts[r + 1] = starts[r] + counts[r] * rec
    total = starts[n_runs]
    starts[n_runs + 1] = total + 1         # a sentinel past the end
    n_blocks = (total + block - 1) // block
    sizes = np.zeros(n_blocks, np.int64)
    worst = 2 + 1 + (9 * block + 7) // 8 + 4 + 8     # all literals of 9 bits
    out = np.empty(max(n_blocks, 1) * worst, np.uint8)
    used = 0
    r = np.int64(0)             # not a literal: one specialisation of _block
    for k in range(n_blocks):
        lo = k * block
        hi = min(total, lo + block)
        size, r = _block(out[used:used + worst], rows, starts, lo, hi, r)
        sizes[k] = size
        used += size
    return out[:used], sizes


def encode_repeated(values: np.ndarray, counts: np.ndarray, block: int = 32768) -> list[bytes]:
    """The pieces of a VTK appended DataArray (see :func:`nurbsdem.io.vtu.encode`) holding
    ``np.repeat(values, counts, axis=0)``: row k of ``values`` (any dtype) ``counts[k]``
    times; ``block`` uncompressed bytes per zlib stream.  A row may have at most 32768
    bytes (deflate's window)."""
    v = np.ascontiguousarray(values)
    n = v.shape[0] if v.ndim else 1
    width = int(np.prod(v.shape[1:], dtype=np.int64)) * v.itemsize
    rows = v.reshape(-1).view(np.uint8).reshape(n, width)
    if rows.shape[1] > MAX_DIST:
        raise ValueError(f"rows of {rows.shape[1]} bytes: deflate reaches {MAX_DIST} back")
    counts = np.asarray(counts, np.int64).reshape(-1)
    if counts.shape[0] != n or (counts < 0).any():
        raise ValueError("counts: one non-negative count per row")
    if rows.shape[1] == 0:
        rows, counts = np.zeros((0, 1), np.uint8), np.zeros(0, np.int64)
    data, sizes = _blocks(rows, counts, int(block))
    total = int(counts.sum()) * rows.shape[1]
    last = total - (len(sizes) - 1) * block if len(sizes) else 0
    header = np.concatenate([[len(sizes), block, last], sizes]).astype(np.uint32)
    return [header.tobytes(), data.tobytes()]

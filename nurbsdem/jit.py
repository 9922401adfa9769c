"""How the hot compiled kernels are compiled.

numba counts references to every array it handles (its runtime, NRT): each view a kernel
takes of a workspace row (``wf[_PA]``) or a shape table (``tab[6]``) is an atomic increment
and decrement, also inside a kernel called from a loop.  In the contact problem those atomic
operations took about a third of a warm LCP's time on one thread (``perf`` on a batch of the
paper example's compaction; the batch 1.5 x faster without them, same bits), and two threads
share the shape tables' counters.  A kernel that creates no array needs no counts:
:func:`kernel` compiles it without the runtime.  A kernel that allocates (``np.zeros`` …)
keeps plain ``njit`` (numba refuses to compile an allocation here: the error names it).
"""
from __future__ import annotations

from typing import Callable

from numba import njit


def kernel(func: Callable | None = None, *, inline: str = "never"):
    """``numba.njit(cache=True)`` without reference counting, for kernels that take views of
    arrays passed in but create none (usable bare, ``@kernel``, or ``@kernel(inline=...)``)."""
    jit = njit(cache=True, _nrt=False, inline=inline)
    return jit(func) if func is not None else jit

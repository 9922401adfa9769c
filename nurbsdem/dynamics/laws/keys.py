"""The deck keys of a contact law: spelling, unit, valid range and the reason for the range.

A law lists its keys (:attr:`LawKey`); the one Interface front-end
(:func:`nurbsdem.dynamics.laws.interface.build_interface`, called by the deck reader and by
:meth:`nurbsdem.Simulation.add_interface`) checks every value against its key's range with
the same message, and the law reads them from the :class:`~nurbsdem.model.Interface`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class LawKey:
    """One key of a law's ``Interface`` entry.

    deck: the deck's spelling (``NormalPenalty``); attr: the Interface attribute and the Python
    argument (``normal_penalty``); unit; lo, hi: the valid range, ``lo_open`` / ``hi_open``
    whether the bound itself is excluded; reason: why values outside are refused; required:
    the entry must give it (else ``default``); written_at_default: see below."""

    deck: str
    attr: str
    unit: str
    lo: float
    reason: str
    lo_open: bool = False
    hi: float = math.inf
    hi_open: bool = False
    required: bool = False
    default: float = 0.0
    #: whether a deck written back (:func:`~.interface.interface_text`) names the key when it
    #: holds its default (False for an optional extra such as RollingFriction: a deck without
    #: it is written as it was)
    written_at_default: bool = True

    def range_text(self) -> str:
        """``must be > 0`` / ``must be >= 0`` / ``must lie in (0, 1]``."""
        if math.isinf(self.hi):
            return f"must be {'>' if self.lo_open else '>='} {self.lo:g}"
        return (f"must lie in {'(' if self.lo_open else '['}{self.lo:g}, {self.hi:g}"
                f"{')' if self.hi_open else ']'}")

    def admits(self, value: float) -> bool:
        """Whether value lies in the key's range (NaN never does)."""
        above = value > self.lo if self.lo_open else value >= self.lo
        below = value < self.hi if self.hi_open else value <= self.hi
        return bool(above and below)

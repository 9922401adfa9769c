"""Contact laws as units, and the registry the engine dispatches through.

A law is one module of this package (:mod:`.linear_penalty`, :mod:`.hertz_mindlin`) holding

* a frozen dataclass (``LinearPenalty``, ``HertzMindlin``): its deck name, its ``code`` (the
  value of its rows' MODEL column), its deck keys with their valid ranges and the reasons
  (:class:`~.keys.LawKey`), ``from_interface`` (the law of an
  :class:`~nurbsdem.model.Interface` between two materials) and ``as_row`` (its row of the
  interface table, :mod:`.table`);
* two compiled functions, inlined into the force kernel (:mod:`nurbsdem.dynamics.forces`):
  ``normal(table, ma, mb, d, radius, imass)`` -> (k_n, c_n, k_t, c_t, elastic normal force,
  normal elastic energy) — the tangent stiffnesses and dampings are also what the time-step
  control reads per contact — and ``spring_scale(table, ma, mb, d, ddot, h, radius)`` ->
  (whether, factor) on the tangential spring before its increment.

The normal clip at 0, the tangential spring, its dashpot, the Coulomb return mapping and the
tangential elastic energy ½ k_t |s|² are common to all laws (the kernel's shared part).

:data:`LAWS` (deck name -> law) and :data:`LAWS_BY_CODE` (code -> law) are the registry.
:func:`law_normal` and :func:`law_spring_scale` dispatch on the row's code to the built-in
laws; they are compiled once and cached.  A law added at run time with :func:`register`
(docs/extending.md) gets the next code and its own copy of the force kernels
(:func:`nurbsdem.dynamics.laws.engine.engine_kernels`), compiled on first use without the
on-disk cache.
"""
from __future__ import annotations

import types

import numpy as np
from numba import njit

from . import hertz_mindlin, linear_penalty
from .hertz_mindlin import HertzMindlin
from .linear_penalty import LinearPenalty
from .table import MODEL, RF, InterfaceTable, codes_of

#: the built-in laws, their modules in code order
BUILTIN = (linear_penalty, hertz_mindlin)
#: deck name -> law class
LAWS: dict[str, type] = {LinearPenalty.name: LinearPenalty, HertzMindlin.name: HertzMindlin}
#: code (MODEL column) -> law class
LAWS_BY_CODE: dict[int, type] = {law.code: law for law in LAWS.values()}
#: code -> the module (or namespace) with the law's compiled ``normal`` and ``spring_scale``
KERNELS_BY_CODE: dict[int, object] = {m.CODE: m for m in BUILTIN}
#: the codes the cached kernels dispatch to
BUILTIN_CODES = frozenset(KERNELS_BY_CODE)


@njit(cache=True, inline="always")
def law_normal(table, ma, mb, d, radius, imass):
    """The normal part of the law of row table[ma, mb] (each law's ``normal``); a row of an
    unknown code (NaN: no interface) takes the linear law's."""
    if table[ma, mb, MODEL] == hertz_mindlin.CODE:
        return hertz_mindlin.normal(table, ma, mb, d, radius, imass)
    return linear_penalty.normal(table, ma, mb, d, radius, imass)


@njit(cache=True, inline="always")
def law_spring_scale(table, ma, mb, d, ddot, h, radius):
    """The tangential spring's factor of the law of row table[ma, mb] (each law's
    ``spring_scale``)."""
    if table[ma, mb, MODEL] == hertz_mindlin.CODE:
        return hertz_mindlin.spring_scale(table, ma, mb, d, ddot, h, radius)
    return linear_penalty.spring_scale(table, ma, mb, d, ddot, h, radius)


def register(law: type, normal, spring_scale) -> int:
    """Add a law (a class with ``name``, ``keys``, ``needs_contact_radius``, ``as_row`` and
    ``from_interface`` as the built-in ones; its ``code`` is set here) with its compiled
    ``normal`` and ``spring_scale`` (njit functions of the built-in laws' signatures).
    Returns its code.  Registering a name again replaces that law (same code)."""
    old = LAWS.get(law.name)
    code = old.code if old is not None else max(LAWS_BY_CODE) + 1
    if code in BUILTIN_CODES:
        raise ValueError(f"{law.name} is a built-in law")
    law.code = code
    LAWS[law.name] = law
    LAWS_BY_CODE[code] = law
    KERNELS_BY_CODE[code] = types.SimpleNamespace(normal=normal, spring_scale=spring_scale)
    return code


def unregister(name: str) -> None:
    """Remove a law added by :func:`register`."""
    law = LAWS[name]
    if law.code in BUILTIN_CODES:
        raise ValueError(f"{name} is a built-in law")
    del LAWS[name], LAWS_BY_CODE[law.code], KERNELS_BY_CODE[law.code]


def law_named(name: str) -> type | None:
    """The law of a deck or Python name, case, ``-`` and ``_`` aside (``LinearPenalty``,
    ``linear_penalty``), or of its Interface ``model`` (``linear``, ``hertz``); else None."""
    key = str(name).lower().replace("-", "").replace("_", "")
    for law in LAWS.values():
        if key in (law.name.lower(), law.model.lower()):
            return law
    return None


def needs_contact_radius(table: np.ndarray) -> bool:
    """Whether a dense interface table (M, M, NCOL) has a row of a law that needs each
    contact's equivalent radius (Hertz–Mindlin: the exact curvatures)."""
    return any(LAWS_BY_CODE[c].needs_contact_radius for c in codes_of(table)
               if c in LAWS_BY_CODE)


def rolls(table: np.ndarray) -> bool:
    """Whether a dense interface table (M, M, NCOL) has a row with a rolling friction
    (:mod:`nurbsdem.dynamics.rolling`: the kernel then needs each contact's rolling radius)."""
    col = np.asarray(table)[..., RF]
    return bool(np.any(col[np.isfinite(col)] > 0.0))


def builtin_only(table: np.ndarray) -> bool:
    """Whether every row of the table is of a built-in law (the cached kernels and the
    compiled deck steps dispatch to these only)."""
    return codes_of(table) <= BUILTIN_CODES


__all__ = ["LAWS", "LAWS_BY_CODE", "BUILTIN", "LinearPenalty", "HertzMindlin", "InterfaceTable",
           "law_normal", "law_spring_scale", "register", "unregister", "law_named",
           "needs_contact_radius", "rolls", "builtin_only"]

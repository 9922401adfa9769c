"""The force kernels of an interface table: the cached ones of the built-in laws, or copies
that dispatch to the laws registered at run time as well (:func:`engine_kernels`).  Above
:mod:`nurbsdem.dynamics.forces` and :mod:`nurbsdem.dynamics.implicit`, whose kernels it
copies."""
from __future__ import annotations

import types

import numpy as np
from numba import njit

from .. import forces, implicit, step
from . import KERNELS_BY_CODE, builtin_only, linear_penalty
from .table import MODEL


_ENGINES: dict[tuple, types.SimpleNamespace] = {}


def engine_kernels(table: np.ndarray) -> types.SimpleNamespace:
    """The force kernels for a table: ``contact_loads`` (:func:`nurbsdem.dynamics.forces.
    contact_loads`), ``dashpots_of_evaluation`` (:func:`nurbsdem.dynamics.implicit.
    dashpots_of_evaluation`) and the internal step's ``contact_part``
    (:func:`nurbsdem.dynamics.step.contact_part`).  For the built-in laws the cached ones; with a registered law,
    copies of them whose dispatch includes it (compiled once per set of laws)."""
    if builtin_only(table):
        return types.SimpleNamespace(contact_loads=forces.contact_loads,
                                     dashpots_of_evaluation=implicit.dashpots_of_evaluation,
                                     contact_part=step.contact_part)
    laws = tuple(sorted((c, id(k.normal), id(k.spring_scale)) for c, k in KERNELS_BY_CODE.items()))
    if laws not in _ENGINES:
        _ENGINES[laws] = _rebuilt_kernels()
    return _ENGINES[laws]


def _dispatch_source(kind: str, args: str) -> str:
    """Source of a dispatch on the row's code over every registered law (linear default);
    ``F<code>`` names the law's function."""
    lines = [f"def law_{kind}(table, ma, mb, {args}):",
             "    code = table[ma, mb, MODEL]"]
    for code in sorted(KERNELS_BY_CODE):
        if code != linear_penalty.CODE:
            lines.append(f"    if code == {code}:")
            lines.append(f"        return F{code}(table, ma, mb, {args})")
    lines.append(f"    return F{linear_penalty.CODE}(table, ma, mb, {args})")
    return "\n".join(lines) + "\n"


def _rebuilt_kernels() -> types.SimpleNamespace:
    """Copies of the force kernels that call a dispatch over all registered laws: numba reads
    a kernel's globals when it compiles it, so each copy is the same code with the names of
    the functions it calls bound to their copies."""
    names = {}
    for kind, args in (("normal", "d, radius, imass"), ("spring_scale", "d, ddot, h, radius")):
        scope = {"MODEL": MODEL}
        scope.update({f"F{c}": getattr(k, kind) for c, k in KERNELS_BY_CODE.items()})
        exec(_dispatch_source(kind, args), scope)
        names[f"law_{kind}"] = njit(inline="always")(scope[f"law_{kind}"])
    for name in ("_contact_laws_range", "_contact_laws_threads", "contact_forces",
                 "contact_loads"):
        names[name] = _copy(getattr(forces, name), names)
    dashpots = _copy(implicit.dashpots_of_evaluation, {"contact_loads": names["contact_loads"]})
    part = _copy(step.contact_part, {"contact_loads": names["contact_loads"],
                                     "dashpots_of_evaluation": dashpots})
    return types.SimpleNamespace(contact_loads=names["contact_loads"],
                                 dashpots_of_evaluation=dashpots, contact_part=part)


def _copy(kernel, rebind: dict):
    """An uncached copy of a numba kernel with some of its globals rebound."""
    fn = kernel.py_func
    scope = dict(fn.__globals__)
    scope.update(rebind)
    copy = types.FunctionType(fn.__code__, scope, fn.__name__, fn.__defaults__, fn.__closure__)
    options = {k: v for k, v in kernel.targetoptions.items() if k not in ("cache", "nopython")}
    return njit(**options)(copy)

"""The one front-end of the ``Interface`` entry: the deck reader (:mod:`nurbsdem.io.deck`) and
:meth:`nurbsdem.Simulation.add_interface` build an :class:`~nurbsdem.model.Interface` with
:func:`build_interface` and check that the interfaces cover every pair with
:func:`check_coverage`: one set of rules and messages.  A front-end says how it names the keys
(the deck's ``NormalPenalty``, Python's ``normal_penalty``) and how it raises (the deck with
file:line) through a :class:`Front`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Callable, NoReturn

from ...model import PAIR_KINDS, Interface, Model
from . import LAWS, law_named

#: the keys common to every law besides the law's own: which pairs the interface covers
COMMON_KEYS = ("Model", "Between", "Materials")
#: the law of an Interface entry without ``Model``
DEFAULT_LAW = "LinearPenalty"
#: Interface fields a law key may fill (the others go to ``Interface.params``)
_FIELDS = {f.name for f in fields(Interface)}


@dataclass(frozen=True)
class Front:
    """How a front-end names a key and raises.

    label: the entry in messages (``Interface 3`` / ``interface 3``); spell: a deck key ->
    the name the user wrote; fail(message): raises (the deck adds file:line)."""

    label: str
    spell: Callable[[str], str]
    fail: Callable[[str], NoReturn]


def python_name(key: str) -> str:
    """The Python argument of a deck key: ``NormalPenalty`` -> ``normal_penalty``."""
    return "".join("_" + c.lower() if c.isupper() and i else c.lower()
                   for i, c in enumerate(key))


def _owners(key: str) -> list[str]:
    return [law.name for law in LAWS.values() if any(k.deck == key for k in law.keys)]


def build_interface(iid: int, model: str | None, values: dict[str, float], between: str | None,
                    materials, front: Front, line: int = 0,
                    known_materials=None) -> Interface:
    """The :class:`~nurbsdem.model.Interface` ``iid`` of law ``model`` (a name of
    :func:`~nurbsdem.dynamics.laws.law_named`; None: LinearPenalty) with the law keys given
    in ``values`` (deck key -> number), ``between`` (None or one of
    :data:`~nurbsdem.model.PAIR_KINDS`) and ``materials`` (None, 2 ids: particle-particle, 1
    id: particle-wall).  Checks: the law exists, every key is the law's, its required keys are
    given, each value lies in its key's range (:class:`~.keys.LawKey`), Between and Materials
    agree, and (``known_materials`` given) the materials exist."""
    law = law_named(model if model is not None else DEFAULT_LAW)
    if law is None:
        front.fail(f"{front.label}: {front.spell('Model')} must be "
                   f"{' or '.join(LAWS)}, got {model!r}")
    keys = {k.deck: k for k in law.keys}
    for name in values:
        if name not in keys:
            owners = " or ".join(_owners(name)) or "no law"
            front.fail(f"{front.label}: {front.spell(name)} does not apply to a {law.name} "
                       f"interface ({law.note}); {front.spell(name)} applies to "
                       f"{front.spell('Model')} {owners} only")
    for k in law.keys:
        if k.required and k.deck not in values:
            front.fail(f"{front.label}: missing {front.spell(k.deck)}")
    vals = {k.attr: float(k.default) for k in law.keys}
    for name, value in values.items():
        k = keys[name]
        x = float(value)
        if not math.isfinite(x):
            front.fail(f"{front.label}: {front.spell(name)} must be a finite number, got {value!r}")
        if not k.admits(x):
            front.fail(f"{front.label}: {front.spell(name)} {k.range_text()}, got {x:g} "
                       f"({k.reason})")
        vals[k.attr] = x
    between, mats = _coverage(between, materials, front, known_materials)
    own = {a: v for a, v in vals.items() if a in _FIELDS}
    params = {a: v for a, v in vals.items() if a not in _FIELDS}
    normal_penalty = own.pop("normal_penalty", 0.0)
    return Interface(iid, normal_penalty, **own, between=between, materials=mats, line=line,
                     model=law.model, params=params)


def interface_text(itf: Interface, number: Callable[[float], str] = repr) -> str:
    """The deck words of an Interface's law: ``Interface ID [Model NAME] KEY value ...`` with
    the law's keys in its order (``Model`` left out for :data:`DEFAULT_LAW`); ``number``
    writes a value.  Between and Materials are the caller's."""
    law = law_named(itf.model)
    words = [f"Interface {itf.id}"] + ([] if law.name == DEFAULT_LAW else [f"Model {law.name}"])
    for k in law.keys:
        value = itf.params[k.attr] if k.attr in itf.params else getattr(itf, k.attr)
        if k.written_at_default or value != k.default:
            words.append(f"{k.deck} {number(value)}")
    return " ".join(words)


def _coverage(between, materials, front: Front, known_materials):
    """Between (lower case) and Materials (a tuple of ids) checked against each other."""
    if between is not None:
        if not isinstance(between, str) or between.lower() not in PAIR_KINDS:
            front.fail(f"{front.label}: {front.spell('Between')} must be particle-particle or "
                       f"particle-wall, got {between!r}")
        between = between.lower()
    mats = None
    if materials is not None:
        mats = tuple(int(m) for m in materials)
        kind = {2: "particle-particle", 1: "particle-wall"}.get(len(mats))
        if kind is None:
            front.fail(f"{front.label}: {front.spell('Materials')} takes 2 ids "
                       f"(particle-particle) or 1 (particle-wall), got {len(mats)}")
        if between is not None and between != kind:
            front.fail(f"{front.label}: {front.spell('Materials')} with {len(mats)} id(s) "
                       f"means {kind} pairs, but {front.spell('Between')} says {between}")
        if known_materials is not None:
            for m in mats:
                if m not in known_materials:
                    front.fail(f"{front.label}: unknown material {m}")
        between = kind
    return between, mats


def check_coverage(model: Model, fail: Callable[[str, int | None], NoReturn],
                   first_use: Callable[[int], int | None], spell: Callable[[str], str] = str,
                   hint: str = "") -> None:
    """Every pair of particle materials, and every particle material against the walls when
    there are walls, is covered by an interface, and the materials of the pairs that a law
    reading the materials covers (Hertz–Mindlin) have a YoungModulus.  ``fail(message,
    line)`` raises; ``first_use(material)``: the line where a material is first used (for
    an uncovered pair); ``spell``: the front-end's name of a deck word; ``hint`` ends the
    uncovered-pair message."""
    mats = sorted(model.particle_materials())
    pairs = [("particle-particle", (a, b)) for i, a in enumerate(mats) for b in mats[i:]]
    if model.walls and mats:
        pairs += [("particle-wall", (a,)) for a in mats]
    for kind, mm in pairs:
        itf = model.interface(kind, mm)
        if itf is None:
            what = " and ".join(map(str, mm))
            fail(f"no contact {spell('Interface')} covers {kind} pairs of material"
                 f"{'s' if len(mm) > 1 else ''} {what}{hint}", first_use(mm[-1]))
        law = law_named(itf.model)
        if law is not None and law.uses_materials:
            for mid in mm:
                mat = model.materials[mid]
                if mat.young_modulus is None:
                    where = f", line {mat.line}" if mat.line else ""
                    fail(f"Interface {itf.id} (Model {law.name}) covers material {mid}, which "
                         f"needs a YoungModulus (Material {mid}{where})", itf.line)

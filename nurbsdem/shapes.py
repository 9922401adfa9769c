"""Shape generators (public API): exact spheres and ellipsoids, the paper's particles, walls.

``nurbsdem.shapes.sphere(r)``, ``.ellipsoid(a, b, c)``, ``.single_patch_sphere(r)`` return
:class:`~nurbsdem.geometry.shape.Shape` objects; ``.flat_wall`` and ``.box_walls`` return
patches. See :mod:`nurbsdem.geometry.generators` and :mod:`nurbsdem.geometry.particles`.

The shape functions check their arguments as a deck's ``Shape`` entry does (the ranges of
:data:`nurbsdem.io.deck.RANGES` for ``Radius`` and ``SemiAxes``, the deck's largest aspect
ratio) and raise :class:`~nurbsdem.errors.InputError` with a one-line message.
"""
from __future__ import annotations

import math
from typing import Any

from .errors import InputError
from .geometry import generators as _gen
from .geometry import particles as _particles
from .geometry.generators import (box_walls, ellipsoid_patches, flat_wall,
                                  single_patch_sphere_patches, sphere_patches)


def _length(key: str, value: Any, what: str) -> float:
    """A finite length > 0 (m) in the deck's range of ``key``, else an InputError."""
    from .io.deck import _DeckError, check_range
    if isinstance(value, bool):
        raise InputError(f"{what}: {key} must be a number, got {value!r}")
    try:
        x = float(value)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{what}: {key} must be a number, got {value!r}") from None
    if not (math.isfinite(x) and x > 0):
        raise InputError(f"{what}: {key} must be a finite number > 0 (m), got {value!r}")
    try:
        check_range(key, x, f"{what}: ")
    except _DeckError as exc:
        raise InputError(str(exc)) from None
    return x


def sphere(radius: float, name: str | None = None):
    """Exact sphere of radius ``radius`` (m): six rational biquartic patches."""
    return _gen.sphere(_length("Radius", radius, "sphere"), name=name)


def single_patch_sphere(radius: float, name: str | None = None):
    """Exact single-patch sphere of radius ``radius`` (m), with poles and a seam."""
    return _gen.single_patch_sphere(_length("Radius", radius, "single_patch_sphere"), name=name)


def ellipsoid(a: float, b: float, c: float, name: str | None = None):
    """Exact ellipsoid with semi-axes a, b, c (m) along x, y, z."""
    from .ranges import ASPECT_MAX
    abc = [_length("SemiAxes", x, "ellipsoid") for x in (a, b, c)]
    if max(abc) > ASPECT_MAX * min(abc):
        raise InputError(f"ellipsoid: SemiAxes {max(abc) / min(abc):.3g} times longer than wide "
                         f"is beyond the {ASPECT_MAX:g} the contact search resolves")
    return _gen.ellipsoid(*abc, name=name)


def paper_particle(kind: str = "A"):
    """The patches of the paper's particle ``kind`` ("A", "B" or "C")."""
    return _particles.paper_particle(_paper_kind(kind))


def paper_particle_shape(kind: str = "A"):
    """The paper's particle ``kind`` ("A", "B" or "C") as a Shape."""
    return _particles.paper_particle_shape(_paper_kind(kind))


def _paper_kind(kind: Any) -> str:
    try:
        return _particles.particle_name(kind)
    except ValueError as exc:
        raise InputError(str(exc)) from None


__all__ = ["sphere", "ellipsoid", "single_patch_sphere", "sphere_patches", "ellipsoid_patches",
           "single_patch_sphere_patches", "flat_wall", "box_walls", "paper_particle",
           "paper_particle_shape"]

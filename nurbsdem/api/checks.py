"""The checks of :class:`~nurbsdem.simulation.Simulation`'s arguments: each value is checked as
the deck checks the same key (a number, finite, in the range of :data:`nurbsdem.ranges.RANGES`)
and a problem is an :class:`~nurbsdem.errors.InputError` with a one-line message that names
the entry (``what``) and the deck's key."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError

#: ``Model.path`` of a scene built in Python (its errors carry no file location).
PYTHON_SCENE = "<python>"


def strip_location(exc: InputError) -> InputError:
    """The same error without the pseudo file location of a scene built in Python."""
    if exc.path == PYTHON_SCENE:
        return InputError(exc.detail, where=exc.where)
    return exc


def shown(value: Any, limit: int = 60) -> str:
    """repr(value), cut to ``limit`` characters (a message stays one short line)."""
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def optional_path(value: Any, what: str) -> Any:
    """``value`` when it is None, a str or a path; else an :class:`InputError`."""
    if value is None or isinstance(value, (str, Path)):
        return value
    import os
    if isinstance(value, os.PathLike):
        return value
    raise InputError(f"{what} must be a folder or file path (str or pathlib.Path) or None, "
                     f"got {value!r}")


def number(key: str, value: Any, what: str, positive: bool = False,
           nonnegative: bool = False) -> float:
    """``value`` as a finite float in the deck's range of ``key`` (> 0 with ``positive``,
    >= 0 with ``nonnegative``)."""
    try:
        x = float(value)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{what}: {key} must be a number, got {shown(value)}") from None
    if not math.isfinite(x):
        raise InputError(f"{what}: {key} must be a finite number, got {value!r}")
    if positive and not x > 0:
        raise InputError(f"{what}: {key} must be > 0, got {x:g}")
    if nonnegative and x < 0:
        raise InputError(f"{what}: {key} must be >= 0, got {x:g}")
    in_range(key, x, what)
    return x


def in_range(key: str, value: Any, what: str) -> None:
    """Raise the deck's message when ``value`` lies outside the range of ``key``."""
    from ..io.deck import _DeckError, check_range
    try:
        check_range(key, value, f"{what}: ")
    except _DeckError as exc:
        raise InputError(str(exc)) from None


def vector(key: str, value: Any, what: str, n: int = 3) -> np.ndarray:
    """``value`` as ``n`` finite floats in the deck's range of ``key``."""
    try:
        v = np.array(value, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{what}: {key} must be {n} numbers, got {shown(value)}") from None
    if v.shape != (n,):
        raise InputError(f"{what}: {key} must be {n} numbers, got {shown(value)}")
    if not np.isfinite(v).all():
        raise InputError(f"{what}: {key} must be finite numbers, got {value!r}")
    in_range(key, v, what)
    return v


def periodic(x: Any, y: Any, z: Any, what: str = "set_periodic"):
    """The :class:`~nurbsdem.model.PeriodicSpec` of the intervals (lo, hi) (m) given per axis
    (None: the axis does not repeat), checked as the deck's ``Periodic`` entry."""
    from ..model import PeriodicSpec
    lo, hi, axes = np.zeros(3), np.zeros(3), np.zeros(3, bool)
    for k, (name, v) in enumerate(zip("XYZ", (x, y, z))):
        if v is None:
            continue
        lo[k], hi[k] = vector(name, v, what, n=2)
        axes[k] = True
        if not lo[k] < hi[k]:
            raise InputError(f"{what}: {name} needs lo < hi, got {lo[k]:g} {hi[k]:g}")
    if not axes.any():
        raise InputError(f"{what}: give at least one axis (x, y or z as (lo, hi))")
    return PeriodicSpec(lo, hi, axes)


def entity_id(value: Any, what: str) -> int:
    """An entry's id: an integer from 1 to the deck's largest id."""
    from ..io.deck import ID_MAX
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise InputError(f"{what}: id must be an integer >= 1, got {shown(value)}")
    if value > ID_MAX:
        raise InputError(f"{what}: id {shown(value)} is too large: ids are at most {ID_MAX:g} "
                         f"(as in a deck)")
    return int(value)


def rotvec_of_matrix(R: np.ndarray, what: str) -> np.ndarray:
    """The rotation vector (rad) of a proper rotation matrix (3, 3)."""
    if not np.isfinite(R).all() or not np.allclose(R @ R.T, np.eye(3), atol=1e-9) \
            or not np.linalg.det(R) > 0:
        raise InputError(f"{what}: rotation must be a rotation vector (3,) or a proper "
                         f"rotation matrix (3, 3)")
    from scipy.spatial.transform import Rotation
    return Rotation.from_matrix(R).as_rotvec()


def output_settings(vtk_every: Any, vtk_resolution: Any, monitors_every: Any,
                    results_every: Any, checkpoint_every: Any) -> None:
    """The ``Output`` settings: intervals > 0 (s) in the deck's range, the resolution an
    integer from 1 to 10 000 (quads per patch direction)."""
    for key, val in (("Every", vtk_every), ("Every", monitors_every),
                     ("Every", checkpoint_every)) + ((("Every", results_every),)
                                                    if results_every is not None else ()):
        number(key, val, "an output interval", positive=True)
    if not (isinstance(vtk_resolution, (int, np.integer)) and 1 <= vtk_resolution <= 10 ** 4):
        raise InputError(f"vtk_resolution must be an integer between 1 and 10000, got "
                         f"{vtk_resolution!r}")


def _contact_option_defaults() -> dict[str, Any]:
    """The keywords :class:`~nurbsdem.contact.scene.SceneContacts` takes from
    ``contact_options``, with their defaults (its own signature)."""
    import inspect
    from ..contact.scene import SceneContacts
    params = inspect.signature(SceneContacts.__init__).parameters
    return {k: p.default for k, p in params.items()
            if p.default is not inspect.Parameter.empty and k != "walls"}


def solver_options(options: dict[str, Any]) -> dict[str, Any]:
    """The solver's keywords checked as a deck checks its values: ``safety`` in the deck's
    ``Safety`` range, ``contact_options`` a dict of :class:`SceneContacts` keywords (booleans
    for its switches, finite lengths >= 0 in m for the others); raises :class:`InputError`."""
    out = dict(options)
    if out.get("safety") is not None:
        out["safety"] = number("Safety", out["safety"], "safety", positive=True)
    opts = out.get("contact_options")
    if opts is None:
        return out
    if not isinstance(opts, dict):
        raise InputError(f"contact_options must be a dict of keywords, got {opts!r}")
    known = _contact_option_defaults()
    checked = {}
    for key, value in opts.items():
        if key not in known:
            raise InputError(f"contact_options: unknown keyword {key!r} (known: "
                             f"{', '.join(sorted(known))})")
        if isinstance(known[key], bool):
            if not isinstance(value, (bool, np.bool_)):
                raise InputError(f"contact_options: {key} must be True or False, got {value!r}")
            checked[key] = bool(value)
        elif value is None and known[key] is None:
            checked[key] = None
        else:
            checked[key] = number(key, value, "contact_options", nonnegative=True)
    out["contact_options"] = checked
    return out


def solver_keywords(options: dict[str, Any]) -> dict[str, Any]:
    """:meth:`~nurbsdem.simulation.Simulation.from_deck`'s solver keywords: each one a keyword
    of :class:`~nurbsdem.solver.Solver` that a deck does not set, checked by
    :func:`solver_options`."""
    import inspect
    from ..solver import Solver
    known = set(inspect.signature(Solver.__init__).parameters) - {"self", "model", "output",
                                                                  "restart", "quiet"}
    for key in options:
        if key not in known:
            raise InputError(f"from_deck: unknown keyword {key!r} (solver options: "
                             f"{', '.join(sorted(known))})")
    return solver_options(options)

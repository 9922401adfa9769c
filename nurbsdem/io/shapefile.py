"""Shape files: YAML, SI units (metres).

::

    name: A                      # optional
    patches:
      - degree_u: 3
        degree_v: 3
        knots_u: [0, 0, 0, 0, 0.667, 1.333, 2, 2, 2, 2]
        knots_v: [...]
        control_points:          # n_u rows of n_v [x, y, z]
          - [[x, y, z], [x, y, z], ...]
        weights:                 # optional, n_u rows of n_v numbers, default 1
          - [1, 1, ...]

The loader is strict where PyYAML's default is lax: every float notation (``1e-3``,
``.5``, ``1E+3``) loads as a float, and a duplicate key is an error naming the line.
Writing uses ``repr`` of each float, so a write/read round trip is exact.
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..errors import InputError
from ..geometry.kernel import MAX_DEGREE
from ..geometry.nurbs import Patch

_FLOAT_RE = re.compile(r"""^[-+]?(?:
      (?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
    | \.[0-9_]+(?:[eE][-+]?[0-9]+)?
    | [0-9][0-9_]*[eE][-+]?[0-9]+
    | \.(?:inf|Inf|INF)
    | \.(?:nan|NaN|NAN))$""", re.X)


class StrictLoader(yaml.SafeLoader):
    """SafeLoader that reads every float notation as float and rejects duplicate keys."""


StrictLoader.yaml_implicit_resolvers = {
    k: [r for r in v if r[0] != "tag:yaml.org,2002:float"]
    for k, v in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
StrictLoader.add_implicit_resolver("tag:yaml.org,2002:float", _FLOAT_RE,
                                   list("-+0123456789."))


def _construct_mapping(loader: StrictLoader, node: yaml.MappingNode, deep: bool = False) -> dict:
    loader.flatten_mapping(node)
    out: dict = {}
    for key_node, value_node in node.value:
        key = loader.construct_object(key_node, deep=deep)
        if key in out:
            raise yaml.constructor.ConstructorError(
                None, None, f"duplicate key {key!r}", key_node.start_mark)
        out[key] = loader.construct_object(value_node, deep=deep)
    return out


StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


#: Deepest nesting a shape file may have (a patch needs 4 levels: patches, points, row, xyz).
MAX_NESTING = 32
#: Largest coordinate (m) and knot value a shape file may hold.
COORD_MAX = 1e6
#: Largest ratio of the largest to the smallest weight of a patch.
WEIGHT_RATIO_MAX = 1e12
#: Most control points of one patch (memory and evaluation cost).
MAX_CONTROL_POINTS = 10 ** 6


class _Composer(yaml.composer.Composer):
    """Composes nodes with a nesting limit and without aliases (``*ref``: exponential
    expansion), so that any text is answered quickly."""


def _compose_node(self, parent, index):
    if self.check_event(yaml.events.AliasEvent):
        event = self.peek_event()
        raise yaml.composer.ComposerError(None, None, "YAML aliases (*name) are not supported "
                                          "in shape files", event.start_mark)
    depth = getattr(self, "_nurbsdem_depth", 0)
    if depth >= MAX_NESTING:
        raise yaml.composer.ComposerError(None, None, f"nested deeper than {MAX_NESTING} levels",
                                          self.peek_event().start_mark)
    self._nurbsdem_depth = depth + 1
    try:
        return yaml.composer.Composer.compose_node(self, parent, index)
    finally:
        self._nurbsdem_depth = depth


StrictLoader.compose_node = _compose_node  # type: ignore[method-assign]


def not_a_file(path: str | Path) -> str | None:
    """Why ``path`` cannot be read as a file ("no such file", "is a folder, not a file",
    ...), or None when it is a regular file (or a link to one)."""
    p = Path(path)
    if p.is_file():
        return None
    if p.is_dir():
        return "is a folder, not a file"
    if p.exists():
        return "is not a regular file"
    if p.is_symlink():
        return "is a broken link"
    return "no such file"


def read_text_file(path: str | Path) -> str:
    """The text of a UTF-8 file (a byte-order mark is allowed); :class:`InputError` when it
    cannot be read or is not UTF-8 text."""
    path = str(path)
    why = not_a_file(path)
    if why is not None and why.startswith("is "):
        raise InputError(f"cannot read file: it {why}", path=path)
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read file: {exc.strerror or exc}", path=path) from None
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[:exc.start].count(b"\n") + 1
        raise InputError(f"not a UTF-8 text file (byte 0x{data[exc.start]:02x} at offset "
                         f"{exc.start})", path=path, line=line) from None
    if "\x00" in text:
        raise InputError("not a text file (it contains NUL bytes)", path=path,
                         line=text[:text.index("\x00")].count("\n") + 1)
    return text


def parse_yaml_text(text: str, path: str) -> Any:
    """Parse YAML text strictly; errors are :class:`InputError` with file and line."""
    try:
        return yaml.load(text, Loader=StrictLoader)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = mark.line + 1 if mark is not None else None
        msg = exc.problem or str(exc)
        if exc.context and "duplicate" not in msg:
            msg = f"{exc.context}, {msg}"
        raise InputError(msg, path=path, line=line) from None
    except yaml.YAMLError as exc:
        raise InputError(f"invalid YAML: {' '.join(str(exc).split())}", path=path) from None
    except RecursionError:
        raise InputError(f"nested too deeply (at most {MAX_NESTING} levels)", path=path) from None
    except (ValueError, OverflowError) as exc:   # e.g. an integer of 5000 digits
        raise InputError(f"invalid value: {' '.join(str(exc).split())}", path=path) from None


def load_yaml(path: str | Path) -> Any:
    """Parse a YAML file strictly; errors are :class:`InputError` with file and line."""
    return parse_yaml_text(read_text_file(path), str(path))


def _all_numbers(value: Any) -> bool:
    """True if every leaf of a nested list is an int or float (not bool)."""
    if isinstance(value, list):
        return all(_all_numbers(v) for v in value)
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _number_array(value: Any, path: str, where: str, field: str, ndim: int) -> np.ndarray:
    if not _all_numbers(value):
        # strings such as '1' and booleans would otherwise be converted silently
        raise InputError(f"{field} must contain only numbers", path=path, where=where)
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{field} has rows of different lengths (it must be a "
                         f"{ndim}-level nested list of equal-length rows)",
                         path=path, where=where) from None
    if arr.ndim != ndim:
        raise InputError(f"{field} must be a {ndim}-level nested list of numbers "
                         f"(got {arr.ndim} levels)", path=path, where=where)
    return arr


_PATCH_KEYS = {"degree_u", "degree_v", "knots_u", "knots_v", "control_points", "weights"}


def patches_from_data(data: Any, path: str) -> tuple[list[Patch], str | None]:
    """Build patches from parsed YAML data (see module docstring); validates each patch."""
    if not isinstance(data, dict) or "patches" not in data:
        raise InputError("a shape file must be a mapping with a 'patches' list", path=path)
    unknown = set(data) - {"patches", "name"}
    if unknown:
        raise InputError(f"unknown key {sorted(unknown)[0]!r} (expected 'name', 'patches')", path=path)
    name = data.get("name")
    if name is not None and not isinstance(name, (str, int)):
        raise InputError("name must be a string", path=path)
    plist = data["patches"]
    if not isinstance(plist, list) or not plist:
        raise InputError("'patches' must be a non-empty list", path=path)
    patches = []
    for i, pd in enumerate(plist):
        where = f"patch {i}"
        if not isinstance(pd, dict):
            raise InputError("a patch must be a mapping", path=path, where=where)
        missing = sorted(_PATCH_KEYS - {"weights"} - set(pd))
        if missing:
            raise InputError(f"missing key {missing[0]!r}", path=path, where=where)
        extra = sorted(set(pd) - _PATCH_KEYS)
        if extra:
            raise InputError(f"unknown key {extra[0]!r}", path=path, where=where)
        for key in ("degree_u", "degree_v"):
            if not isinstance(pd[key], int) or isinstance(pd[key], bool):
                raise InputError(f"{key} must be an integer, got {pd[key]!r}", path=path, where=where)
            if pd[key] > MAX_DEGREE:
                raise InputError(f"{key} must be at most {MAX_DEGREE}, got {pd[key]}",
                                 path=path, where=where)
        cp = _number_array(pd["control_points"], path, where, "control_points", 3)
        w = None
        if pd.get("weights") is not None:
            w = _number_array(pd["weights"], path, where, "weights", 2)
        patch = Patch(pd["degree_u"], pd["degree_v"],
                      _number_array(pd["knots_u"], path, where, "knots_u", 1),
                      _number_array(pd["knots_v"], path, where, "knots_v", 1), cp, w)
        patch.validate(path, i)
        patches.append(patch)
    return patches, (str(name) if name is not None else None)


def check_patch_numbers(patch: Patch, path: str, where: str, line: int | None = None) -> None:
    """Refuse numbers a valid patch may hold but nurbsdem cannot compute with: coordinates
    and knots beyond :data:`COORD_MAX`, weights spread beyond :data:`WEIGHT_RATIO_MAX`, more
    than :data:`MAX_CONTROL_POINTS` control points, degrees above the kernel's maximum."""
    def fail(msg: str) -> None:
        raise InputError(msg, path=path, line=line, where=where)

    cp = np.asarray(patch.control_points, float)
    if cp.shape[0] * cp.shape[1] > MAX_CONTROL_POINTS:
        fail(f"{cp.shape[0]} x {cp.shape[1]} control points are more than {MAX_CONTROL_POINTS:g}")
    for deg in (patch.degree_u, patch.degree_v):
        if deg > MAX_DEGREE:
            fail(f"degree {deg} is above the largest supported degree {MAX_DEGREE}")
    big = float(np.abs(cp).max()) if cp.size else 0.0
    if big > COORD_MAX:
        fail(f"a control point coordinate is {big:.3g} m, beyond {COORD_MAX:g} m (float64 "
             f"geometry that far out cannot resolve contacts at particle scale)")
    for name, knots in (("knots_u", patch.knots_u), ("knots_v", patch.knots_v)):
        k = np.asarray(knots, float)
        if float(np.abs(k).max()) > COORD_MAX:
            fail(f"{name} holds {float(np.abs(k).max()):.3g}, beyond {COORD_MAX:g}")
        if (k[-1] - k[0]) < 1e-12 * max(1.0, float(np.abs(k).max())):
            fail(f"{name} spans a parameter range too small to compute with")
    w = np.asarray(patch.weights, float)
    if w.size and float(w.max()) > WEIGHT_RATIO_MAX * float(w.min()):
        fail(f"weights range from {float(w.min()):.3g} to {float(w.max()):.3g}, a ratio above "
             f"{WEIGHT_RATIO_MAX:g}")


def read_patches(path: str | Path) -> tuple[list[Patch], str | None]:
    """Read the patches and name of a shape file (no closedness/convexity check)."""
    return patches_from_data(load_yaml(path), str(path))


def load_shape(path: str | Path, check: bool = True, convexity_tol: float | None = None):
    """Load a shape file into a :class:`~nurbsdem.geometry.shape.Shape`.

    Errors (syntax, bad patch data, open or non-convex shape) are :class:`InputError`
    naming the file and the line or patch. ``convexity_tol``: accepted non-convexity
    relative to the size (default: :data:`~nurbsdem.geometry.connectivity.DEFAULT_CONVEXITY_TOL`).
    """
    from ..geometry.shape import Shape

    patches, name = read_patches(path)
    for i, p in enumerate(patches):
        check_patch_numbers(p, str(path), f"patch {i}")
    return shape_or_input_error(
        lambda: Shape(patches, name=name, source=str(path), check=check,
                      convexity_tol=convexity_tol), str(path))


def shape_or_input_error(make, path: str):
    """``make()`` (a Shape built from file data); numerical failures of degenerate data
    (singular matrices, overflow, hull errors) become one :class:`InputError` for the file."""
    from scipy.spatial import QhullError

    try:
        return make()
    except InputError:
        raise
    except (ValueError, ArithmeticError, np.linalg.LinAlgError, QhullError) as exc:
        raise InputError(f"the surface is degenerate and cannot be used "
                         f"({type(exc).__name__}: {' '.join(str(exc).split())[:160]})",
                         path=path) from None


def _floats(arr: np.ndarray) -> Any:
    """Nested lists of Python floats (repr round-trips exactly)."""
    return np.asarray(arr, dtype=float).tolist()


def shape_to_data(patches, name: str | None = None) -> dict:
    """The YAML-ready mapping of a list of patches."""
    data: dict = {}
    if name is not None:
        data["name"] = name
    data["patches"] = []
    for p in patches:
        pd = {"degree_u": int(p.degree_u), "degree_v": int(p.degree_v),
              "knots_u": _floats(p.knots_u), "knots_v": _floats(p.knots_v),
              "control_points": _floats(p.control_points)}
        if not np.all(p.weights == 1.0):
            pd["weights"] = _floats(p.weights)
        data["patches"].append(pd)
    return data


class _FlowDumper(yaml.SafeDumper):
    """Dumper that writes innermost lists (points, knot vectors) on one line."""


def _represent_list(dumper: yaml.SafeDumper, data: list):
    flow = all(not isinstance(x, (list, dict)) for x in data)
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flow)


_FlowDumper.add_representer(list, _represent_list)


def save_shape(path: str | Path, patches_or_shape, name: str | None = None) -> None:
    """Write a shape file (atomically: a temporary file renamed into place)."""
    from .atomic import atomic_write_text

    patches = getattr(patches_or_shape, "patches", patches_or_shape)
    if name is None:
        name = getattr(patches_or_shape, "name", None)
    text = yaml.dump(shape_to_data(patches, name), Dumper=_FlowDumper, sort_keys=False,
                     width=200)
    atomic_write_text(path, text)

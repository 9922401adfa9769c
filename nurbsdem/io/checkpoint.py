"""Checkpoints: a nested dict of arrays and scalars in one HDF5 file, written atomically.

:func:`save_checkpoint` writes to a temporary file next to the target, fsyncs it, renames it
onto the target (``os.replace``) and fsyncs the folder, so a run killed at any moment leaves
either the previous checkpoint or the new one, complete. :func:`load_checkpoint` returns
exactly what was saved:

========================  =============================================================
saved value               loaded back as
========================  =============================================================
dict (str or int keys)    dict, same keys in the same order
list, tuple               list, tuple
numpy array               numpy array, same dtype (incl. byte order, bool, unicode,
                          structured, datetime), same shape (incl. empty)
numpy scalar              numpy scalar of the same dtype
bool, int, float,         the same Python type (ints of any size)
complex, str, bytes, None
========================  =============================================================

Object arrays and other types raise ``TypeError``; a str key containing ``/`` or starting
with ``__`` raises ``ValueError``.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .atomic import ensure_space, write_hdf5_atomically

FORMAT = "nurbsdem-checkpoint-1"
_KIND = "__kind__"
_RAW_DTYPE_KINDS = "UMmV"  # stored as raw bytes + dtype string (h5py lacks them or may alter)


def _check_key(key: Any) -> str:
    if isinstance(key, bool) or not isinstance(key, (str, int, np.integer)):
        raise TypeError(f"checkpoint keys must be str or int, got {type(key).__name__}")
    if isinstance(key, str):
        if "/" in key or key.startswith("__") or key in ("", "."):
            raise ValueError(f"invalid checkpoint key {key!r}")
    return str(key)


def _write(parent, name: str, value: Any) -> None:
    """Store ``value`` under ``parent[name]`` (h5py group), tagged with its kind."""
    if isinstance(value, Mapping):
        g = parent.create_group(name, track_order=True)
        keys = list(value.keys())
        int_keys = bool(keys) and all(isinstance(k, (int, np.integer)) and not isinstance(k, bool)
                                      for k in keys)
        if not int_keys and any(not isinstance(k, str) for k in keys):
            raise TypeError(f"checkpoint dict {name!r}: keys must be all str or all int")
        g.attrs[_KIND] = "dict_int" if int_keys else "dict"
        for k in keys:
            _write(g, _check_key(k), value[k])
        return
    if isinstance(value, (list, tuple)):
        g = parent.create_group(name, track_order=True)
        g.attrs[_KIND] = "list" if isinstance(value, list) else "tuple"
        for i, item in enumerate(value):
            _write(g, str(i), item)
        return
    if isinstance(value, np.ndarray):
        _write_array(parent, name, value, "ndarray")
        return
    if isinstance(value, np.generic):
        _write_array(parent, name, np.asarray(value), "npscalar")
        return
    if value is None:
        ds = parent.create_dataset(name, data=np.zeros(0, np.uint8))
        ds.attrs[_KIND] = "none"
        return
    if isinstance(value, bool):
        ds = parent.create_dataset(name, data=np.bool_(value))
        ds.attrs[_KIND] = "bool"
        return
    if isinstance(value, int):
        if -2 ** 63 <= value < 2 ** 63:
            ds = parent.create_dataset(name, data=np.int64(value))
            ds.attrs[_KIND] = "int"
        else:
            ds = parent.create_dataset(name, data=np.frombuffer(str(value).encode(), np.uint8))
            ds.attrs[_KIND] = "bigint"
        return
    if isinstance(value, float):
        ds = parent.create_dataset(name, data=np.float64(value))
        ds.attrs[_KIND] = "float"
        return
    if isinstance(value, complex):
        ds = parent.create_dataset(name, data=np.complex128(value))
        ds.attrs[_KIND] = "complex"
        return
    if isinstance(value, (str, bytes)):
        raw = value.encode("utf-8") if isinstance(value, str) else value
        ds = parent.create_dataset(name, data=np.frombuffer(raw, np.uint8))
        ds.attrs[_KIND] = "str" if isinstance(value, str) else "bytes"
        return
    raise TypeError(f"cannot store {type(value).__name__} in a checkpoint ({name!r})")


def _write_array(parent, name: str, arr: np.ndarray, kind: str) -> None:
    if arr.dtype.hasobject:
        raise TypeError(f"cannot store an object array in a checkpoint ({name!r})")
    if arr.dtype.kind in _RAW_DTYPE_KINDS:
        data = np.frombuffer(np.ascontiguousarray(arr).tobytes(), np.uint8)
        ds = parent.create_dataset(name, data=data)
        ds.attrs[_KIND] = kind + "_raw"
        ds.attrs["dtype"] = repr(np.lib.format.dtype_to_descr(arr.dtype))
        ds.attrs["shape"] = np.array(arr.shape, np.int64)
        return
    ds = parent.create_dataset(name, data=arr)
    ds.attrs[_KIND] = kind


def _raw_dtype(spec: str) -> np.dtype:
    import ast
    return np.lib.format.descr_to_dtype(ast.literal_eval(spec))


def _read(obj) -> Any:
    """Inverse of :func:`_write`."""
    import h5py

    kind = obj.attrs.get(_KIND)
    if isinstance(kind, bytes):
        kind = kind.decode()
    if isinstance(obj, h5py.Group):
        if kind in ("dict", "dict_int", None):
            out = {}
            for k in obj.keys():
                out[int(k) if kind == "dict_int" else k] = _read(obj[k])
            return out
        items = [_read(obj[str(i)]) for i in range(len(obj))]
        return items if kind == "list" else tuple(items)
    if kind in ("ndarray", "npscalar"):
        data = obj[()]
        if kind == "ndarray":
            return np.asarray(data, dtype=obj.dtype).reshape(obj.shape)
        return data
    if kind in ("ndarray_raw", "npscalar_raw"):
        dt = _raw_dtype(str(obj.attrs["dtype"]))
        shape = tuple(int(x) for x in obj.attrs["shape"])
        arr = np.frombuffer(obj[()].tobytes(), dt).reshape(shape).copy()
        return arr if kind == "ndarray_raw" else arr[()]
    if kind == "none":
        return None
    if kind == "bool":
        return bool(obj[()])
    if kind == "int":
        return int(obj[()])
    if kind == "bigint":
        return int(obj[()].tobytes().decode())
    if kind == "float":
        return float(obj[()])
    if kind == "complex":
        return complex(obj[()])
    if kind == "str":
        return obj[()].tobytes().decode("utf-8")
    if kind == "bytes":
        return obj[()].tobytes()
    raise ValueError(f"unknown checkpoint entry kind {kind!r} at {obj.name}")


def _remove_stale_temporaries(path: Path) -> None:
    """Delete temporaries left by a killed :func:`save_checkpoint` of the same file."""
    for tmp in path.parent.glob(f".{path.name}.*.tmp"):
        try:
            tmp.unlink()
        except OSError:
            pass


def _state_bytes(value: Any) -> int:
    """Rough size (bytes) of a checkpoint state: its arrays and strings."""
    if isinstance(value, Mapping):
        return sum(_state_bytes(v) for v in value.values()) + 64
    if isinstance(value, (list, tuple)):
        return sum(_state_bytes(v) for v in value) + 64
    if isinstance(value, np.ndarray):
        return int(value.nbytes) + 64
    if isinstance(value, (str, bytes)):
        return len(value) + 64
    return 64


def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def save_checkpoint(path: str | Path, state: Mapping[str, Any]) -> None:
    """Write ``state`` (nested dict of arrays, scalars, strings, lists) to ``path`` atomically.

    The file is HDF5: a group per dict/list, a dataset per value, each tagged with its kind;
    file attributes ``format`` and ``nurbsdem_version``.
    """
    from .. import __version__

    if not isinstance(state, Mapping):
        raise TypeError("the checkpoint state must be a dict")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    _remove_stale_temporaries(path)
    ensure_space(path.parent, 2 * _state_bytes(state) + 1024 * 1024)

    def fill(f) -> None:
        f.attrs["format"] = FORMAT
        f.attrs["nurbsdem_version"] = __version__
        keys = list(state.keys())
        int_keys = bool(keys) and all(isinstance(k, (int, np.integer))
                                      and not isinstance(k, bool) for k in keys)
        if not int_keys and any(not isinstance(k, str) for k in keys):
            raise TypeError("checkpoint keys must be all str or all int")
        f.attrs[_KIND] = "dict_int" if int_keys else "dict"
        for k in keys:
            _write(f, _check_key(k), state[k])
    write_hdf5_atomically(path, fill, track_order=True)
    _fsync_dir(path.parent)


def load_checkpoint(path: str | Path) -> dict[str, Any]:
    """Read a checkpoint written by :func:`save_checkpoint` (exact round trip).

    Raises :class:`~nurbsdem.errors.InputError` naming the file when it is not a readable
    nurbsdem checkpoint (another HDF5 file such as ``results.h5``, a truncated or corrupted
    file, not HDF5 at all).
    """
    import h5py

    from ..errors import InputError

    spath = str(path)
    try:
        f = h5py.File(path, "r")
    except FileNotFoundError:
        raise InputError("no such checkpoint file", path=spath) from None
    except (OSError, ValueError) as exc:
        raise InputError(f"not a readable checkpoint (HDF5: {_short(exc)})", path=spath) from None
    with f:
        try:
            fmt = f.attrs.get("format")
            if isinstance(fmt, bytes):
                fmt = fmt.decode()
        except (OSError, ValueError, KeyError, UnicodeDecodeError) as exc:
            raise InputError(f"corrupted checkpoint ({_short(exc)})", path=spath) from None
        if fmt != FORMAT:
            what = "a nurbsdem results file" if fmt == "nurbsdem-results-1" else f"format {fmt!r}"
            raise InputError(f"not a nurbsdem checkpoint ({what}); give the checkpoint.h5 of "
                             f"the results folder", path=spath)
        try:
            return _read(f)
        except (OSError, ValueError, KeyError, TypeError, UnicodeDecodeError, SyntaxError) as exc:
            raise InputError(f"corrupted checkpoint ({_short(exc)})", path=spath) from None


def _short(exc: BaseException) -> str:
    return " ".join(str(exc).split())[:160] or type(exc).__name__


def restart_state(path: str | Path, model) -> dict[str, Any]:
    """The state of a checkpoint to restart ``model`` from: :func:`load_checkpoint`, then a
    check that it was written for the same simulation. The decks are compared as parsed
    models (:func:`nurbsdem.model.model_differences`), so comments, layout, block order and
    the Output block may differ. Raises :class:`~nurbsdem.errors.InputError`."""
    from ..errors import InputError
    from ..model import model_differences
    from .deck import build_model

    st = load_checkpoint(path)
    deck = st.get("deck")
    if not isinstance(deck, str) or "time" not in st:
        raise InputError("not a nurbsdem checkpoint of a run (no deck or time in it)",
                         path=str(path))
    if deck == model.text:
        return st
    try:
        old = build_model(deck, model.path)
    except InputError as exc:
        raise InputError(f"the checkpoint was written for a different deck (its deck no "
                         f"longer reads: {exc.detail})", path=str(path)) from None
    diff = model_differences(old, model)
    if diff:
        raise InputError(f"the checkpoint was written for a different deck (it differs in "
                         f"{', '.join(diff)}); restart with the deck that wrote it",
                         path=str(path))
    return st

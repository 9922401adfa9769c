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

Layout (format 2): two datasets, ``data`` (uint8: the bytes of every array and bytes value,
one after the other) and ``manifest`` (uint8: JSON UTF-8, the nested structure with each
leaf's kind, and for arrays their dtype descriptor, shape, offset and length in ``data``;
floats as ``float.hex``).  Format 1 (a group per dict or list and a dataset per value, each
tagged with its kind) is still read.  Why: HDF5 creates each dataset or attribute in the
interpreter, holding the GIL: a checkpoint of ~70 values written one by one in the output
worker kept the time loop waiting for a sizeable share of a run that checkpoints often;
packed into two datasets it costs a small fraction of that.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .atomic import ensure_space, write_hdf5_atomically

FORMAT = "nurbsdem-checkpoint-2"
#: the earlier layout (a dataset per value), still read
FORMAT_V1 = "nurbsdem-checkpoint-1"
_KIND = "__kind__"


def _check_key(key: Any) -> str:
    if isinstance(key, bool) or not isinstance(key, (str, int, np.integer)):
        raise TypeError(f"checkpoint keys must be str or int, got {type(key).__name__}")
    if isinstance(key, str):
        if "/" in key or key.startswith("__") or key in ("", "."):
            raise ValueError(f"invalid checkpoint key {key!r}")
    return str(key)


def _pack(value: Any, name: str, chunks: list[bytes], size: list[int]) -> Any:
    """The manifest node of ``value`` (JSON-able), its arrays' and bytes' contents appended to
    ``chunks`` (``size[0]``: their total length so far, the next offset)."""
    def stored(raw: bytes) -> list[int]:
        at = size[0]
        chunks.append(raw)
        size[0] += len(raw)
        return [at, len(raw)]

    if isinstance(value, Mapping):
        keys = list(value.keys())
        int_keys = bool(keys) and all(isinstance(k, (int, np.integer)) and not isinstance(k, bool)
                                      for k in keys)
        if not int_keys and any(not isinstance(k, str) for k in keys):
            raise TypeError(f"checkpoint dict {name!r}: keys must be all str or all int")
        return {"dict_int" if int_keys else "dict":
                [[_check_key(k), _pack(value[k], f"{name}/{k}", chunks, size)] for k in keys]}
    if isinstance(value, (list, tuple)):
        return {"list" if isinstance(value, list) else "tuple":
                [_pack(item, f"{name}/{i}", chunks, size) for i, item in enumerate(value)]}
    if isinstance(value, (np.ndarray, np.generic)):
        arr = np.asarray(value)
        if arr.dtype.hasobject:
            raise TypeError(f"cannot store an object array in a checkpoint ({name!r})")
        kind = "ndarray" if isinstance(value, np.ndarray) else "npscalar"
        return {kind: [repr(np.lib.format.dtype_to_descr(arr.dtype)), list(arr.shape),
                       *stored(np.ascontiguousarray(arr).tobytes())]}
    if value is None:
        return {"none": 0}
    if isinstance(value, bool):
        return {"bool": value}
    if isinstance(value, int):
        return {"int": str(value)}
    if isinstance(value, float):
        return {"float": value.hex()}
    if isinstance(value, complex):
        return {"complex": [value.real.hex(), value.imag.hex()]}
    if isinstance(value, str):
        return {"str": value}
    if isinstance(value, bytes):
        return {"bytes": stored(value)}
    raise TypeError(f"cannot store {type(value).__name__} in a checkpoint ({name!r})")


def _unpack(node: Any, data: bytes) -> Any:
    """Inverse of :func:`_pack` (``data``: the ``data`` dataset's bytes)."""
    ((kind, body),) = node.items()
    if kind in ("dict", "dict_int"):
        return {(int(k) if kind == "dict_int" else k): _unpack(v, data) for k, v in body}
    if kind in ("list", "tuple"):
        items = [_unpack(v, data) for v in body]
        return items if kind == "list" else tuple(items)
    if kind in ("ndarray", "npscalar"):
        spec, shape, at, n = body
        dt = _raw_dtype(spec)
        if at < 0 or n < 0 or at + n > len(data) or n != dt.itemsize * int(np.prod(shape)):
            raise ValueError(f"array of {n} bytes at {at} outside the data or not its shape")
        arr = np.frombuffer(data[at:at + n], dt).reshape(shape).copy()
        return arr if kind == "ndarray" else arr[()]
    if kind == "none":
        return None
    if kind == "bool":
        return bool(body)
    if kind == "int":
        return int(body)
    if kind == "float":
        return float.fromhex(body)
    if kind == "complex":
        return complex(float.fromhex(body[0]), float.fromhex(body[1]))
    if kind == "str":
        return str(body)
    if kind == "bytes":
        at, n = body
        if at < 0 or n < 0 or at + n > len(data):
            raise ValueError(f"bytes of {n} at {at} outside the data")
        return data[at:at + n]
    raise ValueError(f"unknown checkpoint entry kind {kind!r}")


def _raw_dtype(spec: str) -> np.dtype:
    import ast
    return np.lib.format.descr_to_dtype(ast.literal_eval(spec))


def _read(obj) -> Any:
    """A value of a format-1 checkpoint (a group per dict or list, a dataset per value)."""
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

    The file is HDF5: the datasets ``manifest`` and ``data`` (module docstring), file
    attributes ``format`` and ``nurbsdem_version``.  A value that cannot be stored raises
    before the file is touched.
    """
    from .. import __version__

    if not isinstance(state, Mapping):
        raise TypeError("the checkpoint state must be a dict")
    path = Path(path)
    chunks: list[bytes] = []
    manifest = json.dumps(_pack(state, "", chunks, [0]), separators=(",", ":"))

    def fill(f) -> None:
        f.attrs["format"] = FORMAT
        f.attrs["nurbsdem_version"] = __version__
        f.create_dataset("manifest", data=np.frombuffer(manifest.encode(), np.uint8))
        f.create_dataset("data", data=np.frombuffer(b"".join(chunks), np.uint8))

    path.parent.mkdir(parents=True, exist_ok=True)
    _remove_stale_temporaries(path)
    ensure_space(path.parent, 2 * _state_bytes(state) + 1024 * 1024)
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
        if fmt not in (FORMAT, FORMAT_V1):
            what = "a nurbsdem results file" if fmt == "nurbsdem-results-1" else f"format {fmt!r}"
            raise InputError(f"not a nurbsdem checkpoint ({what}); give the checkpoint.h5 of "
                             f"the results folder", path=spath)
        try:
            if fmt == FORMAT_V1:
                return _read(f)
            return _unpack(json.loads(f["manifest"][()].tobytes().decode()),
                           f["data"][()].tobytes())
        except (OSError, ValueError, KeyError, TypeError, IndexError, AttributeError,
                UnicodeDecodeError, SyntaxError) as exc:
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

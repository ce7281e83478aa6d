"""Serialization of FMU states: nested dicts of numpy arrays and scalars to bytes.

``fmi2SerializeFMUstate`` needs the whole internal state of an instance
(estimator covariances, windows, random-generator state, current inputs and
parameters) as bytes that restore it exactly in a fresh instance. Arrays are
stored as their raw little-endian bytes (base64), so a round trip is
bit-for-bit, NaN and inf included; generator states (dicts of Python ints) and
other scalars go through JSON unchanged. The SHA-256 of the state's JSON is
stored beside it: bytes damaged since (a changed digit of an estimate, a
truncated file) are refused, never restored as another state. Only numpy and
the standard library are used.

>>> import numpy as np
>>> state = {"x": np.array([1.0, np.nan]), "k": 3, "rng": {"state": 2**100}}
>>> back = decode_state(encode_state(state))
>>> back["x"].tobytes() == state["x"].tobytes(), back["k"], back["rng"]["state"] == 2**100
(True, 3, True)
"""

from __future__ import annotations

import base64
import hashlib
import json
from typing import Any

import numpy as np

from ..core._errors import ArgumentError, ArgumentTypeError

__all__ = ["encode_state", "decode_state", "copy_state", "FORMAT"]

#: Version tag stored in every serialized state.
FORMAT = "lpvest-fmu-state-2"

_ARRAY = "__ndarray__"
_TUPLE = "__tuple__"


def _encode(obj: object) -> object:
    if isinstance(obj, np.ndarray):
        arr = np.ascontiguousarray(obj)
        if arr.dtype.kind not in "fiub":
            raise ArgumentTypeError(f"cannot serialize an array of dtype {arr.dtype}")
        dtype = arr.dtype.newbyteorder("<") if arr.dtype.byteorder == ">" else arr.dtype
        return {
            _ARRAY: base64.b64encode(arr.astype(dtype, copy=False).tobytes()).decode("ascii"),
            "dtype": dtype.str,
            "shape": list(arr.shape),
        }
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, dict):
        out = {}
        for k, v in obj.items():
            if not isinstance(k, str):
                raise ArgumentTypeError(f"state keys must be strings; found {k!r}")
            out[k] = _encode(v)
        return out
    if isinstance(obj, tuple):
        return {_TUPLE: [_encode(v) for v in obj]}
    if isinstance(obj, list):
        return [_encode(v) for v in obj]
    if obj is None or isinstance(obj, bool | int | float | str):
        return obj
    raise ArgumentTypeError(f"cannot serialize a {type(obj).__name__} in an FMU state")


def _decode(obj: Any) -> Any:
    if isinstance(obj, dict):
        if _ARRAY in obj:
            raw = base64.b64decode(obj[_ARRAY])
            return np.frombuffer(raw, dtype=np.dtype(obj["dtype"])).reshape(obj["shape"]).copy()
        if _TUPLE in obj:
            return tuple(_decode(v) for v in obj[_TUPLE])
        return {k: _decode(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_decode(v) for v in obj]
    return obj


def _digest(encoded: object) -> str:
    # json.dumps of what json.loads read back from json.dumps is the same text (floats by repr)
    return hashlib.sha256(json.dumps(encoded, allow_nan=True).encode("utf-8")).hexdigest()


def encode_state(state: dict[str, object]) -> bytes:
    """``state`` (nested dicts, lists, tuples, numpy arrays, scalars) as bytes."""
    encoded = _encode(state)
    return json.dumps({"format": FORMAT, "sha256": _digest(encoded), "state": encoded},
                      allow_nan=True).encode("utf-8")


def decode_state(data: bytes) -> dict[str, Any]:
    """The state :func:`encode_state` wrote (arrays come back as fresh copies).

    Raises
    ------
    ArgumentError
        Not such a state, another format, or damaged (its SHA-256 differs).
    """
    try:
        doc = json.loads(bytes(data).decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ArgumentError(f"not a serialized lpvest FMU state: {exc}") from exc
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        found = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
        raise ArgumentError(f"not a serialized lpvest FMU state (format {found!r}; expected {FORMAT!r})")
    if "state" not in doc or doc.get("sha256") != _digest(doc["state"]):
        raise ArgumentError("not a serialized lpvest FMU state (it is damaged: its SHA-256 does not match)")
    try:
        return _decode(doc["state"])
    except (TypeError, ValueError, KeyError, AttributeError) as exc:
        raise ArgumentError(f"not a serialized lpvest FMU state: {exc}") from exc


def copy_state(state: Any) -> Any:
    """A deep copy of a state (arrays copied), without going through bytes."""
    if isinstance(state, np.ndarray):
        return state.copy()
    if isinstance(state, dict):
        return {k: copy_state(v) for k, v in state.items()}
    if isinstance(state, list):
        return [copy_state(v) for v in state]
    if isinstance(state, tuple):
        return tuple(copy_state(v) for v in state)
    return state

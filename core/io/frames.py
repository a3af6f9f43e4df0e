"""One record format for the wire and the disk: msgpack maps with a kind, a version and a place.

Every record is a msgpack map ``{"kind": str, "v": 1, "run": str, "seq": int, ...}``. The same
bytes travel after a topic frame on the ZeroMQ PUB socket (``[topic, record]``) and after a
``u32 length | u32 crc32`` prefix in segment files (core/io/recording.py), so a reader of one is a
reader of the other. docs/wire-format.md is the human description of what is checked here.

Arrays travel as ``{"dtype": str, "shape": [..], "data": bytes}`` with a whitelisted
little-endian dtype: never pickles, never object arrays. ``decode`` is written for hostile
input (network peers, damaged files): every length is capped before anything is allocated, the
nesting depth and node count are bounded, and anything unexpected raises
:class:`avard.core.errors.FormatError` naming what is wrong; nothing else escapes.

Times: ``t_mono`` is CLOCK_MONOTONIC in seconds and ``t_real`` is CLOCK_REALTIME (Unix time) in
seconds, both for the first sample of the record (``i0``) or the moment of the event. Sample
index (``i0``, ``n``: the half-open range ``[i0, i0 + n)``) is the truth for ordering.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

import msgpack
import numpy as np
from avard.core.errors import FormatError

#: Format version written in every record (``"v"``); a reader refuses any other.
FORMAT_VERSION = 1

#: Every record kind. ``checkpoint`` carries StreamingAllan.state() (disk only).
KINDS = ("header", "raw", "temp", "gap", "event", "avar", "status", "checkpoint")

#: PUB topics, and which topic each kind travels on (gaps are events for subscribers).
TOPICS = ("raw", "temp", "avar", "status", "event")
TOPIC_OF_KIND = {
    "raw": "raw",
    "temp": "temp",
    "avar": "avar",
    "status": "status",
    "event": "event",
    "gap": "event",
    "header": "status",
}

#: Array dtypes accepted on decode (numpy ``dtype.str``); everything is little-endian.
ALLOWED_DTYPES = frozenset(
    {"|b1", "|i1", "|u1", "<i2", "<u2", "<i4", "<u4", "<i8", "<u8", "<f4", "<f8"}
)

#: Default cap of one encoded record (bytes). A raw block of 32 samples is ~0.5 kB; a
#: checkpoint of the Allan accumulators is well under 1 MB.
DEFAULT_MAX_BYTES = 16 * 1024 * 1024
#: Cap of one array's payload (bytes), independent of the record cap.
MAX_ARRAY_BYTES = 16 * 1024 * 1024
MAX_ARRAY_NDIM = 8
#: Structural limits against deep nesting and node floods (a record is a few hundred nodes).
MAX_DEPTH = 32
MAX_NODES = 1_000_000

_ARRAY_KEYS = frozenset({"dtype", "shape", "data"})
_MISSING = object()
_INT = int


# --------------------------------------------------------------------------------------------
# arrays


def pack_array(a: Any) -> dict[str, Any]:
    """Return ``{"dtype", "shape", "data"}`` for an array-like with a whitelisted dtype.

    The data are written little-endian and C-contiguous, so the receiver never needs to know
    the sender's byte order. Object, string and other dtypes raise FormatError.
    """
    arr = np.asarray(a)
    if arr.dtype.kind not in "biuf":
        raise FormatError(
            f"cannot pack an array of dtype {arr.dtype}: only bool, integer and float arrays "
            "travel (never objects or strings)"
        )
    arr = np.ascontiguousarray(arr, dtype=arr.dtype.newbyteorder("<"))
    dtype = arr.dtype.str
    if dtype not in ALLOWED_DTYPES:
        raise FormatError(
            f"cannot pack an array of dtype {dtype}: allowed are {sorted(ALLOWED_DTYPES)}"
        )
    if arr.nbytes > MAX_ARRAY_BYTES:
        raise FormatError(
            f"array of {arr.nbytes} bytes exceeds the {MAX_ARRAY_BYTES}-byte cap; "
            "send it in smaller blocks"
        )
    return {"dtype": dtype, "shape": list(arr.shape), "data": arr.tobytes()}


def is_packed_array(obj: Any) -> bool:
    """True when ``obj`` has the shape of a packed array (a map with dtype, shape, data)."""
    return isinstance(obj, dict) and obj.keys() == _ARRAY_KEYS


def unpack_array(obj: Any, *, max_bytes: int = MAX_ARRAY_BYTES, where: str = "array") -> np.ndarray:
    """Turn a packed array map back into a read-only numpy array (a view on the bytes).

    Checks: the map has exactly dtype/shape/data, the dtype is whitelisted, the shape is a
    short list of non-negative ints whose product × itemsize equals ``len(data)``, and the
    payload is at most ``max_bytes``. Anything else raises FormatError naming ``where``.
    """
    if not is_packed_array(obj):
        raise FormatError(f"{where}: expected a map with keys dtype, shape, data")
    dtype, shape, data = obj["dtype"], obj["shape"], obj["data"]
    if not isinstance(dtype, str) or dtype not in ALLOWED_DTYPES:
        raise FormatError(f"{where}: dtype {dtype!r} is not allowed ({sorted(ALLOWED_DTYPES)})")
    if not isinstance(shape, list) or len(shape) > MAX_ARRAY_NDIM:
        raise FormatError(f"{where}: shape must be a list of at most {MAX_ARRAY_NDIM} ints")
    count = 1
    for dim in shape:
        if type(dim) is not _INT or dim < 0:
            raise FormatError(f"{where}: shape {shape!r} must hold non-negative ints")
        count *= dim  # Python ints: a hostile shape cannot overflow this product
    if not isinstance(data, bytes | bytearray | memoryview):
        raise FormatError(f"{where}: data must be bytes, got {type(data).__name__}")
    if len(data) > max_bytes:
        raise FormatError(f"{where}: {len(data)} bytes exceed the {max_bytes}-byte cap")
    itemsize = np.dtype(dtype).itemsize
    if count * itemsize != len(data):
        raise FormatError(
            f"{where}: shape {shape} × {itemsize} bytes = {count * itemsize} bytes, "
            f"but data holds {len(data)}"
        )
    try:
        return np.frombuffer(data, dtype=np.dtype(dtype)).reshape(shape)
    except ValueError:  # e.g. [2**62, 0, 2**62]: no data, but numpy refuses the shape
        raise FormatError(f"{where}: shape {_short(shape)} is beyond what an array can "
                          "have") from None


# --------------------------------------------------------------------------------------------
# record schema: required fields per kind, with their types

# Types: "int" non-negative int, "num" int or float, "str", "map", "list", "array" packed array,
# "num|none", "array|list".
_COMMON = {"kind": "str", "v": "int", "run": "str", "seq": "int"}
SCHEMA: dict[str, dict[str, str]] = {
    "header": {"t_mono": "num", "t_real": "num", "rate_hz": "num", "i0": "int"},
    "raw": {"i0": "int", "n": "int", "t_mono": "num", "t_real": "num", "counts": "array"},
    "temp": {"i0": "int", "t_mono": "num", "t_real": "num", "names": "list", "values_c": "list"},
    "gap": {"i0": "int", "n": "int", "t_mono": "num", "t_real": "num", "reason": "str"},
    "event": {"name": "str", "t_mono": "num", "t_real": "num", "detail": "map"},
    "avar": {"i_end": "int", "n_samples": "int", "t_mono": "num", "t_real": "num",
             "snapshot": "map"},
    "status": {"t_mono": "num", "t_real": "num", "status": "map"},
    "checkpoint": {"i_end": "int", "n_samples": "int", "t_mono": "num", "t_real": "num",
                   "state": "map"},
}
#: Optional fields that are type-checked when present.
OPTIONAL: dict[str, dict[str, str]] = {
    "header": {"channels": "list", "temperature_channels": "list",
               "scale_m_s2_per_count": "num|none", "range_g": "num|none", "sensor": "map",
               "config": "map"},
    "raw": {"rate_hz": "num", "chip_temp_c": "num|none"},
    "temp": {"source": "str"},
    "gap": {"lost_messages": "int", "topic": "str"},
    "event": {"i0": "int"},
    "avar": {"fit": "map|none"},
}


def _is_array(v: Any) -> bool:
    return isinstance(v, np.ndarray) or is_packed_array(v)


# One predicate per type name; validate() runs on every published record, so these stay cheap.
_TYPE_CHECKS: dict[str, Callable[[Any], bool]] = {
    # numpy scalars are accepted on the way out (msgpack gets them as plain numbers); bool is
    # never a number here
    "int": lambda v: (type(v) is int or isinstance(v, np.integer)) and bool(v >= 0),
    "num": lambda v: (type(v) is int or isinstance(v, float | np.integer | np.floating)),
    "num|none": lambda v: v is None or isinstance(v, float | np.integer | np.floating)
    or type(v) is int,
    "str": lambda v: type(v) is str,
    "map": lambda v: isinstance(v, dict),
    "map|none": lambda v: v is None or isinstance(v, dict),
    "list": lambda v: isinstance(v, list),
    "array": _is_array,
}
# (field, predicate, type name, required) per kind, common fields first
_CHECKS: dict[str, list[tuple[str, Callable[[Any], bool], str, bool]]] = {
    kind: [(name, _TYPE_CHECKS[typ], typ, req)
           for fields, req in ((_COMMON, True), (SCHEMA[kind], True),
                               (OPTIONAL.get(kind, {}), False))
           for name, typ in fields.items()]
    for kind in SCHEMA
}


def validate(record: Mapping[str, Any]) -> None:
    """Check the kind, version and the required fields of a record; FormatError otherwise."""
    if not isinstance(record, Mapping):
        raise FormatError(f"a record must be a map, got {type(record).__name__}")
    kind = record.get("kind")
    if not isinstance(kind, str) or kind not in SCHEMA:  # a list/map kind is unhashable
        raise FormatError(f"unknown record kind {kind!r}; known kinds are {', '.join(KINDS)}")
    if record.get("v") != FORMAT_VERSION:
        raise FormatError(
            f"{kind} record has format version {record.get('v')!r}; this avard reads "
            f"version {FORMAT_VERSION} (upgrade avard to read newer recordings)"
        )
    for name, ok, typ, required in _CHECKS[kind]:
        value = record.get(name, _MISSING)
        if value is _MISSING:
            if required:
                raise FormatError(f"{kind} record lacks the required field {name!r}")
            continue
        if not ok(value):
            raise FormatError(
                f"{kind} record field {name!r} should be {typ}, "
                f"got {type(value).__name__} {_short(value)}"
            )
    if kind == "raw":
        counts = record["counts"]
        shape = counts.shape if isinstance(counts, np.ndarray) else counts["shape"]
        if not (isinstance(shape, list | tuple) and len(shape) == 2 and shape[0] == record["n"]):
            raise FormatError(
                f"raw record: counts shape {_short(shape)} does not match n={record['n']}"
            )
        # Readers stack raw blocks as (n, 3) integer ADXL355 counts; anything else would only
        # fail later, far from the record that caused it.
        dtype = counts.dtype.str if isinstance(counts, np.ndarray) else counts["dtype"]
        if not isinstance(dtype, str) or dtype not in ALLOWED_DTYPES:
            raise FormatError(f"raw.counts: dtype {_short(dtype)} is not allowed "
                              f"({sorted(ALLOWED_DTYPES)})")
        if shape[1] != 3 or dtype[1] not in ("i", "u"):
            raise FormatError(
                f"raw record: counts must be (n, 3) integer ADXL355 counts, got dtype "
                f"{_short(dtype)} shape {_short(shape)}"
            )
    if kind == "temp":
        names, values = record["names"], record["values_c"]
        if len(names) != len(values):
            raise FormatError("temp record: names and values_c differ in length")
        if not all(isinstance(n, str) for n in names) or not all(
                v is None or type(v) in (int, float) for v in values):
            raise FormatError(
                f"temp record: names must be strings and values_c numbers in °C or None, got "
                f"{_short(names)} and {_short(values)}"
            )


    if kind == "header":
        for key in ("channels", "temperature_channels"):
            names = record.get(key, [])
            if not all(isinstance(n, str) for n in names):
                raise FormatError(f"header record: {key} must be a list of strings, got "
                                  f"{_short(names)}")


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


# --------------------------------------------------------------------------------------------
# encode / decode


def _default(obj: Any) -> Any:
    """msgpack hook: numpy arrays become packed arrays, numpy scalars plain numbers."""
    if isinstance(obj, np.ndarray):
        return pack_array(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    if isinstance(obj, tuple):
        return list(obj)
    raise FormatError(f"cannot encode a {type(obj).__name__} in a record ({_short(obj)})")


def encode(record: Mapping[str, Any], *, check: bool = True) -> bytes:
    """Return the msgpack bytes of a record (numpy arrays packed), validating it first."""
    if check:
        validate(record)
    try:
        return msgpack.packb(record, use_bin_type=True, default=_default, strict_types=False)
    except (TypeError, ValueError, OverflowError) as exc:
        raise FormatError(f"cannot encode {record.get('kind')!r} record: {exc}") from exc


def unpack_bounded(data: bytes | bytearray | memoryview, *, max_bytes: int = DEFAULT_MAX_BYTES,
                   what: str = "message") -> Any:
    """msgpack-decode untrusted bytes with every length capped; FormatError on anything odd.

    Returns plain Python objects (dict, list, str, bytes, int, float, bool, None); extension
    types, non-string map keys, trailing bytes, more than MAX_DEPTH levels or MAX_NODES nodes
    are refused.
    """
    if not isinstance(data, bytes | bytearray | memoryview):
        raise FormatError(f"{what}: expected bytes, got {type(data).__name__}")
    size = len(data)
    if size > max_bytes:
        raise FormatError(f"{what}: {size} bytes exceed the {max_bytes}-byte cap")
    if size == 0:
        raise FormatError(f"{what}: empty")
    try:
        obj = msgpack.unpackb(
            data, raw=False, strict_map_key=True, use_list=True,
            max_str_len=size, max_bin_len=size,
            max_array_len=size, max_map_len=size, max_ext_len=0,
            ext_hook=_refuse_ext, timestamp=0,
        )
    except FormatError:
        raise
    except (ValueError, TypeError, OverflowError, msgpack.UnpackException) as exc:
        # ExtraData, StackError, OutOfData, invalid UTF-8 and length limits all land here
        raise FormatError(f"{what}: not a valid msgpack message ({type(exc).__name__}: "
                          f"{_short(str(exc))})") from None
    _check_structure(obj, what)
    return obj


def _refuse_ext(code: int, data: bytes) -> Any:
    raise FormatError(f"msgpack extension type {code} is not allowed in avard records")


_LEAF_TYPES = frozenset({type(None), bool, int, float, str, bytes})


def _check_structure(obj: Any, what: str) -> None:
    """Bound depth and node count, and allow only plain msgpack types (no Timestamp/ExtType).

    Iterative on purpose: a deeply nested hostile message must not hit Python's recursion
    limit. Only containers go on the stack (leaves are checked in place): this runs on every
    received message.
    """
    if type(obj) not in (dict, list):
        if type(obj) not in _LEAF_TYPES:
            raise FormatError(f"{what}: value of type {type(obj).__name__} is not allowed")
        return
    stack: list[tuple[Any, int]] = [(obj, 0)]
    nodes = 1
    while stack:
        item, depth = stack.pop()
        if depth >= MAX_DEPTH:
            raise FormatError(f"{what}: nested deeper than {MAX_DEPTH} levels")
        values = item.values() if type(item) is dict else item
        nodes += len(values)
        if nodes > MAX_NODES:
            raise FormatError(f"{what}: more than {MAX_NODES} values")
        if _LEAF_TYPES.issuperset(map(type, values)):
            continue                      # leaves only (most containers): checked in one go
        for v in values:
            t = type(v)
            if t is dict or t is list:
                stack.append((v, depth + 1))
            elif t not in _LEAF_TYPES:
                raise FormatError(f"{what}: value of type {t.__name__} is not allowed")


def decode(data: bytes | bytearray | memoryview, *, max_bytes: int = DEFAULT_MAX_BYTES,
           arrays: bool = True) -> dict[str, Any]:
    """Decode and validate one record; FormatError for anything that is not a valid record.

    With ``arrays=True`` the top-level packed arrays (e.g. ``counts``) come back as read-only
    numpy arrays; nested ones (inside ``snapshot``/``state``) stay packed maps, for
    :func:`unpack_arrays` to convert when wanted.
    """
    record = unpack_bounded(data, max_bytes=max_bytes, what="record")
    if not isinstance(record, dict):
        raise FormatError(f"record: expected a map, got {type(record).__name__}")
    validate(record)
    if arrays:
        for key, value in record.items():
            # msgpack gives plain dicts; few values are maps of three (a header has ~20 values)
            if type(value) is dict and len(value) == 3 and is_packed_array(value):
                where = f"{record['kind']}.{key}"
                record[key] = unpack_array(value, max_bytes=max_bytes, where=where)
    return record


def unpack_arrays(obj: Any, *, max_bytes: int = MAX_ARRAY_BYTES) -> Any:
    """Return a copy of a decoded structure with every packed array turned into numpy.

    Depth is already bounded by :func:`decode`, so the recursion here is safe.
    """
    if is_packed_array(obj):
        return unpack_array(obj, max_bytes=max_bytes)
    if isinstance(obj, dict):
        return {k: unpack_arrays(v, max_bytes=max_bytes) for k, v in obj.items()}
    if isinstance(obj, list):
        return [unpack_arrays(v, max_bytes=max_bytes) for v in obj]
    return obj


# --------------------------------------------------------------------------------------------
# builders: the one place that knows which fields a kind carries


def _base(kind: str, run: str, seq: int) -> dict[str, Any]:
    return {"kind": kind, "v": FORMAT_VERSION, "run": str(run), "seq": int(seq)}


def _now_fields(t_mono: float, t_real: float) -> dict[str, float]:
    return {"t_mono": float(t_mono), "t_real": float(t_real)}


def header_record(run: str, *, rate_hz: float, t_mono: float, t_real: float, i0: int = 0,
                  seq: int = 0, channels: Sequence[str] = ("x", "y", "z"),
                  scale_m_s2_per_count: float | None = None, range_g: float | None = None,
                  sensor: Mapping[str, Any] | None = None,
                  temperature_channels: Sequence[str] = (), software: str = "",
                  config: Mapping[str, Any] | None = None, **extra: Any) -> dict[str, Any]:
    """Everything needed to interpret a run: rates, scale, sensors, software, config."""
    rec = _base("header", run, seq)
    rec.update(_now_fields(t_mono, t_real))
    rec.update(
        rate_hz=float(rate_hz), i0=int(i0), channels=list(channels),
        scale_m_s2_per_count=scale_m_s2_per_count, range_g=range_g,
        sensor=dict(sensor or {}), temperature_channels=list(temperature_channels),
        software=software, config=dict(config or {}),
    )
    rec.update(extra)
    return rec


def raw_record(run: str, seq: int, i0: int, counts: Any, t_mono: float, t_real: float, *,
               rate_hz: float | None = None, chip_temp_c: float | None = None) -> dict[str, Any]:
    """A block of raw ADXL355 counts (n, 3) int32 for samples ``[i0, i0 + n)``."""
    arr = np.asarray(counts)
    if arr.ndim != 2 or arr.dtype.kind not in "iu":
        raise FormatError(
            f"raw block must be (n, channels) integer counts, got {arr.dtype}{arr.shape}"
        )
    rec = _base("raw", run, seq)
    rec.update(i0=int(i0), n=int(arr.shape[0]), **_now_fields(t_mono, t_real),
               counts=np.asarray(arr, dtype=np.int32))
    if rate_hz is not None:
        rec["rate_hz"] = float(rate_hz)
    if chip_temp_c is not None:
        rec["chip_temp_c"] = float(chip_temp_c)
    return rec


def temp_record(run: str, seq: int, i0: int, names: Sequence[str],
                values_c: Iterable[float | None], t_mono: float, t_real: float, *,
                source: str = "ds18b20") -> dict[str, Any]:
    """Temperatures in °C read at sample index ``i0``; a failed read is None."""
    vals = [None if v is None or not math.isfinite(float(v)) else float(v) for v in values_c]
    rec = _base("temp", run, seq)
    rec.update(i0=int(i0), **_now_fields(t_mono, t_real), names=[str(n) for n in names],
               values_c=vals, source=source)
    return rec


def gap_record(run: str, seq: int, i0: int, n: int, t_mono: float, t_real: float,
               reason: str, **detail: Any) -> dict[str, Any]:
    """Samples ``[i0, i0 + n)`` that are missing, and why (overrun, bus_error, restart, ...)."""
    rec = _base("gap", run, seq)
    rec.update(i0=int(i0), n=int(n), **_now_fields(t_mono, t_real), reason=str(reason))
    rec.update(detail)
    return rec


def event_record(run: str, seq: int, name: str, t_mono: float, t_real: float, *,
                 i0: int | None = None, detail: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Something that happened: clock step, sensor lost/back, disk full, start, stop."""
    rec = _base("event", run, seq)
    rec.update(name=str(name), **_now_fields(t_mono, t_real), detail=dict(detail or {}))
    if i0 is not None:
        rec["i0"] = int(i0)
    return rec


def avar_record(run: str, seq: int, i_end: int, n_samples: int, snapshot: Mapping[str, Any],
                t_mono: float, t_real: float, *, fit: Mapping[str, Any] | None = None
                ) -> dict[str, Any]:
    """An Allan snapshot (AllanSnapshot.to_dict()) of all samples before index ``i_end``."""
    rec = _base("avar", run, seq)
    rec.update(i_end=int(i_end), n_samples=int(n_samples), **_now_fields(t_mono, t_real),
               snapshot=dict(snapshot), fit=None if fit is None else dict(fit))
    return rec


def status_record(run: str, seq: int, status: Mapping[str, Any], t_mono: float,
                  t_real: float) -> dict[str, Any]:
    """Service health for humans and monitors (rate_hz, samples, gaps, subscribers, disk)."""
    rec = _base("status", run, seq)
    rec.update(**_now_fields(t_mono, t_real), status=dict(status))
    return rec


def checkpoint_record(run: str, seq: int, i_end: int, n_samples: int, state: Mapping[str, Any],
                      t_mono: float, t_real: float) -> dict[str, Any]:
    """StreamingAllan.state() after all samples before ``i_end``, for restart restore."""
    rec = _base("checkpoint", run, seq)
    rec.update(i_end=int(i_end), n_samples=int(n_samples), **_now_fields(t_mono, t_real),
               state=dict(state))
    return rec


def topic_of(record: Mapping[str, Any]) -> str:
    """The PUB topic a record travels on; FormatError for kinds that are never published."""
    kind = record.get("kind")
    try:
        return TOPIC_OF_KIND[kind]  # type: ignore[index]
    except KeyError:
        raise FormatError(f"records of kind {kind!r} are not published") from None


# --------------------------------------------------------------------------------------------
# request / reply messages of the request socket

#: Operations the request socket knows; the server may register fewer.
REQUEST_OPS = ("snapshot", "status", "recent", "header", "sensors")
MAX_REQUEST_BYTES = 65536


def encode_request(op: str, args: Mapping[str, Any] | None = None, *, id: int = 0) -> bytes:
    """``{"op": str, "args": map, "id": int}``: one request to the request socket."""
    return msgpack.packb({"op": op, "args": dict(args or {}), "id": int(id)}, use_bin_type=True,
                         default=_default)


def decode_request(data: bytes, *, max_bytes: int = MAX_REQUEST_BYTES) -> dict[str, Any]:
    """Decode a request; FormatError when it is not ``{"op": str, "args": map, ...}``."""
    req = unpack_bounded(data, max_bytes=max_bytes, what="request")
    if not isinstance(req, dict):
        raise FormatError(f"request: expected a map, got {type(req).__name__}")
    if not isinstance(req.get("op"), str):
        raise FormatError("request: field 'op' (a string, e.g. 'snapshot') is required")
    args = req.get("args", {})
    if not isinstance(args, dict):
        raise FormatError("request: field 'args' must be a map")
    rid = req.get("id", 0)
    if type(rid) is not int:
        raise FormatError("request: field 'id' must be an int")
    return {"op": req["op"], "args": args, "id": rid}


def encode_reply(op: str, *, result: Mapping[str, Any] | None = None, error: str | None = None,
                 id: int = 0) -> bytes:
    """``{"ok": bool, "op": str, "id": int, "result": map}`` or ``{..., "error": str}``."""
    msg: dict[str, Any] = {"v": FORMAT_VERSION, "ok": error is None, "op": op, "id": int(id)}
    if error is None:
        msg["result"] = dict(result or {})
    else:
        msg["error"] = str(error)
    return msgpack.packb(msg, use_bin_type=True, default=_default)


def decode_reply(data: bytes, *, max_bytes: int = DEFAULT_MAX_BYTES) -> dict[str, Any]:
    """Decode a reply; FormatError when malformed. An error reply is returned, not raised."""
    rep = unpack_bounded(data, max_bytes=max_bytes, what="reply")
    if not isinstance(rep, dict) or not isinstance(rep.get("ok"), bool):
        raise FormatError("reply: expected a map with a boolean 'ok'")
    if rep["ok"] and not isinstance(rep.get("result"), dict):
        raise FormatError("reply: 'result' map missing from a successful reply")
    if not rep["ok"] and not isinstance(rep.get("error"), str):
        raise FormatError("reply: 'error' string missing from a failed reply")
    return rep

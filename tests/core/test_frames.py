"""The record format: round trips of every kind, and refusal of everything malformed."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest
from avard.core.errors import FormatError
from avard.core.io import frames as F


def _examples() -> list[dict]:
    rng = np.random.default_rng(1)
    counts = rng.integers(-(1 << 19), 1 << 19, size=(32, 3), dtype=np.int32)
    snap = {"tau": np.array([0.008, 0.016]), "avar": np.ones((2, 3)), "n_samples": 10}
    return [
        F.header_record("run-a", rate_hz=125.0, t_mono=1.5, t_real=1.7e9, channels=["x", "y", "z"],
                        scale_m_s2_per_count=3.9e-6 * 9.80665, range_g=2.0,
                        sensor={"id": "adxl355"}, temperature_channels=["plate"],
                        software="avard 0.1", config={"odr_hz": 125}),
        F.raw_record("run-a", 7, 320, counts, 10.25, 1.7e9 + 10.25, rate_hz=125.0001,
                     chip_temp_c=24.5),
        F.temp_record("run-a", 2, 400, ["plate", "air"], [21.0625, float("nan")], 11.0, 1.7e9),
        F.gap_record("run-a", 1, 352, 48, 10.6, 1.7e9, "overrun", lost_messages=0),
        F.event_record("run-a", 3, "clock_step", 12.0, 1.7e9, i0=500, detail={"step_s": -0.25}),
        F.avar_record("run-a", 4, 1024, 1000, snap, 13.0, 1.7e9,
                      fit={"terms": {"quantization": {"value": 1e-5}}}),
        F.status_record("run-a", 5, {"rate_hz": 125.0, "samples": 1024}, 13.0, 1.7e9),
        F.checkpoint_record("run-a", 6, 1024, 1000, {"sums": np.arange(4.0)}, 13.0, 1.7e9),
    ]


@pytest.mark.parametrize("rec", _examples(), ids=lambda r: r["kind"])
def test_every_kind_round_trips(rec: dict) -> None:
    out = F.decode(F.encode(rec))
    assert out["kind"] == rec["kind"] and out["v"] == F.FORMAT_VERSION
    assert out["run"] == "run-a" and out["seq"] == rec["seq"]
    for key, value in rec.items():
        if isinstance(value, np.ndarray):
            assert out[key].dtype == value.dtype
            np.testing.assert_array_equal(out[key], value)
        elif key in {"snapshot", "state"}:
            restored = F.unpack_arrays(out[key])
            for k, v in value.items():
                np.testing.assert_array_equal(restored[k], v)
        elif key == "values_c":
            assert out[key][0] == value[0] and out[key][1] is None  # NaN → None (failed read)
        else:
            assert out[key] == value, key


def test_builders_fill_index_range_and_times() -> None:
    counts = np.zeros((5, 3), dtype=np.int64)
    rec = F.raw_record("r", 0, 100, counts, 1.0, 2.0)
    assert (rec["i0"], rec["n"], rec["t_mono"], rec["t_real"]) == (100, 5, 1.0, 2.0)
    assert rec["counts"].dtype == np.int32
    with pytest.raises(FormatError, match="integer counts"):
        F.raw_record("r", 0, 0, np.zeros((5, 3)), 0.0, 0.0)


@pytest.mark.parametrize("dtype", sorted(F.ALLOWED_DTYPES))
def test_whitelisted_dtypes_round_trip(dtype: str) -> None:
    a = (np.arange(24) % 2).astype(dtype).reshape(2, 3, 4)
    packed = F.pack_array(a)
    b = F.unpack_array(msgpack.unpackb(msgpack.packb(packed)))
    assert b.dtype == np.dtype(dtype) and b.shape == (2, 3, 4)
    np.testing.assert_array_equal(a, b)


def test_big_endian_and_non_contiguous_arrays_travel_little_endian() -> None:
    a = np.arange(12, dtype=">i4").reshape(3, 4)[:, ::2]
    packed = F.pack_array(a)
    assert packed["dtype"] == "<i4"
    np.testing.assert_array_equal(F.unpack_array(packed), a)


@pytest.mark.parametrize("bad", [np.array(["a"]), np.array([object()], dtype=object),
                                 np.array([1 + 2j])])
def test_pack_refuses_objects_strings_complex(bad: np.ndarray) -> None:
    with pytest.raises(FormatError):
        F.pack_array(bad)


@pytest.mark.parametrize(
    ("obj", "match"),
    [
        ({"dtype": "|O", "shape": [1], "data": b"12345678"}, "not allowed"),
        ({"dtype": ">i4", "shape": [1], "data": b"1234"}, "not allowed"),
        ({"dtype": "<U1", "shape": [1], "data": b"1234"}, "not allowed"),
        ({"dtype": "<i4", "shape": [2], "data": b"1234"}, "data holds"),
        ({"dtype": "<i4", "shape": [-1], "data": b"1234"}, "non-negative"),
        ({"dtype": "<i4", "shape": [True], "data": b"1234"}, "non-negative"),
        ({"dtype": "<i4", "shape": [1 << 62, 1 << 62], "data": b"1234"}, "data holds"),
        ({"dtype": "<i4", "shape": [1] * 9, "data": b"1234"}, "at most"),
        ({"dtype": "<i4", "shape": [1], "data": "1234"}, "must be bytes"),
        ({"dtype": "<i4", "shape": [1]}, "keys dtype, shape, data"),
    ],
)
def test_unpack_array_refuses(obj: dict, match: str) -> None:
    with pytest.raises(FormatError, match=match):
        F.unpack_array(obj)


def test_unpack_array_size_cap() -> None:
    packed = F.pack_array(np.zeros(1000))
    with pytest.raises(FormatError, match="cap"):
        F.unpack_array(packed, max_bytes=7999)
    assert F.unpack_array(packed, max_bytes=8000).shape == (1000,)


def _raw_bytes() -> bytes:
    return F.encode(_examples()[1])


def test_every_truncation_is_refused() -> None:
    data = _raw_bytes()
    for cut in range(len(data)):
        with pytest.raises(FormatError):
            F.decode(data[:cut])


def test_trailing_bytes_and_size_cap() -> None:
    data = _raw_bytes()
    with pytest.raises(FormatError, match=r"extra data|ExtraData"):
        F.decode(data + b"\x00")
    with pytest.raises(FormatError, match="cap"):
        F.decode(data, max_bytes=len(data) - 1)
    assert F.decode(data, max_bytes=len(data))["kind"] == "raw"


def _mutate(**changes: object) -> bytes:
    rec = dict(_examples()[1])
    rec["counts"] = F.pack_array(rec["counts"])
    for k, v in changes.items():
        if v is KeyError:
            del rec[k]
        else:
            rec[k] = v
    return msgpack.packb(rec, use_bin_type=True)


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"v": 2}, "version 2"),
        ({"v": "1"}, "version"),
        ({"kind": "pickle"}, "unknown record kind"),
        ({"kind": KeyError}, "unknown record kind"),
        ({"run": 5}, "'run' should be str"),
        ({"seq": -1}, "'seq' should be int"),
        ({"seq": 1.5}, "'seq' should be int"),
        ({"i0": KeyError}, "lacks the required field 'i0'"),
        ({"t_mono": "now"}, "'t_mono' should be num"),
        ({"n": 31}, "does not match n=31"),
        ({"counts": [1, 2, 3]}, "'counts' should be array"),
        ({"counts": {"dtype": "|O", "shape": [32, 3], "data": b"x" * 768}}, "not allowed"),
        ({"rate_hz": "fast"}, "'rate_hz' should be num"),
    ],
)
def test_invalid_records_are_refused_with_the_field_named(changes: dict, match: str) -> None:
    with pytest.raises(FormatError, match=match):
        F.decode(_mutate(**changes))


@pytest.mark.parametrize(
    "data",
    [
        b"",
        b"\xc1",                                   # never-used msgpack byte
        b"\xdd\xff\xff\xff\xff",                   # array claiming 4 G elements
        b"\xdf\xff\xff\xff\xff",                   # map claiming 4 G pairs
        b"\xdb\xff\xff\xff\xff",                   # str claiming 4 GB
        b"\xc6\xff\xff\xff\xff" + b"x" * 10,       # bin claiming 4 GB
        b"\x91" * 100_000,                         # deep nesting
        b"\xd6\xff\x00\x00\x00\x00",               # timestamp extension
        b"\xc7\x03\x05abc",                        # other extension
        msgpack.packb({1: 2}),                     # non-string key
        msgpack.packb([1, 2, 3]),                  # not a map
        msgpack.packb({"kind": "raw", "v": 1, "k": b"\xa1\xff"}),
        b"\x81\xa4kind\xa2\xff\xfe",               # invalid UTF-8
    ],
)
def test_hostile_bytes_raise_format_error_only(data: bytes) -> None:
    with pytest.raises(FormatError):
        F.decode(data)


def test_moderate_nesting_bounded_by_max_depth() -> None:
    nested: object = 1
    for _ in range(F.MAX_DEPTH + 2):
        nested = [nested]
    rec = dict(_examples()[6])
    rec["status"] = {"deep": nested}
    with pytest.raises(FormatError, match="nested deeper"):
        F.decode(msgpack.packb(rec))


def test_topics_of_kinds() -> None:
    assert F.topic_of({"kind": "gap"}) == "event"
    assert F.topic_of({"kind": "raw"}) == "raw"
    with pytest.raises(FormatError, match="not published"):
        F.topic_of({"kind": "checkpoint"})


def test_request_and_reply_messages() -> None:
    req = F.decode_request(F.encode_request("recent", {"seconds": 5}, id=9))
    assert req == {"op": "recent", "args": {"seconds": 5}, "id": 9}
    for bad, match in [(msgpack.packb({"args": {}}), "'op'"),
                       (msgpack.packb({"op": "x", "args": [1]}), "'args'"),
                       (msgpack.packb({"op": "x", "id": "1"}), "'id'"),
                       (msgpack.packb("snapshot"), "expected a map"),
                       (b"\x00" * 70000, "cap")]:
        with pytest.raises(FormatError, match=match):
            F.decode_request(bad)
    ok = F.decode_reply(F.encode_reply("status", result={"a": np.arange(3)}, id=2))
    assert ok["ok"] and ok["id"] == 2
    np.testing.assert_array_equal(F.unpack_arrays(ok["result"])["a"], np.arange(3))
    err = F.decode_reply(F.encode_reply("status", error="nope"))
    assert not err["ok"] and err["error"] == "nope"
    with pytest.raises(FormatError):
        F.decode_reply(msgpack.packb({"ok": True}))


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"temperature_channels": ["plate", 3]}, "list of strings"),
        ({"temperature_channels": "plate"}, "should be list"),
        ({"scale_m_s2_per_count": "big"}, "should be num"),
        ({"config": []}, "should be map"),
    ],
)
def test_header_fields_that_readers_use_are_checked(changes: dict, match: str) -> None:
    rec = dict(_examples()[0], **changes)
    with pytest.raises(FormatError, match=match):
        F.decode(msgpack.packb(rec, use_bin_type=True))

"""Hostile input against the record decoder (avard.core.io.frames): hypothesis fuzzing.

Every decoder must, for any bytes at all, either return a valid record or raise FormatError
with a message saying what is wrong: no other exception, no hang, and no allocation that grows
with what a header *claims* instead of with the bytes actually received. Inputs are: random
bytes; valid records truncated, bit-flipped, spliced and extended; arbitrary msgpack values;
valid records with single fields of the wrong type; packed arrays with hostile dtype/shape; deep
nesting; and every msgpack container/str/bin/ext header declaring 2**32 - 1 elements.

The number of inputs tried is counted per decoder and printed at the end of the pytest run
("avard fuzz inputs tried"); it is also kept in the pytest cache under avard/fuzz/. Set
AVARD_FUZZ_SCALE=20 (say) for a long run; CI uses scale 1.
"""

from __future__ import annotations

import os
import struct
import tracemalloc
from collections import Counter
from typing import Any

import msgpack
import numpy as np
import pytest
from avard.core.errors import FormatError
from avard.core.io import frames
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

SCALE = float(os.environ.get("AVARD_FUZZ_SCALE", "1"))


def fuzz_settings(examples: int) -> settings:
    return settings(
        max_examples=max(1, int(examples * SCALE)),
        deadline=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                               HealthCheck.filter_too_much],
        derandomize=SCALE == 1,  # CI: the same inputs every run; long runs explore
    )


# -------------------------------------------------------------------------- input counting


class _FuzzReport:
    """pytest plugin registered at run time: prints the counts in the terminal summary."""

    name = "avard-fuzz-report"

    def __init__(self) -> None:
        self.counts: Counter[str] = Counter()

    def pytest_terminal_summary(self, terminalreporter: Any) -> None:
        if not self.counts:
            return
        terminalreporter.section("avard fuzz inputs tried")
        for key in sorted(self.counts):
            terminalreporter.write_line(f"{key:<40} {self.counts[key]:>9}")
        terminalreporter.write_line(f"{'total':<40} {sum(self.counts.values()):>9}")


class FuzzCounter:
    """Counts inputs per decoder for one test module; merged into the run's report."""

    def __init__(self, report: _FuzzReport) -> None:
        self.report = report
        self.counts: Counter[str] = Counter()

    def tick(self, decoder: str, n: int = 1) -> None:
        self.counts[decoder] += n
        self.report.counts[decoder] += n


def make_counter(request: pytest.FixtureRequest) -> FuzzCounter:
    pm = request.config.pluginmanager
    report = pm.get_plugin(_FuzzReport.name)
    if report is None:
        report = _FuzzReport()
        pm.register(report, _FuzzReport.name)
    return FuzzCounter(report)


def save_counts(request: pytest.FixtureRequest, counter: FuzzCounter) -> None:
    cache = getattr(request.config, "cache", None)  # absent under -p no:cacheprovider
    if cache is not None:
        cache.set(f"avard/fuzz/{request.module.__name__.rsplit('.', 1)[-1]}",
                                 dict(counter.counts))


@pytest.fixture(scope="module")
def counter(request):
    c = make_counter(request)
    yield c
    save_counts(request, c)


# -------------------------------------------------------------------------- checking one input


def assert_clean_outcome(fn, data: bytes, **kwargs: Any) -> Any:
    """Call a decoder: a result or a FormatError with a real message; anything else fails."""
    try:
        return fn(data, **kwargs)
    except FormatError as exc:
        message = str(exc)
        assert len(message) >= 10, f"unhelpful error message {message!r}"
        return exc


def assert_bounded_allocation(fn, data: bytes, *, slack: int = 1 << 20, factor: int = 64,
                              **kwargs: Any) -> Any:
    """Run a decoder under tracemalloc: its peak allocation must be bounded by the bytes it was
    given (factor × len + slack), never by a length the input merely declares."""
    limit = factor * len(data) + slack
    peak = None
    # tracemalloc's peak is the process's: once in a while another thread (the test runner's)
    # allocates during the call. The decoder's own allocation is the same every time, so a
    # second measurement under the limit shows that the first one's excess was not its own.
    for _attempt in range(2):
        tracemalloc.start()
        try:
            outcome = assert_clean_outcome(fn, data, **kwargs)
            _, peak = tracemalloc.get_traced_memory()
        finally:
            tracemalloc.stop()
        if peak <= limit:
            break
    assert peak is not None and peak <= limit, \
        f"decoding {len(data)} bytes allocated {peak} bytes (> {limit})"
    return outcome


# -------------------------------------------------------------------------- strategies

_finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
_names = st.text(alphabet="abcdefxyz_0123456789", min_size=1, max_size=8)


@st.composite
def valid_records(draw) -> dict[str, Any]:
    """Records built by the same builders the service uses, with random content."""
    run = draw(st.text(max_size=12))
    seq = draw(st.integers(0, 2**63 - 1))
    t_mono, t_real = draw(_finite), draw(_finite)
    kind = draw(st.sampled_from(["header", "raw", "temp", "gap", "event", "avar", "status",
                                 "checkpoint"]))
    i0 = draw(st.integers(0, 2**62))
    if kind == "header":
        return frames.header_record(run, rate_hz=draw(_finite), t_mono=t_mono, t_real=t_real,
                                    i0=i0, seq=seq, scale_m_s2_per_count=3.8e-5,
                                    temperature_sensors=draw(st.lists(_names, max_size=3)))
    if kind == "raw":
        n = draw(st.integers(0, 40))
        counts = draw(st.lists(st.integers(-(2**19), 2**19 - 1), min_size=3 * n,
                               max_size=3 * n))
        return frames.raw_record(run, seq, i0, np.array(counts, np.int32).reshape(n, 3),
                                 t_mono, t_real, rate_hz=125.0)
    if kind == "temp":
        names = draw(st.lists(_names, max_size=4))
        values = draw(st.lists(st.one_of(st.none(), _finite), min_size=len(names),
                               max_size=len(names)))
        return frames.temp_record(run, seq, i0, names, values, t_mono, t_real)
    if kind == "gap":
        return frames.gap_record(run, seq, i0, draw(st.integers(0, 2**40)), t_mono, t_real,
                                 draw(st.sampled_from(["overrun", "bus_error", "restart"])))
    if kind == "event":
        return frames.event_record(run, seq, draw(_names), t_mono, t_real, i0=i0,
                                   detail={"step_s": draw(_finite)})
    if kind == "avar":
        snap = {"tau": np.arange(draw(st.integers(0, 8)), dtype=np.float64)}
        return frames.avar_record(run, seq, i0, i0, snap, t_mono, t_real)
    if kind == "status":
        return frames.status_record(run, seq, {"rate_hz": draw(_finite)}, t_mono, t_real)
    return frames.checkpoint_record(run, seq, i0, i0, {"sums": [draw(_finite)]}, t_mono, t_real)


def encoded(record: dict[str, Any]) -> bytes:
    return frames.encode(record)


# Arbitrary msgpack values, including every type msgpack has and odd mixes of them.
_msgpack_ints = st.integers(-(2**63), 2**64 - 1)  # every int msgpack can carry
_leaf = st.one_of(
    st.none(), st.booleans(), _msgpack_ints, st.floats(), st.text(max_size=20),
    st.binary(max_size=40),
)
msgpack_values = st.recursive(
    _leaf,
    lambda children: st.one_of(
        st.lists(children, max_size=6),
        st.dictionaries(st.text(max_size=8), children, max_size=6),
    ),
    max_leaves=40,
)


@st.composite
def mutated(draw, source) -> bytes:
    """Valid bytes, then damaged the ways files and networks damage them."""
    data = bytearray(draw(source))
    for _ in range(draw(st.integers(1, 4))):
        how = draw(st.sampled_from(["truncate", "flip", "insert", "append", "splice", "set"]))
        pos = draw(st.integers(0, max(0, len(data))))
        if how == "truncate":
            del data[pos:]
        elif how == "flip" and data:
            i = min(pos, len(data) - 1)
            data[i] ^= 1 << draw(st.integers(0, 7))
        elif how == "insert":
            data[pos:pos] = draw(st.binary(min_size=1, max_size=16))
        elif how == "append":
            data += draw(st.binary(min_size=1, max_size=64))
        elif how == "splice" and data:
            end = draw(st.integers(pos, len(data)))
            del data[pos:end]
        elif how == "set" and data:
            i = min(pos, len(data) - 1)
            data[i] = draw(st.sampled_from([0x00, 0xFF, 0xC1, 0xDD, 0xDF, 0xC6, 0xDB, 0xC9]))
    return bytes(data)


@st.composite
def wrong_type_records(draw) -> bytes:
    """A valid record with one field (or a nested array field) replaced by a hostile value."""
    rec = draw(valid_records())
    wire = msgpack.unpackb(encoded(rec), raw=False)
    key = draw(st.sampled_from(sorted(wire)))
    wire[key] = draw(st.one_of(msgpack_values, hostile_arrays()))
    return msgpack.packb(wire, use_bin_type=True)


@st.composite
def hostile_arrays(draw) -> dict[str, Any]:
    """Packed-array maps whose dtype, shape or data lie or try to make the decoder allocate."""
    dtype = draw(st.one_of(
        st.sampled_from(sorted(frames.ALLOWED_DTYPES)),
        st.sampled_from(["O", "|O", "<U8", "|S4", "V8", ">i4", "<c16", "<M8[s]", "", "i4"]),
        _msgpack_ints, st.none(), st.binary(max_size=4),
    ))
    shape = draw(st.one_of(
        st.lists(st.integers(-2, 2**63), max_size=10),
        st.just([2**31, 2**31]), st.just([2**62, 0, 2**62]), st.just([-1]),
        _msgpack_ints, st.text(max_size=4), st.lists(st.floats(), max_size=3),
    ))
    data = draw(st.one_of(st.binary(max_size=64), st.text(max_size=8), _msgpack_ints))
    return {"dtype": dtype, "shape": shape, "data": data}


def _declared(header: bytes, count_format: str, count: int) -> bytes:
    return header + struct.pack(count_format, count)


# Every msgpack header that declares a length, with the largest length its width allows.
HUGE_DECLARATIONS = [
    _declared(b"\xdd", ">I", 2**32 - 1),  # array 32
    _declared(b"\xdc", ">H", 2**16 - 1),  # array 16
    _declared(b"\xdf", ">I", 2**32 - 1),  # map 32
    _declared(b"\xde", ">H", 2**16 - 1),  # map 16
    _declared(b"\xdb", ">I", 2**32 - 1),  # str 32
    _declared(b"\xc6", ">I", 2**32 - 1),  # bin 32
    _declared(b"\xc9", ">I", 2**32 - 1) + b"\x01",  # ext 32
    _declared(b"\xd9", ">B", 255),  # str 8
]


@st.composite
def huge_declared_lengths(draw) -> bytes:
    """A (possibly valid-looking) prefix, then a header declaring 2**32-1 of something, then a
    few bytes: the decoder must notice the data are not there before it allocates."""
    prefix = draw(st.sampled_from([
        b"", b"\x81\xa4kind", b"\x84\xa4kind\xa3raw\xa1v\x01\xa3run\xa1r\xa3seq",
        b"\x91" * draw(st.integers(0, 20)),
    ]))
    body = draw(st.sampled_from(HUGE_DECLARATIONS))
    tail = draw(st.binary(max_size=32))
    return prefix + body + tail


@st.composite
def deep_nesting(draw) -> bytes:
    depth = draw(st.integers(frames.MAX_DEPTH - 2, 200_000))
    opener = draw(st.sampled_from([b"\x91", b"\x81\xa1k", b"\xdd\x00\x00\x00\x01"]))
    return opener * depth + b"\xc0"


# -------------------------------------------------------------------------- frames.decode


def _check_record(out: Any) -> None:
    if isinstance(out, FormatError):
        return
    assert isinstance(out, dict)
    frames.validate(out)  # whatever decode returns is a valid record
    for value in out.values():
        if isinstance(value, np.ndarray):
            assert value.dtype.str in frames.ALLOWED_DTYPES
            assert not value.flags.writeable  # a view on the received bytes, never copied


@fuzz_settings(1500)
@given(data=st.binary(max_size=2048))
def test_decode_random_bytes(counter, data):
    counter.tick("frames.decode")
    _check_record(assert_clean_outcome(frames.decode, data))


@fuzz_settings(400)
@given(data=mutated(valid_records().map(encoded)))
def test_decode_damaged_valid_records(counter, data):
    counter.tick("frames.decode")
    _check_record(assert_clean_outcome(frames.decode, data))


@fuzz_settings(200)
@given(rec=valid_records())
def test_decode_round_trips_every_valid_record(counter, rec):
    counter.tick("frames.decode")
    out = frames.decode(encoded(rec))
    assert out["kind"] == rec["kind"] and out["seq"] == rec["seq"] and out["run"] == rec["run"]
    if rec["kind"] == "raw":
        np.testing.assert_array_equal(out["counts"], rec["counts"])


@fuzz_settings(200)
@given(value=msgpack_values)
def test_decode_arbitrary_msgpack_values(counter, value):
    counter.tick("frames.decode")
    data = msgpack.packb(value, use_bin_type=True)
    _check_record(assert_clean_outcome(frames.decode, data))


@fuzz_settings(250)
@given(data=wrong_type_records())
def test_decode_records_with_a_field_of_the_wrong_type(counter, data):
    counter.tick("frames.decode")
    _check_record(assert_clean_outcome(frames.decode, data))


@fuzz_settings(300)
@given(array=hostile_arrays(), n=st.integers(0, 2**40))
# found by a run at AVARD_FUZZ_SCALE=10: zero elements, but a shape numpy refuses
@example(array={"dtype": "<f4", "shape": [2**62, 0, 2**62], "data": b""}, n=0)
def test_decode_raw_records_with_hostile_arrays(counter, array, n):
    counter.tick("frames.decode")
    rec = {"kind": "raw", "v": 1, "run": "r", "seq": 0, "i0": 0, "n": n, "t_mono": 0.0,
           "t_real": 0.0, "counts": array}
    data = msgpack.packb(rec, use_bin_type=True)
    _check_record(assert_bounded_allocation(frames.decode, data))
    counter.tick("frames.unpack_array")
    assert_bounded_allocation(frames.unpack_array, array)


@fuzz_settings(200)
@given(data=huge_declared_lengths())
def test_decode_huge_declared_lengths_allocate_nothing_big(counter, data):
    counter.tick("frames.decode")
    out = assert_bounded_allocation(frames.decode, data)
    assert isinstance(out, FormatError)


@fuzz_settings(40)
@given(data=deep_nesting())
def test_decode_deep_nesting_is_refused_without_recursion(counter, data):
    counter.tick("frames.decode")
    out = assert_clean_outcome(frames.decode, data)
    assert isinstance(out, FormatError)


def test_decode_oversized_input_is_refused_before_parsing(counter):
    counter.tick("frames.decode", 2)
    big = b"\x91" + b"\xc4\xff" + b"x" * (frames.DEFAULT_MAX_BYTES + 1)
    with pytest.raises(FormatError, match="cap"):
        frames.decode(big)
    with pytest.raises(FormatError, match="cap"):
        frames.decode(b"\x80" * 100, max_bytes=10)


# -------------------------------------------------------------------------- request / reply


@fuzz_settings(250)
@given(data=st.one_of(st.binary(max_size=512), msgpack_values.map(
    lambda v: msgpack.packb(v, use_bin_type=True)), huge_declared_lengths(), deep_nesting()))
def test_decode_request_and_reply(counter, data):
    counter.tick("frames.decode_request")
    req = assert_bounded_allocation(frames.decode_request, data)
    if not isinstance(req, FormatError):
        assert isinstance(req["op"], str) and isinstance(req["args"], dict)
    counter.tick("frames.decode_reply")
    assert_clean_outcome(frames.decode_reply, data)


@fuzz_settings(120)
@given(value=msgpack_values)
def test_unpack_arrays_on_any_decoded_structure(counter, value):
    counter.tick("frames.unpack_arrays")
    assert_clean_outcome(frames.unpack_arrays, value)

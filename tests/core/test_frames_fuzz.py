"""Hypothesis fuzzing of the record and request decoders: FormatError or a valid record, always.

Inputs tried per CI run: 3 × 300 examples (random bytes, mutated valid records, random msgpack
structures) plus 300 requests; ``--runslow`` runs 20 000 of each.
"""

from __future__ import annotations

import msgpack
import numpy as np
import pytest
from avard.core.errors import FormatError
from avard.core.io import frames as F
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

CI = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
SLOW = settings(max_examples=20_000, deadline=None, suppress_health_check=list(HealthCheck))

_VALID = F.encode(F.raw_record("run", 3, 96, np.arange(96, dtype=np.int32).reshape(32, 3),
                               1.0, 2.0, rate_hz=125.0))

_leaves = st.one_of(st.none(), st.booleans(), st.integers(-(1 << 63), (1 << 64) - 1),
                    st.floats(allow_nan=True), st.text(max_size=20), st.binary(max_size=40))
_msgpack_obj = st.recursive(
    _leaves,
    lambda children: st.one_of(st.lists(children, max_size=5),
                               st.dictionaries(st.text(max_size=8), children, max_size=5)),
    max_leaves=40,
)
# records that look nearly right: valid field names with arbitrary values
_fields = st.sampled_from(["kind", "v", "run", "seq", "i0", "n", "t_mono", "t_real", "counts",
                           "rate_hz", "names", "values_c", "snapshot", "status", "reason"])
_near_records = st.dictionaries(
    _fields,
    st.one_of(_msgpack_obj, st.sampled_from(F.KINDS), st.just(1),
              st.fixed_dictionaries({"dtype": st.sampled_from(["<i4", "|O", "<f8", ">i4"]),
                                     "shape": st.lists(st.integers(-2, 1 << 40), max_size=3),
                                     "data": st.binary(max_size=64)})),
)


def _decode_or_format_error(data: bytes) -> None:
    try:
        rec = F.decode(data, max_bytes=1 << 16)
    except FormatError as exc:
        assert str(exc)  # a message that says something
        return
    assert rec["kind"] in F.KINDS and rec["v"] == F.FORMAT_VERSION


def _mutated(data: bytes, edits: list[tuple[int, int]], cut: int) -> bytes:
    buf = bytearray(data)
    for pos, val in edits:
        buf[pos % len(buf)] = val
    return bytes(buf[: max(1, cut % (len(buf) + 1))])


@CI
@given(st.binary(max_size=2048))
def test_random_bytes(data: bytes) -> None:
    _decode_or_format_error(data)


@CI
@given(st.lists(st.tuples(st.integers(0, 10_000), st.integers(0, 255)), max_size=8),
       st.integers(0, 10_000))
def test_mutated_valid_records(edits: list[tuple[int, int]], cut: int) -> None:
    _decode_or_format_error(_mutated(_VALID, edits, cut if edits else len(_VALID)))


@CI
@given(st.one_of(_msgpack_obj, _near_records))
def test_random_msgpack_structures(obj: object) -> None:
    _decode_or_format_error(msgpack.packb(obj, use_bin_type=True))


@CI
@given(st.one_of(st.binary(max_size=512), _msgpack_obj.map(msgpack.packb)))
def test_requests(data: bytes) -> None:
    try:
        req = F.decode_request(data)
    except FormatError:
        return
    assert isinstance(req["op"], str) and isinstance(req["args"], dict)


@pytest.mark.slow
@SLOW
@given(st.one_of(st.binary(max_size=4096), _msgpack_obj.map(msgpack.packb),
                 _near_records.map(msgpack.packb)))
def test_long_fuzz(data: bytes) -> None:
    _decode_or_format_error(data)

"""StreamingAllan: equal to the batch estimator for any block split, gaps, merge, state."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest
from avard.core.allan.deviations import allan_variance, pavar
from avard.core.allan.streaming import AllanSnapshot, StreamingAllan
from avard.core.errors import DataError, FormatError
from hypothesis import given, settings
from hypothesis import strategies as st


def feed(acc: StreamingAllan, y: np.ndarray, sizes) -> None:
    i = 0
    for n in sizes:
        acc.update(y[i : i + n])
        i += n
    acc.update(y[i:])


def random_record(n: int, c: int, seed: int, integer: bool = False) -> np.ndarray:
    rng = np.random.default_rng(seed)
    if integer:
        # raw 20-bit counts around 1 g on the first axis (256000 LSB/g at ±2 g)
        return rng.integers(-400, 400, size=(n, c)) + np.array([256000] + [0] * (c - 1))
    drift = np.cumsum(rng.normal(0, 1e-3, (n, c)), axis=0)
    return rng.normal(0, 0.01, (n, c)) + drift + np.array([9.81] + [0.0] * (c - 1))


@settings(max_examples=25, deadline=None)
@given(
    # below and above the 4096-set threshold where small blocks are collected first
    sizes=st.lists(st.one_of(st.integers(0, 40), st.integers(0, 9000)), min_size=0,
                   max_size=12),
    rate=st.sampled_from([1.0, 100.0, 125.0, 3.7]),
    integer=st.booleans(),
    overlap=st.sampled_from([1, 4, 8]),
)
def test_streaming_equals_batch_for_any_block_split(sizes, rate, integer, overlap) -> None:
    y = random_record(20000, 2, seed=len(sizes), integer=integer)
    acc = StreamingAllan(2, rate, overlap=overlap)
    feed(acc, y, sizes)
    got = acc.result()
    ref = pavar(y, rate, overlap=overlap)
    np.testing.assert_array_equal(got.m, ref.m)
    np.testing.assert_array_equal(got.stride, ref.stride)
    np.testing.assert_array_equal(got.n, ref.n)
    np.testing.assert_allclose(got.tau, ref.tau, rtol=1e-15)
    np.testing.assert_allclose(got.var, ref.var, rtol=1e-12)
    np.testing.assert_array_equal(got.alpha, ref.alpha)
    np.testing.assert_allclose(got.edf, ref.edf, rtol=1e-12)
    np.testing.assert_allclose(got.lo, ref.lo, rtol=1e-12)


def test_tau0_not_one_gives_rate_independent_variance() -> None:
    """τ0 enters only τ = m·τ0: the same samples at another rate give the same variances, and
    they equal NIST SP 1065 eq. 12 written with the phase x = τ0·Σy and τ in seconds."""
    y = random_record(5000, 1, seed=1)[:, 0]
    a, b = StreamingAllan(1, 1.0), StreamingAllan(1, 250.0)
    a.update(y)
    b.update(y)
    ra, rb = a.result(), b.result()
    np.testing.assert_allclose(rb.tau, ra.tau / 250.0)
    np.testing.assert_array_equal(ra.var, rb.var)
    np.testing.assert_allclose(rb.var, avar_eq12(y, 250.0, rb.m, rb.stride), rtol=1e-9)


def avar_eq12(y: np.ndarray, rate: float, ms: np.ndarray, strides: np.ndarray) -> np.ndarray:
    """AVAR from NIST SP 1065 eq. 12 in seconds, x = τ0·cumsum(y), i on a grid of the stride."""
    tau0 = 1.0 / rate
    x = np.concatenate([[0.0], np.cumsum(y)]) * tau0
    out = []
    for m, s in zip(ms, strides, strict=True):
        tau = m * tau0
        i = np.arange(0, x.size - 2 * m, s)
        dd = x[i + 2 * m] - 2 * x[i + m] + x[i]
        out.append(np.sum(dd**2) / (2 * tau**2 * dd.size))
    return np.array(out)


def test_full_overlap_small_m_matches_oavar() -> None:
    y = random_record(4000, 1, seed=2)[:, 0]
    acc = StreamingAllan(1, 50.0)
    acc.update(y)
    got = acc.result()
    ref = allan_variance(y, 50.0, got.tau[:4], kind="oavar")
    np.testing.assert_allclose(got.var[:4], ref.var, rtol=1e-12)
    assert list(got.stride[:6]) == [1, 1, 1, 1, 2, 4]


def test_gaps_end_segments_like_batch() -> None:
    y = random_record(9000, 3, seed=3)
    acc = StreamingAllan(3, 10.0)
    acc.update(y[:2500])
    acc.gap()
    acc.update(y[2500:2510])  # a segment too short for any difference above m = 4
    acc.gap()
    acc.update(y[2510:])
    got = acc.result()
    ref = pavar(y, 10.0, gaps=[2500, 2510])
    np.testing.assert_array_equal(got.n, ref.n[: got.n.size])
    np.testing.assert_allclose(got.var, ref.var[: got.n.size], rtol=1e-12)
    assert acc.n_samples == 9000 and acc.n_segments == 3
    # no difference straddles a gap: fewer differences than without the gaps
    whole = StreamingAllan(3, 10.0)
    whole.update(y)
    assert np.all(got.n < whole.result().n[: got.n.size])


def test_merge_adds_sums_of_segments() -> None:
    y = random_record(8000, 2, seed=4, integer=True)
    a, b = StreamingAllan(2, 100.0), StreamingAllan(2, 100.0)
    a.update(y[:5000])
    b.update(y[5000:])
    a.merge(b)
    ref = pavar(y, 100.0, gaps=[5000])
    got = a.result()
    np.testing.assert_array_equal(got.n, ref.n)
    np.testing.assert_allclose(got.var, ref.var, rtol=1e-12)
    assert a.n_samples == 8000
    with pytest.raises(DataError, match="cannot merge"):
        a.merge(StreamingAllan(2, 50.0))


@pytest.mark.parametrize("integer", [True, False])
def test_state_round_trip_through_msgpack_continues_exactly(integer: bool) -> None:
    y = random_record(12000, 3, seed=5, integer=integer)
    straight = StreamingAllan(3, 100.0, names=["x", "y", "z"])
    straight.update(y)
    first = StreamingAllan(3, 100.0, names=["x", "y", "z"])
    first.update(y[:7001])
    first.update(y[7001:7010])  # leaves small blocks pending: state() must fold them in
    blob = msgpack.packb(first.state())
    resumed = StreamingAllan.from_state(msgpack.unpackb(blob))
    assert resumed.names == ["x", "y", "z"] and resumed.n_samples == 7010
    assert msgpack.packb(resumed.state()) == blob  # every sum and history point, bit for bit
    np.testing.assert_array_equal(resumed.result().var, first.result().var)
    resumed.update(y[7010:])
    np.testing.assert_allclose(resumed.result().var, straight.result().var, rtol=1e-12)
    np.testing.assert_array_equal(resumed.result().n, straight.result().n)


def test_state_is_small_and_bad_state_is_format_error() -> None:
    acc = StreamingAllan(6, 100.0)  # 3 axes + chip + 2 DS18B20
    acc.update(random_record(50000, 6, seed=6))
    assert len(msgpack.packb(acc.state())) <= 64 * 1024
    bad = acc.state()
    bad["v"] = 99
    with pytest.raises(FormatError, match="version"):
        StreamingAllan.from_state(bad)
    broken = acc.state()
    del broken["levels"]
    with pytest.raises(FormatError, match="malformed"):
        StreamingAllan.from_state(broken)


def test_weights_give_variance_of_linear_combination() -> None:
    rng = np.random.default_rng(7)
    temp = np.cumsum(rng.normal(0, 0.01, 20000))
    axis = 9.81 + 0.003 * temp + rng.normal(0, 1e-3, 20000)
    y = np.column_stack([axis, temp])
    acc = StreamingAllan(2, 100.0, names=["z", "t"])
    acc.update(y)
    w = np.array([1.0, -0.003])
    comb = acc.result(weights=w)
    single = StreamingAllan(1, 100.0)
    single.update(y @ w)
    ref = single.result()
    assert comb.var.ndim == 1
    np.testing.assert_allclose(comb.var, ref.var, rtol=1e-8)
    # removing the temperature term lowers the long-τ variance of the axis
    assert comb.var[-3] < acc.result().channel(0).var[-3]


def test_snapshot_contents_and_to_dict() -> None:
    acc = StreamingAllan(2, 100.0, names=["x", "t"])
    empty = acc.snapshot()
    assert empty.tau.size == 0 and empty.n_samples == 0
    acc.update(random_record(3000, 2, seed=8))
    snap = acc.snapshot(ci=0.9)
    assert isinstance(snap, AllanSnapshot)
    k = snap.tau.size
    assert snap.avar.shape == (k, 2) and snap.cov.shape == (k, 2, 2) and snap.edf.shape == (k, 2)
    assert np.all(snap.lo <= snap.avar) and np.all(snap.avar <= snap.hi)
    np.testing.assert_allclose(np.diagonal(snap.cov, axis1=1, axis2=2), snap.avar)
    d = msgpack.unpackb(msgpack.packb(snap.to_dict()))
    assert d["n_samples"] == 3000 and d["names"] == ["x", "t"] and d["ci"] == 0.9
    assert d["kind"] == "pavar"


def counts_stay_exact(n_total: int, offset: int) -> None:
    block = 1 << 20
    rng = np.random.default_rng(9)
    shifted, plain = StreamingAllan(1, 100.0), StreamingAllan(1, 100.0)
    head = []  # the first samples, for an independent check at m ≤ 8
    for start in range(0, n_total, block):
        noise = rng.integers(-200, 201, size=min(block, n_total - start), dtype=np.int64)
        shifted.update(noise + offset)
        plain.update(noise)
        if start < 4 * block:
            head.append(noise + offset)
    a, b = shifted.result(), plain.result()
    assert shifted.n_samples == n_total
    np.testing.assert_array_equal(a.var, b.var)
    np.testing.assert_array_equal(a.n, b.n)
    # Independent check: the same record's first 4 Mi samples, phase = plain int64 cumsum
    # without any offset removal (5e11 … 5e12 counts·samples), m = 1 … 8 (stride 1).
    y = np.concatenate(head)
    ref = StreamingAllan(1, 100.0)
    ref.update(y)
    x = np.concatenate([[0], np.cumsum(y)])
    for k, m in enumerate([1, 2, 4, 8]):
        dd = (x[2 * m :] - 2 * x[m:-m] + x[: -2 * m]).astype(np.float64)
        np.testing.assert_allclose(ref.result().var[k], np.sum(dd**2) / (2 * m * m * dd.size),
                                   rtol=1e-13)


def test_raw_counts_stay_exact_at_sixty_hour_phase_magnitude() -> None:
    """int64 phase keeps every difference exact: an offset changes no sum by a single bit.
    3 h at 100 Hz with a 20 g offset reaches the phase magnitude of 60 h at 1 g
    (2.16e7 samples × 256000 LSB ≈ 5.5e12); the full 60 h run is the slow test below."""
    counts_stay_exact(1_080_000, 5_120_000)


@pytest.mark.slow
def test_sixty_hours_of_raw_counts_on_a_1g_axis_stay_exact() -> None:
    """The full 60 h at 100 Hz (21.6 M samples) of 20-bit counts with 1 g = 256000 LSB."""
    counts_stay_exact(21_600_000, 256_000)


@pytest.mark.parametrize(
    ("block", "msg"),
    [
        (np.ones((10, 3)), "shape"),
        (np.ones(10), "shape"),
        (np.array([[1.0, np.nan]]), "NaN"),
        (np.array([["a", "b"]]), "dtype"),
    ],
)
def test_bad_blocks_raise(block, msg) -> None:
    acc = StreamingAllan(2, 100.0)
    with pytest.raises(DataError, match=msg):
        acc.update(block)


def test_bad_construction_and_too_early_result() -> None:
    with pytest.raises(DataError, match="rate_hz"):
        StreamingAllan(1, -1.0)
    with pytest.raises(DataError, match="overlap"):
        StreamingAllan(1, 1.0, overlap=6)
    with pytest.raises(DataError, match="n_channels"):
        StreamingAllan(0, 1.0)
    acc = StreamingAllan(1, 1.0)
    acc.update(np.ones(1))
    with pytest.raises(DataError, match="too few"):
        acc.result()


def test_integer_accumulator_refuses_fractional_samples() -> None:
    acc = StreamingAllan(1, 1.0)
    acc.update(np.arange(10))
    acc.update(np.array([3.0, 4.0]))  # integral floats are fine
    with pytest.raises(DataError, match="integer counts"):
        acc.update(np.array([0.5]))


def test_phase_beyond_2_pow_53_falls_back_to_exact_int64_grids() -> None:
    """int64 samples so large that the running sum passes 2**53: the accumulator switches
    that segment to int64 grids and still equals the batch estimator (which is int64 always)."""
    rng = np.random.default_rng(10)
    y = rng.integers(-(2**40), 2**40, size=(30000, 1)) + 2**48
    y[0] = 0  # the segment's first sample is removed, so the sum grows by ~2**48 per sample
    acc = StreamingAllan(1, 10.0)
    for blk in np.array_split(y, 7):
        acc.update(blk)
    ref = pavar(y[:, 0], 10.0)
    np.testing.assert_allclose(acc.result().var, ref.var, rtol=1e-12)
    assert acc.state()["big"] is True


def test_constant_input_gives_zero_and_nan_free_snapshot() -> None:
    acc = StreamingAllan(2, 100.0)
    acc.update(np.full((5000, 2), 256000, dtype=np.int32))
    snap = acc.snapshot()
    np.testing.assert_array_equal(snap.avar, 0.0)
    assert np.all(np.isfinite(snap.edf))


@pytest.mark.parametrize("integer", [True, False])
def test_streaming_hadamard_equals_batch_phvar(integer: bool) -> None:
    y = random_record(7000, 2, seed=11, integer=integer)
    acc = StreamingAllan(2, 50.0, hadamard=True)
    feed(acc, y, [1, 31, 999, 4097, 5])
    got = acc.result()
    ref = allan_variance(y, 50.0, kind="phvar")
    assert got.kind == "phvar"
    np.testing.assert_array_equal(got.n, ref.n)
    np.testing.assert_allclose(got.var, ref.var, rtol=1e-12)
    np.testing.assert_array_equal(got.alpha, ref.alpha)
    # the first levels are fully overlapping: the ordinary OHVAR
    np.testing.assert_allclose(got.var[:4], allan_variance(y, 50.0, got.tau[:4],
                                                           kind="ohvar").var, rtol=1e-12)
    again = StreamingAllan.from_state(msgpack.unpackb(msgpack.packb(acc.state())))
    assert again.kind == "phvar"
    np.testing.assert_array_equal(again.result().var, got.var)
    with pytest.raises(DataError, match="kind"):
        acc.merge(StreamingAllan(2, 50.0))


@settings(max_examples=20, deadline=None)
@given(
    cuts=st.lists(st.integers(0, 5000), min_size=1, max_size=8),
    gap_after=st.lists(st.booleans(), min_size=8, max_size=8),
    integer=st.booleans(),
)
def test_streaming_with_gaps_equals_batch_segments(cuts, gap_after, integer) -> None:
    """Random block boundaries, a gap after some of them: same sums as batch with gaps=."""
    y = random_record(5000, 2, seed=sum(cuts) % 97, integer=integer)
    edges = sorted(set(cuts))
    acc = StreamingAllan(2, 20.0)
    gaps, start = [], 0
    for i, e in enumerate(edges):
        acc.update(y[start:e])
        if gap_after[i] and 0 < e < 5000:
            acc.gap()
            gaps.append(e)
        start = e
    acc.update(y[start:])
    ref = pavar(y, 20.0, gaps=gaps)
    got = acc.result()
    k = got.n.size
    np.testing.assert_array_equal(got.n, ref.n[:k])
    assert np.all(ref.n[k:] == 0)
    np.testing.assert_allclose(got.var, ref.var[:k], rtol=1e-12)


def test_cascade_noise_id_sums_equal_the_plain_computation() -> None:
    """The ladders inside the cascade (averages queued per level, pushed in batches, carried
    through a state round trip with averages still queued, and ended by a gap) hold the lag-1
    autocorrelation of the non-overlapping m-averages computed plainly, at every level and
    difference order."""
    from .test_allan_noise_id import _pooled_r1

    y = random_record(30000, 2, 8)
    acc = StreamingAllan(2, 10.0)
    rng = np.random.default_rng(8)
    i = 0
    for cut in (17000, 30000):
        while i < cut:
            n = int(min(cut - i, rng.integers(1, 5000)))
            acc.update(y[i:i + n])
            i += n
            if 9000 <= i < 9000 + 5000 and n < 5000:
                acc = StreamingAllan.from_state(msgpack.unpackb(msgpack.packb(acc.state())))
        if cut == 17000:
            acc.gap()
    acc.result()  # settles the queues
    segs = [y[:17000], y[17000:]]
    for lev in acc._levels:
        m = lev.m
        avgs = [np.diff(np.concatenate([np.zeros((1, 2)), np.cumsum(s, axis=0)])[::m], axis=0)
                for s in segs]
        for k in range(3):
            parts = [np.diff(a, n=k, axis=0) for a in avgs]
            parts = [q for q in parts if len(q) > 1]
            if sum(len(q) for q in parts) < 3:
                continue
            for ch in range(2):
                want = _pooled_r1([q[:, ch] for q in parts])
                assert lev.ladder.r1(k)[ch] == pytest.approx(want, abs=1e-9), (m, k, ch)


@pytest.mark.parametrize("hadamard", [False, True])
def test_covariance_alone_is_the_results_covariance_to_the_bit(hadamard: bool) -> None:
    """``covariance()`` (explain's compensated AVAR reads only τ and the covariance) gives
    ``result()``'s τ and covariance to the bit: one and three channels, with a gap, blocks of
    any size, integer counts; and it refuses too few samples as ``result`` does."""
    rng = np.random.default_rng(11)
    for c, integer in ((1, False), (3, False), (2, True)):
        x = np.cumsum(rng.standard_normal((30_000, c)), axis=0)
        if integer:
            x = np.rint(1000 * x).astype(np.int64)
        sa = StreamingAllan(c, 7.5, hadamard=hadamard)
        for a, b in ((0, 1000), (1000, 1003), (1003, 20_000)):
            sa.update(x[a:b])
        sa.gap()
        sa.update(x[20_000:])
        got = sa.covariance()
        res = sa.result()
        assert got.tau.tobytes() == res.tau.tobytes()
        assert res.cov is not None and got.cov.tobytes() == res.cov.tobytes()
    with pytest.raises(DataError, match="no Allan variance yet"):
        StreamingAllan(1, 1.0).covariance()

"""The compiled OADEV loop (``core/allan/_kernels.c``) against the numpy path it stands beside:
the same sums, the same OADEV, α and R(n), for any split into pieces, gaps and channels.

Locally a missing build skips the compiled half, saying why; under CI (``CI=true``) the
extension must have been built (the install compiles it), so a missing one fails."""

from __future__ import annotations

import itertools
import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from avard.core.allan import kernels
from avard.core.allan.noise_id import Lag1Ladder, RnSums
from avard.core.allan.overlapping import OverlappingAllan
from avard.core.errors import DataError


@pytest.fixture
def compiled() -> Iterator[None]:
    if kernels._C is None:
        reason = "the compiled kernel is not built (no compiler at install?)"
        if os.environ.get("CI") == "true":
            pytest.fail(f"CI must test the compiled kernel: {reason}")
        pytest.skip(reason)
    yield
    kernels.use_compiled(True)


def test_sumsq_equals_numpy(compiled: None) -> None:
    rng = np.random.default_rng(5)
    x = np.cumsum(rng.standard_normal(20_011)) + 1e4  # a wandering phase far from 0
    c = kernels.compiled()
    assert c is not None
    for m, n in [(1, 1), (1, 3), (3, 7), (17, 5000), (4096, 11_000)]:
        x0, x1, x2 = x[:n], x[m:m + n], x[2 * m:2 * m + n]
        d = kernels.second_differences(x0, x1, x2)
        assert c.sumsq(x0, x1, x2) == pytest.approx(float(np.dot(d, d)), rel=1e-12)
    assert c.sumsq(x[:0], x[:0], x[:0]) == 0.0


def test_sumsq_is_its_four_lane_sum_bit_for_bit(compiled: None) -> None:
    """``sumsq`` is exactly its definition's four partial sums (difference i into lane
    i mod 4, the last n mod 4 into lane 0, then (s0 + s1) + (s2 + s3)), whichever copy of
    the loop the loader picked for this CPU (an AVX2 one on x86-64): Python's floats, the
    same IEEE operations in the same order, give the very bits."""
    c = kernels.compiled()
    assert c is not None
    rng = np.random.default_rng(29)
    x = np.cumsum(rng.standard_normal(30_011)) * 1e-3 + 9.81
    for m, n in [(1, 5), (2, 4_099), (7, 10_002), (1_024, 20_001)]:
        x0, x1, x2 = x[:n].tolist(), x[m:m + n].tolist(), x[2 * m:2 * m + n].tolist()
        lanes = [0.0, 0.0, 0.0, 0.0]
        n4 = n - n % 4
        for i in range(n):
            d = (x2[i] - x1[i]) - (x1[i] - x0[i])
            lanes[i % 4 if i < n4 else 0] += d * d
        want = (lanes[0] + lanes[1]) + (lanes[2] + lanes[3])
        assert c.sumsq(x[:n], x[m:m + n], x[2 * m:2 * m + n]) == want


def test_sumsq_refuses_what_it_cannot_read(compiled: None) -> None:
    c = kernels.compiled()
    assert c is not None
    x = np.zeros(10)
    with pytest.raises(ValueError, match="same length"):
        c.sumsq(x[:5], x[:4], x[:5])
    with pytest.raises((TypeError, ValueError, BufferError)):
        c.sumsq(x[::2], x[:5], x[:5])  # strided: not contiguous
    with pytest.raises(TypeError, match="float64"):
        c.sumsq(np.zeros(5, np.float32), x[:5], x[:5])


def test_sumsq_ring_is_sumsq_on_the_spans_bit_for_bit(compiled: None) -> None:
    """``sumsq_ring`` (every channel at many τ in one call, straight from the OADEV's ring)
    gives each span's ``sumsq`` to the bit, where a span lies whole in the ring and where
    x0, x1, x2 or all three wrap round its end (the loop then runs between the wrap points,
    each difference in its lane), for lengths of every remainder mod 4 and none."""
    c = kernels.compiled()
    assert c is not None
    rng = np.random.default_rng(17)
    cap = 1000
    ring = np.cumsum(rng.standard_normal((3, cap)), axis=1) + 1e4

    def span(ch: int, p: int, n: int) -> np.ndarray:
        return ring[ch, np.arange(p, p + n) % cap]  # a copy, in order across the end

    rows = [(0, 1, 0), (0, 1, 1), (5, 3, 7), (0, 17, 966), (990, 1, 9), (985, 2, 13),
            (600, 150, 131), (700, 120, 257), (2_997, 1, 1000 - 2), (10_400, 333, 334),
            (980, 7, 1000), (421, 499, 2)]
    spans = np.array(rows, dtype=np.int64)
    out = np.full((len(rows), 3), np.nan)
    c.sumsq_ring(ring, spans, out)
    wrapped = 0
    for j, (lo, m, n) in enumerate(rows):
        wrapped += any((p % cap) + n > cap for p in (lo, lo + m, lo + 2 * m))
        for ch in range(3):
            want = c.sumsq(span(ch, lo, n), span(ch, lo + m, n), span(ch, lo + 2 * m, n))
            assert out[j, ch] == want, (lo, m, n, ch)
    assert wrapped >= 6  # the cases above do wrap, each of the three spans in some
    with pytest.raises(ValueError, match="span"):
        c.sumsq_ring(ring, np.array([[0, 0, 5]], dtype=np.int64), np.empty((1, 3)))
    with pytest.raises(ValueError, match="span"):
        c.sumsq_ring(ring, np.array([[0, 1, cap + 1]], dtype=np.int64), np.empty((1, 3)))
    with pytest.raises(ValueError, match="out"):
        c.sumsq_ring(ring, spans, np.empty((len(rows), 2)))
    with pytest.raises(TypeError, match="int64"):
        c.sumsq_ring(ring, spans.astype(np.float64), out)


def test_rn_sums_push_phase_equals_push(compiled: None) -> None:
    """The fused loop keeps exactly the running sums ``push`` keeps: same MVAR/AVAR ratio,
    ring and carry, whatever the split, across a gap."""
    rng = np.random.default_rng(9)
    x = np.cumsum(rng.standard_normal((2, 9000)), axis=1)
    m = 37
    pieces = [0, 1, 50, 51, 2000, 4321, 9000 - 2 * m]

    def feed(use_c: bool) -> RnSums:
        kernels.use_compiled(use_c)
        r = RnSums(2, m)
        for a, b in itertools.pairwise(pieces):
            r.push_phase(x[:, a:b], x[:, a + m:b + m], x[:, a + 2 * m:b + 2 * m])
            if a == 2000:
                r.gap()
        return r

    fast, slow = feed(True), feed(False)
    np.testing.assert_allclose(fast.ratio(), slow.ratio(), rtol=1e-12)
    assert fast.n_mod == slow.n_mod and fast.n_d == slow.n_d
    np.testing.assert_allclose(fast.s_d, slow.s_d, rtol=1e-12)
    # the fused loop's Σ D² is sumsq's to the bit: keeping R(n) never changes the OADEV
    kernels.use_compiled(True)
    c = kernels.compiled()
    assert c is not None
    ring = np.zeros(m)
    for n in (1, 4, 7, 1001):
        got = c.sumsq_mod(x[0, :n], x[0, m:m + n], x[0, 2 * m:2 * m + n], ring, 0, 0.0)[0]
        assert got == c.sumsq(x[0, :n], x[0, m:m + n], x[0, 2 * m:2 * m + n])


@pytest.mark.parametrize(("piece", "span"), [(64, 1 << 18), (1 << 12, 1 << 18), (1 << 12, 5000)])
def test_oadev_compiled_equals_numpy(compiled: None, piece: int, span: int,
                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """The whole estimator on both paths: short τ (one span) and long τ (three spans, the
    ring wrapping), R(n) kept where the record is short in averages, a gap, 2 channels; the
    ladder's averages taken from the ring in spans cut by the ring's end, a gap, or
    ``LADDER_SPAN``."""
    from avard.core.allan import overlapping

    monkeypatch.setattr(overlapping, "LADDER_SPAN", span)
    rng = np.random.default_rng(piece)
    n = 40_000
    walk = np.cumsum(rng.standard_normal((n, 2)), axis=0) * 1e-3
    y = rng.standard_normal((n, 2)) + walk + np.array([0.0, 9.81])
    ms = 2 ** np.arange(14)

    def run(use_c: bool, n_total: int | None) -> OverlappingAllan:
        kernels.use_compiled(use_c)
        oa = OverlappingAllan(2, 100.0, ms, piece=piece, n_total=n_total)
        oa.update(y[:12_345])
        oa.update(y[12_345:25_000])
        oa.gap()
        oa.update(y[25_000:])
        return oa

    for n_total in (None, n):
        fast_acc, slow_acc = run(True, n_total), run(False, n_total)
        fast, slow = fast_acc.result(), slow_acc.result()
        np.testing.assert_allclose(fast.var, slow.var, rtol=1e-11)
        np.testing.assert_array_equal(fast.n, slow.n)
        np.testing.assert_array_equal(fast.alpha, slow.alpha)
        np.testing.assert_allclose(fast.edf, slow.edf, rtol=1e-9)
        _assert_same_ladders(fast_acc, slow_acc)


def _assert_same_ladders(fast: OverlappingAllan, slow: OverlappingAllan) -> None:
    """Every τ's noise-identification sums equal on both paths (α alone, being rounded,
    would hide a wrong span)."""
    for k, (a, b) in enumerate(zip(fast._ladders, slow._ladders, strict=True)):
        ta, tb = a.totals(), b.totals()
        for f in Lag1Ladder.FIELDS:
            np.testing.assert_allclose(ta[f], tb[f], rtol=1e-9, atol=1e-9 * max(
                1.0, float(np.max(np.abs(tb["s2"])))), err_msg=f"tau {k}: {f}")


def test_averages_waiting_in_the_ring_survive_a_short_piece(compiled: None) -> None:
    """A block's short last piece brings no average at a long m; the full piece after it
    must not overwrite the averages still waiting in the ring (a grid that is not octaves,
    where the ring's length is no multiple of every m)."""
    y = np.random.default_rng(16).standard_normal(65536 + 43 + 65536) + 3.0
    cuts = [(0, 65536), (65536, 65579), (65579, len(y))]

    def run(use_c: bool) -> OverlappingAllan:
        kernels.use_compiled(use_c)
        oa = OverlappingAllan(1, 1.0, [60, 32780])
        for a, b in cuts:
            oa.update(y[a:b])
        return oa

    fast, slow = run(True), run(False)
    np.testing.assert_array_equal(fast.result().alpha, slow.result().alpha)
    _assert_same_ladders(fast, slow)


def _lag_reference(z: np.ndarray, lags: int, old: int) -> list[float]:
    """Σ z over the new values and Σ z_t z_{t+j} over pairs whose later value is new."""
    out = [float(z[old:].sum())]
    for j in range(lags + 1):
        t = np.arange(max(0, len(z) - j))
        keep = t + j >= old
        out.append(float(np.dot(z[t[keep]], z[t[keep] + j])))
    return out


def test_lag_sums_equals_numpy(compiled: None) -> None:
    """The ladder's sums from a running-sum span (m ≥ 1) or from the values (m = 0), with the
    first ``old`` values only in the products reaching a new one: every length round the
    loop's block and vector steps."""
    c = kernels.compiled()
    assert c is not None
    rng = np.random.default_rng(12)
    y = rng.standard_normal(5000) + 3.0
    x = np.concatenate([[0.0], np.cumsum(y)])
    for m, k, old, lags in itertools.product((0, 1, 3, 64), (0, 1, 3, 4, 7, 511, 512, 513,
                                                              1030), (0, 1, 3), (0, 1, 3)):
        if old > k or (m > 1 and k * m > len(y)):
            continue
        src = y[:k] if m == 0 else x[:k * max(m, 1) + 1]
        z = (y[:k] if m == 0 else np.diff(x[:k * m + 1:m])) - 0.25
        out = np.zeros(lags + 2)
        assert c.lag_sums(src, m, 0.25, out, old) == k
        np.testing.assert_allclose(out, _lag_reference(z, lags, old), rtol=1e-12, atol=1e-9)
    with pytest.raises(ValueError, match="out must hold"):
        c.lag_sums(x, 1, 0.0, np.zeros(6), 0)
    with pytest.raises(ValueError, match="old"):
        c.lag_sums(x[:3], 1, 0.0, np.zeros(5), 3)
    with pytest.raises(ValueError, match="m must"):
        c.lag_sums(x, -1, 0.0, np.zeros(5), 0)


def test_running_sum_is_numpys_cumsum_bit_for_bit(compiled: None) -> None:
    """The OADEV's running sum from a strided column, offset taken off: the very bits of
    numpy's subtract and cumsum (so the OADEV is the same on both paths)."""
    c = kernels.compiled()
    assert c is not None
    a = np.random.default_rng(13).normal(9.81, 1e-3, (70_001, 3))
    out = np.empty(len(a))
    for ch in range(3):
        last = c.running_sum(a[:, ch], a[0, ch], 2.5, out)
        ref = np.empty(len(a) + 1)
        ref[0] = 2.5
        np.subtract(a[:, ch], a[0, ch], out=ref[1:])
        np.cumsum(ref, out=ref)
        np.testing.assert_array_equal(out, ref[1:])
        assert last == ref[-1]
    with pytest.raises(ValueError, match="same length"):
        c.running_sum(a[:5, 0], 0.0, 0.0, out)


def test_ladder_compiled_equals_numpy(compiled: None) -> None:
    """Lag1Ladder on both paths, fed pushes of every size (the few-values start, the compiled
    loop's minimum, spans that begin with the last pushed averages), a gap and a shift: the
    same sums to rounding and the same α."""
    rng = np.random.default_rng(14)
    y = rng.standard_normal((3, 30_000)).cumsum(axis=1) * 1e-2 + rng.standard_normal((3, 30_000))
    m = 4
    x = np.concatenate([np.zeros((3, 1)), np.cumsum(y, axis=1)], axis=1)
    sizes = [5, 10, 70, 63, 64, 2000, 1, 3000]

    def run(use_c: bool) -> Lag1Ladder:
        kernels.use_compiled(use_c)
        lad = Lag1Ladder(3, cross=False)
        j = 0
        for i, size in enumerate(sizes):
            if i == 6:
                lad.gap()
            if i % 2:
                old = lad.span_overlap() if i != 6 else 0
                lad.push_spans(x[:, (j - old) * m:(j + size) * m + 1], m, np.full(3, 0.5), old)
            else:
                z = x[:, (j + 1) * m:(j + size) * m + 1:m] - x[:, j * m:(j + size - 1) * m + 1:m]
                lad.push_rows(z, np.full(3, 0.5))
            j += size
        return lad

    fast, slow = run(True), run(False)
    tf, ts = fast.totals(), slow.totals()
    for f in Lag1Ladder.FIELDS:
        np.testing.assert_allclose(tf[f], ts[f], rtol=1e-10, atol=1e-8, err_msg=f)
    np.testing.assert_array_equal(fast.alpha(-2), slow.alpha(-2))
    with pytest.raises(DataError, match="old"):
        fast.push_spans(x[:, :100], m, None, 4)
    assert fast.span_overlap() == 3
    with pytest.raises(DataError, match="old=1"):  # part of the reach-back: refused
        fast.push_spans(x[:, :100], m, None, 1)


def test_welch_compiled_equals_numpy(compiled: None) -> None:
    """The Welch spectrum's Σ |X|² over segments by ``power_sum`` and by numpy's square and
    sums: the same PSD to rounding, over blocks that leave segments across their ends."""
    from avard.core.analysis.spectrum import WelchAccumulator

    a = np.random.default_rng(15).standard_normal((50_000, 2)) + np.array([0.0, 9.81])
    psd = []
    for use_c in (True, False):
        kernels.use_compiled(use_c)
        w = WelchAccumulator(2, 100.0, 4096)
        for i in range(0, len(a), 7000):
            w.update(a[i:i + 7000])
        psd.append(w.result()[1])
    np.testing.assert_allclose(psd[0], psd[1], rtol=1e-12)
    kernels.use_compiled(True)
    c = kernels.compiled()
    assert c is not None
    with pytest.raises(ValueError, match="k blocks"):
        c.power_sum(np.zeros(10), 2, np.zeros(3))


def test_a_build_of_another_interface_is_not_used(compiled: None,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """A stale ``_kernels`` (built from another ``_kernels.c``, e.g. left in a source tree)
    is ignored, and ``AVARD_NO_C_KERNELS`` chooses numpy only when set to something other
    than 0."""
    from avard.core.allan import _kernels  # type: ignore[attr-defined]

    assert kernels._load() is _kernels
    monkeypatch.setattr(_kernels, "API", kernels.API + 1)
    assert kernels._load() is None
    monkeypatch.setattr(_kernels, "API", kernels.API)
    monkeypatch.setenv("AVARD_NO_C_KERNELS", "0")
    assert kernels._load() is _kernels
    monkeypatch.setenv("AVARD_NO_C_KERNELS", "1")
    assert kernels._load() is None


@pytest.mark.parametrize("n", [17, 18, 19, 40, 65536])
def test_local_residual_equals_numpy(compiled: None, n: int) -> None:
    """The input screen's statistic by ``local_residual`` (one pass, a strided column) and by
    numpy's reflected pad and cumulative sum: equal to rounding at every length the screen
    uses, ends included, and the screen's verdicts on a record with shocks and a start-up
    glitch the same on both paths."""
    from avard.core.io.screen import screen_accel
    from avard.core.io.screen.accel import _local_residual

    rng = np.random.default_rng(n)
    a = rng.normal(0, 1e-3, (n, 3)) + np.array([0.0, 0.0, 9.81])
    c = kernels.compiled()
    assert c is not None
    for j in range(3):
        out = np.empty(n)
        c.local_residual(a[:, j], 8, out)
        ref = np.abs(_local_residual(np.ascontiguousarray(a[:, j]), 8))
        np.testing.assert_allclose(out, ref, rtol=0, atol=1e-12)
    if n == 65536:
        a[3, 1] += 0.05  # a start-up glitch
        a[30_000:30_003, 0] -= 0.04  # a 3-sample shock
        a[50_000, 2] += 0.03
        got = screen_accel(a)
        kernels.use_compiled(False)
        want = screen_accel(a)
        np.testing.assert_array_equal(got, want)
        assert got[3] and got[30_001] and got[50_000]
    with pytest.raises(ValueError, match="len"):
        c.local_residual(np.zeros(16), 8, np.zeros(16))


def test_first_order_is_lfilter_bit_for_bit(compiled: None) -> None:
    """explain's thermal lag (``thermal_fit.lag_filter``) on the compiled loop: the very bits
    of scipy.signal.lfilter from its lfilter_zi steady state, for lags of either sign from a
    fraction of a block to longer than the record, and through the whole lag scan."""
    from avard.core.explain.thermal_fit import lag_filter
    from avard.core.sim.thermal import lag_coefficients
    from scipy import signal as sps

    c = kernels.compiled()
    assert c is not None
    rng = np.random.default_rng(23)
    T = 21.0 + np.cumsum(rng.normal(0.0, 0.01, 20_001)) + 0.0625 * rng.integers(0, 3, 20_001)
    for lag in (0.3, 4.0, 37.5, 600.0, 1e6):
        b, a = lag_coefficients(lag, 0.8)
        out = np.empty(len(T))
        last = c.first_order(T, b[0], b[1], a[1], 0.7, out)
        ref, zf = sps.lfilter(b, a, T, zi=[0.7])
        np.testing.assert_array_equal(out, ref)
        assert last == zf[0]
        for sign in (1.0, -1.0):
            fast = lag_filter(T, sign * lag, 1.25)
            kernels.use_compiled(False)
            try:
                slow = lag_filter(T, sign * lag, 1.25)
            finally:
                kernels.use_compiled(True)
            np.testing.assert_array_equal(fast, slow)
    with pytest.raises(ValueError, match="as long as x"):
        c.first_order(T[:5], 1.0, 0.0, 0.0, 0.0, np.empty(4))


def test_explain_with_the_compiled_lag_equals_scipys(compiled: None, tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """A whole explanation on a seeded weekend record (a coupling through a lag, the lag scan,
    its jackknife, the held-out halves) is the same with the compiled thermal lag as with
    scipy's lfilter (the other kernels on in both): every finding, parameter and interval,
    bit for bit."""
    from types import SimpleNamespace

    from avard.core.explain.engine import explain_file
    from avard.core.explain.options import ExplainOptions
    from avard.core.io.source import open_record

    from tests.support.weekend import Weekend, save

    w = Weekend(hours=2.0, die_tau_s=300.0, plate_tau_s=0.0, coefficient=(8e-4, 0.0, 0.0))
    path = save(23017, w, tmp_path / "w.npz")

    def claims() -> list[tuple[str, str, dict[str, float], dict[str, list[float]]]]:
        ex = explain_file(open_record(str(path)), ExplainOptions(heldout=True))
        return [(a, f.cause, f.params, f.intervals) for a, ch in ex.channels.items()
                for f in ch.findings]

    fast = claims()
    # the thermal lag filter reads the kernels in thermal_fit.signals
    from avard.core.explain.thermal_fit import signals

    monkeypatch.setattr(signals, "kernels", SimpleNamespace(compiled=lambda: None))
    slow = claims()
    assert any(c[1] == "temperature" for c in fast)
    assert fast == slow

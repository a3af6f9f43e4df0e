"""core/allan/cross.py: the streaming Allan moments of a sensor pair, held equal to the batch
path of the one separation estimator (core/analysis/separate.py), across block splits, gaps,
merges and checkpoints; and the state's size per pair, measured."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest
from avard.core.allan.cross import CrossAllan, PairMoments
from avard.core.allan.deviations import allan_variance
from avard.core.analysis.separate import PAIRS, AxisSeparation, separate, separate_moments
from avard.core.errors import DataError, FormatError

RATE = 125.0
AXES = ("x", "y", "z")


def _rig(seed: int, n: int, s: int, common: float = 1e-4) -> list[np.ndarray]:
    """``s`` sensors (n, 3) m/s²: one bed (white + a slow walk) plus each one's own white
    noise of a different level."""
    rng = np.random.default_rng(seed)
    bed = rng.normal(0, common, (n, 3)) + np.cumsum(rng.normal(0, 2e-6, (n, 3)), axis=0)
    return [bed + rng.normal(0, (1.5 + i) * 1e-4, (n, 3)) + 9.81 * (i == 0)
            for i in range(s)]


def _streamed(ys: list[np.ndarray], blocks: list[int]) -> dict[tuple[int, int], CrossAllan]:
    """Pair accumulators fed the aligned records in blocks of the given sizes (cycled)."""
    axes = AXES[:ys[0].shape[1]]
    accs = {p: CrossAllan(RATE, axes=axes, sensors=(f"s{p[0]}", f"s{p[1]}"))
            for p in PAIRS[len(ys)]}
    i, k = 0, 0
    n = len(ys[0])
    while i < n:
        j = min(n, i + blocks[k % len(blocks)])
        for (a, b), acc in accs.items():
            acc.update(ys[a][i:j], ys[b][i:j])
        i, k = j, k + 1
    return accs


def _live(accs: dict[tuple[int, int], CrossAllan], s: int) -> list[AxisSeparation]:
    moments = {p: acc.moments() for p, acc in accs.items()}
    axes = next(iter(accs.values())).axes
    return [separate_moments({p: m[c] for p, m in moments.items()}, s, ax)
            for c, ax in enumerate(axes)]


def _offline_moments(ys: list[np.ndarray], c: int) -> dict[tuple[int, int], PairMoments]:
    """The batch moments (the cascade's stride) of each pair, as separate() computes them."""
    s = len(ys)
    cols = [y[:, c] for y in ys]
    res = allan_variance(np.column_stack(cols + [cols[i] - cols[j] for i, j in PAIRS[s]]),
                         RATE, kind="pavar")
    return {p: PairMoments.from_result(res, p[0], p[1], s + k, len(cols[0]))
            for k, p in enumerate(PAIRS[s])}


def _assert_same(live: list[AxisSeparation], offline: list[AxisSeparation],
                 ys: list[np.ndarray], accs: dict[tuple[int, int], CrossAllan],
                 rel: float = 1e-12) -> None:
    """The moments to ``rel``; the separated parts, which are differences of them (eqs. 1, 2),
    to ``rel`` of the moments they are differences of (a self-noise near 0 is the difference
    of two variances 10⁴ times larger, so its own relative rounding is not the estimator's)."""
    for c, (x, y) in enumerate(zip(live, offline, strict=True)):
        want = _offline_moments(ys, c)
        scale = np.zeros(len(x.m))
        for p, acc in accs.items():
            got, ref = acc.moments()[c], want[p].at(x.m)
            got = got.at(x.m)
            for f in ("var_a", "var_b", "cov", "var_d", "edf_a", "edf_b", "edf_d"):
                np.testing.assert_allclose(getattr(got, f), getattr(ref, f), rtol=rel, atol=0)
            scale = np.maximum.reduce([scale, ref.var_a, ref.var_b])
        np.testing.assert_array_equal(x.m, y.m)
        np.testing.assert_array_equal(x.averages, y.averages)
        for p, q in zip((*x.self_noise, x.common), (*y.self_noise, y.common), strict=True):
            np.testing.assert_array_equal(p.upper_limit, q.upper_limit)
            np.testing.assert_array_less(np.abs(p.var - q.var), rel * scale)
            np.testing.assert_allclose(p.lo, q.lo, rtol=rel, atol=0)
            np.testing.assert_allclose(p.hi, q.hi, rtol=rel, atol=0)
            np.testing.assert_allclose(p.edf, q.edf, rtol=1e-9)
        assert [v.state for v in x.verdicts] == [v.state for v in y.verdicts]


@pytest.mark.parametrize("s", [2, 3])
def test_streaming_separation_equals_the_offline_estimator(s: int) -> None:
    ys = [y[:, 1:] for y in _rig(s, 40_000, s)]    # y and z (3 axes: the service's test)
    offline = separate(ys, RATE, sensors=[f"s{i}" for i in range(s)], axes=AXES[1:],
                       fit=False, overlap=8)
    accs = _streamed(ys, [1, 37, 4096, 5000, 3])
    live = _live(accs, s)
    assert len(live[0].tau) >= 12
    _assert_same(live, list(offline.axes), ys, accs)
    # up to m = S the cascade is fully overlapping: the default offline separation there
    full = separate(ys, RATE, sensors=[f"s{i}" for i in range(s)], axes=AXES[1:], fit=False)
    short = full.axes[0].m <= 8
    np.testing.assert_allclose(live[0].self_noise[0].var[short[:len(live[0].m)]],
                               full.axes[0].self_noise[0].var[short], rtol=1e-12)


def test_a_loss_in_either_sensor_ends_the_pairs_segment() -> None:
    a, b = _rig(4, 20_000, 2)
    ia = np.arange(20_000)
    ib = np.arange(20_000) + 1000          # b's own index runs on another origin
    ia[5000:5100] = -1                     # a lost 100 samples
    ib[12_000] = -1                        # b lost one
    ib[15_000:] += 3                       # b's alignment slipped by 3 samples
    acc = CrossAllan(RATE)
    for i in range(0, 20_000, 333):
        acc.feed(ia[i:i + 333], ib[i:i + 333], a[i:i + 333], b[i:i + 333])
    ok = (ia >= 0) & (ib >= 0)
    assert acc.n_samples == int(ok.sum())
    assert acc.n_segments == 4
    # the batch estimator on the kept rows, split at the same places (no difference across)
    kept = np.flatnonzero(ok)
    gaps = [int(np.searchsorted(kept, g)) for g in (5100, 12_001, 15_000)]
    cols = np.column_stack([np.column_stack([a[kept, c], b[kept, c], a[kept, c] - b[kept, c]])
                            for c in range(3)])
    res = allan_variance(cols, RATE, kind="pavar", gaps=gaps)
    want = PairMoments.from_result(res, 6, 7, 8, len(kept))
    got = acc.moments()[2]
    k = len(got.m)
    np.testing.assert_array_equal(got.n, want.n[:k])
    for f in ("var_a", "var_b", "cov", "var_d", "edf_d"):
        np.testing.assert_allclose(getattr(got, f), getattr(want, f)[:k], rtol=1e-12)


def test_checkpoint_and_merge_continue_exactly() -> None:
    a, b = _rig(5, 30_000, 2)
    whole = CrossAllan(RATE)
    whole.update(a[:10_000], b[:10_000])
    restored = CrossAllan.from_state(msgpack.unpackb(msgpack.packb(whole.state())))
    for acc in (whole, restored):
        acc.update(a[10_000:], b[10_000:])
    for x, y in zip(whole.moments(), restored.moments(), strict=True):
        np.testing.assert_array_equal(x.var_d, y.var_d)
        np.testing.assert_array_equal(x.cov, y.cov)
    # two segments in two accumulators, merged = one accumulator with a gap between them
    one = CrossAllan(RATE)
    one.update(a[:12_000], b[:12_000])
    one.gap()
    one.update(a[12_000:], b[12_000:])
    left, right = CrossAllan(RATE), CrossAllan(RATE)
    left.update(a[:12_000], b[:12_000])
    right.update(a[12_000:], b[12_000:])
    left.merge(right)
    for x, y in zip(one.moments(), left.moments(), strict=True):
        np.testing.assert_allclose(x.var_d, y.var_d, rtol=1e-12)
        np.testing.assert_allclose(x.cov, y.cov, rtol=1e-12)


def test_state_size_per_pair_is_kilobytes_and_grows_by_octave_only() -> None:
    """The figure the issue asks for: the bytes of one pair's state (3 axes) as msgpack."""
    rng = np.random.default_rng(6)
    sizes = {}
    acc = CrossAllan(RATE)
    fed = 0
    for n in (1 << 14, 1 << 16, 1 << 18):
        acc.update(rng.normal(size=(n - fed, 3)), rng.normal(size=(n - fed, 3)))
        fed = n
        sizes[n] = len(msgpack.packb(acc.state()))
    print(f"CrossAllan state per pair (3 axes): {sizes} bytes")
    # 2^18 samples is 35 min at 125 Hz; a weekend (2^24.4) adds 6.4 octaves more
    per_octave = (sizes[1 << 18] - sizes[1 << 14]) / 4
    weekend = sizes[1 << 18] + 6.4 * per_octave
    assert per_octave < 8_000
    assert weekend < 200_000, f"a weekend's pair state would be {weekend:.0f} bytes"


def test_refusals() -> None:
    acc = CrossAllan(RATE)
    with pytest.raises(DataError, match="aligned"):
        acc.update(np.zeros((4, 3)), np.zeros((5, 3)))
    with pytest.raises(DataError, match="too few"):
        acc.moments()
    with pytest.raises(DataError, match="one index per row"):
        acc.feed([0, 1], [0], np.zeros((2, 3)), np.zeros((2, 3)))
    with pytest.raises(DataError, match="distinct"):
        CrossAllan(RATE, sensors=("a", "a"))
    with pytest.raises(FormatError):
        CrossAllan.from_state({"kind": "cross_allan", "v": 1, "axes": ["x"]})
    with pytest.raises(DataError, match="every pair"):
        separate_moments({}, 2, "z")


@pytest.mark.parametrize("s", [2, 3])
def test_streaming_equals_offline_where_estimates_fall_far_below_zero(s: int) -> None:
    """A bed 30× the sensors' own noise: negative self-noise estimates, whose upper ends are
    held at the zero estimate's (the sensitivity floor of covariance_interval), are the same
    live and offline: one estimator for both paths."""
    ys = [y[:, 1:] for y in _rig(s + 4, 20_000, s, common=3e-3)]
    offline = separate(ys, RATE, sensors=[f"s{i}" for i in range(s)], axes=AXES[1:],
                       fit=False, overlap=8)
    accs = _streamed(ys, [4096, 77])
    live = _live(accs, s)
    assert any(np.any(p.var < 0) for ax in live for p in ax.self_noise) or s == 3
    # the moments' own rounding: sums of a bed 30× larger, in another order (cascade, batch)
    _assert_same(live, list(offline.axes), ys, accs, rel=1e-11)

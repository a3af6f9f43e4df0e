"""``coarse._turn_tops`` on a stable coarse log sitting at a threshold (its readings flicker
between two levels, a turn at almost every run): the work grows with the turns, not their
square, and the tops are those of the per-turn reading (a naive reference)."""

from __future__ import annotations

import builtins
import math

import numpy as np
from avard.core.explain.thermal_fit import coarse


def _naive_tops(v, R, q, real=None):
    """The per-turn reading as first written (each turn's neighbours looked up in the list
    of turns): the reference the built-once lookup must reproduce."""
    lev = np.round(v / q)
    out = np.array(R, dtype=float)
    ch = np.flatnonzero(np.diff(lev) != 0)
    if len(ch) < 3:
        return out
    starts = np.concatenate([[0], ch + 1])
    ends = np.concatenate([ch, [len(v) - 1]])
    lv = lev[starts]
    k = np.arange(1, len(lv) - 1)
    turn = k[(lv[k] - lv[k - 1]) * (lv[k] - lv[k + 1]) > 0]
    if len(turn) < 2:
        return out
    turns = turn.tolist()
    mid = 0.5 * (starts[turn] + ends[turn])
    for i, r in enumerate(turns):
        a, b = int(starts[r]), int(ends[r])
        if real is not None and not np.all(real[int(starts[r - 1]):int(ends[r + 1]) + 1]):
            continue
        if i >= 1 and i + 1 < len(turn):
            period = mid[i + 1] - mid[i - 1]
        else:
            period = 2.0 * (mid[i + 1] - mid[i] if i == 0 else mid[i] - mid[i - 1])
        if not period > 0:
            continue
        alpha = min(math.pi * (b - a + 1) / period, 0.499 * math.pi)
        side = np.sign(lv[r] - lv[r - 1])
        theta = (lv[r] - 0.5 * side) * q
        bulge = side * (out[a:b + 1] - theta)
        a0, b1 = int(starts[r - 1]), int(ends[r + 1])
        outer = (r - 1 not in turns and r + 1 not in turns
                 and r - 1 > 0 and r + 1 < len(lv) - 1)
        alpha2 = math.pi * (b1 - a0 + 1) / period
        if outer and alpha < alpha2 < math.pi:
            h = q * (1.0 - math.cos(alpha)) / (math.cos(alpha) - math.cos(alpha2))
        else:
            h = 2.0 * (1.0 - math.cos(alpha)) / (alpha * math.sin(alpha)) * float(bulge.max())
        peak = float(bulge.max())
        f = h / peak if peak > 0 else 1.0
        top = theta + f * (out[a:b + 1] - theta)
        c = lv[r] * q
        out[a:b + 1] = np.clip(top, c - q / 2, c + q / 2)
    return out


def _cycle(n, q, seed, period=600.0, amp=0.7, noise=0.0):
    rng = np.random.default_rng(seed)
    t = np.arange(n)
    return np.round((22.1 + amp * q * np.sin(2 * math.pi * t / period)
                     + noise * rng.standard_normal(n)) / q) * q


def test_tops_match_the_per_turn_reading():
    from avard.core.explain.thermal_paths.columns import crossing_reconstruction
    q = 0.5
    for seed, noise in ((0, 0.0), (1, 0.04), (2, 0.15)):
        v = _cycle(3000, q, seed, amp=1.6, noise=noise)
        R = coarse._crossing_ends(v, crossing_reconstruction(v, q), q)
        real = np.ones(len(v), dtype=bool)
        real[1200:1500] = False
        for rl in (None, real):
            got = coarse._turn_tops(v, R, q, rl)
            assert np.array_equal(got, _naive_tops(v, R, q, rl))
        assert not np.array_equal(coarse._turn_tops(v, R, q), R)  # the tops did move


def test_flickering_log_work_grows_with_the_turns(monkeypatch):
    """Every element a set is built from is counted (the lookup that made it quadratic):
    the count may grow with the turns, not as their square."""
    counted = [0]

    def counting_set(*a):
        s = builtins.set(*a)
        counted[0] += len(s)
        return s

    monkeypatch.setattr(coarse, "set", counting_set, raising=False)
    q = 0.5
    rng = np.random.default_rng(0)
    n = 20000
    T = np.round((22.25 + 0.02 * rng.standard_normal(n)) / q) * q  # at the 22.0/22.5 threshold
    runs = 1 + int(np.count_nonzero(np.diff(T)))
    assert runs > n // 4  # the flicker: thousands of turns
    d = coarse.derounded(T, (q, 0.0))
    assert np.all(np.abs(d - T) <= q / 2 + 1e-12)  # within each reading's cell
    assert counted[0] <= 4 * n


def test_a_bridged_gap_is_read_as_the_gap_it_was():
    """The slow view bridges a log's hole (``SlowView.finish``), so ``derounded`` sees no NaN:
    given the hole as ``real`` (``coarse_regressor``'s ``holes``), the reconstruction is the
    one of the NaN gap, whose turns next to it are the spline's (review28a's gap.py)."""
    rate = 10 / 16
    t = np.arange(int(4 * 3600 * rate)) / rate
    q = 0.25
    R = np.round((22 + 0.5 * np.sin(2 * math.pi * t / 1800)) / q) * q
    idx = np.arange(len(R))
    for a, b in ((4000, 4700), (3900, 5600), (4100, 4200), (4400, 5100)):
        X = R.copy()
        X[a:b] = np.nan
        ok = np.isfinite(X)
        bridged = np.interp(idx, idx[ok], X[ok])
        want = coarse.derounded(X, (q, 0.0))
        got = coarse.derounded(bridged, (q, 0.0), real=ok)
        assert np.allclose(got[ok], want[ok], rtol=0, atol=1e-12)
        col = coarse.coarse_regressor(bridged[:, None], [(q, 0.0)], {0: [(a, b - 1)]})
        assert np.allclose(col[ok, 0], want[ok], rtol=0, atol=1e-12)
        # without the hole the bridge's turns are read as the room's
        assert not np.allclose(coarse.derounded(bridged, (q, 0.0))[ok], want[ok], atol=1e-9)

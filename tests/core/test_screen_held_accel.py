"""The input screen's held-acceleration rule (core/io/screen.py, ``HeldAccel``): an
accelerometer that repeats its last sample (a stuck FIFO, a driver repeating the last frame)
for minutes was read by explain as a cause (excursions, bias steps) while the screen said
"nothing masked". A run of identical samples that the axis's own chance of a repeat makes
implausible is cut as a gap and listed, by analyze and explain alike; a quiet axis on a coarse
grid, whose values repeat legitimately, is not touched."""

from __future__ import annotations

import json

import numpy as np
import pytest
from avard.core.analysis.engine import analyze
from avard.core.analysis.options import AnalyzeOptions
from avard.core.explain.engine import explain_file
from avard.core.explain.options import ExplainOptions
from avard.core.io.screen import ScreenLog, screen_blocks
from avard.core.io.screen.held_accel import HELD_MIN_RUN, HeldAccel, held_suspect, held_threshold
from avard.core.io.screen.stream import ScreenedSource
from avard.core.io.source import open_record

LSB = 3.9e-6 * 9.80665  # an ADXL355's step (m/s²)
EVENTS_AND_LINES = ("sinusoid", "periodic")


def _gridded(n: int, sigma_lsb: float, seed: int, axes: int = 3) -> np.ndarray:
    """White noise of ``sigma_lsb`` LSB on the LSB grid, around a 1 g axis."""
    rng = np.random.default_rng(seed)
    a = np.round(sigma_lsb * rng.standard_normal((n, axes))) * LSB
    a[:, -1] += 9.80665
    return a


def _hold(a: np.ndarray, at: int, length: int) -> np.ndarray:
    """The last sample before ``at`` repeated for ``length`` rows (every axis: a repeated
    frame)."""
    a = a.copy()
    for r in (at - 2, at + length):  # neighbours that differ from it on every axis
        same = a[r] == a[at - 1]
        a[r, same] += LSB
    a[at:at + length] = a[at - 1]
    return a


def _screen(a: np.ndarray, block: int, rate: float = 125.0) -> tuple[ScreenLog, list]:
    blocks = [(a[i:i + block], None, i + block >= len(a)) for i in range(0, len(a), block)]
    log = ScreenLog(rate)
    out = list(screen_blocks(iter(blocks), rate, ["x", "y", "z"], [], log))
    return log, out


def test_a_three_minute_hold_is_cut_listed_and_claims_nothing(tmp_path):
    """The adversary's class on a generator of our own: 4 h at 10 Hz of white noise on an
    LSB grid, every axis held at its last sample for 3 minutes. On the code before the rule,
    explain claimed excursions on the held axes."""
    rate, n = 10.0, int(4 * 3600 * 10.0)
    a = _gridded(n, 6.0, 11)
    # a held value well off the mean on every axis (what makes the stretch a cause)
    rng = np.random.default_rng(3)
    at = int(rng.uniform(0.3, 0.7) * n)
    a[at - 1, :] += np.array([1.0, -1.0, 1.0]) * 10 * LSB
    a = _hold(a, at, int(180 * rate))
    path = tmp_path / "held.npz"
    np.savez(path, accel=a, rate_hz=rate)
    ex = explain_file(open_record(path), ExplainOptions())
    claimed = {ch: [f.cause for f in c.claimed if f.cause not in EVENTS_AND_LINES]
               for ch, c in ex.channels.items()}
    assert not any(claimed.values()), claimed
    d = ex.to_dict()["screened"]
    assert d["counts"] == {"held_accel": 1}
    (s,) = d["stretches"]
    assert s["first_sample"] == at - 1 and s["last_sample"] == at + int(180 * rate) - 1
    assert s["axes"] == ["x", "y", "z"]
    assert abs(s["start_s"] - (at - 1) / rate) < 1e-9
    assert abs(s["end_s"] - s["start_s"] - 180.1) < 1e-6
    assert d["samples_masked"] == int(180 * rate) + 1
    text = "\n".join(ex.screen.lines()) if ex.screen is not None else ""
    assert "1 held acceleration (identical samples)" in text
    assert "accel (x, y, z): held acceleration (identical samples) at" in text
    # analyze says the same, in its text and JSON
    an = analyze(open_record(path), AnalyzeOptions(channels=("x",)))
    da = an.to_dict()["screened"]
    assert da["counts"] == {"held_accel": 1} and da["stretches"] == d["stretches"]
    json.dumps(da)
    from avard.core.analysis.formats import format_table

    assert "held acceleration (identical samples) at" in format_table(an)


@pytest.mark.parametrize("block", [4096, 1 << 16])
def test_quiet_quantised_axes_with_natural_repeats_are_not_masked(block):
    """An axis whose noise is a fraction of its LSB repeats its value most of the time, and a
    chip filter's correlated samples repeat in clusters: its own runs say so, nothing is cut.
    An axis that turns quiet midway (a pump stops) is judged by its new noise."""
    from scipy.signal import lfilter

    n = 1 << 20
    for seed, sigma in enumerate((0.2, 0.35, 0.6, 1.2)):
        log, out = _screen(_gridded(n, sigma, 100 + seed), block)
        assert not log.stretches, (sigma, log.stretches[:3])
        assert sum(len(b[0]) for b in out) == n
    rng = np.random.default_rng(7)
    w = lfilter([0.05], [1, -0.95], rng.standard_normal((n, 3)), axis=0)
    log, _ = _screen(np.round(w / np.sqrt(0.05 / 1.95) * 0.7) * LSB, block)
    assert not log.stretches
    busy_then_quiet = np.concatenate([_gridded(n // 2, 3.0, 8), _gridded(n // 2, 0.15, 9)])
    log, _ = _screen(busy_then_quiet, block)
    assert not log.stretches


@pytest.mark.parametrize(("block", "at", "length"), [
    (4096, 4000, 300),      # across one boundary
    (1000, 2500, 5000),     # across several blocks
    (1 << 16, 65500, 40),   # a short one, 36 rows on one side
])
def test_a_held_stretch_across_block_boundaries_is_one_gap(block, at, length):
    n = 200_000
    a = _hold(_gridded(n, 4.0, 5), at, length)
    log, out = _screen(a, block)
    assert [(s.kind, s.first, s.last, s.axes) for s in log.stretches] == [
        ("held_accel", at - 1, at + length - 1, ("x", "y", "z"))]
    assert log.stretches[0].count == length + 1
    assert sum(len(b[0]) for b in out) == n - length - 1
    # a segment ends before the stretch: no Allan difference straddles it
    rows = np.cumsum([len(b[0]) for b in out])
    ends = [int(r) for r, b in zip(rows, out, strict=True) if b[2]]
    assert at - 1 in ends and ends[-1] == n - length - 1


def test_one_stuck_axis_is_cut_and_named():
    """A stuck channel of one axis (the others live) is held too: its rows are cut on every
    axis, as a shock's are, and the stretch names the axis."""
    a = _gridded(300_000, 4.0, 6)
    a[100_000:100_500, 1] = a[99_999, 1]
    log, _ = _screen(a, 1 << 16)
    assert [(s.kind, s.first, s.last, s.axes) for s in log.stretches] == [
        ("held_accel", 99_999, 100_499, ("y",))]


def test_the_threshold_follows_the_axis_own_chance_of_a_repeat():
    """Float noise (no repeat): the floor; a coarse quiet axis: far longer; too few runs:
    not judged."""
    h = HeldAccel()
    rng = np.random.default_rng(1)
    h.feed(0, np.column_stack([rng.standard_normal(1 << 16),
                               np.round(0.3 * rng.standard_normal(1 << 16)),
                               np.zeros(1 << 16)]))
    assert h.hist is not None
    k = [held_threshold(h.hist[j], h.rows) for j in range(3)]
    assert k[0] == HELD_MIN_RUN and 100 < k[1] < 5000 and k[2] == np.inf


def test_a_second_read_and_the_parallel_chunks_keep_the_held_stretch(tmp_path):
    """A later read takes the first read's verdicts (fewer columns, no judging) and says the
    same kind; a parallel chunk that sees a run that may be held hands no verdicts on, so the
    one-worker read judges the whole record."""
    from avard.core.analysis.parallel import ChunkResult, _screen, _screen_cut

    a = _hold(_gridded(150_000, 4.0, 12), 70_000, 2_000)
    path = tmp_path / "h.npz"
    np.savez(path, accel=a, rate_hz=125.0)
    src = ScreenedSource(open_record(path))
    first = list(src.blocks(4096, columns=[0, 1, 2], temperature=False))
    again = list(src.blocks(4096, columns=[2], temperature=False))
    assert [len(b[0]) for b in again] == [len(b[0]) for b in first]
    assert src.log is not None and src.log.counts() == {"held_accel": 1}
    log2 = ScreenLog(125.0)
    list(screen_blocks(iter([(a[i:i + 4096], None, i + 4096 >= len(a))
                             for i in range(0, len(a), 4096)]), 125.0, ["x", "y", "z"], [],
                       log2))
    assert [(s.kind, s.first, s.last) for s in log2.stretches] == [
        ("held_accel", 69_999, 71_999)]
    # the chunks: each block judged on its own
    blk = a[69_632:69_632 + 4096]
    assert held_suspect(blk) and not held_suspect(_gridded(4096, 4.0, 13))
    cut = _screen_cut({(0, 0): ChunkResult(None, None, {69_632: _screen(blk)})}, 4096)
    assert cut.verdicts is None


def test_the_state_stays_bounded_over_a_long_quiet_record():
    """Bounded memory: the blocks' own run counts and the candidates kept are those of rows
    still to judge, however long the record."""
    h = HeldAccel()
    rng = np.random.default_rng(2)
    kept = []
    for i in range(300):
        blk = np.round(0.3 * rng.standard_normal((4096, 3)))
        h.feed(i * 4096, blk)
        if i:
            h.verdict((i - 1) * 4096, 4096)
        assert len(h.blocks) <= 3
        kept.append(sum(len(c) for c in h.cand))
    # the candidates of the two blocks in flight, at most one per HELD_MIN_RUN rows each
    assert max(kept) <= 3 * 2 * 4096 // HELD_MIN_RUN and max(kept[200:]) <= 2 * max(kept[:20])

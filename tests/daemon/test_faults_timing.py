"""Timing faults: a stalled reader (FIFO overrun) and steps of CLOCK_REALTIME (NTP).

An overrun loses an unknown number of sets: the service records one gap whose bounds are the
exact jump of the sample index, estimated from the elapsed time, so index and time stay
aligned (the time base is re-anchored after it). A step of the wall clock changes nothing in
the sample timing (CLOCK_MONOTONIC) and is recorded as a ``clock_step`` event.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from .test_faults_bus import (
    RATE,
    assert_allan_stream_equals_recording,
    assert_index_jumps_match_gaps,
    assert_subscriber_saw_everything,
    run_rig,
)


@pytest.mark.parametrize("stall_s", [0.6, 3.0])
def test_overrun_becomes_a_gap_with_bounds_and_the_time_base_is_reanchored(tmp_path, stall_s):
    def inject(ctx: dict, t: float) -> None:
        if t > 15 and ctx["once"]("stall"):
            ctx["clock"].advance(stall_s)  # the reader did not run for stall_s: FIFO overruns

    rig = run_rig(tmp_path, 35.0, inject=inject)
    recs = rig.records()
    gaps = [g for g in assert_index_jumps_match_gaps(recs) if g["n"]]
    assert len(gaps) == 1
    gap = gaps[0]
    assert "overrun" in gap["reason"]
    # The FIFO held 32 sets (0.256 s at 125 Hz); the rest of the stall and of the poll period
    # before it (the drain after the stall comes one period after the previous one) is lost.
    lost_s = stall_s + rig.svc.acq.period - 32 / RATE
    assert abs(gap["n"] - lost_s * RATE) <= 0.1 * RATE + 2, gap["n"]
    raw = [r for r in recs if r["kind"] == "raw"]
    # Index and CLOCK_MONOTONIC stay aligned across the gap: the time between the blocks
    # around it equals their index distance / rate (the gap is the right size) ...
    before = max((r for r in raw if r["i0"] < gap["i0"]), key=lambda r: r["i0"])
    after = min((r for r in raw if r["i0"] > gap["i0"]), key=lambda r: r["i0"])
    dt = after["t_mono"] - before["t_mono"]
    assert abs(dt - (after["i0"] - before["i0"]) / RATE) < 3.0 / RATE
    # ... and after it the stamps follow the index at the chip's real rate (re-anchored fit).
    # The emulated chip runs off its nominal 125 Hz by the preset's ppm error, as real parts
    # do, so the reference is its true rate: over 20 s a few hundred ppm is more than 2 periods.
    true_rate = rig.ctx["emu"].true_odr_hz
    late = [r for r in raw if r["i0"] >= gap["i0"] + gap["n"]]
    i = np.array([r["i0"] for r in late], dtype=float)
    t = np.array([r["t_mono"] for r in late])
    # The first block after the gap is stamped before the fit has re-anchored: it carries the
    # gap estimate's error (a few periods, bounded above); from the next block on the stamps
    # follow the index.
    resid = t[1:] - t[1] - (i[1:] - i[1]) / true_rate
    assert np.max(np.abs(resid)) < 2.0 / RATE
    assert abs(t[1] - t[0] - (i[1] - i[0]) / true_rate) < 3.0 / RATE
    assert rig.svc.final_status["overruns"] == 1
    assert_subscriber_saw_everything(rig)
    assert rig.listener.sub.stats.samples_service_gap == gap["n"]
    assert_allan_stream_equals_recording(rig)


def test_realtime_steps_are_events_and_sample_timing_stays_monotonic(tmp_path):
    steps = [-3600.0, 7.5, -0.2]

    def inject(ctx: dict, t: float) -> None:
        for k, step in enumerate(steps):
            if t > 8 + 7 * k and ctx["once"](f"step{k}"):
                ctx["clock"].step_realtime(step)

    rig = run_rig(tmp_path, 35.0, inject=inject)
    recs = rig.records()
    events = [r for r in recs if r["kind"] == "event" and r["name"] == "clock_step"]
    assert [pytest.approx(e["detail"]["step_s"], abs=1e-6) for e in events] == steps
    # No sample lost, none reordered: the index is continuous and CLOCK_MONOTONIC increases.
    assert assert_index_jumps_match_gaps(recs) == []
    raw = [r for r in recs if r["kind"] == "raw"]
    assert all(b["t_mono"] > a["t_mono"] for a, b in itertools.pairwise(raw))
    assert all(b["i0"] == a["i0"] + a["n"] for a, b in itertools.pairwise(raw))
    # Each event sits at the sample index where the step was seen, in order.
    idx = [e["i0"] for e in events]
    assert idx == sorted(idx) and raw[0]["i0"] < idx[0] < raw[-1]["i0"]
    assert rig.svc.final_status["clock_steps"] == len(steps)
    # Wall-clock times written beside the samples follow the stepped clock from each step on.
    for a, b in itertools.pairwise([*events, None]):
        offset = a["detail"]["t_real_after"] - a["t_mono"]
        between = [r for r in raw if r["i0"] >= a["i0"] and (b is None or r["i0"] < b["i0"])]
        assert between and all(abs(r["t_real"] - r["t_mono"] - offset) < 1e-3 for r in between)
    # Subscribers see the same events.
    published = [r for t, r in rig.listener.records if t == "event" and r["name"] == "clock_step"]
    assert len(published) == len(steps)
    assert_subscriber_saw_everything(rig)

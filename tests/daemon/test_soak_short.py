"""The soak of benchmarks/bench_soak.py, 75 simulated minutes, in CI.

The whole service at 125 Hz over the emulator with a remote ``avard record`` subscriber (a
separate process over loopback TCP) and a fault every 12 simulated minutes, so each of the
six kinds goes in once (the suite's time is bounded; the 60-hour run takes every kind many
times): every sample
published is received, every sample acquired is recorded, every lossy fault left a gap
record, RSS stays flat after warm-up, and the Allan result of the stream, the recording and
the subscriber's copy are equal. The 60-hour run is ``python -m benchmarks soak``.
"""

from __future__ import annotations

from benchmarks.bench_soak import MAX_RSS_GROWTH, format_result, run_soak

HOURS = 1.25


def test_seventy_five_simulated_minutes_with_every_fault(tmp_path, capsys):
    res = run_soak(HOURS, tmp_path, fault_every_h=0.2, seed=3)
    with capsys.disabled():
        print("\n" + format_result(res))
    # A fault of every kind went in, and the run covered its length.
    assert res.sim_s >= HOURS * 3600
    assert set(res.faults) == {"eio", "eio_burst", "unplug", "stall", "ds18b20", "clock_step"}
    assert res.produced >= HOURS * 3600 * 125 * 0.99
    # Every promise of the soak, named.
    failed = [name for name, ok in res.checks.items() if not ok]
    assert failed == [], format_result(res)
    # The numbers behind the main ones, so a failure says how far off it was.
    assert res.received == res.published == res.recorded
    # Produced = recorded + lost in gaps, up to the overrun estimates (±1 sample per fault)
    # and the FIFO still full at stop.
    n_faults = sum(res.faults.values())
    assert abs(res.produced - res.recorded - res.gap_samples_recorded) <= 2 * n_faults + 64
    assert max(rss for _, rss in res.rss_trace if _ >= 720) - res.rss_warm < MAX_RSS_GROWTH
    assert res.allan_rel_diff["recording"] < 1e-9 and res.allan_rel_diff["subscriber"] < 1e-9

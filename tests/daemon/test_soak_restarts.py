"""The soak's restart classes (benchmarks/soak_restarts.py), one round, in CI: early stops,
a silent sensor stopped by SIGTERM, restarts in quick succession, the checkpoint file damaged,
emptied and deleted, and CLOCK_REALTIME stepped two days forward with retention set. After
every run the accumulators equal the offline Allan variance of the recording (#26 items 1-4)."""

from __future__ import annotations

import pytest

from benchmarks.soak_restarts import format_campaign, run_restart_campaign


@pytest.mark.slow
def test_one_round_of_the_restart_classes(tmp_path, capsys):
    res = run_restart_campaign(tmp_path, seed=2, cycles=1)
    with capsys.disabled():
        print("\n" + format_campaign(res))
    assert set(res.faults) == {"early_stop", "silent_sensor_stop", "quick_restart",
                               "checkpoint_damaged", "checkpoint_emptied",
                               "checkpoint_deleted", "clock_step_retention"}
    failed = [name for name, ok in res.checks.items() if not ok]
    assert failed == [], format_campaign(res)
    assert res.segments_deleted == 0
    assert 0 < res.accumulators <= res.recorded

"""Retention measures age in the recording's own time, never by file mtimes against
CLOCK_REALTIME (#26 item 4).

A Pi without an RTC starts on a stale clock and NTP steps it forward: with ``retention_days``
set, the old recorder compared segment mtimes with the stepped clock and deleted every segment
written before the step. Age is now the distance in sample indices (over the output rate) from
the newest sample written, so a clock step, in either direction, deletes nothing it should not.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
from avard.core.io import frames
from avard.daemon.service.recorder import Recorder

RATE = 125.0
DAY = 86400.0


def _writer(d: Path, run: str, t_real: list[float], **kw) -> Recorder:
    now = [0.0]

    def header() -> dict:
        return frames.header_record(run, rate_hz=RATE, t_mono=now[0], t_real=t_real[0],
                                    scale_m_s2_per_count=1e-5)

    rec = Recorder(d, run, header, segment_s=10.0, clock=lambda: now[0],
                   realtime=lambda: t_real[0], **kw)
    rec.now = now          # type: ignore[attr-defined]
    return rec


def _raw(run: str, i0: int, t_real: float, n: int = 125) -> dict:
    return frames.raw_record(run, 0, i0, np.zeros((n, 3), np.int32), i0 / RATE, t_real,
                             rate_hz=RATE)


def test_a_forward_wall_clock_step_deletes_no_segment(tmp_path):
    real = [time.time()]                    # CLOCK_REALTIME as the files' mtimes see it
    rec = _writer(tmp_path, "n00000001-a", real, retention_days=1.0)
    i = 0
    for k in range(60):                     # 60 s of samples, a segment every 10 s
        if k == 30:
            real[0] += 2 * DAY              # NTP corrects a stale clock by two days
        rec.now[0] = float(k)               # type: ignore[attr-defined]
        assert rec.write(_raw("n00000001-a", i, real[0]))
        i += 125
        real[0] += 1.0
    rec.close()
    assert rec.deleted == []
    assert len(list(tmp_path.glob("*.avr"))) == 6


def test_old_mtimes_do_not_make_recent_data_old(tmp_path):
    """Files copied back from a backup (mtimes years old) are as old as their samples."""
    real = [1.7e9]
    first = _writer(tmp_path, "n00000001-a", real)
    first.write(_raw("n00000001-a", 0, real[0]))
    first.close()
    assert first.path is not None
    os.utime(first.path, (1.0, 1.0))
    rec = _writer(tmp_path, "n00000002-b", real, retention_days=1.0)
    rec.write(_raw("n00000002-b", 3600 * 125, real[0] + 3600))   # an hour of samples later
    rec.close()
    assert first.path.exists() and rec.deleted == []


def test_segments_older_than_retention_in_sample_time_are_deleted(tmp_path):
    real = [1.7e9]
    rec = _writer(tmp_path, "n00000001-a", real, retention_days=1.0)
    written = []
    for k, i0 in enumerate([0, int(0.5 * DAY * RATE), int(1.4 * DAY * RATE),
                            int(2.3 * DAY * RATE)]):
        rec.now[0] = 10.0 * k               # type: ignore[attr-defined]
        real[0] -= 5 * DAY                  # the wall clock runs backwards: irrelevant
        rec.write(_raw("n00000001-a", i0, real[0]))
        written.append(rec.path)
    rec.now[0] += 10.0                      # type: ignore[attr-defined]
    rec.write(_raw("n00000001-a", int(2.3 * DAY * RATE) + 125, real[0]))  # rotates: retention
    rec.close()
    # the newest sample is at 2.3 days; a segment is deleted when everything in it is more
    # than a day older: the first two (2.3 and 1.8 days old; the third is 0.9 days old)
    assert [p.name for p in written[:2]] == rec.deleted
    assert all(p.exists() for p in written[2:])

"""Order that does not depend on the wall clock (#16 item 3): run ids and file names sort in
data order when CLOCK_REALTIME is wrong at a start, the sample index continues from the
recording, and the restart gap is measured on CLOCK_MONOTONIC within a boot."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from avard.core.io import frames
from avard.core.io.recording import RecordingReader, load_recording, segment_files
from avard.daemon.compose import compose
from avard.daemon.config import load_config
from avard.daemon.config_types import as_config
from avard.daemon.hw.simulation import build_simulated
from avard.daemon.service.recorder import (
    LastRecorded,
    Recorder,
    last_recorded,
    new_run_id,
    restart_gap,
)
from avard.daemon.service.supervisor import Service

from tests.support.rigs import rig_from_parts


def _run_service(data: Path, seconds: float, *, clock_back_s: float = 0.0) -> Service:
    cfg = load_config(None, **{"recording.data_dir": str(data), "publish.enabled": False,
                               "sensor.poll_hz": 1.0, "recording.segment_s": 3600.0})
    dev, clock, sims, _emu = build_simulated(cfg, "quiet-lab", seed=3)
    clock.step_realtime(-clock_back_s)          # a Pi without RTC, before NTP
    svc = compose(as_config(cfg), rig_from_parts(as_config(cfg), dev, clock,
                                                 simulate="quiet-lab", sims=sims))
    svc.run(seconds)
    return svc


def test_a_run_started_with_the_clock_an_hour_behind_sorts_after_the_run_it_followed(tmp_path):
    data = tmp_path / "rec"
    first = _run_service(data, 20.0)
    second = _run_service(data, 20.0, clock_back_s=3600.0)
    assert first.run_id.startswith("n00000001-") and second.run_id.startswith("n00000002-")
    assert sorted([second.run_id, first.run_id]) == [first.run_id, second.run_id]
    # the UTC stamp in the second id is an hour earlier, the order is still data order
    assert second.run_id.split("-")[1] < first.run_id.split("-")[1]
    names = [f.name for f in segment_files(data)]
    assert names[0].startswith(first.run_id) and names[-1].startswith(second.run_id)
    recs = list(RecordingReader(data))
    idx = np.concatenate([r["i0"] + np.arange(r["n"]) for r in recs if r["kind"] == "raw"])
    assert np.all(np.diff(idx) > 0)                       # data order, no sample twice
    (gap,) = [r for r in recs if r["kind"] == "gap" and r["reason"] == "restart"]
    # another "boot" (each simulated process has its own monotonic clock) and a wall clock
    # behind the recording: the gap's length is unknown and says so; the index continues
    assert gap["clock"] == "unknown" and gap["n"] == 0
    assert gap["i0"] == max(r["i0"] + r["n"] for r in recs
                            if r["kind"] == "raw" and r["run"] == first.run_id)
    rec = load_recording(data)
    assert rec.meta["samples_duplicated"] == 0 and rec.meta["segment_bounds"][1] > 0


def test_run_ids_carry_a_sequence_from_the_recording(tmp_path):
    a = new_run_id(tmp_path, 2.0e9)
    assert a.startswith("n00000001-")
    (tmp_path / f"{a}_0000_x.avr").write_bytes(b"")
    b = new_run_id(tmp_path, 1.0e9)                       # the wall clock went back 30 years
    assert b.startswith("n00000002-") and a < b
    (tmp_path / "20260101T000000Z-abcdef_0000_x.avr").write_bytes(b"")   # an old-style name
    assert sorted([b, "20260101T000000Z-abcdef"])[-1] == b


def _segment(d: Path, run: str, boot: str | None, i0: int, n: int, t_mono: float,
             t_real: float) -> None:
    def header() -> dict[str, Any]:
        return frames.header_record(run, rate_hz=125.0, t_mono=t_mono, t_real=t_real, i0=i0,
                                    scale_m_s2_per_count=3.9e-5, boot_id=boot)

    rec = Recorder(d, run, header)
    rec.write(frames.raw_record(run, 0, i0, np.zeros((n, 3), np.int32), t_mono, t_real,
                                rate_hz=125.0))
    rec.close()


def test_the_restart_gap_is_measured_on_the_monotonic_clock_within_a_boot(tmp_path):
    _segment(tmp_path, "n00000001-x", "boot-a", 1000, 125, 500.0, 1.7e9)
    last = last_recorded(tmp_path, 125.0)
    assert last == LastRecorded(1125, 501.0, 1.7e9 + 1.0, "boot-a")
    # same boot, 7 s later on CLOCK_MONOTONIC, CLOCK_REALTIME an hour behind: exact
    g = restart_gap(last, boot_id="boot-a", t_mono=508.0, t_real=1.7e9 - 3600, rate_hz=125.0)
    assert (g.i0, g.n, g.clock) == (1125, 875, "monotonic")
    # another boot: CLOCK_MONOTONIC means nothing across it; the wall clock is used
    g = restart_gap(last, boot_id="boot-b", t_mono=3.0, t_real=1.7e9 + 11.0, rate_hz=125.0)
    assert (g.n, g.clock) == (1250, "realtime")
    # another boot and the wall clock behind the recording: unknown, 0 samples, said so
    g = restart_gap(last, boot_id="boot-b", t_mono=3.0, t_real=1.7e9 - 3600, rate_hz=125.0)
    assert (g.n, g.clock) == (0, "unknown")

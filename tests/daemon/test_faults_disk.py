"""A full disk under the running service (a recorder whose writes fail with ENOSPC).

Acquisition and publishing go on untouched; the recording pauses, says so in the status, and
when space returns it resumes with one ``disk_full`` gap record whose bounds are exactly the
samples the recording lacks. Nothing else is lost and every segment still reads back.
"""

from __future__ import annotations

import errno
from pathlib import Path
from typing import Any

import numpy as np
from avard.core.recording import RecordingReader
from avard.daemon.recorder import FileOps, Recorder

from .test_faults_bus import RATE, run_rig


class FullDisk(FileOps):
    """Real files; while ``full`` every write fails with ENOSPC after writing half its bytes
    (as a real full disk can), and free space reads 0."""

    def __init__(self) -> None:
        self.full = False
        self.refused = 0

    def write(self, f: Any, data: bytes) -> None:
        if self.full:
            self.refused += 1
            f.write(data[: len(data) // 2])
            f.flush()
            raise OSError(errno.ENOSPC, "No space left on device (injected)")
        super().write(f, data)

    def fsync(self, f: Any) -> None:
        if self.full:
            raise OSError(errno.ENOSPC, "No space left on device (injected)")
        super().fsync(f)

    def free_bytes(self, directory: Path) -> int:
        return 0 if self.full else 10**12


def test_disk_full_keeps_acquiring_and_publishing_records_the_loss_and_resumes(tmp_path):
    ops = FullDisk()
    seen: dict[str, Any] = {}

    def recorder_factory(svc: Any) -> Recorder:
        r = svc.cfg["recording"]
        # every clock of the recorder on the service's (virtual) time, so the retry after
        # retry_s happens on schedule however fast the simulation runs
        return Recorder(svc.data_dir, svc.run_id, svc.header, segment_s=r["segment_s"],
                        fsync_interval_s=r["fsync_interval_s"], retry_s=1.0,
                        clock=svc.clock.monotonic, wall=svc.clock.monotonic,
                        realtime=svc.clock.realtime, fileops=ops)

    def inject(ctx: dict, t: float) -> None:
        if t > 12 and ctx["once"]("full"):
            ops.full = True
        if t > 18 and ctx["once"]("status"):
            seen["status"] = ctx["svc"].status()
        if t > 22 and ctx["once"]("space"):
            ops.full = False

    rig = run_rig(tmp_path, 40.0, inject=inject, recorder_factory=recorder_factory)
    assert ops.refused > 0
    # While full, the status said so; the service kept acquiring.
    disk = seen["status"]["disk"]
    assert disk["state"] != "writing", disk
    # Publishing never noticed: the subscriber got every sample, contiguous, no gap at all.
    st = rig.listener.sub.stats
    assert st.messages_lost == 0 and st.samples_unexplained == 0
    assert st.samples_service_gap == 0
    sub_idx = np.concatenate([r["i0"] + np.arange(r["n"]) for r in rig.listener.raw()])
    np.testing.assert_array_equal(sub_idx, np.arange(sub_idx[0], sub_idx[0] + sub_idx.size))
    assert rig.svc.final_status["samples"] == sub_idx.size
    # The recording: every segment reads back without a corrupt frame (the half-written
    # frame of each failed write was cut off again) ...
    reader = RecordingReader(rig.data_dir)
    recs = list(reader)
    assert [p for p in reader.problems if p.kind != "truncated"] == []
    # ... lacks exactly the samples of its one disk_full gap ...
    gaps = [r for r in recs if r["kind"] == "gap"]
    assert [g["reason"] for g in gaps] == ["disk_full"]
    gap = gaps[0]
    rec_idx = np.concatenate([r["i0"] + np.arange(r["n"]) for r in recs if r["kind"] == "raw"])
    missing = np.setdiff1d(sub_idx, rec_idx)
    assert missing.size == gap["n"] > 0
    np.testing.assert_array_equal(missing, np.arange(gap["i0"], gap["i0"] + gap["n"]))
    # ... which is about the 10 s the disk was full: plus at most one retry interval, one raw
    # block, and however far the recorder thread worked behind the reader when the disk
    # filled (a simulation at full speed: a few virtual seconds, bounded by the ring) ...
    ring_s = rig.svc.cfg["service"]["ring_s"]
    assert 9.0 * RATE <= gap["n"] <= (10.0 + 1.0 + 1.0 + min(ring_s, 5.0)) * RATE
    # ... and it resumed: samples after the gap reach to the end of the run.
    assert rec_idx[-1] == sub_idx[-1]
    assert rig.svc.final_status["disk"]["samples_lost"] == gap["n"]

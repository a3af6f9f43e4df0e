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
from avard.core.io.recording import RecordingReader
from avard.daemon.service.recorder import FileOps, Recorder

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
    full_from, full_to = int(12 * RATE), int(22 * RATE)  # sample indices: 10 s of data

    retry_s = 1.0
    data_time = [0.0]  # seconds of data the recorder has been handed: its retry clock

    class DiskFillsAtIndex(Recorder):
        """The disk is full while the recorder writes samples [full_from, full_to): defined
        on the data, so however far the recorder thread works behind the reader, the window
        is the same 10 s of samples."""

        def write(self, record: dict[str, Any]) -> bool:
            if record.get("kind") == "raw":
                ops.full = full_from <= record["i0"] < full_to
                data_time[0] = record["i0"] / RATE
            return super().write(record)

    def recorder_factory(svc: Any) -> Recorder:
        r = svc.cfg["recording"]
        # The retry after retry_s (and the fsync interval) run on the time of the data the
        # recorder writes, so where the gap ends does not depend on how far the recorder
        # thread lags the reader on a loaded machine; segments rotate on the service clock.
        return DiskFillsAtIndex(svc.data_dir, svc.run_id, svc.header,
                                segment_s=r["segment_s"],
                                fsync_interval_s=r["fsync_interval_s"], retry_s=retry_s,
                                clock=svc.clock.monotonic, wall=lambda: data_time[0],
                                realtime=svc.clock.realtime, fileops=ops)

    def inject(ctx: dict, t: float) -> None:
        if ops.full and "status" not in seen:
            seen["status"] = ctx["svc"].status()

    rig = run_rig(tmp_path, 40.0, inject=inject, recorder_factory=recorder_factory,
                  speed=10.0)
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
    # ... which starts with the first block the recorder was handed inside the window and
    # ends with the first block at or after a retry whose samples lie past the window. The
    # recorder's blocks are the drains it took from the ring (several at once when it ran
    # behind), so the bounds are stated on its own blocks, from the rule, not on timing:
    raw = sorted((r for r in recs if r["kind"] == "raw"), key=lambda r: r["i0"])
    before = next(r for r in raw if r["i0"] + r["n"] == gap["i0"])
    after = next(r for r in raw if r["i0"] == gap["i0"] + gap["n"])
    longest = max(r["n"] for r in raw)
    # the last block written began before the window; every lost block began inside it or
    # after it, before the resume
    assert before["i0"] < full_from <= gap["i0"]
    # writing resumed with a block past the window, at the first retry after it: retries
    # come every retry_s of data time while full, so the window's end block (which begins
    # within one block of full_to) is followed by a retry within retry_s, whose block
    # begins within one block of it
    assert full_to <= after["i0"] < full_to + longest + retry_s * RATE + longest
    # ... and it resumed: samples after the gap reach to the end of the run.
    assert rec_idx[-1] == sub_idx[-1]
    assert rig.svc.final_status["disk"]["samples_lost"] == gap["n"]

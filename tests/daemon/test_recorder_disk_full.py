"""A full disk under the recorder alone: on a real (small, loop-mounted tmpfs) file system, and
with a file-system layer whose cut-off after ENOSPC fails too.

What must hold: no torn frame stays in the middle of a recording (the cut-off is an unbuffered
ftruncate), or, when even that fails, the torn frame is the tail of a segment that is never
appended to again, so the reader skips it and loses nothing else; the state file is written
whole or not at all, with no ``.tmp`` left behind; and the samples that did not reach the disk
are exactly the ``disk_full`` gap written on resume.
"""

from __future__ import annotations

import errno
import os
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

import numpy as np
import pytest
from avard.core.io import frames
from avard.core.io.recording import RecordingReader, load_recording
from avard.daemon.service.recorder import FileOps, Recorder, write_atomic

RATE = 125.0
BLOCK = 100


class Clock:
    """A hand-driven clock for the recorder's retry timer."""

    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def _header() -> dict[str, Any]:
    return frames.header_record("20260101T000000Z-1", rate_hz=RATE, t_mono=0.0, t_real=0.0,
                                scale_m_s2_per_count=3.9e-5)


def _raw(i0: int) -> dict[str, Any]:
    # noise, so the frames do not compress and each is the same size
    counts = np.random.default_rng(i0).integers(-2**19, 2**19, size=(BLOCK, 3), dtype=np.int32)
    return frames.raw_record("x", 0, i0, counts, i0 / RATE, i0 / RATE)


def _indices(path: Path) -> tuple[np.ndarray, list[dict[str, Any]], RecordingReader]:
    reader = RecordingReader(path)
    recs = list(reader)
    raw = [r["i0"] + np.arange(r["n"]) for r in recs if r["kind"] == "raw"]
    return np.concatenate(raw), [r for r in recs if r["kind"] == "gap"], reader


@pytest.fixture
def small_fs(tmp_path: Path) -> Iterator[Path]:
    """A 160 kB tmpfs mounted for this test (root only: CI runs as root)."""
    mnt = tmp_path / "fs"
    mnt.mkdir()
    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs needs root")
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=160k", "tmpfs", str(mnt)],
                          capture_output=True, text=True)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def test_a_real_full_disk_leaves_no_torn_frame_and_no_tmp_and_the_gap_is_exact(small_fs):
    filler = small_fs / "filler"
    filler.write_bytes(os.urandom(48 * 1024))   # freed later: "space comes back"
    data = small_fs / "rec"
    wall = Clock()
    rec = Recorder(data, "20260101T000000Z-1", _header, segment_s=1e9, retry_s=1.0,
                   clock=wall, wall=wall)
    state = data / "allan-state.ckpt"
    state.write_bytes(b"old")
    i0 = 0
    written: list[int] = []
    while not rec.disk_full:
        assert i0 < 10_000 * BLOCK, "the 160 kB file system never filled up"
        if rec.write(_raw(i0)):
            written.append(i0)
        i0 += BLOCK
    assert rec.status()["state"] == "disk_full"
    # While full: the checkpoint state file cannot be written; the old one stays, no .tmp.
    with pytest.raises(OSError) as err:
        write_atomic(state, os.urandom(200 * 1024))
    assert err.value.errno == errno.ENOSPC
    assert state.read_bytes() == b"old"
    assert list(data.glob("*.tmp")) == []
    # The segment that hit ENOSPC ends on a whole frame: the reader finds nothing to skip.
    idx, gaps, reader = _indices(data)
    assert reader.problems == []
    np.testing.assert_array_equal(idx, np.arange(len(written) * BLOCK))
    # More blocks arrive while full (lost), then space comes back and writing resumes.
    lost_from = i0 - BLOCK
    for _ in range(5):
        assert not rec.write(_raw(i0))
        i0 += BLOCK
    filler.unlink()
    wall.t += 2.0
    for _ in range(3):
        assert rec.write(_raw(i0))
        i0 += BLOCK
    rec.close()
    idx, gaps, reader = _indices(data)
    assert reader.problems == []
    assert [(g["reason"], g["i0"], g["n"]) for g in gaps] == [
        ("disk_full", lost_from, i0 - 3 * BLOCK - lost_from)]
    expect = np.concatenate([np.arange(lost_from), np.arange(i0 - 3 * BLOCK, i0)])
    np.testing.assert_array_equal(idx, expect)
    assert rec.status()["samples_lost"] == i0 - 3 * BLOCK - lost_from


class TornAndStuck(FileOps):
    """Writes half a frame then ENOSPC while ``full``; cutting it off fails as well."""

    truncate_pause_s = 0.0

    def __init__(self) -> None:
        self.full = False
        self.truncates = 0

    def write(self, f: IO[bytes], data: bytes) -> None:
        if self.full:
            super().write(f, data[: len(data) // 2])
            raise OSError(errno.ENOSPC, "No space left on device (injected)")
        super().write(f, data)

    def truncate(self, f: IO[bytes], size: int) -> None:
        self.truncates += 1
        raise OSError(errno.EIO, "Input/output error (injected)")

    def free_bytes(self, directory: Path) -> int:
        return 0 if self.full else 10**12


def test_a_torn_frame_that_cannot_be_cut_off_costs_only_its_own_records(tmp_path):
    ops = TornAndStuck()
    wall = Clock()
    rec = Recorder(tmp_path, "20260101T000000Z-1", _header, segment_s=1e9, retry_s=1.0,
                   clock=wall, wall=wall, fileops=ops)
    for k in range(10):
        assert rec.write(_raw(k * BLOCK))
    ops.full = True
    assert not rec.write(_raw(10 * BLOCK))
    assert ops.truncates == ops.truncate_attempts == 3   # retried, then given up, and said so
    assert rec.status()["torn_frames"] == 1
    assert not rec.write(_raw(11 * BLOCK))
    ops.full = False
    wall.t += 2.0
    for k in range(12, 20):
        assert rec.write(_raw(k * BLOCK))
    rec.close()
    files = sorted(tmp_path.glob("*.avr"))
    assert len(files) == 2                      # resumed in a new segment, never the torn one
    idx, gaps, reader = _indices(tmp_path)
    # The torn frame is the first segment's tail: reported, skipped, nothing else lost.
    assert [(Path(p.file).name, p.kind) for p in reader.problems] == [(files[0].name,
                                                                       "truncated")]
    assert [(g["i0"], g["n"]) for g in gaps] == [(10 * BLOCK, 2 * BLOCK)]
    expect = np.concatenate([np.arange(10 * BLOCK), np.arange(12 * BLOCK, 20 * BLOCK)])
    np.testing.assert_array_equal(idx, expect)
    # the disk_full gap explains the missing samples: no loss is blamed on the torn tail
    rec = load_recording(tmp_path)
    assert rec.meta["samples_lost"] == 0 and len(rec.meta["problems"]) == 1

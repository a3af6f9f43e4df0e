"""One walk over a recording (issue #16 items 2, 4, 5): damaged headers cost only the records
they touch, every loss is reported as sample-index ranges, duplicated or overlapping index
ranges are reported and counted once, and ``avard analyze`` splits the data exactly where the
service's accumulators did (every gap record, run change and index jump)."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from avard.core.analysis.engine import analyze
from avard.core.analysis.options import AnalyzeOptions
from avard.core.errors import FormatError
from avard.core.io import frames
from avard.core.io.recording import (
    RecordingReader,
    WalkReport,
    load_recording,
    replay_allan,
    walk,
)
from avard.core.io.source import open_record
from avard.daemon.service.recorder import Recorder
from hypothesis import given, settings
from hypothesis import strategies as st

RATE = 125.0
SCALE = 3.9e-5
BLOCK = 50


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def _write_run(directory: Path, run: str, i0: int, blocks: int, *, seed: int,
               segment_s: float = 1e9, header_every_s: float = 0.0,
               restart_gap: bool = False, offset: float = 0.0) -> None:
    """One run through the real segment writer: raw blocks of random-walk counts."""
    clock = Clock()

    def header() -> dict[str, Any]:
        return frames.header_record(run, rate_hz=RATE, t_mono=clock.t, t_real=clock.t,
                                    i0=i0, scale_m_s2_per_count=SCALE)

    rec = Recorder(directory, run, header, segment_s=segment_s, header_every_s=header_every_s,
                   clock=clock, wall=clock, realtime=lambda: 1.7e9 + clock.t)
    rng = np.random.default_rng(seed)
    if restart_gap:
        rec.write(frames.gap_record(run, 0, i0, 0, 0.0, 0.0, "restart"))
    for k in range(blocks):
        clock.t = k * BLOCK / RATE
        walk_ = np.cumsum(rng.normal(0, 30, (BLOCK, 3)), axis=0) + offset
        rec.write(frames.raw_record(run, 0, i0 + k * BLOCK, walk_.astype(np.int32),
                                    clock.t, clock.t))
    rec.close()


def _flip(path: Path, at: int) -> None:
    data = bytearray(path.read_bytes())
    data[at] ^= 0x04
    path.write_bytes(bytes(data))


def _index(rec: Any) -> np.ndarray:
    return np.asarray(rec.meta["index"])


def test_a_single_segment_with_a_damaged_header_reads_whole_from_the_header_copy(tmp_path):
    _write_run(tmp_path, "20260101T000000Z-a", 0, 40, seed=1, header_every_s=5.0)
    ref = replay_allan(tmp_path).snapshot()
    (seg,) = sorted(tmp_path.glob("*.avr"))
    _flip(seg, 40)                              # inside the first header's payload
    rec = load_recording(tmp_path)
    np.testing.assert_array_equal(_index(rec), np.arange(40 * BLOCK))
    assert len(rec.meta["problems"]) == 1 and "corrupt" in rec.meta["problems"][0]
    assert rec.meta["losses"] == [] and rec.meta["samples_lost"] == 0
    report = WalkReport()
    got = replay_allan(tmp_path, report=report).snapshot()
    assert report.recovered_headers == ["20260101T000000Z-a"]
    assert got.n_samples == ref.n_samples == 40 * BLOCK
    np.testing.assert_allclose(got.avar, ref.avar, rtol=1e-12)


def test_a_damaged_first_header_is_replaced_by_the_next_segment_of_the_same_run(tmp_path):
    # no header copies: segment 0's records wait for segment 1's header
    _write_run(tmp_path, "20260101T000000Z-a", 0, 40, seed=2, segment_s=8.0)
    segs = sorted(tmp_path.glob("*.avr"))
    assert len(segs) >= 2
    _flip(segs[0], 30)
    rec = load_recording(tmp_path)
    np.testing.assert_array_equal(_index(rec), np.arange(40 * BLOCK))
    assert rec.meta["samples_lost"] == 0


def test_a_damaged_raw_frame_is_reported_as_the_samples_it_held(tmp_path):
    _write_run(tmp_path, "20260101T000000Z-a", 0, 40, seed=3)
    (seg,) = sorted(tmp_path.glob("*.avr"))
    reader = RecordingReader(seg)
    offsets = [(fr.offset, frames.decode(fr.payload)) for fr in reader.frames()]
    at, victim = next((o, r) for o, r in offsets if r["kind"] == "raw" and r["i0"] == 500)
    _flip(seg, at + 60)
    rec = load_recording(tmp_path)
    assert rec.meta["losses"] == [{"run": "20260101T000000Z-a", "i0": 500, "n": BLOCK,
                                   "cause": rec.meta["losses"][0]["cause"]}]
    assert f"byte {at}" in rec.meta["losses"][0]["cause"]
    assert rec.meta["samples_lost"] == victim["n"] == BLOCK
    assert np.setdiff1d(np.arange(40 * BLOCK), _index(rec)).tolist() == list(range(500, 550))


def test_no_surviving_header_is_refused_naming_the_samples_it_costs(tmp_path):
    _write_run(tmp_path, "20260101T000000Z-a", 0, 10, seed=4)
    (seg,) = sorted(tmp_path.glob("*.avr"))
    _flip(seg, 30)
    with pytest.raises(FormatError, match=f"{10 * BLOCK} samples without a header"):
        load_recording(tmp_path)


def test_a_segment_concatenated_twice_counts_once_and_is_reported(tmp_path):
    _write_run(tmp_path, "20260101T000000Z-a", 0, 30, seed=5)
    ref = replay_allan(tmp_path).snapshot()
    (seg,) = sorted(tmp_path.glob("*.avr"))
    seg.write_bytes(seg.read_bytes() * 2)
    rec = load_recording(tmp_path)
    np.testing.assert_array_equal(_index(rec), np.arange(30 * BLOCK))
    assert rec.meta["samples_duplicated"] == 30 * BLOCK
    assert rec.meta["problems"] == []
    got = replay_allan(tmp_path).snapshot()
    assert got.n_samples == ref.n_samples
    np.testing.assert_allclose(got.avar, ref.avar, rtol=1e-12)


def test_overlapping_runs_keep_each_index_once_and_report_the_overlap(tmp_path):
    _write_run(tmp_path, "20260101T000000Z-a", 0, 20, seed=6)
    _write_run(tmp_path, "20260101T000100Z-b", 15 * BLOCK, 20, seed=7)   # 5 blocks overlap
    report = WalkReport()
    idx = np.concatenate([r["i0"] + np.arange(r["n"])
                          for r in walk(RecordingReader(tmp_path), report)
                          if r["kind"] == "raw"])
    np.testing.assert_array_equal(idx, np.arange(35 * BLOCK))
    assert report.samples_duplicated == 5 * BLOCK
    assert report.duplicates == [(15 * BLOCK + k * BLOCK, BLOCK) for k in range(5)]


def test_a_copied_segment_file_counts_once(tmp_path):
    _write_run(tmp_path, "20260101T000000Z-a", 0, 20, seed=8, segment_s=4.0)
    segs = sorted(tmp_path.glob("*.avr"))
    shutil.copy(segs[0], tmp_path / (segs[-1].stem + "_copy.avr"))   # sorts last
    rec = load_recording(tmp_path)
    np.testing.assert_array_equal(_index(rec), np.arange(20 * BLOCK))
    assert rec.meta["samples_duplicated"] > 0


def test_analyze_splits_at_restarts_exactly_as_the_service_accumulators(tmp_path):
    """Back-to-back runs whose restart gaps are zero-length: the index is contiguous, but the
    service (and its replay) starts a new segment at every run change and gap record."""
    i0 = 0
    for k in range(4):
        _write_run(tmp_path, f"20260101T00000{k}Z-r", i0, 30, seed=10 + k, restart_gap=k > 0,
                   offset=5000.0 * k)
        i0 += 30 * BLOCK
    rec = load_recording(tmp_path)
    assert np.all(np.diff(_index(rec)) == 1)          # no index jump anywhere
    assert rec.meta["segment_bounds"] == [0, 1500, 3000, 4500, 6000]
    service = replay_allan(tmp_path).result()
    # the service's estimator (the streaming cascade); analyze's default is the full OADEV
    result = analyze(open_record(str(tmp_path)),
                     AnalyzeOptions(find_sinusoids=False, estimator="cascade"))
    for c, name in enumerate("xyz"):
        ours = result.channels[name].allan
        theirs = service.channel(c)
        np.testing.assert_array_equal(ours.tau, theirs.tau)
        np.testing.assert_allclose(ours.dev, theirs.dev, rtol=1e-12)


def test_records_waiting_for_a_header_are_bounded_and_reported(tmp_path, monkeypatch):
    import avard.core.io.recording as recording

    monkeypatch.setattr(recording, "MAX_HEADERLESS_SAMPLES", 10 * BLOCK)
    _write_run(tmp_path, "20260101T000000Z-a", 0, 40, seed=9, header_every_s=8.0)
    (seg,) = sorted(tmp_path.glob("*.avr"))
    _flip(seg, 30)              # the first header; the copy comes after 8 s (1000 samples)
    report = WalkReport()
    idx = np.concatenate([r["i0"] + np.arange(r["n"])
                          for r in walk(RecordingReader(tmp_path), report)
                          if r["kind"] == "raw"])
    lost = [(x.i0, x.n) for x in report.losses]
    assert lost == [(k * BLOCK, BLOCK) for k in range(len(lost))] and lost
    np.testing.assert_array_equal(idx, np.arange(len(lost) * BLOCK, 40 * BLOCK))


@pytest.fixture(scope="module")
def three_segments(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("walk")
    _write_run(d, "20260101T000000Z-a", 0, 60, seed=11, segment_s=8.0, header_every_s=3.0)
    return d


@settings(max_examples=150, deadline=None)
@given(flips=st.lists(st.tuples(st.integers(0, 2), st.floats(0, 1, exclude_max=True),
                                st.integers(0, 7)), min_size=1, max_size=4))
def test_no_sample_goes_missing_silently_under_random_bit_flips(three_segments, tmp_path_factory,
                                                                flips) -> None:
    """Whatever single bits flip: every sample index below the last one read is either read
    (once) or reported lost, never silently missing."""
    d = tmp_path_factory.mktemp("flipped")
    segs = sorted(three_segments.glob("*.avr"))
    for seg in segs:
        shutil.copy(seg, d / seg.name)
    for which, where, bit in flips:
        f = d / segs[which % len(segs)].name
        data = bytearray(f.read_bytes())
        data[int(where * len(data))] ^= 1 << bit
        f.write_bytes(bytes(data))
    report = WalkReport()
    got = [r["i0"] + np.arange(r["n"]) for r in walk(RecordingReader(d), report)
           if r["kind"] == "raw"]
    read = np.concatenate(got) if got else np.zeros(0, dtype=np.int64)
    assert np.unique(read).size == read.size                     # each index once
    lost = np.concatenate([np.arange(x.i0, x.i0 + x.n) for x in report.losses]
                          or [np.zeros(0, dtype=np.int64)])
    assert np.intersect1d(read, lost).size == 0
    top = int(read.max()) + 1 if read.size else 0
    covered = np.union1d(read, lost)
    assert np.setdiff1d(np.arange(top), covered).size == 0, report.losses


def test_avard_analyze_names_the_lost_and_duplicated_samples(tmp_path, capsys):
    """What the walk repaired reaches the user: analyze's table and JSON give the samples a
    damaged frame cost (as an index range) and the duplicated samples it counted once."""
    import json

    from avard.daemon import cli

    _write_run(tmp_path, "20260101T000000Z-a", 0, 40, seed=3, segment_s=4.0)
    segs = sorted(tmp_path.glob("*.avr"))
    reader = RecordingReader(segs[1])
    at, victim = next((fr.offset, r) for fr in reader.frames()
                      if (r := frames.decode(fr.payload))["kind"] == "raw")
    _flip(segs[1], at + 60)
    shutil.copy(segs[0], tmp_path / (segs[-1].stem + "_copy.avr"))   # sorts last
    lost = f"[{victim['i0']}, {victim['i0'] + BLOCK})"
    assert cli.main(["analyze", str(tmp_path)]) == 0
    table = capsys.readouterr().out
    assert f"{BLOCK} samples lost (damage or missing segments) at {lost}" in table
    assert "duplicated samples counted once" in table
    assert cli.main(["analyze", str(tmp_path), "--json"]) == 0
    rec = json.loads(capsys.readouterr().out)["recording"]
    assert rec["samples_lost"] == BLOCK and rec["losses"][0]["i0"] == victim["i0"]
    assert rec["samples_duplicated"] > 0

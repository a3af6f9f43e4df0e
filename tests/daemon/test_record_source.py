"""The recording as a record source (issue #25), on real recordings written by `avard run
--simulate`: nothing missing goes unsaid (a deleted, emptied or replaced segment is a loss in
samples, with where; a copied segment is one WARNING, not one per block), runs at different
rates are refused together and analysed one at a time, and every path into analyze gives
the same answer: ``analyze(open_record(p))`` is ``avard analyze p`` for an .npz, a CSV and a
recording of the same samples, and the recording's filter corner travels with its blocks."""

from __future__ import annotations

import json
import logging
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from avard.core.analysis.engine import analyze
from avard.core.analysis.options import AnalyzeOptions
from avard.core.errors import DataError
from avard.core.io.recording import RecordingReader, load_recording
from avard.core.io.source import RecordFormat, StreamSource, open_record
from avard.daemon.cli import main

from .test_recording_rates import _mixed

CONFIG = """
[allan]
snapshot_interval_s = 10.0
checkpoint_interval_s = 10.0
[recording]
segment_s = 10.0
[publish]
enabled = false
"""


def _record(tmp: Path, name: str, *, seconds: float, seed: int, odr: float = 125.0,
            data: Path | None = None) -> Path:
    """A recording written by `avard run --simulate quiet-lab --speed 0` (segments of 10 s)."""
    cfg = tmp / f"{name}.toml"
    cfg.write_text(CONFIG + f"[sensor]\nodr_hz = {odr}\n")
    data = data or tmp / name
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    done = subprocess.run(
        [sys.executable, "-m", "avard.daemon.cli", "run", "--config", str(cfg), "--simulate",
         "quiet-lab", "--data-dir", str(data), "--speed", "0", "--duration", str(seconds),
         "--seed", str(seed)], capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    return data


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """40 s at 125 Hz in segments of about 10 s."""
    tmp = tmp_path_factory.mktemp("rec")
    rec = _record(tmp, "rec", seconds=40.0, seed=5)
    assert len(_segments(rec)) >= 3            # a middle one at least
    return rec


def _segments(rec: Path) -> list[Path]:
    return sorted(rec.glob("*.avr"))


def _raw_count(seg: Path) -> int:
    """How many raw records a segment holds."""
    return sum(r["kind"] == "raw" for r in RecordingReader(seg))


def _raw_samples(seg: Path) -> tuple[int, int]:
    """(first index, samples) of a segment's raw records."""
    raws = [r for r in RecordingReader(seg) if r["kind"] == "raw"]
    return int(raws[0]["i0"]), sum(int(r["n"]) for r in raws)


def _copy(recording: Path, tmp_path: Path) -> Path:
    out = tmp_path / "rec"
    shutil.copytree(recording, out)
    return out


def _json(path: Path, *extra: str, capsys: pytest.CaptureFixture[str]) -> dict:
    assert main(["analyze", str(path), "--json", *extra]) == 0
    return json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("how", ["deleted", "emptied", "replaced by a directory"])
def test_a_missing_middle_segment_is_a_loss_in_samples_with_where(
        recording: Path, tmp_path: Path, how: str, capsys: pytest.CaptureFixture[str],
        caplog: pytest.LogCaptureFixture) -> None:
    rec = _copy(recording, tmp_path)
    whole = open_record(rec).info
    # a middle segment that holds samples (where the service rotated depends on how fast it
    # ran: segment 1 held no raw frame in one run of a fresh clone's suite)
    segs = _segments(rec)
    k = next(k for k in range(1, len(segs) - 1) if _raw_count(segs[k]))
    victim = segs[k]
    i0, n = _raw_samples(victim)
    victim.unlink()
    if how == "emptied":
        victim.write_bytes(b"")
    elif how == "replaced by a directory":
        victim.mkdir()
    with caplog.at_level(logging.WARNING):
        info = open_record(rec).info
    assert info.recording is not None
    (loss,) = info.recording.losses
    assert (loss.i0, loss.n) == (i0, n)
    state = {"deleted": "missing", "emptied": "empty",
             "replaced by a directory": "not a file"}[how]
    assert f"segment {k:04d} {state}" in loss.where
    assert info.n_samples == whole.n_samples - n
    assert info.recording.runs[0].samples_lost == n
    said = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(said) == 1 and f"{n} samples lost in 1 place" in said[0]
    d = _json(rec, capsys=capsys)
    assert d["recording"]["samples_lost"] == n
    assert d["recording"]["losses"][0]["i0"] == i0 and f"{k:04d}" in d["recording"]["losses"][
        0]["where"]
    # the samples either side are never joined by an Allan difference
    assert d["recording"]["segments"] == 2


def test_a_copied_segment_is_counted_once_and_said_once(
        recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        caplog: pytest.LogCaptureFixture) -> None:
    rec = _copy(recording, tmp_path)
    segs = _segments(rec)
    _i0, n = _raw_samples(segs[0])
    shutil.copy(segs[0], rec / (segs[-1].stem + "_copy.avr"))      # sorts last
    with caplog.at_level(logging.WARNING):
        info = open_record(rec).info
    assert info.recording is not None
    assert info.recording.samples_duplicated == n
    assert info.n_samples == open_record(recording).info.n_samples
    said = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(said) == 1 and f"{n} read twice" in said[0], said
    d = _json(rec, capsys=capsys)
    assert d["recording"]["samples_duplicated"] == n
    assert [x["where"] for x in d["recording"]["duplicates"]] == [
        str(rec / (segs[-1].stem + "_copy.avr"))]


def test_runs_at_different_rates_are_refused_together_and_analysed_one_at_a_time(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    # the service refuses to record another rate into a directory: such a directory is one
    # an older version left, the second run continuing the first's sample index
    # (test_recording_rates._mixed; a run recorded apart and copied in would start at
    # index 0 again, and its samples would be the first run's duplicates)
    rec = _mixed(tmp_path, monkeypatch)
    capsys.readouterr()        # what the two runs logged: the test reads analyze's line only
    runs = sorted({p.name.split("_")[0] for p in _segments(rec)})
    assert len(runs) == 2
    with pytest.raises(DataError, match="incompatible rates") as err:
        open_record(rec)
    assert runs[0] in str(err.value) and runs[1] in str(err.value)
    assert main(["analyze", str(rec)]) == 2
    msg = capsys.readouterr().err.strip()
    assert len(msg.splitlines()) == 1 and all(run in msg for run in runs)
    # each run's rate (fitted, ± its uncertainty, once the service's fit has one)
    assert re.search(r" 12[45](\.\d+)?( ± [\d.]+)? Hz", msg)
    assert re.search(r" 2[45]\d(\.\d+)?( ± [\d.]+)? Hz", msg)
    for run, rate in zip(runs, (125.0, 250.0), strict=True):
        d = _json(rec, "--run", run, capsys=capsys)
        assert abs(d["rate_hz"] / rate - 1) < 1e-2
        assert [r["run"] for r in d["recording"]["runs"]] == [run]


def _held(t: np.ndarray) -> np.ndarray:
    """Each column's last finite value carried forward (NaN before the first)."""
    ok = np.isfinite(t)
    at = np.where(ok, np.arange(len(t))[:, None], -1)
    np.maximum.accumulate(at, axis=0, out=at)
    out = np.take_along_axis(t, np.maximum(at, 0), axis=0)
    out[at < 0] = np.nan
    return out


def test_a_recording_streams_the_samples_load_recording_holds(recording: Path) -> None:
    """The blocks of a recording are what the whole-record loader holds, sample for sample,
    in blocks of any size; read twice, the same. Temperatures come as an .npz holds them:
    each reading on the row of its sample index and NaN between (one reading per
    conversion, not one per sample), so that held they are the loader's hold."""
    whole = load_recording(recording)
    raws = [r for r in RecordingReader(recording) if r["kind"] == "raw"]
    index = np.concatenate([np.arange(r["i0"], r["i0"] + r["n"]) for r in raws])
    assert np.all(np.diff(index) > 0)         # one run, no copy: the rows' indices
    readings: dict[str, set[int]] = {}
    for r in RecordingReader(recording):
        if r["kind"] == "temp":
            for name, v in zip(r["names"], r["values_c"], strict=True):
                if v is not None and r["i0"] <= index[-1]:
                    # the row of its index, or the first row after it
                    readings.setdefault(name, set()).add(
                        int(np.searchsorted(index, r["i0"])))
    src = open_record(recording)
    for block in (1000, 1 << 16):
        got = list(src.blocks(block))
        assert all(len(a) <= block for a, _t, _e in got)
        np.testing.assert_array_equal(np.concatenate([a for a, _t, _e in got]), whole.accel)
        temps = np.concatenate([t for _a, t, _e in got if t is not None])
        np.testing.assert_array_equal(_held(temps), whole.temperature_c)
        for j, name in enumerate(src.info.temperature_names):
            assert set(np.flatnonzero(np.isfinite(temps[:, j])).tolist()) == readings[name]
    assert src.info.format is RecordFormat.RECORDING
    cols = np.concatenate([a for a, _t, _e in src.blocks(777, columns=[2])])
    np.testing.assert_array_equal(cols[:, 0], whole.accel[:, 2])


def _same(a: dict, b: dict) -> None:
    """Two analyze JSONs equal in everything but the source path."""
    a, b = dict(a), dict(b)
    a.pop("source"), b.pop("source")
    assert a == b


def test_every_path_into_analyze_gives_avard_analyze(
        recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    whole = load_recording(recording)
    info = open_record(recording).info
    npz = tmp_path / "same.npz"
    # the same samples as the simulator writes them: its ADXL355 says so (odr_nominal_hz)
    np.savez(npz, accel=whole.accel, rate_hz=info.rate_hz, odr_nominal_hz=125.0,
             lsb_mps2=info.lsb_mps2)
    csv = tmp_path / "same.csv"
    np.savetxt(csv, whole.accel, delimiter=",", header="x,y,z", comments="", fmt="%.17g")
    rate = repr(info.rate_hz)
    for path, extra in ((recording, []), (npz, []), (csv, ["--rate", rate])):
        src = open_record(path, rate_hz=info.rate_hz if extra else None)
        ours = json.loads(json.dumps(analyze(src).to_dict(), allow_nan=False))
        _same(ours, _json(path, *extra, capsys=capsys))
    # a recording and an .npz of the same samples from the same ADXL355: the same fit,
    # filter corner and LSB included
    rec_an, npz_an = analyze(open_record(recording)), analyze(open_record(npz))
    assert rec_an.meta["filter_corner_hz"] == npz_an.meta["filter_corner_hz"] == info.rate_hz / 4
    for k in "xyz":
        assert (rec_an.channels[k].fit.terms["velocity_random_walk"].value
                == npz_an.channels[k].fit.terms["velocity_random_walk"].value)
    # blocks handed over from anywhere (the old analyze_stream(*iter_blocks(rec)) path) carry
    # the recording's RecordInfo, and with it the corner: the same answer
    src = open_record(recording)
    streamed = analyze(StreamSource(src.info, src.blocks()))
    assert streamed.meta["filter_corner_hz"] == info.rate_hz / 4
    _same(streamed.to_dict(), rec_an.to_dict())


def test_analyze_does_not_load_a_recording(recording: Path, monkeypatch) -> None:
    """The whole-record loader is never called by analyze."""
    from avard.core.io import recording as module

    def refuse(*_a, **_k):  # pragma: no cover - failing is the point
        raise AssertionError("load_recording called")

    monkeypatch.setattr(module, "load_recording", refuse)
    assert analyze(open_record(recording), AnalyzeOptions(channels=("x",))).n_samples > 0


def test_a_recording_still_being_written_reads_as_it_was_opened(recording: Path,
                                                                 tmp_path: Path) -> None:
    """The service appends while analyze reads: every read stops where the scan stopped, so
    the passes agree with each other and with the description."""
    from avard.core.io import frames
    from avard.core.io.recording import frame

    rec = _copy(recording, tmp_path)
    src = open_record(rec)
    n = src.info.n_samples
    assert n is not None
    last = _segments(rec)[-1]
    run = last.name.split("_")[0]
    more = frames.raw_record(run, 10**6, n, np.ones((125, 3), dtype=np.int32), 0.0, 0.0)
    with open(last, "ab") as fh:
        fh.write(frame(frames.encode(more)))
    assert sum(len(a) for a, _t, _e in src.blocks()) == n
    assert analyze(src, AnalyzeOptions(channels=("z",))).n_samples == n
    assert open_record(rec).info.n_samples == n + 125      # opened again: the new block


def _flip(path: Path, at: int) -> None:
    data = bytearray(path.read_bytes())
    data[at] ^= 0x04
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("damage", ["none", "flipped", "copied", "deleted"])
def test_the_read_plan_is_the_walk(recording: Path, tmp_path: Path, damage: str) -> None:
    """The fast path (the scan's read plan: only the counts' bytes read again) yields the
    very blocks of the general one (every frame decoded and walked), on a clean recording, a
    damaged frame, a copied segment and a deleted one; temperatures and column picks too."""
    rec = _copy(recording, tmp_path)
    segs = _segments(rec)
    if damage == "flipped":
        # inside the segment whatever its size (where the service rotated depends on how
        # fast it ran)
        _flip(segs[2], min(5000, segs[2].stat().st_size // 2))
    elif damage == "copied":
        shutil.copy(segs[0], rec / (segs[-1].stem + "_copy.avr"))
    elif damage == "deleted":
        segs[1].unlink()
    src = open_record(rec)
    assert src._plan is not None          # the fast path is the one taken
    for kw in ({}, {"columns": [2, 0], "temperature": False}):
        fast = list(src.blocks(1000, **kw))
        plan, src._plan = src._plan, None
        slow = list(src.blocks(1000, **kw))
        src._plan = plan
        assert len(fast) == len(slow)
        for (a, t, e), (b, u, f) in zip(fast, slow, strict=True):
            np.testing.assert_array_equal(a, b)
            assert e == f
            if t is None:
                assert u is None
            else:
                np.testing.assert_array_equal(t, u)


def test_a_run_too_short_for_the_rate_fit_joins_its_odr_and_leaves_the_mean(
        recording: Path, tmp_path: Path) -> None:
    """A run killed before the service fitted its rate carries the nominal ODR: it is one
    sensor's data with runs of the same ODR (not refused for the nominal's ppm), and the
    record's rate stays the fitted one."""
    rec = _copy(recording, tmp_path)
    fitted = open_record(rec).info
    _record(tmp_path, "short", seconds=5.0, seed=9, data=rec)
    info = open_record(rec).info
    assert info.recording is not None
    first, short = info.recording.runs
    assert first.rate_fitted and not short.rate_fitted and short.rate_hz == 125.0
    assert info.rate_hz == fitted.rate_hz and info.rate_u_hz == fitted.rate_u_hz
    assert info.n_samples == fitted.n_samples + short.n_samples


def test_a_segment_removed_while_it_is_read_is_one_line(recording: Path,
                                                         tmp_path: Path) -> None:
    rec = _copy(recording, tmp_path)
    src = open_record(rec)
    _segments(rec)[0].unlink()                # retention, between the scan and the pass
    with pytest.raises(DataError, match="removed while the recording was read"):
        list(src.blocks())


def test_damaged_frames_are_one_line_per_file_and_one_per_run(
        recording: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    from avard.core.io import frames

    rec = _copy(recording, tmp_path)

    def raw_frames(seg: Path) -> list[tuple[int, dict]]:
        recs = [(fr.offset, frames.decode(fr.payload)) for fr in RecordingReader(seg).frames()]
        return [(at, r) for at, r in recs if r["kind"] == "raw"]

    # where the service rotated depends on how fast it ran: a later segment with room for
    # three damaged frames apart (9 raw frames), not a fixed one that may hold fewer
    seg = next(s for s in _segments(rec)[1:] if len(raw_frames(s)) >= 9)
    hits = raw_frames(seg)[2:9:3]     # apart: 3 losses
    for at, _r in hits:
        _flip(seg, at + 60)
    with caplog.at_level(logging.WARNING):
        info = open_record(rec).info
    said = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(said) == 2, said
    assert seg.name in said[0] and "3 damaged" in said[0]
    lost = sum(int(r["n"]) for _at, r in hits)
    assert f"{lost} samples lost in 3 place(s)" in said[1]
    assert info.recording is not None and info.recording.samples_lost == lost
    assert [x.i0 for x in info.recording.losses] == [int(r["i0"]) for _at, r in hits]

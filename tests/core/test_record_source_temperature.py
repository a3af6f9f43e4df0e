"""A recording's temperatures reach the screen and explain as an .npz's do: one reading per
DS18B20 conversion, on the row of its sample index, NaN between. A recording used to hand them
over held at the last reading, so every sample was a "reading" to the input screen (0.8 GB
to screen 24 h) and its spike, dropout and stuck rules judged held values.

The recordings here are written frame by frame from the samples and readings of an .npz
(its accel as integer counts, so both hold the very same samples; a temperature record per
reading and channel, failed reads as None, as the service writes them), over two segment
files with status records among the blocks."""

from __future__ import annotations

import itertools
import shutil
from pathlib import Path

import numpy as np
import pytest
from avard.core.io import frames
from avard.core.io.recording import frame
from avard.core.io.screen.stream import ScreenedSource
from avard.core.io.source import open_record

from tests.support.adversary_gen import make_record as adversary_record

#: m/s² per count of the recordings written here (fine enough for any record's samples)
SCALE = 1e-7



def assert_same_tables(fast: list[tuple[np.ndarray, np.ndarray]],
                       slow: list[tuple[np.ndarray, np.ndarray]], least: int) -> None:
    """Two reads' temperature tables (index, value per channel) equal, each channel holding
    more than ``least`` readings (so the comparison compares something)."""
    assert [len(i) for i, _v in fast] == [len(i) for i, _v in slow]
    assert all(len(i) > least for i, _v in fast)
    for (i1, v1), (i2, v2) in zip(fast, slow, strict=True):
        np.testing.assert_array_equal(i1, i2)
        np.testing.assert_array_equal(v1, v2)

def _write(path: Path, records: list[dict]) -> None:
    path.write_bytes(b"".join(frame(frames.encode(r)) for r in records))


def _as_recording(accel: np.ndarray, temps: np.ndarray, names: list[str], rate: float,
                  out: Path, *, block: int = 50) -> Path:
    """A recording of ``accel`` (n, 3) counts and the readings of ``temps`` (n, k) °C, NaN
    between readings: each finite value one temp record at its row's index; in a hole of
    more than 5 s of a channel a failed read (None) every second, as the service records a
    DS18B20 that stopped answering."""
    out.mkdir(parents=True)
    run = "r1"
    seq = [0]

    def nxt() -> int:
        seq[0] += 1
        return seq[0]

    head = frames.header_record(run, rate_hz=rate, t_mono=0.0, t_real=0.0,
                                scale_m_s2_per_count=SCALE, temperature_channels=names)
    readings: list[tuple[int, str, float | None]] = []
    for j, name in enumerate(names):
        rows = np.flatnonzero(np.isfinite(temps[:, j]))
        readings += [(int(i), name, float(temps[i, j])) for i in rows]
        for a, b in itertools.pairwise(rows):
            if (b - a) / rate > 5.0:
                readings += [(int(i), name, None)
                             for i in range(int(a) + int(rate), int(b), int(rate))]
    readings.sort(key=lambda r: r[0])
    n = len(accel)
    segs: list[list[dict]] = [[head], [dict(head, seq=nxt())]]
    at = 0
    for b, i0 in enumerate(range(0, n, block)):
        seg = segs[0 if i0 < n // 2 else 1]
        while at < len(readings) and readings[at][0] < i0 + block:
            i, name, v = readings[at]
            seg.append(frames.temp_record(run, nxt(), i, [name], [v], i / rate, i / rate))
            at += 1
        seg.append(frames.raw_record(run, nxt(), i0, accel[i0:i0 + block].astype(np.int32),
                                     i0 / rate, i0 / rate))
        if b % 40 == 0:
            seg.append(frames.status_record(run, nxt(), {"blocks": b}, i0 / rate, i0 / rate))
    for k, recs in enumerate(segs):
        _write(out / f"{run}_{k:04d}_x.avr", recs)
    return out


def _npz(accel: np.ndarray, temps: np.ndarray, names: list[str], rate: float,
         path: Path) -> Path:
    np.savez(path, accel=accel * SCALE, rate_hz=np.float64(rate), temperature_c=temps,
             temperature_names=np.array(names))
    return path


def _screened(path: Path) -> ScreenedSource:
    src = ScreenedSource(open_record(path))
    for _ in src.blocks(1 << 12):
        pass
    assert src.log is not None and src.log.done
    return src


def _stretches(src: ScreenedSource) -> list[tuple]:
    assert src.log is not None
    return [(s.channel, s.kind, s.first, s.last, s.count, round(s.start_s, 9),
             round(s.end_s, 9)) for s in src.log.stretches]


@pytest.fixture(scope="module")
def faulty(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, dict]:
    """The adversary generator's faulty null record (2 h; 85 °C, −127 °C, spikes, a dropout,
    a stuck run, a start-up glitch, a shock) as an .npz and as a recording."""
    tmp = tmp_path_factory.mktemp("faulty")
    truth = adversary_record("null_faulty", 202, tmp / "gen.npz", hours=2.0)
    with np.load(tmp / "gen.npz") as z:
        rate = float(z["rate_hz"])
        counts = np.rint(np.asarray(z["accel"], dtype=float) / SCALE)
        temps = np.asarray(z["temperature_c"], dtype=float).reshape(len(counts), -1)
        names = [str(x) for x in z["temperature_names"]]
    assert np.abs(counts).max() < 2 ** 31
    return (_npz(counts, temps, names, rate, tmp / "same.npz"),
            _as_recording(counts, temps, names, rate, tmp / "rec"), truth)


def test_the_screen_judges_a_recording_as_the_same_samples_in_an_npz(faulty) -> None:
    """Every verdict (85 °C, −127 °C, spikes, the dropout, the stuck run, the glitch and the
    shock) at the same samples and times, on a recording and on an .npz of its samples."""
    npz, rec, _truth = faulty
    a, b = _screened(npz), _screened(rec)
    assert a.log is not None and b.log is not None
    assert a.log.counts() == {"power_on_85": 3, "read_error": 2, "spike": 2, "dropout": 1,
                              "stuck": 1, "startup_glitch": 1, "shock": 1}
    assert _stretches(b) == _stretches(a)
    assert b.log.readings == a.log.readings


def test_a_recording_hands_over_readings_not_held_values(faulty) -> None:
    """Temperatures of a recording's blocks are the .npz's, NaN for NaN: what explain's slow
    view and the screen read is the same on both."""
    npz, rec, _truth = faulty
    t_npz = np.concatenate([t for _a, t, _e in open_record(npz).blocks(1 << 12)])
    t_rec = np.concatenate([t for _a, t, _e in open_record(rec).blocks(1 << 12)])
    np.testing.assert_array_equal(t_rec, t_npz)


def _readings_at(rate: float, tmp: Path, minutes: float = 20.0) -> tuple[int, int]:
    """The readings the screen kept on a recording of ``minutes`` at ``rate`` Hz whose one
    DS18B20 reads once a second (the same readings at every rate), and how many there are."""
    rng = np.random.default_rng(3)
    n = int(minutes * 60 * rate)
    counts = np.rint(rng.normal(0, 100, (n, 3))) + 1e6
    temps = np.full((n, 1), np.nan)
    every = int(rate)
    steps = np.round(np.cumsum(rng.normal(0, 0.02, len(temps[::every]))) / 0.0625) * 0.0625
    temps[::every, 0] = 21.0 + steps
    src = _screened(_as_recording(counts, temps, ["ambient"], rate, tmp / f"r{rate:g}"))
    assert src.log is not None
    return src.log.readings["ambient"], int(np.count_nonzero(np.isfinite(temps)))


def test_the_screen_keeps_one_entry_per_reading_whatever_the_sample_rate(tmp_path) -> None:
    """What the screen holds of a temperature channel is its readings: as many at 200 Hz as
    at 10 Hz (held values made it one per sample: 20× more at 200 Hz), including a stuck
    sensor's repeated value (one reading per conversion, never de-duplicated)."""
    kept_10, n_10 = _readings_at(10.0, tmp_path)
    kept_200, n_200 = _readings_at(200.0, tmp_path)
    assert n_10 == n_200 == 1200
    assert kept_10 == n_10 and kept_200 == n_200


def test_the_temperatures_read_where_the_scan_skipped_them_are_the_walks(faulty, tmp_path
                                                                       ) -> None:
    """The temperature tables read from the byte ranges the scan noted are the ones a walk
    of every record gives, on a clean recording, with a copied segment and with a damaged
    temperature frame (which both paths drop)."""
    _npz_path, rec, _truth = faulty
    for damage in ("none", "copied", "flipped"):
        here = tmp_path / damage
        shutil.copytree(rec, here)
        segs = sorted(here.glob("*.avr"))
        if damage == "copied":
            shutil.copy(segs[0], here / (segs[-1].stem + "_copy.avr"))
        elif damage == "flipped":
            data = bytearray(segs[1].read_bytes())
            at = data.find(b"\xa4kind\xa4temp", len(data) // 2)
            data[at + 12] ^= 0xFF
            segs[1].write_bytes(bytes(data))
        src = open_record(here)
        assert src._places is not None and src._places.ok
        fast = src._temperature_tables()
        src._temps, src._places = None, None
        assert_same_tables(fast, src._temperature_tables(), 1000)


def test_a_headerless_runs_readings_land_on_no_other_runs_rows(tmp_path: Path) -> None:
    """A run whose header never survived is dropped by the walk (its samples reported lost);
    its temperature records, read from the ranges the scan skipped and keyed by index alone,
    landed on another run's rows (a 99 °C reading on r1's samples)."""
    rate, rng = 100.0, np.random.default_rng(1)
    d = tmp_path / "rec"
    d.mkdir()

    def run_records(run: str, with_header: bool, t_off: int, value: float | None,
                    i_off: int) -> list[dict]:
        seq = itertools.count(1)
        recs = [frames.header_record(run, rate_hz=rate, t_mono=0.0, t_real=0.0,
                                     scale_m_s2_per_count=SCALE,
                                     temperature_channels=["t0"])] if with_header else []
        for i0 in range(0, 1000, 100):
            v = 20.0 + i0 / 1000 if value is None else value
            recs.append(frames.temp_record(run, next(seq), i0 + t_off, ["t0"], [v],
                                           (i0 + t_off) / rate, (i0 + t_off) / rate))
            counts = rng.integers(-1000, 1000, size=(100, 3)).astype(np.int32)
            recs.append(frames.raw_record(run, next(seq), i0 + i_off, counts,
                                          (i0 + i_off) / rate, (i0 + i_off) / rate))
        return recs

    _write(d / "r1_00000000_a.avr", run_records("r1", True, 0, None, 0))
    _write(d / "r2_00000000_b.avr", run_records("r2", False, 50, 99.0, 2000))
    src = open_record(str(d))
    temps = np.concatenate([t for _a, t, _end in src.blocks(1 << 12)])
    assert not np.any(temps == 99.0)
    assert np.count_nonzero(np.isfinite(temps)) == 10

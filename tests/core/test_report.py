"""report: the streamed analysis, sinusoid detection, the --json shape, kalibr and csv output,
and the figure."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest
from avard.core.analysis.engine import analyze
from avard.core.analysis.formats import adev_csv, format_table, kalibr_yaml
from avard.core.analysis.options import AnalyzeOptions
from avard.core.analysis.spectrum import WelchAccumulator, find_lines
from avard.core.errors import DataError
from avard.core.io.source import RecordFormat, open_record
from avard.core.model.terms import TERMS, UNITS

from .test_fit import record

RATE = 50.0


@pytest.fixture(scope="module")
def lab_npz(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two channels: white + flicker, one with a 2.5 Hz line of 4e-4 m/s²."""
    rng = np.random.default_rng(3)
    n = 1 << 17
    a = record(n, RATE, rng, N=2e-4, B=4e-5)
    b = record(n, RATE, rng, N=2e-4, B=4e-5, K=1e-5)
    b += 4e-4 * np.sin(2 * np.pi * 2.5 * np.arange(n) / RATE)
    p = tmp_path_factory.mktemp("rep") / "lab.npz"
    np.savez(p, accel=np.column_stack([a, b]), rate_hz=RATE, axes=np.array(["x", "z"]))
    return p


@pytest.mark.parametrize("channels", [1, 3])
def test_streamed_welch_equals_scipy_welch(channels: int) -> None:
    """The streamed, batched accumulator against scipy.signal.welch (Hann, 50 % overlap,
    constant detrend, density) on the whole record, for blocks that cut segments anywhere."""
    from scipy.signal import welch

    rng = np.random.default_rng(11)
    n, L = 50_000, 1 << 10
    y = rng.normal(0.0, 1e-3, (n, channels)) + np.array([0.1, -0.2, 9.81][:channels])
    y += 2e-4 * np.sin(2 * np.pi * 3.3 * np.arange(n) / 40.0)[:, None]
    acc = WelchAccumulator(channels, 40.0, L)
    i = 0
    for size in itertools.cycle([2999, 1, 7000, 1024]):
        if i >= n:
            break
        acc.update(y[i:i + size])
        i += size
    f, psd = acc.result()
    f_ref, psd_ref = welch(y, 40.0, window="hann", nperseg=L, noverlap=L // 2,
                           detrend="constant", scaling="density", axis=0)
    np.testing.assert_allclose(f, f_ref, rtol=1e-15)
    np.testing.assert_allclose(psd, psd_ref, rtol=1e-9)
    assert acc.n_seg == (n - L) // (L // 2) + 1


def test_welch_segment_must_be_even() -> None:
    with pytest.raises(DataError, match="even length"):
        WelchAccumulator(1, 10.0, 255)


def test_streamed_welch_never_spans_a_gap() -> None:
    """Across ``gap()`` no segment mixes the two sides: the accumulated spectrum is the
    segment-count-weighted mean of scipy's Welch of each side (one far from the other)."""
    from scipy.signal import welch

    rng = np.random.default_rng(12)
    L = 256
    sides = [rng.normal(5.0, 1e-3, (3000, 2)), rng.normal(-7.0, 2e-3, (2100, 2))]
    acc = WelchAccumulator(2, 10.0, L)
    for y in sides:
        for i in range(0, len(y), 700):
            acc.update(y[i:i + 700])
        acc.gap()
    counts = [(len(y) - L) // (L // 2) + 1 for y in sides]
    ref = sum(c * welch(y, 10.0, window="hann", nperseg=L, noverlap=L // 2,
                        detrend="constant", scaling="density", axis=0)[1]
              for c, y in zip(counts, sides, strict=True)) / sum(counts)
    assert acc.n_seg == sum(counts)
    np.testing.assert_allclose(acc.result()[1], ref, rtol=1e-9)


def test_find_lines_recovers_frequency_and_amplitude() -> None:
    rng = np.random.default_rng(5)
    fs, n = 100.0, 1 << 18
    t = np.arange(n) / fs
    y = rng.normal(scale=1e-2, size=n) + 3e-3 * np.sin(2 * np.pi * 7.3 * t) \
        + 1e-3 * np.sin(2 * np.pi * 21.0 * t + 1)
    w = WelchAccumulator(1, fs, 1 << 13)
    for i in range(0, n, 10_000):  # streamed in blocks that do not align with segments
        w.update(y[i:i + 10_000])
    f, psd = w.result()
    assert np.sum(psd[:, 0]) * (f[1] - f[0]) == pytest.approx(np.var(y), rel=0.05)
    lines = find_lines(f, psd[:, 0], w.n_seg)
    assert len(lines) == 2
    assert lines[0]["frequency_hz"] == pytest.approx(7.3, abs=f[1])
    assert lines[0]["amplitude"] == pytest.approx(3e-3, rel=0.1)
    assert lines[1]["frequency_hz"] == pytest.approx(21.0, abs=f[1])
    assert lines[1]["amplitude"] == pytest.approx(1e-3, rel=0.15)
    # pure noise: no line in 20 spectra (the test keeps a false line at 1 % per spectrum)
    found = 0
    for _ in range(20):
        w = WelchAccumulator(1, fs, 1 << 12)
        w.update(rng.normal(size=1 << 16))
        f, psd = w.result()
        found += len(find_lines(f, psd[:, 0], w.n_seg))
    assert found <= 1


def test_find_lines_no_false_lines_on_a_red_spectrum_and_finds_a_low_line() -> None:
    """8191 averaged segments make the test tight (threshold ≈ 1.05 × background), so the
    background near 0 Hz must follow a rising 1/f spectrum: a window padded at DC read a 60 h
    record's flicker rise as lines at 0.05 and 0.09 Hz (and reads this one as a line). A real
    line 12 bins up is found, with its amplitude."""
    rng = np.random.default_rng(8)
    fs, n, L = 100.0, 1 << 23, 1 << 11
    spec = np.fft.rfft(rng.normal(size=n))
    fr = np.fft.rfftfreq(n, 1 / fs)
    fr[0] = fr[1]
    red = rng.normal(size=n) + 0.3 * np.fft.irfft(spec / np.sqrt(fr), n)   # white + 1/f
    f = np.fft.rfftfreq(L, 1 / fs)
    f_line = f[12] + 0.3 * f[1]
    line = 0.05 * np.sin(2 * np.pi * f_line * np.arange(n) / fs)
    for y, expect in ((red, 0), (red + line, 1)):
        w = WelchAccumulator(1, fs, L)
        w.update(y)
        f, psd = w.result()
        assert w.n_seg > 8000
        assert psd[4, 0] > 1.3 * psd[60, 0]   # red at the low end
        lines = find_lines(f, psd[:, 0], w.n_seg)
        assert len(lines) == expect, lines
        if expect:
            assert lines[0]["frequency_hz"] == pytest.approx(f_line, abs=f[1])
            assert lines[0]["amplitude"] == pytest.approx(0.05, rel=0.2)


def test_analysis_json_has_exactly_the_issue_shape(lab_npz: Path) -> None:
    an = analyze(open_record(str(lab_npz)))
    d = json.loads(json.dumps(an.to_dict(), allow_nan=False))
    assert set(d) == {"source", "rate_hz", "n_samples", "estimator", "estimator_description",
                      "channels", "screened"}
    # the input screen (core/io/screen.py) says what it masked: nothing on a clean record
    # (``notes``/``refused``: what it found of each temperature log as a whole, and the logs
    # the thermal model must not use: none on a clean record; ``temperature_units``: the
    # logs' units as asked, --temperature-units, auto by default; ``reading_steps``: each
    # log's reading step and origin, K, and whether it is coarser than the 12-bit 0.0625 K)
    assert set(d["screened"]) == {"counts", "samples_masked", "stretches", "rules", "units",
                                  "notes", "refused", "temperature_units", "reading_steps"}
    for v in d["screened"]["reading_steps"].values():
        assert v is None or (set(v) == {"step_k", "origin_k", "coarse"} and not v["coarse"])
    assert d["screened"]["temperature_units"] == "auto"
    assert d["screened"]["counts"] == {} and d["screened"]["samples_masked"] == 0
    assert d["screened"]["notes"] == {} and d["screened"]["refused"] == {}
    assert d["estimator"] == "oadev" and "OADEV" in d["estimator_description"]
    assert d["rate_hz"] == RATE and d["n_samples"] == 1 << 17
    assert list(d["channels"]) == ["x", "z"]
    for cname, ch in d["channels"].items():
        assert set(ch) == {"estimator", "tau_s", "adev", "adev_lo", "adev_hi", "edf", "alpha",
                           "units", "terms", "sinusoids", "fit", "slow_sinusoid", "drift"}
        # where R came from and the drift floor (analysis/drift.py), in SI
        assert set(ch["drift"]) == {"rate_ramp_from", "floor", "unit", "interval_noise"}
        assert ch["drift"]["unit"] == "m/s^3" and ch["drift"]["floor"] >= 0
        # issue 24: the slow-sinusoid search below the line finder's band, what it found or
        # why nothing is claimed
        slow = ch["slow_sinusoid"]
        assert {"note", "band_cycles_per_record", "statistic", "threshold",
                "units"} <= set(slow)
        if "frequency_hz" in slow:
            lo, hi = slow["frequency_interval_hz"]
            assert lo <= slow["frequency_hz"] <= hi
            assert slow["units"]["amplitude"] == "m/s^2"
        assert ch["estimator"] == "oadev"
        k = len(ch["tau_s"])
        assert all(len(ch[key]) == k for key in ("adev", "adev_lo", "adev_hi", "edf", "alpha"))
        assert set(ch["terms"]) == set(TERMS)
        for name, t in ch["terms"].items():
            assert set(t) == {"value", "lo", "hi", "unit", "present", "upper", "note"}
            assert t["unit"] == UNITS[name]
            if t["present"]:
                assert t["lo"] <= t["value"] <= t["hi"] and t["upper"] is None
            else:
                assert t["value"] is None and t["lo"] is None and t["hi"] is None
                # the table's "absent (< upper)" is in the JSON too
                upper = an.channels[cname].fit.terms[name].upper
                assert upper is not None and t["upper"] == pytest.approx(upper) and upper > 0
        assert set(ch["fit"]) == {"tau_min_s", "tau_max_s", "chi2_dof"}
        for s in ch["sinusoids"]:
            # issue 23: each amplitude with its 68 % interval, and its disturbance
            assert set(s) == {"frequency_hz", "amplitude", "amplitude_interval", "disturbance"}
            assert s["amplitude_interval"][0] <= s["amplitude"] <= s["amplitude_interval"][1]
    x, z = d["channels"]["x"], d["channels"]["z"]
    assert x["sinusoids"] == []
    assert len(z["sinusoids"]) == 1
    assert z["sinusoids"][0]["frequency_hz"] == pytest.approx(2.5, abs=0.01)
    assert z["sinusoids"][0]["amplitude"] == pytest.approx(4e-4, rel=0.1)
    assert x["terms"]["velocity_random_walk"]["present"]
    assert z["terms"]["rate_random_walk"]["present"]
    assert not x["terms"]["rate_random_walk"]["present"]


def test_table_csv_and_kalibr(lab_npz: Path) -> None:
    an = analyze(open_record(str(lab_npz)), AnalyzeOptions(channels=("z",)))
    assert list(an.channels) == ["z"]
    text = format_table(an)
    assert "velocity_random_walk (N)" in text and "m/s/sqrt(s)" in text
    assert "absent" in text and "2.5 Hz" in text and "χ²/dof" in text
    rows = adev_csv(an).strip().splitlines()
    assert rows[0].split(",") == ["channel", "tau_s", "adev_mps2", "adev_lo_mps2",
                                  "adev_hi_mps2", "edf", "model_adev_mps2", "used", "alpha",
                                  "estimator"]
    assert all(r.endswith(",oadev") for r in rows[1:])
    assert "fully overlapping ADEV (OADEV" in text
    assert len(rows) == 1 + len(an.channels["z"].allan.tau)
    first = rows[1].split(",")
    assert first[0] == "z" and float(first[1]) == pytest.approx(1 / RATE)
    yaml = {}
    for line in kalibr_yaml(an).splitlines():
        if line and not line.startswith("#"):
            key, _, val = line.partition(":")
            yaml[key.strip()] = val.split("#")[0].strip()
    fit = an.channels["z"].fit
    assert float(yaml["accelerometer_noise_density"]) == pytest.approx(
        fit.terms["velocity_random_walk"].value, rel=1e-6)
    assert float(yaml["accelerometer_random_walk"]) == pytest.approx(
        fit.terms["rate_random_walk"].value, rel=1e-6)
    assert float(yaml["update_rate"]) == RATE


def test_unknown_channel_and_short_record(tmp_path: Path, lab_npz: Path) -> None:
    with pytest.raises(DataError, match="channel 'q'"):
        analyze(open_record(str(lab_npz)), AnalyzeOptions(channels=("q",)))
    p = tmp_path / "short.npz"
    np.savez(p, accel=np.zeros((10, 3)), rate_hz=10.0)
    with pytest.raises(DataError, match="samples"):
        analyze(open_record(str(p)))


def test_progress_is_reported_per_block(lab_npz: Path) -> None:
    seen: list[tuple[int, int | None]] = []
    analyze(open_record(str(lab_npz)),
            AnalyzeOptions(block=20_000), progress=lambda d, t: seen.append((d, t)))
    assert seen[-1] == (1 << 17, 1 << 17) and len(seen) == math.ceil((1 << 17) / 20_000)


def test_plot_writes_a_figure(tmp_path: Path, lab_npz: Path) -> None:
    pytest.importorskip("matplotlib")
    from avard.core.plot import plot_analysis

    an = analyze(open_record(str(lab_npz)))
    out = plot_analysis(an, tmp_path / "f.png")
    data = out.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000


def test_real_imudata_analysis(imudata_dir: Path) -> None:
    an = analyze(open_record(str(imudata_dir / "adis16405_run2.npz")),
                 AnalyzeOptions(channels=("x",)))
    fit = an.channels["x"].fit
    n = fit.terms["velocity_random_walk"]
    assert n.present and 1e-3 < n.value < 1e-2  # ADIS16405: a few mm/s/√s
    assert fit.tau_min_s > 0.01  # its own filter bends the shortest τ: left out
    assert fit.chi2_dof > 1  # real data: the five terms are not the whole story


def test_recording_of_the_service_is_analysed_with_its_gap(tmp_path: Path) -> None:
    """An avard recording (header + raw count blocks + a gap record, as the service writes it)
    is read through the recording reader, split at the gap, and modelled with the ADXL355
    filter (ODR/4) because it is the chip's own data."""
    from avard.core.io import frames, recording
    from scipy import signal

    rng = np.random.default_rng(21)
    rate, scale, n_blk = 125.0, 3.83e-5, 2048
    b, a = signal.butter(2, 0.5)
    white = signal.lfilter(b, a, 2e-4 * np.sqrt(rate) * rng.standard_normal((40 * n_blk, 3)),
                           axis=0)
    counts = np.rint(white / scale).astype(np.int32)
    recs = [frames.header_record("run-1", rate_hz=rate, t_mono=0.0, t_real=1.7e9,
                                 scale_m_s2_per_count=scale)]
    i0, seq = 0, 1
    for k in range(40):
        if k == 20:  # 1000 samples lost to an overrun
            recs.append(frames.gap_record("run-1", seq, i0, 1000, 1.0, 1.0, "overrun"))
            i0 += 1000
            seq += 1
        recs.append(frames.raw_record("run-1", seq, i0, counts[k * n_blk:(k + 1) * n_blk],
                                      float(k), 1.7e9 + k))
        i0 += n_blk
        seq += 1
    seg = tmp_path / "rec" / "run-1_0000.avr"
    seg.parent.mkdir()
    seg.write_bytes(b"".join(recording.frame(frames.encode(r)) for r in recs))
    an = analyze(open_record(str(seg.parent)))
    assert an.info is not None and an.info.format is RecordFormat.RECORDING
    assert an.info.recording is not None and an.info.recording.n_segments == 2
    assert an.meta["filter_corner_hz"] == pytest.approx(rate / 4)
    assert an.n_samples == 40 * n_blk
    fit = an.channels["x"].fit
    assert fit.tau_min_s == pytest.approx(2 / rate)  # filter modelled: from two samples
    n = fit.terms["velocity_random_walk"]
    assert abs(n.value - 2e-4) < 4 * (n.hi - n.lo) / 2

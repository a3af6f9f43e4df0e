"""A line swept over more bins than the line finder's background window (issue 23, item 6:
one periodic disturbance, one finding, with its frequency range and an amplitude interval),
and the Allan variance of a sampled line that the fit models it with."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from avard.core.analysis.spectrum import (
    WelchAccumulator,
    _find_at,
    find_lines,
    line_components,
    line_groups,
    welch_nperseg,
)
from avard.core.model.terms import sinusoid_avar, swept_sinusoid_avar
from avard.daemon.cli import main

RATE, HOURS = 10.0, 4.0
F_A, F_B = 3.05, 3.15


def _swept(n: int, amplitude: float) -> np.ndarray:
    t = np.arange(n) / RATE
    return amplitude * np.sin(2 * math.pi * (F_A * t + (F_B - F_A) * t**2 / (2 * t[-1])))


def _spectrum(y: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    w = WelchAccumulator(1, RATE, welch_nperseg(len(y)))
    w.update(y[:, None])
    f, p = w.result()
    return f, p[:, 0], w.n_seg


def _oadev2(y: np.ndarray, m: int) -> float:
    """Brute-force overlapping AVAR of rate samples at τ = m samples."""
    c = np.concatenate([[0.0], np.cumsum(y)])
    yb = (c[m:] - c[:-m]) / m
    return 0.5 * float(np.mean((yb[m:] - yb[:-m]) ** 2))


def test_a_pump_swept_over_a_wide_band_is_one_drifting_finding_with_its_band() -> None:
    """A line swept linearly over 0.1 Hz in 4 h at 10 Hz spreads over ≈ 160 Welch bins, five
    times the fine search's ±32-bin window: inside it the window's median is as raised as
    the bin it tests, so the fine search sees nothing however strong the line is. The
    broad search finds one drifting disturbance over the band, its amplitude that of the
    band's whole power."""
    n = int(RATE * HOURS * 3600)
    rng = np.random.default_rng(11)
    y = 1.5e-4 * math.sqrt(RATE) * rng.standard_normal(n) + _swept(n, 1e-3)
    f, p, n_seg = _spectrum(y)
    assert _find_at(f, p, n_seg, 0.01, 32) == []   # the fine search alone is blind to it
    (g,) = line_groups(find_lines(f, p, n_seg))
    assert g.kind == "drifting" and g.band_hz is not None
    assert g.band_hz[0] == pytest.approx(F_A, abs=0.01)
    assert g.band_hz[1] == pytest.approx(F_B, abs=0.01)
    assert g.amplitude == pytest.approx(1e-3, rel=0.03)
    assert g.amplitude_lo < g.amplitude < g.amplitude_hi
    # the fit is given one component over the band with the band's amplitude
    (comp,) = line_components(find_lines(f, p, n_seg))
    assert comp["amplitude"] == pytest.approx(g.amplitude)
    assert (comp["sweep_lo_hz"], comp["sweep_hi_hz"]) == pytest.approx(g.band_hz)


def test_the_broad_search_adds_no_line_to_null_spectra() -> None:
    """White + flicker + random walk, half of them through a steep low-pass near rate/4: the
    broad search runs at a tenth of the fine search's false-line probability per rebinning,
    so 40 spectra should hold none (0.2 % each)."""
    rng = np.random.default_rng(5)
    n = int(RATE * 2 * 3600)
    fr = np.fft.rfftfreq(n, 1 / RATE)
    fr[0] = fr[1]
    broad = 0
    for r in range(40):
        y = 1.6e-4 * math.sqrt(RATE) * rng.standard_normal(n)
        y += 6e-5 * np.fft.irfft(np.fft.rfft(rng.standard_normal(n)) / np.sqrt(fr), n)
        y += 2e-6 / math.sqrt(RATE) * np.cumsum(rng.standard_normal(n))
        if r % 2:
            y = np.fft.irfft(np.fft.rfft(y) / np.sqrt(1 + (fr / 2.5) ** 8), n)
        broad += sum(ln.get("group", 0.0) >= 1000 for ln in find_lines(*_spectrum(y)))
    assert broad == 0


def test_a_sampled_lines_allan_variance_is_the_models() -> None:
    """A 3.1 Hz line sampled at 10 Hz: the mean of m samples has the gain
    sin(πfτ)/(m·sin(πf/rate)), not the continuous sin(πfτ)/(πfτ), which is 28 % low at
    every τ; and a line swept over a band is the mean of the steady ones it passes through."""
    n = 1 << 17
    t = np.arange(n) / RATE
    steady = 1e-3 * np.sin(2 * math.pi * 3.1 * t + 0.4)
    swept = _swept(n, 1e-3)
    for m in (1, 2, 3, 8, 13, 64):
        tau = m / RATE
        got = _oadev2(steady, m)
        assert sinusoid_avar([tau], 1e-3, 3.1, RATE)[0] == pytest.approx(got, rel=0.02)
        assert sinusoid_avar([tau], 1e-3, 3.1)[0] < 0.8 * got   # the continuous form
        assert swept_sinusoid_avar([tau], 1e-3, F_A, F_B, RATE)[0] == pytest.approx(
            _oadev2(swept, m), rel=0.05)


def test_analyze_models_a_swept_pump_instead_of_making_noise_terms_of_it(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A record from the adversary's generator (written apart from avard): a pump at about
    70× a steady line's minimum swept over 0.1 Hz. analyze used to find no line at all and
    make a quantization term of it (χ²/dof over 1000); it now reports one drifting
    disturbance with the generator's amplitude and band, and its fit passes."""
    from tests.support.adversary_gen import make_record

    rec = tmp_path / "pump.npz"
    truth = make_record("pump", 110, rec, None, 15.0)["axes"]["x"]
    assert main(["analyze", str(rec), "--channels", "x", "--json"]) == 0
    ch = json.loads(capsys.readouterr().out)["channels"]["x"]
    (s,) = ch["sinusoids"]
    assert s["amplitude"] == pytest.approx(truth["amplitude"], rel=0.05)
    assert truth["frequency_lo_hz"] < s["frequency_hz"] < truth["frequency_hi_hz"]
    assert ch["fit"]["chi2_dof"] < 3.0
    q = ch["terms"]["quantization"]
    assert not q["present"] or q["value"] < 1e-5


def test_a_spectrum_too_short_to_search_holds_no_line() -> None:
    """The broad search asks what the fine one does of its input: a spectrum of a few bins
    (or one segment) is no line, not an IndexError."""
    assert find_lines(np.array([0.0]), np.array([1.0]), 5) == []
    assert find_lines(np.linspace(0.0, 5.0, 300), np.ones(300), 1) == []


def test_a_swept_pump_and_its_swept_harmonic_are_one_disturbance_with_two_bands() -> None:
    """Two effects at once: a pump swept 1.05 → 1.15 Hz and its second harmonic (2.10 →
    2.30 Hz), each wider than the fine search's window. The coarse search marks the second
    as the first's harmonic; read as one band from 1.05 to 2.3 Hz (the two clusters taken
    together) the finding placed a disturbance where there is none."""
    n = int(RATE * HOURS * 3600)
    t = np.arange(n) / RATE
    rng = np.random.default_rng(12)
    y = (1.5e-4 * math.sqrt(RATE) * rng.standard_normal(n)
         + 1e-3 * np.sin(2 * math.pi * (1.05 * t + 0.10 * t**2 / (2 * t[-1])))
         + 4e-4 * np.sin(2 * math.pi * (2.10 * t + 0.20 * t**2 / (2 * t[-1]))))
    (g,) = line_groups(find_lines(*_spectrum(y)))
    assert g.harmonics == (1, 2) and g.band_hz is not None
    assert g.band_hz[0] == pytest.approx(1.05, abs=0.01)
    assert g.band_hz[1] == pytest.approx(1.15, abs=0.01)
    assert g.amplitude == pytest.approx(1e-3, rel=0.05)

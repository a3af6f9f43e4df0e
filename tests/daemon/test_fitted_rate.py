"""The fitted output rate everywhere: snapshots, recording headers and `avard analyze`.

The emulated ADXL355 runs off its nominal 125 Hz by +3000 and −2200 ppm (a real part's clock
is off by up to a few thousand ppm). τ labels, the recording's rate and the noise density
that `avard analyze` finds must follow the real rate (to 50 ppm), not the nominal one.
"""

from __future__ import annotations

import io
import json
from contextlib import redirect_stdout
from pathlib import Path

import numpy as np
import pytest
from avard.core.io.recording import RecordingReader, load_recording
from avard.daemon.cli import main
from avard.daemon.compose import simulated_service
from avard.daemon.config import load_config


def _analyze(path: Path, *extra: str) -> dict:
    buf = io.StringIO()
    with redirect_stdout(buf):
        assert main(["analyze", str(path), "--json", *extra]) == 0
    return json.loads(buf.getvalue())


def _n_coefficients(report: dict) -> list[float]:
    """The velocity random walk N (m/s/√s) of every axis in an analyze report."""
    return [float(ch["terms"]["velocity_random_walk"]["value"])
            for ch in report["channels"].values()
            if ch.get("terms", {}).get("velocity_random_walk", {}).get("value") is not None]


@pytest.mark.parametrize("ppm", [3000.0, -2200.0])
def test_tau_header_and_analysis_use_the_fitted_rate(tmp_path: Path, ppm: float) -> None:
    cfg = load_config(None, **{"recording.data_dir": str(tmp_path), "publish.enabled": False,
                               "allan.snapshot_interval_s": 20.0, "sensor.poll_hz": 1.0,
                               "recording.segment_s": 60.0})
    svc, _sims, emu = simulated_service(cfg, "quiet-lab", seed=3, odr_error_ppm=ppm)
    svc.run(200.0)
    true_rate = emu.true_odr_hz
    assert true_rate == pytest.approx(125.0 * (1 + ppm * 1e-6), rel=1e-12)

    def off_ppm(rate: float) -> float:
        return abs(rate / true_rate - 1.0) * 1e6

    recs = list(RecordingReader(tmp_path))
    avars = [r for r in recs if r["kind"] == "avar"]
    assert avars
    snap = avars[-1]["snapshot"]
    assert off_ppm(snap["rate_hz"]) < 50
    np.testing.assert_allclose(np.asarray(snap["tau"]) * true_rate, snap["m"], rtol=50e-6)
    headers = [r for r in recs if r["kind"] == "header"]
    # every segment starts with a header, and the newest carries the fitted rate
    assert len({r["i0"] for r in headers}) >= 3
    assert off_ppm(headers[-1]["rate_hz"]) < 50
    assert off_ppm(load_recording(tmp_path).rate_hz) < 50

    fitted = _n_coefficients(_analyze(tmp_path))
    truth = _n_coefficients(_analyze(tmp_path, "--rate", repr(true_rate)))
    nominal = _n_coefficients(_analyze(tmp_path, "--rate", "125.0"))
    assert len(fitted) == len(truth) == len(nominal) == 3
    np.testing.assert_allclose(fitted, truth, rtol=50e-6)
    # and the check can fail: with the nominal rate N is off by about ppm/2
    assert max(abs(a / b - 1) for a, b in zip(nominal, truth, strict=True)) > 300e-6

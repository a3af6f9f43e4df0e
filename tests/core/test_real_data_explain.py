"""`avard explain` on the real ADIS16405 runs (../shared/data/imudata, skipped when absent).

What is known about them (their README): output quantized at 0.0327 m/s², the sensor's own
filtering at the shortest τ; and what explain finds in them (docs/real-data.md): a periodic
disturbance near 0.56 Hz in every run that the five-term model reads as bias instability."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from avard.core.explain import explain


def _run(path, axis: int = 0) -> SimpleNamespace:
    with np.load(path, allow_pickle=False) as z:
        accel = np.asarray(z["accel"][:, axis : axis + 1], dtype=float)
        rate = float(z["rate_hz"])
        name = str(z["axes"][axis])
    return SimpleNamespace(accel=accel, rate_hz=rate, names=[name], temperature_c=None,
                           temperature_names=[], source=path.name)


@pytest.fixture(scope="module")
def run1_x_heldout_on_run2(imudata_dir):
    r1 = _run(imudata_dir / "adis16405_run1.npz")
    r2 = _run(imudata_dir / "adis16405_run2.npz")
    return explain(r1, holdout=r2).channels["x"]


def test_known_properties_are_found(run1_x_heldout_on_run2):
    ch = run1_x_heldout_on_run2
    found = {f["cause"]: f["params"] for f in ch.findings}
    assert found["quantization"]["lsb"] == pytest.approx(0.0327, rel=0.01)
    assert "filter" in found and 0 < found["filter"]["bandwidth_hz"] < 50.0


def test_the_line_near_0p56_hz_is_the_cause_and_holds_on_another_run(run1_x_heldout_on_run2):
    ch = run1_x_heldout_on_run2
    lines = [f["params"] for f in ch.findings if f["cause"] == "sinusoid"]
    assert any(0.55 < p["frequency_hz"] < 0.58 for p in lines)
    # the misfit of the five terms is large and the extension pays off on the other run
    assert ch.misfit and ch.base.chi2_dof > ch.extended.chi2_dof
    assert ch.gain > 1.5 and ch.holdout_gain > 1.5
    # the base fit had read the line's Allan bump as bias instability
    b_base = ch.base.terms()["bias_instability"]["value"]
    b_ext = ch.extended.terms()["bias_instability"]["value"]
    assert b_base > 1.5 * b_ext

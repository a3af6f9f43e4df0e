"""The Allan core on real static IMU data (ADIS16405, ../shared/data/imudata)."""

from __future__ import annotations

from pathlib import Path

import allantools
import numpy as np
from avard.core.allan.deviations import oavar, pavar
from avard.core.allan.streaming import StreamingAllan
from avard.core.analysis.options import AnalyzeOptions
from avard.core.io.source import open_record


def test_real_run_streaming_equals_batch_and_allantools(imudata_dir: Path) -> None:
    with np.load(imudata_dir / "adis16405_run1.npz") as f:
        y = np.column_stack([f["accel"], f["gyro"]])  # m/s² and rad/s, 100 Hz
        rate = float(f["rate_hz"])
    acc = StreamingAllan(6, rate, names=["ax", "ay", "az", "gx", "gy", "gz"])
    for blk in np.array_split(y, 333):  # ~3000-sample blocks: pending + direct paths
        acc.update(blk)
    got, ref = acc.result(), pavar(y, rate)
    np.testing.assert_array_equal(got.n, ref.n)
    np.testing.assert_allclose(got.var, ref.var, rtol=1e-12)
    # fully overlapping levels against allantools on the gravity axis
    _, dev, _, _ = allantools.oadev(y[:, 2], rate=rate, data_type="freq", taus="octave")
    z = oavar(y[:, 2], rate)
    np.testing.assert_allclose(z.dev[: dev.size], dev, rtol=1e-9)
    np.testing.assert_allclose(got.channel(2).var[:4], z.var[:4], rtol=1e-12)
    # every interval brackets its estimate, and the noise type is one of the power laws
    assert np.all(got.lo <= got.var) and np.all(got.var <= got.hi)
    assert set(np.unique(got.alpha)) <= {-2.0, -1.0, 0.0, 1.0, 2.0}


def test_cli_path_and_python_api_give_one_alpha_and_edf(imudata_dir: Path) -> None:
    """`avard analyze` (streamed OADEV) and `oavar` (batch) on a real record: the same noise
    type and EDF at every τ, the cascade the same α where its τ coincide (issue 12: the CLI
    and the API used to disagree, EDF 158 against 520 at one point)."""
    from avard.core.analysis.engine import analyze
    from avard.core.analysis.signal_edf import with_signal_edf

    path = imudata_dir / "adis16405_run1.npz"
    # the same samples on both paths: the input screen (which cuts two shocks from this run)
    # is analyze's, not the estimator's
    an = analyze(open_record(str(path)), AnalyzeOptions(find_sinusoids=False, screen=False))
    with np.load(path) as f:
        accel, rate = f["accel"], float(f["rate_hz"])
    cascade = StreamingAllan(3, rate)
    cascade.update(accel)
    casc = cascade.result()
    for j, ch in enumerate(an.channels.values()):
        api = oavar(accel[:, j], rate, ch.allan.tau)
        np.testing.assert_array_equal(api.alpha, ch.allan.alpha)
        # analyze prints the EDF its fit supports (analysis/signal_edf.py): the API's, given
        # the same fit, is the same
        np.testing.assert_allclose(with_signal_edf(api, ch.fit).edf, ch.allan.edf, rtol=1e-12)
        assert np.all(ch.allan.edf >= api.edf * (1 - 1e-12))
        k = min(len(casc.m), len(ch.allan.m))
        np.testing.assert_array_equal(casc.alpha[:k, j], ch.allan.alpha[:k])

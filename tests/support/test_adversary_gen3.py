"""The adversary generator 3's truth against direct computations on the records it writes."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from tests.support import adversary_gen3 as gen


def _load(p):
    d = np.load(p)
    return {k: d[k] for k in d.files}, json.loads(open(str(p) + ".truth.json").read())


def _means_1s(a: np.ndarray, rate: float) -> np.ndarray:
    k = int(rate)
    return a[: (a.size // k) * k].reshape(-1, k).mean(axis=1)


def _logged(rec, j: int, n1: int) -> np.ndarray:
    """The logged channel j on the 1 s grid, by linear interpolation between readings."""
    t = np.arange(rec["accel"].shape[0]) / float(rec["rate_hz"])
    col = rec["temperature_c"][:, j]
    ok = np.isfinite(col)
    return np.interp(np.arange(n1) + 0.5, t[ok], col[ok])


def test_remount_coupling_before_and_after_the_change_by_regression(tmp_path):
    p = tmp_path / "r.npz"
    gen.make_record("remount", 3, 4.0, p)
    rec, tr = _load(p)
    x = _means_1s(rec["accel"][:, 0], float(rec["rate_hz"]))
    u = gen.lag1(_logged(rec, 0, x.size), 1.0, tr["die_lag_s"])
    ts = int(tr["axes"]["x"]["change_s"])
    for sl, key in ((slice(600, ts - 300), "coefficient_before"),
                    (slice(ts + 300, x.size - 300), "coefficient_after")):
        a = np.column_stack([np.ones(x[sl].size), np.arange(x[sl].size), u[sl]])
        c = np.linalg.lstsq(a, x[sl], rcond=None)[0][2]
        want = tr["axes"]["x"][key]
        assert c == pytest.approx(want, rel=0.15), key
    # the change flips x's sign and keeps y's
    assert tr["axes"]["x"]["coefficient_after"] * tr["axes"]["x"]["coefficient_before"] < 0
    assert tr["axes"]["y"]["coefficient_after"] / tr["axes"]["y"]["coefficient_before"] >= 2.5


def test_the_signal_in_the_record_is_the_truths_and_z_carries_none(tmp_path):
    p = tmp_path / "c.npz"
    tr = gen.make_record("cubic", 4, 4.0, p)
    rec, _ = _load(p)
    rate = float(rec["rate_hz"])
    for j, ax in enumerate("xyz"):
        y = _means_1s(rec["accel"][:, j], rate)
        s = tr["_signals"]["x"][: y.size]               # x's shape, the regressor
        a = np.column_stack([np.ones(y.size), np.arange(y.size), s])
        slope = np.linalg.lstsq(a, y, rcond=None)[0][2]
        want = {"x": 1.0, "y": -0.8, "z": 0.0}[ax]
        assert slope == pytest.approx(want, abs=0.05), ax
    # cubic near the mean: the signal at a small anomaly is far below a linear one's
    w = tr["axes"]["x"]["width_k"]
    assert abs(np.tanh((0.2 * w / w) ** 3)) < 0.01


def test_flicker_plateau_is_the_stated_b():
    rng = np.random.default_rng(7)
    b, t_rec = 2e-5, 4 * 3600.0
    t = np.arange(0, t_rec, 1.0)
    avs = []
    for _ in range(6):
        taus, av = gen.avar_oct(gen.flicker_ou(rng, t, b, t_rec), 1.0)
        avs.append(av)
    m = np.mean(avs, axis=0)
    want = 2 * math.log(2) / math.pi * b * b
    sel = (taus >= 128) & (taus <= 1024)
    assert np.all(np.abs(m[sel] / want - 1) < 0.3), m[sel] / want


def test_null_faults_are_in_the_log_as_the_truth_says(tmp_path):
    p = tmp_path / "f.npz"
    gen.make_record("faults", 2, 4.0, p)
    rec, tr = _load(p)
    temp = rec["temperature_c"]
    assert int(np.sum(temp == 85.0)) == tr["n_85"]
    assert int(np.sum(temp == -127.0)) == tr["n_minus127"]
    rate = float(rec["rate_hz"])
    i0, i1 = (int(v * rate) for v in tr["dropout_s"])
    for name in tr["dropout_channels"]:
        j = ["plate", "ambient"].index(name)
        assert not np.isfinite(temp[i0:i1, j]).any()
        assert np.isfinite(temp[:i0, j]).any() or np.isfinite(temp[i1:, j]).any()


def test_clock_offset_and_stated_cadence(tmp_path):
    p = tmp_path / "k.npz"
    gen.make_record("clockoff", 5, 4.0, p)
    rec, tr = _load(p)
    rows = np.flatnonzero(np.isfinite(rec["temperature_c"][:, 0]))
    rate = float(rec["rate_hz"])
    # the readings' row spacing is the reading interval on the logger's clock
    spacing = np.median(np.diff(rows)) / rate
    drift = (rows[-1] - rows[0]) / rate / ((rows.size - 1) * tr["t_read_s"]) - 1
    assert spacing == pytest.approx(tr["t_read_s"], rel=0.05)
    assert drift * 1e6 == pytest.approx(tr["clock_ppm"], abs=60)
    q = tmp_path / "h.npz"
    gen.make_record("cadence", 5, 4.0, q)
    rec, tr = _load(q)
    assert float(rec["rate_hz"]) == pytest.approx(tr["stated_rate_hz"])
    assert abs(float(rec["rate_hz"]) / tr["rate_hz"] - 1) >= 0.01
    col = rec["temperature_c"][:, 0]
    first = np.flatnonzero(np.isfinite(col))[0]
    assert np.isfinite(col[first:]).all()                 # held: a value on every row
    changes = np.flatnonzero(np.diff(col[first:]) != 0)
    # no change comes sooner than the reading interval (readings are held between)
    assert np.min(np.diff(changes)) >= int(tr["t_read_s"] * tr["rate_hz"]) - 1


@pytest.mark.parametrize("seed,mode", [(2, "spliced"), (3, "held")])
def test_acceleration_gap(tmp_path, seed, mode):
    p = tmp_path / "g.npz"
    gen.make_record("accgap", seed, 4.0, p)
    rec, tr = _load(p)
    rate = float(rec["rate_hz"])
    n_full = round(4 * 3600 * rate)
    assert tr["gap"]["mode"] == mode
    if mode == "spliced":
        assert rec["accel"].shape[0] == n_full - int(180 * rate)
    else:
        i0 = round(tr["gap"]["at_s"] * rate)
        seg = rec["accel"][i0 - 1: i0 + int(180 * rate)]
        assert np.all(seg == seg[0])


def test_oracle_says_no_candidate_describes_a_remount(tmp_path):
    tr = gen.make_record("remount", 6, 4.0, tmp_path / "o.npz")
    assert tr["axes"]["x"]["oracle"]["resid_over_noise_max"] > 10

"""`avard analyze --stat … --dynamic` end to end: the statistics asked for, in the table, the
JSON, the csv and the plots; the fit's own OADEV reused for "oadev"; bad options one line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from avard.core.allan.longtau import statistic
from avard.daemon.cli import main


@pytest.fixture(scope="module")
def npz(tmp_path_factory: pytest.TempPathFactory) -> Path:
    rng = np.random.default_rng(4)
    n = 40_000
    accel = 1e-3 * rng.standard_normal((n, 2))
    accel[n // 2:, 1] *= 2.0  # ch1's white level doubles mid-run
    p = tmp_path_factory.mktemp("stat") / "rec.npz"
    np.savez(p, accel=accel, rate_hz=50.0)
    return p


def test_json_has_the_statistics_asked_and_the_dynamic_map(
        npz: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["analyze", str(npz), "--json", "--stat", "oadev,totdev,theoh",
                 "--dynamic", "--window", "100"]) == 0
    d = json.loads(capsys.readouterr().out)
    st = d["statistics"]
    assert st["averaging"] == {"linear": 1, "quadratic": 10}
    for ch in ("ch0", "ch1"):
        got = st["channels"][ch]["statistics"]
        assert list(got) == ["oadev", "totdev", "theoh"]
        # "oadev" is the analysis's own (the fit's) OADEV, not another computation
        assert got["oadev"]["dev"] == d["channels"][ch]["adev"]
        assert got["totdev"]["unit"] == "m/s²" and got["theoh"]["stride"][0] == 10
    accel = np.load(npz)["accel"]
    want = statistic("totdev", accel[:, 0], 50.0, "octave")
    assert st["channels"]["ch0"]["statistics"]["totdev"]["dev"] == pytest.approx(
        want.dev.tolist(), rel=1e-12)
    dyn_x = st["channels"]["ch0"]["dynamic_adev"]
    dyn_y = st["channels"]["ch1"]["dynamic_adev"]
    assert dyn_y["changes"][0] is True and dyn_x["changes"][0] is False
    assert dyn_y["window_s"] == 100.0 and max(dyn_y["tau"]) <= 25.0


def test_table_csv_and_plots(npz: Path, tmp_path: Path,
                             capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("matplotlib")
    csv, png = tmp_path / "stats.csv", tmp_path / "a.png"
    assert main(["analyze", str(npz), "--stat", "mdev,tdev", "--dynamic", "--window", "100",
                 "--step", "100",
                 "--export", "stats", str(csv), "--plot", str(png)]) == 0
    out = capsys.readouterr().out
    assert "channel ch0: mdev (modified Allan deviation)" in out
    assert "channel ch1: dynamic ADEV" in out and "(changes)" in out
    rows = csv.read_text().splitlines()
    assert rows[0] == "channel,statistic,tau_s,dev,dev_lo,dev_hi,edf,alpha,averaging,unit"
    assert any(r.startswith("ch0,tdev,") and r.endswith(",m/s") for r in rows)
    assert (tmp_path / "a_stats.png").stat().st_size > 10_000
    assert (tmp_path / "a_dynamic.png").stat().st_size > 10_000


@pytest.mark.parametrize(("argv", "message"), [
    (["--stat", "oadev,allen"], "statistic 'allen' is unknown"),
    (["--window", "10"], "add --dynamic"),
    (["--dynamic", "--window", "-1"], "positive number of seconds"),
    (["--export", "stats", "s.csv"], "needs --stat"),
    (["--dynamic", "--window", "1e6"], "longer than the record"),
])
def test_bad_options_are_one_line_and_exit_2(npz: Path, argv: list[str], message: str,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["analyze", str(npz), *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_dynamic_bins_by_the_logged_temperature(
        tmp_path: Path, npz: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--dynamic on a record that logs temperature (one DS18B20 read a second, NaN between,
    as avard simulate writes it): the ADEV by temperature, held at each reading. The white
    level doubles above 21 °C on a ±1 °C cycle, so the bins disagree at τ0 and the warmest
    is about twice the coolest; a record without temperatures says why there is none."""
    rate, n = 50.0, 120_000
    t = np.arange(n) / rate
    temp = 21.0 + np.sin(2 * np.pi * t / 600.0)
    rng = np.random.default_rng(8)
    accel = 1e-3 * rng.standard_normal((n, 1)) * np.where(temp > 21.0, 2.0, 1.0)[:, None]
    logged = np.full((n, 1), np.nan)
    logged[:: int(rate)] = temp[:: int(rate), None]
    p = tmp_path / "temp.npz"
    np.savez(p, accel=accel, rate_hz=rate, temperature_c=logged,
             temperature_names=np.array(["plate"]))
    assert main(["analyze", str(p), "--json", "--dynamic"]) == 0
    by_t = json.loads(capsys.readouterr().out)["statistics"]["channels"]["ch0"][
        "adev_by_temperature"]
    assert by_t["changes"][0] and by_t["p_value"][0] < 1e-6
    dev = np.array(by_t["dev"])
    assert 1.8 < dev[-1, 0] / dev[0, 0] < 2.2
    assert main(["analyze", str(npz), "--json", "--dynamic", "--window", "100"]) == 0
    none = json.loads(capsys.readouterr().out)["statistics"]["channels"]["ch0"]
    assert none["adev_by_temperature"] == {"note": "the record logs no temperature"}

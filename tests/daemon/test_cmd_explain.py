"""`avard explain` end to end through the CLI dispatcher: summary, --json shape, --report
files, --holdout, and user errors as one line with exit status 2."""

from __future__ import annotations

import json

import numpy as np
import pytest
from avard.core import effects
from avard.daemon import cli

N = 1 << 17


def _save(path, rec):
    np.savez(path, accel=rec.accel, rate_hz=rec.rate_hz, axes=np.array(rec.names),
             temperature_c=rec.temperature_c,
             temperature_names=np.array(rec.temperature_names))
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("explain")
    rec, truth = effects.make_case(21, "sinusoid", n=2 * N)
    a = _save(d / "a.npz", effects.HiddenRecord(rec.accel[:N], rec.rate_hz, rec.names,
                                                  rec.temperature_c[:N],
                                                  rec.temperature_names))
    b = _save(d / "b.npz", effects.HiddenRecord(rec.accel[N:], rec.rate_hz, rec.names,
                                                  rec.temperature_c[N:],
                                                  rec.temperature_names))
    return a, b, truth


def test_json_output(files, capsys):
    a, _, truth = files
    assert cli.main(["explain", str(a), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    ch = out["channels"]["x"]
    assert [f["cause"] for f in ch["findings"]] == ["sinusoid"]
    f0 = ch["findings"][0]["params"]["frequency_hz"]
    assert f0 == pytest.approx(truth.params["frequency_hz"], rel=0.02)
    assert ch["gain"] > 1 and ch["holdout_gain"] > 1
    assert ch["extended"]["extra"][0]["cause"] == "sinusoid"


def test_summary_report_and_holdout(files, tmp_path, capsys):
    a, b, _ = files
    rep = tmp_path / "rep"
    assert cli.main(["explain", str(a), "--holdout", str(b), "--report", str(rep)]) == 0
    text = capsys.readouterr().out
    assert "FOUND sinusoid" in text and "held out" in text and "m/s" in text
    md = (rep / "report.md").read_text()
    assert "## Channel x" in md and "sinusoid" in md and "Evidence per cause" in md
    for png in ("adev_x.png", "misfit_x.png", "temperature_adev.png"):
        assert (rep / png).stat().st_size > 1000


def test_user_errors_exit_2(tmp_path, capsys):
    assert cli.main(["explain", str(tmp_path / "missing.npz")]) == 2
    assert "does not exist" in capsys.readouterr().err
    np.savez(tmp_path / "norate.npz", accel=np.zeros((5000, 1)))
    assert cli.main(["explain", str(tmp_path / "norate.npz")]) == 2
    assert "--rate" in capsys.readouterr().err
    assert cli.main(["explain", str(tmp_path / "norate.npz"), "--rate", "50"]) == 2
    assert "constant" in capsys.readouterr().err  # readable now, but there is no noise
    np.savez(tmp_path / "short.npz", accel=np.zeros((100, 1)), rate_hz=50.0)
    assert cli.main(["explain", str(tmp_path / "short.npz")]) == 2
    assert "too few" in capsys.readouterr().err


def test_finds_the_simulators_own_filter(tmp_path, capsys):
    """Across modules: a record from `avard simulate` (quiet-lab: the ADXL355 low-pass at
    ODR/4) must come back with the filter named at its corner, and nothing claimed that the
    preset does not put in the record."""
    out = tmp_path / "ql.npz"
    assert cli.main(["simulate", "--preset", "quiet-lab", "--hours", "0.5", "--seed", "3",
                     "--out", str(out)]) == 0
    capsys.readouterr()
    with np.load(out, allow_pickle=False) as z:
        cfg = json.loads(str(z["sim_config"]))
        rate = float(z["rate_hz"])
    assert cli.main(["explain", str(out), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)["channels"]
    in_preset = {"filter", "temperature", "warmup"}
    if any(s > 0 for s in cfg.get("gm_sigma_mps2", [0.0])):
        in_preset.add("gauss_markov")
    for axis, ch in res.items():
        found = {f["cause"]: f["params"] for f in ch["findings"]}
        assert set(found) <= in_preset, (axis, found)
        assert found["filter"]["bandwidth_hz"] == pytest.approx(rate / 4, rel=0.3)

"""`avard simulate`: writes a readable .npz; wrong parameters end with a clear message."""

from __future__ import annotations

import json

import numpy as np
from avard.daemon.cli import main


def test_simulate_writes_npz(tmp_path, capsys) -> None:
    out = tmp_path / "t3.npz"
    rc = main(["simulate", "--preset", "paper-table3", "--hours", "0.01", "--seed", "3",
               "--out", str(out), "--set", "bias_instability=1e-5,2e-5,3e-5",
               "--set", "sinusoids=[[2, 1e-4, 0.5]]"])
    assert rc == 0
    assert "m/s²" in capsys.readouterr().out
    with np.load(out, allow_pickle=False) as d:
        assert d["accel"].shape == (4500, 3)
        assert float(d["rate_hz"]) == 125.0
        cfg = json.loads(str(d["sim_config"]))
        assert cfg["bias_instability"] == [1e-5, 2e-5, 3e-5]
        assert cfg["sinusoids"] == [[2.0, 1e-4, 0.5, 0.0]]
        assert int(d["seed"]) == 3


def test_same_seed_same_file(tmp_path) -> None:
    args = ["simulate", "--preset", "quiet-lab", "--hours", "0.005", "--seed", "8"]
    assert main([*args, "--out", str(tmp_path / "a.npz")]) == 0
    assert main([*args, "--out", str(tmp_path / "b.npz")]) == 0
    with np.load(tmp_path / "a.npz") as a, np.load(tmp_path / "b.npz") as b:
        assert np.array_equal(a["accel"], b["accel"])


def test_unknown_key_names_the_valid_ones(tmp_path, capsys) -> None:
    rc = main(["simulate", "--hours", "0.01", "--out", str(tmp_path / "x.npz"),
               "--set", "noise_density=1e-4"])
    assert rc == 2
    err = capsys.readouterr().err
    assert "noise_density" in err and "velocity_random_walk" in err and "valid keys" in err
    assert not (tmp_path / "x.npz").exists()


def test_bad_value_and_missing_out(tmp_path, capsys) -> None:
    assert main(["simulate", "--out", str(tmp_path / "x.npz"), "--set", "odr_hz=100"]) == 2
    assert "not an ADXL355 output data rate" in capsys.readouterr().err
    assert main(["simulate", "--hours", "1"]) == 2
    assert "--out" in capsys.readouterr().err
    assert main(["simulate", "--hours", "-1", "--out", str(tmp_path / "x.npz")]) == 2


def test_list_shows_parameters(capsys) -> None:
    assert main(["simulate", "--preset", "adxl355-datasheet", "--list",
                 "--set", "range_g=4"]) == 0
    out = capsys.readouterr().out
    assert "velocity_random_walk" in out and "range_g = 4" in out and "m/s²" in out

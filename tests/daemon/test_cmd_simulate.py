"""`avard simulate`: writes a readable .npz; wrong parameters end with a clear message."""

from __future__ import annotations

import json

import numpy as np
import pytest
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


def test_an_unseeded_record_stores_the_seed_it_drew_and_that_seed_remakes_it(
        tmp_path, capsys) -> None:
    import re

    assert main(["simulate", "--hours", "0.003", "--out", str(tmp_path / "a.npz")]) == 0
    printed = re.search(r"seed (\d+)\)", capsys.readouterr().out)
    assert printed is not None
    with np.load(tmp_path / "a.npz") as a:
        seed = int(a["seed"])
        accel = a["accel"]
    assert seed == int(printed.group(1)) and seed >= 0
    assert main(["simulate", "--hours", "0.003", "--seed", str(seed),
                 "--out", str(tmp_path / "b.npz")]) == 0
    with np.load(tmp_path / "b.npz") as b:
        assert np.array_equal(b["accel"], accel)


def test_a_record_larger_than_the_free_space_is_refused_with_the_numbers(
        tmp_path, capsys) -> None:
    import shutil

    from avard.core.sim.presets import make_config
    from avard.core.sim.sim_io import npz_size

    free = shutil.disk_usage(tmp_path).free
    cfg = make_config("quiet-lab")
    # twice the hours that would fill the disk
    hours = 2 * free / (npz_size(cfg, 1.0).peak_bytes)
    rc = main(["simulate", "--hours", f"{hours:.6g}", "--out", str(tmp_path / "big.npz")])
    err = capsys.readouterr().err
    assert rc == 2
    assert "free" in err and "while writing" in err and "fewer --hours" in err
    assert list(tmp_path.iterdir()) == []  # nothing started


def test_the_size_estimate_is_what_is_written(tmp_path) -> None:
    from avard.core.sim.presets import make_config
    from avard.core.sim.sim_io import npz_size

    assert main(["simulate", "--hours", "0.02", "--seed", "2",
                 "--out", str(tmp_path / "a.npz")]) == 0
    size = npz_size(make_config("quiet-lab"), 0.02)
    written = (tmp_path / "a.npz").stat().st_size
    assert written <= size.final_bytes < written + (1 << 16)


def _signal_leaves_no_temporary_files(tmp_path, signum: int) -> None:
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "long.npz"
    p = subprocess.Popen([sys.executable, "-m", "avard.daemon.cli", "simulate", "--hours",
                          "60", "--seed", "1", "--out", str(out)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:  # until the writer has begun filling its .part
            parts = list(tmp_path.glob(".long.npz.*.part"))
            if parts and parts[0].stat().st_size > (1 << 20):
                break
            time.sleep(0.05)
        else:
            raise AssertionError("simulate did not start writing within 60 s")
        p.send_signal(signum)
        _, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 128 + signum, err
    assert "Traceback" not in err
    assert f"stopped by {signal.Signals(signum).name}" in err
    assert list(tmp_path.iterdir()) == []


def test_sigterm_removes_the_temporary_files(tmp_path) -> None:
    import signal

    _signal_leaves_no_temporary_files(tmp_path, signal.SIGTERM)


def test_sighup_removes_the_temporary_files(tmp_path) -> None:
    import signal

    _signal_leaves_no_temporary_files(tmp_path, signal.SIGHUP)


@pytest.mark.parametrize(("hours", "message"), [
    ("1e308", "not a record that can be written"), ("1e-12", "less than one sample"),
    ("inf", "positive number"), ("nan", "positive number"), ("-1", "positive number"),
])
def test_impossible_lengths_are_one_line(tmp_path, capsys, hours: str, message: str) -> None:
    assert main(["simulate", "--hours", hours, "--out", str(tmp_path / "x.npz")]) == 2
    assert message in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("axes", ["0", "-2", "x,x,z"])
def test_axes_that_are_not_three_names_are_refused_in_one_line(tmp_path, capsys,
                                                               axes: str) -> None:
    """``--set axes=0`` (a number once parsed) ended in a TypeError traceback; ``x,x,z``
    made a file whose second axis went unreported by every reader of it."""
    out = tmp_path / "x.npz"
    assert main(["simulate", "--hours", "0.001", "--seed", "1", "--out", str(out),
                 "--set", f"axes={axes}"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "axes" in err and "x,y,z" in err, err
    assert not out.exists()

"""`avard analyze` end to end through the CLI dispatcher: outputs, exports, and failures that
exit non-zero with a message naming the problem."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from avard.daemon.cli import main


@pytest.fixture(scope="module")
def npz(tmp_path_factory: pytest.TempPathFactory) -> Path:
    rng = np.random.default_rng(8)
    n = 1 << 16
    accel = 1e-3 * rng.standard_normal((n, 3)) + np.cumsum(
        3e-6 * rng.standard_normal((n, 3)), axis=0)
    p = tmp_path_factory.mktemp("cli") / "rec.npz"
    np.savez(p, accel=accel, rate_hz=100.0)
    return p


def test_table_goes_to_stdout(npz: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["analyze", str(npz)]) == 0
    out, err = capsys.readouterr()
    for ch in ("channel x", "channel y", "channel z"):
        assert ch in out
    assert "velocity_random_walk (N)" in out and "absent" in out and "fitted τ" in out
    assert "\r" not in err  # no progress when stderr is not a terminal


def test_json_exports_and_plot(npz: Path, tmp_path: Path,
                               capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("matplotlib")
    y, c, png = tmp_path / "imu.yaml", tmp_path / "adev.csv", tmp_path / "adev.png"
    rc = main(["analyze", str(npz), "--json", "--channels", "x", "z", "--export", "kalibr",
               str(y), "--export", "csv", str(c), "--plot", str(png)])
    assert rc == 0
    d = json.loads(capsys.readouterr().out)
    assert list(d["channels"]) == ["x", "z"] and d["rate_hz"] == 100.0
    n = d["channels"]["x"]["terms"]["velocity_random_walk"]
    assert n["present"] and n["lo"] <= 1e-3 / np.sqrt(100.0) <= n["hi"] * 1.01
    assert "accelerometer_noise_density:" in y.read_text()
    assert c.read_text().startswith("channel,tau_s,adev_mps2")
    assert png.stat().st_size > 10_000


@pytest.mark.parametrize(("args", "message"), [
    (["/nonexistent/x.npz"], "no such file"),
    (["{bad}"], "not a complete .npz"),
    (["{nokey}"], "no 'accel'"),
    (["{npz}", "--rate", "-3"], "positive"),
    (["{npz}", "--channels", "w"], "channel 'w'"),
    (["{npz}", "--export", "yaml", "out.yaml"], "unknown format"),
    (["{csv}"], "--rate"),
    (["{npz}", "--workers", "0"], "--workers 0"),
    (["{npz}", "--workers", "two"], "whole number"),
])
def test_failures_exit_nonzero_with_a_message(npz: Path, tmp_path: Path, args: list[str],
                                              message: str,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"garbage")
    nokey = tmp_path / "nokey.npz"
    np.savez(nokey, acceleration=np.zeros((10, 3)), rate_hz=1.0)
    csv = tmp_path / "r.csv"
    csv.write_text("x,y\n1,2\n3,4\n")
    argv = [a.format(npz=npz, bad=bad, nokey=nokey, csv=csv) for a in args]
    rc = main(["analyze", *argv])
    err = capsys.readouterr().err
    assert rc != 0
    assert message in err and "error" in err


def test_real_imudata_through_the_console_script(imudata_dir: Path) -> None:
    exe = Path(sys.executable).with_name("avard")
    r = subprocess.run([str(exe), "analyze", str(imudata_dir / "adis16405_run3.npz"),
                        "--json"], capture_output=True, text=True, timeout=300, check=False)
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["n_samples"] == 1_000_000 and set(d["channels"]) == {"x", "y", "z"}
    for ch in d["channels"].values():
        assert ch["terms"]["velocity_random_walk"]["present"]
        assert ch["fit"]["tau_min_s"] < ch["fit"]["tau_max_s"]


def test_cli_holds_blas_to_one_thread_before_numpy_loads() -> None:
    """The `avard` process sets one BLAS thread before numpy is first imported (a user's own
    setting wins)."""
    code = ("import os, sys; import avard.daemon.cli; "
            "print('numpy' in sys.modules, os.environ['OPENBLAS_NUM_THREADS'], "
            "os.environ['OMP_NUM_THREADS'])")
    env = {k: v for k, v in os.environ.items()
           if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, check=True).stdout.split()
    assert out == ["False", "1", "1"]
    env["OMP_NUM_THREADS"] = "3"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, check=True).stdout.split()
    assert out == ["False", "1", "3"]


def test_psd_flag_plot_and_export(npz: Path, tmp_path: Path,
                                  capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("matplotlib")
    fig, spec = tmp_path / "a.png", tmp_path / "psd.csv"
    assert main(["analyze", str(npz), "--psd", "--plot", str(fig), "--export", "psd",
                 str(spec)]) == 0
    out, _ = capsys.readouterr()
    assert "PSD white density" in out
    assert fig.exists() and (tmp_path / "a_psd.png").exists()
    assert spec.read_text().startswith("channel,f_hz,psd_m2ps4_per_hz")
    assert main(["analyze", str(npz), "--export", "psd", str(spec)]) == 2
    assert "--export psd needs --psd" in capsys.readouterr().err


def test_cascade_estimator_is_named(npz: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["analyze", str(npz), "--json", "--estimator", "cascade"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["estimator"] == "cascade"
    assert all(ch["estimator"] == "cascade" for ch in d["channels"].values())


def test_workers_give_the_one_worker_json(npz: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--workers 2 cuts the record by time and adds the chunks up exactly: the JSON is one
    worker's, to the rounding of the sums."""
    assert main(["analyze", str(npz), "--json", "--workers", "1"]) == 0
    one = json.loads(capsys.readouterr().out)
    assert main(["analyze", str(npz), "--json", "--workers", "2"]) == 0
    two = json.loads(capsys.readouterr().out)
    for name, ch in one["channels"].items():
        other = two["channels"][name]
        np.testing.assert_allclose(other["adev"], ch["adev"], rtol=1e-12)
        assert other["alpha"] == ch["alpha"]
        np.testing.assert_allclose(other["edf"], ch["edf"], rtol=1e-12)
        for term, t in ch["terms"].items():
            assert other["terms"][term]["present"] == t["present"]

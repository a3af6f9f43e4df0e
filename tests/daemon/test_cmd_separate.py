"""`avard separate`: the table, --json, --plot, and bad input as one line with status 2."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from avard.daemon import cli

RATE = 20.0
N = 1 << 14


def _write(tmp: Path, names: tuple[str, ...] = ("a", "b", "c"),
           own: tuple[float, ...] = (3e-3, 1e-3, 2e-3), common: float = 3e-4) -> list[str]:
    rng = np.random.default_rng(5)
    bed = rng.normal(0, common, (N, 2))
    paths = []
    for name, s in zip(names, own, strict=False):
        p = tmp / f"{name}.npz"
        np.savez(p, accel=bed + rng.normal(0, s, (N, 2)), rate_hz=RATE,
                 axes=np.array(["x", "z"]))
        paths.append(str(p))
    return paths


def test_three_records_give_the_table_and_the_verdict(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture) -> None:
    paths = _write(tmp_path)
    assert cli.main(["separate", *paths, "--channels", "z"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("three-cornered hat: 3 sensors (a, b, c), 16384 samples at 20 Hz")
    assert "aligned by index" in out and "axis z" in out and "axis x" not in out
    # the bed at a tenth of the quietest sensor: below every sensor's noise at short τ
    assert "a: the common input is below its own noise at τ = 0.05–" in out
    assert "(ADEV at least ×" in out
    assert "b: self-noise fit: velocity_random_walk" in out


def test_json_is_finite_si_and_matches_the_truth(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture) -> None:
    paths = _write(tmp_path, names=("a", "b"))
    assert cli.main(["separate", *paths, "--json", "--names", "left", "right"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["method"] == "groslambert covariance" and d["units"]["adev"] == "m/s^2"
    z = d["axes"]["z"]
    # white own noise: ADEV at τ0 = σ (to ~1 % with 16384 samples; coverage of the interval
    # is the slow test's), with an interval of that size around it
    for name, sigma in (("left", 3e-3), ("right", 1e-3)):
        sn = z["sensors"][name]["self_noise"]
        assert sn["adev"][0] == pytest.approx(sigma, rel=0.04)
        assert sn["adev_lo"][0] < sn["adev"][0] < sn["adev_hi"][0] < 1.05 * sn["adev_lo"][0]
        n_fit = z["sensors"][name]["fit"]["terms"]["velocity_random_walk"]["value"]
        assert n_fit == pytest.approx(sigma / np.sqrt(RATE), rel=0.05)


def test_plot_writes_one_figure(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    paths = _write(tmp_path, names=("a", "b"))
    out = tmp_path / "sep.png"
    assert cli.main(["separate", *paths, "--plot", str(out)]) == 0
    assert out.stat().st_size > 10_000


@pytest.mark.parametrize(("extra", "message"), [
    ((), "2 or 3 records"),
    (("--names", "one"), "--names: 1 names for 2 records"),
    (("--rate", "-3"), "--rate"),
    (("--channels", "q"), "--channels q"),
])
def test_bad_input_is_one_line_and_status_2(tmp_path: Path, capsys: pytest.CaptureFixture,
                                            extra: tuple[str, ...], message: str) -> None:
    paths = _write(tmp_path, names=("a", "b"))
    args = [paths[0]] if not extra else [*paths, *extra]
    assert cli.main(["separate", *args]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("how", ["same path", "another spelling", "a copy"])
def test_one_record_given_twice_is_refused_in_one_line(tmp_path: Path, capsys, how: str) -> None:
    """Separated from itself, a record gave a self-noise of exactly 0 and its own noise as the
    'common input', with exit status 0."""
    a = _write(tmp_path, ("a",))[0]
    b = {"same path": a, "another spelling": str(Path(a).parent / "." / Path(a).name),
         "a copy": str(tmp_path / "copy.npz")}[how]
    if how == "a copy":
        Path(b).write_bytes(Path(a).read_bytes())
    assert cli.main(["separate", a, b]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "different sensors" in err, err

"""Every number `avard analyze` writes says its unit and which estimator made it: the JSON's
per-τ arrays carry a unit map, the figure's legend names the estimator, the text table says
where the ADEV values are (issue 12, review finding F)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from avard.core.analysis.engine import analyze
from avard.core.analysis.formats import format_table
from avard.core.analysis.options import AnalyzeOptions
from avard.core.analysis.results import ADEV_UNITS
from avard.core.io.source import open_record
from avard.core.sim.presets import make_config
from avard.core.sim.sim_io import write_npz
from avard.daemon.cli import main


@pytest.fixture(scope="module")
def record(tmp_path_factory: pytest.TempPathFactory) -> Path:
    rng = np.random.default_rng(4)
    p = tmp_path_factory.mktemp("units") / "w.npz"
    np.savez(p, accel=rng.normal(scale=1e-3, size=(1 << 14, 2)), rate_hz=100.0)
    return p


@pytest.mark.parametrize("estimator", ["oadev", "cascade"])
def test_every_per_tau_array_in_the_json_has_an_si_unit(record: Path, estimator: str) -> None:
    an = analyze(open_record(str(record)), AnalyzeOptions(estimator=estimator))
    for ch in an.to_dict()["channels"].values():
        n_tau = len(ch["tau_s"])
        arrays = {k for k, v in ch.items() if isinstance(v, list) and len(v) == n_tau}
        assert arrays and arrays <= set(ch["units"]), arrays - set(ch["units"])
        assert ch["units"]["adev"] == ch["units"]["adev_lo"] == ch["units"]["adev_hi"] == "m/s^2"
        assert ch["units"]["tau_s"] == "s" and ch["estimator"] == estimator
    assert ADEV_UNITS["edf"] == ADEV_UNITS["alpha"] == "1"


def test_the_table_says_where_the_adev_values_are(record: Path) -> None:
    text = format_table(analyze(open_record(str(record))))
    assert "fully overlapping ADEV (OADEV" in text
    assert "--json or --export csv" in text and "m/s²" in text


@pytest.mark.parametrize(("estimator", "name"), [("oadev", "measured OADEV"),
                                                 ("cascade", "measured cascade ADEV")])
def test_the_figure_legend_names_the_estimator(record: Path, estimator: str,
                                               name: str) -> None:
    pytest.importorskip("matplotlib")
    from avard.core.plot import _panel, pyplot

    an = analyze(open_record(str(record)), AnalyzeOptions(estimator=estimator))
    fig, ax = pyplot().subplots()
    try:
        _panel(ax, next(iter(an.channels.values())))
        labels = ax.get_legend_handles_labels()[1]
    finally:
        pyplot().close(fig)
    measured = [lab for lab in labels if lab.startswith("measured")]
    assert measured and all(lab.startswith(name) for lab in measured), labels


def test_compensated_adev_in_the_json_has_its_unit(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    p = tmp_path / "t.npz"
    write_npz(p, make_config("paper-table3"), 0.1, seed=2)  # 0.05 h is too short to fit
    assert main(["analyze", str(p), "--temperature", "plate", "--json", "--channels", "z"]) == 0
    comp = json.loads(capsys.readouterr().out)["channels"]["z"]["temperature_compensation"]
    assert len(comp["compensated_adev"]) > 3 and comp["units"] == {"compensated_adev": "m/s^2"}

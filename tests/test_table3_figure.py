"""The figure of docs/table3.md (docs/scripts/table3_note.py): every ADEV set carries its
interval bars, and the legend says the estimator, the interval level and both record lengths.
Read from the matplotlib objects, not the pixels."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from avard.core.sim.presets import TABLE3_K_PRINTED, make_config

from tests.support.table3 import analyse_record

pytest.importorskip("matplotlib")

SCRIPT = Path(__file__).resolve().parents[1] / "docs" / "scripts" / "table3_note.py"
# short records (seconds to analyse): the figure does not depend on the length beyond its
# labels, so two lengths that differ are all the test needs
HOURS, LITERAL_HOURS = 0.1, 0.02


def _script():
    spec = importlib.util.spec_from_file_location("table3_note", SCRIPT)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def figure():
    import matplotlib.pyplot as plt

    analyses = analyse_record(make_config("paper-table3"), HOURS, 1, find_sinusoids=False)
    literal = analyse_record(make_config("paper-table3", rate_random_walk=TABLE3_K_PRINTED),
                             LITERAL_HOURS, 1, find_sinusoids=False)
    fig = _script().adev_figure(analyses, literal, HOURS, LITERAL_HOURS, seed=1)
    yield fig, analyses, literal
    plt.close(fig)


def test_legend_names_interval_level_estimator_and_both_lengths(figure) -> None:
    fig, analyses, _ = figure
    assert len(fig.legends) == 1
    texts = [t.get_text() for t in fig.legends[0].get_texts()]
    data = [t for t in texts if "interval" in t]
    assert len(data) == 2, texts
    level = f"{100 * analyses[0].result.ci:.0f} %"
    assert level == "68 %"
    for t in data:
        assert level in t and "overlapping ADEV" in t, t
    assert data[0].startswith(f"{HOURS:g} h record"), data
    assert data[1].startswith(f"{LITERAL_HOURS:g} h record"), data
    assert fig.get_suptitle()


def test_every_adev_set_has_its_interval_bars_and_the_sets_differ(figure) -> None:
    from matplotlib.container import ErrorbarContainer

    fig, analyses, literal = figure
    assert len(fig.axes) == 3
    for a, ax in enumerate(fig.axes):
        sets = [c for c in ax.containers if isinstance(c, ErrorbarContainer)]
        assert len(sets) == 2, ax.get_title()
        styles = set()
        for c, an in zip(sets, (analyses[a], literal[a]), strict=True):
            line, _, (bars,) = c.lines
            r = an.result
            segs = bars.get_segments()
            assert len(segs) == len(r.tau)
            # each bar spans the result's own interval at its τ
            lo = np.array([s[:, 1].min() for s in segs])
            hi = np.array([s[:, 1].max() for s in segs])
            np.testing.assert_allclose(lo, r.dev_lo, rtol=1e-12)
            np.testing.assert_allclose(hi, r.dev_hi, rtol=1e-12)
            assert (hi > lo).all()
            styles.add((line.get_color(), line.get_marker()))
        assert len(styles) == 2, styles
        assert "τ" in ax.get_xlabel() and "(s)" in ax.get_xlabel()
    assert "m/s²" in fig.axes[0].get_ylabel()

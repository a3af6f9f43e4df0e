"""The analysis figure: every shaded or drawn element is named in its legend."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from avard.core.io.source import open_record


def test_the_fitted_range_is_in_the_legend(tmp_path: Path, monkeypatch: pytest.MonkeyPatch
                                           ) -> None:
    pytest.importorskip("matplotlib")
    from avard.core import plot
    from avard.core.analysis.engine import analyze

    rng = np.random.default_rng(5)
    data = tmp_path / "w.npz"
    np.savez(data, accel=rng.normal(0, 1e-3, (20000, 1)), rate_hz=100.0)
    an = analyze(open_record(str(data)))
    legends: list[list[str]] = []
    save = plot.save_figure

    def keep(fig: Any, path: Any, *, dpi: int) -> Path:
        legends.extend([t.get_text() for t in ax.get_legend().get_texts()]
                       for ax in fig.axes if ax.get_legend() is not None)
        return save(fig, path, dpi=dpi)

    monkeypatch.setattr(plot, "save_figure", keep)
    out = plot.plot_analysis(an, tmp_path / "a.png")
    assert out.stat().st_size > 10_000
    fit = an.channels[next(iter(an.channels))].fit
    assert any(f"fitted τ range ({fit.tau_min_s:.3g}–{fit.tau_max_s:.3g} s)" in t
               for t in legends[0])

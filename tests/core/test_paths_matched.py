"""An extension is chosen over one lag on held-out halves where both have the same nuisance
columns refitted (``thermal_paths._matched``): ``_held_dev`` refits each model's own start
states on the held-out half, and an extension's more or longer lags bring more of them
(docs/log/2026-11-28-match24h.md)."""

from __future__ import annotations

import numpy as np
import pytest
from avard.core.explain.engine import explain_file
from avard.core.explain.options import ExplainOptions
from avard.core.explain.thermal_fit.sums import octave_sums_by_part
from avard.core.explain.thermal_paths import HELDOUT_MARGIN, path_columns
from avard.core.explain.thermal_paths.columns import Column
from avard.core.explain.thermal_paths.deviance import _fit, _held_dev, _view
from avard.core.explain.thermal_paths.readings import _matched
from avard.core.io.source import open_record

from tests.core.test_thermal_paths import BASE, C, _slow
from tests.support.hidden import Truth, make_record, save


def test_an_extension_that_only_adds_a_start_state_gains_nothing_once_matched():
    """One lag through 300 s on a record that also holds a slow settling its own start state
    cannot follow (e^(−t/2400 s)); the "extension" is the same one lag with one more start
    state (e^(−t/1800 s)) and no other term. Refitted on the held-out half as its own
    column, that start state predicts it better than one lag by more than the margin an
    extension needs; with the same columns refitted for both it gains nothing: exactly
    nothing with the same coupling, and less than the margin with each coupling fitted on
    the other half."""
    _y, T = _slow(BASE, 5)
    n = len(T)
    t = np.arange(n, dtype=float)
    rng = np.random.default_rng(1)
    U = path_columns(T, [Column("u", 300.0), Column("start", 300.0),
                         Column("start", 1800.0)], 1.0)
    y = C * U[:, 0] + 3e-4 * np.exp(-t / 2400.0) + rng.normal(0.0, 1e-4, n)
    halves = octave_sums_by_part(np.column_stack([y, U]), np.array([0, n // 2, n]))
    k = len(halves[0].ms)
    vh = [_view(h, np.full(k, 50.0), h.n, np.ones(k, dtype=bool), np.full(k, 1e-8))
          for h in halves]
    one_ix, ext_ix = [1, 2], [1, 2, 3]  # the coupling first, then the start states
    raw = matched = 0.0
    for a, b in ((0, 1), (1, 0)):
        b_one, b_ext = _fit(vh[a], one_ix), _fit(vh[a], ext_ix)
        raw += _held_dev(vh[b], ext_ix, b_ext, 1) - _held_dev(vh[b], one_ix, b_one, 1)
        matched += _matched(vh[b], (ext_ix, b_ext, 1), (one_ix, b_one, 1))
        # the same coupling: the two models are one once their nuisance columns are
        assert _matched(vh[b], (ext_ix, b_one[:1], 1), (one_ix, b_one, 1)) == pytest.approx(
            0.0, abs=1e-9)
    assert raw < -HELDOUT_MARGIN
    assert abs(matched) < HELDOUT_MARGIN


def test_one_lag_is_kept_where_two_paths_won_only_on_their_start_states(tmp_path):
    """hidden.py's seed 5, y: the truth is exactly one lag of 300 s (1.5e-3 m/s²/K, the
    ambient channel logged, 4 h). Two paths (8.0e-3 at 590 s and −7.9e-3 at 850 s, their
    zero-frequency gain a tenth of the truth's) predicted the held-out halves better than
    one lag by more than the margin, on the freedom of their own start states refitted on
    the halves they were scored on; with the same start states refitted for both they
    predict worse. One lag must be chosen, with the truth's coefficient and lag."""
    rec, _ = make_record(5, truth=Truth(coefficient=(3e-3, 1.5e-3, 0), lag_s=300.0),
                         logged=("ambient",), hours=4.0)
    path = save(rec, tmp_path / "s5.npz")
    ch = explain_file(open_record(str(path)), ExplainOptions(channels=("y",))).channels["y"]
    th = ch.thermal
    assert th is not None and th.path is not None and th.passed
    assert th.mechanism == "one_lag"
    assert th.coefficient == pytest.approx(1.5e-3, rel=0.2)
    assert th.lag_s == pytest.approx(300.0, rel=0.2)
    # the raw gain and its matched score are both in the JSON, and a note says why
    d = th.path.to_dict()
    raw = d["heldout_minus2lnL"]
    assert raw["two_path"] - raw["one_lag"] < -HELDOUT_MARGIN
    assert d["heldout_matched_minus_one_lag"]["two_path"] > -HELDOUT_MARGIN
    assert any(n.startswith("two_path predicts better") and "same nuisance columns" in n
               for n in th.path.notes)

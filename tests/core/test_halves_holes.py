"""The record's own held-out halves (``avard explain RECORD``, no ``--holdout``) carry the input
screen's holes as a second record does (issue 23 item 1: "a hole in a log is never a cause on
another channel"; a masked stretch is a gap to the estimators). Before, the halves carried
none: a 25-minute dropout in the temperature log was interpolated across in the held-out half,
the extended model's prediction there ran on that interpolation, and its misfit went into the
held-out χ² (a record that predicts its halves with a gain of 0.98 clean gave −10 to −31 with
the dropout, and the held-out test rejected the coupling it had found). Now each half's holes,
with the lag's settling after them, are gaps of its held-out Allan variance
(``holdout.Part.holes``, ``thermal_fit.hole_mask``, one mechanism for both paths), and each
half's thermal fit leaves them out of its regression as the whole record's fit does."""

from __future__ import annotations

import math

import numpy as np
import pytest
from avard.core.explain.engine import Explanation, explain_file
from avard.core.explain.holdout import _part_holes
from avard.core.explain.options import ExplainOptions
from avard.core.explain.verdict import ALPHA
from avard.core.io.source import open_record

from tests.support.hidden import Truth, make_record, save

HOURS = 4.0
DROPOUT_S = 1500.0


def _record(tmp_path, seed: int, half: str | None):
    """The record of ``seed`` (x coupled 3e-3 m/s²/K through 300 s to the logged ambient),
    clean (``half`` None) or with a 25-minute dropout and three DS18B20 85.0 °C power-on
    readings in its ``half`` ("first" or "second")."""
    rec, _ = make_record(seed, hours=HOURS, logged=("ambient",),
                         truth=Truth(coefficient=(3e-3, 0, 0), lag_s=300.0))
    if half is not None:
        t = rec.temperature_c
        n = len(t)
        i0 = int((0.2 if half == "first" else 0.7) * n)
        t[i0:i0 + int(DROPOUT_S * rec.rate_hz)] = np.nan
        ok = np.flatnonzero(np.isfinite(t[:, 0]))
        mine = ok[ok < n // 2] if half == "first" else ok[ok >= n // 2]
        for k in (0.1, 0.5, 0.9):
            t[mine[int(k * len(mine))], 0] = 85.0
    return save(rec, tmp_path / f"r{seed}_{half or 'clean'}.npz")


def _explain(path) -> Explanation:
    return explain_file(open_record(path), ExplainOptions(channels=("x",)))


def _held(ex: Explanation) -> tuple[float, float, float, int]:
    """(gain, χ²_base, χ²_ext, n) of axis x over the record's two halves."""
    assert ex.holdout is not None and ex.holdout.mode == "split"
    c = ex.holdout.channels["x"]
    assert c.reason is None and c.gain is not None
    return c.gain, c.chi2_base, c.chi2_ext, c.n_points


@pytest.fixture(scope="module")
def clean(tmp_path_factory) -> Explanation:
    return _explain(_record(tmp_path_factory.mktemp("clean"), 3, None))


@pytest.mark.parametrize("half", ["first", "second"])
def test_a_dropout_in_a_half_is_a_gap_not_a_misfit(tmp_path, clean, half):
    """The same record clean and with a dropout and 85 °C readings in one half: the held-out
    gain agrees within its interval (a model that predicts the data gives χ²_ext ≈ n ± √(2n),
    so the gain 1 − χ²_ext/χ²_base is known to ±√(2n)/χ²_base), the extended model predicts
    the halves (χ²_ext within χ²(n)'s upper tail), the claims are the same and the held-out
    part of the verdict is the clean record's (not rejected)."""
    faulty = _explain(_record(tmp_path, 3, half))
    g_c, _b_c, _e_c, _n_c = _held(clean)
    g_f, b_f, e_f, n_f = _held(faulty)
    assert abs(g_f - g_c) <= 2 * math.sqrt(2 * n_f) / b_f, (g_f, g_c)
    assert e_f < n_f + 4 * math.sqrt(2 * n_f), e_f
    assert g_f > 0.9
    # the screen saw the dropout (the record's own screen, not a held-out record's)
    d = faulty.to_dict()
    assert d["screened"]["counts"].get("dropout") == 1
    assert d["holdout_screened"] is None
    for ex in (clean, faulty):
        assert [f.cause for f in ex.channels["x"].claimed] == ["temperature"]
    vc, vf = clean.channels["x"].verdict, faulty.channels["x"].verdict
    assert vc is not None and vf is not None
    assert not vc.heldout_rejects and not vf.heldout_rejects
    assert vc.heldout_p is not None and vc.heldout_p >= ALPHA
    assert vf.heldout_p is not None and vf.heldout_p >= ALPHA


def test_each_half_carries_the_record_holes_on_its_own_blocks():
    """A hole is given to the half whose blocks it covers, on that half's block index; one
    that ends before the second half starts stays with it at negative blocks (its lag's
    settling can reach into the half), one that starts after the first half ends does not."""
    holes = {0: [(10, 20), (95, 104), (150, 160)], 1: []}
    first, second = _part_holes(holes, 0, 100), _part_holes(holes, 100, 200)
    assert first == {0: [(10, 20), (95, 104)], 1: []}
    assert second == {0: [(-90, -80), (-5, 4), (50, 60)], 1: []}
    assert _part_holes(None, 0, 100) == {}

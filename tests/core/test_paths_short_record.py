"""A record too short for the thermal path test's τ (20 minutes of the adversary's faulty,
coupled class): the dT/dt reading beside one lag had an empty view, whose fit is zeros, and
read as two signals 0 σ apart with a coupling of 0 — the note then divided by that coupling
(ZeroDivisionError, found by small25). An empty view is no evidence: no rival."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from avard.core.explain.engine import explain_file
from avard.core.explain.thermal_paths.columns import Column
from avard.core.explain.thermal_paths.deviance import _View
from avard.core.explain.thermal_paths.readings import _rate_separation
from avard.core.io.source import open_record

from tests.support.adversary_gen import make_record


def test_a_view_without_tau_is_no_rival_reading() -> None:
    empty = _View(np.zeros((0, 3, 3)), np.zeros(0), np.zeros(0))
    cols = (Column("u", 60.0),)
    where = {Column("u", 0.0): 0, Column("rate", 0.0): 1,
             cols[0]: 2}
    lam, c, r = _rate_separation(empty, where, cols, 1e-3)
    assert lam == float("inf") and np.isnan(c) and np.isnan(r)


def test_explain_on_a_twenty_minute_faulty_coupled_record_says_what_it_found(
        tmp_path: Path) -> None:
    path = tmp_path / "short.npz"
    make_record("faulty_coupled", 3, path, hours=1 / 3)
    ex = explain_file(open_record(path))
    d = ex.to_dict()
    assert set(d["channels"]) == {"x", "y", "z"}
    # the screen still lists the log's faults (the record's whole point)
    assert d["screened"]["counts"]

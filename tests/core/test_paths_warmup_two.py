"""Two thermal paths beside a warm-up (issue 23 items 3 and 4, docs/log/2026-11-29-paths29.md):
the benchmark's ``path+warm-up: two paths`` row, where the warm-up's e^(−t/900 s) is the
second path's own start state."""

from __future__ import annotations

from dataclasses import replace

import pytest


def _row(name: str):
    from benchmarks.bench_explain_weekend import rows_paths

    return next(x for x in rows_paths() if x.name == name)


@pytest.mark.parametrize("seed", [30010, 30012])
def test_a_warm_up_is_no_evidence_between_two_paths_and_a_dt_term(seed):
    """What the record resolves (``bench_path_ident.record_resolves``): the non-centrality
    between the true two-path signal and the best dT/dt reading cannot grow because the
    record also holds a warm-up, whose size is unknown to either reading (a nuisance of free
    size beside both, as explain fits it). Left out of the rival, the warm-up's own size was
    read as a separation (λ 103 and 105 on these records against 46 and 70 without it)."""
    from benchmarks.bench_explain_weekend import _whiten
    from benchmarks.bench_path_ident import ID_BLOCK, record_resolves

    r = _row("path+warm-up: two paths")
    w = r.weekend
    assert w.warmups
    n = int(w.hours * 3600 * w.rate_hz)
    W = _whiten(n, ID_BLOCK, float(w.rate_hz))
    truth = {**r.truth, "lag_s": 0.0}
    with_wu = record_resolves(w, seed, truth, W)["lambda_rate"]
    without = record_resolves(replace(w, warmups=[]), seed, truth, W)["lambda_rate"]
    assert with_wu <= without * (1 + 1e-6)


def test_two_paths_named_with_a_dt_term_hold_beside_the_transients_where_the_term_does():
    """Seed 30000 of the row: one lag fails its own test, two paths are chosen with the
    dT/dt term named beside them (one drive line: the record cannot tell them apart); beside
    the compound search's transients (the warm-up) the dT/dt term is chosen and two paths'
    lag leaves no half to test. The coupling is claimed, both readings named, with no
    interval on their parameters (before: nothing was claimed on x)."""
    from benchmarks.bench_explain_weekend import explain_weekend

    r = _row("path+warm-up: two paths")
    ex, _ = explain_weekend(r.weekend, 30000, heldout=True)
    th = [f for f in ex.channels["x"].claimed if f.cause == "temperature"]
    assert th, "no temperature claim on x"
    named = {th[0].mechanism, *th[0].alternatives}
    assert {"two_path", "rate"} <= named
    assert not th[0].intervals
    for ax in ("y", "z"):
        assert not [f for f in ex.channels[ax].claimed if f.cause not in ("sinusoid", "periodic")]

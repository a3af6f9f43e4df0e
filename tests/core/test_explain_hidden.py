"""Hidden-effect tests: a seeded generator hides one cause (or none) in a simulated record;
`explain` gets only the record and must name the cause with its parameters within the issue's
tolerances (frequency 2 %, temperature coefficient 20 %, step time 2 % of the record, time
constants 30 %; see avard.core.effects.TOLERANCE) and claim nothing else. Null records must
come back with no findings."""

from __future__ import annotations

import pytest
from avard.core import effects, explain

CI_SEEDS = (101, 202, 303)  # 3 × 9 kinds = 27 cases in CI (records of 2^18 samples, 50 Hz)
SLOW_SEEDS = tuple(range(5000, 5012))


def _run(seed: int, kind: str) -> None:
    rec, truth = effects.make_case(seed, kind)
    ch = explain.explain(rec).channels["x"]
    ok, why = effects.check_case(truth, ch.findings)
    assert ok, f"seed {seed}: {why}; tests: " + " | ".join(
        f"{t.cause}: {t.evidence}" for t in ch.tests if t.passed or t.cause == truth.cause)
    if truth.cause is not None and truth.cause not in ("quantization", "rate_ramp",
                                                        "temperature"):
        # the extension must pay off on the held-out half (ramps, temperature couplings and
        # rounding noise the free five terms can mimic there: they need only not hurt)
        assert ch.holdout_gain is not None and ch.holdout_gain > 1.0


@pytest.mark.parametrize("kind", effects.CASE_KINDS)
@pytest.mark.parametrize("seed", CI_SEEDS)
def test_hidden_effect_is_found(seed, kind):
    _run(seed, kind)


@pytest.mark.slow
def test_large_hidden_effect_set_rates():
    """108 more cases (12 per kind): per-case chance misses are expected at the edges of the
    tolerances, so the large set asserts the rates (the benchmark prints them per cause):
    every null record clean, ≥ 95 % detected within tolerance, ≤ 2 % with a false claim."""
    detected, false_claims, effects_n, misses = 0, 0, 0, []
    for kind in effects.CASE_KINDS:
        for seed in SLOW_SEEDS:
            rec, truth = effects.make_case(seed, kind)
            findings = explain.explain(rec).channels["x"].findings
            ok, why = effects.check_case(truth, findings)
            claimed = [f["cause"] for f in findings]
            if truth.cause is None:
                assert not findings, f"seed {seed}: null record, claimed {claimed}"
            else:
                effects_n += 1
                detected += ok
            false_claims += any(c != truth.cause for c in claimed) or len(claimed) > 1
            if not ok:
                misses.append(f"seed {seed} {kind}: {why}")
    n_cases = len(effects.CASE_KINDS) * len(SLOW_SEEDS)
    assert detected / effects_n >= 0.95, misses
    assert false_claims / n_cases <= 0.02, misses

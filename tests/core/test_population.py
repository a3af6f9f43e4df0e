"""The population rule of `avard fleet` (core/analysis/population.py) on hand-made fits."""

from __future__ import annotations

from dataclasses import dataclass, field

import pytest
from avard.core.analysis.population import MIN_SENSORS, format_population, population
from avard.core.model.terms import TERMS


@dataclass
class _Term:
    present: bool = False
    value: float | None = None
    lo: float | None = None
    hi: float | None = None
    upper: float | None = None


@dataclass
class _Fit:
    terms: dict
    chi2_dof: float = 1.0


@dataclass
class _Channel:
    fit: _Fit


@dataclass
class _Analysis:
    channels: dict
    n_samples: int = 360_000
    rate_hz: float = 100.0
    meta: dict = field(default_factory=dict)

    def recording_summary(self):
        return None


def _sensor(n: float, half: float = 0.01e-4, k: float | None = None) -> _Analysis:
    terms = {t: _Term(upper=1e-6) for t in TERMS}
    terms["velocity_random_walk"] = _Term(True, n, n - half, n + half)
    if k is not None:
        terms["rate_random_walk"] = _Term(True, k, 0.9 * k, 1.1 * k)
    return _Analysis({"x": _Channel(_Fit(terms))})


def test_an_interval_three_spreads_off_the_median_is_an_outlier_and_only_it() -> None:
    batch = {f"s{i}": _sensor(1e-4 * (1 + 0.02 * (i - 4))) for i in range(9)}
    batch["hot"] = _sensor(1.5e-4)
    batch["cold"] = _sensor(0.6e-4)
    pop = population(batch)
    assert {(o.sensor, o.term) for o in pop.outliers} == {("hot", "velocity_random_walk"),
                                                          ("cold", "velocity_random_walk")}
    hot = next(o for o in pop.outliers if o.sensor == "hot")
    assert "above" in hot.reason and "spreads" in hot.reason
    assert "OUTLIER" in format_population(pop)


def test_a_loosely_measured_term_is_not_an_outlier_for_its_scatter() -> None:
    """The interval, not the value, is compared: 1.5e-4 ± 0.6e-4 reaches the centre."""
    batch = {f"s{i}": _sensor(1e-4 * (1 + 0.02 * (i - 4))) for i in range(9)}
    batch["loose"] = _sensor(1.5e-4, half=0.6e-4)
    assert not population(batch).outliers


def test_identical_sensors_use_their_interval_as_the_spread() -> None:
    """Values agreeing better than they are measured: a difference of half an interval is
    measurement scatter, not an outlier (the MAD alone would be zero)."""
    batch = {f"s{i}": _sensor(1e-4) for i in range(6)}
    batch["near"] = _sensor(1e-4 + 0.02e-4)
    pop = population(batch)
    assert not pop.outliers
    spread = next(s for s in pop.spreads if s.term == "velocity_random_walk")
    assert spread.spread == pytest.approx(0.01e-4, rel=1e-9)


def test_fewer_than_three_sensors_with_a_term_are_not_judged() -> None:
    batch = {f"s{i}": _sensor(1e-4) for i in range(5)}
    batch["a"] = _sensor(1e-4, k=1e-6)
    batch["b"] = _sensor(1e-4, k=9e-6)
    pop = population(batch)
    k = next(s for s in pop.spreads if s.term == "rate_random_walk")
    assert (k.n, k.of, k.centre) == (2, 7, None) and k.n < MIN_SENSORS
    assert not [o for o in pop.outliers if o.term == "rate_random_walk"]
    assert "not judged" in format_population(pop)

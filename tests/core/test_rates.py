"""The one rate-compatibility rule (core/io/rates.py)."""

from __future__ import annotations

import pytest
from avard.core.errors import DataError
from avard.core.io.rates import format_rate, rates_compatible, require_compatible


def test_two_runs_of_one_sensor_agree_and_another_odr_does_not() -> None:
    # two fits of one chip's 125 Hz ODR, 2 ppm apart (explain --holdout's real case)
    assert rates_compatible(124.90011, 124.89984, 1e-5, 1e-5)
    # 100 ppm slack with no uncertainty given: 125 Hz ± 0.0125 Hz
    assert rates_compatible(125.0, 125.012)
    assert not rates_compatible(125.0, 125.02)
    # three combined standard uncertainties widen it
    assert rates_compatible(125.0, 125.02, 0.002, 0.002)
    assert not rates_compatible(125.0, 4000.0, 0.01, 0.01)
    assert not rates_compatible(125.0, 62.5)
    assert not rates_compatible(125.0, float("nan"))
    assert not rates_compatible(0.0, 0.0)


def test_the_refusal_names_both_records_and_rates_with_enough_digits() -> None:
    with pytest.raises(DataError) as e:
        require_compatible("run1", 124.90011, "run2", 125.5, 1e-5, 1e-5)
    msg = str(e.value)
    assert "run1" in msg and "run2" in msg
    assert "124.900110" in msg and "125.500000" in msg
    assert format_rate(124.90011) == "124.90011 Hz"
    require_compatible("a", 125.0, "b", 125.001)  # agreeing rates pass silently

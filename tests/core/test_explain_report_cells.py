"""explain's report tables say "—" where a number does not exist, never "nan"."""

import math

from avard.core.explain.report import _cell


def test_a_missing_number_is_a_dash_not_nan() -> None:
    assert _cell(math.nan, ".4g") == "—" and _cell(None, ".3g") == "—"
    assert _cell(math.inf, "+.3g") == "—"
    assert _cell(1.23456, ".3g") == "1.23" and _cell(-0.5, "+.3g") == "-0.5"

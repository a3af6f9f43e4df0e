"""The one rule for putting two records (or two runs of one recording) together by rate.

Every run of the service fits its own ADXL355 output data rate (the chip's oscillator is
off its nominal by up to a few hundred ppm and drifts with temperature), so two recordings
of one sensor never carry the very same rate. They are one sensor's data when the fitted
rates agree within ``K_SIGMA`` combined standard uncertainties plus ``SLACK_PPM`` of the
rate: the uncertainties cover the fits, the slack covers the oscillator's drift between runs
(the ADXL355's ODR tempco is tens of ppm over a lab's temperature range), while a different
ODR setting (125 Hz against 4 kHz, or 62.5 against 125 Hz) is orders of magnitude away.

Used by every command that combines records: explain's ``--holdout``, the record source's
runs, separate and fleet.
"""

from __future__ import annotations

import math

from avard.core.errors import DataError

#: Combined standard uncertainties the two fitted rates may differ by.
K_SIGMA = 3.0
#: Slack in ppm of the rate, for the oscillator's drift between runs.
SLACK_PPM = 100.0


def rate_tolerance_hz(a_hz: float, b_hz: float, u_a_hz: float = 0.0,
                      u_b_hz: float = 0.0) -> float:
    """How far apart (Hz) two rates with standard uncertainties may be and still agree."""
    return K_SIGMA * math.hypot(u_a_hz, u_b_hz) + SLACK_PPM * 1e-6 * max(abs(a_hz), abs(b_hz))


def rates_compatible(a_hz: float, b_hz: float, u_a_hz: float = 0.0,
                     u_b_hz: float = 0.0) -> bool:
    """True when two fitted rates are the same sensor's rate by the rule above."""
    if not (math.isfinite(a_hz) and math.isfinite(b_hz)) or a_hz <= 0 or b_hz <= 0:
        return False
    return abs(a_hz - b_hz) <= rate_tolerance_hz(a_hz, b_hz, u_a_hz, u_b_hz)


def format_rate(rate_hz: float, u_hz: float = 0.0) -> str:
    """A rate with enough digits to tell two runs apart (10 significant digits, or to the
    uncertainty's second digit), and its uncertainty when known: '124.9001123 ± 0.0000021 Hz'."""
    if u_hz > 0 and math.isfinite(u_hz):
        decimals = max(0, 1 - math.floor(math.log10(u_hz)))
        return f"{rate_hz:.{decimals}f} ± {u_hz:.{decimals}f} Hz"
    return f"{rate_hz:.10g} Hz"


def require_compatible(a_name: str, a_hz: float, b_name: str, b_hz: float,
                       u_a_hz: float = 0.0, u_b_hz: float = 0.0) -> None:
    """Raise ``DataError`` naming both records and both rates when they do not agree."""
    if rates_compatible(a_hz, b_hz, u_a_hz, u_b_hz):
        return
    tol = rate_tolerance_hz(a_hz, b_hz, u_a_hz, u_b_hz)
    raise DataError(
        f"{a_name} was sampled at {format_rate(a_hz, u_a_hz)} and {b_name} at "
        f"{format_rate(b_hz, u_b_hz)}: {abs(a_hz - b_hz):.3g} Hz apart, more than the "
        f"{tol:.3g} Hz that {K_SIGMA:g} combined standard uncertainties plus {SLACK_PPM:g} ppm "
        "allow; they are not one sensor at one rate: analyse them separately")

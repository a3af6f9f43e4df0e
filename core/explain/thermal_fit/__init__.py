"""Which logged temperature drives an axis, through what first-order lag, with what
coefficient; and the temperature-compensated Allan variance. For ``avard explain`` (and
``avard analyze --temperature``).

Physics: heat reaches the sensor die from the logged channel (plate, ambient or the chip's own)
through a thermal mass, a first-order lag: dT_s/dt = (T − T_s)/τ_L. The output moves by
c·T_s (bias and sensitivity tempco, m/s²/K). Both act on seconds to hours, so the fit runs on
the slow view (block means of ≈ 1 s; ``explain.SlowView``).

Estimator. For a trial lag τ_L the logged channel is passed through the lag (exact
discretisation for a linearly interpolated input, ``thermal.lag_coefficients``) and the
streaming Allan accumulator (``streaming.StreamingAllan``, analyze's estimator at its octave τ)
gives the Allan covariance of axis y and lagged temperature u. At each τ_k the regression of
Allan differences of y on those of u is c_k = Cov_A(y, u)/AVAR(u), with variance
r_k/(AVAR(u)·ν_k) (r_k the residual AVAR, ν_k the EDF of the axis at τ_k: the number of
independent differences). Differencing removes the offset and whitens flicker and random walk,
so the regression is valid under the axis's own noise. The c_k are combined with inverse-
variance weights; neighbouring octaves share data (correlation ≈ 0.5, fit.py), which the
combined variance includes (ρ_kl = 0.5^|k−l|): this analytic z picks each channel's lag
(maximum of z² over a log grid refined around the best point), one covariance for every lag
and channel compared. Which channel drives is decided by each channel's held-out likelihood
through its own lag (``_choose_channel``, ``holdout.channel_heldout``), not by this z: the
room seen through the plate's long lag is a second description of a coupling through the
plate, and its smoother regressor took the larger z. At the chosen lag the test's analytic se is the
regressor's own (``octave_spectra``, ``coupling_test``: the octaves see the same slow noise,
near one number for a trend under red noise), its threshold the t of the degrees of freedom
that se rests on. Under red noise the EDF model is too optimistic (the noise differences are
not independent across a slow regressor), so the reported standard error of ĉ is the larger
of that se and a delete-a-group jackknife over 10 contiguous parts
(``jackknife_tempco``: its parts can be shorter than the noise's correlation at the
regressor's period), z = ĉ/se, and the lag's 68 % interval is the lag's own delete-a-group
jackknife (``lag_interval``); the parts hold the Allan differences whose middle they hold,
at every octave (``octave_sums_by_part``). Test: z ≥ ``Z_TEMPERATURE`` (5: the lag and
channel search look at ≈ 50 correlated trials), or the t of the se's degrees of freedom at
the search's share of the axis's false-alarm budget where that is more
(``CouplingTest.threshold``). The test's z is its own combination of the octaves, the one
of least variance under the regressor's octave covariance with non-negative weights
(``least_variance_weights``; its jackknife with those weights fixed): where a day's cycle
drives the slow octaves, the inverse-variance weights' shared red noise there set the
se and its degrees of freedom (so the threshold). ĉ and its interval keep the
inverse-variance weights.

Compensated AVAR: AVAR(y − ĉu) = AVAR_y − 2ĉ·Cov_A + ĉ²·AVAR_u from the same covariance, as a
ratio to AVAR_y applied to analyze's full-rate curve (below the slow view's first τ the
thermal share falls as τ³: a smooth signal's AVAR ∝ τ², white noise's ∝ 1/τ).
"""

from __future__ import annotations

from avard.core.explain.thermal_fit.axes import fit_thermal, fit_thermal_axes, with_paths
from avard.core.explain.thermal_fit.fit import ThermalFit, compensated_avar, signal_avar_on
from avard.core.explain.thermal_fit.jackknife import coefficient_se
from avard.core.explain.thermal_fit.lag import min_detectable_tempco
from avard.core.explain.thermal_fit.octaves import tempco_from_cov
from avard.core.explain.thermal_fit.settings import Z_TEMPERATURE
from avard.core.explain.thermal_fit.signals import allan2, lag_filter, without_start

__all__ = [
    "Z_TEMPERATURE",
    "ThermalFit",
    "allan2",
    "coefficient_se",
    "compensated_avar",
    "fit_thermal",
    "fit_thermal_axes",
    "lag_filter",
    "min_detectable_tempco",
    "signal_avar_on",
    "tempco_from_cov",
    "with_paths",
    "without_start",
]

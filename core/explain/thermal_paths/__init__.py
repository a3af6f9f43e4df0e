"""Thermal paths beyond one first-order lag, chosen by held-out likelihood (issue 23 item 4).

``thermal_fit`` finds the driving channel and one lag of either sign. The physics may need
more; the candidates, each a linear model in regressors built from the driving channel T
(slow view, °C) with its nonlinear parameter θ on a grid:

- ``one_lag``: c·u_L, u_L = ``lag_filter(T, L)`` (θ = L, either sign);
- ``two_path``: c₁·u_L1 + c₂·u_L2, 0 ≤ L1 < L2 (two first-order paths, e.g. plate → die and
  room → die; θ = (L1, L2));
- ``quadratic``: c·u_L + q·(v_L − v̄)² (m/s²/K²), v_L = lag(T̂, L) on the temperature
  behind the readings (``crossing_reconstruction``, as the relay below: squared, their
  rounding is an error every part shares), L also over the one-lag fit's leads
  (``quadratic_leads``);
- ``rate``: c·u_L + r·dT/dt (m/s² per K/s, L ≥ 0), dT/dt of the logged channel smoothed
  forward and back through a ``RATE_SMOOTH_S`` lag (jω/(1 + ω²s²): no phase; the readings'
  0.0625 K steps would make a raw gradient spikes). The rate term on the channel itself and
  the static coupling through its own lag: as c·u_L + r·du_L/dt, (c + jωr)/(1 + jωL) at
  one drive frequency, c crossed zero along the ridge L trades on, and was not resolved;
  a negative L (a lead-lag, T + a·dT/dt) would be a second rate term. The smoothing's gain
  1/(1 + ω²s²) falls on whatever lines the drive has (a compressor's third harmonic: 0.82),
  and the fit made r up for it; a refined term's coefficients are read back through the
  gain its own columns and weights give the unsmoothed slope of the temperature behind the
  readings (``_ungained``), while θ, the deviance and the choice stay on the smoothed
  column (that slope as the regressor moved the one-line fit along its (c, r, L) ridge);
- ``hysteresis``: c·u_L + h·r_w, r_w ∈ {−1, +1} a non-ideal relay of width w (K), the
  Preisach elementary hysteron (``_relay``: +1 once the temperature rose w above its last
  minimum, −1 once it fell w below its last maximum) on lag(T̂, L), T̂ the temperature behind
  the readings (``crossing_reconstruction``: the 0.0625 K rounding an error in the
  regressor, not a signal); θ = (L, w), L also over the short negative lags
  ``HYSTERESIS_LEADS_S`` (the lag and the width trade along a ridge through a lag of 0);
  its coefficients and θ averaged over the grid points within the 68 % profile's Δ, each
  by its likelihood (``AVERAGED``), not read at the best one. A play operator (a lead that
  crosses over while the temperature turns back by w) on the readings themselves was the
  candidate before; on the hysteresis row it was chosen on 3 of 20 records, the relay on T̂
  on 19 of 20
  (docs/log/explain.md).

Every candidate also carries the lag filter's unknown start state (e^(−t/|L|) per lag, a
nuisance regressor, as ``thermal_fit.without_start``).

**Estimator.** The Allan covariance of (y, all regressors) at octave τ (``thermal_fit.
octave_sums``: one pass gives every candidate, since it is bilinear), on ``PARTS`` contiguous
parts whose sums add exactly. For coefficients β of a regressor subset the residual AVAR at
τ_k is r_k(β) = V_yy − 2βᵀV_uy + βᵀV_uuβ; with a free noise level per τ and ν_k independent
differences (the axis's EDF), −2 ln L = Σ_k ν_k ln r_k(β) + const (the deviance D). β
minimises it (iteratively reweighted: weights ν_k/r_k); θ is the grid point of least D.

**Choice by held-out likelihood.** Each candidate is fitted (θ and β) on one half of the
record and its deviance measured on the other half with those values (β and θ fixed); both
folds add: H = D_B(fit on A) + D_A(fit on B). An extension is preferred over ``one_lag``
(and over no coupling at all) only when its H is lower by ``HELDOUT_MARGIN`` and its extra
term passes its own test (a Wald z from the delete-a-part jackknife, Student's t with
``PARTS`` − 1 dof, ≥ ``alarm.bonferroni_t(alarm.THERMAL_PATHS, trials, PARTS − 1)``, the
trials all grid points of all extensions): the false-alarm budget per axis holds the paths'
share. The margin grows by the share of the held-out deviance the readings' rounding through
the one-lag coupling makes up (``_View.rounding_share``): a path that smooths the 0.0625 K
steps gains that much without physics; a linear candidate (two paths, dT/dt) only by what
it passes less of that rounding than one lag does, through its own |H|² (``_smoothing``).
A candidate whose θ sits at the end of its grid is
open and never chosen over one lag (``OPEN_MARGIN`` is infinite): its θ is a bound, not an
estimate, and on typical-tempco records two lags of opposite sign at 1800 and 3600 s won the
held-out test by fitting the room's slow wander (3 of 20 records; one lag 20 of 20 without
them); a note names it. Other extensions that beat one lag so and predict within the
margin of the chosen one are named beside it (``PathFit.alternatives``), and the record
says it cannot tell them apart; an alternative passes every test the chosen one had to,
and is not one with more parameters that predicts worse than the chosen one (the simpler
and the better by both measures). Two paths hold the dT/dt term in their limit (u_L1 −
u_L2 ≈ (L2 − L1)·du/dt below 1/L2, at one drive frequency anywhere along their ridge), so
against a chosen dT/dt term they need the margin any extension needs over the model it
holds: short of it they are its reading with a parameter more, the same mechanism, noted
and not named (``_mimic``). One lag
kept while the hysteresis predicts the held-out halves better by ``LEAN_MARGIN`` (short of
what choosing it needs): one lag's coefficient and lag are then a linear model's reading of
a response no linear path has, model-dependent and printed with no interval
(``PathFit.leaning``).

**Intervals (68 %, ± ``T68`` jackknife standard errors).** Coefficients: the larger of the
delete-a-part jackknife over the ``PARTS`` parts with θ fixed and with θ re-chosen (red
noise breaks the analytic ones, as in ``thermal_fit``), widened to the profile over θ (the
coefficients at every grid point within ``PROFILE_DELTA`` = 1 of the best deviance, times
the Birge factor where the best fit's deviance exceeds its dof: the 68 % profile on one
parameter; the held-out margin chooses the model only). θ: the
jackknife of θ re-chosen with each part left out, each best grid point refined by a
parabola in ln L through its neighbours, widened to the same profile and to half way to the
neighbouring grid points at least. A coefficient that changes sign over the profile: the
parameters are not resolved (``PathScore.resolved`` False), reported with no interval.
For two paths and dT/dt, when they may be chosen, θ is continuous instead (``_refine``): a
local grid around the coarse optimum and a parabola per lag, on the whole record and in
each delete-a-part fit, so the jackknife with θ re-chosen is the estimator's spread and not
the coarse grid's steps (a dT/dt term's from the octave where the readings' rounding is no
larger a share of its rate column than of the linear column at the rounding floor,
``_rate_floor``: an error in the regressor pulled r − c·L low there); their profile's Δ is
scaled by the Birge factor either way
(``profile_delta(two_sided=True)``: the one-lag weights hold the signal one lag leaves, so
the deviance is several times too small a scale).
An ``AVERAGED`` candidate (the hysteresis) reports the likelihood-weighted average over the
profile's grid points instead of the best one, and its coefficients' interval is ± ``T68``
times the average's own jackknife (the average taken again in each part), not widened to
the profile's ends (the average does not jump between them as a best point does).
"""

from __future__ import annotations

from avard.core.explain.thermal_paths.choose import choose_path
from avard.core.explain.thermal_paths.columns import path_columns
from avard.core.explain.thermal_paths.minima import (
    fit_weights,
    min_detectable_hysteresis_fit,
    min_detectable_path,
    min_detectable_rate,
    min_detectable_rate_fit,
    one_lag_separation_fit,
    rate_lag_separation,
    relay_harmonics,
    rounding_floor,
    rounding_time,
)
from avard.core.explain.thermal_paths.readings import (
    both_readings,
    rate_reading,
    reads_as_rate,
    second_path_reading,
)
from avard.core.explain.thermal_paths.scores import PathFit, PathScore
from avard.core.explain.thermal_paths.settings import CANDIDATES, HELDOUT_MARGIN

__all__ = [
    "CANDIDATES",
    "HELDOUT_MARGIN",
    "PathFit",
    "PathScore",
    "both_readings",
    "choose_path",
    "fit_weights",
    "min_detectable_hysteresis_fit",
    "min_detectable_path",
    "min_detectable_rate",
    "min_detectable_rate_fit",
    "one_lag_separation_fit",
    "path_columns",
    "rate_lag_separation",
    "rate_reading",
    "reads_as_rate",
    "relay_harmonics",
    "rounding_floor",
    "rounding_time",
    "second_path_reading",
]

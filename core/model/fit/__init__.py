"""Fit the IEEE noise terms to an Allan variance curve, with intervals that are checked.

The method (one channel, overlapping or partially overlapping AVAR):

1. **Model.** σ²(τ) = Σ_j θ_j·b_j(τ) with θ_j the squared coefficients and b_j the closed forms
   of ``model.py`` (IEEE 952 Annex C): Q: 3/τ², N: 1/τ (or the low-pass-filtered white curve
   when the sensor's filter corner is given), B: 2 ln2/π, K: τ/3, R: τ²/2, plus any ``extra``
   component whose nonlinear parameter is fixed (sinusoid at f0: sin⁴(πf0τ)/(πf0τ)²;
   Gauss–Markov with T; those are linear in A², σ²).
2. **Weights.** var(σ̂²_k) = 2σ⁴_k/EDF_k (NIST SP 1065 §5.3), with σ²_k the *model* value
   (iteratively reweighted, so points that happen to fall low do not get extra weight).
3. **Correlation.** Neighbouring overlapping AVAR estimates share data: with octave spacing
   the correlation is about 0.5 for white noise and 0.9 for rate random walk. The full
   covariance Cov(σ̂²_k, σ̂²_l) = (2/M)∫S²|H_k|²|H_l|²dν is computed from the fitted model's
   own spectrum (``model.avar_covariance_kernels``), each power law's variance at each τ made
   Greenhall and Riley's finite-record one (``_covariance_kernels``: Whittle's first-order
   form understates it with few averages); the estimate is the non-negative weighted
   least-squares solution and its covariance is the sandwich (XᵀWX)⁻¹XᵀWCWX(XᵀWX)⁻¹.
4. **τ range from the data.** Points with too few differences (EDF < ``min_edf``, or fewer
   than ``min_averages`` independent τ-averages in the record) are left out at long τ. At short
   τ, unless the filter is modelled, the shortest point is left out while the curve still
   shows a significant filter bend (a negative τ⁻² deficit below the white line, more than
   ``drop_z`` standard errors; see ``_short_tau_cut``), up to ``max_drop`` points. With the
   filter modelled (``filter_corner_hz``), the model is exact from one sample on: the chip
   filters its white noise (``model.lowpass_white_avar``) and its bias-instability (flicker)
   noise (``model.lowpass_flicker_avar``: 0.38× the floor at one sample, 0.80× at two), and
   the fit starts at two samples (``filter_min_m``): the one-sample point depends on the
   spectrum right at Nyquist, which neither model pins down.
5. **Presence.** Stepwise likelihood-ratio selection (``_select_terms``): a term is present
   when removing it raises the generalised χ² by at least ``z_present``² (z_present = 2.33:
   a one-sided 1 % level for a coefficient on its boundary θ = 0). Terms left out are
   reported absent (value None) with a one-sided upper limit.
6. **Intervals.** θ̂ ± z_ci·se at level ``ci`` (68.3 % by default), mapped through √ to the
   coefficient, widened by the Birge ratio √(χ²/dof) when that exceeds 1. A coverage study
   over simulated records checks them (tests/core/test_fit_coverage.py): 60–76 % of 68 %
   intervals hold the true N and B; false presence of Q, K, R stays under 5 % (measured
   0.5–3 %).

``slope_method`` is the reading used by the paper's MATLAB workflow, allan_variance_ros and
kalibr_allan, kept for comparison (benchmarks/bench_fit.py).
"""

from __future__ import annotations

from avard.core.model.fit.chi2 import ModelChi2, model_chi2, slope_method
from avard.core.model.fit.components import CAUSE_ALPHA, avar_estimate_covariance, model_components
from avard.core.model.fit.long_tau import (
    LongTauCurve,
    refuted_by,
    resolved_long_tau_terms,
    with_long_tau_refuted,
)
from avard.core.model.fit.noise import fit_noise
from avard.core.model.fit.results import Component, NoiseFit, TermEstimate

__all__ = ["CAUSE_ALPHA", "Component", "LongTauCurve", "ModelChi2", "NoiseFit", "TermEstimate",
           "avar_estimate_covariance", "fit_noise", "model_chi2", "model_components",
           "refuted_by", "resolved_long_tau_terms", "slope_method", "with_long_tau_refuted"]

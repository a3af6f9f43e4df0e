"""A fitted model against a measured curve: its generalised χ² with the τ range and p-value
(``model_chi2``), and the slope method's quick read of the terms."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from avard.core.allan.chi2 import chi2_sf
from avard.core.errors import FitError
from avard.core.model import terms as mdl
from avard.core.model.fit.components import avar_estimate_covariance
from avard.core.model.fit.problem import _n_samples, _usable, _whitener
from avard.core.model.fit.results import NoiseFit
from numpy.typing import NDArray

#: χ² upper-tail probability below which a fit misfits its curve (and a filtered model is
#: checked against the data).
FILTER_MISFIT_P = 1e-3


def _misfit(fit: NoiseFit) -> bool:
    """Whether the fit's χ² is beyond its upper tail at ``FILTER_MISFIT_P``."""
    return (fit.dof > 0 and math.isfinite(fit.chi2_dof)
            and float(chi2_sf(fit.chi2_dof * fit.dof, fit.dof)) < FILTER_MISFIT_P)


@dataclass(frozen=True)
class ModelChi2:
    """``model_chi2``'s answer: the generalised χ² of an Allan variance against a fixed model,
    over ``n_points`` τ (``tau_s``, s). χ² ≈ n when the model describes the data."""

    chi2: float
    n_points: int
    tau_s: NDArray[np.float64]


def model_chi2(model: NoiseFit, result: Any, tau_range: tuple[float, float] | None = None, *,
               predictive: bool = False, min_edf: float = 3.0,
               min_averages: float = 8.0, extra_cov: NDArray | None = None) -> ModelChi2:
    """χ² of a fixed, already fitted model on (other) Allan variance data; nothing is fitted.

    ``model``: a ``fit_noise`` result; ``result``: a single-channel ``AllanResult`` of rate
    data in m/s² at the model's sample rate (e.g. a held-out record or another part of one).
    The points are those ``fit_noise`` would use (its cuts: ≥ ``min_averages`` independent
    averages, EDF ≥ ``min_edf``) inside ``tau_range`` (s). The residual r = σ̂² − Σθ_j·b_j(τ)
    is whitened with the covariance ``fit_noise`` models for its own fit, evaluated at the
    model's θ: Whittle kernels of the model's components (Cov(σ̂²_k, σ̂²_l) =
    (2/M)∫S²|H_k|²|H_l|²dν) and the NIST SP 1065 §5.3 floor 2σ⁴/EDF on the diagonal; χ² =
    rᵀC⁻¹r. On the data the model was fitted on (same τ range) this is the fit's own χ²
    (``chi2_dof·dof``; a test holds them equal).

    ``predictive``: the model predicts data it was not fitted on, so its own uncertainty adds
    to C (independent of the data's scatter): the fit's parameter covariance carried to the
    prediction, X·Cov(θ)·Xᵀ, and for each IEEE term the fit left out, a standard error of
    U²/z_present on its θ from its upper limit U (the term is known only to lie below U).
    ``extra_cov``: a further covariance of the prediction over all of ``result``'s τ (the
    caller's, e.g. the uncertainty of a removed signal's parameters), added on the points used.
    Returns χ² NaN and n 0 when no τ qualifies.
    """
    idx = _usable(result, min_edf, min_averages, tau_range)
    tau = np.asarray(result.tau, dtype=float)[idx]
    if len(idx) == 0:
        return ModelChi2(math.nan, 0, tau)
    var = np.asarray(result.var, dtype=float)[idx]
    rate = float(result.rate_hz)
    comps = model.components
    X = np.column_stack([c.basis(tau, rate) for c in comps])
    theta = np.asarray(model.theta, dtype=float)
    stride = np.asarray(getattr(result, "stride", np.ones_like(result.m)))[idx]
    C = avar_estimate_covariance(comps, theta, np.asarray(result.m)[idx],
                                 _n_samples(result)[idx], rate, stride)
    if predictive:
        # its parameters were estimated on other data (covariance Birge-scaled by the fit)
        C = C + X @ np.asarray(model.theta_cov, dtype=float) @ X.T
        # U² = θ̂ + z·se (``_upper_limit``): θ of a left-out term carries up to U²/z; a short
        # fit that cannot tell flicker from random walk must not predict either with confidence
        for k, comp in enumerate(comps):
            te = model.terms.get(comp.label)
            if te is not None and not te.present and te.upper:
                se = te.upper**2 / model.z_present
                C = C + se**2 * np.outer(X[:, k], X[:, k])
    if extra_cov is not None:
        C = C + np.asarray(extra_cov, dtype=float)[np.ix_(idx, idx)]
    r = _whitener(C) @ (var - X @ theta)
    return ModelChi2(float(r @ r), len(idx), tau)


def slope_method(result: Any) -> dict[str, float]:
    """The slope reading of the MATLAB example, allan_variance_ros and kalibr_allan.

    On log-log ADEV: the line of slope −½ through the point whose local slope is closest to
    −½, read at τ = 1 s → N; slope +½ through the point closest to +½, read at τ = 3 s → K;
    B = min ADEV / 0.664 (IEEE 952 Annex C). No uncertainty, biased where terms overlap.
    """
    var = np.asarray(result.var, dtype=float)
    if var.ndim != 1:
        raise FitError("slope_method takes one channel: pass result.channel(c)")
    tau = np.asarray(result.tau, dtype=float)
    ok = np.isfinite(var) & (var > 0)
    tau, adev = tau[ok], np.sqrt(var[ok])
    if len(tau) < 3:
        raise FitError("the slope method needs at least 3 averaging times")
    lt, la = np.log10(tau), np.log10(adev)
    slope = np.diff(la) / np.diff(lt)

    def line_at(target: float, tau_read: float) -> float:
        i = int(np.argmin(np.abs(slope - target)))
        b = la[i] - target * lt[i]
        return float(10 ** (target * math.log10(tau_read) + b))

    return {
        "velocity_random_walk": line_at(-0.5, 1.0),
        "bias_instability": float(adev.min() / mdl.BI_FACTOR),
        "rate_random_walk": line_at(0.5, 3.0),
    }

"""The long-τ check: a term the fit claims from its longest octaves refuted where the total (or
Theo) deviation beyond them shows a deficit."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from avard.core.errors import FitError
from avard.core.model.fit.problem import _n_samples
from avard.core.model.fit.results import LONG_TAU_TERMS, NOT_RESOLVED, Component, NoiseFit
from numpy.typing import NDArray


@dataclass(frozen=True)
class LongTauCurve:
    """A statistic measured at τ beyond the fit, to test the fitted model against
    (``refuted_by``): too few averages to fit, not too few to test.

    ``kind`` "oavar": the overlapping AVAR (the curve the fit read, or the live cascade's
    points beyond it), whose expectation is the model's AVAR. "totvar": TOTVAR (NIST SP 1065
    eq. 25), which reaches T/2 with more EDF but is biased low against the AVAR: by
    1 − a·τ/T for flicker and random-walk FM (§5.2.11, ``TOTVAR_BIAS``) and, for a ramp's
    deterministic part, by ``ramp_factor`` (its exact TOTVAR over its AVAR at each τ on the
    record's grid, ``total.ramp_totvar_ratio``: about 1 − 0.93·τ/T). ``record_s`` is T."""

    kind: str
    tau: NDArray[np.float64]  # s
    var: NDArray[np.float64]  # the statistic's variance estimate at each τ (input unit²)
    edf: NDArray[np.float64]  # its equivalent degrees of freedom
    record_s: float = math.inf
    ramp_factor: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        if self.kind not in ("oavar", "totvar"):
            raise FitError(f"long-τ curve kind {self.kind!r} is unknown; use 'oavar' or "
                           "'totvar'")


#: TOTVAR's bias against AVAR, 1 − a·τ/T, by the model component's cause (NIST SP 1065
#: §5.2.11: a = 1/(3 ln 2) for flicker FM, 3/4 for random-walk FM; 0 for white FM, and for
#: the components that are white at τ far beyond their corner or time constant). A
#: sinusoid's part is taken as its AVAR: at the τ tested its AVAR is small (it falls as
#: 1/τ² beyond its period) and only the differences reaching into the reflection differ.
TOTVAR_BIAS = {"bias_instability": 1.0 / (3.0 * math.log(2.0)),
               "lowpass_flicker": 1.0 / (3.0 * math.log(2.0)), "rate_random_walk": 0.75}


def _expected_columns(curve: LongTauCurve, comps: Sequence[Component],
                      rate: float) -> NDArray[np.float64]:
    """(τ, component): each component's part of the curve's expectation per unit θ."""
    tau = np.asarray(curve.tau, dtype=float)
    cols = np.column_stack([c.basis(tau, rate) for c in comps]) if comps else \
        np.zeros((len(tau), 0))
    if curve.kind == "oavar":
        return cols
    frac = tau / curve.record_s
    for i, c in enumerate(comps):
        if c.cause == "rate_ramp":
            if curve.ramp_factor is None:
                raise FitError("a TOTVAR curve needs the ramp's factor (ramp_factor)")
            cols[:, i] *= curve.ramp_factor
        elif c.cause in TOTVAR_BIAS:
            cols[:, i] *= np.clip(1.0 - TOTVAR_BIAS[c.cause] * frac, 0.0, 1.0)
    return cols


def _deficit_z(curve: LongTauCurve, comps: Sequence[Component], theta: NDArray,
               cov: NDArray, rate: float) -> NDArray[np.float64]:
    """How far below the fitted model each point of ``curve`` falls, in standard deviations
    (``refuted_by``). ``theta`` and ``cov`` over every component (zero where a component is
    absent or fixed).

    A rate ramp R rises as τ² at every τ, and its part of the AVAR estimate, R²τ²/2, is
    deterministic: it does not scatter. A slow periodic signal rises the same way below a
    quarter of its period and then turns down, so on 41 min of a `quiet-lab` record (a
    30-minute air-conditioning cycle) the fit read a ramp from τ ≤ 262 s that predicted
    2.3e-8 m²/s⁴ at τ = 1049 s, where the record measured 4.6e-10 (issue 24). The estimate
    at such a τ is taken as a non-central χ²: the noise part V_n of the model (its
    components with a spectrum) with the curve's EDF ν, plus the deterministic part S, so
    Var = (2V_n² + 4 S V_n)/ν (NIST SP 1065 §5.3 for V_n alone), to which the prediction's
    own uncertainty adds (x·Cov(θ)·xᵀ, the fit's final covariance: a ramp known to ±θ/z
    predicts to about S/z); z = (V_n + S − σ̂²)/√Var. A rate random walk, itself noise,
    scatters too much at two to eight averages to be refuted this way, which is right: a
    record that short cannot refute it."""
    cols = _expected_columns(curve, comps, rate)
    det = np.array([c.psd(rate) is None for c in comps], dtype=bool)
    th = np.asarray(theta, dtype=float)
    signal = cols[:, det] @ th[det] if det.any() else np.zeros(len(curve.tau))
    noise = cols[:, ~det] @ th[~det] if (~det).any() else np.zeros(len(curve.tau))
    pred = np.einsum("ka,ab,kb->k", cols, np.asarray(cov, dtype=float), cols)
    nu = np.asarray(curve.edf, dtype=float)
    sd = np.sqrt(np.maximum(2.0 * noise**2 + 4.0 * signal * noise, 0.0) / nu
                 + np.maximum(pred, 0.0))
    deficit = noise + signal - np.asarray(curve.var, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(sd > 0, deficit / sd, np.where(deficit > 0, np.inf, 0.0))


def refuted_by(fit: NoiseFit, curve: LongTauCurve, z_refute: float | None = None) -> bool:
    """Whether ``curve`` (τ beyond the fit) falls below the fitted model by more than
    ``z_refute`` standard deviations (default the fit's presence z: a term is refuted on
    the same evidence that makes it present) at any of its τ; see ``_deficit_z``. The one
    refutation of the long-τ terms, live and offline: ``fit_noise`` applies it to the τ its
    own curve holds beyond the fit, ``avard analyze`` also to the TOTVAR out to T/2
    (``core.analysis.long_tau_check``)."""
    if len(curve.tau) == 0:
        return False
    z = _deficit_z(curve, fit.components, fit.theta, fit.theta_cov, fit.rate_hz)
    return bool(np.any(z > (fit.z_present if z_refute is None else z_refute)))


def resolved_long_tau_terms(fit: NoiseFit) -> list[str]:
    """The long-τ terms (``LONG_TAU_TERMS``) the fit claims present with no note."""
    return [t for t in LONG_TAU_TERMS if t in fit.terms and fit.terms[t].present
            and fit.terms[t].note is None]


def with_long_tau_refuted(fit: NoiseFit) -> NoiseFit:
    """``fit`` with its present long-τ terms flagged ``NOT_RESOLVED`` (where no other note
    stands), as ``fit_noise`` flags them when the τ beyond its fit refute them."""
    from dataclasses import replace

    terms = {k: (replace(v, note=NOT_RESOLVED) if k in LONG_TAU_TERMS and v.present
                 and v.note is None else v) for k, v in fit.terms.items()}
    return replace(fit, terms=terms)


def _refuted_beyond(result: Any, last: int, comps: list[Component], fitted: list[int],
                    theta: NDArray, fixed: list[int], theta_fixed: NDArray,
                    active: list[int], cov: NDArray, rate: float, z_refute: float,
                    min_averages: float) -> bool:
    """Whether the τ the record measured beyond the fit (fewer than ``min_averages``
    averages: too few to fit, not too few to test) fall below the fitted model by more than
    ``z_refute`` standard deviations, which refutes the terms that make the long end; the
    curve's own points, as a "oavar" ``LongTauCurve``, through ``_deficit_z``."""
    tau = np.asarray(result.tau, dtype=float)
    var = np.asarray(result.var, dtype=float)
    edf = np.asarray(getattr(result, "edf", np.full_like(var, np.nan)), dtype=float)
    n = np.asarray(result.n, dtype=float)
    M = _n_samples(result)
    n_total = float(np.nanmax(M)) if len(M) else 0.0
    m = np.asarray(result.m, dtype=float)
    far = np.arange(last + 1, len(tau))
    far = far[np.isfinite(var[far]) & (var[far] > 0) & (n[far] > 0)
              & np.isfinite(edf[far]) & (edf[far] > 0) & (n_total / m[far] >= 2.0)
              & (n_total / m[far] < min_averages)]
    if len(far) == 0:
        return False
    theta_all = np.zeros(len(comps))
    theta_all[fitted] = theta
    theta_all[fixed] = theta_fixed
    act = [fitted[a] for a in active]
    cov_all = np.zeros((len(comps), len(comps)))
    cov_all[np.ix_(act, act)] = cov
    curve = LongTauCurve("oavar", tau[far], var[far], edf[far])
    return bool(np.any(_deficit_z(curve, comps, theta_all, cov_all, rate) > z_refute))

"""``fit_noise``: the IEEE noise terms fitted to one channel's AVAR, from the τ range the data
support (the filter's bend cut at short τ) to the terms present and their intervals."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from statistics import NormalDist
from typing import Any

import numpy as np
from avard.core.errors import FitError
from avard.core.model.fit.chi2 import _misfit
from avard.core.model.fit.components import _components, _covariance_kernels
from avard.core.model.fit.long_tau import _refuted_beyond
from avard.core.model.fit.problem import (
    _avar_cov,
    _fit_active,
    _gls_scaled,
    _n_samples,
    _Problem,
    _usable,
    _whitener,
)
from avard.core.model.fit.results import (
    LONG_TAU_TERMS,
    NOT_RESOLVED,
    RAMP_OR_WALK,
    ROUNDING,
    Component,
    NoiseFit,
    TermEstimate,
)
from avard.core.model.fit.select import _rests_on_longest, _select_terms
from avard.core.model.terms import TERMS, UNITS
from numpy.typing import ArrayLike


def _short_tau_cut(p: _Problem, comps: list[Component], fitted: list[int], rate_hz: float,
                   drop_z: float, max_drop: int) -> int:
    """Number of shortest τ to leave out because the sensor's low-pass bends them.

    A low-pass on white noise lowers the AVAR at a few samples by an amount falling like
    1/m (the bend of ``model.lowpass_white_avar`` is ≈ −c·N²τ0/τ²): a *negative* τ⁻² term,
    which quantization (positive τ⁻²) cannot produce. So while the remaining curve, fitted
    with the terms other than Q plus a free-signed τ⁻² "bend" column (GLS with the modelled
    covariance), shows a bend below zero by more than ``drop_z`` standard errors, the
    shortest point is left out; at most ``max_drop`` points go.
    """
    base = [j for j, a in enumerate(fitted) if comps[a].cause != "quantization"]
    K = p.X.shape[0]
    start = 0
    while start < max_drop and K - start >= len(base) + 3:
        idx = np.arange(start, K)
        _, _, C, _ = _fit_active(p, idx, base)
        T = _whitener(C)
        tau = p.m_tau[idx]
        X = np.column_stack([p.X[np.ix_(idx, np.asarray(base, dtype=np.intp))],
                             1.0 / (tau * rate_hz) ** 2])
        coef, cov = _gls_scaled(T @ X, T @ p.y[idx])
        se = math.sqrt(max(cov[-1, -1], 0.0))
        if se > 0 and coef[-1] / se < -drop_z:
            start += 1
        else:
            break
    return start


#: The Allan variances (any unit squared) the fit's arithmetic holds: its covariance takes
#: products of four of them
VAR_SCALE_MAX = 1e60


def fit_noise(
    result: Any,
    *,
    filter_corner_hz: float | None = None,
    terms: Sequence[str] = TERMS,
    extra: Sequence[Mapping] = (),
    tau_range: tuple[float, float] | None = None,
    ci: float = 0.683,
    z_present: float = 2.33,
    min_edf: float = 3.0,
    min_averages: float = 8.0,
    drop_z: float = 3.0,
    max_drop: int = 8,
    birge_scale: bool = True,
    rounding_lsb: float | None = None,
    filter_min_m: int = 2,
    added_cov: ArrayLike | None = None,
    check_filter: bool = True,
    upper_limits: bool = True,
    long_tau_notes: bool = True,
) -> NoiseFit:
    """Fit the IEEE terms (and ``extra`` components) to one channel's Allan variance.

    ``result``: a single-channel ``AllanResult`` (tau, m, stride, var, n, edf, rate_hz) of
    rate data in m/s². ``filter_corner_hz``: model the sensor's low-pass (ADXL355: ODR/4) on
    the white and the flicker (bias-instability) noise, so the fit starts at
    ``filter_min_m`` samples (2), instead of excluding the bent short τ.
    ``extra``: dicts
    ``{"cause": "sinusoid"|"gauss_markov"|"filter", "params": {...}}``; the nonlinear
    parameter (frequency_hz, T, corner_hz) is fixed, the amplitude-like one (amplitude,
    sigma, N) is fitted unless given. ``tau_range``: (min, max) seconds to restrict the
    automatic range further. ``rounding_lsb``: the record's LSB (m/s²) when it is known to be
    rounded after the sensor's filter (ADXL355 output): the rounding adds unfiltered white
    noise of LSB²/12 per sample, a fixed component; N is then reported as the white level of
    the output, √(N_filtered² + LSB²/(12·fs)), the N a datasheet or the slope method gives.
    ``added_cov``: a (len(tau), len(tau)) covariance of the AVAR points from outside the
    noise model, added to the modelled one wherever the fit uses it (GLS weights, χ², the
    presence test, the intervals): ``avard explain`` passes the uncertainty of a signal it
    removed before refitting (a temperature coupling, a warm-up), so that the extended fit's
    intervals carry it.
    With ``filter_corner_hz`` (and ``check_filter``, False when a user named the corner),
    the filter model is checked against the curve: when it misfits (χ² upper tail < 1e-3)
    and the curve fitted without it shows no bent short τ, the fit without it is returned
    (``filter_corner_hz`` None: the record has no such filter).
    ``upper_limits`` False: the absent terms' upper limits are not computed (their
    ``upper`` None; every other field the same), for a caller that reads only the
    likelihood and the extra components (the Gauss–Markov scan's profile fits).
    ``long_tau_notes`` False: whether the present long-τ terms rest on the longest τ alone
    (a fit without it) or are refuted by the τ beyond the fit is not checked (their
    ``note`` stays None; every number the same), for the same callers.
    See the module docstring for the method and the tests.
    """
    var = np.asarray(result.var, dtype=float)
    if var.ndim != 1:
        raise FitError("fit_noise takes one channel: pass result.channel(c)")
    rate = float(result.rate_hz)
    if not (math.isfinite(rate) and rate > 0):
        raise FitError(f"sample rate {rate} Hz is not a positive number")
    tau = np.asarray(result.tau, dtype=float)
    m = np.asarray(result.m, dtype=np.int64)
    M = _n_samples(result)
    keep = _usable(result, min_edf, min_averages, tau_range)
    extra = list(extra)
    n_q2 = 0.0
    if rounding_lsb is not None:
        if not (math.isfinite(rounding_lsb) and rounding_lsb > 0):
            raise FitError(f"rounding_lsb {rounding_lsb} m/s² is not a positive number")
        n_q2 = rounding_lsb**2 / (12.0 * rate)
        extra.append({"cause": "white", "label": ROUNDING, "params": {"N": math.sqrt(n_q2)}})
    comps = _components(terms, extra, filter_corner_hz, rate)
    fitted = [i for i, c in enumerate(comps) if c.fixed_value is None]
    fixed = [i for i, c in enumerate(comps) if c.fixed_value is not None]
    pos = var[np.isfinite(var) & (var > 0)]
    infinite = bool(np.any(np.isinf(var)))
    if infinite or (len(pos) and (pos.max() > VAR_SCALE_MAX or pos.min() < 1.0 / VAR_SCALE_MAX)):
        # the data's scale, not its noise (a constant channel's AVAR is zero, not infinite):
        # squares beyond float64, or a covariance whose products over- or underflow in the
        # fit's linear algebra (a LinAlgError from an eigen-solve had escaped)
        raise FitError("the Allan variance is "
                       + ("infinite at some τ" if infinite else
                          f"{pos.min():.3g} to {pos.max():.3g}")
                       + ": values this large or small are beyond the fit's float64 "
                       "arithmetic; check the data's scale and units (m/s²)")
    if not len(pos):
        # zero Allan variance at every τ: a longer record would not help
        raise FitError("the Allan variance is zero at every τ: the channel is constant (no "
                       "noise to fit); check the sensor, or leave the channel out (--channels)")
    if len(keep) < len(fitted) + 2:
        raise FitError(
            f"only {len(keep)} usable averaging times for {len(fitted)} model terms; record "
            "a longer data set or fit fewer terms"
        )
    t_k = tau[keep]
    X = np.column_stack([comps[i].basis(t_k, rate) for i in fitted])
    fixed_avar = np.zeros(len(keep))
    theta_fixed = np.array([float(comps[i].fixed_value or 0.0) ** 2 for i in fixed])
    for i, th in zip(fixed, theta_fixed, strict=True):
        fixed_avar += th * comps[i].basis(t_k, rate)
    stride = np.asarray(getattr(result, "stride", np.ones_like(m)), dtype=np.int64)
    G = _covariance_kernels([comps[i] for i in fitted] + [comps[i] for i in fixed], m[keep],
                            stride[keep], M[keep], rate)
    added = None
    if added_cov is not None:
        full = np.asarray(added_cov, dtype=float)
        if full.shape != (len(tau), len(tau)) or not np.all(np.isfinite(full)):
            raise FitError(f"added_cov must be a finite ({len(tau)}, {len(tau)}) matrix, got "
                           f"shape {full.shape}")
        added = full[np.ix_(keep, keep)]
    p = _Problem(y=var[keep] - fixed_avar, X=X, fixed=fixed_avar, G=G,
                 theta_fixed=theta_fixed, M=M[keep], edf_floor=100.0 * M[keep], m_tau=t_k,
                 added=added)

    K = len(keep)
    A = len(fitted)
    start = 0
    if filter_corner_hz is None:
        start = _short_tau_cut(p, comps, fitted, rate, drop_z, max_drop)
    else:
        # The one-sample point hangs on the spectrum right at Nyquist, where neither the
        # chip's filter (the datasheet gives only its corner) nor the 1/f model is pinned
        # down; fitted, it turned a 0.1 % difference there into a false quantization term
        # on 10 of 10 X/Y axes of 60 h paper-table3 records, none from two samples on.
        start = int(np.searchsorted(m[keep], filter_min_m))
    idx = np.arange(start, K)

    labels = [comps[a].label for a in fitted]
    ramp = labels.index("rate_ramp") if "rate_ramp" in labels else None
    walk = labels.index("rate_random_walk") if "rate_random_walk" in labels else None
    active, z_all, upper, ambiguous = _select_terms(p, idx, A, z_present, ramp, walk,
                                                    upper_limits)
    # kept in the model (the curve needs them), but flagged: a display says "not yet
    # resolved" instead of an interval and a time to target
    unresolved = [a for a in active if long_tau_notes and labels[a] in LONG_TAU_TERMS
                  and _rests_on_longest(p, idx, active, a, z_present**2, ramp, walk)]
    if active:
        theta, cov, C, chi2 = _fit_active(p, idx, active)
    else:
        theta, cov = np.zeros(A), np.zeros((0, 0))
        C = _avar_cov(p, theta, idx)
        r = _whitener(C) @ p.y[idx]
        chi2 = float(r @ r)
    sign, log_det = np.linalg.slogdet(C)
    dof = len(idx) - len(active)
    chi2_dof = chi2 / dof if dof > 0 else float("nan")
    # Birge ratio: when the residuals scatter more than their modelled covariance allows, the
    # intervals widen by √(χ²/dof) (never narrow); a misfit model then reports honest,
    # larger uncertainties instead of precise wrong ones.
    birge = math.sqrt(chi2_dof) if math.isfinite(chi2_dof) and chi2_dof > 1 else 1.0
    if birge_scale:
        cov = cov * birge**2
    # A deterministic term's interval is never narrower than its presence test's evidence:
    # present at z = √Δχ² it is known to about θ/z. The model's own covariance can claim far
    # less, since a ramp or a sinusoid adds no scatter of its own to the AVAR estimates: ±2 %
    # on a ramp whose test gave z = 3.3 (issue 24). (The noise terms keep their sandwich
    # intervals, whose coverage tests/core/test_fit_coverage.py measures.) Rows and columns
    # scale together, so the correlations stay.
    if active:
        th_a = theta[active]
        z_a = np.array([z_all[a] if np.isfinite(z_all[a]) and z_all[a] > 0
                        and comps[fitted[a]].psd(rate) is None else np.inf for a in active])
        se_now = np.sqrt(np.maximum(np.diag(cov), 0.0))
        floor = np.where(np.isfinite(z_a), th_a / z_a, 0.0)
        grow = np.where((se_now > 0) & (floor > se_now), floor / np.maximum(se_now, 1e-300),
                        1.0)
        cov = cov * np.outer(grow, grow)
    se_active = np.sqrt(np.maximum(np.diag(cov), 0.0))
    if long_tau_notes and active and _refuted_beyond(
            result, keep[idx[-1]], comps, fitted, theta, fixed, theta_fixed, active, cov,
            rate, z_present, min_averages):
        unresolved += [a for a in active if labels[a] in LONG_TAU_TERMS and a not in unresolved]

    # the standard normal quantile from the standard library: importing scipy.stats for it
    # cost `avard analyze` 0.4–0.9 s of CPU and ~25 MB
    zci = NormalDist().inv_cdf(0.5 + ci / 2.0)
    est: dict[str, TermEstimate] = {}
    extras: list[dict[str, Any]] = []
    sinusoids: list[dict[str, float | None]] = []
    theta_all = np.zeros(len(comps))
    for j, a in enumerate(fitted):
        theta_all[a] = theta[j]
    for i, th in zip(fixed, theta_fixed, strict=True):
        theta_all[i] = th
    for j, a in enumerate(fitted):
        comp = comps[a]
        present = j in active and theta[j] > 0
        if present:
            s = se_active[active.index(j)]
            # the white level of the output includes the (known, fixed) rounding noise
            q = n_q2 if comp.label == "velocity_random_walk" else 0.0
            val = math.sqrt(theta[j] + q)
            lo = math.sqrt(max(theta[j] - zci * s, 0.0) + q)
            hi = math.sqrt(theta[j] + zci * s + q)
            te = TermEstimate(val, lo, hi, comp.unit, True, float(z_all[j]))
            if ambiguous and j in (ramp, walk):
                te.note = RAMP_OR_WALK
            elif j in unresolved:
                te.note = NOT_RESOLVED
        else:
            theta_all[a] = 0.0
            te = TermEstimate(None, None, None, comp.unit, False,
                              None if np.isnan(z_all[j]) else float(z_all[j]),
                              None if np.isnan(upper[j]) else math.sqrt(max(upper[j], 0.0)),
                              RAMP_OR_WALK if ambiguous and j in (ramp, walk) else None)
        if comp.label in TERMS:
            est[comp.label] = te
        else:
            info = {"cause": comp.cause, "label": comp.label,
                    "params": {**comp.params, comp.value_key: te.value}, "present": present,
                    "lo": te.lo, "hi": te.hi, "unit": te.unit}
            extras.append(info)
            if comp.cause == "sinusoid" and present:
                sinusoids.append({"frequency_hz": comp.params["frequency_hz"],
                                  "amplitude": te.value, "lo": te.lo, "hi": te.hi})
    for i in fixed:
        comp = comps[i]
        extras.append({"cause": comp.cause, "label": comp.label,
                       "params": {**comp.params, comp.value_key: comp.fixed_value},
                       "present": True, "lo": None, "hi": None, "unit": comp.unit,
                       "fixed": True})
    for t in TERMS:
        est.setdefault(t, TermEstimate(None, None, None, UNITS[t], False))
    full_cov = np.zeros((len(comps), len(comps)))
    act = [fitted[j] for j in active]
    full_cov[np.ix_(act, act)] = cov
    fit = NoiseFit(
        terms=est, sinusoids=sinusoids, extra=extras,
        tau_min_s=float(t_k[idx[0]]), tau_max_s=float(t_k[idx[-1]]), chi2_dof=float(chi2_dof),
        rate_hz=rate, filter_corner_hz=filter_corner_hz, n_points=len(idx), dof=dof, ci=ci,
        z_present=z_present, components=comps, theta=theta_all, theta_cov=full_cov,
        log_det_cov=float(log_det) if sign > 0 else math.nan,
    )
    if filter_corner_hz is None or not check_filter or not _misfit(fit):
        return fit
    # The filter model, checked against the curve: misfitting, while the curve fitted
    # without it shows no bent short τ at all, means the record has no such filter (a white
    # + random-walk record without one, read as an ADXL355 record, gave χ²/dof 5–10, a
    # false quantization term and "the five-term model does not describe this curve";
    # issue 24). The fit without it is then returned (its filter_corner_hz None).
    plain = fit_noise(result, terms=terms, extra=extra, tau_range=tau_range, ci=ci,
                      z_present=z_present, min_edf=min_edf, min_averages=min_averages,
                      drop_z=drop_z, max_drop=max_drop, birge_scale=birge_scale,
                      rounding_lsb=rounding_lsb, filter_min_m=filter_min_m,
                      added_cov=added_cov, upper_limits=upper_limits,
                      long_tau_notes=long_tau_notes)
    unbent = plain.tau_min_s <= float(tau[keep[0]])
    better = not _misfit(plain) or plain.chi2_dof < 0.5 * fit.chi2_dof
    return plain if unbent and better else fit

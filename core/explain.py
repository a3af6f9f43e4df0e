"""`avard explain`: where the IEEE noise model disagrees with a measurement, why, and what
naming the cause gains on data the extension was not fitted on.

Pipeline per channel (issue 6):

1. Measure: overlapping AVAR (NIST SP 1065 eq. 12) on a half-octave τ grid with
   Greenhall–Riley EDF and χ² intervals (NIST SP 1065 eq. 40).
2. Base model: the five IEEE terms (IEEE 952 Annex C) fitted to the AVAR by EDF-weighted
   non-negative least squares, iteratively reweighted with var(σ̂²) = 2σ⁴/ν (allan.md).
   Band: the model's own χ² interval with the estimator's EDF.
3. Misfit: contiguous τ ranges where the measurement leaves the band, with the largest
   deviation in sigmas z = (σ̂² − σ²)/(σ²√(2/ν)).
4. Causes: the detectors of :mod:`avard.core.causes`, in a fixed order, one acceptance at a
   time; after each acceptance the data are corrected (temperature, steps, warm-up, drifts)
   or the model gains a component (sinusoid, Gauss–Markov, filter, quantization), and every
   detector runs again on what is left.
5. Extend: refit the five terms to the corrected data with the accepted components.
6. Gain: EDF-weighted χ² per degree of freedom of base over extended model, on the data used
   to fit and on held-out data. Without ``holdout`` the models are refitted on the first half
   and predict the second half (cause parameters as found on the whole record, so events
   anywhere in it can be named); with ``holdout`` the models fitted on the whole record predict
   the other record. A cause whose removal makes the held-out χ² better (by more than its
   scatter 2√(2/K)) is not claimed.

Gains are ratios: 1 = no change, 3 = the extended model's misfit is a third of the base's.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import nnls
from scipy.stats import chi2 as chi2_dist

from . import causes as cz
from . import model
from .errors import DataError

log = logging.getLogger(__name__)

MISFIT_SIGMA = 3.0
MIN_SAMPLES = 1 << 12


# --------------------------------------------------------------------------------------------
# measurement


@dataclass
class Measured:
    """AVAR of one channel: tau (s), m, var ((m/s²)²), edf and the 68.3 % χ² interval."""

    tau: NDArray
    m: NDArray
    var: NDArray
    edf: NDArray
    lo: NDArray
    hi: NDArray
    n: int
    rate_hz: float


def measure(y: NDArray, rate_hz: float, m: NDArray | None = None) -> Measured:
    """Overlapping AVAR with EDF and χ² interval (see module doc)."""
    y = np.asarray(y, dtype=np.float64)
    if m is None:
        m = cz.tau_grid(len(y), rate_hz)
    v = cz.oavar(y, rate_hz, m)
    v = np.maximum(v, 1e-300)
    edf = cz.avar_edf(v, m, len(y))
    lo = edf * v / chi2_dist.ppf(0.5 + 0.683 / 2, edf)
    hi = edf * v / chi2_dist.ppf(0.5 - 0.683 / 2, edf)
    return Measured(m / rate_hz, m, v, edf, lo, hi, len(y), rate_hz)


# --------------------------------------------------------------------------------------------
# fitting the IEEE terms (plus component columns)


@dataclass
class Fit:
    """The five IEEE terms and extra components fitted to one AVAR curve."""

    coef: NDArray  # θ per column (value² of each term / component)
    cov: NDArray  # covariance of θ from the weighted normal equations (optimistic)
    columns: list[str]  # TERMS then one name per extra component
    extra: list[dict]  # {"cause", "params"} of components that enter the model
    filter_hz: float | None
    fixed_fn: Callable[[NDArray], NDArray]
    rate_hz: float
    chi2: float = 0.0
    dof: int = 1

    def design(self, tau: NDArray) -> NDArray:
        return _design(tau, self.rate_hz, self.extra, self.filter_hz)

    def avar(self, tau: NDArray) -> NDArray:
        """Model AVAR of the noise and model-side components at ``tau`` (s)."""
        return self.design(tau) @ self.coef + self.fixed_fn(tau)

    @property
    def chi2_dof(self) -> float:
        return self.chi2 / max(self.dof, 1)

    def terms(self) -> dict[str, dict[str, Any]]:
        """Coefficients as in `avard analyze`: value, 68.3 % interval, SI unit, present."""
        out = {}
        for i, name in enumerate(model.TERMS):
            th, sd = float(self.coef[i]), math.sqrt(max(float(self.cov[i, i]), 0.0))
            present = th > 0 and th - sd > 0
            out[name] = {
                "value": math.sqrt(th) if th > 0 else None,
                "lo": math.sqrt(max(th - sd, 0.0)) if th > 0 else None,
                "hi": math.sqrt(th + sd) if th > 0 else None,
                "unit": model.UNITS[name],
                "present": bool(present),
            }
        return out

    def extra_out(self) -> list[dict]:
        """Extra components with their refitted amplitudes."""
        out = []
        k = len(model.TERMS)
        for comp in self.extra:
            p = dict(comp["params"])
            if comp["cause"] == "sinusoid":
                p["amplitude"] = math.sqrt(max(float(self.coef[k]), 0.0))
                k += 1
            elif comp["cause"] == "gauss_markov":
                p["sigma"] = math.sqrt(max(float(self.coef[k]), 0.0))
                k += 1
            out.append({"cause": comp["cause"], "params": p})
        return out


def _design(tau: NDArray, rate_hz: float, extra: list[dict], filter_hz: float | None) -> NDArray:
    cols = [3.0 / tau**2]
    if filter_hz is not None:
        cols.append(model.lowpass_white_avar(tau, 1.0, rate_hz, filter_hz))
    else:
        cols.append(1.0 / tau)
    cols += [np.full_like(tau, model.BI_FACTOR**2), tau / 3.0, tau**2 / 2.0]
    for comp in extra:
        p = comp["params"]
        if comp["cause"] == "sinusoid":
            cols.append(model.sinusoid_avar(tau, 1.0, p["frequency_hz"]))
        elif comp["cause"] == "gauss_markov":
            cols.append(model.gauss_markov_avar(tau, 1.0, p["time_constant_s"]))
    return np.column_stack(cols)


def _zero(tau: NDArray) -> NDArray:
    return np.zeros_like(np.asarray(tau, dtype=float))


def fit_terms(meas: Measured, *, extra: Sequence[dict] = (), filter_hz: float | None = None,
              fixed_fn: Callable[[NDArray], NDArray] = _zero, n_params_extra: int = 0,
              columns_extra: Sequence[NDArray] = ()) -> Fit:
    """EDF-weighted NNLS of AVAR on the term columns (θ = value²), reweighted three times with
    the model itself (var(σ̂²) ≈ 2σ⁴/ν). ``columns_extra`` are trial columns (detectors)."""
    tau, v, edf = meas.tau, meas.var, meas.edf
    a = _design(tau, meas.rate_hz, list(extra), filter_hz)
    if columns_extra:
        a = np.column_stack([a, *columns_extra])
    fixed = fixed_fn(tau)
    ref = v.copy()
    coef = np.zeros(a.shape[1])
    for _ in range(4):
        w = np.sqrt(edf / 2.0) / ref
        aw = a * w[:, None]
        scale = np.linalg.norm(aw, axis=0)
        scale[scale == 0] = 1.0
        sol, _ = nnls(aw / scale, (v - fixed) * w, maxiter=50 * a.shape[1])
        coef = sol / scale
        ref = np.maximum(a @ coef + fixed, 1e-3 * v)
    model_v = a @ coef + fixed
    active = coef > 0
    cov = np.zeros((a.shape[1], a.shape[1]))
    if np.any(active):
        w = np.sqrt(edf / 2.0) / model_v
        aw = (a * w[:, None])[:, active]
        try:
            cov_a = np.linalg.pinv(aw.T @ aw)
            cov[np.ix_(active, active)] = cov_a
        except np.linalg.LinAlgError:  # pragma: no cover - pinv does not raise in practice
            pass
    names = list(model.TERMS) + [c["cause"] for c in extra]
    fit = Fit(coef, cov, names, [dict(c) for c in extra], filter_hz, fixed_fn, meas.rate_hz)
    fit.chi2 = cz.chi2(v, model_v, edf)
    fit.dof = len(tau) - int(np.count_nonzero(active)) - n_params_extra
    return fit


def misfit_ranges(meas: Measured, model_v: NDArray, sigma: float = MISFIT_SIGMA) -> list[dict]:
    """Contiguous τ ranges where |z| ≥ sigma, z = (σ̂² − σ²)/(σ²√(2/ν)), with the largest |z|."""
    z = (meas.var - model_v) / (model_v * np.sqrt(2.0 / meas.edf))
    out: list[dict] = []
    i = 0
    while i < len(z):
        if abs(z[i]) >= sigma:
            j = i
            while j + 1 < len(z) and abs(z[j + 1]) >= sigma and np.sign(z[j + 1]) == np.sign(z[i]):
                j += 1
            k = i + int(np.argmax(np.abs(z[i: j + 1])))
            out.append({"tau_range_s": [float(meas.tau[i]), float(meas.tau[j])],
                        "max_sigma": float(z[k]),
                        "direction": "above" if z[k] > 0 else "below"})
            i = j + 1
        else:
            i += 1
    return out


def band(meas: Measured, model_v: NDArray, ci: float = 0.683) -> tuple[NDArray, NDArray]:
    """Where the measurement should fall if the model were right: σ²·χ²_ν(q)/ν."""
    e = meas.edf
    return (model_v * chi2_dist.ppf(0.5 - ci / 2, e) / e,
            model_v * chi2_dist.ppf(0.5 + ci / 2, e) / e)


# --------------------------------------------------------------------------------------------
# the state of an explanation: what is removed from the data and what enters the model


@dataclass
class Segment:
    """A stretch of data the model is evaluated on: rate data, temperatures, the time of its
    first sample in the explained record (s), and whether it starts at power-on."""

    y: NDArray
    temps: NDArray | None
    t0_s: float
    starts_record: bool


@dataclass
class Accepted:
    causes: list[cz.Candidate] = field(default_factory=list)

    def removed_signal(self, seg: Segment, rate_hz: float, skip: str | None = None) -> NDArray:
        """The deterministic part the accepted causes put into this segment."""
        n = len(seg.y)
        d = np.zeros(n)
        for i, c in enumerate(self.causes):
            if skip is not None and _key(i, c) == skip:
                continue
            p = c.params
            if c.cause == "temperature" and seg.temps is not None:
                d += cz.temperature_signal(seg.temps, c.detail["channel"], p["coefficient"],
                                           p["lag_s"], rate_hz)
            elif c.cause == "bias_step":
                d += cz.step_signal(n, rate_hz, p["time_s"], p["size"], seg.t0_s)
            elif c.cause == "warmup":
                t0 = seg.t0_s if not seg.starts_record else 0.0
                d += cz.warmup_signal(n, rate_hz, p["time_constant_s"], p["size"], t0)
            elif c.cause == "rate_ramp":
                d += cz.ramp_signal(n, rate_hz, p["slope"], seg.t0_s)
        return d

    def model_parts(self, rate_hz: float, skip: str | None = None
                    ) -> tuple[list[dict], float | None, Callable[[NDArray], NDArray], int]:
        extra, filt, lsbs, npar = [], None, [], 0
        for i, c in enumerate(self.causes):
            if skip is not None and _key(i, c) == skip:
                continue
            npar += len(c.params)
            if c.cause in ("sinusoid", "gauss_markov"):
                extra.append({"cause": c.cause, "params": dict(c.params)})
            elif c.cause == "filter":
                filt = c.params["bandwidth_hz"]
            elif c.cause == "quantization":
                lsbs.append(c.params["lsb"])

        def fixed(tau: NDArray) -> NDArray:
            out = np.zeros_like(np.asarray(tau, dtype=float))
            for q in lsbs:
                out += cz.quantization_avar(tau, q, rate_hz)
            return out

        return extra, filt, fixed, npar


def _key(i: int, c: cz.Candidate) -> str:
    return f"{i}:{c.cause}"


def _fit_extended(seg: Segment, acc: Accepted, rate_hz: float, m: NDArray,
                  skip: str | None = None) -> tuple[Fit, Measured]:
    """Remove the accepted deterministic causes from the segment and fit the noise terms plus
    the accepted model components to what is left; returns the fit and that measurement."""
    d = acc.removed_signal(seg, rate_hz, skip)
    meas = measure(seg.y - d, rate_hz, m)
    extra, filt, fixed, npar = acc.model_parts(rate_hz, skip)
    fit = fit_terms(meas, extra=extra, filter_hz=filt, fixed_fn=fixed, n_params_extra=npar)
    return fit, meas


def _predict_raw(fit: Fit, seg: Segment, acc: Accepted, rate_hz: float, m: NDArray,
                 skip: str | None = None) -> NDArray:
    """The model's AVAR of the raw segment: the noise model plus the AVAR of what the
    accepted causes (parameters unchanged) put into this segment. Nothing is fitted here;
    the cross term between noise and the removed signal has zero mean and is left out."""
    v = fit.avar(m / rate_hz)
    d = acc.removed_signal(seg, rate_hz, skip)
    if np.any(d):
        v = v + cz.oavar(d, rate_hz, m)
    return v


# --------------------------------------------------------------------------------------------
# detection loop


ORDER = ("quantization", "sinusoid", "filter", "temperature", "warmup", "bias_step",
         "rate_ramp", "gauss_markov")
#: causes that may be found more than once (several lines, several steps)
REPEATABLE = ("sinusoid", "bias_step")
#: causes that must improve the held-out misfit (see the claim rule in explain_channel)
GAIN_REQUIRED = ("sinusoid", "gauss_markov")


def _fmt_params(p: dict[str, float]) -> str:
    return "{" + ", ".join(f"{k}: {v:.4g}" for k, v in p.items()) + "}"
MAX_FINDINGS = 8


def _detect_all(seg: Segment, rate_hz: float, temp_names: list[str], m: NDArray,
                raw: Measured) -> tuple[Accepted, list[cz.Candidate], Measured]:
    """Run the detectors until none passes; returns the accepted causes, the last test of
    every cause, and the AVAR of the data with the accepted causes removed."""
    acc = Accepted()
    tested: dict[str, cz.Candidate] = {}
    record_s = len(seg.y) / rate_hz
    meas = raw
    for it in range(MAX_FINDINGS + 1):
        work = seg.y - acc.removed_signal(seg, rate_hz)
        if it > 0 and any(c.cause in cz.REMOVED for c in acc.causes):
            meas = measure(work, rate_hz, m)
        if it == MAX_FINDINGS:
            break
        extra, filt, fixed, _npar = acc.model_parts(rate_hz)
        cur = fit_terms(meas, extra=extra, filter_hz=filt, fixed_fn=fixed)
        cur_v = cur.avar(meas.tau)
        have = {c.cause for c in acc.causes}
        fits: dict | None = None
        found = None
        for cause in ORDER:
            if cause in have and cause not in REPEATABLE:
                continue
            if cause == "quantization":
                cand = cz.detect_quantization(seg.y, rate_hz)
            elif cause == "sinusoid":
                ex = tuple(c.detail["band_hz"] for c in acc.causes if c.cause == "sinusoid")
                cand = cz.detect_sinusoid(work, rate_hz, meas.tau, cur_v, meas.edf, ex)
            elif cause == "filter":
                fixed_v = fixed(meas.tau) + sum(
                    (model.sinusoid_avar(meas.tau, c.params["amplitude"], c.params["frequency_hz"])
                     for c in acc.causes if c.cause == "sinusoid"), np.zeros(len(meas.tau)))
                cand = cz.detect_filter(meas.tau, meas.var, meas.edf, rate_hz, fixed_v)
            elif cause == "temperature":
                cand = cz.detect_temperature(work, rate_hz, seg.temps, temp_names)
            elif cause in ("warmup", "bias_step"):
                fits = fits or cz._transient_fits(work, rate_hz)
                cand = (cz.detect_warmup(work, rate_hz, fits) if cause == "warmup"
                        else cz.detect_bias_step(work, rate_hz, fits))
            elif cause == "rate_ramp":
                cand = cz.detect_rate_ramp(work, rate_hz)
            else:  # gauss_markov
                def fit_fn(cols: list[NDArray], _meas=meas, _e=extra, _f=filt, _x=fixed
                           ) -> tuple[NDArray, NDArray]:
                    f = fit_terms(_meas, extra=_e, filter_hz=_f, fixed_fn=_x, columns_extra=cols)
                    a = f.design(_meas.tau)
                    if cols:
                        a = np.column_stack([a, *cols])
                    return a @ f.coef + _x(_meas.tau), f.coef

                cand = cz.detect_gauss_markov(meas.tau, meas.var, meas.edf, fit_fn, record_s)
            if cause not in tested or cand.passed:
                tested[cause] = cand
            if cand.passed:
                found = cand
                break
        if found is None:
            break
        log.info("accepted %s %s", found.cause, found.params)
        acc.causes.append(found)
    return acc, list(tested.values()), meas


# --------------------------------------------------------------------------------------------
# the result


@dataclass
class ChannelExplanation:
    name: str
    measured: Measured
    base: Fit
    base_model: NDArray
    misfit: list[dict]
    findings: list[dict]
    tests: list[cz.Candidate]
    extended: Fit
    extended_model: NDArray  # prediction of the raw data's AVAR
    gain: float
    holdout_gain: float | None
    holdout_chi2: dict[str, float] = field(default_factory=dict)
    dropped: list[str] = field(default_factory=list)

    def to_json(self) -> dict:
        return {
            "base": {"terms": self.base.terms(), "chi2_dof": self.base.chi2_dof},
            "findings": self.findings,
            "extended": {"terms": self.extended.terms(), "extra": self._extra(),
                         "chi2_dof": self.extended.chi2_dof},
            "gain": self.gain,
            "holdout_gain": self.holdout_gain,
        }

    def _extra(self) -> list[dict]:
        return [{"cause": f["cause"], "params": f["params"]} for f in self.findings]


@dataclass
class Explanation:
    channels: dict[str, ChannelExplanation]
    rate_hz: float
    source: str
    holdout_source: str | None
    #: AVAR of each temperature channel (K²), for the report: the witness's own stability
    temperature: dict[str, Measured] = field(default_factory=dict)

    def to_json(self) -> dict:
        return {"channels": {k: v.to_json() for k, v in self.channels.items()}}


def _as_arrays(record: Any) -> tuple[NDArray, float, list[str], NDArray | None, list[str]]:
    accel = np.asarray(record.accel, dtype=np.float64)
    if accel.ndim == 1:
        accel = accel[:, None]
    rate = float(record.rate_hz)
    names = list(getattr(record, "names", None) or [f"ch{i}" for i in range(accel.shape[1])])
    temps = getattr(record, "temperature_c", None)
    tnames = list(getattr(record, "temperature_names", None) or [])
    if temps is not None:
        temps = np.asarray(temps, dtype=np.float64).reshape(len(accel), -1)
        good = np.all(np.isfinite(temps), axis=0)
        if not np.all(good):
            # a temperature channel with gaps cannot witness: forward-fill short gaps
            for j in np.flatnonzero(~good):
                col = temps[:, j]
                ok = np.isfinite(col)
                if np.count_nonzero(ok) < 2:
                    col[:] = 0.0
                else:
                    col[~ok] = np.interp(np.flatnonzero(~ok), np.flatnonzero(ok), col[ok])
        tnames += [f"T{i}" for i in range(len(tnames), temps.shape[1])]
    if not np.all(np.isfinite(accel)):
        raise DataError("the acceleration contains NaN or inf samples; cut them out or fill "
                        "the gap before running explain")
    if len(accel) < MIN_SAMPLES:
        raise DataError(f"{len(accel)} samples are too few to explain; record at least "
                        f"{MIN_SAMPLES} samples (several minutes)")
    if not rate > 0:
        raise DataError(f"sample rate {rate} Hz must be > 0")
    return accel, rate, names, temps, tnames


def _contribution(c: cz.Candidate, fit: Fit, seg: Segment, m: NDArray, rate_hz: float
                  ) -> NDArray:
    tau = m / rate_hz
    p = c.params
    if c.cause in cz.REMOVED:
        one = Accepted([c])
        d = one.removed_signal(seg, rate_hz)
        return cz.oavar(d, rate_hz, m) if np.any(d) else np.zeros(len(m))
    if c.cause == "sinusoid":
        return model.sinusoid_avar(tau, p["amplitude"], p["frequency_hz"])
    if c.cause == "gauss_markov":
        return model.gauss_markov_avar(tau, p["sigma"], p["time_constant_s"])
    if c.cause == "quantization":
        return cz.quantization_avar(tau, p["lsb"], rate_hz)
    # filter: how far the low-pass moves the white line
    n2 = float(fit.coef[1])
    return np.abs(model.lowpass_white_avar(tau, 1.0, rate_hz, p["bandwidth_hz"]) - 1.0 / tau) * n2


def explain_channel(y: NDArray, rate_hz: float, temps: NDArray | None, temp_names: list[str],
                    name: str = "x", holdout: tuple[NDArray, NDArray | None] | None = None
                    ) -> ChannelExplanation:
    """Run the whole pipeline on one channel (see module doc)."""
    n = len(y)
    m = cz.tau_grid(n, rate_hz)
    whole = Segment(y, temps, 0.0, True)
    meas = measure(y, rate_hz, m)
    base = fit_terms(meas)
    base_v = base.avar(meas.tau)
    misfit = misfit_ranges(meas, base_v)

    acc, tests, _ = _detect_all(whole, rate_hz, temp_names, m, meas)

    # held-out evaluation (and the claim rule)
    if holdout is not None:
        fit_seg = whole
        ho_seg = Segment(holdout[0], holdout[1], 0.0, True)
        m_fit = m
    elif n // 2 >= MIN_SAMPLES:
        h = n // 2
        fit_seg = Segment(y[:h], None if temps is None else temps[:h], 0.0, True)
        ho_seg = Segment(y[h:], None if temps is None else temps[h:], h / rate_hz, False)
        m_fit = cz.tau_grid(h, rate_hz)
    else:
        fit_seg = ho_seg = None
    ho: tuple[float, float] | None = None
    dropped: list[str] = []
    if fit_seg is not None and ho_seg is not None:
        m_ho = cz.tau_grid(len(ho_seg.y), rate_hz)
        m_ho = m_ho[m_ho <= m_fit[-1]]
        ho_meas = measure(ho_seg.y, rate_hz, m_ho)
        base_fit_part = fit_terms(measure(fit_seg.y, rate_hz, m_fit))
        pred_base = base_fit_part.avar(ho_meas.tau)

        def z2(pred: NDArray) -> NDArray:
            """Per-τ χ² terms (ν/2)(σ̂²/σ² − 1)² of a prediction of the held-out AVAR."""
            r = ho_meas.var / pred - 1.0
            return 0.5 * ho_meas.edf * r * r

        def ho_ext(a: Accepted, skip: str | None = None) -> tuple[NDArray, Fit | None]:
            if not [c for i, c in enumerate(a.causes) if _key(i, c) != skip]:
                return pred_base, None
            e, _ = _fit_extended(fit_seg, a, rate_hz, m_fit, skip)
            return _predict_raw(e, ho_seg, a, rate_hz, m_ho, skip), e

        pred_e, fit_e = ho_ext(acc)
        # Claim rule. A component that adds AVAR of its own (a line, a bump) must predict the
        # held-out AVAR better than the model without it (refitted on the fit part); the
        # others (removed signals, the filter's shape), which the free terms can partly
        # mimic, must not make it worse beyond the scatter √(2/K) of χ²/K. Judged where the
        # cause acts (held-out τ where it carries ≥ 20 % of the predicted AVAR) and over the
        # whole curve; failing both, it is not claimed. Quantization is a property of the
        # values, not a statistical claim: it holds when the held-out values sit on the same
        # grid. Drop the worst offender and look again.
        k_all = len(m_ho)
        while acc.causes and fit_e is not None:
            worst, worst_excess = None, 1.0
            for i, c in enumerate(acc.causes):
                if c.cause == "quantization":
                    q = cz.detect_quantization(ho_seg.y, rate_hz)
                    same = q.passed and abs(q.params["lsb"] / c.params["lsb"] - 1) < 0.01
                    excess = 1.0 if same else math.inf
                else:
                    pred_wo, _ = ho_ext(acc, _key(i, c))
                    contrib = _contribution(c, fit_e, ho_seg, m_ho, rate_hz)
                    sel = contrib >= 0.2 * pred_e
                    if not np.any(sel):
                        sel = contrib == contrib.max()
                    zw, zo = z2(pred_e), z2(pred_wo)
                    r_local = float(np.sum(zw[sel]) / max(np.sum(zo[sel]), 1e-300))
                    r_all = float(np.sum(zw) / max(np.sum(zo), 1e-300))
                    strict = c.cause in GAIN_REQUIRED
                    lim_local = 1.0 if strict else 1.0 + math.sqrt(2.0 / sel.sum())
                    lim_all = 1.0 if strict else 1.0 + math.sqrt(2.0 / k_all)
                    excess = min(r_local / lim_local, r_all / lim_all)
                if excess > worst_excess:
                    worst, worst_excess = i, excess
            if worst is None:
                break
            c = acc.causes.pop(worst)
            why = ("the held-out values are not on its grid" if c.cause == "quantization" else
                   f"with it the held-out misfit is {worst_excess:.3g}x beyond its limit, where "
                   "it acts and overall")
            dropped.append(f"{c.cause} {_fmt_params(c.params)}: {why}; not claimed")
            log.info("%s", dropped[-1])
            pred_e, fit_e = ho_ext(acc)
        ho = (float(np.sum(z2(pred_base))) / len(m_ho), float(np.sum(z2(pred_e))) / len(m_ho))

    ext, _ = _fit_extended(whole, acc, rate_hz, m)
    # judged like the base model: as a prediction of the measured (raw) AVAR
    ext_v = _predict_raw(ext, whole, acc, rate_hz, m)
    ext.chi2 = cz.chi2(meas.var, ext_v, meas.edf)
    ext.dof = max(len(m) - int(np.count_nonzero(ext.coef > 0))
                  - sum(len(c.params) for c in acc.causes), 1)
    gain = base.chi2_dof / max(ext.chi2_dof, 1e-300)

    findings = []
    for c in acc.causes:
        contrib = _contribution(c, ext, whole, m, rate_hz)
        share = contrib / np.maximum(ext_v, 1e-300)
        idx = np.flatnonzero(share >= 0.2)
        if len(idx) == 0:
            idx = np.array([int(np.argmax(share))])
        findings.append({"cause": c.cause,
                         "params": {k: float(v) for k, v in c.params.items()},
                         "tau_range_s": [float(meas.tau[idx[0]]), float(meas.tau[idx[-1]])],
                         "evidence": c.evidence})

    return ChannelExplanation(
        name, meas, base, base_v, misfit, findings, tests, ext, ext_v, gain,
        None if ho is None else ho[0] / max(ho[1], 1e-300),
        {} if ho is None else {"base": ho[0], "extended": ho[1]}, dropped)


def explain(record: Any, *, holdout: Any | None = None,
            channels: Sequence[str] | None = None) -> Explanation:
    """Explain every (or the named) channel of ``record`` (any object with ``accel`` (N, C)
    m/s², ``rate_hz``, ``names``, ``temperature_c`` and ``temperature_names``, such as
    :class:`avard.core.readers.Record`). ``holdout`` is a second record of the same sensor."""
    accel, rate, names, temps, tnames = _as_arrays(record)
    ho = None
    if holdout is not None:
        h_accel, h_rate, h_names, h_temps, _ = _as_arrays(holdout)
        if abs(h_rate - rate) > 1e-6 * rate:
            raise DataError(f"held-out record runs at {h_rate} Hz, the data at {rate} Hz; "
                            "hold out a record taken at the same rate")
        ho = (h_accel, h_names, h_temps)
    wanted = list(channels) if channels else names
    unknown = [c for c in wanted if c not in names]
    if unknown:
        raise DataError(f"unknown channel(s) {', '.join(unknown)}; the data have "
                        f"{', '.join(names)}")
    flat = [c for c in wanted if np.ptp(accel[:, names.index(c)]) == 0]
    if flat:
        raise DataError(f"channel(s) {', '.join(flat)} are constant: there is no noise to "
                        "explain; check the sensor or choose other channels (--channels)")
    out = {}
    for c in wanted:
        j = names.index(c)
        hol = None
        if ho is not None:
            hj = ho[1].index(c) if c in ho[1] else j
            if hj >= ho[0].shape[1]:
                raise DataError(f"held-out record has no channel {c!r}")
            hol = (ho[0][:, hj], ho[2])
        log.info("explaining channel %s", c)
        out[c] = explain_channel(accel[:, j], rate, temps, tnames, c, hol)
    t_avar = {}
    if temps is not None:
        for j, tn in enumerate(tnames):
            if np.ptp(temps[:, j]) > 0:
                t_avar[tn] = measure(temps[:, j], rate)
    return Explanation(out, rate, str(getattr(record, "source", "")),
                       None if holdout is None else str(getattr(holdout, "source", "")), t_avar)

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

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from statistics import NormalDist
from typing import Any

import numpy as np
from avard.core.allan.chi2 import chi2_sf
from avard.core.allan.edf import edf_greenhall
from avard.core.errors import FitError
from avard.core.model import terms as mdl
from avard.core.model.nnls import nnls
from avard.core.model.terms import TERMS, UNITS
from numpy.typing import ArrayLike, NDArray

__all__ = ["CAUSE_ALPHA", "Component", "LongTauCurve", "ModelChi2", "NoiseFit", "TermEstimate",
           "avar_estimate_covariance", "fit_noise", "model_chi2", "model_components",
           "refuted_by", "resolved_long_tau_terms", "slope_method", "with_long_tau_refuted"]


@dataclass
class TermEstimate:
    """One coefficient: value with its interval [lo, hi] at the fit's confidence level, in
    ``unit`` (SI). ``present`` False means the data do not support the term: value/lo/hi None.
    ``z`` is the presence test's statistic √Δχ² (None if not fitted); ``upper`` for an absent
    term is its one-sided upper limit at the test's level (the data exclude larger values)."""

    value: float | None
    lo: float | None
    hi: float | None
    unit: str
    present: bool
    z: float | None = None
    upper: float | None = None
    note: str | None = None

    def to_dict(self) -> dict[str, Any]:
        # "upper": an absent term's one-sided upper limit (null when present or not tested)
        return {"value": self.value, "lo": self.lo, "hi": self.hi, "unit": self.unit,
                "present": self.present,
                "upper": None if self.present or self.upper is None else float(self.upper),
                "note": self.note}


@dataclass
class Component:
    """One linear column of the model: θ·basis(τ), θ = (coefficient)². ``fixed_value`` set
    means the coefficient is known and not fitted."""

    label: str
    cause: str
    params: dict[str, float]
    value_key: str
    unit: str
    fixed_value: float | None = None

    def basis(self, tau: NDArray, rate_hz: float) -> NDArray[np.float64]:
        """AVAR per unit θ at τ."""
        return mdl.component_avar(self.cause, tau, {**self.params, self.value_key: 1.0},
                                  rate_hz=rate_hz)

    def psd(self, rate_hz: float) -> mdl.PsdFn | None:
        """Unit PSD (cycles/sample) for the estimator covariance; None if deterministic."""
        if self.cause in TERMS:
            return mdl.term_psd(self.cause, rate_hz)
        if self.cause == "gauss_markov":
            return mdl.gauss_markov_psd(rate_hz, self.params["T"])
        if self.cause == "white":
            return mdl.term_psd("velocity_random_walk", rate_hz)
        if self.cause == "lowpass_flicker":
            return mdl.lowpass_flicker_psd(rate_hz, self.params["corner_hz"],
                                           int(self.params.get("order", 2)))
        if self.cause in ("filter", "lowpass_white"):
            return mdl.lowpass_white_psd(rate_hz, self.params["corner_hz"],
                                         int(self.params.get("order", 2)))
        return None  # sinusoid: deterministic


@dataclass
class NoiseFit:
    """Result of ``fit_noise`` for one channel (SI units throughout).

    ``terms``: every IEEE term, present or absent; ``sinusoids``: present sinusoids
    ``{"frequency_hz", "amplitude", "lo", "hi"}``; ``extra``: every extra component
    ``{"cause", "params", "present", "lo", "hi"}``; ``tau_min_s``/``tau_max_s``: the τ range
    used; ``chi2_dof``: generalised χ²/dof of the residuals with the modelled covariance
    (≈ 1 when the model describes the data).
    """

    terms: dict[str, TermEstimate]
    sinusoids: list[dict[str, float | None]]
    extra: list[dict[str, Any]]
    tau_min_s: float
    tau_max_s: float
    chi2_dof: float
    rate_hz: float = 1.0
    filter_corner_hz: float | None = None
    n_points: int = 0
    dof: int = 0
    ci: float = 0.683
    z_present: float = 2.33
    components: list[Component] = field(default_factory=list, repr=False)
    theta: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0), repr=False)
    theta_cov: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 0)), repr=False)
    #: ln det of the modelled AVAR covariance at the fitted θ over the points used: with
    #: χ² it gives the Gaussian −2 ln L (χ² + ln det C) that compares models whose
    #: covariances differ (a nonlinear parameter scanned outside the fit, e.g. a
    #: Gauss–Markov T); χ² alone favours the model that predicts the larger scatter
    log_det_cov: float = math.nan
    #: the deterministic terms resolved apart from the AVAR (a drift the time domain told
    #: from a random walk, ``analysis.drift``): their part may take the printed EDF past the
    #: record's support (``analysis.signal_edf``), which the AVAR fit's own parts may not
    resolved_apart: tuple[str, ...] = ()
    #: a drift the time domain found beside the noise but did not resolve (``analysis.drift``:
    #: its slope's 68 % interval clear of zero, the test short of its level): the rate ramp
    #: (input unit per s) at that interval's near end, 0 where none. The AVAR holds at least
    #: that ramp at the 68 % level; it does not scatter (``analysis.signal_edf``), and it is
    #: no claim: the terms and the model are the AVAR fit's
    drift_floor: float = 0.0
    #: beside ``drift_floor``, the drift test's GLS slope and its 68 % profile interval
    #: (slope, lo, hi; input unit per s), () where no floor is carried: the printed bounds
    #: of such a record take the ramp's uncertainty from the slope (``analysis.signal_edf``)
    drift_slope: tuple[float, float, float] | tuple[()] = ()
    #: the noise the drift test's slope interval was computed under, where a drift is
    #: reported (a ramp resolved from the time domain, or ``drift_floor``):
    #: ``analysis.drift.INTERVAL_NOISE`` ("refit_less_line", "fit", or a fallback to the
    #: fit's N and B that says why); "" where no interval was computed
    drift_interval_noise: str = ""

    def component_avars(self, tau: ArrayLike) -> dict[str, NDArray[np.float64]]:
        """AVAR of each present component at τ, keyed by label (term name, 'sinusoid 50 Hz'…)."""
        t = np.atleast_1d(np.asarray(tau, dtype=float))
        out = {}
        for comp, th in zip(self.components, self.theta, strict=True):
            if th > 0:
                out[comp.label] = th * comp.basis(t, self.rate_hz)
        return out

    def model_avar(self, tau: ArrayLike) -> NDArray[np.float64]:
        """Total fitted model AVAR at τ ((m/s²)²)."""
        t = np.atleast_1d(np.asarray(tau, dtype=float))
        total = np.zeros_like(t)
        for v in self.component_avars(t).values():
            total += v
        return total

    def values(self) -> dict[str, float | None]:
        """Point values of the IEEE terms (None when absent), for ``model.model_avar``."""
        return {k: t.value for k, t in self.terms.items()}

    def to_dict(self) -> dict[str, Any]:
        return {
            "terms": {k: t.to_dict() for k, t in self.terms.items()},
            "sinusoids": [{"frequency_hz": s["frequency_hz"], "amplitude": s["amplitude"]}
                          for s in self.sinusoids],
            "fit": {"tau_min_s": self.tau_min_s, "tau_max_s": self.tau_max_s,
                    "chi2_dof": self.chi2_dof},
        }


# ---------------------------------------------------------------------------------------------


_VALUE_KEYS = {"sinusoid": ("amplitude", "m/s^2"), "gauss_markov": ("sigma", "m/s^2"),
               "filter": ("N", "m/s/sqrt(s)"), "lowpass_white": ("N", "m/s/sqrt(s)"),
               "white": ("N", "m/s/sqrt(s)")}
#: Note on K and R when the record cannot tell a rate ramp from a rate random walk.
RAMP_OR_WALK = "ramp or random walk: this record cannot tell them apart; read as random walk"
#: Note on a present K or R that only the longest τ of the fit shows (``_rests_on_longest``)
#: or that the τ beyond the fit refute (``_refuted_beyond``): the model keeps it, displays
#: say "not yet resolved" instead of its interval.
NOT_RESOLVED = ("not yet resolved: only the long end of the fit shows this term (its longest τ "
                "alone, or the τ beyond the fit fall below it), which a slow periodic signal "
                "mimics there as well; a longer record decides")
#: The terms that rise with τ and so are decided at the long end of the curve.
LONG_TAU_TERMS = ("rate_random_walk", "rate_ramp")
#: Label of the fixed rounding component (``fit_noise(rounding_lsb=...)``).
ROUNDING = "rounding"


def _components(terms: Iterable[str], extra: Sequence[Mapping], filter_corner_hz: float | None,
                rate_hz: float) -> list[Component]:
    comps = []
    for t in terms:
        if t not in TERMS:
            raise FitError(f"unknown noise term {t!r}; choose from {', '.join(TERMS)}")
        if t == "velocity_random_walk" and filter_corner_hz is not None:
            comps.append(Component(t, "filter", {"corner_hz": float(filter_corner_hz)}, "N",
                                   UNITS[t]))
        elif t == "bias_instability" and filter_corner_hz is not None:
            comps.append(Component(t, "lowpass_flicker", {"corner_hz": float(filter_corner_hz)},
                                   "value", UNITS[t]))
        else:
            comps.append(Component(t, t, {}, "value", UNITS[t]))
    for e in extra:
        cause = e.get("cause")
        if cause not in _VALUE_KEYS:
            raise FitError(f"extra component {e!r}: cause must be one of {sorted(_VALUE_KEYS)}")
        key, unit = _VALUE_KEYS[cause]
        params = {k: float(v) for k, v in dict(e.get("params", {})).items()}
        fixed = params.pop(key, None)
        if cause == "sinusoid":
            f0 = params.get("frequency_hz")
            if f0 is None or not 0 < f0 <= rate_hz / 2:
                raise FitError(f"sinusoid needs 0 < frequency_hz <= {rate_hz / 2} Hz; got {f0}")
            label = f"sinusoid {f0:.6g} Hz"
        elif cause == "white":
            label = str(e.get("label", "white"))
        elif cause == "gauss_markov":
            if "time_constant_s" in params:  # the explain pipeline's name for T
                params["T"] = params.pop("time_constant_s")
            if params.get("T", 0) <= 0:
                raise FitError("gauss_markov needs a correlation time T > 0 s in params")
            label = f"gauss_markov T={params['T']:.4g} s"
        else:
            if "corner_hz" not in params:
                raise FitError("filter needs params corner_hz")
            label = "filtered white"
        comps.append(Component(label, cause, params, key, unit, fixed))
    return comps


def model_components(terms: Iterable[str], extra: Sequence[Mapping] = (), *, rate_hz: float,
                     filter_corner_hz: float | None = None) -> list[Component]:
    """The components ``fit_noise`` builds for ``terms`` and ``extra`` (same arguments), for
    computing with the fit's own model outside a fit (e.g. a stated detection minimum)."""
    return _components(terms, extra, filter_corner_hz, rate_hz)


#: The power-law type (α of S_y ∝ f^α) of each noise cause, for its Greenhall–Riley EDF;
#: a cause not listed (a Gauss–Markov process, which is no one power law) keeps Whittle's.
CAUSE_ALPHA = {"quantization": 2, "velocity_random_walk": 0, "white": 0, "filter": 0,
                "lowpass_white": 0, "bias_instability": -1, "lowpass_flicker": -1,
                "rate_random_walk": -2}


def _covariance_kernels(components: Sequence[Component], m: NDArray[np.int64],
                        stride: NDArray, M: NDArray[np.float64], rate_hz: float
                        ) -> NDArray[np.float64]:
    """The kernels of ``mdl.avar_covariance_kernels`` with each component's variance at
    each τ made Greenhall and Riley's finite-record value (NIST SP 1065 §5.3), correlations
    kept. Whittle's (2/M)∫S²|H|⁴ is first order in 1/M: with few averages it understates
    the variance of a flicker or random-walk estimate (by 12 % at 13 averages of 60 h), and
    the fit's χ² test rejected 3.0 % of pure white + flicker 60 h records at its 1 % level
    (issue 24). G[k, l, a, b] is scaled by (g_ka g_kb g_la g_lb)^¼, g_ka = GR's variance of
    component a alone at τ_k over Whittle's, so each pure component's diagonal is GR's."""
    G = mdl.avar_covariance_kernels(m, [c.psd(rate_hz) for c in components])
    K, A = len(m), len(components)
    g = np.ones((K, A))
    # the strides as the loop reads them (int() of each, as astype truncates)
    on = (np.asarray(m, dtype=np.int64).tobytes(), np.asarray(stride).astype(np.int64).tobytes(),
          np.asarray(M, dtype=np.float64).tobytes(), float(rate_hz))
    for a, comp in enumerate(components):
        alpha = CAUSE_ALPHA.get(comp.cause)
        if alpha is None:
            continue
        g[:, a] = _gr_scale(comp.cause, comp.value_key, tuple(sorted(comp.params.items())),
                            alpha, np.ascontiguousarray(G[:, :, a, a].diagonal()).tobytes(),
                            *on)
    r = np.sqrt(np.sqrt(g))  # (K, A): g^¼
    return G * (r[:, None, :, None] * r[:, None, None, :] * r[None, :, :, None]
                * r[None, :, None, :])


@lru_cache(maxsize=1024)
def _gr_scale(cause: str, value_key: str, params: tuple[tuple[str, float], ...], alpha: int,
              diag: bytes, m: bytes, stride: bytes, M: bytes, rate_hz: float
              ) -> NDArray[np.float64]:
    """Whittle's variance of one component alone at each τ over Greenhall and Riley's
    (``_covariance_kernels``' g), from its kernels' diagonal ``diag`` and the τ (``m``,
    ``stride``, ``M``: the arrays' bytes): a pure function of them, the same for every fit on
    these τ (a Gauss–Markov scan fits once per correlation time, every other component
    unchanged), so computed once (read-only)."""
    mk = np.frombuffer(m, dtype=np.int64)
    st = np.frombuffer(stride, dtype=np.int64)
    Mk = np.frombuffer(M, dtype=np.float64)
    d = np.frombuffer(diag, dtype=np.float64)
    b = Component(cause, cause, dict(params), value_key, "").basis(mk / rate_hz, rate_hz)
    out = np.ones(len(mk))
    for k in range(len(mk)):
        if d[k] <= 0 or not b[k] > 0:
            continue
        whittle = b[k] ** 2 * Mk[k] / d[k]
        gr = edf_greenhall(alpha, 2, int(mk[k]), max(int(st[k]), 1), int(Mk[k]) + 1)
        if math.isfinite(gr) and gr > 0:
            out[k] = whittle / gr
    out.setflags(write=False)
    return out


def avar_estimate_covariance(components: Sequence[Component], theta: ArrayLike,
                             m: ArrayLike, n_samples: ArrayLike, rate_hz: float,
                             stride: ArrayLike | None = None) -> NDArray[np.float64]:
    """Cov(σ̂²_k, σ̂²_l) of overlapping AVAR estimates at τ_k = m_k/fs from records of
    ``n_samples`` samples, for the model Σθ_j·b_j: the covariance ``fit_noise`` weights its
    fit with (Whittle kernels (2/M)∫S²|H_k|²|H_l|²dν of the components' spectra, each
    power law's variance made Greenhall–Riley's: ``_covariance_kernels``; the NIST SP 1065
    §5.3 floor 2σ⁴/EDF on the diagonal). ``theta`` in the order of ``components``;
    ``stride`` the samples between the differences of each τ (1, fully overlapping, by
    default)."""
    m_a = np.asarray(m, dtype=np.int64)
    M = np.asarray(n_samples, dtype=float) * np.ones(len(m_a))
    tau = m_a / float(rate_hz)
    th = np.asarray(theta, dtype=float)
    X = np.column_stack([c.basis(tau, rate_hz) for c in components])
    st = np.ones(len(m_a)) if stride is None else np.asarray(stride) * np.ones(len(m_a))
    G = _covariance_kernels(components, m_a, st, M, float(rate_hz))
    p = _Problem(y=X @ th, X=X, fixed=np.zeros(len(m_a)), G=G, theta_fixed=np.zeros(0), M=M,
                 edf_floor=100.0 * M, m_tau=tau)
    return _avar_cov(p, th, np.arange(len(m_a)))


def _n_samples(result: Any) -> NDArray[np.float64]:
    """Samples spanned by the differences of each τ: (n − 1)·stride + 2m (≈ N for every τ)."""
    stride = np.asarray(getattr(result, "stride", np.ones_like(result.m)), dtype=float)
    return (np.asarray(result.n, float) - 1.0) * stride + 2.0 * np.asarray(result.m, float)


def _usable(result: Any, min_edf: float, min_averages: float,
            tau_range: tuple[float, float] | None) -> NDArray[np.intp]:
    """Indices of the τ points a fit may use: a finite positive AVAR, enough independent
    averages (≥ ``min_averages``) and EDF (≥ ``min_edf``) for a usable weight, inside
    ``tau_range`` (s). One cut for ``fit_noise`` and ``model_chi2``."""
    var = np.asarray(result.var, dtype=float)
    tau = np.asarray(result.tau, dtype=float)
    m = np.asarray(result.m, dtype=float)
    n = np.asarray(result.n, dtype=float)
    M = _n_samples(result)
    n_total = float(np.nanmax(M)) if len(M) else 0.0
    edf = np.asarray(getattr(result, "edf", np.full_like(var, np.nan)), dtype=float)
    ok = np.isfinite(var) & (var > 0) & (n > 0)
    # long-τ cut: too few independent averages, or too few EDF for a usable weight
    ok &= n_total / m >= min_averages
    ok &= ~(np.isfinite(edf) & (edf < min_edf))
    if tau_range is not None:
        ok &= (tau >= tau_range[0] * (1 - 1e-9)) & (tau <= tau_range[1] * (1 + 1e-9))
    return np.flatnonzero(ok)


#: ``_fit_active``'s result: θ, Cov θ[active], the AVAR covariance C and the χ² of the fit.
_ActiveFit = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], float]


@dataclass
class _Problem:
    """The fixed ingredients of one channel's fit over the τ points kept."""

    y: NDArray[np.float64]  # measured AVAR minus fixed components
    X: NDArray[np.float64]  # (K, A) basis of fitted components
    fixed: NDArray[np.float64]  # (K,) AVAR of fixed components
    G: NDArray[np.float64]  # (K, K, A+F, A+F) covariance kernels
    theta_fixed: NDArray[np.float64]
    M: NDArray[np.float64]  # (K,) number of difference positions
    edf_floor: NDArray[np.float64]
    m_tau: NDArray[np.float64]  # (K,) τ of the points (s)
    # (K, K) covariance from outside the noise model (the uncertainty of a removed signal)
    added: NDArray[np.float64] | None = None
    # ``_fit_active``'s results by (points, components, iterations): the selection, its
    # ramp/walk comparison, the long-τ check and the final fit ask for the same ones
    fits: dict[tuple[bytes, tuple[int, ...], int], _ActiveFit] = field(default_factory=dict)
    # ``_at``'s slices by points: every iteration of every fit on the same points takes them
    subsets: dict[bytes, _Subset] = field(default_factory=dict)


@dataclass(frozen=True)
class _Subset:
    """The fixed ingredients of ``_avar_cov`` at some points ``idx`` of a ``_Problem``: G's
    block, max(M_k, M_l), the basis, the fixed components' AVAR, the EDF floor, the added
    covariance (the same arrays every call would slice)."""

    G: NDArray[np.float64]
    MM: NDArray[np.float64]
    X: NDArray[np.float64]
    fixed: NDArray[np.float64]
    edf_floor: NDArray[np.float64]
    added: NDArray[np.float64] | None


def _at(p: _Problem, idx: NDArray) -> _Subset:
    """``p``'s ingredients at points ``idx``, sliced once per problem and points."""
    key = np.asarray(idx, dtype=np.intp).tobytes()
    got = p.subsets.get(key)
    if got is None:
        M = p.M[idx]
        got = _Subset(p.G[np.ix_(idx, idx)], np.maximum.outer(M, M), p.X[idx], p.fixed[idx],
                      p.edf_floor[idx],
                      None if p.added is None else p.added[np.ix_(idx, idx)])
        for arr in (got.G, got.MM, got.X, got.fixed, got.edf_floor, got.added):
            if arr is not None:
                arr.flags.writeable = False
        p.subsets[key] = got
    return got


def _theta_full(p: _Problem, theta: NDArray) -> NDArray:
    return np.concatenate([theta, p.theta_fixed])


def _avar_cov(p: _Problem, theta: NDArray, idx: NDArray) -> NDArray[np.float64]:
    """Modelled covariance matrix of the AVAR estimates at points ``idx`` (Whittle form),
    with a floor so that deterministic-only models keep finite weights."""
    th = _theta_full(p, theta)
    sub = _at(p, idx)
    q = np.einsum("klab,a,b->kl", sub.G, th, th)
    C = 2.0 * q / sub.MM
    model = sub.X @ theta + sub.fixed
    floor = 2.0 * model**2 / sub.edf_floor
    d = np.diag(C).copy()
    bump = np.maximum(floor - d, 0.0)
    C.flat[:: len(C) + 1] = d + bump  # the diagonal
    if sub.added is not None:
        C += sub.added
    return C


def _whitener(C: NDArray) -> NDArray[np.float64]:
    """T with T·C·Tᵀ = I on C's numerically non-null subspace (eigen-decomposition of the
    correlation matrix; directions below 1e-10 of the largest eigenvalue are dropped)."""
    d = np.sqrt(np.diag(C))
    R = C / (d[:, None] * d[None, :])  # np.outer's product
    w, V = np.linalg.eigh(R)
    keep = w > 1e-10 * w.max()
    return (V[:, keep] / np.sqrt(w[keep])).T / d


def _param_cov(A: NDArray) -> NDArray[np.float64]:
    """(AᵀA)⁻¹ of a whitened design A, its columns scaled to unit norm first. The basis spans
    many decades (1/τ², 1/τ, τ, τ² over 0.01 s to 10⁴ s), and the pseudo-inverse of the
    unscaled normal matrix cut its smallest directions as numerically null, which set their
    variance to zero: a 60 h record without a filter read a 0.04 % shortfall at one sample
    as a bend at z = −9700 and left out its 5 shortest τ as "filter-bent" (issue 24)."""
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0] = 1.0
    As = A / scale
    return np.linalg.pinv(As.T @ As) / np.outer(scale, scale)


def _gls_scaled(A: NDArray, b: NDArray) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Least squares of the whitened system A·θ ≈ b: (θ, Cov θ), columns scaled as in
    ``_param_cov``."""
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0] = 1.0
    coef, *_ = np.linalg.lstsq(A / scale, b, rcond=None)
    return coef / scale, _param_cov(A)


def _gls_nnls(X: NDArray, y: NDArray, T: NDArray, Ty: NDArray | None = None
              ) -> tuple[NDArray[np.float64], float]:
    """Non-negative generalised least squares: min ‖T(y − Xθ)‖², θ ≥ 0; returns (θ, χ²).
    Columns are scaled to unit norm first because the basis spans many decades. ``Ty``:
    T·y when the caller has it (the selection's subsets share one T)."""
    A = T @ X
    b = T @ y if Ty is None else Ty
    scale = np.sqrt(np.add.reduce(A * A, axis=0))  # np.linalg.norm(A, axis=0), as it sums
    scale[scale == 0] = 1.0
    sol, rnorm = nnls(A / scale, b, maxiter=50 * X.shape[1] + 100)
    return sol / scale, float(rnorm**2)


def _fit_active(p: _Problem, idx: NDArray, active: list[int], iterations: int = 8
                ) -> _ActiveFit:
    """``_fit_once``, computed once per problem for each (points, components): a pure
    function of them, so the cached result is the one a new call would give bit for bit
    (its arrays are read-only, so no caller can change what another one reads)."""
    key = (np.asarray(idx, dtype=np.intp).tobytes(), tuple(active), iterations)
    got = p.fits.get(key)
    if got is None:
        got = _fit_once(p, idx, active, iterations)
        for arr in got[:3]:
            arr.flags.writeable = False
        p.fits[key] = got
    return got


def _fit_once(p: _Problem, idx: NDArray, active: list[int], iterations: int
              ) -> _ActiveFit:
    """Iterated GLS fit, θ ≥ 0, on points ``idx`` with components ``active``: the covariance
    of the AVAR estimates is recomputed from the current model until θ settles.

    Returns θ (zeros for inactive components), Cov(θ[active]) = (XᵀC⁻¹X)⁻¹, the AVAR
    covariance C and the generalised χ² of the residuals."""
    A = p.X.shape[1]
    X = p.X[np.ix_(idx, np.asarray(active, dtype=np.intp))]
    y = p.y[idx]
    theta = np.zeros(A)
    # start: relative weights from the measured values, no correlation
    v = 2.0 * np.maximum(y + p.fixed[idx], 1e-300) ** 2 / p.M[idx]
    theta[active], _ = _gls_nnls(X, y, np.diag(1.0 / np.sqrt(v)))
    for _ in range(iterations):
        C = _avar_cov(p, theta, idx)
        new = np.zeros(A)
        new[active], _ = _gls_nnls(X, y, _whitener(C))
        done = _settled(new, theta)
        theta = new
        if done:
            break
    C = _avar_cov(p, theta, idx)
    T = _whitener(C)
    TX = T @ X
    cov = _param_cov(TX)
    r = T @ (y - X @ theta[active])
    return theta, cov, C, float(r @ r)


def _settled(new: NDArray, old: NDArray) -> bool:
    """``np.allclose(new, old, rtol=1e-5, atol=0)``, the iteration's stop: |new − old| ≤
    1e-5·|old| everywhere, the same comparison without allclose's per-call overhead where
    both are finite (allclose itself otherwise: its rules for infinities and NaN)."""
    if not (np.isfinite(new).all() and np.isfinite(old).all()):
        return bool(np.allclose(new, old, rtol=1e-5, atol=0))
    return bool((np.abs(new - old) <= 1e-5 * np.abs(old)).all())


def _neg_log_lik(p: _Problem, idx: NDArray, active: list[int]) -> float:
    """−2 ln L (up to a constant) of the AVAR points under the fitted model ``active`` with
    the model's own covariance: χ² + ln det C."""
    _, _, C, c2 = _fit_active(p, idx, active)
    sign, logdet = np.linalg.slogdet(C)
    return c2 + logdet if sign > 0 else math.inf


def _select_terms(p: _Problem, idx: NDArray, A: int, z_present: float,
                  ramp: int | None = None, walk: int | None = None,
                  upper_limits: bool = True
                  ) -> tuple[list[int], NDArray[np.float64], NDArray[np.float64], bool]:
    """Stepwise selection by the likelihood-ratio test on the correlated, EDF-weighted
    residuals: a component is kept when removing it raises χ² by at least z_present²
    (2.33² = 5.4: one-sided 1 % for a coefficient on the boundary θ = 0).

    All candidate models are compared with one covariance, the one of the full model (every
    candidate term fitted), so that a deterministic term (rate ramp, which adds no estimator
    variance of its own) cannot look significant merely by shrinking its own error bars.
    Forward steps add the candidate that lowers χ² most while the drop passes the test; then
    backward steps remove any term that no longer passes. Returns the selected components,
    √Δχ² of each (the z of its test) and, for the terms left out, the one-sided upper limit
    θ̂ + z_present·se of θ when fitted with the selected ones (a "not detected, below" bound).

    Rate ramp (index ``ramp``) against rate random walk (``walk``): a random walk's
    realisation over a record looks like a trend, and a ramp fitted with the covariance of a
    model in which it has taken the random walk's place has tight error bars it did not earn.
    So the common covariance is that of the model *without* the ramp (the long-τ excess read
    as a random walk): the ramp must beat what a random walk would do. When exactly one of
    the two is selected, the two readings are compared by their Gaussian likelihood, each
    with its own covariance; when neither is better by the test's margin the record cannot
    tell them apart: the random walk is kept (the stochastic reading, whose interval includes
    the realisation's scatter) and the last value returned is True ("ramp or random walk").
    """
    base = [a for a in range(A) if a != ramp] if walk is not None else list(range(A))
    _, _, C_star, _ = _fit_active(p, idx, base)
    T = _whitener(C_star)
    y = p.y[idx]
    Ty = T @ y
    Xi = _at(p, idx).X
    crit = z_present**2

    done: dict[tuple[int, ...], tuple[float, NDArray]] = {}

    def chi2(active: list[int]) -> tuple[float, NDArray]:
        # the forward, backward and upper-limit passes ask for the same subsets again: one
        # fit each (a pure function of the subset under the one covariance T)
        key = tuple(active)
        if key not in done:
            if not active:
                r = T @ y
                done[key] = float(r @ r), np.zeros(0)
            else:
                th, c2 = _gls_nnls(np.ascontiguousarray(Xi[:, np.asarray(active, dtype=np.intp)]),
                                   y, T, Ty)
                done[key] = c2, th
        return done[key]

    z_all = np.full(A, np.nan)
    active: list[int] = []
    cur, _ = chi2(active)
    while len(active) < A:
        trials = []
        for a in range(A):
            if a not in active:
                cand = sorted([*active, a])
                c2, th = chi2(cand)
                trials.append((c2, a, cand, th))
        c2, a, cand, th = min(trials, key=lambda t: t[0])
        gain = cur - c2
        if gain < crit or th[cand.index(a)] <= 0:
            break
        active, cur = cand, c2
    while active:
        drops = []
        for a in active:
            rest = [b for b in active if b != a]
            c2, _ = chi2(rest)
            drops.append((c2 - cur, a))
            z_all[a] = math.sqrt(max(c2 - cur, 0.0))
        gain, a = min(drops)
        if gain >= crit:
            break
        active.remove(a)
        cur, _ = chi2(active)
    ambiguous = False
    if ramp is not None and walk is not None and ramp in active and walk in active:
        # both chosen: the ramp stays only if it also wins on likelihood with the models'
        # own covariances; else the random walk alone reads the long-τ excess
        without = [b for b in active if b != ramp]
        if not _neg_log_lik(p, idx, active) + crit < _neg_log_lik(p, idx, without):
            active = without
            ambiguous = True
    if ramp is not None and walk is not None and (ramp in active) != (walk in active):
        # One of the two was chosen: compare the two readings by their Gaussian likelihood,
        # each with its own covariance (χ² + ln det C), so that a random walk's wide scatter
        # and a ramp's tight one both count. Clearly better (by the test's margin) wins;
        # otherwise the record cannot tell them apart and the random walk is reported.
        there, other = (ramp, walk) if ramp in active else (walk, ramp)
        swapped = sorted([b for b in active if b != there] + [other])
        nll_there, nll_other = _neg_log_lik(p, idx, active), _neg_log_lik(p, idx, swapped)
        if nll_other + crit < nll_there:
            active = swapped
        elif not nll_there + crit < nll_other:
            ambiguous = True
            if there == ramp:  # the random walk reading
                active = swapped
        cur, _ = chi2(active)
        if walk in active:
            c2_no_walk, _ = chi2([b for b in active if b != walk])
            z_all[walk] = math.sqrt(max(c2_no_walk - cur, 0.0))
    rescued = _rescue_hidden_terms(p, idx, A, active, crit, ramp)
    if rescued:
        for a, z in rescued.items():
            z_all[a] = z
        active = sorted([*active, *rescued])
        cur, _ = chi2(active)
    upper = np.full(A, np.nan)
    for a in range(A):
        if a not in active:
            cand = sorted([*active, a])
            c2, th = chi2(cand)
            z_all[a] = math.sqrt(max(cur - c2, 0.0))
            if upper_limits:
                upper[a] = _upper_limit(p, idx, cand, a, z_present, T)
    return active, z_all, upper, ambiguous


#: The own-covariance χ² upper tail below which the selection looks again for a noise term
#: the common covariance hid (``_rescue_hidden_terms``): the level of explain's misfit test.
RESCUE_P = 0.01


def _rescue_hidden_terms(p: _Problem, idx: NDArray, A: int, active: list[int], crit: float,
                         ramp: int | None) -> dict[int, float]:
    """Noise terms the selection's common covariance hid: {component: z} to add.

    The selection compares subsets under the full model's covariance, in which every term
    carries the variance it has when fitted. Beside a bias instability that took up the long-τ
    rise, the full model's random walk scatters the longest τ so widely that they weigh little,
    and the random walk that rise is made of passed at z 2.2–2.3 (or not at all, its NNLS
    coefficient 0 beside the flicker) on 4 h records of white + flicker + random walk, where
    the model left without it misfits its own covariance at χ²/dof 4–34 (p 1e-7 to 1e-85) and
    explain said "unexplained" on 8 % of null axes. So where the selected model fails its own
    χ² test at ``RESCUE_P``, each absent stochastic term (never the ramp, which adds no
    variance and is tested against the random walk above) is tried by the Gaussian
    likelihood with each model's own covariance (χ² + ln det C, as the ramp against the walk)
    and the best one that lowers it by the test's margin (``crit``) with a positive
    coefficient is added, until the model passes or none does. Its z is √ of that drop."""
    out: dict[int, float] = {}
    cur = list(active)
    while cur:  # (an empty selection keeps its own χ²: nothing was seen at all)
        _, _, _, c2 = _fit_active(p, idx, cur)
        dof = len(idx) - len(cur)
        if dof <= 1 or not math.isfinite(c2) or float(chi2_sf(c2, dof)) >= RESCUE_P:
            return out
        here = _neg_log_lik(p, idx, cur)
        best: tuple[float, int] | None = None
        for a in range(A):
            if a in cur or a == ramp:
                continue
            cand = sorted([*cur, a])
            th, _, _, _ = _fit_active(p, idx, cand)
            if not th[a] > 0:
                continue
            gain = here - _neg_log_lik(p, idx, cand)
            if gain >= crit and (best is None or gain > best[0]):
                best = (gain, a)
        if best is None:
            return out
        out[best[1]] = math.sqrt(best[0])
        cur = sorted([*cur, best[1]])
    return out


def _upper_limit(p: _Problem, idx: NDArray, cand: list[int], a: int, z: float,
                 T0: NDArray, iterations: int = 6) -> float:
    """One-sided upper limit θ_u = θ̂ + z·se of an absent component's θ, with the AVAR
    covariance evaluated *at* θ_u (the hypothesis the limit excludes), iterated to a fixed
    point. With the covariance of the fitted model instead, a random walk whose realisation
    fell low also had small error bars, and the limit came out below the truth in 1 of 8
    absent-K records (issue 12); a term as large as θ_u scatters the AVAR as much as it
    would if it were there."""
    X = p.X[np.ix_(idx, np.asarray(cand, dtype=np.intp))]
    y = p.y[idx]
    j = cand.index(a)
    theta = np.zeros(p.X.shape[1])
    T = T0  # first round: the common covariance of the selection
    up = 0.0
    for _ in range(iterations):
        th, _ = _gls_nnls(X, y, T)
        TX = T @ X
        se = math.sqrt(max(_param_cov(TX)[j, j], 0.0))
        new = th[j] + z * se
        done = up > 0 and abs(new - up) <= 1e-3 * up
        up = new
        theta[cand] = th
        theta[a] = up  # the covariance of the next round: the term at its limit
        if done:
            break
        T = _whitener(_avar_cov(p, theta, idx))
    return up


def _rests_on_longest(p: _Problem, idx: NDArray, active: list[int], a: int, crit: float,
                      ramp: int | None, walk: int | None) -> bool:
    """Whether component ``a``'s presence hangs on the longest τ of the fit alone: with that
    point left out its likelihood-ratio gain falls below the test's ``crit``.

    A rate ramp (AVAR ∝ τ²) and a rate random walk (∝ τ) are read at the long end of the
    curve, where the last point holds a handful of averages, and a slow periodic signal (a
    30-minute air-conditioning cycle) rises as τ² below a quarter of its period: on 40 min of
    such a record the fit read a ramp from its one last point, which the longer τ beyond
    the fit (too few averages to fit) refuted (issue 24). As in ``_select_terms``, the test
    uses one covariance for both models, that of the active model with the ramp read as a
    random walk, so the ramp must beat what a random walk would do."""
    sub = idx[:-1]
    if len(sub) < len(active) + 2:
        return True
    cov_model = list(active)
    if ramp is not None and walk is not None and ramp in cov_model:
        cov_model = sorted({b for b in cov_model if b != ramp} | {walk})
    _, _, C, _ = _fit_active(p, sub, cov_model)
    T = _whitener(C)
    y = p.y[sub]
    _, with_a = _gls_nnls(p.X[np.ix_(sub, np.asarray(active, dtype=np.intp))], y, T)
    rest = [b for b in active if b != a]
    if rest:
        _, without = _gls_nnls(p.X[np.ix_(sub, np.asarray(rest, dtype=np.intp))], y, T)
    else:
        r = T @ y
        without = float(r @ r)
    return without - with_a < crit


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
    if not np.any(np.isfinite(var) & (var > 0)):
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

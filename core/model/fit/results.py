"""What a noise fit returns: each term's estimate with its interval (``TermEstimate``), a model
component (``Component``), the fit itself (``NoiseFit``), and the words a fit says where the
record cannot tell."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from avard.core.model import terms as mdl
from avard.core.model.terms import TERMS
from numpy.typing import ArrayLike, NDArray


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

"""The held-out gain of ``avard explain``: how much better the extended model predicts data it
was not fitted on than analyze's base model does.

Both models are fitted on one part of the data (the *fit part*) and predict the Allan variance
of another (the *held-out part*):

- **split** (default): the record's slow view (block means of ≈ 1 s, ``explain.SlowView``) in
  two time-contiguous halves A and B, two folds: fit on A and predict B, fit on B and predict
  A; the χ² of both folds add.
- **file** (``--holdout FILE``): the whole record is the fit part; FILE, a second record of
  the same sensor (rates agreeing by ``core.io.rates``' one rule: every run fits its own) with
  the same channels, is held out. Each side's slow view has the same block in samples and its
  τ in seconds of its own rate.

On the fit part, the *base* model is ``fit.fit_noise`` of its AVAR (analyze's terms and its
lines); the *extended* model is the same fit of its AVAR with the claimed causes' signals
removed, their parameters fitted on the fit part alone: the temperature coefficient and lag
(``thermal_fit.fit_thermal`` on the claimed channel), the warm-up, the steps, excursions and
drift (least squares, ``causes``, ``_fit_events``) where the fit part holds them, the
Gauss–Markov σ as a GLS component (at the correlation time found on the whole record). On the
held-out part, the base model predicts the measured AVAR; the extended model predicts the AVAR
with the *predicted* signals removed: the temperature through the fitted lag and coefficient
from the held-out part's own logged temperature, a warm-up's tail where the held-out part
follows it, a drift's ramp at the fit part's rate. A warm-up, a step or an excursion is an
event of one record, not a property of the sensor: it predicts nothing in another record or
the other half, so where the held-out half holds one it is taken out of *both* models'
held-out AVAR alike (``_held_events``: a step's or excursion's edges cut as gaps, a warm-up
refitted there as a nuisance).

Misfit: the generalised χ² of the held-out AVAR against each model's prediction, with the
covariance ``fit_noise`` models (each power law's variance at each τ Greenhall and Riley's
finite-record one, NIST SP 1065 §5.3, the correlations between τ from Whittle's kernels of
the model's own spectrum), over the τ both fits used and the held-out part resolves
(``fit.model_chi2`` with ``predictive``). No parameter is fitted on those points, so a model
that describes the sensor gives χ² ≈ n (the number of τ). The gain is

    gain = 1 − χ²_ext / χ²_base   (both on the same held-out τ, summed over folds and axes)

0: the extension predicts no better; 0.9: its held-out misfit is a tenth of the base's;
negative: it predicts worse (over-fitting). It is null, with the reason, when no cause is
claimed (the extended model is the base model), when every claimed cause is an event (a
warm-up, a step: nothing to predict) or the record is too short to split.
The AVAR here is the slow view's (τ ≥ one block), where every cause acts.

The verdict's held-out test reads ``Fold.chi2_ext_pred``: the extended χ² with the
prediction's own uncertainty in the covariance, (1) the claimed mechanism's parameters'
spread (``_prediction_cov``, the delta method) and (2) the noise terms' (``_noise_scatter``).
``model_chi2(predictive=True)`` carries the fitted θ's covariance into the predicted *mean*
but weighs the residual with the estimator covariance at θ̂ as if exact; that covariance is
quadratic in θ, so its expectation over θ's distribution is C(θ̂) plus Σ_l C(√λ_l·v_l) over
Cov θ's eigenpairs, which (2) adds. Why this and not a model average over the terms' choices:
on halves of white + flicker + random-walk sensors (the weekend benchmark's levels, 2 h
halves) the folds that failed at 1 % were those whose half had under-read a long-τ term
(its model without the flicker, or without the random walk), whose long-τ scatter was then
weighed as too small; averaging the prediction's mean over the neighbouring term choices
(Akaike weights) moved the failures at 1 % from 5 % to 4 %, forcing every term into the
prediction made them 9 %, and the expected scatter took them to 1–1.7 % on the same
records. The terms whose uncertainty (2) carries are fitted on the fit part's τ below its
longest octaves (``_scatter_model``): a drive slower than the part, outside every candidate,
sits on those octaves and would otherwise widen the scatter that is to judge it.
(1) and (2) are absent from ``chi2_ext``, which makes the gain (a poorly determined
model gains nothing by its own uncertainty).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from avard.core.allan.deviations import AllanResult
from avard.core.allan.streaming import StreamingAllan
from avard.core.analysis.spectrum import line_components
from avard.core.errors import DataError, FitError
from avard.core.explain import causes as cz
from avard.core.explain.thermal_fit import ThermalFit, fit_thermal, fit_thermal_axes, lag_filter
from avard.core.explain.thermal_fit.coarse import derounded
from avard.core.explain.thermal_fit.holes import feed, hole_mask
from avard.core.explain.thermal_fit.rounding import DS18B20_STEP_K
from avard.core.io.rates import format_rate, require_compatible
from avard.core.io.screen.log_step import is_coarse
from avard.core.model.fit import NoiseFit, avar_estimate_covariance, fit_noise, model_chi2
from avard.core.model.terms import TERMS
from numpy.typing import NDArray

if TYPE_CHECKING:  # types only: channel_heldout imports the first two where it runs
    from avard.core.explain.thermal_fit.sums import OctaveSums
    from avard.core.explain.thermal_paths.columns import Column
    from avard.core.io.screen import ScreenLog

__all__ = ["DEFINITION", "ChannelHoldout", "Fold", "Holdout", "check_compatible",
           "holdout_file", "holdout_split"]

#: Fewest slow-view points in each part (as for explain's time-domain causes).
MIN_PART_POINTS = 256
#: Causes that are events of one record, not properties of the sensor.
EVENTS = frozenset({"warmup", "bias_step", "excursion"})
#: Lags of a held-out part's start left out (the lag filter's unknown start state:
#: e^(−5) < 1 % of the start-up difference remains).
HELD_SETTLE_LAGS = 5.0

DEFINITION = ("gain = 1 − χ²_ext/χ²_base: generalised χ² (covariance modelled as avard "
              "analyze's fit models it) of the held-out Allan variance ((m/s²)², τ in s) "
              "against the base model (analyze's terms and lines) and against the extended "
              "model (the claimed causes, parameters fitted on the fit part only, their "
              "predicted signals removed from the held-out part); 0 = no better, 1 = perfect, "
              "< 0 = worse. χ² ≈ n (the number of held-out τ) when a model predicts the data.")


class AvarOf(Protocol):
    """(series, blocks per second[, rows kept]) -> its Allan variance; the rows kept only
    where some are left out as gaps (``_avar``, or ``_channel``'s kept by content)."""

    def __call__(self, y: NDArray, rate: float, keep: NDArray[np.bool_] | None = None, /
                 ) -> AllanResult: ...


class _Lined(Protocol):
    @property
    def lines(self) -> list[dict[str, float]]: ...


class Explained(Protocol):
    """What the held-out measure reads of one axis's explanation
    (``engine.ChannelExplanation``, which imports this module): analyze's lines of the axis
    (``base.lines``), the claimed findings and the whole record's thermal fit."""

    @property
    def base(self) -> _Lined: ...

    @property
    def claimed(self) -> list[cz.Finding]: ...

    @property
    def thermal(self) -> ThermalFit | None: ...


def _avar(y: NDArray, rate_hz: float, keep: NDArray[np.bool_] | None = None) -> AllanResult:
    """Analyze's streaming estimator on one slow-view series; the rows ``keep`` leaves out
    are gaps (no Allan difference spans them)."""
    sa = StreamingAllan(1, rate_hz)
    feed(sa, np.asarray(y, dtype=float)[:, None], keep)
    return sa.result()


# --------------------------------------------------------------------------------------------
# results


@dataclass
class Fold:
    """One fit-part → held-out-part prediction of one axis."""

    fit_part: str
    heldout_part: str
    chi2_base: float
    chi2_ext: float
    n_points: int
    tau_range_s: tuple[float, float]
    #: ``chi2_ext`` with the uncertainty of the claimed mechanism's prediction added to the
    #: covariance (``_prediction_cov``): the verdict's held-out test. ``chi2_ext`` (its
    #: parameters taken as exact, as the base model's prediction is) makes the gain, so a
    #: poorly determined mechanism gains nothing by its own uncertainty. NaN: not measured.
    chi2_ext_pred: float = math.nan

    def to_dict(self) -> dict[str, Any]:
        return {"fit_part": self.fit_part, "heldout_part": self.heldout_part,
                "chi2_base": self.chi2_base, "chi2_extended": self.chi2_ext,
                "chi2_extended_with_prediction": self.chi2_ext_pred,
                "n_points": self.n_points, "tau_range_s": list(self.tau_range_s)}


@dataclass
class ChannelHoldout:
    """One axis: held-out χ² of the base and the extended model, summed over the folds."""

    name: str
    causes: list[str]
    folds: list[Fold] = field(default_factory=list)
    reason: str | None = None

    @property
    def chi2_base(self) -> float:
        return float(sum(f.chi2_base for f in self.folds)) if self.folds else math.nan

    @property
    def chi2_ext(self) -> float:
        return float(sum(f.chi2_ext for f in self.folds)) if self.folds else math.nan

    @property
    def chi2_ext_pred(self) -> float:
        """``chi2_ext`` with the prediction's own uncertainty (``Fold.chi2_ext_pred``)."""
        return float(sum(f.chi2_ext_pred for f in self.folds)) if self.folds else math.nan

    @property
    def n_points(self) -> int:
        return sum(f.n_points for f in self.folds)

    @property
    def gain(self) -> float | None:
        """1 − χ²_ext/χ²_base, or None when nothing is claimed on this axis."""
        if not self.causes or not self.folds or not self.chi2_base > 0:
            return None
        return 1.0 - self.chi2_ext / self.chi2_base

    @property
    def note(self) -> str | None:
        """Why a gain near 0 is expected: the claimed causes are only events (a warm-up, a
        step), which predict nothing in data they were not fitted on."""
        if self.causes and set(self.causes) <= EVENTS:
            return ("a warm-up or a step is an event of one record: it predicts no other "
                    "data, so its held-out gain is near 0 by design; its own test is the "
                    "evidence")
        return None

    def to_dict(self) -> dict[str, Any]:
        return {"causes": self.causes, "chi2_base": self.chi2_base, "note": self.note,
                "chi2_extended": self.chi2_ext,
                "chi2_extended_with_prediction": self.chi2_ext_pred, "n_points": self.n_points,
                "gain": self.gain, "folds": [f.to_dict() for f in self.folds],
                "reason": self.reason}


@dataclass
class Holdout:
    """The held-out measure of a whole explanation (``mode`` "split" or "file")."""

    mode: str
    source: str
    block_s: float
    channels: dict[str, ChannelHoldout] = field(default_factory=dict)
    reason: str | None = None
    #: what the input screen masked in the held-out record (``--holdout FILE``; a
    #: ``core.io.screen.ScreenLog``), None for the record's own halves
    screen: ScreenLog | None = None

    @property
    def gain(self) -> float | None:
        """1 − Σχ²_ext/Σχ²_base over the axes with a claimed cause; None when there is none
        (or the record could not be split)."""
        chs = [c for c in self.channels.values() if c.gain is not None]
        if self.reason is not None or not chs or self._events_only:
            return None
        b = sum(c.chi2_base for c in chs)
        return 1.0 - sum(c.chi2_ext for c in chs) / b if b > 0 else None

    @property
    def _events_only(self) -> bool:
        """Every claimed cause on every axis is an event (a warm-up, a step): their held-out
        gain is near 0 by design, so a headline figure would read as a failed model."""
        claimed = [set(c.causes) for c in self.channels.values() if c.causes]
        return bool(claimed) and all(cs <= EVENTS for cs in claimed)

    @property
    def why_no_gain(self) -> str | None:
        if self.reason is not None:
            return self.reason
        if self._events_only:
            return ("every claimed cause is an event of this record (a warm-up or a step): "
                    "it predicts no other data, so there is no held-out gain to measure; "
                    "each cause's own test is the evidence (per-axis χ² in 'channels')")
        if self.gain is None:
            # an axis with a claim whose held-out fit failed is not "nothing claimed" (a lag
            # of 1837 s on a 4 h record left too little of each half, and the text said no
            # cause was claimed beside a FOUND temperature)
            failed = [f"{k}: {c.reason}" for k, c in self.channels.items()
                      if c.causes and c.reason is not None]
            if failed:
                return ("the axes with a claimed cause could not be held out ("
                        + "; ".join(failed) + ")")
            return "no cause claimed on any axis: the extended model is the base model"
        return None

    def screen_dict(self) -> dict[str, Any] | None:
        """The held-out record's screen for the JSON (``holdout_screened``, beside the
        record's ``screened``): the same shape, with the held-out record's name."""
        if self.screen is None:
            return None
        return {"record": "held-out", "source": self.source, **self.screen.to_dict()}

    def screen_lines(self, limit: int = 8) -> list[str]:
        """The held-out record's screen in the text, each line said to be the held-out
        record's (the record's own screen is said just before it)."""
        if self.screen is None:
            return []
        first, *rest = self.screen.lines(limit)
        return [f"held-out record {self.source}: {first}", *rest]

    def to_dict(self) -> dict[str, Any]:
        return {"mode": self.mode, "source": self.source, "holdout_gain": self.gain,
                "definition": DEFINITION, "reason": self.why_no_gain,
                "slow_view_block_s": self.block_s, "units": "SI",
                "channels": {k: v.to_dict() for k, v in self.channels.items()}}


# --------------------------------------------------------------------------------------------
# the causes of one axis, refitted on a fit part


@dataclass
class Part:
    """A slice of the slow view of one axis, ``y`` (m/s²); ``t0_s`` its start (s) on the time
    axis of its own record; ``label`` for the output."""

    y: NDArray[np.float64]
    t0_s: float
    label: str
    first: bool  # starts at its record's start (a warm-up can be fitted here)
    #: blocks per second of the part's own record (None: the fold's); a second record of the
    #: same sensor fits its own rate, so its τ are its own
    rate_b: float | None = None
    #: the thermal model fitted on this part (split: one lag scan for all the axes that
    #: claim the same channel, ``_part_thermals``); None: fitted when needed
    thermal: ThermalFit | None = None
    #: per temperature column, (first, last) blocks of this part where the input screen says
    #: its log tells nothing of the temperature (a dropout, a stuck run): the held-out
    #: prediction through that log is interpolated there, so those blocks and the lag's
    #: settling after them are gaps of the held-out Allan variance (``_fold``)
    holes: dict[int, list[tuple[int, int]]] = field(default_factory=dict)
    #: the (step K, origin) of the claimed channel's readings in this part's record where it
    #: is its own (a second record's logs screened for their own step); None: the thermal
    #: model's (``ThermalFit.grid``)
    grid: tuple[float, float] | None = None

    def rate(self, default: float) -> float:
        return default if self.rate_b is None else self.rate_b


@dataclass
class Claims:
    """What explain claimed on the whole record for one axis (parameters from there are used
    only where stated: the Gauss–Markov T, the temperature channel, the step's time)."""

    thermal_channel: int | None = None  # index into the temperature columns
    warmup: bool = False
    step_time_s: float | None = None
    gauss_markov_T: float | None = None
    lines: list[dict[str, float]] = field(default_factory=list)
    whole_thermal: ThermalFit | None = None  # the whole record's, for "file"
    whole_warmup: tuple[float, float] | None = None  # (T, size) for "file"
    whole_step: tuple[float, float] | None = None  # (time, size) for "file"
    #: every claimed step, excursion and drift of the whole record, in its order: (cause,
    #: params, 68 % intervals); their times locate them in a part, their sizes (a drift's
    #: rate) are the whole record's, used only in "file" (``_signals``)
    events: list[tuple[str, dict[str, float], dict[str, list[float]]]] = field(
        default_factory=list)

    @property
    def names(self) -> list[str]:
        out = []
        if self.thermal_channel is not None:
            out.append("temperature")
        if self.warmup:
            out.append("warmup")
        if self.step_time_s is not None:
            out.append("bias_step")
        for cause in ("excursion", "drift"):
            if any(e[0] == cause for e in self.events):
                out.append(cause)
        if self.gauss_markov_T is not None:
            out.append("gauss_markov")
        return out


Temps = tuple[NDArray, slice] | None
#: a claimed mechanism's predicted held-out signal changed to the lower and the upper end of
#: one of its parameters' 68 % intervals (added to the prediction)
Spread = tuple[NDArray[np.float64], NDArray[np.float64]]


def _signals(fit: Part, held: Part, c: Claims, rate_b: float, refit: bool,
             u_fit: Temps, u_held: Temps
             ) -> tuple[NDArray[np.float64], NDArray[np.float64], int, float, list[Spread],
                        NDArray[np.float64], NDArray[np.bool_] | None]:
    """(signal on the fit part, its prediction on the held-out part, blocks to leave out at
    the held-out part's start, the longest lag of the temperature prediction (s), the
    prediction's changes at the ends of its parameters' 68 % intervals: ``Spread``, the
    claimed events' nuisance signal on the held-out part and the held-out blocks their edges
    leave out, both for *both* models: ``_held_events``) of the claimed causes.
    ``u_fit``/``u_held``: (the claimed
    temperature channel of the part's record (°C), the part's slice of it), for the lag
    filter; ``refit``: fit the parameters on the fit part (split) or use the whole record's
    (file: the fit part is the whole record).

    The sensor's temperature when a record starts is unknown (the lag filter's start state).
    On a fit part that starts its record, the start-up settling is fitted with the thermal
    model (``ThermalFit.signal(temps, y)``, as explain does); on a held-out part nothing may
    be fitted, so its first ``HELD_SETTLE_LAGS`` lags are left out of both models' χ²."""
    d_fit = np.zeros(len(fit.y))
    d_held = np.zeros(len(held.y))
    skip = 0
    longest = 0.0
    spread: list[Spread] = []
    wt = c.whole_thermal
    if (c.thermal_channel is not None and u_fit is not None and u_held is not None
            and wt is not None and wt.path is not None and wt.mechanism != "one_lag"):
        # a thermal path beyond one lag: its θ and coefficients from the whole record (its
        # own held-out choice is ``thermal_paths``'), the signal run over each part's whole
        # logged series so that a part starts in the state the sensor was in
        th0 = replace(wt, channel_index=0)
        sf = th0.signal(u_fit[0][:, None])[u_fit[1]]
        sh = replace(th0, grid=held.grid or th0.grid).signal(u_held[0][:, None])[u_held[1]]
        d_fit += sf - sf.mean()
        d_held += sh - sh.mean()
        # its response's size known to its coefficient's se (θ's own spread is not carried)
        r = wt.coef_se / abs(wt.coefficient) if wt.coefficient else math.nan
        if math.isfinite(r) and r > 0:
            spread.append((-r * (sh - sh.mean()), r * (sh - sh.mean())))
        longest = max(abs(x) for x in wt.path.chosen.theta[:2]) if wt.path.kind in (
            "two_path",) else abs(wt.lag_s)
        if held.first and longest > 0:
            skip = math.ceil(HELD_SETTLE_LAGS * longest * held.rate(rate_b))
    elif c.thermal_channel is not None and u_fit is not None and u_held is not None:
        part_t = u_fit[0][u_fit[1]][:, None]
        if refit:
            th = fit.thermal if fit.thermal is not None else \
                fit_thermal(fit.y, part_t, ["t"], rate_b)
        else:
            assert c.whole_thermal is not None
            th = replace(c.whole_thermal, channel_index=0)
        coef, lag = th.coefficient, th.lag_s
        longest = abs(lag)
        if fit.first:
            d_fit += th.signal(part_t, fit.y)
        else:
            # the lag runs over the whole logged series the part belongs to, so the part
            # starts in the state the sensor was in
            uf = lag_filter(derounded(u_fit[0], th.grid), lag, rate_b)[u_fit[1]]
            d_fit += coef * (uf - uf.mean())
        # the de-rounded log, as ``ThermalFit.signal`` removes it on the whole record: the
        # readings' rounding is not in the axis, and a negative lag's lead-lag (gain 2 at
        # high frequencies) would put it into the prediction as a misfit of the right model
        g_held = held.grid or th.grid
        t_held = derounded(u_held[0], g_held)
        uh = lag_filter(t_held, lag, held.rate(rate_b))[u_held[1]]
        d_held += coef * (uh - uh.mean())
        if math.isfinite(th.coef_se) and th.coef_se > 0:
            spread.append((-th.coef_se * (uh - uh.mean()), th.coef_se * (uh - uh.mean())))
        ends = []
        # the lag's ends read a coarse held-out log as the prediction does (its own step):
        # on the readings, the ends' difference from the prediction was the coarse rounding
        # through the lag, a spread that widened the prediction by what no lag moves (the
        # 12-bit log's ends stay on its readings, as they were)
        t_ends = t_held if is_coarse(g_held[0]) else u_held[0]
        for lg in (th.lag_lo, th.lag_hi):
            if math.isfinite(lg) and lg != lag:
                ul = lag_filter(t_ends, lg, held.rate(rate_b))[u_held[1]]
                ends.append(coef * ((ul - ul.mean()) - (uh - uh.mean())))
            else:
                ends.append(np.zeros(len(held.y)))
        if any(e.any() for e in ends):
            spread.append((ends[0], ends[1]))
        if held.first and lag != 0:
            skip = math.ceil(HELD_SETTLE_LAGS * abs(lag) * held.rate(rate_b))
    if c.warmup and fit.first:
        if refit:
            _sse, T, size = cz.transient_fits(fit.y - d_fit, rate_b)["warmup"]
        else:
            assert c.whole_warmup is not None
            T, size = c.whole_warmup
        d_fit += cz.warmup_signal(len(fit.y), rate_b, T, size)
        if held.t0_s > fit.t0_s:  # the same record, later: the warm-up's tail
            d_held += cz.warmup_signal(len(held.y), held.rate(rate_b), T, size,
                                       t0_s=held.t0_s)
    rate = _fit_events(fit, c, rate_b, refit, d_fit)
    if rate is not None:
        # a drift is a constant rate (the sensor's ageing), not an event: the fit part's rate
        # predicts the held-out part's ramp, known to the whole record's interval widened to
        # the fit part's length (a walk-dominated slope's error ∝ 1/√length)
        th_ = np.arange(len(held.y)) / held.rate(rate_b)
        ramp = th_ - th_.mean()
        d_held += rate * ramp
        iv = next((e[2].get("rate") for e in c.events if e[0] == "drift"), None)
        if iv is not None and len(iv) == 2 and all(map(math.isfinite, iv)):
            n_all = len(fit.y) + (len(held.y) if refit else 0)
            se = 0.5 * abs(iv[1] - iv[0]) * math.sqrt(n_all / len(fit.y))
            if se > 0:
                spread.append((-se * ramp, se * ramp))
    w_held, gaps = _held_events(fit, held, c, rate_b, refit, d_held)
    return d_fit, d_held, skip, longest, spread, w_held, gaps


def _event_column(cause: str, p: dict[str, float], n: int, rate: float, t0_s: float
                  ) -> NDArray[np.float64] | None:
    """A claimed step's or excursion's shape (unit size) on ``n`` blocks from ``t0_s``, None
    where it is constant there (its edges outside: an offset, nothing to the AVAR)."""
    if cause == "bias_step":
        col = cz.step_signal(n, rate, p["time_s"], 1.0, t0_s=t0_s)
    elif cause == "excursion":
        col = (cz.step_signal(n, rate, p["start_s"], 1.0, t0_s=t0_s)
               - cz.step_signal(n, rate, p["end_s"], 1.0, t0_s=t0_s))
    else:
        return None
    return col if np.ptp(col) > 0 else None


def _fit_events(fit: Part, c: Claims, rate_b: float, refit: bool,
                d_fit: NDArray[np.float64]) -> float | None:
    """Remove the claimed steps, excursions and drift from the fit part (``d_fit``, in place)
    and return the drift's rate (m/s³; None: none claimed). Split: their times from the
    whole record (where the search placed them), their sizes and the rate by one least
    squares on this part alone, with the other claimed signals already out; file: the whole
    record's, the fit part being the whole record. Every event whose edge the part holds is
    removed, not one step re-detected on the part (that found the larger edge of whatever
    the part held: one of two steps, or an excursion's edge read as a step)."""
    if not c.events:
        return None
    n = len(fit.y)
    if not refit:
        rate = None
        for cause, p, _iv in c.events:
            if cause == "drift":
                rate = float(p["rate"])
                t = np.arange(n) / rate_b
                d_fit += rate * (t - t.mean())
            else:
                col = _event_column(cause, p, n, rate_b, fit.t0_s)
                if col is not None:
                    d_fit += p["size"] * col
        return rate
    cols = [col for cause, p, _iv in c.events
            if (col := _event_column(cause, p, n, rate_b, fit.t0_s)) is not None]
    drift = any(e[0] == "drift" for e in c.events)
    t = np.arange(n) / rate_b
    if drift:
        cols.append(t - t.mean())
    if not cols:
        return None
    X = np.column_stack([np.ones(n), *cols])
    beta = np.linalg.lstsq(X, fit.y - d_fit, rcond=None)[0]
    d_fit += X[:, 1:] @ beta[1:]
    return float(beta[-1]) if drift else None


def _held_events(fit: Part, held: Part, c: Claims, rate_b: float, refit: bool,
                 d_held: NDArray[np.float64]
                 ) -> tuple[NDArray[np.float64], NDArray[np.bool_] | None]:
    """The claimed events that lie in the held-out part (split only: a second record holds
    none of this one's): (a signal to remove from the held-out series of *both* models, the
    blocks both models' held-out Allan variance leaves out as gaps; None: none).

    An event predicts nothing in data it was not fitted on (its size in the held-out part
    is not known from the fit part), so it must neither count against the extended model
    (which, fitted where the event is absent or removed, carries no noise that absorbs it)
    nor for it: it is taken out of the held-out comparison the same way for both. A step's
    or an excursion's edge is *cut*: the blocks around it (its time's 68 % interval, three
    times over, and a block each side) are gaps, and no Allan difference spans them; an
    offset is invisible to every difference that does not, so nothing is fitted on the
    held-out data and only the edge's time, not its size, comes from the whole record. A
    warm-up in a held-out part that starts the record has no edge to cut: its time constant
    and size are refitted there as a nuisance (least squares, ``causes.transient_fits``,
    with the predicted signals out) and removed from both models' series. (A warm-up in the
    fit part predicts its own tail in the later held-out part: ``_signals``.)"""
    n = len(held.y)
    w = np.zeros(n)
    if not refit:
        return w, None
    rh = held.rate(rate_b)
    t = held.t0_s + np.arange(n) / rh
    keep = np.ones(n, dtype=bool)
    for cause, p, iv in c.events:
        keys = {"bias_step": ("time_s",), "excursion": ("start_s", "end_s")}.get(cause, ())
        for k in keys:
            e = float(p[k])
            lo, hi = (iv.get(k) or [e, e])[:2]
            a = e - 3.0 * max(0.0, e - lo) - 1.0 / rh
            b = e + 3.0 * max(0.0, hi - e) + 1.0 / rh
            keep &= ~((t >= a) & (t <= b))
    if c.warmup and held.first and not fit.first:
        _sse, T, size = cz.transient_fits(held.y - d_held, rh)["warmup"]
        w += cz.warmup_signal(n, rh, T, size)
    return w, None if keep.all() else keep


def _kept(p: Part, channel: int | None, lag_s: float, rate_b: float
          ) -> NDArray[np.bool_] | None:
    """The blocks of ``p`` its Allan variance keeps (None: all) for an axis predicted through
    temperature column ``channel`` with the longest lag ``lag_s``: its log's holes and the
    lag's settling after them left out (``thermal_fit.hole_mask``)."""
    if channel is None:
        return None
    return hole_mask(len(p.y), p.holes.get(channel, []), lag_s, p.rate(rate_b))


def _part_holes(holes: dict[int, list[tuple[int, int]]] | None, lo: int, hi: int
                ) -> dict[int, list[tuple[int, int]]]:
    """The holes (per temperature column, (first, last) blocks of the record) of the part
    made of the record's blocks ``lo``…``hi - 1``, on the part's own block index. A hole
    that ends before the part's start is kept (at negative blocks): the lag runs over the
    whole logged series, so its settling can reach into the part."""
    return {j: [(a - lo, b - lo) for a, b in spans if a < hi]
            for j, spans in (holes or {}).items()}


def _fold(fit: Part, held: Part, c: Claims, rate_b: float, refit: bool,
          u_fit: Temps, u_held: Temps, avar: AvarOf | None = None) -> Fold:
    """Fit both models on ``fit`` and measure their held-out χ² on ``held``. ``avar``: the
    Allan variance of a series (``_avar`` by default; ``_channel`` keeps it by content)."""
    of = _avar if avar is None else avar

    def av(y: NDArray, rate: float, keep: NDArray[np.bool_] | None = None) -> AllanResult:
        return of(y, rate) if keep is None else of(y, rate, keep)
    nyq = rate_b / 4.0  # lines well below the slow view's Nyquist (block means attenuate)
    # the frequency (and a drifting line's band) fixed, the amplitude fitted on each half
    extra = [{"cause": "sinusoid", "params": {k: ln[k] for k in (
        "frequency_hz", "sweep_lo_hz", "sweep_hi_hz") if k in ln}}
             for ln in line_components(c.lines)
             if 0 < ln["frequency_hz"] and ln.get("sweep_hi_hz", ln["frequency_hz"]) < nyq]
    fit_base = av(fit.y, rate_b)
    base = fit_noise(fit_base, extra=extra)
    if c.names:
        d_fit, d_held, skip, lag, spread, w_held, gaps = _signals(fit, held, c, rate_b, refit,
                                                                  u_fit, u_held)
        # the held-out part's log holes (the screen's dropouts, masked readings and stuck
        # runs; a half of the record as a second record): the prediction there runs on an
        # interpolated temperature, so they and the lag's settling after them are gaps of
        # both models' held-out Allan variance (as of the thermal fit's regression,
        # ``thermal_fit.hole_mask``), never a misfit of the extended model. On the fit part
        # the thermal fit leaves them out of its regression; its Allan variance stays whole
        # (a gapped one fits the noise model worse than the interpolation's residual costs)
        keep = _kept(held, c.thermal_channel, lag, rate_b)
        if gaps is not None:  # the claimed events' edges (``_held_events``)
            keep = gaps if keep is None else keep & gaps
        kept = len(held.y) - skip if keep is None else int(np.count_nonzero(keep[skip:]))
        if kept < MIN_PART_POINTS:
            raise FitError(f"the held-out part is too short once its first {skip} blocks "
                           "(the thermal lag's unknown start state), its log's holes "
                           "and its claimed events' edges are left out")
        ks = None if keep is None else keep[skip:]
        gm = ([] if c.gauss_markov_T is None else
              [{"cause": "gauss_markov", "params": {"T": c.gauss_markov_T}}])
        fit_ext = av(fit.y - d_fit, rate_b)
        ext = fit_noise(fit_ext, extra=[*extra, *gm])
        y_held = held.y - w_held  # a held-out warm-up, out for both models
        held_var = av(y_held[skip:], held.rate(rate_b), ks)
        held_ext = av((y_held - d_held)[skip:], held.rate(rate_b), ks)
        pred_cov = _prediction_cov(y_held - d_held, skip, held.rate(rate_b), spread,
                                   lambda y, r: av(y, r, ks))
    else:
        held_var = av(held.y, held.rate(rate_b))
        ext, held_ext = base, held_var
        pred_cov = None
        fit_ext = fit_base
    # the noise terms' own uncertainty in the held-out AVAR's scatter (``_noise_scatter``),
    # read from the fit part's short τ (``_scatter_model``)
    noise_cov = _noise_scatter(_scatter_model(fit_ext, ext), held_ext)
    pred_cov = noise_cov if pred_cov is None else pred_cov + noise_cov
    rng = (max(base.tau_min_s, ext.tau_min_s), min(base.tau_max_s, ext.tau_max_s))
    # the same block counts on the held-out side, whose τ are in seconds of its own rate
    r = rate_b / held.rate(rate_b)
    rng = (rng[0] * r, rng[1] * r)
    cb = model_chi2(base, held_var, rng, predictive=True)
    ce = model_chi2(ext, held_ext, rng, predictive=True)
    nb, ne = cb.n_points, ce.n_points
    if nb != ne or nb == 0:
        raise FitError(f"no common held-out τ in {rng[0]:.3g}…{rng[1]:.3g} s")
    pred = model_chi2(ext, held_ext, rng, predictive=True, extra_cov=pred_cov).chi2
    return Fold(fit.label, held.label, cb.chi2, ce.chi2, nb, rng, pred)


#: The noise terms whose uncertainty the held-out scatter carries are fitted on the fit
#: part's τ up to its longest over this factor (``_scatter_model``).
SCATTER_TAU_FACTOR = 4.0


@dataclass(frozen=True)
class NoiseOptions:
    """The ``fit_noise`` options a fitted model was made with, as far as the model itself
    says them (``of``): its IEEE terms, its extra components (lines, a Gauss–Markov, a fixed
    rounding white: each with its fixed parameters, the fitted amplitude left to the fit),
    the filter corner it kept, its presence level and interval level. ``fit`` redoes that
    fit on another Allan variance or τ range, so a refit cannot drift from its model when
    ``_fold``'s own fits gain an option."""

    terms: tuple[str, ...]
    extra: tuple[Mapping[str, object], ...]
    filter_corner_hz: float | None
    ci: float
    z_present: float

    @classmethod
    def of(cls, model: NoiseFit) -> NoiseOptions:
        terms = tuple(c.label for c in model.components if c.label in TERMS)
        extra = tuple(
            {"cause": c.cause, "label": c.label,
             "params": {**c.params, **({} if c.fixed_value is None
                                       else {c.value_key: c.fixed_value})}}
            for c in model.components if c.label not in TERMS)
        return cls(terms, extra, model.filter_corner_hz, model.ci, model.z_present)

    def fit(self, result: AllanResult, tau_range: tuple[float, float] | None = None
            ) -> NoiseFit:
        # the model kept its filter (or had none): not checked again on a part of its τ
        return fit_noise(result, terms=self.terms, extra=self.extra,
                         filter_corner_hz=self.filter_corner_hz, check_filter=False,
                         ci=self.ci, z_present=self.z_present, tau_range=tau_range)


def _scatter_model(fit_avar: AllanResult, model: NoiseFit) -> NoiseFit:
    """The noise fit whose terms' uncertainty ``_noise_scatter`` carries: ``model``'s own
    fit (its options, ``NoiseOptions.of``) redone on the fit part's Allan variance
    ``fit_avar`` over τ up to ``model.tau_max_s / SCATTER_TAU_FACTOR`` (``model`` itself
    when that fit fails).

    Why not ``model``'s: a drive slower than the fit part that no candidate describes sits
    on its longest τ, where the terms are known to a few EDF; there it widens the upper
    limits of the terms the fit leaves out (a random walk, a rate ramp) or takes the place
    of the term that is there, and the scatter carried from those limits then hides in the
    other half the very misfit the held-out test exists to find. Below the longest octaves
    that drive cannot reach: the terms are read where they are known, and what the short τ
    cannot tell (a random walk's level) still carries its own, honest, upper limit. On a
    half without such a drive the short fit knows the long-τ terms less well than the whole
    range does, so its scatter is often the larger: the held-out test stays calibrated on
    described sensors (``tests/core/test_heldout_calibration.py``); the branch's log
    (docs/log/2026-11-29-heldpow28.md) has the measured nulls and power. The refit is
    ``model``'s with its own options (terms, lines, filter corner, presence level): a
    scatter read from another model (another z, no filter) would carry another model's
    uncertainty."""
    hi = model.tau_max_s / SCATTER_TAU_FACTOR
    if not hi > model.tau_min_s:
        return model
    try:
        return NoiseOptions.of(model).fit(fit_avar, (0.0, hi))
    except (FitError, DataError, ValueError, np.linalg.LinAlgError):
        return model


def _noise_scatter(model: NoiseFit, result: AllanResult) -> NDArray[np.float64]:
    """What the noise terms' uncertainty adds to the held-out AVAR's *scatter*: the
    expectation, over the fitted θ's distribution (θ̂, Cov θ), of the estimator covariance
    C(θ) less C(θ̂), on all of ``result``'s τ.

    ``model_chi2(predictive=True)`` carries Cov θ into the predicted *mean* (X·Cov θ·Xᵀ), but
    weighs the residual with the estimator covariance at the fitted θ̂ as if exact. That
    covariance is a quadratic form in θ (the Whittle kernels of S = Σθ_j·s_j:
    C(θ) = (2/M)·θᵀGθ), so E[C(θ)] = C(θ̂) + C_G(Cov θ), and with Cov θ = Σ λ_l v_l v_lᵀ,
    C_G(Cov θ) = Σ_l C(√λ_l·v_l). A half that happens to under-read a term (a random walk's
    or a flicker's level from a 2 h half is known to tens of %) otherwise weighs the other
    half's long τ, where that term's scatter dominates, with a variance too small for it: on
    pure white + flicker + random-walk halves the held-out test failed at 1 % about five
    times too often, each fold alike. The terms the fit left out carry their standard error
    U²/z (as ``model_chi2`` gives their mean), θ̂ 0. The estimator's floor (2σ⁴/EDF on the
    diagonal) is left at θ̂ (C(√λ·v) of a small direction keeps a floor of its own, below
    the kernels' by the floor's 1/(100·M))."""
    comps = model.components
    cov = np.array(model.theta_cov, dtype=float)
    for k, c in enumerate(comps):
        te = model.terms.get(c.label)
        if te is not None and not te.present and te.upper:
            cov[k, k] += (te.upper**2 / model.z_present) ** 2
    m = np.asarray(result.m, dtype=np.int64)
    stride = np.asarray(getattr(result, "stride", np.ones_like(m)), dtype=float)
    # the samples the differences of each τ span (``fit._n_samples``)
    n_samp = (np.asarray(result.n, dtype=float) - 1.0) * stride + 2.0 * m
    out = np.zeros((len(m), len(m)))
    if not np.all(np.isfinite(cov)) or not cov.any():
        return out
    lam, V = np.linalg.eigh(0.5 * (cov + cov.T))
    for lv, v in zip(lam, V.T, strict=True):
        if lv > 0:
            c = avar_estimate_covariance(comps, math.sqrt(lv) * v, m, n_samp,
                                         float(result.rate_hz), stride)
            out += np.where(np.isfinite(c), c, 0.0)
    return out


def _prediction_cov(y_ext: NDArray, skip: int, rate: float, spread: list[Spread],
                    avar: Callable[[NDArray, float], AllanResult]
                    ) -> NDArray[np.float64] | None:
    """The covariance, over the held-out AVAR's τ, that the claimed mechanism's parameters'
    uncertainty adds to the extended model's prediction (the delta method): the held-out
    AVAR with the predicted signal removed, ``y_ext``, changes by g·δp when a parameter p
    moves by δp; g·σ_p is half the difference of that AVAR with p at the two ends of its
    68 % interval. Parameters taken as independent (each carries its own end pair).

    Without it a mechanism fitted on one half is held to predict the other as if its
    parameters were exact, and a correct one fails the held-out test by its own fitting
    error: the held-out χ² then needs a ratio over n that also hides wrong mechanisms."""
    if not spread:
        return None
    cols = []
    for lo, hi in spread:
        a = np.asarray(avar((y_ext - lo)[skip:], rate).var, dtype=float).ravel()
        b = np.asarray(avar((y_ext - hi)[skip:], rate).var, dtype=float).ravel()
        g = 0.5 * (b - a)
        cols.append(np.where(np.isfinite(g), g, 0.0))
    G = np.column_stack(cols)
    return np.asarray(G @ G.T, dtype=float)


# --------------------------------------------------------------------------------------------
# the two modes


def claims_of(ch: Explained, temp_names: Sequence[str]) -> Claims:
    """The claimed causes of one ``explain.ChannelExplanation``."""
    c = Claims(lines=list(ch.base.lines))
    for f in ch.claimed:
        if f.cause == "temperature" and f.channel in temp_names:
            c.thermal_channel = list(temp_names).index(f.channel)
            c.whole_thermal = ch.thermal
        elif f.cause == "warmup":
            c.warmup = True
            c.whole_warmup = (f.params["time_constant_s"], f.params["size"])
        elif f.cause == "bias_step":
            c.step_time_s = f.params["time_s"]
            c.whole_step = (f.params["time_s"], f.params["size"])
        if f.cause in ("bias_step", "excursion", "drift"):
            # every one of them, each located (a second step, an excursion's edges, a
            # drift's ramp) on both parts (``_signals``)
            c.events.append((f.cause, dict(f.params), dict(f.intervals or {})))
        elif f.cause == "gauss_markov":
            c.gauss_markov_T = f.params["time_constant_s"]
    return c


def _channel(name: str, c: Claims, folds: list[tuple[Part, Part]], rate_b: float,
             refit: bool, temps_of: Callable[[Part], Temps]) -> ChannelHoldout:
    out = ChannelHoldout(name, c.names)
    # a part is the fit part of one fold and the held-out part of the other (split, when
    # nothing is left out at its start, or nothing is claimed): its Allan variance, a pure
    # function of its values and rate, is computed once
    seen: dict[tuple[bytes, float, bytes], AllanResult] = {}

    def avar(y: NDArray, rate: float, keep: NDArray[np.bool_] | None = None) -> AllanResult:
        key = (np.ascontiguousarray(y, dtype=float).tobytes(), float(rate),
               b"" if keep is None else np.ascontiguousarray(keep).tobytes())
        if key not in seen:
            seen[key] = _avar(y, rate) if keep is None else _avar(y, rate, keep)
        return seen[key]

    try:
        for fit, held in folds:
            u_fit, u_held = temps_of(fit), temps_of(held)
            out.folds.append(_fold(fit, held, c, rate_b, refit, u_fit, u_held, avar))
    except (FitError, DataError) as exc:
        out.folds = []
        out.reason = f"held-out fit failed: {exc}"
    return out


def holdout_split(explanations: Mapping[str, Explained], y_slow: NDArray, t_slow: NDArray | None,
                  t_names: Sequence[str], names: Sequence[str], rate_b: float,
                  source: str, holes: dict[int, list[tuple[int, int]]] | None = None
                  ) -> Holdout:
    """Two folds over the time-contiguous halves of the record's slow view (module doc).
    ``holes``: per temperature column, the record's blocks where the input screen says its
    log tells nothing; each half carries its own (``Part.holes``), as a second record does
    in ``holdout_file``, and its thermal fit leaves them out as the whole record's does."""
    M = len(y_slow)
    h = M // 2
    ho = Holdout("split", source, 1.0 / rate_b)
    if h < MIN_PART_POINTS:
        ho.reason = (f"record too short to split: {M} slow-view blocks of {1 / rate_b:.3g} s, "
                     f"each half needs {MIN_PART_POINTS}")
        return ho
    claims = {name: claims_of(ch, t_names) for name, ch in explanations.items()}
    halves = _part_holes(holes, 0, h), _part_holes(holes, h, M)
    thermals = _part_thermals(claims, y_slow, t_slow, names, rate_b, h, halves)
    for name, c in claims.items():
        j = list(names).index(name)
        y = y_slow[:, j]
        A = Part(y[:h], 0.0, "first half", True, thermal=thermals.get((name, True)),
                 holes=halves[0])
        B = Part(y[h:], h / rate_b, "second half", False,
                 thermal=thermals.get((name, False)), holes=halves[1])

        def temps_of(p: Part, c: Claims = c) -> Temps:
            if c.thermal_channel is None or t_slow is None:
                return None
            return t_slow[:, c.thermal_channel], slice(0, h) if p.first else slice(h, None)

        ho.channels[name] = _channel(name, c, [(A, B), (B, A)], rate_b, True, temps_of)
    return ho


def _part_thermals(claims: dict[str, Claims], y_slow: NDArray, t_slow: NDArray | None,
                   names: Sequence[str], rate_b: float, h: int,
                   halves: tuple[dict[int, list[tuple[int, int]]], ...] = ({}, {})
                   ) -> dict[tuple[str, bool], ThermalFit]:
    """The thermal model of every axis that claims a temperature channel, fitted on each half
    (key: (axis, first half?)): the axes that claim the same channel share one lag scan
    (``fit_thermal_axes``), as on the whole record, each half's log holes (``halves``, per
    half and temperature column) left out of its regression as the whole record's are;
    each axis's own fit as ``fit_thermal`` gives it alone."""
    out: dict[tuple[str, bool], ThermalFit] = {}
    if t_slow is None:
        return out
    by_channel: dict[int, list[str]] = {}
    for name, c in claims.items():
        if c.thermal_channel is not None:
            by_channel.setdefault(c.thermal_channel, []).append(name)
    for ch, axes in by_channel.items():
        cols = [list(names).index(a) for a in axes]
        for first, part, ph in ((True, slice(0, h), halves[0]),
                                (False, slice(h, None), halves[1])):
            wt = claims[axes[0]].whole_thermal
            fits = fit_thermal_axes(y_slow[part][:, cols], t_slow[part, ch][:, None], ["t"],
                                    rate_b, {0: ph.get(ch, [])}, lag_intervals=False,
                                    grids=None if wt is None else [wt.grid])
            out.update({(a, first): f for a, f in zip(axes, fits, strict=True)})
    return out


@dataclass(frozen=True)
class SetUp:
    """What makes two records the same sensor set-up (``check_compatible``), read from a
    record's meta: its fitted rate (Hz) and that rate's standard uncertainty (0 where the
    record carries none: the rule's 100 ppm slack alone), its accelerometer and temperature
    channels."""

    rate_hz: float
    rate_u_hz: float
    names: tuple[str, ...]
    temperature_names: tuple[str, ...]

    @classmethod
    def of(cls, meta: Mapping[str, object]) -> SetUp:
        # ``RecordInfo.as_meta``'s key (an older spelling accepted: reading only it had
        # taken every record's uncertainty as 0, the rule's 100 ppm alone)
        r = meta.get("rate_hz")
        u = meta.get("rate_u_hz", meta.get("rate_uncertainty_hz"))
        if not isinstance(r, int | float):
            raise DataError(f"the record's meta has no sample rate (rate_hz {r!r})")
        return cls(float(r),
                   float(u) if isinstance(u, int | float) and math.isfinite(u) and u > 0
                   else 0.0,
                   _strings(meta.get("names")), _strings(meta.get("temperature_names")))

    def describe(self) -> str:
        return (f"{format_rate(self.rate_hz, self.rate_u_hz)}, channels "
                f"{','.join(self.names) or 'none'}, temperatures "
                f"{','.join(self.temperature_names) or 'none'}")


def _strings(v: object) -> tuple[str, ...]:
    return tuple(str(x) for x in v) if isinstance(v, list | tuple) else ()


def check_compatible(meta: Mapping[str, object], other: Mapping[str, object], path: str
                     ) -> None:
    """One line (DataError, exit 2) when ``other`` is not a record of the same sensor set-up
    as ``meta``: rates that agree by the one rule of ``core.io.rates`` (every run fits its own
    rate, so two records of one sensor never carry the very same one) and the same
    accelerometer and temperature channels."""
    a, b = SetUp.of(meta), SetUp.of(other)
    require_compatible("the data", a.rate_hz, f"--holdout {path}", b.rate_hz, a.rate_u_hz,
                       b.rate_u_hz)
    if (a.names, a.temperature_names) != (b.names, b.temperature_names):
        raise DataError(f"--holdout {path}: {b.describe()}; the data has {a.describe()}: give "
                        "a record of the same sensor with the same channels")


def holdout_file(explanations: Mapping[str, Explained], y_slow: NDArray, t_slow: NDArray | None,
                 y_held: NDArray, t_held: NDArray | None, t_names: Sequence[str],
                 names: Sequence[str], rate_b: float, source: str,
                 held_rate_b: float | None = None,
                 held_holes: dict[int, list[tuple[int, int]]] | None = None,
                 held_refused: dict[int, str] | None = None,
                 screen: ScreenLog | None = None) -> Holdout:
    """Models fitted on the whole record (its slow view ``y_slow``) predict a second record
    of the same sensor (its slow view ``y_held``, the same block in samples; ``held_rate_b``
    its blocks per second by its own fitted rate, default ``rate_b``). The held-out record
    is screened as the record is (``screen``: its ``ScreenLog``): ``held_holes`` per
    temperature column, its blocks where the log says nothing (gaps of the held-out Allan
    variance of an axis that claims that channel); ``held_refused`` per column, why the
    screen refused its log (a log in °F: nothing of it may predict)."""
    ho = Holdout("file", source, 1.0 / rate_b, screen=screen)
    if len(y_held) < MIN_PART_POINTS:
        ho.reason = (f"held-out record too short: {len(y_held)} slow-view blocks of "
                     f"{1 / rate_b:.3g} s, it needs {MIN_PART_POINTS}")
        return ho
    for name, ch in explanations.items():
        j = list(names).index(name)
        c = claims_of(ch, t_names)
        fit = Part(y_slow[:, j], 0.0, "data", True)
        k = c.thermal_channel
        # the held-out log read on its own step (its screen's), not the record's
        g = None if screen is None or k is None else (
            screen.rounding_grid(t_names[k]) or (DS18B20_STEP_K, 0.0))
        held = Part(y_held[:, j], 0.0, "holdout", True, held_rate_b,
                    holes=dict(held_holes or {}), grid=g)
        why = None if k is None else (held_refused or {}).get(k)
        if why is None and k is not None and t_held is not None and np.count_nonzero(
                np.isfinite(t_held[:, k])) < 2:
            why = "no readings once screened"
        if why is not None and k is not None:
            # the claimed channel's held-out log cannot carry the prediction: said, not
            # measured on a log the screen refused (a °F log read as °C predicts nonsense)
            ho.channels[name] = ChannelHoldout(
                name, c.names, reason=f"held-out fit failed: the held-out record's "
                f"temperature log {t_names[k]} is not used ({why})")
            continue

        def temps_of(p: Part, c: Claims = c) -> Temps:
            src = t_slow if p.label == "data" else t_held
            if c.thermal_channel is None or src is None:
                return None
            return src[:, c.thermal_channel], slice(None)

        ho.channels[name] = _channel(name, c, [(fit, held)], rate_b, False, temps_of)
    return ho


# --------------------------------------------------------------------------------------------
# which logged channel drives an axis, by held-out likelihood (issue 23, item 4)


@dataclass(frozen=True)
class ChannelPath:
    """One logged channel as the driver of one axis through one lag of either sign: its
    held-out −2 ln L (``heldout``, both folds: the coefficient fitted on one half of the
    record, its deviance measured on the other, the lag filter's start state refitted there),
    at the channel's own lag ``lag_s``; ``coefficient`` the whole record's; ``rounding`` the
    share of the held-out deviance the readings' 0.0625 K rounding through that coupling
    makes up (``thermal_paths._View.rounding_share``, reported). The channels of one axis
    share their τ, weights and blocks, so their deviances compare."""

    index: int
    heldout: float
    lag_s: float
    coefficient: float
    rounding: float
    #: ``heldout`` split over the record's ``thermal_paths.PARTS`` parts (each held-out
    #: half's deviance is the sum of its parts': the Allan difference sums add), in the
    #: record's order: what the spread of a difference between two channels is read from
    parts: tuple[float, ...] = ()

    def versus(self, other: ChannelPath) -> tuple[float, float]:
        """(this channel's held-out −2 ln L less ``other``'s, the standard error of that
        difference from its spread over the parts: √(P/(P − 1)·Σ(d_p − d̄)²) for P parts, a
        delete-a-part jackknife's of a sum)."""
        d = np.asarray(self.parts, dtype=float) - np.asarray(other.parts, dtype=float)
        P = len(d)
        se = math.sqrt(P / (P - 1) * float(np.sum((d - d.mean()) ** 2))) if P > 1 else 0.0
        return self.heldout - other.heldout, se


def channel_heldout(y: NDArray, temps: NDArray, lags0: dict[int, float], rate_hz: float,
                    floors: dict[int, float] | None = None,
                    holes: dict[int, list[tuple[int, int]]] | None = None,
                    columns: dict[int, dict[Column, NDArray[np.float64]]] | None = None,
                    steps: dict[int, float] | None = None) -> dict[int, ChannelPath]:
    """Each channel ``j`` of ``lags0`` as the driver of axis ``y`` (slow view at
    ``rate_hz``) through its own lag ``lags0[j]`` (s, the lag scan's on the whole record),
    scored as ``thermal_paths.choose_path`` scores its candidates: the coefficient fitted on
    one half, −2 ln L of the other half with it (the start state refitted there), both
    folds added (``_fit``, ``_dev``, ``_held_dev``, one pass of ``octave_sums_by_part``).

    The lag is each channel's whole-record one, not re-chosen on each half: on the paths'
    coarse grid (0, 15, 30, 60, 120 s …) a half re-chose a 56 s plate lag as −15 and 120 s
    and lost 40 in held-out −2 ln L for it, while a long lag's error is taken up by its
    coefficient (a lag long against the drive's period trades with it), so re-choosing on
    the halves favoured the farther channel on every quiet-lab record tried.

    So the channels compare, every channel's deviance is on one footing: the τ from the
    largest of the channels' rounding floors (``floors``), the blocks outside every
    channel's holes (``holes``, with their settling), and one noise AVAR to weigh the
    residual against, the residual of all the channels together at their own lags on the
    whole record (what none of them explains). ``columns``: per channel, the regressors
    already built for another axis (``path_columns``' ``done``); ``steps``: each channel's
    reading step (K; default the 12-bit), its rounding's."""
    from avard.core.explain.thermal_fit.holes import hole_mask
    from avard.core.explain.thermal_fit.sums import min_tau_for, octave_sums_by_part
    from avard.core.explain.thermal_paths.columns import path_columns, trials
    from avard.core.explain.thermal_paths.deviance import _fit, _held_dev, _resid, _View, _view
    from avard.core.explain.thermal_paths.rounding import _edf_at, sawtooth_avar
    from avard.core.explain.thermal_paths.settings import FIT_POINTS, PARTS

    y = np.asarray(y, dtype=float)
    f = 1 << max(0, math.ceil(math.log2(len(y) / FIT_POINTS)))
    m = (len(y) // f) * f
    ys = y[:m].reshape(-1, f).mean(axis=1)
    rate = rate_hz / f
    keep = np.ones(len(y), dtype=bool)
    for j, L0 in lags0.items():
        kj = hole_mask(len(y), (holes or {}).get(j, []), max(abs(L0), 60.0), rate_hz)
        if kj is not None:
            keep &= kj
    cut: NDArray[np.bool_] = np.asarray(keep[:m].reshape(-1, f).all(axis=1), dtype=bool)
    blocks = [ys]
    idx: dict[int, list[int]] = {}
    Ts = {j: np.asarray(temps[:m, j], dtype=float).reshape(-1, f).mean(axis=1) for j in lags0}
    for j, L0 in lags0.items():
        # (the coupling's column first, then its start state: ``trials``' order)
        cols = list(trials("one_lag", [round(L0, 3)])[0].cols)
        done = None if columns is None else columns.setdefault(j, {})
        first = 1 + sum(b.shape[1] for b in blocks[1:])
        idx[j] = list(range(first, first + len(cols)))
        blocks.append(path_columns(Ts[j], cols, rate, done))
    X = np.column_stack(blocks)
    # each part the differences whose middle it holds, none across the middle: the first
    # and last five parts add up to each half's own sums (as ``choose_path``)
    edges = np.linspace(0, len(ys), PARTS + 1).astype(int)
    cut[int(edges[PARTS // 2])] = False
    parts = octave_sums_by_part(X, edges, cut)
    whole = sum(parts[1:], start=parts[0])
    halves = [parts[:PARTS // 2], parts[PARTS // 2:]]
    half = [sum(h[1:], start=h[0]) for h in halves]
    ms = whole.ms
    ok_tau = (ms / rate) >= min_tau_for(0.0, max((floors or {}).get(j, 0.0) for j in lags0))
    ref = _avar(ys, rate)
    edf = _edf_at(ms / rate, np.asarray(ref.tau, float),
                     np.asarray(ref.edf, float).reshape(len(ref.tau), -1)[:, 0])
    # the weights: the residual of every channel at its own lag on the whole record, the
    # same for each channel (each channel's own one-lag residual, as choose_path weighs its
    # candidates, would give each its own scale)
    joint = [i for ix in idx.values() for i in ix]
    v0 = _view(whole, edf, whole.n, np.ones(len(ms), dtype=bool))
    full = whole.cov()
    r0 = _resid(_View(full, np.ones(len(ms)), np.ones(len(ms))), joint,
                   _fit(_View(v0.cov, v0.nu, v0.cov[:, 0, 0]), joint))
    s_ref = np.where(r0 > 1e-6 * full[:, 0, 0], r0, 1e-6 * full[:, 0, 0])
    vw = _view(whole, edf, whole.n, ok_tau, s_ref)
    out: dict[int, ChannelPath] = {}
    for j, L0 in lags0.items():
        r_ref = sawtooth_avar(Ts[j], rate, ms / rate, L0, step=(steps or {}).get(j))
        vh = [_view(h, edf, whole.n, ok_tau, s_ref, r_ref) for h in half]
        held, per_part = 0.0, []
        for a, b in ((0, 1), (1, 0)):
            beta = _fit(vh[a], idx[j])
            held += _held_dev(vh[b], idx[j], beta, 1)
            per_part += _part_devs(half[b], halves[b], idx[j], beta[:1], edf, whole.n, ok_tau,
                                   s_ref)
        # (per_part in the record's order: the first half's parts were scored second)
        per_part = per_part[PARTS // 2:] + per_part[:PARTS // 2]
        c = float(_fit(vw, idx[j])[0])
        out[j] = ChannelPath(j, held, float(L0), c, sum(v.rounding_share(c) for v in vh),
                             tuple(per_part))
    return out


def _part_devs(half: OctaveSums, parts: list[OctaveSums], idx: list[int], beta: NDArray,
               edf: NDArray, n_ref: NDArray, ok_tau: NDArray, s_ref: NDArray) -> list[float]:
    """The held-out deviance of one half (``thermal_paths._held_dev`` of a model whose
    couplings ``beta`` on columns ``idx[:len(beta)]`` were fitted on the other half, its
    nuisance columns refitted on this one) split over the half's ``parts``: with β and the
    nuisance fixed the residual is one linear combination of the columns, and ν·r of the
    half is the sum of its parts' (the Allan difference sums add, ν ∝ their count)."""
    from avard.core.explain.thermal_paths.deviance import _fit, _View

    k = min(len(half.ms), len(edf), len(ok_tau))
    covh = half.cov()[:k]
    with np.errstate(invalid="ignore", divide="ignore"):
        nuh = np.asarray(edf[:k], float) * half.n[:k] / np.asarray(n_ref[:k], float)
    s = np.asarray(s_ref[:k], float)
    good = (ok_tau[:k] & np.isfinite(nuh) & (nuh >= 3)
            & np.all(np.isfinite(covh), axis=(1, 2)) & np.isfinite(s) & (s > 0))
    n = len(beta)
    C = covh.shape[1]
    A = np.zeros((1 + len(idx) - n, C))
    A[0, 0] = 1.0
    A[0, idx[:n]] -= beta
    for r, j in enumerate(idx[n:], start=1):
        A[r, j] = 1.0
    v = _View(np.einsum("ri,kij,sj->krs", A, covh[good], A), nuh[good], s[good])
    rest = list(range(1, A.shape[0]))
    g = _fit(v, rest) if len(v.nu) else np.zeros(len(rest))
    vec = A[0] - g @ A[1:] if rest else A[0]
    out = []
    for p in parts:
        cp = p.cov()[:k][good]
        with np.errstate(invalid="ignore", divide="ignore"):
            nup = np.asarray(edf[:k], float)[good] * p.n[:k][good] / np.asarray(n_ref[:k],
                                                                              float)[good]
            r = np.einsum("i,kij,j->k", vec, np.nan_to_num(cp), vec)
        out.append(float(np.sum(np.nan_to_num(nup * r / s[good]))))
    return out

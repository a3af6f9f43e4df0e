"""``avard explain``: where the fitted noise model leaves the measurement, the physical cause,
and the model extended by it; on the engine of ``avard analyze``. docs/explain.md is the
reference.

Streamed, in bounded memory:

1. **Base model = analyze's fit.** ``explain_file`` calls ``analysis.engine.analyze`` on the
   record, the very function ``avard analyze`` runs, with its passes and so its peak memory
   (blocks from anywhere, ``explain_stream``, go through the same ``analyze`` in one pass);
   the record is screened once (``core.io.screen.ScreenedSource``) for both. Its Allan
   estimator and EDF, its line finder (``analysis.spectrum.find_lines``), its
   ``fit.fit_noise`` GLS with the modelled covariance, presence test, intervals and upper
   limits. Sinusoids found there are part of the base model.
2. **Slow view.** On analyze's first pass (``analysis.engine.FirstPassTap``: that pass reads
   every column and the temperatures through the one screen; only a parallel analysis, whose
   workers read the chunks, leaves it to one more read), block means of every axis and
   temperature channel are kept (blocks of 2^k samples, at least ``BLOCK_S``, at most
   ``MAX_POINTS`` per channel: ≈ 2 MB a channel).
   Everything explain adds acts on seconds or longer, so it is found there.
3. **Causes**, each tested at its share of one false-alarm level per axis (``alarm``):

   - ``temperature`` (:mod:`avard.core.explain.thermal_fit`, then
     :mod:`avard.core.explain.thermal_paths`): which logged channel drives the axis through a
     first-order lag of either sign, coefficient (m/s²/K) and lag (s) with 68 % intervals from
     the streaming Allan covariance of axis and lagged temperature; then whether a richer path
     (two lags, a quadratic, a dT/dt term, hysteresis) predicts held-out halves better.
   - ``warmup``, ``bias_step``, ``excursion`` and ``drift``
     (:mod:`avard.core.explain.transients`, ``_compound``): on the slow view by GLS with the
     noise covariance of N, B, K; ``find_compound`` proposes effects one at a time while the
     best reaches a fraction of its Bonferroni threshold, refines them together and drops,
     one at a time, those below their threshold in the joint fit against the noise with all
     of them removed; ``confirm_compound`` is the claim's test (z on the scan's grid and the
     size's distance from zero, both at the threshold), at the search's end and again when a
     transient is taken out afterwards (below the temperature's rounding through the coupling,
     ``causes.transient_floor``; in a hole of the driving log, ``_not_in_hole``; a warm-up
     the lag filter's start state can make). A drift is told from a random walk in the time
     domain (``transients.test_drift``). The window-contrast detectors of
     :mod:`avard.core.explain.causes` serve only quick looks (the thermal start state's
     check, a held-out part's leftover step).
   - ``gauss_markov`` (:mod:`avard.core.explain.gauss_markov`): a component of the GLS fit
     itself (closed-form AVAR), its T scanned by −2 ln L.
   - ``sinusoid`` / ``periodic``: analyze's lines, one finding per disturbance
     (``spectrum.line_groups``).

   The claimed signals are removed from the axis through the Allan covariance of axis and
   signal (``removed_avar``) and analyze's fit is made again on what is left, their
   parameters' uncertainty carried in as a covariance of the points
   (``removal_covariance``, ``fit_noise(added_cov=…)``). Rate ramp, the chip filter and the
   LSB rounding are terms of analyze's model already.
4. **Gain**: generalised χ²/dof (with the modelled covariance) of the base over the extended
   fit: 1 = no change. **Verdict** (:mod:`avard.core.explain.verdict`): whether the extended
   model describes the axis in-sample and on held-out data, else "unexplained".
5. **Held-out gain** (:mod:`avard.core.explain.holdout`): both models refitted on one half of the
   slow view predict the other (two folds), or, with a second record of the same sensor
   (``holdout``), fitted on this record predict that one; 1 − χ²_ext/χ²_base of the held-out
   AVAR.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from avard.core.allan.streaming import StreamingAllan
from avard.core.analysis.engine import ProgressFn, analyze
from avard.core.analysis.results import Analysis, ChannelAnalysis
from avard.core.analysis.spectrum import LineGroup, line_components, line_groups
from avard.core.blas import one_blas_thread
from avard.core.errors import DataError, FitError
from avard.core.explain import causes as cz
from avard.core.explain import coupling_change as cchange
from avard.core.explain import transients as tr
from avard.core.explain.causes import Finding
from avard.core.explain.gauss_markov import scan_gauss_markov
from avard.core.explain.holdout import (
    EVENTS,
    ChannelHoldout,
    Holdout,
    check_compatible,
    holdout_file,
    holdout_split,
)
from avard.core.explain.options import DEFAULT_EXPLAIN, ExplainOptions
from avard.core.explain.thermal_fit import (
    ThermalFit,
    compensated_avar,
    fit_thermal_axes,
    signal_avar_on,
    with_paths,
)
from avard.core.explain.thermal_fit.axes import path_of
from avard.core.explain.thermal_fit.holes import HOLE_SETTLE_LAGS, feed, hole_mask
from avard.core.explain.thermal_fit.rounding import reading_grid
from avard.core.explain.thermal_paths import (
    both_readings,
    rate_reading,
    reads_as_rate,
    second_path_reading,
)
from avard.core.explain.thermal_paths.readings import holds_beside
from avard.core.explain.verdict import Verdict, compensation_worse_at, judge
from avard.core.io.screen import ScreenedSource, ScreenLog
from avard.core.io.source import RecordSource, StreamSource
from avard.core.model.fit import NoiseFit, fit_noise
from numpy.typing import NDArray

__all__ = ["ChannelExplanation", "Explanation", "Finding", "SlowView", "block_size",
           "explain_file", "explain_stream", "misfit_ranges"]

#: Target length of one slow-view block (s); the block is the next power of two in samples.
BLOCK_S = 1.0
#: Most block means kept per channel (longer records get longer blocks).
MAX_POINTS = 1 << 18
MISFIT_SIGMA = 3.0
#: Fewest slow-view points for the time-domain causes.
MIN_SLOW_POINTS = 256

StageFn = Callable[[str], None]


# --------------------------------------------------------------------------------------------
# the slow view: block means of the axes and temperatures, collected while analyze streams


def block_size(rate_hz: float, n_samples: int | None) -> int:
    """Samples per slow-view block: a power of two (so its τ grid is analyze's octave grid),
    at least ``BLOCK_S`` long and at most ``MAX_POINTS`` blocks for a known length."""
    want = max(1.0, rate_hz * BLOCK_S, (n_samples or 0) / MAX_POINTS)
    return 1 << math.ceil(math.log2(want))


def _after(carry: NDArray[np.float64], x: NDArray[np.float64]) -> NDArray[np.float64]:
    """``x`` after the rows ``carry`` left from the last block (``x`` itself when none)."""
    return np.concatenate([carry, x]) if len(carry) else x


def slow_block_means(a: NDArray[np.float64], b: int) -> NDArray[np.float64]:
    """The means of consecutive ``b``-row blocks of ``a`` (nb·b, C):
    ``a.reshape(nb, b, C).mean(axis=1)`` to the bit. Over that middle axis numpy adds the
    block's rows one after the other, each a C-long inner loop; with C ≥ 2 the same
    additions in the same order are done here as b adds of whole (nb, C) row slices, which
    costs about half as much on every block explain reads. One channel (its blocks
    contiguous, which numpy sums pairwise), rows not laid out one after the other (numpy's
    order follows the strides) and blocks longer than their count (b slices of few rows)
    keep numpy's mean (``tests/core/test_explain_slow_view.py`` holds the two
    equal)."""
    nb = len(a) // b
    v = a.reshape(nb, b, a.shape[1])
    if a.shape[1] < 2 or b > nb or not a.flags.c_contiguous:
        return np.asarray(v.mean(axis=1), dtype=np.float64)
    s = np.zeros((nb, a.shape[1]))  # numpy's sum starts from 0 too (a block of −0.0: +0.0)
    for i in range(b):
        s += v[:, i, :]
    return np.asarray(s / b, dtype=np.float64)


def _reading_means(t: NDArray[np.float64], b: int
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(means, times): the mean of the finite readings in each block of ``b`` rows of ``t``
    (n, k), and the mean row of those readings in the block, as a fraction of a block from
    the block's centre (the acceleration's block mean is at the centre); NaN where a block
    holds none. A DS18B20 reads every 0.75 s, so nearly every value is NaN: the few readings
    are summed into their blocks by ``bincount``, in row order as a sum over the block adds
    them (the zeros a masked sum adds between them change no bit), instead of five passes
    over every value.

    The times are what :meth:`SlowView.finish` places each mean at: a 10 Hz record read
    every 8 rows holds its readings at rows 0 and 8 of a 16-row block, 0.35 s before the
    acceleration's centre, and a mean taken as the block's own value read the temperature
    0.35 s early (a +0.35 s bias on every lag)."""
    nb, k = len(t) // b, t.shape[1]
    r, c = np.nonzero(np.isfinite(t))
    where = (r // b) * k + c
    s = np.bincount(where, weights=t[r, c], minlength=nb * k).reshape(nb, k)
    cnt = np.bincount(where, minlength=nb * k).reshape(nb, k)
    rows = np.bincount(where, weights=(r % b).astype(float), minlength=nb * k).reshape(nb, k)
    with np.errstate(invalid="ignore", divide="ignore"):
        return (np.where(cnt > 0, s / cnt, np.nan),
                np.where(cnt > 0, (rows / cnt - 0.5 * (b - 1)) / b, np.nan))


class SlowView:
    """Block means (``b`` samples each) of C axes and k temperature channels; a temperature
    block without a reading (DS18B20 every 0.75 s) is NaN until ``finish`` interpolates it."""

    def __init__(self, b: int, n_axes: int, n_temps: int) -> None:
        self.b = int(b)
        self._acc: list[NDArray[np.float64]] = []
        self._tmp: list[NDArray[np.float64]] = []
        #: per block, where its readings' mean sits (fraction of a block from its centre)
        self._when: list[NDArray[np.float64]] = []
        self._carry_a = np.zeros((0, n_axes))
        self._carry_t = np.zeros((0, n_temps))
        self.n_temps = n_temps

    def update(self, accel: NDArray, temp: NDArray | None) -> None:
        # the carry is empty when the blocks are whole multiples of b (the usual case): then
        # the block itself, not a copy of it
        a = _after(self._carry_a, np.asarray(accel, dtype=float))
        nb = len(a) // self.b
        self._acc.append(slow_block_means(a[:nb * self.b], self.b))
        self._carry_a = a[nb * self.b:].copy()  # not a view of a block its reader may reuse
        if self.n_temps:
            t = (np.full((len(accel), self.n_temps), np.nan) if temp is None
                 else np.asarray(temp, dtype=float).reshape(len(accel), -1))
            t = _after(self._carry_t, t)
            means, when = _reading_means(t[:nb * self.b], self.b)
            self._tmp.append(means)
            self._when.append(when)
            self._carry_t = t[nb * self.b:].copy()

    def finish(self, holes: Sequence[Sequence[tuple[float, float]]] = (),
               rate_b: float = 1.0
               ) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
        """(axes (M, C), temperatures (M, k) with gaps interpolated, or None). ``holes``: per
        temperature channel, (start, end) s where the screen says the log tells nothing of the
        temperature (a stuck run: its readings were read before the rule could know), made
        gaps before the interpolation; ``rate_b`` blocks per second."""
        acc = np.concatenate(self._acc) if self._acc else np.zeros((0, self._carry_a.shape[1]))
        if not self.n_temps or not self._tmp:
            return acc, None
        tmp = np.concatenate(self._tmp)
        idx = np.arange(len(tmp))
        # each block's readings' mean at the time of its readings, interpolated onto the
        # block centres the acceleration's means sit at (``_reading_means``)
        at = idx[:, None] + np.concatenate(self._when)
        for j, spans in enumerate(holes):
            for t0, t1 in spans:
                tmp[max(0, math.floor(t0 * rate_b)):math.ceil(t1 * rate_b) + 1, j] = np.nan
        for j in range(tmp.shape[1]):
            ok = np.isfinite(tmp[:, j])
            if np.count_nonzero(ok) < 2:
                tmp[:, j] = np.nan
            else:
                tmp[:, j] = np.interp(idx, at[ok, j], tmp[ok, j])
        return acc, tmp


# --------------------------------------------------------------------------------------------
# results


@dataclass
class ChannelExplanation:
    """One axis: analyze's result (``base``), the extended fit, what was tested and found,
    the base model's misfit ranges and the temperature-compensated AVAR (or None)."""

    name: str
    base: ChannelAnalysis
    extended: NoiseFit
    findings: list[Finding]
    misfit: list[dict[str, Any]]
    thermal: ThermalFit | None = None
    compensated_var: NDArray[np.float64] | None = None
    contributions: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    #: AVAR with only the temperature part removed (the thermal fit's compensated curve)
    thermal_compensated_var: NDArray[np.float64] | None = None
    #: the extended model's own misfit ranges (τ beyond 3 σ)
    ext_misfit: list[dict[str, Any]] = field(default_factory=list)
    #: whether the extended model describes the axis (``verdict.judge``), set by explain
    verdict: Verdict | None = None
    #: τ (fitted or not) where the compensation makes the ADEV worse beyond its interval
    #: (then the compensated ADEV is not given)
    compensation_worse_s: list[float] = field(default_factory=list)

    def compensation_dict(self) -> dict[str, Any] | None:
        """The temperature compensation (``avard analyze --temperature``): the thermal fit
        and the compensated ADEV at the channel's τ (m/s²), or None."""
        if self.thermal is None or self.thermal_compensated_var is None:
            return None
        worse = self._worse(self.thermal_compensated_var)
        if worse:
            return {**self.thermal.to_dict(), "compensated_adev": None,
                    "compensated_withheld": _withheld(worse), "units": {}}
        return {**self.thermal.to_dict(),
                "compensated_adev": np.sqrt(self.thermal_compensated_var).tolist(),
                "units": {"compensated_adev": "m/s^2"}}

    @property
    def claimed(self) -> list[Finding]:
        return [f for f in self.findings if f.claimed]

    @property
    def gain(self) -> float:
        """χ²/dof of the base fit over the extended one (1: no change)."""
        b, e = self.base.fit.chi2_dof, self.extended.chi2_dof
        return b / e if math.isfinite(b) and math.isfinite(e) and e > 0 else float("nan")

    def to_dict(self) -> dict[str, Any]:
        ext = self.extended.to_dict()
        tau = self.base.allan.tau
        out: dict[str, Any] = {
            "base": self.base.to_dict(),
            "extended": {"terms": ext["terms"], "fit": ext["fit"],
                         "components": [_extra_dict(e) for e in self.extended.extra]},
            "findings": [f.to_dict() for f in self.findings],
            "misfit": self.misfit,
            "gain": self.gain,
            "verdict": None if self.verdict is None else self.verdict.to_dict(),
            "thermal": None if self.thermal is None else self.thermal.to_dict(),
            "compensated": None,
            "compensated_withheld": None,
        }
        if self.compensated_var is not None:
            if self.compensation_worse_s:
                out["compensated_withheld"] = _withheld(self.compensation_worse_s)
            else:
                out["compensated"] = {"tau_s": tau.tolist(),
                                      "adev": np.sqrt(self.compensated_var).tolist()}
        return out

    def _worse(self, comp_var: NDArray[np.float64]) -> list[float]:
        a = self.base.allan
        return compensation_worse_at(np.asarray(a.tau, dtype=float), a.hi, comp_var)

    def judge(self, held: ChannelHoldout | None, record_reason: str | None = None,
              screen: ScreenLog | None = None) -> None:
        """Set ``verdict`` from the extended fit and the held-out χ² (``held``: this axis's
        ``holdout.ChannelHoldout`` or None; ``record_reason``: why the held-out test asked
        for could not run on the record at all); when it fails, the claimed causes'
        parameters are model-dependent, and their intervals are withheld where held-out
        data reject."""
        # a warm-up or a step predicts nothing in other data: no held-out test of them
        hx: tuple[float | None, int] = (None, 0)
        missing: str | None = None
        if held is not None and held.folds and held.note is None:
            # with the prediction's own uncertainty: the mechanism's parameters were fitted
            # on the other half (``holdout.Fold.chi2_ext_pred``)
            hx = (held.chi2_ext_pred, held.n_points)
        elif held is not None and held.causes and held.note is None:
            # asked, a mechanism to predict, and no fold ran: the in-sample χ² is not the test
            missing = held.reason or "no held-out fold could be fitted"
        elif held is None and record_reason is not None and any(
                f.claimed and f.cause not in (*EVENTS, "sinusoid", "periodic")
                for f in self.findings):
            # asked, and the record itself could not be split (too short): the same
            missing = record_reason
        self.verdict = judge(self.extended.chi2_dof, self.extended.dof, self.ext_misfit, *hx,
                             heldout_missing=missing,
                             changed=cchange.change_line(self.findings))
        if self.verdict.explained:
            return
        chan = None if screen is None or self.thermal is None else self.thermal.channel
        coarse = None if screen is None or chan is None else screen.coarse(chan, cause=True)
        if coarse is not None:
            # the misfit may be the coarse log's, whose temperature the model reconstructs
            # (``screen.ScreenLog.coarse``)
            self.verdict = replace(self.verdict, suspect=f"temperature '{chan}': {coarse}")
        for f in self.findings:
            if f.claimed and f.cause not in ("sinusoid", "periodic"):
                f.model_dependent = True
                if self.verdict.heldout_rejects and f.intervals:
                    f.intervals_if_model_held, f.intervals = f.intervals, {}


def _withheld(worse: list[float]) -> str:
    return ("not given: the compensation makes the ADEV worse than uncompensated beyond its "
            "68 % interval at τ " + ", ".join(f"{t:.3g}" for t in worse[:8])
            + (" …" if len(worse) > 8 else "") + " s (it removes a signal the axis does not "
            "carry there)")


def _extra_dict(e: dict[str, Any]) -> dict[str, Any]:
    return {k: e[k] for k in ("cause", "label", "params", "present", "lo", "hi", "unit")
            if k in e}


@dataclass
class Explanation:
    """The whole result: analyze's ``Analysis`` of the record, one ``ChannelExplanation`` per
    axis, the AVAR of each temperature channel (K², for the report) and the slow-view block."""

    analysis: Analysis
    channels: dict[str, ChannelExplanation]
    temperature: dict[str, Any] = field(default_factory=dict)
    block_s: float = 0.0
    #: the held-out measure (None only when explain was asked not to make it)
    holdout: Holdout | None = None
    #: what the input screen masked (core/io/screen.py), None for blocks that bypassed it
    screen: ScreenLog | None = None
    #: the record's temperature channels the thermal model could not use, with why (a log
    #: without two readings, or one value throughout): said, never dropped in silence
    temperature_unused: dict[str, str] = field(default_factory=dict)

    @property
    def source(self) -> str:
        return self.analysis.source

    @property
    def rate_hz(self) -> float:
        return self.analysis.rate_hz

    def to_dict(self) -> dict[str, Any]:
        """JSON shape (SI units; NaN is written as null by the command)."""
        ho = None if self.holdout is None else self.holdout.to_dict()
        return {"source": self.source, "rate_hz": self.rate_hz,
                "n_samples": self.analysis.n_samples, "units": "SI",
                "holdout_gain": None if ho is None else ho["holdout_gain"],
                "holdout": ho,
                "screened": None if self.screen is None else self.screen.to_dict(),
                # the held-out record's (--holdout FILE), screened by the same rules
                "holdout_screened": None if self.holdout is None
                else self.holdout.screen_dict(),
                "temperature_unused": dict(self.temperature_unused),
                "channels": {k: {**v.to_dict(), "caveats": self.caveats(k)}
                             for k, v in self.channels.items()}}

    def caveats(self, channel: str) -> list[str]:
        """The caveats said under the channel's findings in the text and the report (a
        coupling on a recording of several short runs: ``report.runs_caveat``), for the
        JSON: the same lines, so ``--json`` says what the text says."""
        from avard.core.explain.report import runs_caveat  # report imports this module

        ch = self.channels[channel]
        caveat = (runs_caveat(self) if any(f.cause == "temperature" for f in ch.claimed)
                  else None)
        change = cchange.change_line(ch.findings) or cchange.hedged_line(ch.findings)
        return [c for c in (change, caveat) if c is not None]


# --------------------------------------------------------------------------------------------
# misfit


def misfit_ranges(tau: NDArray, var: NDArray, model_var: NDArray, edf: NDArray,
                  sigma: float = MISFIT_SIGMA) -> list[dict[str, Any]]:
    """Contiguous τ ranges where |z| ≥ sigma, z = (σ̂² − σ²)/(σ²√(2/ν)) (var(σ̂²) = 2σ⁴/ν,
    NIST SP 1065 §5.3), with the largest |z|, its direction and the measured ADEV over the
    model's there (σ̂/σ, the misfit's size in the curve's own terms)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        z = (var - model_var) / (model_var * np.sqrt(2.0 / edf))
    z = np.where(np.isfinite(z), z, 0.0)
    out: list[dict[str, Any]] = []
    i = 0
    while i < len(z):
        if abs(z[i]) >= sigma:
            j = i
            while j + 1 < len(z) and abs(z[j + 1]) >= sigma and np.sign(z[j + 1]) == np.sign(z[i]):
                j += 1
            k = i + int(np.argmax(np.abs(z[i:j + 1])))
            out.append({"tau_range_s": [float(tau[i]), float(tau[j])],
                        "max_sigma": float(z[k]),
                        "adev_ratio": float(np.sqrt(var[k] / model_var[k]))
                        if var[k] > 0 and model_var[k] > 0 else math.nan,
                        "direction": "above" if z[k] > 0 else "below"})
            i = j + 1
        else:
            i += 1
    return out


def _used(fit: NoiseFit, tau: NDArray) -> NDArray[np.bool_]:
    return (tau >= fit.tau_min_s * (1 - 1e-9)) & (tau <= fit.tau_max_s * (1 + 1e-9))


# --------------------------------------------------------------------------------------------
# the stream


Block = tuple[NDArray[np.float64], NDArray[np.float64] | None, bool]


def _why_unused(t: NDArray | None, refused: str | None = None) -> str | None:
    """Why a temperature channel's slow view cannot drive the thermal model, or None where
    it can (every block has a value, and they vary). ``refused``: the input screen's reason
    to refuse the log as a whole (a log in °F: ``ScreenLog.refused``)."""
    if refused:
        return refused
    if t is None or not len(t) or not np.all(np.isfinite(t)):
        return "fewer than two readings"
    if not np.ptp(t) > 0:
        return f"one value throughout ({float(t[0]):.4g} °C): nothing to regress on"
    return None


def _unknown_temperature(temperature: str, meta: dict[str, Any]) -> None:
    tnames = list(meta.get("temperature_names") or [])
    raise DataError(f"temperature channel {temperature!r} is not in this record; its "
                    "temperature channels are " + (", ".join(tnames) or "none"))


@one_blas_thread  # a library entry point (core/blas.py): the pool's workers busy-wait
def explain_file(source: RecordSource, options: ExplainOptions = DEFAULT_EXPLAIN, *,
                 holdout: RecordSource | None = None, progress: ProgressFn | None = None,
                 stage: StageFn | None = None) -> Explanation:
    """Explain ``source`` (``core.io.source.open_record``: an .npz, a CSV or a recording).
    ``options`` are analyze's plus explain's (``ExplainOptions``). ``holdout``: a second
    record of the same sensor (same rate and channels, checked before any work) that the
    models fitted here predict; without it the record's halves predict each other."""
    meta = source.info.as_meta()
    if holdout is not None:
        check_compatible(meta, holdout.info.as_meta(), holdout.info.source)
    temperature = options.temperature
    if temperature is not None and temperature not in (meta.get("temperature_names") or []):
        _unknown_temperature(temperature, meta)
    # The base is `avard analyze` of the record itself, the same call: the same passes (one
    # per channel group whose OADEV histories fit its budget, so the same peak memory; one
    # pass over every channel, as explain_stream must do with blocks from anywhere, would
    # hold all axes' histories at once, 3x analyze's peak on a 60 h record). Its first pass
    # reads every column and the temperatures through the one screen and feeds the slow
    # view (``FirstPassTap``): the record is read, screened and its temperatures decoded
    # once. Only a parallel analysis, whose workers read the chunks, leaves the slow view to
    # one more read.
    if not source.rereadable:
        return explain_stream(source, options, holdout=holdout, progress=progress,
                              stage=stage)
    screened = (source if isinstance(source, ScreenedSource)
                else ScreenedSource(source, options.temperature_units))
    tap = _SlowTap(source.info.rate_hz, source.info.n_samples, len(source.info.names),
                   len(source.info.temperature_names))
    an = analyze(screened, options, progress=progress, tap=tap)
    an.meta["screen"] = screened.log      # as analyze says it of a source it screens itself
    if not tap.complete:
        if stage is not None:
            stage("reading the record's slow view (block means)")
        # a fresh screen: the parallel chunks' verdicts told the log nothing of the
        # temperatures, which this read screens
        return explain_stream(source.source if isinstance(source, ScreenedSource) else source,
                              options, holdout=holdout, progress=progress, stage=stage,
                              base=an)
    return _explained(an, tap.slow, screened.log, meta, options, _held(holdout, options, meta),
                      stage)


class _SlowTap:
    """The slow view fed by analyze's first pass (``analysis.engine.FirstPassTap``), or by
    ``explain_stream``'s blocks; ``complete`` once it has seen the whole record."""

    def __init__(self, rate_hz: float, n_samples: int | None, n_axes: int,
                 n_temps: int) -> None:
        self.slow = SlowView(block_size(float(rate_hz), n_samples), n_axes, n_temps)
        self.complete = False

    def update(self, accel: NDArray[np.float64], temp: NDArray[np.float64] | None) -> None:
        a = np.asarray(accel, dtype=float).reshape(len(accel), -1)
        if self.slow.n_temps and temp is not None and np.asarray(temp).size:
            self.slow.update(a, temp)
        else:
            self.slow.update(a, None)

    def end(self) -> None:
        self.complete = True


#: The held-out record: its description, its screened blocks (read when the held-out
#: measure asks) and the screen they come through (its log complete once they are read).
Held = tuple[dict[str, Any], Iterable[Any], ScreenedSource]


def _held(holdout: RecordSource | None, options: ExplainOptions, meta: dict[str, Any]
          ) -> Held | None:
    """The held-out record, checked against this record's, read through the same input
    screen as the record (``ScreenedSource``: the same rules, ``--temperature-units`` alike,
    so a °F log is converted or refused as the record's is): its 85 °C values, read errors
    and spikes are masked, its shocks cut out, its dropouts and stuck runs listed."""
    if holdout is None:
        return None
    h_meta = holdout.info.as_meta()
    check_compatible(meta, h_meta, str(h_meta.get("source", "holdout")))
    screened = (holdout if isinstance(holdout, ScreenedSource)
                else ScreenedSource(holdout, options.temperature_units))
    return h_meta, _unused_held(screened.blocks(options.block), screened,
                                list(h_meta.get("temperature_names") or [])), screened


def _unused_held(blocks: Iterable[Block], screened: ScreenedSource, tnames: list[str]
                 ) -> Iterator[Block]:
    """``blocks`` handed on as they are; once read, each held-out log that the record's rule
    (``_why_unused``) would not use is refused in the held-out screen's log, with that rule's
    reason, so that no prediction runs through it: a log of one value throughout (no
    variation to predict from) predicted the held-out axis as flat and called a correct
    model's gain −3e3 ("UNEXPLAINED") where the record's own side said "not used". Judged on
    the screened readings (each log's least and greatest, and how many), in bounded memory;
    a log the screen refused keeps the screen's reason."""
    k = len(tnames)
    lo, hi = np.full(k, np.inf), np.full(k, -np.inf)
    count = np.zeros(k, dtype=np.int64)
    for blk in blocks:
        temp = blk[1]
        if k and temp is not None and np.asarray(temp).size:
            t = np.asarray(temp, dtype=float).reshape(len(blk[0]), -1)
            fin = np.isfinite(t)
            count += fin.sum(axis=0)
            lo = np.minimum(lo, np.where(fin, t, np.inf).min(axis=0, initial=np.inf))
            hi = np.maximum(hi, np.where(fin, t, -np.inf).max(axis=0, initial=-np.inf))
        yield blk
    log = screened.log
    if log is None:
        return
    for j, nm in enumerate(tnames):
        # fewer than two readings: holdout_file says so itself ("no readings once screened")
        why = None if count[j] < 2 else _why_unused(np.array([lo[j], hi[j]]))
        if why is not None:
            log.refused.setdefault(nm, why)


@one_blas_thread
def explain_stream(source: RecordSource, options: ExplainOptions = DEFAULT_EXPLAIN, *,
                   holdout: RecordSource | None = None, progress: ProgressFn | None = None,
                   stage: StageFn | None = None, base: Analysis | None = None) -> Explanation:
    """``explain_file`` on blocks from anywhere (``core.io.source.StreamSource``: accel
    (n, C) m/s², temperature (n, k) °C or None, segment end). ``holdout``: a second record of
    the same sensor. ``base``: analyze's result for these blocks when the caller has it
    (``explain_file`` after a parallel analysis); the blocks then feed only the slow view."""
    # one screen for the slow view and the analysis: analyze is handed the screened blocks
    screened = (source if isinstance(source, ScreenedSource)
                else ScreenedSource(source, options.temperature_units))
    meta = source.info.as_meta()
    blocks = screened.blocks(options.block)
    held = _held(holdout, options, meta)
    tnames = list(meta.get("temperature_names") or [])
    if options.temperature is not None and options.temperature not in tnames:
        _unknown_temperature(options.temperature, meta)
    tap = _SlowTap(float(meta["rate_hz"]), meta.get("n_samples"), len(meta["names"]),
                   len(tnames))

    def tee() -> Iterator[tuple[NDArray[np.float64], bool]]:
        for accel, temp, end in blocks:
            a = np.asarray(accel, dtype=float).reshape(len(accel), -1)
            tap.update(a, temp)
            yield a, end

    if base is None:
        an = analyze(StreamSource(source.info, ((a, None, end) for a, end in tee())),
                     replace(options, screen=False), progress=progress)
        an.meta["screen"] = screened.log
    else:
        an = base
        for _ in tee():
            pass
    return _explained(an, tap.slow, screened.log, meta, options, held, stage)


def _explained(an: Analysis, slow: SlowView, screen: ScreenLog | None, meta: dict[str, Any],
               options: ExplainOptions, held: Held | None,
               stage: StageFn | None) -> Explanation:
    """The explanation of ``an`` (analyze's result) from the slow view of the same screened
    blocks (``screen``: that screen's log), whichever read fed it."""
    temperature, heldout = options.temperature, options.heldout
    rate = float(meta["rate_hz"])
    names = list(meta["names"])
    tnames = list(meta.get("temperature_names") or [])
    b = slow.b
    rate_b = rate / b
    stuck = [[(x.start_s, x.end_s) for x in screen.stretches
              if x.channel == nm and x.kind == "stuck"] for nm in tnames] if screen else []
    y_slow, t_slow = slow.finish(stuck, rate_b)
    # the channels asked for (all, or ``--temperature``'s), each usable or said why not
    why = {j: _why_unused(None if t_slow is None else t_slow[:, j],
                          None if screen is None else screen.refused.get(tnames[j]))
           for j in range(len(tnames)) if temperature in (None, tnames[j])}
    t_ok = [j for j, w in why.items() if w is None]
    unused = {tnames[j]: w for j, w in why.items() if w is not None}
    t_allan: dict[str, Any] = {}
    if t_slow is not None and t_ok and len(t_slow) >= 16:
        sa = StreamingAllan(len(t_ok), rate_b, names=[tnames[j] for j in t_ok])
        sa.update(t_slow[:, t_ok])
        res = sa.result()
        for i, j in enumerate(t_ok):
            t_allan[tnames[j]] = res.channel(i) if len(t_ok) > 1 else res
    cols = [names.index(nm) for nm in an.channels]
    th_fits: list[ThermalFit | None] = [None] * len(cols)
    if t_slow is not None and t_ok and len(y_slow) >= MIN_SLOW_POINTS:
        if stage is not None:
            stage("fitting the thermal model")
        # the screen's holes in each log: gaps of its regression, never the axis's response
        holes = ({i: screen.hole_blocks(tnames[j], rate_b) for i, j in enumerate(t_ok)}
                 if screen is not None else None)
        # each log on its own step and origin (``screen.log_step``): a coarse log's
        # reconstruction and rounding leave a finer log's fit as it is
        grids = [None if screen is None else screen.rounding_grid(tnames[k]) for k in t_ok]
        th_fits, settled = _thermal_fits(y_slow[:, cols], t_slow[:, t_ok],
                                         [tnames[k] for k in t_ok], rate_b, holes,
                                         [_noise_levels(ch.fit) for ch in an.channels.values()],
                                         grids)
    else:
        settled = [None] * len(cols)
    out: dict[str, ChannelExplanation] = {}
    for (name, ch), th, w0 in zip(an.channels.items(), th_fits, settled, strict=True):
        if stage is not None:
            stage(f"explaining channel {name}")
        j = names.index(name)
        # the causes' rounding floors on the step of the log the axis's thermal model reads
        with reading_grid(None if th is None else th.grid):
            out[name] = _explain_channel(ch, y_slow[:, j], rate_b,
                                         None if t_slow is None else t_slow[:, t_ok],
                                         th, an, meta, always_compensate=temperature is not None,
                                         holes=screen, settled=w0)
    if not heldout and held is None:
        for ch_ex in out.values():
            ch_ex.judge(None, screen=screen)
        return Explanation(an, out, t_allan, b / rate, screen=screen,
                           temperature_unused=unused)
    if stage is not None:
        stage("measuring the gain on held-out data")
    ho = _holdout(out, y_slow, t_slow, tnames, names, rate_b, b, meta, held, screen)
    for name, ch_ex in out.items():
        ch_ex.judge(ho.channels.get(name), ho.reason, screen)
    return Explanation(an, out, t_allan, b / rate, ho, screen=screen,
                       temperature_unused=unused)


def _thermal_fits(Y: NDArray, temps: NDArray, tnames: list[str], rate_b: float,
                  holes: dict[int, list[tuple[int, int]]] | None,
                  noise: list[dict[str, float]],
                  grids: list[tuple[float, float] | None] | None = None
                  ) -> tuple[list[ThermalFit | None], list[NDArray[np.float64] | None]]:
    """(each axis's thermal model with its path, each axis's warm-up beyond the lag
    filter's start state or None). A warm-up at the record's start is taken over by the
    thermal model's start state (its own settling e^(−t/τ_L), of any size) or, on an axis
    whose warm-up is not near the lag, by a path with a long second lag or a dT/dt term
    (issue 23: a 2.4e-3 m/s², 15-minute warm-up beside a 5-minute lag was read as two paths or
    a rate term, or left unclaimed as the start state's); taken out before the path is
    chosen, it takes a quadratic's or a second path's own start with it. So the one-lag fit
    comes first, a warm-up that passes the compound search's warm-up test against the start
    state (``transients.warmup_beyond_start``) on the axis with that coupling removed gives
    its T, and the path is chosen with the warm-up as a nuisance beside every candidate
    (``thermal_paths.choose_path``'s ``warmups``: its size fitted jointly with each, on the
    axis as recorded). The warm-up is then tested again beside the path chosen, and one that
    passes is ``_explain_channel``'s, which fits no start state beside it. It is claimed, or
    not, by the compound search as any warm-up. ``grids``: each log's (step, origin), None
    for the 12-bit default (``fit_thermal_axes``)."""
    fits = fit_thermal_axes(Y, temps, tnames, rate_b, holes, grids=grids)
    settled: list[NDArray[np.float64] | None] = [None] * len(fits)
    nzs: dict[int, dict[str, float]] = {}
    found: dict[int, tuple[float, ...]] = {}
    first: dict[int, NDArray[np.float64]] = {}
    moved: set[int] = set()  # found only without the one lag's start state
    for a, th in enumerate(fits):
        # every axis: a quadratic or a relay the one lag cannot follow may fail the one-lag
        # test and pass its own (``with_paths``), beside a warm-up as well
        r = Y[:, a] - th.signal(temps)
        # the noise of the axis with the coupling out, by the robust Allan variance that
        # a few large differences (the warm-up's) move little: analyze's fit counts the
        # thermal cycle as noise (K 6× the truth beside a 2e-3 m/s²/K coupling)
        nz = nzs[a] = tr.robust_noise(r, rate_b, noise[a]["N"])
        c = tr.warmup_beyond_start(r, rate_b, nz, th.lag_s)
        if not c.passed and th.lag_s:
            # the one lag's own start state is no reference where the warm-up moved that
            # lag: beside a quadratic a 900 s warm-up pulled it to a lead of −398 s, whose
            # start state e^(−t/398) took the warm-up up (4.4–4.6 σ against 4.64). Found
            # here it is only a nuisance beside the paths; it is tested again beside the
            # path chosen (below) and claimed, or not, by the compound search
            c = tr.warmup_beyond_start(r, rate_b, nz, 0.0)
            if c.passed:
                moved.add(a)
        if c.passed:
            # its T and size refined by the compound search's joint fit, without the
            # start state (the scan's size is the share left beside it)
            c = tr.refine_compound(r, rate_b, nz, [c])[0]
            if c.params["time_constant_s"] > len(Y) / rate_b / 4:
                # refined beyond the scan's longest T (a quarter of the record): a slow
                # trend of the record, not a warm-up to hold beside the paths (T 6105 s on
                # a 4 h record beside a plain 300 s lag: two paths won beside it)
                moved.discard(a)
                continue
            found[a] = (float(c.params["time_constant_s"]),)
            first[a] = cz.cause_signal(c, len(Y), rate_b)
    # the path chosen with the warm-up beside every candidate, its size fitted jointly with
    # each (``choose_path``'s ``warmups``), on the axis as recorded: a warm-up taken out
    # before the choice took a quadratic's own start with it (q·(u − ū)² is largest where
    # the temperature is farthest from its mean, often the record's first minutes: the
    # warm-up came out 1.5× its size, and the quadratic row beside a real warm-up was right
    # on 1 of 40), or a second path's (the two-path + compressor row), and one left in was
    # taken over by a path with a long second lag or a dT/dt term
    out: list[ThermalFit | None] = list(with_paths(fits, Y, temps, holes, warmups=found))
    # what was found may be a path's own start: a second path through the plate's long lag
    # settles with the plate, and one lag leaves that start in its residual (a "warm-up" of
    # T 3266 s on a two-path + compressor record: beside it, two paths ran to their grid's
    # end and a dT/dt term was chosen, where two paths alone predict the record better by
    # 70). So the path is also chosen with nothing beside it, and an extension chosen there
    # whose signal from the logged temperature alone (nothing of free size or time constant)
    # leaves no warm-up beyond the start state explains that start itself: it is kept, and
    # no warm-up, where it also predicts the held-out halves better than one lag by the
    # margin with the warm-up beside it (the two-path + compressor record: by 102, there
    # at its grid's end). One whose gain is the warm-up's is not: the logged temperature
    # settles at the start too, and a dT/dt term with a 424 s lag read a 900 s warm-up
    # beside one lag from that settling (its Δ −55 alone, +1.3 beside the warm-up). Nor is
    # one of the mechanism chosen beside the warm-up: both choices name the same path, and
    # the one with nothing beside it differs only in having read the warm-up into that
    # path's own parameters (a dT/dt term beside a 900 s warm-up: chosen both ways, alone
    # with the rate term taking the warm-up from the temperature's start, r and c 20–40 %
    # off and the warm-up never claimed; or alone two paths of opposite sign that nearly
    # cancel, 381 and 480 s, the dT/dt term's own limit), so the fit made beside the
    # warm-up stands and the warm-up is tested beside it below (``_same_path``) — where
    # the warm-up is still beyond the start state beside that fit; where it is not, it was
    # that path's own start (a second path through the plate's 900 s, chosen both ways:
    # beside the "warm-up", T 2471 s, its L2 came out 628 s, alone 1005 s) and the fit
    # alone, which explains it, is kept as before
    # (only where an extension gains over one lag beside the warm-up as ``_gain_beside``
    # asks, other than the one chosen there where the warm-up stands beside it: elsewhere
    # the choice alone cannot replace it, and it is a second path choice on the axis)
    stands = {a: o is not None and o.passed and tr.warmup_beyond_start(
        Y[:, a] - o.signal(temps), rate_b, nzs[a], o.lag_s).passed
        for a in found if (o := out[a]) is not None and o.mechanism != "one_lag"}
    back = [a for a in found if (o := out[a]) is not None and o.path is not None
            and any(k != "one_lag" and (k != o.mechanism or not stands.get(a, False))
                    and _gain_beside(o, k) for k in o.path.scores)]
    alone = dict(zip(back, with_paths([fits[a] for a in back], Y[:, back], temps, holes),
                     strict=True))
    # two paths in the dT/dt term's limit chosen beside the warm-up are that term's reading
    # where the choice alone reads as the term too (``_rate_beside``): read so before the
    # choice alone is weighed against it, with the warm-up tested beside the term
    for a, th in alone.items():
        if (o := out[a]) is not None and (rr := _rate_beside(o, th)) is not None:
            out[a] = rr
            stands[a] = rr.passed and tr.warmup_beyond_start(
                Y[:, a] - rr.signal(temps), rate_b, nzs[a], rr.lag_s).passed
    for a, th in alone.items():
        o = out[a]
        if (o is not None and th.mechanism != "one_lag"
                and not (stands.get(a, False) and _same_path(th, o))
                and _gain_beside(o, th.mechanism)
                and not tr.warmup_beyond_start(Y[:, a] - th.signal(temps), rate_b, nzs[a],
                                               th.lag_s).passed):
            out[a] = th
            del found[a]
    # the path choice starts from the one lag's fit (its lag, its Allan reference, its
    # test), which the warm-up moved (a 900 s warm-up beside a 300 s lag: 313–345 s; beside
    # a lag of 0, z 5.3 against 6.2 for a coupling at 3× its minimum); where that start
    # chose an extension or failed its test, or its start state took the warm-up up (found
    # only without it: a lead of −398 s kept beside a lag-0 coupling, c 0.57 of the truth),
    # the one lag is refitted without the warm-up's first estimate and the path chosen again
    # beside it; an axis whose one lag passes and stays keeps its fit (a refit is 15 % of
    # explain's CPU on a 12 h quiet-lab record)
    redo = [a for a in found if (th := out[a]) is not None
            and (th.mechanism != "one_lag" or not th.passed or a in moved)]
    base: list[ThermalFit] = list(fits)  # each axis's one lag, the path choice's start
    if redo:
        Yw = Y[:, redo] - np.column_stack([first[a] for a in redo])
        refit = fit_thermal_axes(Yw, temps, tnames, rate_b, holes, grids=grids)
        again = with_paths(refit, Y[:, redo], temps, holes,
                           warmups={i: found[a] for i, a in enumerate(redo)})
        for a, th, b0 in zip(redo, again, refit, strict=True):
            out[a], base[a] = th, b0
    # and so again on the refit's choice; where the choice alone is two paths of their own
    # response and the dT/dt term stands beside the warm-up, or two paths in its limit, the
    # finding names both readings (``thermal_paths.second_path_reading``, ``both_readings``)
    for a in found:
        if (th := out[a]) is not None and (r := _rate_beside(th, alone.get(a))) is not None:
            out[a] = r
        if ((th := out[a]) is not None and th.path is not None
                and (al := alone.get(a)) is not None and al.path is not None
                and (pf := (second_path_reading(th.path, al.path)
                            or both_readings(th.path, al.path))) is not None):
            out[a] = replace(th, path=pf)
    _beside_transients(out, base, Y, temps, holes, found, rate_b, noise)
    # the warm-up is then a cause of its own where it is still beyond the start state beside
    # the path chosen (its T and size refitted there, on the axis less that path's signal)
    for a in found:
        th = out[a]
        if th is None or not th.passed:
            continue
        r = Y[:, a] - th.signal(temps)
        c = tr.warmup_beyond_start(r, rate_b, nzs[a], th.lag_s)
        if c.passed:
            settled[a] = cz.cause_signal(tr.refine_compound(r, rate_b, nzs[a], [c])[0],
                                         len(Y), rate_b)
    return out, settled


def _beside_transients(out: list[ThermalFit | None], base: list[ThermalFit], Y: NDArray,
                       temps: NDArray, holes: dict[int, list[tuple[int, int]]] | None,
                       found: dict[int, tuple[float, ...]], rate_b: float,
                       noise: list[dict[str, float]]) -> None:
    """``out`` with each path whose extension is the whole claim (the one lag failed its own
    test) kept only where an extension is still chosen with the transients the compound
    search finds on the axis (as recorded: nothing coupled is claimed there) beside every
    candidate (``with_paths``'s ``given``); elsewhere the one lag's failed fit, no claim.
    The path choice sees no transient but a warm-up: on a 1 h record with no coupling a
    relay's two or three switches took the warm-up and a bias step, passed its extra term's
    test and predicted the held-out halves better than nothing by the margin, and the axis
    claimed a temperature coupling with hysteresis (issue 23's compound 1 h row). Where one
    lag passes, the coupling's claim stands on its own test, and the path is not asked."""
    for a, th in enumerate(out):
        b0 = base[a]
        if th is None or not th.passed or b0.passed or th.mechanism == "one_lag":
            continue
        y = Y[:, a]
        cands, _ = tr.find_compound(
            y, rate_b, lambda d, y=y, n=noise[a]["N"]: tr.robust_noise(y - d, rate_b, n))
        sig = tuple(cz.cause_signal(c, len(y), rate_b) for c in cands if c.cause != "drift")
        if sig and not holds_beside(path_of(b0, y, temps, holes, warmups=found.get(a, ()),
                                            given=sig), th.mechanism):
            out[a] = b0


def _same_path(alone: ThermalFit, beside: ThermalFit) -> bool:
    """Whether the path chosen with nothing beside the warm-up (``alone``) is the mechanism
    chosen beside it: the same candidate, or two paths where the dT/dt term was chosen
    beside it and two paths are that term's reading with a parameter more
    (``thermal_paths.reads_as_rate``)."""
    if alone.mechanism == beside.mechanism:
        return True
    return (alone.mechanism == "two_path" and beside.mechanism == "rate"
            and alone.path is not None and beside.path is not None
            and reads_as_rate(alone.path, beside.path))


def _rate_beside(beside: ThermalFit, alone: ThermalFit | None) -> ThermalFit | None:
    """``beside`` (the path chosen with the warm-up beside every candidate) with the dT/dt
    term chosen, where two paths in its limit were chosen there, the term passes every test
    too (``thermal_paths.rate_reading``) and the choice made with nothing beside the warm-up
    (``alone``) reads as the term as well: the term itself, or two paths in its limit. Beside
    a warm-up, two such paths bring two start states of free size and a lag on the
    derivative that take up what the warm-up's fixed shapes leave, and beat a true dT/dt
    term by 6–11 held out; but a second path through a long lag settles at the start as a
    warm-up does, so beside the warm-up two true paths fall into that limit too, and only
    the choice without it, where the record's start is the second path's, tells them: two
    paths of their own response there (not in the limit) leave the choice beside the
    warm-up as it was. None where nothing changes."""
    if beside.path is None or alone is None or alone.path is None:
        return None
    pf = rate_reading(beside.path, alone.path)
    if pf is None:
        return None
    s = pf.chosen
    # where one lag failed its test, the axis's z is the chosen extension's extra term's
    # (``thermal_fit.with_paths``): it becomes the dT/dt term's, not the two paths' it was
    was = beside.path.chosen
    test = {"z": s.z_extra} if math.isclose(beside.z, was.z_extra) else {}
    return replace(beside, path=pf, coefficient=float(s.beta[0]),
                   coef_se=float(s.beta_se[0]), lag_s=float(s.theta[0]),
                   lag_lo=float(s.theta_lo[0]), lag_hi=float(s.theta_hi[0]),
                   lag_open=s.open_end, **test)


def _gain_beside(th: ThermalFit | None, kind: str) -> bool:
    """Whether the path ``kind`` predicts the held-out halves better than one lag by the
    margin an extension needs in ``th``'s path choice (made with a warm-up beside every
    candidate); False where that choice kept no path (one lag failed its test and no
    extension passed)."""
    pf = None if th is None else th.path
    if pf is None or kind not in pf.scores:
        return False
    return pf.scores[kind].heldout < pf.scores["one_lag"].heldout - pf.margin


def _holdout(out: dict[str, ChannelExplanation], y_slow: NDArray, t_slow: NDArray | None,
             tnames: list[str], names: list[str], rate_b: float, b: int, meta: dict[str, Any],
             holdout: Held | None, screen: ScreenLog | None = None) -> Holdout:
    """The held-out measure (:mod:`avard.core.explain.holdout`): the record's halves, or the second
    record streamed through the input screen and a slow view with the same block (bounded
    memory). Each record's screen holes (``screen``: the record's) are gaps to the held-out
    estimators on whichever side of a fold its blocks are, as they are to its own fit."""
    holes = _log_holes(screen, tnames, rate_b)
    if holdout is None:
        return holdout_split(out, y_slow, t_slow, tnames, names, rate_b,
                             str(meta.get("source", "stream")), holes)
    h_meta, h_blocks, h_screened = holdout
    view = SlowView(b, len(names), len(tnames))
    for accel, temp, _end in h_blocks:
        a = np.asarray(accel, dtype=float).reshape(len(accel), -1)
        has_t = tnames and temp is not None and np.asarray(temp).size
        view.update(a, temp if has_t else None)
    log = h_screened.log
    held_rate_b = float(h_meta["rate_hz"]) / b
    # as for the record (``_explained``): a stuck run is no reading of the temperature, and
    # every hole of a second or more is a gap of the held-out Allan variance of an axis
    # whose prediction runs through that log
    stuck = [[(x.start_s, x.end_s) for x in log.stretches
              if x.channel == nm and x.kind == "stuck"] for nm in tnames] if log else []
    y_h, t_h = view.finish(stuck, held_rate_b)
    refused = ({j: log.refused[nm] for j, nm in enumerate(tnames) if nm in log.refused}
               if log is not None else {})
    # each side's τ in seconds of its own fitted rate (the rates agree by core.io.rates' rule,
    # they are not equal)
    return holdout_file(out, y_slow, t_slow, y_h, t_h, tnames, names, rate_b,
                        str(h_meta.get("source", "holdout")), held_rate_b=held_rate_b,
                        held_holes=_log_holes(log, tnames, held_rate_b),
                        held_refused=refused, screen=log)


def _log_holes(log: ScreenLog | None, tnames: list[str], rate_b: float
               ) -> dict[int, list[tuple[int, int]]]:
    """Per temperature column, the (first, last) slow-view blocks (``rate_b`` blocks per
    second) of every hole of a second or more the screen found in that log (a dropout, a
    masked reading, a stuck run): blocks where the log says nothing of the temperature."""
    if log is None:
        return {}
    return {j: log.hole_blocks(nm, rate_b) for j, nm in enumerate(tnames)}


def _noise_levels(fit: NoiseFit) -> dict[str, float]:
    """N, B, K for the time-domain GLS of the transients (their covariance and their floor):
    a term the fit calls present at its value, an absent one at its upper limit (0 when it
    has none). Absent means the data cannot show the term, not that it is zero; a covariance
    without it pretends the noise is whiter than the data allow. With K read as 0 where the
    fit left it out (26 of 150 axes of warm-up + step records at 3× their minima), the
    warm-up size's 68 % interval held the truth on 6 of those 26 (82 of the other 124);
    the upper limit is the largest K the data allow, so there the intervals err wide."""
    out = {}
    for key, term in (("N", "velocity_random_walk"), ("B", "bias_instability"),
                      ("K", "rate_random_walk")):
        t = fit.terms.get(term)
        v = None if t is None else (t.value if t.present else t.upper)
        out[key] = float(v) if v is not None and math.isfinite(v) else 0.0
    return out


def _thermal_signal(thermal: ThermalFit, temps: NDArray, y: NDArray, rate_b: float,
                    settled: NDArray | None = None) -> tuple[NDArray[np.float64], bool]:
    """The thermal signal to remove, and whether it includes the fitted start state. The lag
    filter's start state is unknown: a start-up settling with the lag's own time constant is
    part of the thermal model (fitted). When a warm-up still shows after that, it is a cause
    of its own: the start state is then not fitted, so the warm-up test sees the transient
    whole. ``settled``: a warm-up found beyond the start state (``_thermal_fits``), taken out
    of ``y`` before the start state is fitted, which would otherwise take it over."""
    if thermal.lag_s == 0:
        return thermal.signal(temps), False
    if settled is not None:
        # the start state and a warm-up found beyond it trade with each other (fitted on the
        # axis less the warm-up's first estimate, β took the estimate's error and the claim
        # kept it: T 650 s for 900 on 3 of 6 records); the warm-up is fitted whole
        return thermal.signal(temps), False
    with_start = thermal.signal(temps, y)
    if cz.detect_warmup(y - with_start, rate_b).passed:
        return thermal.signal(temps), False
    return with_start, True


def _signal_variations(thermal: ThermalFit | None, temps: NDArray | None, y: NDArray,
                       with_start: bool, cands: list[cz.Candidate], rate_b: float
                       ) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """For each uncertain parameter of the removed signals, the change of the removed signal
    when that parameter moves one standard error up and down (68 % half-widths): the thermal
    coefficient and lag, each transient's size and time constant or time."""
    out: list[tuple[NDArray[np.float64], NDArray[np.float64]]] = []
    if thermal is not None and temps is not None and thermal.passed:
        base = thermal.signal(temps, y if with_start else None)
        moves = [("coefficient", thermal.coef_se)]
        if math.isfinite(thermal.lag_hi) and thermal.lag_hi > thermal.lag_lo:
            moves.append(("lag_s", 0.5 * (thermal.lag_hi - thermal.lag_lo)))
        for key, se in moves:
            if not (math.isfinite(se) and se > 0):
                continue
            v = getattr(thermal, key)
            # either sign: a coefficient may be negative, a lag negative (the logged sensor
            # lagging the die)
            sig = [replace(thermal, **{key: v + sgn * se}).signal(
                temps, y if with_start else None) - base for sgn in (1, -1)]
            out.append((sig[0], sig[1]))
    for c in cands:
        base = cz.cause_signal(c, len(y), rate_b)
        for key, (lo, hi) in c.intervals.items():
            se = 0.5 * (hi - lo)
            if key not in c.params or not (math.isfinite(se) and se > 0):
                continue
            sig = [cz.cause_signal(replace(c, params={**c.params, key: c.params[key] + sgn * se}),
                                   len(y), rate_b) - base for sgn in (1, -1)]
            out.append((sig[0], sig[1]))
    return out


def removed_avar(var: NDArray, tau: NDArray, y: NDArray, d: NDArray, rate_b: float,
                 keep: NDArray[np.bool_] | None = None) -> NDArray[np.float64]:
    """``var`` (the axis's AVAR at ``tau``) with the signal ``d`` removed from the slow view
    ``y`` (``compensated_avar`` at coefficient 1), from the Allan covariance of (y, d) alone:
    ``StreamingAllan.covariance``, ``thermal_fit.allan2``'s τ and covariance to the bit
    without the noise identification and EDF it computes and this never reads (an Allan
    pass per removed signal: every transient tried, every parameter moved). ``keep``: the
    blocks the covariance reads (None: all); the others are gaps (``thermal_fit.feed``), so
    ``var`` is scaled by what the removal takes off where ``d`` is known."""
    sa = StreamingAllan(2, rate_b)
    feed(sa, np.column_stack([y, d]), keep)
    return compensated_avar(var, tau, sa.covariance(), 1.0)


def removal_covariance(var: NDArray, tau: NDArray, y: NDArray, total: NDArray, rate_b: float,
                       variations: list[tuple[NDArray[np.float64], NDArray[np.float64]]],
                       keep: NDArray[np.bool_] | None = None) -> NDArray[np.float64]:
    """Covariance of the compensated AVAR at ``tau`` that the removed signal's parameters
    carry, by the delta method: for each parameter, J = [AVAR_c(θ + s) − AVAR_c(θ − s)]/2 (s
    its standard error; the central difference is exact for the thermal coefficient, on which
    the compensated AVAR is quadratic), summed as Σ J Jᵀ with the parameters taken
    independent. ``fit_noise(added_cov=…)`` adds it to the noise model's covariance, so the
    extended fit's intervals carry the uncertainty of what was removed."""
    k = len(tau)
    cov = np.zeros((k, k))
    for up, down in variations:
        hi = removed_avar(var, tau, y, total + up, rate_b, keep)
        lo = removed_avar(var, tau, y, total + down, rate_b, keep)
        j = np.where(np.isfinite(hi - lo), 0.5 * (hi - lo), 0.0)
        cov += np.outer(j, j)
    return cov


def _thermal_keep(thermal: ThermalFit | None, screen: ScreenLog | None, n: int,
                  rate_b: float) -> NDArray[np.bool_] | None:
    """The slow-view blocks the extended fit's Allan variance reads (None: all) for an axis
    whose claimed thermal cause (``thermal``, None when none is claimed) runs on a logged
    temperature: every hole of a second or more in that log (``_log_holes``) and the lag's
    settling after it (``thermal_fit.hole_mask``, the longest lag of a two-path fit) are
    gaps. There the removed signal is made of interpolated temperature; what it leaves in
    the axis is the hole, never the model's misfit (a hole in a log is not a cause)."""
    if thermal is None or screen is None:
        return None
    holes = _log_holes(screen, [thermal.channel], rate_b).get(0, [])
    lag = abs(thermal.lag_s)
    if thermal.path is not None and thermal.path.kind == "two_path":
        lag = max(abs(x) for x in thermal.path.chosen.theta[:2])
    return hole_mask(n, holes, lag, rate_b)


def _explain_channel(ch: ChannelAnalysis, y_slow: NDArray, rate_b: float,
                     temps: NDArray | None, thermal: ThermalFit | None, an: Analysis,
                     meta: dict[str, Any], always_compensate: bool = False,
                     holes: ScreenLog | None = None,
                     settled: NDArray | None = None) -> ChannelExplanation:
    allan = ch.allan
    tau = np.asarray(allan.tau, dtype=float)
    base = ch.fit
    used = _used(base, tau)
    model_v = base.model_avar(tau)
    misfit = misfit_ranges(tau[used], allan.var[used], model_v[used], allan.edf[used])
    findings: list[Finding] = []
    curves: dict[str, NDArray[np.float64]] = {}
    signal = np.zeros(len(y_slow))
    with_start = False
    comp_var: NDArray[np.float64] | None = None
    thermal_only: NDArray[np.float64] | None = None
    trans: list[cz.Candidate] = []
    work = y_slow
    if len(y_slow) >= MIN_SLOW_POINTS:
        if thermal is not None and temps is not None:
            f = thermal.finding()
            f.claimed = thermal.passed
            findings.append(f)
            if thermal.passed or always_compensate:
                d, with_start = _thermal_signal(thermal, temps, y_slow, rate_b, settled)
                thermal_only = removed_avar(allan.var, tau, y_slow, d, rate_b)
                if thermal.passed:
                    signal += d
                    curves["temperature"] = signal_avar_on(d, rate_b, tau)
        work = y_slow - signal
    corner = an.meta.get("filter_corner_hz")
    lsb = meta.get("lsb_mps2")
    kw: dict[str, Any] = {}
    if corner is not None and isinstance(lsb, int | float) and lsb > 0:
        kw["rounding_lsb"] = float(lsb)
    extra: list[dict[str, Any]] = [{"cause": "sinusoid", "params": ln}
                                   for ln in line_components(ch.lines)]

    # the transients' search asks for the same removed signal more than once (nothing
    # found: the search's first noise and the drift test's are both "nothing removed"); each
    # answer costs an Allan pass over the slow view and a GLS fit, so it is kept by content
    noise_seen: dict[bytes, dict[str, float]] = {}

    def noise_without(d: NDArray[np.float64]) -> dict[str, float]:
        """N, B, K of analyze's model fitted to the axis with the thermal signal and ``d``
        removed: each transient is tested against noise with the others (and itself) out."""
        key = np.ascontiguousarray(d, dtype=float).tobytes()
        if key not in noise_seen:
            noise_seen[key] = _noise_of_removed(d)
        return dict(noise_seen[key])

    def _noise_of_removed(d: NDArray[np.float64]) -> dict[str, float]:
        if not np.any(d) and not np.any(signal):
            return _noise_levels(base)
        cv = removed_avar(allan.var, tau, y_slow, signal + d, rate_b)
        ratio = cv / np.where(allan.var > 0, allan.var, 1.0)
        try:
            fit = fit_noise(replace(allan, var=cv, lo=allan.lo * ratio, hi=allan.hi * ratio),
                            filter_corner_hz=corner, extra=extra, **kw)
        except FitError:
            return _noise_levels(base)
        return _noise_levels(fit)

    missed: list[cz.Candidate] = []
    change = None  # coupling_change: whether one coupling describes the record
    if len(y_slow) >= MIN_SLOW_POINTS:
        start = 0.0
        if with_start and thermal is not None:
            # what the lag filter's fitted start state can leave: the removed signal's swing
            # over its first three lags
            head = signal[:max(2, math.ceil(3 * abs(thermal.lag_s) * rate_b))]
            start = float(np.ptp(head))
        trans, missed = _compound(work, rate_b, noise_without, thermal, holes, start)
        change, trans, missed = cchange.check(y_slow, temps, thermal, trans, missed, work,
                                              rate_b, noise_without, holes)

    # the covariance of the compensated points that the removed signal's parameters carry
    # (``removal_covariance``): set by each ``extend``, given to every fit of those points
    added: NDArray[np.float64] | None = None

    def extend(cands: list[cz.Candidate]) -> tuple[NDArray[np.float64], NoiseFit, Any]:
        """(compensated AVAR, extended fit, its Allan result) with the thermal signal and the
        passed transients ``cands`` removed, from the Allan covariance of the axis and that
        signal; refitted exactly as analyze fits (its terms, lines, filter, LSB)."""
        nonlocal added
        total = signal.copy()
        for i, c in enumerate(cands):
            d = cz.cause_signal(c, len(y_slow), rate_b)
            total += d
            curves[_label(c, i, cands)] = signal_avar_on(d, rate_b, tau)
        keep = _thermal_keep(thermal if "temperature" in curves else None, holes,
                             len(y_slow), rate_b)
        cv = removed_avar(allan.var, tau, y_slow, total, rate_b, keep)
        ratio = cv / np.where(allan.var > 0, allan.var, 1.0)
        comp = replace(allan, var=cv, lo=allan.lo * ratio, hi=allan.hi * ratio)
        # the removed signal's parameters are estimates: their uncertainty enters the same
        # GLS fit as a covariance of the compensated points (one set of intervals)
        added = removal_covariance(
            allan.var, tau, y_slow, total, rate_b,
            _signal_variations(thermal if "temperature" in curves else None, temps,
                               y_slow if settled is None else y_slow - settled,
                               with_start, cands, rate_b), keep)
        try:
            fit = fit_noise(comp, filter_corner_hz=corner, extra=extra, added_cov=added,
                            **kw)
        except FitError as exc:
            raise FitError(f"channel {ch.name}, the model with the found causes: {exc}") \
                from exc
        return cv, fit, comp

    ext = base
    current: Any = allan
    if curves or trans:
        comp_var, ext, current = extend(trans)
    trans = trans + missed
    for cand in trans:
        findings.append(Finding(cand.cause, cand.passed, dict(cand.params),
                                dict(cand.intervals) if cand.passed else {},
                                cand.statistic, cand.threshold, cand.evidence))
    gm, gm_fit = scan_gauss_markov(current, ext, corner, extra,
                                   kw if added is None else {**kw, "added_cov": added})
    # a bump that passed the scan's statistic, claimed or not for another reason (T not
    # located): the rounding floor is said too, it is the reason that holds for the bump's σ
    if ((gm.claimed or gm.statistic >= gm.threshold) and thermal is not None
            and thermal.passed):
        floor = cz.gauss_markov_rounding_floor(_rounding_gain(thermal), thermal.grid[0])
        # and where a relay is chosen or named beside the path kept, what its switch times
        # leave (``PathFit.relay_floor``): the removed relay's switch times are uncertain by
        # its own intervals, and one lag kept leaves a named relay's odd harmonics
        rf, rwhy = ((0.0, "") if thermal.path is None or temps is None
                    else thermal.path.relay_floor(temps[:, thermal.channel_index]))
        if gm.params.get("sigma", 0.0) < floor:
            gm = replace(gm, claimed=False, intervals={} if gm.claimed else gm.intervals,
                         evidence=gm.evidence + (
                f"; not claimed: σ is below {floor:.3g} m/s², the RMS of the logged "
                f"temperature's {thermal.grid[0]:g} K rounding through the coupling "
                f"({_rounding_gain(thermal):.3g} m/s²/K), which can look like a bump"))
            gm_fit = None
        elif gm.params.get("sigma", 0.0) < rf:
            gm = replace(gm, claimed=False, intervals={} if gm.claimed else gm.intervals,
                         evidence=gm.evidence + f"; not claimed: σ is below {rwhy}")
            gm_fit = None
    findings.append(gm)
    if gm_fit is not None:
        ext = gm_fit
    findings += [_periodic_finding(g) for g in line_groups(ch.lines)]
    findings = cchange.mark(change, findings)
    out = ChannelExplanation(ch.name, ch, ext, findings, misfit, thermal, comp_var, curves,
                             thermal_only)
    if ext is not base:
        ext_var = np.asarray(current.var, dtype=float)
        eu = _used(ext, tau)
        out.ext_misfit = misfit_ranges(tau[eu], ext_var[eu], ext.model_avar(tau)[eu],
                                       allan.edf[eu])
    else:
        out.ext_misfit = misfit
    if comp_var is not None:
        out.compensation_worse_s = out._worse(comp_var)
    return out


def _periodic_finding(g: LineGroup) -> Finding:
    """One periodic disturbance of analyze's line finder (``spectrum.line_groups``) as one
    finding: a steady line alone is a "sinusoid"; a line with harmonics or sidebands, or a
    drifting line, is "periodic", with its harmonics, modulation and frequency band."""
    params = {"frequency_hz": g.frequency_hz, "amplitude": g.amplitude}
    iv = ({"amplitude": [g.amplitude_lo, g.amplitude_hi]}
          if math.isfinite(g.amplitude_lo) and math.isfinite(g.amplitude_hi) else {})
    what = [f"{g.kind}: {g.members} line(s) of analyze's line finder (spectrum.find_lines) "
            "taken as one disturbance"]
    if len(g.harmonics) > 1:
        params["harmonics"] = float(len(g.harmonics))
        what.append("harmonics " + ", ".join(str(k) for k in g.harmonics))
    if g.modulation_hz is not None:
        params["modulation_hz"] = g.modulation_hz
        what.append(f"sidebands ±{g.modulation_hz:.4g} Hz (a modulation)")
    if g.band_hz is not None:
        params["frequency_lo_hz"], params["frequency_hi_hz"] = g.band_hz
        what.append(f"its frequency moves over {g.band_hz[0]:.5g}–{g.band_hz[1]:.5g} Hz; the "
                    "amplitude is that of the band's whole power")
    cause = "periodic" if len(what) > 1 else "sinusoid"
    return Finding(cause, True, params, iv, math.nan, math.nan,
                   "; ".join(what) + "; part of the base model (analyze's sinusoids)")


def _label(c: cz.Candidate, i: int, cands: list[cz.Candidate]) -> str:
    """The name of a removed signal's AVAR curve: its cause, numbered when the axis has
    several of that cause (two steps: "bias_step 1", "bias_step 2")."""
    same = [j for j, o in enumerate(cands) if o.cause == c.cause]
    return c.cause if len(same) == 1 else f"{c.cause} {same.index(i) + 1}"


def _compound(work: NDArray, rate_b: float, noise_of: tr.NoiseOf, thermal: ThermalFit | None,
              screen: ScreenLog | None, start_span: float = 0.0
              ) -> tuple[list[cz.Candidate], list[cz.Candidate]]:
    """(claimed, not claimed) transients and drift of one axis (:mod:`transients`). Where a
    thermal signal was removed, a transient the logged temperature's rounding can make
    (``causes.transient_floor``), one in a hole of the driving log (``_not_in_hole``), or a
    warm-up the lag filter's fitted start state can make (T within a factor 3 of the lag,
    size within ``start_span``, the removed signal's swing over its first three lags) is not
    claimed, and the others are refitted and tested again without it."""
    found, missed = tr.find_compound(work, rate_b, noise_of)
    if found and thermal is not None and thermal.passed:
        record_s = len(work) / rate_b
        lag = abs(thermal.lag_s)
        checked = []
        for c in found:
            floor, why = cz.transient_floor(c, {}, record_s, _rounding_gain(thermal),
                                            thermal.grid[0])
            T = c.params.get("time_constant_s", math.nan)
            if (c.cause == "warmup" and lag > 0 and lag / 3 <= T <= 3 * lag
                    and abs(c.params["size"]) <= start_span):
                c = replace(c, passed=False, intervals={}, evidence=c.evidence + (
                    f"; not claimed: a settling with the thermal lag's time scale ({lag:.4g} s)"
                    f" and within the swing the removed thermal signal makes over its first "
                    f"three lags ({start_span:.3g} m/s²) is what the lag filter's unknown "
                    "start state can leave"))
            elif abs(c.params["size"]) < floor:
                c = replace(c, passed=False, intervals={}, evidence=c.evidence + (
                    f"; not claimed: size {abs(c.params['size']):.3g} m/s² is below {why}"))
            elif screen is not None:
                c = _not_in_hole(c, screen, thermal, record_s)
            checked.append(c)
        kept = [c for c in checked if c.passed]
        if len(kept) < len(found):
            # the others refitted without it, and tested again in that fit (each claim's
            # statistic and sentence are those of the fit it is reported with)
            found, lost = tr.confirm_compound(work, rate_b, noise_of, kept)
            missed = [c for c in checked if not c.passed] + lost + missed
    drift = tr.test_drift(work, rate_b, noise_of(tr.signal_of(found, len(work), rate_b)),
                          found, noise_of=noise_of)
    return ([*found, drift], missed) if drift.passed else (found, [*missed, drift])


def _rounding_gain(thermal: ThermalFit) -> float:
    """The coefficient through which the logged readings' rounding reaches the residual: ĉ
    times the L1 norm of the path's impulse response, the largest factor it can put on a
    bounded error: 1 for a lag, 3 for a negative lag's lead-lag 2δ − h_lag (a 2× factor, its
    high-frequency gain, left Gauss–Markov claims of 1.02× the floor on 3 of 3 records); for
    a thermal path beyond one lag, the L1 norm of all its linear terms
    (``PathFit.rounding_gain``: a two-path fit's second coefficient counts as much as its
    first)."""
    if thermal.path is not None and thermal.path.kind != "one_lag":
        return thermal.path.rounding_gain()
    return abs(thermal.coefficient) * (3.0 if thermal.lag_s < 0 else 1.0)


def _not_in_hole(c: cz.Candidate, screen: ScreenLog, thermal: ThermalFit,
                 record_s: float) -> cz.Candidate:
    """``c`` unless it is a passed transient inside a hole of the driving temperature log (a
    masked reading, a dropout, a stuck run) or within ``HOLE_SETTLE_LAGS`` lags after it:
    there the removed thermal signal is made of interpolated temperature, and what it leaves
    in the axis is the hole, not a cause of the axis (a 25-minute dropout read as a bias step
    of 4–5e-4 m/s²). Such a transient is not claimed, and says why."""
    if not c.passed:
        return c
    lag = abs(thermal.lag_s)
    if c.cause == "bias_step":
        t_c = float(c.params.get("time_s", math.nan))
        span = (t_c, t_c)
    elif c.cause == "excursion":  # either edge
        span = (float(c.params["start_s"]), float(c.params["end_s"]))
    elif c.cause != "warmup":
        return c
    else:  # a warm-up acts over its first three time constants
        span = (0.0, 3.0 * float(c.params.get("time_constant_s", 0.0)))
    for h0, h1 in screen.holes(thermal.channel):
        if h1 - h0 < 1.0:
            continue  # a single masked reading: the interpolation across it is exact enough
        if span[0] <= h1 + HOLE_SETTLE_LAGS * lag + 1.0 and span[1] >= h0 - 1.0:
            return replace(c, passed=False, intervals={}, evidence=c.evidence + (
                f"; not claimed: it falls in a hole of the temperature log {thermal.channel!r}"
                f" ({h0:.6g}–{h1:.6g} s, or the {HOLE_SETTLE_LAGS:g} lags after it), where "
                "the removed thermal signal is interpolated: a hole in a log is not a cause"))
    return c


def _s(v: float | None) -> str:
    return "—" if v is None else f"{v:.3g}"


"""One axis's thermal fit (``ThermalFit``) and the compensated AVAR it gives."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from avard.core.allan.streaming import StreamingAllan
from avard.core.io.screen.log_step import is_coarse
from numpy.typing import NDArray

if TYPE_CHECKING:
    from avard.core.explain.thermal_paths import PathFit
from avard.core.explain.thermal_fit.coarse import derounded
from avard.core.explain.thermal_fit.rounding import DS18B20_STEP_K
from avard.core.explain.thermal_fit.settings import START_FIT_LAGS, Z_TEMPERATURE
from avard.core.explain.thermal_fit.signals import lag_filter


def coarse_gain_se(fit: ThermalFit, raw: NDArray, recon: NDArray) -> ThermalFit:
    """``fit`` with its coefficient's standard error widened by the reconstruction's gain
    uncertainty when its channel reads on a coarse step (``coarse_regressor``; ``raw``, ``recon``
    the channels as logged and as reconstructed, slow view). Between two crossings of one
    threshold the readings do not say how far the temperature went: the reconstruction
    takes each turn's top as a cycle's (a cosine's, ``coarse._turn_tops``); the spline
    alone takes it as a parabola's, lower (its ĉ high by as much, where the swing spans a
    step or two; a sinusoidal drive's tops are the cosine's). A drive whose turns are
    sharper or flatter than a cosine's lies beyond either, so half the two readings'
    difference, |√(AVAR_spline/AVAR_recon) − 1|/2 at the τ of the reconstruction's largest
    AVAR (the drive), is added to the se in quadrature. It scales with what the tops carry:
    little where the swing spans many steps, more where it spans one or two. (The raw
    readings' ĉ, the quantiser's describing function, bracketed the truth too, but from
    further away whatever the tops (its gain errs in the variable itself), so its half
    bracket over-covered.)
    The detection's z is the regression's (the gain's error scales a coupling that is
    there; it makes none). The relative widening is kept on the fit (``gain_rel``) for a
    path's coefficient beyond one lag (``_with_path``)."""
    if not is_coarse(fit.grid[0]) or not (
            math.isfinite(fit.coef_se) and math.isfinite(fit.coefficient)):
        return fit
    j = fit.channel_index
    var = []
    spline = derounded(np.asarray(raw, dtype=float)[:, j], fit.grid, tops=False)
    for col in (spline, np.asarray(recon, dtype=float)[:, j]):
        sa = StreamingAllan(1, fit.rate_hz)
        sa.update(col[:, None])
        var.append(np.asarray(sa.result().var, dtype=float))
    ok = np.isfinite(var[0]) & np.isfinite(var[1]) & (var[1] > 0)
    if not np.any(ok):
        return fit
    k = int(np.argmax(np.where(ok, var[1], -np.inf)))
    rel = 0.5 * abs(math.sqrt(var[0][k] / var[1][k]) - 1.0)
    return replace(fit, coef_se=math.hypot(fit.coef_se, rel * fit.coefficient), gain_rel=rel)


def signal_avar_on(d: NDArray, rate_hz: float, tau: NDArray) -> NDArray[np.float64]:
    """AVAR ((m/s²)²) a slow signal ``d`` (sampled at ``rate_hz``) puts into a record, at the
    averaging times ``tau`` of the full-rate analysis: measured by the streaming estimator on
    ``d``, log-log interpolated; below its first τ it falls as τ² (a smooth signal)."""
    sa = StreamingAllan(1, rate_hz)
    sa.update(np.asarray(d, dtype=float)[:, None])
    res = sa.result()
    ts, vs = np.asarray(res.tau, float), np.maximum(np.asarray(res.var, float), 1e-300)
    ok = np.isfinite(vs)
    ts, vs = ts[ok], vs[ok]
    t = np.asarray(tau, dtype=float)
    out = np.exp(np.interp(np.log(t), np.log(ts), np.log(vs)))
    low = t < ts[0]
    out[low] = vs[0] * (t[low] / ts[0]) ** 2
    return out


def compensated_avar(var: NDArray, tau: NDArray, res: Any, coefficient: float
                     ) -> NDArray[np.float64]:
    """``var`` (the axis's full-rate AVAR at ``tau``) with the thermal part ĉ·u removed, from
    the two-channel Allan covariance ``res`` (axis, lagged temperature): see module doc."""
    cov = np.asarray(res.cov, dtype=float)
    ts = np.asarray(res.tau, dtype=float)
    vy, vu, cyu = cov[:, 0, 0], cov[:, 1, 1], cov[:, 0, 1]
    comp = vy - 2 * coefficient * cyu + coefficient**2 * vu
    ok = np.isfinite(comp) & (vy > 0)
    ts = ts[ok]
    ratio = np.clip(comp[ok] / vy[ok], 1e-6, None)
    t = np.asarray(tau, dtype=float)
    r = np.exp(np.interp(np.log(t), np.log(ts), np.log(ratio)))
    low = t < ts[0]
    r[low] = 1.0 - (1.0 - ratio[0]) * (t[low] / ts[0]) ** 3
    return np.asarray(var, dtype=float) * r


@dataclass
class ThermalFit:
    """The thermal model of one axis (SI units). ``channel`` drives it through a first-order
    lag ``lag_s`` [lag_lo, lag_hi] with ``coefficient`` [coef_lo, coef_hi] m/s²/K (68 %);
    ``z`` its test statistic; ``others``: the best z and lag of every other channel, and with
    more than one channel what chose between them (``_choose_channel``)."""

    channel: str
    channel_index: int
    coefficient: float
    coef_se: float
    lag_s: float
    lag_lo: float
    lag_hi: float
    z: float
    rate_hz: float
    others: dict[str, dict[str, float]] = field(default_factory=dict)
    allan: Any = field(default=None, repr=False)

    #: the z its test needs (``CouplingTest.threshold``: more than ``Z_TEMPERATURE`` where
    #: the se rests on few degrees of freedom)
    threshold: float = Z_TEMPERATURE
    #: the degrees of freedom the test's se rests on (∞: ``threshold`` is the normal's)
    threshold_dof: float = math.inf
    #: the lag's interval reaches the longest lag tried (record/4): its upper end is open
    lag_open: bool = False
    #: the scan's z of this channel at its best lag, on the covariance common to every lag
    #: and channel the scan compares (the other channels' ``others[...]["z"]``)
    scan_z: float = math.nan
    #: with more than one channel logged, what chose this one (``_choose_channel``): its
    #: held-out −2 ln L, the lag it was scored at, the rounding's share of it, its scan z
    channel_choice: dict[str, float] = field(default_factory=dict)
    #: the channels the record does not tell apart from this one, in words ("" if none)
    channel_note: str = ""
    #: the thermal path chosen by held-out likelihood (``thermal_paths``; None: not
    #: examined). When it is not one lag, ``coefficient``/``coef_se`` are its linear
    #: coupling's and ``lag_s`` its first lag, and ``signal`` is the path's
    path: PathFit | None = field(default=None, repr=False)
    #: the (step K, origin) of the driving channel's readings (``screen.log_step``; the
    #: DS18B20's 12-bit by default): its de-rounding and rounding terms are on it
    grid: tuple[float, float] = (DS18B20_STEP_K, 0.0)
    #: on a coarse grid, the reconstruction's relative gain uncertainty carried in
    #: ``coef_se`` (``coarse_gain_se``; 0 on the 12-bit step)
    gain_rel: float = 0.0

    @property
    def mechanism(self) -> str:
        return "one_lag" if self.path is None else self.path.kind

    @property
    def passed(self) -> bool:
        return self.z >= self.threshold

    @property
    def coef_interval(self) -> tuple[float, float]:
        return self.coefficient - self.coef_se, self.coefficient + self.coef_se

    def signal(self, temps: NDArray, y: NDArray | None = None) -> NDArray[np.float64]:
        """ĉ·(lagged driving channel − its mean) on the slow view (m/s²). The sensor's
        temperature at the record's start is unknown (the lag filter starts at T[0]); with
        the axis ``y`` given, the start-up difference β·e^(−t/τ_L) is fitted to y − ĉu by
        least squares and included, so it is not mistaken for a warm-up.

        β is fitted against the level of the record's first ``START_FIT_LAGS`` lags (an
        offset and a drift over that stretch), not the whole record's: a random walk or
        flicker puts the axis's level at the start anywhere from the whole record's line,
        and a whole-record fit takes that difference into β, leaving −(difference)·(1 −
        e^(−t/τ_L)) in the residual, a warm-up with the lag's time constant (claimed on 10
        of 120 coupled axes of the 24 h weekend benchmark)."""
        if self.path is not None and self.path.kind != "one_lag":
            # the path's signal, scaled with the linear coefficient (the engine moves it by
            # its standard error for the removal's covariance)
            b0 = float(self.path.chosen.beta[0])
            k = self.coefficient / b0 if b0 else 1.0
            return k * self.path.signal(temps[:, self.channel_index], y, self.grid)
        # the readings' rounding is not in the axis (the die is not rounded): removed with
        # the signal, it is added to the compensated axis (``derounded``)
        u = lag_filter(derounded(temps[:, self.channel_index], self.grid), self.lag_s,
                       self.rate_hz)
        d = self.coefficient * (u - u.mean())
        if y is None or self.lag_s == 0:
            return d
        t = np.arange(len(u)) / self.rate_hz
        e = np.exp(-t / abs(self.lag_s))
        m = min(len(t), max(8, math.ceil(START_FIT_LAGS * abs(self.lag_s) * self.rate_hz)))
        a = np.column_stack([np.ones(m), t[:m], e[:m]])
        coef, *_ = np.linalg.lstsq(a, np.asarray(y[:m], dtype=float) - d[:m], rcond=None)
        return d + coef[2] * (e - e.mean())


    def evidence(self, intervals: bool = True) -> str:
        """The finding's text; ``intervals`` False: one lag's coefficient and lag without
        their 68 % intervals (model-dependent: ``finding``)."""
        if self.path is not None and self.path.kind != "one_lag":
            return (f"the axis follows temperature '{self.channel}' (z = {self.z:.3g}, test "
                    f"z ≥ {self.threshold:g}) by {self.path.summary()}{self._channels_text}")
        lo, hi = self.coef_interval
        path = ("a first-order lag of" if self.lag_s >= 0 else
                "a negative lag (the logged sensor lags the die; the die sees T + |lag|·dT/dt)"
                " of")
        lag_iv = f" [{self.lag_lo:.4g}, {self.lag_hi:.4g}]" if intervals else ""
        c_iv = f" [{lo:.4g}, {hi:.4g}] (68 %)" if intervals else " (model-dependent, no interval)"
        txt = (f"the axis follows temperature '{self.channel}' through {path} "
               f"{self.lag_s:.4g} s{lag_iv}"
               f"{' (open: at the end of the lags tried)' if self.lag_open else ''} with "
               f"{self.coefficient:.4g} m/s²/K{c_iv}; Allan-covariance "
               f"regression z = {self.z:.3g} (test: z ≥ {self.threshold:.3g}{self._dof_note})")
        return txt + self._channels_text

    @property
    def _channels_text(self) -> str:
        """How the channel was chosen, every channel by the same numbers: the held-out
        −2 ln L of one lag each, then the scan's z on its one covariance (the chosen
        channel's test z above is another statistic: not beside the others')."""
        if not self.others:
            return ""
        if not self.channel_choice:
            return "; other channels: " + ", ".join(
                f"'{k}' z = {v['z']:.3g} at lag {v['lag_s']:.4g} s"
                for k, v in self.others.items())
        rows = {self.channel: self.channel_choice, **self.others}

        def one(k: str, v: dict[str, float]) -> str:
            mark = " (chosen)" if k == self.channel else ""
            end = ", open" if v.get("open") else ""
            return f"'{k}'{mark} {v['heldout']:.4g} at lag {v['heldout_lag_s']:.4g} s{end}"

        txt = ("; channels by held-out −2 ln L of one lag each (fitted on one half of the "
               "record, scored on the other; lower is better): "
               + ", ".join(one(k, v) for k, v in rows.items())
               + "; scan z on one covariance: "
               + ", ".join(f"'{k}' {v['scan_z']:.3g}" for k, v in rows.items()))
        if self.channel_note:
            txt += "; " + self.channel_note
        return txt

    @property
    def _dof_note(self) -> str:
        if not math.isfinite(self.threshold_dof):
            return ""
        return f", its se's degrees of freedom {self.threshold_dof:.3g}"

    def finding(self) -> Any:
        from avard.core.explain.causes import Finding

        lo, hi = self.coef_interval
        if self.path is not None and self.path.kind != "one_lag":
            p, iv = self.path.params()
            return Finding("temperature", False, p, iv, self.z, self.threshold,
                           self.evidence(), channel=self.channel, mechanism=self.mechanism,
                           model_dependent=self.path.model_dependent,
                           alternatives=self.path.alternatives)
        iv = {"coefficient": [lo, hi], "lag_s": [self.lag_lo, self.lag_hi]}
        if self.path is not None and self.path.beside_better:
            # a reading named beside the one lag kept predicts the held-out halves better
            # (``PathFit.beside_better``): one lag's coefficient and lag are one of two
            # readings, no interval (``--json`` keeps them as ``intervals_if_model_held``)
            return Finding("temperature", False,
                           {"coefficient": self.coefficient, "lag_s": self.lag_s}, {},
                           self.z, self.threshold,
                           self.evidence(intervals=False)
                           + "".join(f"; {n}" for n in self.path.beside_lag),
                           channel=self.channel, mechanism=self.mechanism,
                           model_dependent=True, intervals_if_model_held=iv)
        if self.path is not None and self.path.leaning:
            # one lag kept while a non-linear candidate predicts the held-out halves better:
            # its coefficient and lag are a linear model's, no interval (``--json`` keeps them
            # as ``intervals_if_model_held``)
            note = next(n for n in self.path.notes if n.startswith("one lag kept"))
            return Finding("temperature", False,
                           {"coefficient": self.coefficient, "lag_s": self.lag_s}, {},
                           self.z, self.threshold, f"{self.evidence(intervals=False)}; {note}",
                           channel=self.channel, mechanism=self.mechanism,
                           model_dependent=True, intervals_if_model_held=iv)
        beside = "" if self.path is None else "".join(f"; {n}" for n in self.path.beside_lag)
        return Finding("temperature", False,
                       {"coefficient": self.coefficient, "lag_s": self.lag_s}, iv,
                       self.z, self.threshold, self.evidence() + beside, channel=self.channel,
                       mechanism=self.mechanism)

    def to_dict(self) -> dict[str, Any]:
        lo, hi = self.coef_interval
        return {"channel": self.channel, "coefficient_mps2_per_k": self.coefficient,
                "coefficient_interval": [lo, hi], "lag_s": self.lag_s,
                "lag_interval_s": [self.lag_lo, self.lag_hi],
                "lag_interval_open": bool(self.lag_open),
                "z": self.z,
                "threshold": self.threshold,
                "threshold_dof": (self.threshold_dof if math.isfinite(self.threshold_dof)
                                  else None),
                "passed": self.passed, "others": self.others,
                "channel_choice": self.channel_choice or None,
                "channel_note": self.channel_note or None,
                "mechanism": self.mechanism,
                "path": None if self.path is None else self.path.to_dict()}

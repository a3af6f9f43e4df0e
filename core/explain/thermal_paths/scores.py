"""What the choice reports: one candidate's score (``PathScore``), the choice on one axis
(``PathFit``), and their parameters in words."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from avard.core.explain.thermal_fit import lag_filter
from avard.core.explain.thermal_fit.coarse import behind_readings
from avard.core.explain.thermal_fit.rounding import DS18B20_STEP_K
from avard.core.explain.thermal_paths.columns import Column, _relay, path_columns
from avard.core.explain.thermal_paths.settings import (
    HELDOUT_MARGIN,
    NUISANCE,
    ONE_LINE_SHARE,
    PATH_NAMES,
    PROFILE_DELTA,
    RATE_SMOOTH_S,
    RESOLVED_LAG_S,
    RESOLVED_REL,
)
from numpy.typing import NDArray


@dataclass
class PathScore:
    """One candidate on one axis: its held-out −2 ln L (``heldout``, both folds), the θ and
    coefficients fitted on the whole record with 68 % intervals, the extra term's z."""

    kind: str
    heldout: float
    theta: tuple[float, ...]
    beta: NDArray[np.float64]
    beta_se: NDArray[np.float64]
    theta_lo: tuple[float, ...]
    theta_hi: tuple[float, ...]
    z_extra: float
    open_end: bool
    cols: tuple[Column, ...] = ()
    #: the coefficients' 68 % interval (the jackknife's, widened to the profile over θ)
    beta_lo: tuple[float, ...] = ()
    beta_hi: tuple[float, ...] = ()
    #: False: a coefficient changes sign over the θ the data cannot tell from the best, so
    #: the parameters are model-dependent and carry no interval
    resolved: bool = True
    #: the Δ(−2 ln L) of the profile over θ its intervals were widened to (``profile_delta``)
    profile_delta: float = PROFILE_DELTA
    #: a refined dT/dt term's r − c·L (``net_rate``) and its 68 % interval: reported as its
    #: ``rate_coupling`` (``describe``); () otherwise
    net: tuple[float, ...] = ()
    #: refined two paths: the response at the drive (``_Refined.drive``), reported as
    #: ``drive_period_s``, ``gain_at_drive`` and ``phase_at_drive_rad`` (``describe``)
    drive: tuple[float, ...] = ()
    #: the couplings as fitted to ``cols`` where ``beta`` reads them through a column's gain
    #: (a refined dT/dt term: ``_ungained``), for the signal; () where they are ``beta``
    fitted: tuple[float, ...] = ()
    #: its held-out −2 ln L less one lag's with the same nuisance columns (the union of the
    #: two models' start states, warm-ups and given transients) refitted on the held-out
    #: half for both (``_matched``, both folds): the comparison an extension is chosen by
    #: (``heldout`` refits each model's own, and more or longer lags bring more); 0 for one
    #: lag, NaN where not computed
    matched: float = math.nan

    @property
    def beta_fitted(self) -> NDArray[np.float64]:
        """The coefficients that go with ``cols`` (the signal's, the rounding's)."""
        if not self.fitted:
            return self.beta
        out = np.array(self.beta, dtype=float)
        out[:len(self.fitted)] = self.fitted
        return out


@dataclass
class PathFit:
    """The thermal path chosen for one axis among ``CANDIDATES`` (module doc)."""

    chosen: PathScore
    scores: dict[str, PathScore]
    z_threshold: float
    rate_hz: float
    margin: float = HELDOUT_MARGIN
    notes: list[str] = field(default_factory=list)
    #: held-out −2 ln L of no coupling at all
    none_heldout: float = math.nan
    #: what the readings' rounding through the one-lag coupling makes up of the held-out
    #: deviance (``_View.rounding_share``): an extension must win by this beyond the margin
    rounding: float = 0.0
    #: other extensions the record supports as well as the chosen one (held out within the
    #: margin): the mechanism is one of these, and the parameters carry no interval
    alternatives: tuple[str, ...] = ()
    #: ``LEANING`` candidates that predict the held-out halves better than the one lag kept
    #: (by ``LEAN_MARGIN``, short of what choosing them needs): one lag's linear coefficient
    #: and lag are then a linear model's reading of a non-linear response
    leaning: tuple[str, ...] = ()
    #: per linear extension, what it passes less of that rounding than one lag (its share
    #: to beat instead of ``rounding``: ``_smoothing``)
    own_rounding: dict[str, float] = field(default_factory=dict)
    #: extensions that predict the held-out halves within the margin of the chosen one (or
    #: better) but are not named beside it, because they hold it in their limit with a
    #: parameter more (two paths beside a dT/dt term, ``_mimic``) or their θ sits at the end
    #: of its grid (open): the record does not tell them from it either (the notes say which)
    as_well: tuple[str, ...] = ()
    #: the notes naming another reading beside one lag kept (the dT/dt term, a relay): the
    #: one-lag finding's text says them, not only ``--json``'s notes
    beside_lag: tuple[str, ...] = ()
    #: the readings named beside one lag kept (``beside_lag``) that predict the held-out
    #: halves better than it by ``LEAN_MARGIN`` (the dT/dt reading, c·T + r·dT/dt): one
    #: lag's coefficient is then one of two readings the record does not tell apart and the
    #: data lean to the other, model-dependent with no interval (as ``leaning``)
    beside_better: tuple[str, ...] = ()
    #: the driving channel's readings' (step K, origin) the path was chosen on (its log's
    #: own, ``choose_path``'s ``grid``): its signal's temperature behind the readings and
    #: the relay's switch-time floor are on it
    grid: tuple[float, float] = (DS18B20_STEP_K, 0.0)

    @property
    def model_dependent(self) -> bool:
        """The parameters depend on a model choice the data do not make: a coefficient
        changes sign over the θ as good as the best, another mechanism fits as well, or one
        lag is kept while a non-linear candidate predicts better (``leaning``) or a reading
        named beside it does (``beside_better``)."""
        return (not self.chosen.resolved or bool(self.alternatives) or bool(self.leaning)
                or bool(self.beside_better))

    @property
    def kind(self) -> str:
        return self.chosen.kind

    def signal(self, T: NDArray, y: NDArray | None = None,
               grid: tuple[float, float] | None = None) -> NDArray[np.float64]:
        """The chosen model's signal on the slow view (m/s²); with ``y``, the start states
        fitted (least squares with an offset and a drift), else left out. ``grid``: ``T``'s
        readings' (step K, origin) (a held-out log's own), default the path's ``grid``."""
        s = self.chosen
        X = path_columns(T, list(s.cols), self.rate_hz, grid=self.grid if grid is None else grid)
        n = s_terms(s)
        d = X[:, :n] @ s.beta_fitted[:n]
        if y is None or X.shape[1] == n:
            return np.asarray(d, dtype=float)
        t = np.arange(len(d)) / self.rate_hz
        a = np.column_stack([np.ones_like(t), t, X[:, n:]])
        coef, *_ = np.linalg.lstsq(a, np.asarray(y, dtype=float) - d, rcond=None)
        return np.asarray(d + X[:, n:] @ coef[2:], dtype=float)

    def params(self) -> tuple[dict[str, float], dict[str, list[float]]]:
        """The chosen candidate's parameters (SI) and their 68 % intervals (none where another
        mechanism fits as well or a non-linear one predicts better: ``leaning``)."""
        p, iv = describe(self.chosen)
        return p, ({} if self.alternatives or self.leaning or self.beside_better else iv)

    def rounding_gain(self) -> float:
        """The L1 norm of the chosen path's response to an error in the logged readings
        (m/s² per K): Σ |β_i|·‖h_i‖₁ over its linear regressors, the largest factor the path
        can put on a bounded error (the readings' rounding). A lag's ‖h‖₁ is 1, a negative
        lag's lead-lag 2δ − h_lag 3; the dT/dt column (δ − h_s)/s multiplies either by 2/s.
        Every path's term counts: a two-path fit's coefficients are often large and of
        opposite sign, so the first alone says little of what its sum passes. The quadratic
        and the relay's columns are not linear in the error and are left out (the
        linear term beside them carries the rounding at first order)."""
        s = self.chosen
        g = 0.0
        for c, b in zip(s.cols, s.beta_fitted, strict=False):
            norm = 3.0 if c.lag < 0 else 1.0
            if c.kind == "u":
                g += abs(float(b)) * norm
            elif c.kind == "rate":
                g += abs(float(b)) * norm * 2.0 / RATE_SMOOTH_S
        return g

    def relay_floor(self, T: NDArray) -> tuple[float, str]:
        """(σ m/s², why) a Gauss–Markov bump beside this path must exceed to be claimed where
        a relay is chosen or named beside the path kept (0, "" elsewhere): the larger of

        - the RMS of the relay term's switch-time error: the relay switches on the
          temperature behind the readings, whose level is uncertain by their rounding on
          the log's own step q (``grid``; RMS q/√12), so each switch is off by about that
          over the temperature's slope there (capped at the time to the next switch), a
          pulse of 2|h| for that long: 2|h|·√(Σ δᵢ / record). Where the die swings a few
          steps the slope at a switch is a few mK per minute and δ is a minute: pulses that
          recur twice a cycle with a minute's correlation, which the scan reads as a
          Gauss–Markov process (the adversary's hysteresis 413 and 415: σ 4.8–5.7e-5 m/s²,
          T 25–26 s beside a relay of h ≈ 1.1e-4 chosen right). Like
          ``causes.gauss_markov_rounding_floor`` it bounds from above (the reconstruction
          is no worse than the readings);
        - where the relay is named beside another reading (one lag kept with the relay
          ``as_well`` or ``leaning``, or an alternative), the RMS of the difference of the
          two readings' signals: what the reading removed leaves of the one named beside
          it, a relay's odd harmonics beside one lag (404: σ 7.1e-5, T 64 s)."""
        sc = self.scores.get("hysteresis")
        named = (self.kind, *self.alternatives, *self.as_well, *self.leaning)
        relay = None if sc is None else next((c for c in sc.cols if c.kind == "relay"), None)
        if sc is None or relay is None or "hysteresis" not in named or len(sc.beta) < 2:
            return 0.0, ""
        T = np.asarray(T, dtype=float)
        # the temperature behind the readings on the log's own step and origin, as the relay
        # column was built (``path_columns``, ``behind_readings``): on the 12-bit default a
        # coarse log's knots sat between its levels, and its switch times' error was taken on
        # 0.0625 K
        behind = behind_readings(T, self.grid)
        v = lag_filter(behind, relay.lag, self.rate_hz)
        r = _relay(v, relay.width)
        sw = np.flatnonzero(np.diff(r) != 0) + 1
        record_s = len(T) / self.rate_hz
        floor = 0.0
        if len(sw):
            slope = np.abs(np.gradient(v) * self.rate_hz)[sw]
            gap = np.diff(np.concatenate([sw, [len(r)]])) / self.rate_hz
            delta = np.minimum(self.grid[0] / math.sqrt(12.0)
                               / np.maximum(slope, 1e-300), gap)
            floor = 2 * abs(float(sc.beta[1])) * math.sqrt(float(np.sum(delta)) / record_s)
        why = (f"{floor:.3g} m/s², the RMS of the relay's switch-time error (its switches "
               "on the temperature behind the readings, uncertain by their "
               f"{self.grid[0]:g} K "
               "rounding over the temperature's slope at each switch), which recurs twice a "
               "cycle and can look like a bump")
        # the relay at the ends of its lag's and width's 68 % intervals, the same h
        moved = 0.0
        for lag, w in ((sc.theta_lo[0], relay.width), (sc.theta_hi[0], relay.width),
                       (relay.lag, sc.theta_lo[1]), (relay.lag, sc.theta_hi[1])):
            if not (math.isfinite(lag) and math.isfinite(w)) or w <= 0:
                continue
            d = _relay(lag_filter(behind, lag, self.rate_hz), w) - r
            moved = max(moved, abs(float(sc.beta[1])) * float(np.sqrt(np.mean(d**2))))
        if moved > floor:
            floor = moved
            why = (f"{floor:.3g} m/s², the RMS of how far the relay term moves over its lag's "
                   "and width's 68 % intervals (its switch times as uncertain as they), "
                   "which recurs twice a cycle and can look like a bump")
        if self.kind != "hysteresis":
            d = self._score_signal(sc, T) - self._score_signal(self.chosen, T)
            apart = float(np.sqrt(np.mean((d - d.mean()) ** 2)))
            if apart > floor:
                floor = apart
                why = (f"{floor:.3g} m/s², the RMS of what the {PATH_NAMES[self.kind]} "
                       "kept leaves of the relay named beside it (its odd harmonics), "
                       "which can look like a bump")
        return floor, why

    def _score_signal(self, s: PathScore, T: NDArray, first: int = 0) -> NDArray[np.float64]:
        """Candidate ``s``'s coupling signal on the slow view (no start state), from its
        ``first`` coupling term on, its columns on the path's ``grid`` (the temperature
        behind the readings it was fitted on)."""
        X = path_columns(T, list(s.cols), self.rate_hz, grid=self.grid)
        n = s_terms(s)
        return np.asarray(X[:, first:n] @ s.beta_fitted[first:n], dtype=float)

    def extension_signal(self, T: NDArray) -> NDArray[np.float64]:
        """The chosen extension's own signal on the slow view: its coupling signal less the
        linear coupling's term (a relay's switches, a second path, a quadratic), on the
        path's ``grid`` as ``_score_signal``."""
        return self._score_signal(self.chosen, T, first=1)

    def summary(self) -> str:
        s = self.chosen
        p, iv = self.params()  # no interval where another mechanism fits as well
        txt = ", ".join(f"{k} {v:.4g} [{iv[k][0]:.4g}, {iv[k][1]:.4g}]" if k in iv
                        else f"{k} {v:.4g}" for k, v in p.items())
        txt += "; 68 %" if iv else ""
        ranks = ", ".join(f"{k} {v.heldout - self.scores['one_lag'].heldout:+.3g}"
                          for k, v in self.scores.items() if k != "one_lag")
        end = " (open: θ at the end of its grid)" if s.open_end else ""
        return (f"thermal path: {s.kind} ({txt}){end};"
                f" held-out Δ(−2 ln L) against one lag: {ranks} (an extension needs "
                f"< −{self.margin + self.rounding:.3g}, the margin {self.margin:g} and the "
                f"readings' rounding through the coupling {self.rounding:.3g}"
                + "".join(f", for {PATH_NAMES[k]} what it passes less of it {v:.3g}"
                          for k, v in self.own_rounding.items())
                + f", and its own z ≥ {self.z_threshold:.3g})"
                + "".join(f"; {n}" for n in self.notes))

    def to_dict(self) -> dict[str, object]:
        p, iv = self.params()
        return {"mechanism": self.kind, "mechanism_alternatives": list(self.alternatives),
                "mechanism_fits_as_well": list(self.as_well),
                "params": p, "intervals": iv,
                "open": self.chosen.open_end, "z_extra": self.chosen.z_extra,
                "z_threshold": self.z_threshold, "margin": self.margin,
                "rounding_share": self.rounding,
                "rounding_share_own": dict(self.own_rounding),
                "heldout_minus2lnL": {k: v.heldout for k, v in self.scores.items()},
                # what choosing compares: each less one lag's, the same nuisance columns
                # refitted on the held-out half for both (``_matched``)
                "heldout_matched_minus_one_lag": {
                    k: (v.matched if math.isfinite(v.matched) else None)
                    for k, v in self.scores.items()},
                "model_dependent": self.model_dependent,
                "readings_beside_predict_better": list(self.beside_better),
                "notes": self.notes}


def s_terms(s: PathScore) -> int:
    return sum(1 for c in s.cols if c.kind not in NUISANCE)


_NAMES = {"one_lag": (("coefficient",), ("lag_s",)),
          "two_path": (("coefficient", "coefficient_2"), ("lag_s", "lag_2_s")),
          "quadratic": (("coefficient", "quadratic"), ("lag_s",)),
          "rate": (("coefficient", "rate_coupling"), ("lag_s",)),
          "hysteresis": (("coefficient", "hysteresis"), ("lag_s", "width_k"))}


def describe(s: PathScore) -> tuple[dict[str, float], dict[str, list[float]]]:
    """The candidate's parameters (SI) and their 68 % intervals. A refined dT/dt term
    reports as ``rate_coupling`` its r − c·L (``net_rate``, what the data resolve) and the
    fitted split as ``rate_coupling_beside_lag`` (r with the static lag ``lag_s`` beside it)
    with no interval: along the ridge r and L are not resolved apart."""
    bn, tn = _NAMES[s.kind]
    p: dict[str, float] = {}
    iv: dict[str, list[float]] = {}
    for i, k in enumerate(bn):
        p[k] = float(s.beta[i])
        iv[k] = ([s.beta_lo[i], s.beta_hi[i]] if s.beta_lo else
                 [float(s.beta[i] - s.beta_se[i]), float(s.beta[i] + s.beta_se[i])])
    for i, k in enumerate(tn):
        p[k] = float(s.theta[i])
        iv[k] = [float(s.theta_lo[i]), float(s.theta_hi[i])]
    if s.kind == "two_path" and s.drive:
        # what the record resolves: the response at the drive, with its interval; c₁, c₂ and
        # the lags only where their own interval is within ±RESOLVED_REL (``unresolved``)
        per, a, a_lo, a_hi, ph, ph_lo, ph_hi, share = s.drive
        p.update(drive_period_s=per, gain_at_drive=a, phase_at_drive_rad=ph)
        iv.update(gain_at_drive=[a_lo, a_hi], phase_at_drive_rad=[ph_lo, ph_hi])
        for k in unresolved(p, iv, share):
            del iv[k]
    if s.kind == "rate" and s.net:
        p["rate_coupling_beside_lag"] = p["rate_coupling"]
        # r − c·L's own interval (its jackknife with θ re-chosen, widened to the local
        # profile): r − c·L is the same anywhere along the ridge, so not widened to the
        # split's interval at the fitted L (that hull held the truth on 96 % of the dT/dt
        # row's records: it hedged r − c·L's 3 % bias from the readings' rounding, which
        # ``_rate_floor`` now keeps out)
        iv.pop("rate_coupling")
        p["rate_coupling"] = s.net[0]
        iv["rate_coupling"] = [s.net[1], s.net[2]]
    return p, (iv if s.resolved else {})


def unresolved(p: dict[str, float], iv: dict[str, list[float]],
               share: float = math.nan) -> list[str]:
    """A two-path fit's own parameters (``coefficient``, ``coefficient_2``, ``lag_s``,
    ``lag_2_s``) reported with no interval, "not resolved": all of them where the drive is
    one line (``share``, its part of the channel's variance, at least ``ONE_LINE_SHARE``),
    else those whose 68 % interval is wider than ±``RESOLVED_REL`` of the value (a lag: or
    ±``RESOLVED_LAG_S``) or that hold no interval."""
    out: list[str] = []
    one_line = share >= ONE_LINE_SHARE
    for k in ("coefficient", "coefficient_2", "lag_s", "lag_2_s"):
        if k not in p:
            continue
        if k not in iv or one_line:
            out.append(k)
            continue
        half = 0.5 * (iv[k][1] - iv[k][0])
        room = RESOLVED_REL * abs(p[k])
        if k.startswith("lag"):
            room = max(room, RESOLVED_LAG_S)
        if not half <= room:
            out.append(k)
    return out

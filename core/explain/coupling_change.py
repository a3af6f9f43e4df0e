"""Whether one thermal coupling describes the whole record, or the coupling changed midway (a
re-mounted or re-seated sensor, a loosened clamp): for ``avard explain``.

Issue 23 item 5 asks for an honest "unexplained" that names the cause where it can. A
coupling whose coefficient changes at some time t_s (sign flip or size change) is outside
every thermal candidate (each is one fixed path for the whole record), and the axis jumps at
t_s by (b − a)·u(t_s), u the lagged temperature: the transient search read that jump as a
**bias step** with a ±3 % size and a ±1 s time, and the coupling fitted on the whole record
is the two coefficients' average. This module tests for the change and says it.

The test. On an axis where a thermal coupling was tested (``ThermalFit``, claimed or not:
a coefficient that flips sign averages to nearly nothing, so the whole-record coupling may
fail its own test), take the driving channel u through the fitted lag L (the whole
record's), and the axis y less the transients the compound search found there (a found step
is not left in a part's regression). For a candidate change time t_c split the record
into the part before and the part after, each a record of its own (no Allan difference
spans t_c), and in each fit the coupling by the Allan-covariance regression of
``thermal_fit`` (ĉ = Σ w_k Cov_A(y, u)_k / AVAR_u,k over the octaves τ ≥ the channel's
floor): a before, b after, each with the larger of its analytic se and its delete-a-group
jackknife se over ``GROUPS`` contiguous pieces of the part (the jackknife does not assume
the noise's differences independent across a slow regressor; red noise breaks that). The
two parts share no difference, so under one coupling (a = b)

    z(t_c) = (a − b) / √(se_a² + se_b²)

is a Student-t-like ratio whose se rest on few pieces: its degrees of freedom are the
Satterthwaite combination of the two jackknifes' (``GROUPS`` − 1 each). The change time is
searched over a coarse grid (``GRID``: 20 % … 80 % of the record in steps of 5 %, 13 times;
a part shorter than a fifth of the record holds too few of the slow octaves where a coupling
shows), and the search is counted in the level: the change is said where at some grid time
|z| ≥ t_{dof}(``ALPHA`` / (2·13)) (Bonferroni over the grid, two-sided). ``ALPHA`` is a
share of the size of each of ``alarm``'s shares. This test claims no cause (it takes
claims away), so it is not in ``alarm.ALPHA_AXIS``; its false alarms cost power (a real step
at the wrong time would lose its claim) and are measured on the null rows
(docs/log/2026-11-29-remount27.md).

Why it does not fire on a described sensor: with one coupling a = b in expectation on any
split; a real bias step at t_s beside a steady coupling is a constant in the part after
t_s, which Allan differences of that part do not see (and the step the search found is
taken out of y before, for the splits elsewhere). What it can read as a change is a
coupling that is not the one lag it regresses on and whose one-lag projection differs
between parts because the temperature's spectrum does (a non-linear coupling where one half
swings further): the rows of the adversary's generator measure that.

Where the change is found, its time is estimated within a grid step of the best grid time
(after the test: ``_change_time``, the split of least residual of the differences of minute
means regressed on the lagged temperature's, one coefficient each side), the coefficients
refitted on the parts it makes, and:

- one line in the text, the JSON (the channel's ``caveats`` and a finding of cause
  ``coupling_change``, never claimed) and the report: "the thermal coupling changed at
  about t s (coefficient a ± … before, b ± … after): a single coupling does not describe
  this record";
- a bias step or an excursion edge the compound search found within a grid step of that
  time is not claimed (it is the coupling's change as the step model reads it): marked
  model-dependent, its interval withheld (kept in ``--json`` as
  ``intervals_if_model_held``), and the other transients refitted without it;
- the whole-record coupling's finding, an average of two couplings, is model-dependent and
  its interval withheld likewise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from avard.core.allan.beta import t_two_sided
from avard.core.errors import DataError, FitError
from avard.core.explain import causes as cz
from avard.core.explain import transients as tr
from avard.core.explain.causes import Finding
from avard.core.explain.thermal_fit import (
    ThermalFit,
    allan2,
    hole_mask,
    jackknife_tempco,
    lag_filter,
    min_tau_for,
    rounding_floor_tau,
    tempco_from_cov,
    without_start,
)
from numpy.typing import NDArray

__all__ = ["ALPHA", "GRID", "GROUPS", "CouplingChange", "change_line", "check", "mark",
           "find_change"]

#: The test's share of the axis's false-alarm level (the size of each of ``alarm``'s shares).
ALPHA = 2.5e-4
#: Candidate change times, as fractions of the record (the search counted in the level).
GRID = tuple(round(0.2 + 0.05 * i, 2) for i in range(13))
#: Contiguous pieces of each part for its coefficient's jackknife se.
GROUPS = 10
#: Most slow-view points the parts are regressed on (longer views are averaged further: the
#: coupling acts on minutes, the octaves lost are seconds).
MAX_POINTS = 1 << 15
CAUSE = "coupling_change"


@dataclass(frozen=True)
class Part:
    """The coupling fitted on one part of the record: ĉ (m/s²/K), its se and the dof of
    that se (the jackknife's, GROUPS − 1)."""

    c: float
    se: float
    dof: float
    #: the lag (s) the part's coupling was refitted through (NaN: the whole record's)
    lag_s: float = math.nan


@dataclass(frozen=True)
class CouplingChange:
    """The test's outcome on one axis: the best change time (s) with the coefficients
    before and after it, z against its threshold, the channel and lag regressed on."""

    time_s: float
    before: Part
    after: Part
    z: float
    threshold: float
    channel: str
    lag_s: float
    trials: int
    record_s: float
    #: the transients found at the change and not claimed there (``check``)
    taken: tuple[cz.Candidate, ...] = ()

    @property
    def changed(self) -> bool:
        return self.z >= self.threshold

    @property
    def window_s(self) -> float:
        """How far from ``time_s`` a found step is the change's (one coarse grid step)."""
        return (GRID[1] - GRID[0]) * self.record_s

    def line(self) -> str:
        """The one line said in the text, the JSON and the report."""
        b, a = self.before, self.after
        return (f"the thermal coupling changed at about {self.time_s:.4g} s (coefficient "
                f"{b.c:.3g} ± {b.se:.2g} before, {a.c:.3g} ± {a.se:.2g} after, m/s²/K on "
                f"'{self.channel}' through {_lag(b, self.lag_s)} and {_lag(a, self.lag_s)}; "
                f"z {self.z:.3g} against {self.threshold:.3g} over {self.trials} change "
                "times): a single coupling does not describe this record")

    def finding(self) -> Finding:
        """Never claimed: a change of the coupling is no cause of its own; it says the
        record is not one coupling (the evidence is the line, or why it was not said)."""
        ev = (self.line() if self.changed else
              f"one coupling before and after every change time tried: at the best, "
              f"{self.time_s:.4g} s, {self.before.c:.3g} ± {self.before.se:.2g} before and "
              f"{self.after.c:.3g} ± {self.after.se:.2g} after (m/s²/K), z {self.z:.3g} "
              f"below {self.threshold:.3g}")
        return Finding(CAUSE, False,
                       {"time_s": self.time_s, "coefficient_before": self.before.c,
                        "coefficient_after": self.after.c},
                       {"coefficient_before": [self.before.c - self.before.se,
                                               self.before.c + self.before.se],
                        "coefficient_after": [self.after.c - self.after.se,
                                              self.after.c + self.after.se]},
                       self.z, self.threshold, ev, channel=self.channel)


def _lag(p: Part, whole: float) -> str:
    return f"{(p.lag_s if math.isfinite(p.lag_s) else whole):.3g} s"


def _part(y: NDArray, u: NDArray, keep: NDArray[np.bool_] | None, rate: float,
          mt: float) -> Part:
    """The Allan-covariance coupling of one part (a record of its own) with its se."""
    none = Part(0.0, math.inf, GROUPS - 1.0)  # nothing to compare (z 0 for its split)
    if len(y) < 4 * GROUPS or (keep is not None and np.count_nonzero(keep) < 4 * GROUPS):
        return none
    try:  # a part mostly inside a hole of the log has no octave to regress on
        res = allan2(y, u, rate, keep)
        c, se_a, n = tempco_from_cov(res, mt)
        if n == 0 or not math.isfinite(se_a):
            return none
        _c, se_jk = jackknife_tempco(y, u, rate, GROUPS, mt, keep, res)
    except (DataError, FitError, ValueError):
        return none
    return Part(c, max(se_a, se_jk), GROUPS - 1.0)


def _z(p: Part, q: Part) -> tuple[float, float]:
    """(|a − b|/√(se_a² + se_b²), its Satterthwaite degrees of freedom)."""
    v = p.se**2 + q.se**2
    if not (math.isfinite(v) and v > 0):
        return 0.0, 1.0
    dof = v**2 / (p.se**4 / p.dof + q.se**4 / q.dof)
    return abs(p.c - q.c) / math.sqrt(v), dof


def find_change(y: NDArray, temps: NDArray | None, thermal: ThermalFit | None,
                trans: list[cz.Candidate], rate_b: float,
                screen: Any | None = None) -> CouplingChange | None:
    """The test (module doc) on one axis's slow view ``y`` (``rate_b`` blocks per second)
    against ``thermal``'s channel and lag; ``trans``: the transients found on the axis
    (taken out of ``y`` first); ``screen``: the input screen's log (its holes in the
    channel's log are gaps). None where no coupling was tested or the record is too
    short for the parts."""
    if thermal is None or temps is None or len(y) < 2 * 256:
        return None
    n = len(y)
    found = [c for c in trans if c.passed and c.cause != "drift"]
    yc = np.asarray(y, dtype=float) - (tr.signal_of(found, n, rate_b) if found else 0.0)
    T = np.asarray(temps[:, thermal.channel_index], dtype=float)
    L = float(thermal.lag_s)
    mt = min_tau_for(L, rounding_floor_tau(T, rate_b))
    if not math.isfinite(mt):
        return None
    X = without_start(np.column_stack([yc, lag_filter(T, L, rate_b)]), L, rate_b)
    holes = [] if screen is None else [
        (math.floor(h0 * rate_b), math.ceil(h1 * rate_b))
        for h0, h1 in screen.holes(thermal.channel) if h1 - h0 >= 1.0]
    keep = hole_mask(n, holes, L, rate_b)
    f = 1 << max(0, math.ceil(math.log2(n / MAX_POINTS)))
    if f > 1:
        m = (n // f) * f
        X = X[:m].reshape(-1, f, 2).mean(axis=1)
        keep = None if keep is None else keep[:m].reshape(-1, f).all(axis=1)
    rate = rate_b / f
    M = len(X)

    def at(frac: float) -> tuple[float, float, Part, Part]:
        k = int(round(frac * M))
        p = _part(X[:k, 0], X[:k, 1], None if keep is None else keep[:k], rate, mt)
        q = _part(X[k:, 0], X[k:, 1], None if keep is None else keep[k:], rate, mt)
        z, dof = _z(p, q)
        return z, t_two_sided(ALPHA / len(GRID), max(dof, 1.0)), p, q

    z, thr, p, q, frac = max((at(fr) + (fr,) for fr in GRID), key=lambda r: r[0] / r[1])
    if z >= thr:
        # the time estimated after the test (the decision is the grid's), and the
        # coefficients with their se refitted on the parts it makes
        frac = _change_time(X, keep, rate, frac)
        k = int(round(frac * n))
        p, q = at(frac)[2:]
        p, q = (_refit(yc[a:b], temps[a:b], thermal, rate_b, screen, a, fb)
                for (a, b), fb in (((0, k), p), ((k, n), q)))
    return CouplingChange(frac * M / rate, p, q, z, thr, thermal.channel, L, len(GRID),
                          n / rate_b)


def _refit(y: NDArray, temps: NDArray, thermal: ThermalFit, rate_b: float,
           screen: Any | None, first: int, fallback: Part) -> Part:
    """The coupling of one part (a record of its own) as explain fits a whole record's on
    the same channel (``fit_thermal_axes``: its own lag, the coefficient's interval with
    the lag's share): the numbers the line gives. A change of the coupling leaves the whole
    record's lag an average too (on a sign flip it moved 174 s to 642 s). ``first``: the
    part's first block (its holes are the screen's, shifted); ``fallback``: the test's own
    fit of the part, kept where the refit cannot be made."""
    from avard.core.explain.thermal_fit import fit_thermal_axes

    j = thermal.channel_index
    holes = None if screen is None else {0: [
        (math.floor(h0 * rate_b) - first, math.ceil(h1 * rate_b) - first)
        for h0, h1 in screen.holes(thermal.channel) if h1 - h0 >= 1.0]}
    try:
        fit = fit_thermal_axes(np.asarray(y, dtype=float)[:, None], temps[:, [j]],
                               [thermal.channel], rate_b, holes)[0]
    except (DataError, FitError, ValueError):
        return fallback
    return Part(fit.coefficient, fit.coef_se, GROUPS - 1.0, fit.lag_s)


#: The block (s) whose means' differences estimate the change time (``_change_time``).
TIME_BLOCK_S = 60.0


def _change_time(X: NDArray, keep: NDArray[np.bool_] | None, rate: float,
                 frac: float) -> float:
    """The change time (fraction of the record) within a grid step of the grid's best
    ``frac``: the split that leaves the least residual when the differences of the axis's
    ``TIME_BLOCK_S`` means are regressed on the lagged temperature's with one coefficient
    before it and another after (the difference across the split left out: a jump there
    is free). Differences, so a random walk's level does not pull the split; least squares,
    an estimate (the z scan's best time is biased towards the side whose part is
    cleaner)."""
    k = max(1, round(TIME_BLOCK_S * rate))
    m = len(X) // k
    if m < 16:
        return frac
    B = X[:m * k].reshape(m, k, 2).mean(axis=1)
    ok = np.ones(m, dtype=bool) if keep is None else keep[:m * k].reshape(m, k).all(axis=1)
    dy, du = np.diff(B[:, 0]), np.diff(B[:, 1])
    good = ok[1:] & ok[:-1]
    dy, du = np.where(good, dy, 0.0), np.where(good, du, 0.0)
    cuu, cuy, cyy = (np.concatenate([[0.0], np.cumsum(v)]) for v in (du * du, du * dy, dy * dy))

    def rss(lo: NDArray, hi: NDArray) -> NDArray:
        uu, uy, yy = cuu[hi] - cuu[lo], cuy[hi] - cuy[lo], cyy[hi] - cyy[lo]
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.asarray(yy - np.where(uu > 0, uy**2 / uu, 0.0))

    step = GRID[1] - GRID[0]
    n_d = len(dy)
    j = np.arange(max(1, int((frac - step) * n_d)), min(n_d - 1, int((frac + step) * n_d)) + 1)
    if len(j) == 0:
        return frac
    # split before difference j: parts [0, j) and [j + 1, n_d), difference j (the jump) out
    total = rss(np.zeros_like(j), j) + rss(j + 1, np.full_like(j, n_d))
    return float((j[int(np.argmin(total))] + 1) / n_d)


def _near(c: cz.Candidate, ch: CouplingChange) -> bool:
    """Whether a passed step or excursion edge of ``c`` lies within the change's window."""
    if c.cause == "bias_step":
        times = [float(c.params.get("time_s", math.nan))]
    elif c.cause == "excursion":
        times = [float(c.params["start_s"]), float(c.params["end_s"])]
    else:
        return False
    return any(abs(t - ch.time_s) <= ch.window_s for t in times)


def check(y: NDArray, temps: NDArray | None, thermal: ThermalFit | None,
          trans: list[cz.Candidate], missed: list[cz.Candidate], work: NDArray,
          rate_b: float, noise_of: tr.NoiseOf, screen: Any | None = None
          ) -> tuple[CouplingChange | None, list[cz.Candidate], list[cz.Candidate]]:
    """(the test's outcome, claimed, not claimed transients): ``find_change``, then where
    the coupling changed, a step (or an excursion edge) at the change not claimed and the
    other transients refitted and tested again without it in ``work`` (the axis the
    compound search ran on, ``noise_of`` its noise), as ``engine._compound`` does for a
    transient taken out. The steps taken are kept in the outcome (``taken``) for
    ``mark``."""
    change = find_change(y, temps, thermal, trans, rate_b, screen)
    if change is None or not change.changed or not any(_near(c, change) for c in trans):
        return change, trans, missed
    taken = tuple(c for c in trans if _near(c, change))
    out = [replace(c, passed=False, intervals={}, evidence=c.evidence + (
        f"; not claimed: at the time the thermal coupling changed (about "
        f"{change.time_s:.4g} s), where the axis jumps by the change of the coupling times "
        "the lagged temperature: model-dependent, its interval withheld"))
        for c in taken]
    kept = [c for c in trans if not _near(c, change) and c.cause != "drift"]
    drift = [c for c in trans if c.cause == "drift"]
    lost: list[cz.Candidate] = []
    if kept:
        kept, lost = tr.confirm_compound(work, rate_b, noise_of, kept)
    return replace(change, taken=taken), [*kept, *drift], [*out, *lost, *missed]


def mark(change: CouplingChange | None, findings: list[Finding]) -> list[Finding]:
    """``findings`` with the test's own (never claimed) and, where the coupling changed,
    the steps at the change and the whole-record coupling's finding marked model-dependent
    with their intervals withheld (``--json`` keeps them as ``intervals_if_model_held``)."""
    if change is None:
        return findings
    if change.changed:
        for f in findings:
            if f.cause == "temperature" and f.intervals:
                f.model_dependent = True
                f.intervals_if_model_held, f.intervals = f.intervals, {}
            elif not f.claimed and f.cause in ("bias_step", "excursion"):
                c = next((c for c in change.taken
                          if c.cause == f.cause and c.params == f.params), None)
                if c is not None:
                    f.model_dependent = True
                    f.intervals_if_model_held = dict(c.intervals)
    return [*findings, change.finding()]


def change_line(findings: list[Finding]) -> str | None:
    """The line of a channel whose coupling changed (None elsewhere), from its findings."""
    f = next((f for f in findings if f.cause == CAUSE and f.statistic >= f.threshold), None)
    return None if f is None else f.evidence

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
fail its own test and its lag and channel be anywhere), take the axis y less the
transients the compound search found there (a found step is not left in a part's
regression) and, as regressor u, each logged channel through each lag of ``LAGS`` (those up
to an eighth of the record) and the thermal fit's own channel and lag. The record is cut
into ``SEGMENTS`` contiguous segments, and the Allan difference sums of (y, u) kept per
segment (each difference in the segment of its middle: ``thermal_fit.octave_sums_by_part``,
one pass a regressor). For a candidate change time t_c (a segment boundary) the part before
is the segments before it and the part after the rest; in each the coupling is fitted by
``thermal_fit``'s Allan-covariance regression (ĉ = inverse-variance combination over the
octaves τ ≥ the channel's floor of Cov_A(y, u)/AVAR_u, ``tempco_from_cov``): a before, b
after, each with the larger of its analytic se and its delete-a-segment jackknife se (the
jackknife does not assume the noise's differences independent across a slow regressor; red
noise breaks that). Under one coupling (a = b) the parts' estimates are independent but for
the few long differences about t_c, and

    z(t_c) = (a − b) / √(se_a² + se_b²)

is a Student-t-like ratio whose se rest on few segments: its degrees of freedom are the
Satterthwaite combination of the two jackknifes' (segments − 1 each). The change time is
searched over a coarse grid (``GRID``: 20 % … 80 % of the record in steps of 5 %, 13 times;
a part shorter than a fifth of the record holds too few of the slow octaves where a coupling
shows) and every regressor, and the whole search is counted in the level: the change is said
where for some regressor and grid time |z| ≥ t_dof(``ALPHA`` / (regressors × 13)) two-sided
(Bonferroni: 13 regressors and 169 trials on a two-channel 4 h record, thresholds ≈ 7–9
there). ``ALPHA`` is a share of the size of each of ``alarm``'s shares. This test claims no
cause (it takes claims away), so it is not in ``alarm.ALPHA_AXIS``; its false alarms cost
power (a real step at the wrong time would lose its claim) and are measured on the null rows
(docs/log/2026-11-29-remount27.md).

Why it does not fire on a described sensor: with one coupling a = b in expectation on any
split and through any regressor; a real bias step at t_s beside a steady coupling is a
constant after t_s, which no Allan difference inside a part sees (and the step the search
found is taken out of y before, for the splits elsewhere). What it can read as a change is
a coupling that is not the one lag it regresses on and whose one-lag projection differs
between parts because the temperature's spectrum does: ĉ weights the octaves by the
drive's power there, so a fixed path through two lags in series (or a lag + dT/dt), whose
response relative to one lag varies with frequency, projects on one lag differently under
a 20-minute cycle than under a 2-hour one (review27b's record: z 7.9 against 7.7 with one
coupling, never changed).

The fixed-path test (``cross_split``), made where the scan fires, on every channel whose
own scan fires (each at its best lag and grid time; the smallest decides: the room's
channel, three lags from a coupling through the plate's two, is read by three lags too
coarsely on a 12 h record, where the plate's is not). One fixed path of the richer form
(the channel through three first-order lags and the rate of the first: a sum of lags holds
two lags in series, a lag with a lead and a lag + dT/dt over the band a record drives; the
lags the scan's and the next of ``LAGS`` below and above it, ``path_lags``, or the scan's
beside two other neighbouring lags of ``LAGS`` where those describe the whole record better
by more than a χ²₁ at ``ALPHA``, ``path_sets``: the scan's lag is the one-lag projection's,
0 s on a room channel several hundred seconds from the die) is
fitted on one part (the Allan-covariance regression on the three at once, ``_multi``) and
taken from the other part's axis; what is left there is regressed on the one-lag regressor
(κ, ``_coefficients``), with the larger of its analytic se and the jackknife over both
parts' segments (the fit's replicates and the tested part's). A fixed coupling of that
form leaves κ ≈ 0 whatever the spectrum does between the parts; a coupling that changed
leaves the change itself (for a one-lag re-mount, (b − a) times the lagged temperature).
Both directions are made (fit before, test after, and the reverse: a fit on the part whose
drive is narrow extrapolates poorly to the other) and the smaller |κ|/se over its
threshold decides: t at ``ALPHA`` over the grid's 13 times (the time and regressor are the
scan's; under a fixed richer path the scan's choice leans on the one-lag projection's
difference, not on κ's noise; where no coupling is felt at all the scan's own level holds,
as this test only takes lines away). The change is said (``changed``) where both tests
pass; where the scan fires and the fixed path predicts the other part (or the test cannot
be made), a hedged line (``hedged``) says the record does not tell a changed coupling from
a fixed one that is not one lag under a spectrum that changed. A fixed path can mimic a
change where the parts' spectra differ (a gain per band), so a real change under a changed
room may be hedged too: the honest reading of such a record.

Where the change is found, its time is estimated within a grid step of the best grid time
(after the test: ``_change_time``, the split of least residual of the minute means regressed
on the lagged temperature's, an offset and a coefficient each side; or, where the transient
search found a step or an excursion edge within two grid steps, that jump's time, the nearest
to the estimate), each part's coupling
refitted as explain fits a record's (``fit_thermal_axes`` on every logged channel: its own
channel and lag, the interval with the lag's share; the part less ``GUARD`` of the record
either side of a time the levels estimated; the se no smaller than the scan's own for the
part), and:

- one line in the text, the JSON (the channel's ``caveats`` and a finding of cause
  ``coupling_change``, never claimed) and the report: "the thermal coupling changed at
  about t s (coefficient a ± … before, b ± … after …): a single coupling does not describe
  this record"; where hedged, the hedged line in the JSON (the caveats, the finding) and
  appended to the whole-record temperature finding's evidence (the text and the report
  print it with that finding), never "CHANGED";
- (changed or hedged) a bias step or an excursion edge the compound search found within a
  grid step of that time is not claimed (it is the coupling's change as the step model
  reads it): marked model-dependent, its interval withheld (kept in ``--json`` as
  ``intervals_if_model_held``), and the other transients refitted without it;
- (changed or hedged) the whole-record coupling's finding, an average of two couplings or
  one lag's reading of a path that is not one lag, is model-dependent and its interval
  withheld likewise.

The parts' intervals. A part's refit is explain's one lag, and the logged sensor is not the
die: its own lag puts a lead in the path from the log to the die, c·(1 + s·jω)/(1 + l·jω),
which one lag reads with its lag short by about s and its gain low, by 1–3 % on a plate
sensor 15 s behind the plate, against se's of a few 0.1 % on a 12 h part (with the sensor's
lag taken out of the generator the parts sat within 1.5 se of the truth). So each part's se
carries the one lag's model error as well (``_lead_gain``): the one-lag coefficient less the
steady gain of a lag with a lead fitted on the same part (u_L and du_L/dt at once, L scanned
about the one-lag fit's), with that difference's own jackknife noise taken out, the two
parts' shares pooled (``_shared_model``: one sensor before and after). The coefficient
printed stays the one-lag fit's (the line names its lag); the lead fit's own steady gain is
no better a point (the ridge between a and s makes it noisier than the bias it removes).

A change of the lag alone (the coefficient kept) is not a hypothesis of its own: where it
is large (60 s → 600 s on a synthetic 4 h record) the scan fires through the one-lag
projection's difference and the refitted parts give both lags; a smaller one (60 → 240 s)
was not seen.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from avard.core.allan.beta import t_two_sided
from avard.core.allan.deviations import NORM
from avard.core.errors import DataError, FitError
from avard.core.explain import causes as cz
from avard.core.explain import transients as tr
from avard.core.explain.causes import Finding
from avard.core.explain.thermal_fit import ThermalFit, allan2, lag_filter, without_start
from avard.core.explain.thermal_fit.holes import hole_mask
from avard.core.explain.thermal_fit.rounding import rounding_floor_tau
from avard.core.explain.thermal_fit.signals import _rho
from avard.core.explain.thermal_fit.sums import (
    OctaveSums,
    axes_differences,
    lag_octave_sums,
    min_tau_for,
    octave_sums_by_part,
)
from avard.core.io.screen import ScreenLog
from numpy.typing import NDArray

__all__ = ["ALPHA", "GRID", "LAGS", "SEGMENTS", "CouplingChange", "change_line", "check",
           "cross_split", "find_change", "hedged_line", "mark", "path_lags", "path_sets"]

#: The test's share of the axis's false-alarm level (the size of each of ``alarm``'s shares).
ALPHA = 2.5e-4
#: Candidate change times, as fractions of the record (the search counted in the level).
GRID = tuple(round(0.2 + 0.05 * i, 2) for i in range(13))
#: Contiguous segments of the record (each Allan difference in the segment of its middle):
#: a part is the segments before or after a grid time (one segment a grid step), its
#: jackknife deletes one at a time. 40 (two a grid step) gave the jackknife more degrees of
#: freedom than its segments' shared slow noise leaves it: a null axis of a re-mount
#: record said a change at z 6.0 against 5.7 (5.4 against 7.0 with 20).
SEGMENTS = 20
#: The lags (s) every logged channel is tried through (those up to an eighth of the
#: record), beside the thermal fit's own channel and lag: on a coupling that changes sign
#: the whole record's fit is an average, its lag anywhere (−1800 s on the ambient channel
#: for a re-mount through the plate's 174 s).
LAGS = (0.0, 40.0, 120.0, 300.0, 750.0, 1800.0)
#: Most slow-view points the parts are regressed on (longer views are averaged further: the
#: coupling acts on minutes, the octaves lost are seconds).
MAX_POINTS = 1 << 14
CAUSE = "coupling_change"


@dataclass(frozen=True)
class Part:
    """The coupling fitted on one part of the record: ĉ (m/s²/K), its se and the dof of
    that se (the jackknife's: the part's segments − 1)."""

    c: float
    se: float
    dof: float
    #: the lag (s) the part's coupling was refitted through (NaN: the whole record's)
    lag_s: float = math.nan
    #: the channel the part's coupling was refitted on ("": the test's)
    channel: str = ""
    #: the one lag's model error as a share of the coefficient (``_lead_gain``; 0: not
    #: made), already in ``se``
    model: float = 0.0


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
    #: the holes (s) of the channel's log within a grid step of ``time_s``: a change there
    #: is not seen where it happened, only somewhere across the hole
    holes: tuple[tuple[float, float], ...] = ()
    #: the fixed richer path's test where the one-lag scan fired (``cross_split``): the
    #: smaller of its two directions' z over its threshold (NaN: not run, or could not be)
    path_ratio: float = math.nan
    #: that path's lags (s) and channel (the one whose test is the smallest)
    path_lags: tuple[float, ...] = ()
    path_channel: str = ""

    @property
    def flagged(self) -> bool:
        """The one-lag scan fired: the parts' one-lag couplings differ."""
        return self.z >= self.threshold

    @property
    def changed(self) -> bool:
        """The change is said: the scan fired and the change stands against one fixed path
        of the richer form fitted on either part (a fixed coupling that is not one lag,
        under a temperature spectrum that changed, does not)."""
        return self.flagged and self.path_ratio >= 1.0

    @property
    def hedged(self) -> bool:
        """The scan fired but one fixed richer path fitted on one part predicts the other
        (or that test could not run): the record does not tell a changed coupling from a
        fixed one that is not one lag under a changed spectrum."""
        return self.flagged and not self.path_ratio >= 1.0

    @property
    def window_s(self) -> float:
        """How far from ``time_s`` a found step is the change's (one coarse grid step)."""
        return (GRID[1] - GRID[0]) * self.record_s

    def _numbers(self) -> str:
        b, a = self.before, self.after
        on = (f"on '{self.channel}' through {_lag(b, self.lag_s)} and {_lag(a, self.lag_s)}"
              if not ((b.channel and b.channel != self.channel)
                      or (a.channel and a.channel != self.channel)) else
              f"on '{b.channel or self.channel}' through {_lag(b, self.lag_s)} and "
              f"'{a.channel or self.channel}' through {_lag(a, self.lag_s)}")
        return (f"coefficient {b.c:.3g} ± {b.se:.2g} before, {a.c:.3g} ± {a.se:.2g} after, "
                f"m/s²/K {on}; z {self.z:.3g} against {self.threshold:.3g} over "
                f"{self.trials} change times")

    def _path(self) -> str:
        lags = ", ".join(f"{x:.3g}" for x in sorted(self.path_lags))
        return f"one fixed path through lags {lags} s of '{self.path_channel or self.channel}'"

    def line(self) -> str:
        """The one line said in the text, the JSON and the report: the change where it is
        said, else (the scan fired) the hedged reading that does not tell the two apart."""
        where = "".join(f"; the log of '{self.channel}' has a hole at {h0:.4g}–{h1:.4g} s, "
                        "where the change may lie" for h0, h1 in self.holes)
        if self.changed:
            return (f"the thermal coupling changed at about {self.time_s:.4g} s{where} "
                    f"({self._numbers()}; and against {self._path()} fitted on either "
                    f"part, z/threshold {self.path_ratio:.3g}): a single coupling does not "
                    "describe this record")
        # the same one-lag projection of a fixed path that is not one lag differs between
        # parts whose temperature spectra differ (review27b: two 300 s lags in series under
        # a cycle of 1200 s, then 7200 s, at z 7.9–8.1): not told from a change
        held = ("that test could not be made" if not math.isfinite(self.path_ratio) else
                f"z/threshold {self.path_ratio:.3g}, below 1")
        return (f"the one-lag thermal coupling differs before and after about "
                f"{self.time_s:.4g} s{where} ({self._numbers()}), but {self._path()} "
                f"fitted on one part predicts the other ({held}): the coupling changed "
                "there, or its path is not one lag and the temperature's spectrum changed; "
                "this record does not tell which")

    def finding(self) -> Finding:
        """Never claimed: a change of the coupling is no cause of its own; it says the
        record is not one coupling (the evidence is the line, or why it was not said)."""
        ev = (self.line() if self.flagged else
              f"one coupling before and after every change time tried: at the best, "
              f"{self.time_s:.4g} s, {self.before.c:.3g} ± {self.before.se:.2g} before and "
              f"{self.after.c:.3g} ± {self.after.se:.2g} after (m/s²/K), z {self.z:.3g} "
              f"below {self.threshold:.3g}")
        return Finding(CAUSE, False,
                       {"time_s": self.time_s, "coefficient_before": self.before.c,
                        "coefficient_after": self.after.c,
                        "changed": float(self.changed), "hedged": float(self.hedged),
                        **({"path_ratio": self.path_ratio}
                           if math.isfinite(self.path_ratio) else {})},
                       {"coefficient_before": [self.before.c - self.before.se,
                                               self.before.c + self.before.se],
                        "coefficient_after": [self.after.c - self.after.se,
                                              self.after.c + self.after.se]},
                       self.z, self.threshold, ev, channel=self.channel)


def _lag(p: Part, whole: float) -> str:
    return f"{(p.lag_s if math.isfinite(p.lag_s) else whole):.3g} s"


def _octave_view(n: NDArray, s2: NDArray, ms: NDArray, edf_ref: NDArray, n_ref: NDArray
                 ) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Rows of difference sums as Allan covariances on the octaves the axis's EDF covers:
    (n, cov (S, K, C, C), each row's EDF ``edf_ref`` of ``n_ref`` differences scaled to its
    count (``thermal_fit.cov_view``), the octaves' m as floats)."""
    K = min(n.shape[1], len(edf_ref))
    n, s2, msf = n[:, :K], s2[:, :K], ms[:K].astype(float)
    with np.errstate(invalid="ignore", divide="ignore"):
        cov = s2 / (NORM[2] * msf**2 * np.maximum(n, 1))[..., None, None]
        nu = np.asarray(edf_ref[:K], float) * n / np.asarray(n_ref[:K], float)
    return n, cov, nu, msf


def _coefficients(n: NDArray, s2: NDArray, ms: NDArray, rate: float, edf_ref: NDArray,
                  n_ref: NDArray, mt: float) -> tuple[NDArray, NDArray]:
    """``thermal_fit.tempco_from_cov`` of many difference sums at once: (ĉ, analytic se)
    per row of ``n`` (S, K) differences and ``s2`` (S, K, 2, 2) their Σ D Dᵀ of (axis,
    lagged temperature) at octaves ``ms``; the axis's EDF ``edf_ref`` of ``n_ref``
    differences scaled to each row's count (``thermal_fit.cov_view``); octaves τ ≥ ``mt``
    with an EDF of at least 3 (``thermal_fit._kept``). se ∞ where no octave is left."""
    n, cov, nu, msf = _octave_view(n, s2, ms, edf_ref, n_ref)
    K = len(msf)
    with np.errstate(invalid="ignore", divide="ignore"):
        vy, vu, cyu = cov[..., 0, 0], cov[..., 1, 1], cov[..., 0, 1]
        ok = ((n > 0) & np.isfinite(vy) & np.isfinite(vu) & (vu > 0) & (msf / rate >= mt)
              & np.isfinite(nu) & (nu >= 3))
        ck = np.where(ok, cyu / vu, 0.0)
        se_k = np.where(ok, np.sqrt(np.maximum(vy - cyu**2 / vu, 1e-300) / (vu * nu)), 1.0)
    w = np.where(ok, 1.0 / se_k**2, 0.0)
    sw = w.sum(axis=1)
    ws = w * se_k
    var = np.einsum("sk,kl,sl->s", ws, _rho(K), ws)
    with np.errstate(invalid="ignore", divide="ignore"):
        c = np.where(sw > 0, (w * ck).sum(axis=1) / sw, 0.0)
        se = np.where(sw > 0, np.sqrt(var) / sw, np.inf)
    return c, se


@dataclass(frozen=True)
class _Split:
    """One regressor's best split: z, its threshold, the split's fraction and the parts."""

    z: float
    threshold: float
    frac: float
    before: Part
    after: Part


def _stacked(segs: list[OctaveSums]) -> tuple[int, NDArray, NDArray, NDArray]:
    """The segments' sums stacked on the longest one's octaves: (K, its m, n (G, K),
    s2 (G, K, C, C)), a segment short of an octave counting no difference there."""
    K = max(len(x.ms) for x in segs)
    ms = next(x.ms for x in segs if len(x.ms) == K)
    padded = [x._padded(K) for x in segs]
    return (K, ms, np.array([p[0] for p in padded], dtype=float),
            np.array([p[1] for p in padded], dtype=float))


def _splits(segs: list[OctaveSums], rate: float, edf_ref: NDArray, n_ref: NDArray,
            mt: float, trials: int, grid: tuple[float, ...] = GRID) -> _Split | None:
    """z at every grid split from the segments' sums (``SEGMENTS``, each difference in the
    segment of its middle: ``thermal_fit.octave_sums_by_part``): each part's ĉ and the larger
    of its analytic se and its delete-a-segment jackknife se (the part's segments less
    one: dof segments − 1), the best split by z over its threshold (t at ``ALPHA`` over
    ``trials``, Satterthwaite's dof)."""
    if not segs:
        return None
    K, ms, n, s2 = _stacked(segs)
    G = len(segs)
    Pn = np.concatenate([np.zeros((1, K)), np.cumsum(n, axis=0)])
    Ps = np.concatenate([np.zeros((1, K, 2, 2)), np.cumsum(s2, axis=0)])
    best: _Split | None = None
    for frac in grid:
        k = round(frac * G)
        parts = []
        for lo, hi in ((0, k), (k, G)):
            wn, ws = Pn[hi] - Pn[lo], Ps[hi] - Ps[lo]
            # the whole part, then each of its segments left out in turn
            rn = np.concatenate([wn[None], wn[None] - n[lo:hi]])
            rs = np.concatenate([ws[None], ws[None] - s2[lo:hi]])
            c, se = _coefficients(rn, rs, ms, rate, edf_ref, n_ref, mt)
            g = hi - lo
            cj = c[1:]
            se_jk = (math.sqrt((g - 1) / g * float(np.sum((cj - cj.mean()) ** 2)))
                     if g > 1 and np.all(np.isfinite(cj)) and np.all(np.isfinite(se[1:]))
                     else math.inf)
            parts.append(Part(float(c[0]), max(float(se[0]), se_jk), max(g - 1.0, 1.0)))
        z, dof = _z(*parts)
        thr = t_two_sided(ALPHA / trials, max(dof, 1.0))
        if best is None or z / thr > best.z / best.threshold:
            best = _Split(z, thr, frac, parts[0], parts[1])
    return best


def _z(p: Part, q: Part) -> tuple[float, float]:
    """(|a − b|/√(se_a² + se_b²), its Satterthwaite degrees of freedom)."""
    v = p.se**2 + q.se**2
    if not (math.isfinite(v) and v > 0):
        return 0.0, 1.0
    dof = v**2 / (p.se**4 / p.dof + q.se**4 / q.dof)
    return abs(p.c - q.c) / math.sqrt(v), dof


def _names(thermal: ThermalFit, k: int) -> list[str]:
    """The temperature channels' names in column order: the thermal fit's ``others`` hold
    the other channels in column order, its own sits at ``channel_index``."""
    others = list(thermal.others)
    if len(others) != k - 1:
        return [thermal.channel if j == thermal.channel_index else f"channel {j}"
                for j in range(k)]
    others.insert(thermal.channel_index, thermal.channel)
    return others


def find_change(y: NDArray, temps: NDArray | None, thermal: ThermalFit | None,
                trans: list[cz.Candidate], rate_b: float,
                screen: ScreenLog | None = None) -> CouplingChange | None:
    """The test (module doc) on one axis's slow view ``y`` (``rate_b`` blocks per second)
    against every logged channel ``temps`` through every lag of ``LAGS`` and the thermal
    fit's own; ``trans``: the transients found on the axis (taken out of ``y`` first);
    ``screen``: the input screen's log (its holes in a channel's log are gaps). None where
    no coupling was tested or the record is too short for the parts."""
    if thermal is None or temps is None or len(y) < 2 * 256:
        return None
    n = len(y)
    record_s = n / rate_b
    found = [c for c in trans if c.passed and c.cause != "drift"]
    yc = np.asarray(y, dtype=float) - (tr.signal_of(found, n, rate_b) if found else 0.0)
    names = _names(thermal, temps.shape[1])
    f = 1 << max(0, math.ceil(math.log2(n / MAX_POINTS)))
    m = (n // f) * f
    rate = rate_b / f
    ys = yc[:m].reshape(-1, f).mean(axis=1)
    M = len(ys)
    edges = np.linspace(0, M, SEGMENTS + 1).astype(int)
    ref = allan2(ys, ys, rate)  # the axis's EDF (the same for every regressor)
    edf_ref = np.asarray(ref.edf, dtype=float)
    edf_ref = edf_ref[:, 0] if edf_ref.ndim == 2 else edf_ref
    n_ref = np.asarray(ref.n, dtype=float)
    axes = None
    regressors = [(j, float(L)) for j in range(temps.shape[1]) for L in LAGS
                  if L <= record_s / 8]
    if (thermal.channel_index, float(thermal.lag_s)) not in regressors:
        regressors.append((thermal.channel_index, float(thermal.lag_s)))
    trials = len(regressors) * len(GRID)
    best: tuple[_Split, int, float] | None = None
    by_channel: dict[int, tuple[_Split, float]] = {}
    chans = {j: np.asarray(temps[:m, j], dtype=float).reshape(-1, f).mean(axis=1)
             for j in {j for j, _ in regressors}}
    # each log's rounding floor on its own reading step (a coarse log's rounding reaches
    # longer τ than a 12-bit one's)
    floors = {j: rounding_floor_tau(T, rate, step=_step_of(screen, names[j]))
              for j, T in chans.items() if np.all(np.isfinite(T)) and np.ptp(T) > 0}
    for j, L in regressors:
        if j not in floors:
            continue
        T = chans[j]
        mt = min_tau_for(L, floors[j])
        if not math.isfinite(mt):
            continue
        u = lag_filter(T, L, rate)
        keep = hole_mask(M, [] if screen is None else screen.hole_blocks(names[j], rate),
                         L, rate)
        try:
            if keep is None:
                if axes is None:
                    axes = axes_differences(ys[:, None], edges)
                segs = lag_octave_sums(axes, u, L, rate)
            else:
                X = without_start(np.column_stack([ys, u]), L, rate)
                segs = octave_sums_by_part(X, edges, keep)
        except (DataError, FitError, ValueError):
            continue
        got = _splits(segs, rate, edf_ref, n_ref, mt, trials)
        if got is not None and (best is None
                                or got.z / got.threshold > best[0].z / best[0].threshold):
            best = (got, j, L)
        if got is not None and (j not in by_channel or got.z / got.threshold
                                > by_channel[j][0].z / by_channel[j][0].threshold):
            by_channel[j] = (got, L)
    if best is None:
        return None
    sp, j, L = best
    p, q, frac = sp.before, sp.after, sp.frac
    ratio, plags, pch = math.nan, tuple(path_lags(L, record_s)), names[j]
    if sp.z >= sp.threshold:
        # the change must stand against one fixed path of the richer form fitted on either
        # part (module doc), on every channel whose own scan shows it (each at its best lag
        # and time): a fixed coupling that is not one lag does not, whatever the
        # temperature's spectrum does between the parts; a channel two or three lags from
        # the path (the room, for a coupling through the plate) is read by three lags less
        # well than one nearer it, and a change is seen through both
        made: list[tuple[float, tuple[float, ...], str]] = []
        for jj, (spj, Lj) in sorted(by_channel.items()):
            if spj.z < spj.threshold:
                continue
            lj = sorted({x for c in path_sets(Lj, record_s) for x in c})
            keep = (None if screen is None else
                    hole_mask(M, screen.hole_blocks(names[jj], rate),
                              max(abs(x) for x in lj), rate))
            cross = cross_split(ys, chans[jj], Lj, spj.frac, edges, keep, rate, edf_ref,
                                n_ref, min_tau_for(Lj, floors[jj]), trials, record_s)
            if cross is not None and math.isfinite(cross[0]):
                made.append((cross[0], cross[4], names[jj]))
        if made:  # none made: NaN, the line hedged
            ratio, plags, pch = min(made, key=lambda x: x[0])
        # the time estimated after the test (the decision is the grid's), and each part's
        # coupling refitted on its own (its own lag) on the parts the time makes
        X = without_start(np.column_stack([ys, lag_filter(chans[j], L, rate)]), L, rate)
        keep = (None if screen is None else
                hole_mask(M, screen.hole_blocks(names[j], rate), L, rate))
        frac = _change_time(X, keep, rate, frac)
        timed = False
        # a step or an excursion edge the transient search found near the change is its
        # jump, timed to a second (the least squares in levels drifts with the axis's
        # random walk: 770 s late on two 4 h re-mounts, their steps then still claimed)
        near = [t for t in _event_times(found)
                if abs(t / record_s - sp.frac) <= 2 * (GRID[1] - GRID[0])]
        if near:
            frac = min(near, key=lambda t: abs(t / record_s - frac)) / record_s
            timed = True
        k = round(frac * n)
        # the parts less a guard either side of a time the levels estimated (a few hundred
        # seconds of the other coupling in a part biased its coefficient beyond its se)
        g = 0 if timed else round(GUARD * n)
        p, q = (_refit(yc[a:b], temps[a:b], names, rate_b, screen, a, fb)
                for (a, b), fb in (((0, max(1, k - g)), p), ((min(n - 1, k + g), n), q)))
        p, q = _shared_model(p, q)
    # a change inside a hole of the log (adv15: a re-mount at 5 576 s in a dropout at
    # 4 996–6 501 s was placed at 6 468 and 7 200 s) is seen only across the hole
    t_s, win = frac * record_s, (GRID[1] - GRID[0]) * record_s
    across = () if screen is None or sp.z < sp.threshold else tuple(
        (float(h0), float(h1)) for h0, h1 in screen.holes(names[j])
        if h1 - h0 >= 1.0 and h0 <= t_s + win and h1 >= t_s - win)
    return CouplingChange(t_s, p, q, sp.z, sp.threshold, names[j], L, trials, record_s,
                          holes=across, path_ratio=ratio, path_lags=plags,
                          path_channel=pch)


def _step_of(screen: ScreenLog | None, name: str) -> float | None:
    """The reading step (K) of log ``name`` as the input screen found it; None (the 12-bit
    DS18B20's) where there is no screen or no step."""
    grid = None if screen is None else screen.rounding_grid(name)
    return None if grid is None else grid[0]


def _refit(y: NDArray, temps: NDArray, names: list[str], rate_b: float,
           screen: ScreenLog | None, first: int, fallback: Part) -> Part:
    """The coupling of one part (a record of its own) as explain fits a whole record's
    (``fit_thermal_axes`` on every logged channel: its own channel and lag, the
    coefficient's interval with the lag's share): the numbers the line gives. A change of
    the coupling leaves the whole record's lag an average too (on a sign flip it moved
    174 s to 642 s), and the scan's channel is the one where the parts differ most, not the
    one that describes a part best (the ambient room through one lag for a coupling through
    the plate: a two-lag path read as one, its coefficient 1.2–1.7× the truth with a ±5 %
    interval). ``first``: the part's first block (its holes are the screen's, shifted);
    ``fallback``: the test's own fit of the part, kept where the refit cannot be made."""
    from avard.core.explain.thermal_fit import fit_thermal_axes

    holes = (None if screen is None else
             {i: screen.hole_blocks(nm, rate_b, first) for i, nm in enumerate(names)})
    try:
        fit = fit_thermal_axes(np.asarray(y, dtype=float)[:, None], temps, names, rate_b,
                               holes, grids=None if screen is None else
                               [screen.rounding_grid(nm) for nm in names])[0]
    except (DataError, FitError, ValueError):
        return fallback
    # the se no smaller than the part's own delete-a-segment jackknife at the refit's
    # channel and lag (the segments' spread, where the refit's analytic share assumes its
    # noise model)
    i = names.index(fit.channel) if fit.channel in names else 0
    se_jk = _part_jackknife(np.asarray(y, dtype=float), np.asarray(temps[:, i], dtype=float),
                            fit.lag_s, rate_b, None if holes is None else holes.get(i))
    se = max(fit.coef_se, se_jk) if math.isfinite(se_jk) else fit.coef_se
    # and the one lag's own model error: the logged sensor is not the die (its own lag puts
    # a lead in the path from the log to the die), and one lag reads such a path with its
    # lag short and its gain low by more than its se on a long record; the part's coupling
    # as the steady gain of a lag with a lead differs from the one-lag coefficient by about
    # that error (module doc, "The parts' intervals"; pooled over both parts by the caller)
    share = _lead_gain(np.asarray(y, dtype=float), np.asarray(temps[:, i], dtype=float),
                       fit.lag_s, rate_b, None if holes is None else holes.get(i))
    model = share if math.isfinite(share) else 0.0
    return Part(fit.coefficient, math.hypot(se, model * fit.coefficient), fallback.dof,
                fit.lag_s, fit.channel, model)


def _shared_model(p: Part, q: Part) -> tuple[Part, Part]:
    """Both parts with their one-lag model errors (shares of each coefficient) pooled, the
    root mean square of the two: the error is the path's from the log to the die (the
    logged sensor's own lag, the same sensor before and after), each part's estimate of it
    a noisy one (the larger of the two over-covered the short records, each part's own
    under-covered the long ones)."""
    if p.channel != q.channel or not (p.model > 0 or q.model > 0):
        return p, q
    share = math.sqrt((p.model**2 + q.model**2) / 2)

    def widened(x: Part) -> Part:
        stat = math.sqrt(max(x.se**2 - (x.model * x.c) ** 2, 0.0))
        return replace(x, se=math.hypot(stat, share * x.c), model=share)

    return widened(p), widened(q)


#: The trial lags of the lead-lag refit (``_lead_gain``), as multiples of the one-lag fit's
#: lag: one lag reads a lag with a lead with its lag short, never long by much.
LEAD_LAGS = (0.8, 0.9, 1.0, 1.05, 1.1, 1.15, 1.2, 1.3, 1.45, 1.6)


def _part_view(y: NDArray, T: NDArray, rate_b: float, floor_lag_s: float
               ) -> tuple[NDArray, NDArray, float, int, float] | None:
    """One part averaged to at most ``MAX_POINTS`` block means: (the axis's, the
    temperature's, their rate, the averaging factor, the shortest τ the regression may use
    above the readings' rounding floor for a lag of ``floor_lag_s``); None where the part is
    under two 256-point halves, its temperature flat or not finite, or no τ is usable."""
    n = len(y)
    f = 1 << max(0, math.ceil(math.log2(max(1, n) / MAX_POINTS)))
    m = (n // f) * f
    if m // f < 2 * 256:
        return None
    rate = rate_b / f
    ys = y[:m].reshape(-1, f).mean(axis=1)
    Ts = T[:m].reshape(-1, f).mean(axis=1)
    if not (np.all(np.isfinite(Ts)) and np.ptp(Ts) > 0):
        return None
    mt = min_tau_for(floor_lag_s, rounding_floor_tau(Ts, rate))
    return (ys, Ts, rate, f, mt) if math.isfinite(mt) else None


def _lead_gain(y: NDArray, T: NDArray, lag_s: float, rate_b: float,
               holes: list[tuple[int, int]] | None) -> float:
    """The one lag's model error on one part, as a share of its coefficient: the one-lag
    coefficient through ``lag_s`` less the steady (zero-frequency) gain of a first-order
    lag with a lead, (a + s·jω)/(1 + L·jω) (the axis regressed on u_L and du_L/dt at once,
    ``_multi``, at each lag of ``LEAD_LAGS`` × ``lag_s``; a at the lag of least deviance
    Σ ν ln r over the octaves), with the difference's own noise taken out: d² less its
    delete-a-segment jackknife variance (``PART_SEGMENTS``), never below 0. A difference
    within its noise is no model error (the lead fit's ridge between a and s is noisy on a
    short part, and that noise already sits in the part's se). NaN where it cannot be made
    (a lag ≤ 0: the lead-lag filter of a negative lag is already a lead)."""
    view = (_part_view(y, T, rate_b, 0.0) if math.isfinite(lag_s) and lag_s > 0 else None)
    if view is None:
        return math.nan
    ys, Ts, rate, f, mt = view
    M = len(ys)
    keep = hole_mask(M, [(a // f, b // f) for a, b in holes or []], lag_s * LEAD_LAGS[-1],
                     rate)
    edges = np.linspace(0, M, PART_SEGMENTS + 1).astype(int)
    try:
        ref = allan2(ys, ys, rate)
    except (DataError, FitError, ValueError):
        return math.nan
    edf_ref = np.asarray(ref.edf, dtype=float)
    edf_ref = edf_ref[:, 0] if edf_ref.ndim == 2 else edf_ref
    n_ref = np.asarray(ref.n, dtype=float)
    best: tuple[float, NDArray] | None = None
    one: NDArray | None = None
    for x in LEAD_LAGS:
        L = lag_s * x
        u = lag_filter(Ts, L, rate)
        try:
            X = without_start(np.column_stack([ys, u, np.gradient(u) * rate]), L, rate)
            segs = octave_sums_by_part(X, edges, keep)
        except (DataError, FitError, ValueError):
            continue
        _K, ms, nn, s2 = _stacked(segs)
        # the whole part, then each of its segments left out in turn
        wn, ws = nn.sum(axis=0), s2.sum(axis=0)
        rn = np.concatenate([wn[None], wn[None] - nn])
        rs = np.concatenate([ws[None], ws[None] - s2])
        if x == 1.0:
            one, _ = _coefficients(rn, rs[..., :2, :2], ms, rate, edf_ref, n_ref, mt)
        beta, _ = _multi(rn, rs, ms, rate, edf_ref, n_ref, mt)
        if not np.all(np.isfinite(beta)):
            continue
        _n, cov, nu, msf = _octave_view(rn[:1], rs[:1], ms, edf_ref, n_ref)
        b, C = beta[0], cov[0]
        r = (C[:, 0, 0] - 2.0 * C[:, 0, 1:] @ b
             + np.einsum("i,kij,j->k", b, C[:, 1:, 1:], b))
        ok = (msf / rate >= mt) & np.isfinite(nu[0]) & (nu[0] >= 3) & (r > 0)
        if not np.any(ok):
            continue
        dev = float(np.sum(nu[0][ok] * np.log(r[ok])))
        if best is None or dev < best[0]:
            best = (dev, beta[:, 0])
    if best is None or one is None or not np.all(np.isfinite(one)) or one[0] == 0:
        return math.nan
    d = one - best[1]
    g = len(d) - 1
    var = (g - 1) / g * float(np.sum((d[1:] - d[1:].mean()) ** 2))
    return math.sqrt(max(float(d[0]) ** 2 - var, 0.0)) / abs(float(one[0]))


#: Segments of a part for its coefficient's jackknife (``_part_jackknife``).
PART_SEGMENTS = 10


def _part_jackknife(y: NDArray, T: NDArray, lag_s: float, rate_b: float,
                    holes: list[tuple[int, int]] | None) -> float:
    """The delete-a-segment jackknife se of one part's one-lag coefficient through
    ``lag_s`` (``PART_SEGMENTS`` segments, the part's own Allan-covariance regression as
    the scan makes it); NaN where it cannot be made."""
    view = _part_view(y, T, rate_b, lag_s) if np.all(np.isfinite(lag_s)) else None
    if view is None:
        return math.nan
    ys, Ts, rate, f, mt = view
    M = len(ys)
    keep = hole_mask(M, [(a // f, b // f) for a, b in holes or []], lag_s, rate)
    try:
        X = without_start(np.column_stack([ys, lag_filter(Ts, lag_s, rate)]), lag_s, rate)
        segs = octave_sums_by_part(X, np.linspace(0, M, PART_SEGMENTS + 1).astype(int), keep)
        ref = allan2(ys, ys, rate)
    except (DataError, FitError, ValueError):
        return math.nan
    edf_ref = np.asarray(ref.edf, dtype=float)
    edf_ref = edf_ref[:, 0] if edf_ref.ndim == 2 else edf_ref
    _K, ms, nn, s2 = _stacked(segs)
    wn, ws = nn.sum(axis=0), s2.sum(axis=0)
    c, _ = _coefficients(wn[None] - nn, ws[None] - s2, ms, rate, edf_ref,
                         np.asarray(ref.n, dtype=float), mt)
    g = len(segs)
    if not np.all(np.isfinite(c)):
        return math.nan
    return math.sqrt((g - 1) / g * float(np.sum((c - c.mean()) ** 2)))


#: The share of the record left out of each part either side of a change time estimated
#: in levels (``_change_time``), not by a step the search found.
GUARD = 0.02


#: The block (s) whose means' differences estimate the change time (``_change_time``).
TIME_BLOCK_S = 60.0


def _change_time(X: NDArray, keep: NDArray[np.bool_] | None, rate: float,
                 frac: float) -> float:
    """The change time (fraction of the record) within a grid step of the grid's best
    ``frac``: the split that leaves the least residual when the axis's ``TIME_BLOCK_S``
    means are regressed on the lagged temperature's, with an offset and a coefficient of
    their own on each side (so a jump at the split is free). Levels, not differences: the
    differences of minute means of a logged channel are mostly its 0.0625 K rounding,
    which pulled their coefficient to a third of the truth and the split 450 s late; the
    lagged temperature's swing in levels is many steps. Least squares, an estimate (the z
    scan's best time leans towards the side whose part is cleaner)."""
    k = max(1, round(TIME_BLOCK_S * rate))
    m = len(X) // k
    if m < 16:
        return frac
    B = X[:m * k].reshape(m, k, 2).mean(axis=1)
    ok = np.ones(m, dtype=bool)
    if keep is not None:
        ok = np.asarray(np.asarray(keep[:m * k]).reshape(m, k).all(axis=1), dtype=bool)
    w = ok.astype(float)
    yv, uv = np.where(ok, B[:, 0], 0.0), np.where(ok, B[:, 1], 0.0)
    S = [np.concatenate([[0.0], np.cumsum(v)])
         for v in (w, uv, yv, uv * uv, uv * yv, yv * yv)]

    def rss(lo: NDArray, hi: NDArray) -> NDArray:
        n_, su, sy, suu, suy, syy = (c[hi] - c[lo] for c in S)
        with np.errstate(invalid="ignore", divide="ignore"):
            vu = suu - su**2 / n_
            cuy = suy - su * sy / n_
            r = syy - sy**2 / n_ - np.where(vu > 0, cuy**2 / vu, 0.0)
        return np.asarray(np.where(n_ > 2, r, np.inf))

    step = GRID[1] - GRID[0]
    j = np.arange(max(2, int((frac - step) * m)), min(m - 2, int((frac + step) * m)) + 1)
    if len(j) == 0:
        return frac
    total = rss(np.zeros_like(j), j) + rss(j, np.full_like(j, m))
    return float(j[int(np.argmin(total))] / m)


def _times(c: cz.Candidate) -> list[float]:
    """The times (s) a step or an excursion jumps at ([] for other causes)."""
    if c.cause == "bias_step":
        return [float(c.params.get("time_s", math.nan))]
    if c.cause == "excursion":
        return [float(c.params["start_s"]), float(c.params["end_s"])]
    return []


def _event_times(cands: list[cz.Candidate]) -> list[float]:
    return [t for c in cands if c.passed for t in _times(c) if math.isfinite(t)]


def _near(c: cz.Candidate, ch: CouplingChange) -> bool:
    """Whether a step or excursion edge of ``c`` lies within the change's window."""
    return any(abs(t - ch.time_s) <= ch.window_s for t in _times(c))


def check(y: NDArray, temps: NDArray | None, thermal: ThermalFit | None,
          trans: list[cz.Candidate], missed: list[cz.Candidate], work: NDArray,
          rate_b: float, noise_of: tr.NoiseOf, screen: ScreenLog | None = None
          ) -> tuple[CouplingChange | None, list[cz.Candidate], list[cz.Candidate]]:
    """(the test's outcome, claimed, not claimed transients): ``find_change``, then where
    the coupling changed, a step (or an excursion edge) at the change not claimed and the
    other transients refitted and tested again without it in ``work`` (the axis the
    compound search ran on, ``noise_of`` its noise), as ``engine.compound._compound`` does for a
    transient taken out. The steps taken are kept in the outcome (``taken``) for
    ``mark``."""
    change = find_change(y, temps, thermal, trans, rate_b, screen)
    if change is None or not change.flagged or not any(_near(c, change) for c in trans):
        return change, trans, missed
    taken = tuple(c for c in trans if _near(c, change))
    # where the change is hedged the jump may still be the coupling's: not claimed either
    # (the record does not tell a step from the change there)
    why = ("the thermal coupling changed" if change.changed else
           "the one-lag thermal coupling differs before and after (a change of the "
           "coupling, or a path that is not one lag under a changed spectrum)")
    out = [replace(c, passed=False, intervals={}, evidence=c.evidence + (
        f"; not claimed: at the time {why} (about {change.time_s:.4g} s), where the axis "
        "jumps by the change of the coupling times the lagged temperature if it changed: "
        "model-dependent, its interval withheld"))
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
    if change.flagged:
        for f in findings:
            if f.cause == "temperature" and change.hedged:
                # the hedged reading is said with the coupling it qualifies (the text prints
                # a claimed finding's evidence; the JSON has the channel's caveats too)
                f.evidence = f"{f.evidence}; {change.line()}"
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
    f = next((f for f in findings if f.cause == CAUSE and f.params.get("changed")), None)
    return None if f is None else f.evidence


def hedged_line(findings: list[Finding]) -> str | None:
    """The hedged line of a channel whose one-lag coupling differs between the parts where
    one fixed richer path describes both (None elsewhere), from its findings."""
    f = next((f for f in findings if f.cause == CAUSE and f.params.get("hedged")), None)
    return None if f is None else f.evidence


# --------------------------------------------------------------------------------------------
# the change must survive the paths a fixed coupling that is not one lag would take


def _multi(n: NDArray, s2: NDArray, ms: NDArray, rate: float, edf_ref: NDArray,
           n_ref: NDArray, mt: float) -> tuple[NDArray, NDArray]:
    """The Allan-covariance regression of the axis on p regressors at once, per row of
    ``n`` (S, K) and ``s2`` (S, K, 1 + p, 1 + p): β (S, p) and its analytic covariance
    (S, p, p), each octave weighted by its EDF over the axis's residual of the first
    regressor alone (``_coefficients``' weights), octaves τ ≥ ``mt`` with an EDF ≥ 3."""
    n, cov, nu, msf = _octave_view(n, s2, ms, edf_ref, n_ref)
    p = cov.shape[-1] - 1
    with np.errstate(invalid="ignore", divide="ignore"):
        vy, vu, cyu = cov[..., 0, 0], cov[..., 1, 1], cov[..., 0, 1]
        diag = np.all(np.diagonal(cov[..., 1:, 1:], axis1=-2, axis2=-1) > 0, axis=-1)
        ok = ((n > 0) & np.all(np.isfinite(cov.reshape(*cov.shape[:2], -1)), axis=-1) & diag
              & (msf / rate >= mt) & np.isfinite(nu) & (nu >= 3))
        resid = np.maximum(vy - cyu**2 / vu, 1e-300)
        w = np.where(ok, nu / resid, 0.0)
    cz_ = np.where(ok[..., None, None], cov, 0.0)
    A = np.einsum("sk,skij->sij", w, cz_[..., 1:, 1:])
    b = np.einsum("sk,ski->si", w, cz_[..., 1:, 0])
    beta = np.full((len(n), p), np.nan)
    V = np.full((len(n), p, p), np.nan)
    for s in range(len(n)):
        try:
            Ai = np.linalg.inv(A[s])
        except np.linalg.LinAlgError:
            continue
        if np.all(np.isfinite(Ai)):
            beta[s] = Ai @ b[s]
            V[s] = Ai
    return beta, V


def _path_regressors(T: NDArray, L: float, rate: float, record_s: float) -> list[NDArray]:
    """The richer fixed path's regressors on one channel ``T``: the channel through each of
    ``path_lags`` and the rate of the first (a sum of three first-order lags and a dT/dt
    term: two lags in series, a lag with a lead, a one-lag + dT/dt path over the band the
    record drives, as one fixed response); the first is the one-lag regressor itself."""
    R = [lag_filter(T, x, rate) for x in path_lags(L, record_s)]
    # and the rate of the lagged temperature: a lead (a one-lag + dT/dt path with τ_r > 0)
    # is no sum of lags (false changes on 5 of 20 such 12 h axes without it)
    return [*R, np.gradient(R[0]) * rate]


def path_lags(L: float, record_s: float) -> list[float]:
    """The lags of the richer fixed path: ``L`` first, then the next lag of ``LAGS`` (up to
    an eighth of the record) below and above it."""
    grid = [float(x) for x in LAGS if x <= record_s / 8 and x != L]
    return [float(L), *[x for x in grid if x < L][-1:], *[x for x in grid if x > L][:1]]


def _resid_sums(n: NDArray, s2: NDArray, beta: NDArray) -> NDArray:
    """Σ D Dᵀ of (y − Rβ, u) from those of (y, R…) with u = R[0] (rows of ``s2`` (S, K, 1 +
    p, 1 + p)); β (p,) or one per row (S, p)."""
    b = np.broadcast_to(np.asarray(beta, float), (s2.shape[0], s2.shape[-1] - 1))
    r = np.empty((*s2.shape[:2], 2, 2))
    r[..., 0, 0] = (s2[..., 0, 0] - 2.0 * np.einsum("ski,si->sk", s2[..., 0, 1:], b)
                    + np.einsum("si,skij,sj->sk", b, s2[..., 1:, 1:], b))
    r[..., 0, 1] = r[..., 1, 0] = s2[..., 0, 1] - np.einsum("ski,si->sk", s2[..., 1, 1:], b)
    r[..., 1, 1] = s2[..., 1, 1]
    return r


def _cross(segs: list[OctaveSums], frac: float, rate: float, edf_ref: NDArray,
           n_ref: NDArray, mt: float, trials: int) -> tuple[float, Part, Part, float]:
    """Whether the richer path fitted on one part predicts the other (module doc): for each
    direction (fit before, test after; fit after, test before) the one-lag coefficient κ of
    the tested part's axis less the fitted part's path, its se the larger of the analytic
    one and the jackknife over both parts' segments (the fit's replicates and the test's),
    z = |κ|/se against the scan's threshold (t at ``ALPHA`` over ``trials``, Satterthwaite's
    dof). (the smaller z over its threshold of the two directions, the parts' κ, dof)."""
    _K, ms, n, s2 = _stacked(segs)
    return _cross_sums(ms, n, s2, frac, rate, edf_ref, n_ref, mt)


def _cross_sums(ms: NDArray, n: NDArray, s2: NDArray, frac: float, rate: float,
                edf_ref: NDArray, n_ref: NDArray, mt: float
                ) -> tuple[float, Part, Part, float]:
    """``_cross`` on the segments' stacked sums (n (G, K), s2 (G, K, C, C))."""
    G = len(n)
    k = round(frac * G)
    rows = {}
    for lo, hi in ((0, k), (k, G)):
        wn, ws = n[lo:hi].sum(axis=0), s2[lo:hi].sum(axis=0)
        rows[lo] = (np.concatenate([wn[None], wn[None] - n[lo:hi]]),
                    np.concatenate([ws[None], ws[None] - s2[lo:hi]]), hi - lo)
    out: list[tuple[float, Part, float]] = []
    for fit, test in ((0, k), (k, 0)):
        fn, fs, gf = rows[fit]
        tn, ts, gt = rows[test]
        beta, _ = _multi(fn, fs, ms, rate, edf_ref, n_ref, mt)
        if not np.all(np.isfinite(beta)) or gf < 2 or gt < 2:
            return 0.0, Part(0.0, math.inf, 1.0), Part(0.0, math.inf, 1.0), 1.0
        # the tested part with the fit's replicates, then the tested part's own replicates
        n_rows = np.concatenate([np.repeat(tn[:1], gf + 1, axis=0), tn[1:]])
        s_rows = np.concatenate([np.repeat(ts[:1], gf + 1, axis=0), ts[1:]])
        b_rows = np.concatenate([beta, np.repeat(beta[:1], gt, axis=0)])
        c, se = _coefficients(n_rows, _resid_sums(n_rows, s_rows, b_rows), ms, rate,
                              edf_ref, n_ref, mt)
        cf, ct = c[1:gf + 1], c[gf + 1:]
        jf = (gf - 1) / gf * float(np.sum((cf - cf.mean()) ** 2))
        jt = (gt - 1) / gt * float(np.sum((ct - ct.mean()) ** 2))
        s = max(float(se[0]), math.sqrt(jf + jt))
        if not (math.isfinite(s) and s > 0):
            return 0.0, Part(0.0, math.inf, 1.0), Part(0.0, math.inf, 1.0), 1.0
        dof = ((jf + jt) ** 2 / (jf**2 / (gf - 1) + jt**2 / (gt - 1))
               if jf + jt > 0 else float(G - 2))
        thr = t_two_sided(ALPHA / len(GRID), max(dof, 1.0))
        out.append((abs(float(c[0])) / s / thr, Part(float(c[0]), s, dof), dof))
    (ra, pa, da), (rb, pb, db) = out
    # pa: the part after less the path fitted before; pb: the part before less the after's
    return min(ra, rb), pb, pa, min(da, db)


def path_sets(L: float, record_s: float) -> list[list[float]]:
    """The candidate lag sets of the richer fixed path, ``L`` first in each: ``path_lags``
    (``L`` and its neighbours in ``LAGS``) and ``L`` beside every two neighbouring lags of
    ``LAGS`` (up to an eighth of the record, ``L`` left out): three lags each, as many as
    ``path_lags`` gives. The scan's lag is the one-lag projection's, not
    where the path lives: a room channel two lags and a rate term (τ_r < 0) from the die
    was read through a lag of 0 s, and lags of 0 and 40 s (its neighbours) could not hold
    a path of several hundred seconds (a false "changed" at z/threshold 2.5–2.7)."""
    grid = [float(x) for x in LAGS if x <= record_s / 8 and x != L]
    out = [path_lags(L, record_s)]
    for i in range(len(grid) - 1):
        c = [float(L), *grid[i:i + 2]]
        if all(sorted(c) != sorted(o) for o in out):
            out.append(c)
    return out


def cross_split(ys: NDArray, T: NDArray, L: float, frac: float, edges: NDArray,
                keep: NDArray[np.bool_] | None, rate: float, edf_ref: NDArray,
                n_ref: NDArray, mt: float, trials: int, record_s: float
                ) -> tuple[float, Part, Part, float, tuple[float, ...]] | None:
    """``_cross`` with the richer path's regressors of channel ``T``: the lag set of
    ``path_sets`` that describes the whole record best (least deviance Σ ν ln r over the
    octaves of its Allan-covariance regression, ``_multi``; ``path_lags`` unless another set
    is better by more than a χ²₁ at ``ALPHA`` over the sets), its lags and the rate of u_L
    (``_path_regressors``), each set with its own start-up settling taken out
    (``without_start`` at its longest lag: at the longest of all sets, 1800 s on a 4 h
    record, the settling shape took part of a re-mount's change with it). The set is chosen
    on the whole record, so neither part's prediction is fitted to the part it is tested
    on. (``_cross``'s outcome, the lags)."""
    cands = path_sets(L, record_s)
    cols = {x: lag_filter(T, x, rate) for x in {x for c in cands for x in c}}
    rate_col = np.gradient(cols[float(L)]) * rate
    fits: list[tuple[float, list[float], tuple[NDArray, NDArray, NDArray]]] = []
    for c in cands:
        X = without_start(np.column_stack([ys, *[cols[x] for x in c], rate_col]),
                          max(abs(x) for x in c), rate)
        try:
            segs = octave_sums_by_part(X, edges, keep)
        except (DataError, FitError, ValueError):
            continue
        _K, ms, n, s2 = _stacked(segs)
        wn, ws = n.sum(axis=0)[None], s2.sum(axis=0)[None]
        beta, _ = _multi(wn, ws, ms, rate, edf_ref, n_ref, mt)
        if not np.all(np.isfinite(beta)):
            continue
        _n, cov, nu, msf = _octave_view(wn, ws, ms, edf_ref, n_ref)
        b, C = beta[0], cov[0]
        r = (C[:, 0, 0] - 2.0 * C[:, 0, 1:] @ b
             + np.einsum("i,kij,j->k", b, C[:, 1:, 1:], b))
        ok = (msf / rate >= mt) & np.isfinite(nu[0]) & (nu[0] >= 3) & (r > 0)
        if np.any(ok):
            fits.append((float(np.sum(nu[0][ok] * np.log(r[ok]))), c, (ms, n, s2)))
    if not fits:
        return None
    best = min(fits, key=lambda x: x[0])
    # the scan's own neighbourhood unless another set describes the whole record better by
    # more than a χ²₁ at the test's level over the sets (a re-mount's whole record is two
    # couplings, which some set reads a few units better by chance; a path the
    # neighbourhood cannot hold is hundreds or thousands of units worse)
    margin = t_two_sided(ALPHA / len(cands), 1e6) ** 2
    if fits[0][1] is cands[0] and fits[0][0] - best[0] <= margin:
        best = fits[0]
    _d, c, (ms, n, s2) = best
    out = _cross_sums(ms, n, s2, frac, rate, edf_ref, n_ref, mt)
    return (*out, tuple(c))

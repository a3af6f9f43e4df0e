"""Which logged temperature drives an axis, through what first-order lag, with what
coefficient; and the temperature-compensated Allan variance. For ``avard explain`` (and
``avard analyze --temperature``).

Physics: heat reaches the sensor die from the logged channel (plate, ambient or the chip's own)
through a thermal mass, a first-order lag: dT_s/dt = (T − T_s)/τ_L. The output moves by
c·T_s (bias and sensitivity tempco, m/s²/K). Both act on seconds to hours, so the fit runs on
the slow view (block means of ≈ 1 s; ``explain.SlowView``).

Estimator. For a trial lag τ_L the logged channel is passed through the lag (exact
discretisation for a linearly interpolated input, ``thermal.lag_coefficients``) and the
streaming Allan accumulator (``streaming.StreamingAllan``, analyze's estimator at its octave τ)
gives the Allan covariance of axis y and lagged temperature u. At each τ_k the regression of
Allan differences of y on those of u is c_k = Cov_A(y, u)/AVAR(u), with variance
r_k/(AVAR(u)·ν_k) (r_k the residual AVAR, ν_k the EDF of the axis at τ_k: the number of
independent differences). Differencing removes the offset and whitens flicker and random walk,
so the regression is valid under the axis's own noise. The c_k are combined with inverse-
variance weights; neighbouring octaves share data (correlation ≈ 0.5, fit.py), which the
combined variance includes (ρ_kl = 0.5^|k−l|): this analytic z picks each channel's lag
(maximum of z² over a log grid refined around the best point), one covariance for every lag
and channel compared. Which channel drives is decided by each channel's held-out likelihood
through its own lag (``_choose_channel``, ``holdout.channel_heldout``), not by this z: the
room seen through the plate's long lag is a second description of a coupling through the
plate, and its smoother regressor took the larger z. At the chosen lag the test's analytic se is the
regressor's own (``octave_spectra``, ``coupling_test``: the octaves see the same slow noise,
near one number for a trend under red noise), its threshold the t of the degrees of freedom
that se rests on. Under red noise the EDF model is too optimistic (the noise differences are
not independent across a slow regressor), so the reported standard error of ĉ is the larger
of that se and a delete-a-group jackknife over 10 contiguous parts
(``jackknife_tempco``: its parts can be shorter than the noise's correlation at the
regressor's period), z = ĉ/se, and the lag's 68 % interval is the lag's own delete-a-group
jackknife (``lag_interval``); the parts hold the Allan differences whose middle they hold,
at every octave (``octave_sums_by_part``). Test: z ≥ ``Z_TEMPERATURE`` (5: the lag and
channel search look at ≈ 50 correlated trials), or the t of the se's degrees of freedom at
the search's share of the axis's false-alarm budget where that is more
(``CouplingTest.threshold``). The test's z is its own combination of the octaves, the one
of least variance under the regressor's octave covariance with non-negative weights
(``least_variance_weights``; its jackknife with those weights fixed): where a day's cycle
drives the slow octaves, the inverse-variance weights' shared red noise there set the
se and its degrees of freedom (so the threshold). ĉ and its interval keep the
inverse-variance weights.

Compensated AVAR: AVAR(y − ĉu) = AVAR_y − 2ĉ·Cov_A + ĉ²·AVAR_u from the same covariance, as a
ratio to AVAR_y applied to analyze's full-rate curve (below the slow view's first τ the
thermal share falls as τ³: a smooth signal's AVAR ∝ τ², white noise's ∝ 1/τ).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
from avard.core.allan import kernels
from avard.core.allan.beta import t_two_sided
from avard.core.allan.deviations import (
    DEFAULT_OVERLAP,
    NORM,
    DifferenceSums,
    gram,
    grid_sums_by_part,
    segment_phase,
)
from avard.core.allan.streaming import StreamingAllan
from avard.core.explain import alarm
from avard.core.explain.causes import noise_psd
from avard.core.io.screen import is_coarse
from avard.core.sim.thermal import lag_coefficients
from numpy.typing import NDArray

if TYPE_CHECKING:
    from avard.core.explain.thermal_paths import PathFit
    from avard.core.explain.thermal_paths.columns import Column

__all__ = [
    "Z_TEMPERATURE",
    "ThermalFit",
    "allan2",
    "coefficient_se",
    "compensated_avar",
    "fit_thermal",
    "fit_thermal_axes",
    "lag_filter",
    "min_detectable_tempco",
    "signal_avar_on",
    "tempco_from_cov",
    "with_paths",
    "without_start",
]

Z_TEMPERATURE = 5.0
#: The lag and channel trials the coupling search looks at, about (``alarm``'s budget).
SCAN_TRIALS = 50
#: Contiguous parts of the record for the jackknife standard error of the coefficient.
JACKKNIFE_GROUPS = 10
#: Most block means the lag scan runs on.
SCAN_POINTS = 1 << 15
#: DS18B20 conversion time (s): the temperature says nothing faster than this.
DS18B20_CONVERSION_S = 0.75
#: The lag filter's start state (``ThermalFit.signal``) is fitted over the record's first this
#: many lags: e^(−t/τ_L) is below 1e-8 at the end, and a random walk moves the level little.
START_FIT_LAGS = 20.0
#: The standard uncertainty (s) of when a logged temperature was true, which the lag's
#: interval carries beside its jackknife (``lag_interval``): a DS18B20 reading is the
#: temperature at some moment of its conversion, logged at the conversion's end or later,
#: and the record says not which; the lag is known to no better than half that window. It is
#: the same on every part of the record, so the parts' spread never shows it, and where the
#: record fixes the lag to a second or so it is as large as that spread.
READ_TIME_S = DS18B20_CONVERSION_S / 2
#: octave correlation of neighbouring AVAR estimates (fit.py: ≈ 0.5 for white noise)
_RHO = 0.5


def lag_filter(T: NDArray, lag_s: float, rate_hz: float) -> NDArray[np.float64]:
    """T seen through a first-order lag of time constant ``lag_s`` (s), starting in steady
    state at T[0]; ``lag_s`` = 0 returns T.

    A negative ``lag_s`` is the logged sensor lagging the die: with a = |lag_s|, the lead-lag
    (1 + 2as)/(1 + as) = 2 − 1/(1 + as), i.e. 2T − lag(T, a): at the slow frequencies where
    the coupling acts it is T + a·dT/dt (the die a ahead of the log, continuous through 0
    with the lag, T − a·dT/dt), and its gain at high frequencies stays 2 where the pure
    inverse T + a·dT/dt would amplify the 0.0625 K rounding of the readings without bound
    (which buried a true −90 s lag under its own noise: found at +12 s). It is the model of a
    sensor lag 2a against a die lag a; other ratios differ from it at periods near a."""
    T = np.asarray(T, dtype=float)
    if lag_s < 0:
        return np.asarray(2.0 * T - lag_filter(T, -lag_s, rate_hz), dtype=float)
    if lag_s == 0:
        return T.copy()
    b, a = lag_coefficients(lag_s, 1.0 / rate_hz)
    c = kernels.compiled()
    if c is None or len(T) == 0:  # the general path
        from scipy import signal as sps

        zi = sps.lfilter_zi(b, a) * T[0]
        out, _ = sps.lfilter(b, a, T, zi=zi)
        return np.asarray(out, dtype=float)
    # the compiled loop (lfilter's operations, bit for bit: tests/core/test_kernels.py), from
    # the steady state lfilter_zi solves for, by the same solve: importing scipy.signal for
    # it cost explain more CPU than all its filtering
    zi = np.linalg.solve(np.eye(1) - np.array([[-a[1]]]), np.array([b[1] - a[1] * b[0]]))
    y = np.empty(len(T))
    c.first_order(np.ascontiguousarray(T), b[0], b[1], a[1], float(zi[0] * T[0]), y)
    return y


def derounded(T: NDArray, grid: tuple[float, float] | None = None) -> NDArray[np.float64]:
    """The logged channel ``T`` (slow view, readings interpolated between their times) with
    its readings' rounding smoothed out: where the readings dwell on one 0.0625 K step (a
    run of equal values), the temperature passed the threshold between two neighbouring
    runs' levels half way between them, so those crossings, (time, mid-level), are knots of
    a straight-line interpolation, with the turning points' runs at their middles and the
    first and last readings as they are; ``T`` itself where it holds fewer than two runs.
    NaN stays NaN.

    ``grid``: the readings' (step, origin), default the one in force (``reading_grid``). On a
    step coarser than the 12-bit one the straight lines miss the turns by up to half a
    step for as long as the readings dwell there (through a lag, a misfit at τ of the
    dwell), so the readings' mid-level crossings carry a spline clipped to each reading's
    cell instead (``thermal_paths.columns.crossing_reconstruction``), and before the first
    crossing and after the last (``_crossing_ends``) the spline's slope goes on within the
    reading's cell: held at the first knot's mid-level, the record's first dwell sat up to
    half a coarse step off for minutes, a start the lag filter carries into the τ of the
    lag (through a 300 s lag, 3.5× the error ADEV at τ 100–800 s at 0.125 K). A gap (NaN)
    is bridged on the samples' own times, as the straight lines are: the spline is built on
    the whole index with the gap's values a straight line between its neighbours (not on
    the finite samples squeezed together, which ran it across the gap as if no time had
    passed), and the gap stays NaN."""
    T = np.asarray(T, dtype=float)
    q, origin = reading_step() if grid is None else grid
    if is_coarse(q):
        from avard.core.explain.thermal_paths.columns import crossing_reconstruction

        out = T.copy()
        ok = np.flatnonzero(np.isfinite(T))
        if len(ok) >= 4:
            # on the kept samples' own times: the gap bridged in a straight line (its values
            # are off the grid, so the reconstruction does not clip them to a cell)
            v = np.interp(np.arange(ok[0], ok[-1] + 1), ok, T[ok]) - origin
            r = _crossing_ends(v, crossing_reconstruction(v, q), q) + origin
            out[ok] = r[ok - ok[0]]
        return out
    out = T.copy()
    ok = np.flatnonzero(np.isfinite(T))
    if len(ok) < 4:
        return out
    v = T[ok]
    same = np.diff(v) == 0.0
    # runs of equal values: starts and ends (inclusive) of each run of ``same``
    edge = np.diff(np.concatenate([[0], same.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edge == 1), np.flatnonzero(edge == -1)
    if len(starts) < 2:
        return out
    at = 0.5 * (ok[ends[:-1]] + ok[starts[1:]])
    level = 0.5 * (v[ends[:-1]] + v[starts[1:]])
    # runs more than one step apart are a temperature moving faster than the readings dwell:
    # there the readings between them are the knots, as they are (the rounding is small
    # beside the change; a straight line across a fast stretch bent the record's start)
    lv = v[starts]
    jump = np.abs(np.diff(lv))
    fast = jump > 1.5 * float(np.median(jump))
    if np.any(fast):
        keep_mid = ~fast
        at, level = at[keep_mid], level[keep_mid]
        inner = np.concatenate([np.arange(ends[p], starts[p + 1] + 1)
                                for p in np.flatnonzero(fast)])
        at = np.concatenate([at, ok[inner].astype(float)])
        level = np.concatenate([level, v[inner]])
    # a run whose neighbours are both on one side of it is a turning point: the
    # temperature went past the threshold and back, by up to a step: its level at its
    # middle
    turn = np.flatnonzero((lv[1:-1] - lv[:-2]) * (lv[1:-1] - lv[2:]) > 0) + 1
    # the record's ends at their own readings (held at the first crossing's mid-level, the
    # first run was a step of q/2 at the start: a warm-up to the transients' search)
    at = np.concatenate([at, 0.5 * (ok[starts[turn]] + ok[ends[turn]]), [ok[0], ok[-1]]])
    level = np.concatenate([level, lv[turn], [v[0], v[-1]]])
    o = np.argsort(at, kind="stable")
    at, level = at[o], level[o]
    out[ok] = np.interp(ok, at, level)
    return out


def channel_grids(grids: Sequence[tuple[float, float] | None] | None, k: int
                  ) -> list[tuple[float, float]]:
    """Each of ``k`` temperature channels' (step K, origin): ``grids``' (None, or a None
    entry: the DS18B20's 12-bit (0.0625, 0))."""
    return [(DS18B20_STEP_K, 0.0) if g is None else g
            for g in (list(grids) if grids is not None else [None] * k)]


def coarse_regressor(temps: NDArray, grids: Sequence[tuple[float, float] | None] | None = None
                     ) -> NDArray[np.float64]:
    """The temperature channels (M, k) the thermal regression reads, each on its own grid
    (``grids``, per column; ``channel_grids``): as logged on the 12-bit step, the crossing
    reconstruction (``derounded``) on a coarser one, column by column (a coarse log leaves a
    finer one as logged). A
    coarse quantiser's gain at the drive is not 1 (its describing function: 1.037 for a
    ±0.5 K cycle on a 0.25 K step), an error in the variable no τ floor removes, which put
    ĉ ≈ 3 % low at 0.25 K and 9 % at 0.5 K; the reconstruction follows the drive's
    amplitude. The rounding floors (``rounding_floor_tau``) stay the raw readings': the
    sawtooth they model is the readings', and on the smooth reconstruction a slower slope
    made the floor of a 0.5 K log infinite (no τ left to the regression)."""
    temps = np.asarray(temps, dtype=float)
    T = temps.reshape(len(temps), -1)
    gs = channel_grids(grids, T.shape[1])
    if not any(is_coarse(g[0]) for g in gs):
        return temps
    out = np.column_stack([derounded(T[:, j], g) if is_coarse(g[0]) else T[:, j]
                           for j, g in enumerate(gs)])
    return out.reshape(temps.shape)


def coarse_gain_se(fit: ThermalFit, raw: NDArray, recon: NDArray) -> ThermalFit:
    """``fit`` with its coefficient's standard error widened by the reconstruction's gain
    uncertainty when its channel reads on a coarse step (``coarse_regressor``; ``raw``, ``recon``
    the channels as logged and as reconstructed, slow view). The quantiser's describing
    function makes the raw readings' swing at the drive larger than the temperature's and the
    crossings' spline, on a step a few times narrower than the swing, smaller or larger by
    an amount no τ floor shows: ĉ from either brackets the truth (0.5 K step, ±0.5 K drive:
    0.91× and 1.08× the truth). Half the bracket, √(AVAR_raw/AVAR_recon) − 1 at the τ of the
    reconstruction's largest AVAR (the drive), is added in quadrature: 0.5 % at 0.125 K,
    2 % at 0.25 K, 8 % at 0.5 K. The detection's z is the regression's (the gain's error
    scales a coupling that is there; it makes none). The relative widening is kept on the fit
    (``gain_rel``) for a path's coefficient beyond one lag (``_with_path``)."""
    if not is_coarse(fit.grid[0]) or not (
            math.isfinite(fit.coef_se) and math.isfinite(fit.coefficient)):
        return fit
    j = fit.channel_index
    var = []
    for col in (np.asarray(raw, dtype=float)[:, j], np.asarray(recon, dtype=float)[:, j]):
        sa = StreamingAllan(1, fit.rate_hz)
        sa.update(col[:, None])
        var.append(np.asarray(sa.result().var, dtype=float))
    ok = np.isfinite(var[0]) & np.isfinite(var[1]) & (var[1] > 0)
    if not np.any(ok):
        return fit
    k = int(np.argmax(np.where(ok, var[1], -np.inf)))
    rel = 0.5 * abs(math.sqrt(var[0][k] / var[1][k]) - 1.0)
    return replace(fit, coef_se=math.hypot(fit.coef_se, rel * fit.coefficient), gain_rel=rel)


#: Samples beyond the first (last) crossing whose slope the reconstruction carries back
#: (forward) to the record's start (end): about a minute of a 1.6 s slow view, the time a
#: room's cycle takes between neighbouring crossings of a coarse step.
CROSSING_END_SPAN = 40


def _crossing_ends(v: NDArray, R: NDArray, q: float) -> NDArray[np.float64]:
    """``R`` (the crossing reconstruction of readings ``v`` on step ``q``) before the readings'
    first change of level and after their last: the slope of ``R`` over
    ``CROSSING_END_SPAN`` samples beyond it, carried to the record's end, within the
    reading's cell there (the temperature was in it, and reached its edge at the crossing)."""
    lev = np.round(v / q)
    ch = np.flatnonzero(np.diff(lev) != 0)
    out = np.array(R, dtype=float)
    if len(ch) < 2:
        return out
    i0, i1 = int(ch[0]) + 1, int(ch[-1])
    j = min(len(R) - 1, i0 + CROSSING_END_SPAN)
    s = (R[j] - R[i0]) / max(j - i0, 1)
    c = lev[0] * q
    out[:i0] = np.clip(R[i0] + s * (np.arange(i0) - i0), c - q / 2, c + q / 2)
    j = max(0, i1 - CROSSING_END_SPAN)
    s = (R[i1] - R[j]) / max(i1 - j, 1)
    c = lev[-1] * q
    out[i1 + 1:] = np.clip(R[i1] + s * (np.arange(i1 + 1, len(R)) - i1), c - q / 2, c + q / 2)
    return out


def allan2(y: NDArray, u: NDArray, rate_hz: float,
           keep: NDArray[np.bool_] | None = None) -> Any:
    """Allan variances and covariance of (y, u) with the streaming estimator (rows outside
    ``keep`` left out as gaps)."""
    sa = StreamingAllan(2, rate_hz)
    feed(sa, np.column_stack([y, u]), keep)
    return sa.result()


def _kept(res: Any, min_tau_s: float) -> NDArray[np.bool_]:
    """The rows (τ) of a two-channel Allan result the regression uses."""
    cov = np.asarray(res.cov, dtype=float)
    tau = np.asarray(res.tau, dtype=float)
    edf = np.asarray(res.edf, dtype=float)
    edf_y = edf[:, 0] if edf.ndim == 2 else edf
    vy, vu = cov[:, 0, 0], cov[:, 1, 1]
    return np.asarray(np.isfinite(vy) & np.isfinite(vu) & (vu > 0) & (tau >= min_tau_s)
                      & np.isfinite(edf_y) & (edf_y >= 3))


def regression_terms(res: Any, min_tau_s: float = 2 * DS18B20_CONVERSION_S
                     ) -> tuple[NDArray[np.float64], ...]:
    """(τ, Cov_A(y, u), AVAR_u, AVAR_y, ν_y) at the τ the regression uses, from a
    two-channel Allan result (axis, temperature)."""
    cov = np.asarray(res.cov, dtype=float)
    edf = np.asarray(res.edf, dtype=float)
    edf_y = edf[:, 0] if edf.ndim == 2 else edf
    ok = _kept(res, min_tau_s)
    return (np.asarray(res.tau, dtype=float)[ok], cov[ok, 0, 1], cov[ok, 1, 1],
            cov[ok, 0, 0], edf_y[ok])


@functools.lru_cache(maxsize=64)
def _rho(k: int) -> NDArray[np.float64]:
    """The correlation of neighbouring octaves' c_k for a white regressor and white noise,
    ``_RHO``^|i − j| (k, k): where no regressor's ``octave_spectra`` is at hand; the same
    few sizes every time, so made once each (read-only)."""
    idx = np.arange(k)
    rho = _RHO ** np.abs(np.subtract.outer(idx, idx))
    rho.flags.writeable = False
    return rho


#: ln of the two-sided spectrum at f = 1/(2τ) over τ·AVAR(τ) (``OctaveSpectra._noise``'s
#: level) for power-law noise whose AVAR goes as τ^μ, at μ = −1 … 1 in steps of 1/4: with
#: S(f) = h·f^α (one-sided), α = −μ − 1, AVAR = h·τ^μ·∫2x^α sin⁴(πx)/(πx)² dx (NIST SP 1065
#: eq. 10's transfer function), so the ratio is 2^−α/(2∫…): 1 for white noise, 1/(2 ln 2)
#: for flicker, 3/π² for a random walk (numerical quadrature; the ends in closed form).
_SHAPE_MU = np.linspace(-1.0, 1.0, 9)
_SHAPE_LN = np.array([0.0, -0.0307, -0.0995, -0.1988, -0.3266, -0.4839, -0.6745, -0.9058,
                      -1.1908])
#: Block means in the shortest octave read that ``octave_spectra`` keeps (its spectra on
#: block means of a power of two samples).
SPECTRA_BLOCKS = 16
#: Log-frequency bins per octave of the regression vectors' cross-spectra
#: (``OctaveSpectra``): the axis's noise spectrum is smooth on that scale.
_BINS_PER_OCTAVE = 4


@dataclass(frozen=True)
class OctaveSpectra:
    """The cross-spectra of the octaves' regression vectors a_k = H_kᵀ D_u^k for one
    regressor u (``octave_spectra``), summed in log-frequency bins: ``P`` (B, K, K) at bin
    frequencies ``f`` (B,) (cycles per sample), the octaves ``ms`` (K,) samples; with an
    axis's noise level, the covariance of the octaves' coefficients."""

    ms: NDArray[np.int64]
    f: NDArray[np.float64]
    P: NDArray[np.float64]
    #: Σ D_u² per octave (c_k's denominator) and the regressor's length (samples), both
    #: on the block means of ``step`` samples the spectra were taken on (``f`` too)
    su: NDArray[np.float64]
    n: int
    step: int = 1

    def _noise(self, rows: NDArray, avar: NDArray, shaped: bool = False
               ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(S (B,), λ (B, K)): the axis's noise spectrum at the bins for the AVAR ``avar``
        at the octaves ``rows`` (indices into ``ms``), and how each bin's ln S is made of
        the octaves' ln AVAR (its interpolation weights: the variance's share of each
        octave's estimate, for its degrees of freedom).

        Its two-sided spectrum per sample is taken as S(f) = m·AVAR at f = 1/(2m) (exact
        for white noise, within a factor ≈ 3 for a random walk), log-log interpolated;
        below the longest octave the record cannot say: the reddest noise the sensor's model
        has (rate random walk, f⁻²), which is what a trend's ends see most (the slope of the
        last octaves instead: a null axis whose slow noise followed a setback room passed
        at z 5.7; the cost, a white axis on a pure ramp, an se wider than its scatter);
        above the shortest, the slope of the last three held, clipped to f⁰ … f⁻².

        ``shaped``: each octave's level corrected by the ratio the AVAR's local slope says
        (``_SHAPE_LN``): m·AVAR is the spectrum of white noise, and 3.3× a random walk's,
        1.4× flicker's (the coefficient's se from it 1.8× too wide where the rate random
        walk dominates at the regressor's period: the 68 % intervals of the typical-tempco
        60 h and faulty-log rows held the truth on 80–96 % of records)."""
        ms = self.ms[rows].astype(float) / self.step
        lf = np.log(1.0 / (2.0 * ms))[::-1]
        la = np.log(ms * np.maximum(avar, 1e-300))
        if shaped and len(ms) >= 2:
            mu = np.clip(np.gradient(np.log(np.maximum(avar, 1e-300)), np.log(ms)), -1.0, 1.0)
            la = la + np.interp(mu, _SHAPE_MU, _SHAPE_LN)
        ls = la[::-1]
        x = np.log(self.f)
        K = len(lf)
        lam = np.empty((len(x), K))
        for k in range(K):  # the weights np.interp gives each octave, ends held
            lam[:, k] = np.interp(x, lf, np.eye(K)[k])
        S = lam @ ls
        if K >= 2:
            j = min(3, K)
            lo, hi = x < lf[0], x > lf[-1]
            s_hi = np.clip(np.polyfit(lf[-j:], ls[-j:], 1)[0], -2.0, 0.0)
            S[lo] = ls[0] - 2.0 * (x[lo] - lf[0])
            S[hi] = ls[-1] + s_hi * (x[hi] - lf[-1])
        # lam's columns run longest octave first (lf ascends): back to the rows' order
        return np.exp(S), lam[:, ::-1]

    def _gram(self, rows: NDArray, S: NDArray) -> NDArray[np.float64]:
        # Var⟨a, e⟩ = ∫|A(f)|²S(f)df over ±½ = (1/N)·Σ_{f>0} |A|²S on the 2N-point grid
        G = np.einsum("b,bkl->kl", S, self.P[:, rows][:, :, rows]) / self.n
        su = self.su[rows]
        return np.asarray(G / np.outer(su, su), dtype=float)

    def covariance(self, rows: NDArray, avar: NDArray) -> NDArray[np.float64]:
        """Cov(c_k, c_l) (K, K) over the octaves ``rows`` (indices into ``ms``) for axis noise
        whose AVAR is ``avar`` there (the spectrum of ``_noise``)."""
        return self._gram(rows, self._noise(rows, avar)[0])

    def variance(self, rows: NDArray, avar: NDArray, w: NDArray, edf: NDArray,
                 shaped: bool = False) -> tuple[float, float]:
        """(Var Σ w_k c_k / Σ w_k, its degrees of freedom) for the octaves ``rows``, the axis's
        noise AVAR ``avar`` there with ``edf`` each: the variance is a sum of the bins'
        S·(wᵀP w), each bin's S a product of the octaves' AVAR to the powers λ, so
        octave k carries a_k = Σ_b S_b·(wᵀP_b w)·λ_bk of it, and by Satterthwaite its
        estimate has (Σ a_k)²/Σ(a_k²/ν_k) degrees of freedom. ``shaped``: the spectrum's
        level from the AVAR's local slope (``_noise``)."""
        S, lam = self._noise(rows, avar, shaped)
        su = self.su[rows]
        wn = w / su / float(np.sum(w))
        q = np.einsum("bkl,k,l->b", self.P[:, rows][:, :, rows], wn, wn) / self.n
        share = (S * q) @ lam
        var = float(np.sum(S * q))
        den = float(np.sum(share ** 2 / np.asarray(edf, dtype=float)))
        return var, (var * var / den if den > 0 else math.inf)


def octave_spectra(u: NDArray, ms: NDArray, min_m: float = 0.0) -> OctaveSpectra:
    """The regression vectors' cross-spectra of regressor ``u`` at octaves ``ms`` (samples,
    fully overlapping differences); octaves shorter than ``min_m`` samples (below the
    regression's shortest τ: never read) left zero, most of its cost spared.

    Why: with D_u fixed, c_k's error is ⟨a_k, e⟩/Σ D_u² (e the axis's noise, a_k = H_kᵀ D_u,
    H_k the octave's Allan difference), so Cov(c_k, c_l) ∝ Σ_f A_k(f)·A_l*(f)·S_e(f). For a
    white regressor and white noise neighbours come out near ``_RHO`` = 0.5. For a regressor
    that is mostly a trend (a setback room) D_u is nearly constant and a_k telescopes onto the
    record's two ends at every octave: red noise there (random walk, flicker) is the same
    few slow numbers for every octave, whose c_k are then nearly one number: the fixed 0.5
    gave the combination a standard error far below its scatter (2 false couplings in 45
    null axes)."""
    ms = np.asarray(ms, dtype=np.int64)
    # on block means of ``step`` samples, the shortest octave read ≥ SPECTRA_BLOCKS of them:
    # a difference of block means is the full rate's difference at a stride of ``step``
    # (as the streaming estimator strides its long octaves), and the octaves read are slow
    # (the rounding floor: minutes), so their spectra cost 1/step of the full rate's
    step = 1 << max(0, math.floor(math.log2(max(min_m, 1.0) / SPECTRA_BLOCKS) + 1e-9))
    u = np.asarray(u, dtype=float)
    if step > 1:
        u = u[:len(u) // step * step].reshape(-1, step).mean(axis=1)
    N = len(u)
    S = np.concatenate([[0.0], np.cumsum(u - u.mean())])
    A = np.zeros((len(ms), N))
    su = np.full(len(ms), np.inf)
    for k, m_full in enumerate(ms.tolist()):
        m = m_full // step
        if 2 * m > N or m_full < min_m * (1 - 1e-9) or m < 1:  # τ·rate's rounding
            continue
        n_d = N - 2 * m + 1
        # D(i) = mean of u[i+m:i+2m] − mean of u[i:i+m], i = 0 … n_d − 1
        D = (S[2 * m:2 * m + n_d] - 2.0 * S[m:m + n_d] + S[:n_d]) / m
        su[k] = float(np.einsum("i,i->", D, D))
        # a(t) = Σ_i D(i)·h(t − i), h = −1/m on [0, m), +1/m on [m, 2m): window sums of D
        # (C the cumulative sum of D held at its ends, read as slices, not gathered)
        # C[j + 2m − 1] = Σ D(i < j) for j clipped to 0 … n_d
        cs = np.cumsum(D)
        C = np.concatenate([np.zeros(2 * m), cs, np.full(2 * m - 1, cs[-1])])
        c0, c1, c2 = C[:N], C[m:m + N], C[2 * m:2 * m + N]
        A[k] = ((c1 - c0) - (c2 - c1)) / m
    rows = np.flatnonzero(np.isfinite(su))
    F = np.zeros((len(ms), N), dtype=complex)
    F[rows] = np.fft.rfft(A[rows], n=2 * N, axis=1)[:, 1:]
    f = np.arange(1, F.shape[1] + 1) / (2.0 * N)
    edges = 2.0 ** (np.arange(math.floor(math.log2(f[0]) * _BINS_PER_OCTAVE),
                              1 + math.ceil(math.log2(f[-1]) * _BINS_PER_OCTAVE))
                    / _BINS_PER_OCTAVE)
    b = np.clip(np.searchsorted(edges, f, side="right") - 1, 0, len(edges) - 2)
    B = len(edges) - 1
    P = np.zeros((B, len(ms), len(ms)))
    # f rises, so each bin is one slice of F; Re(F·Fᴴ) = Fr·Frᵀ + Fi·Fiᵀ in real products
    Fr, Fi = np.ascontiguousarray(F.real), np.ascontiguousarray(F.imag)
    cut = np.searchsorted(b, np.arange(B + 1))
    for i in range(B):
        lo, hi = cut[i], cut[i + 1]
        if hi > lo:
            P[i] = Fr[:, lo:hi] @ Fr[:, lo:hi].T + Fi[:, lo:hi] @ Fi[:, lo:hi].T
    fc = np.sqrt(edges[:-1] * edges[1:])
    used = np.abs(P).sum(axis=(1, 2)) > 0
    return OctaveSpectra(ms, fc[used], P[used], su, N, step)


def tempco_from_cov(res: Any, min_tau_s: float = 2 * DS18B20_CONVERSION_S
                    ) -> tuple[float, float, int]:
    """(ĉ, se, points used) from a two-channel AllanResult (axis, temperature): the
    inverse-variance combination over τ of c_k = Cov_A/AVAR_u (module doc), the octaves'
    correlation a white regressor's under white noise (``_rho``), the same for every lag and
    channel a scan compares (``coupling_test``: the regressor's own)."""
    got = _octave_coefficients(res, min_tau_s)
    if got is None:
        return 0.0, math.inf, 0
    ws = got.w * got.se
    var = float(ws @ _rho(len(ws)) @ ws) / float(np.sum(got.w)) ** 2
    return got.chat, math.sqrt(var), len(ws)


class _Octaves(NamedTuple):
    """The regression's octaves: ĉ, c_k, their EDF-model se_k, weights w_k, residual AVAR
    r_k and the axis's EDF ν_k."""

    chat: float
    c: NDArray[np.float64]
    se: NDArray[np.float64]
    w: NDArray[np.float64]
    r: NDArray[np.float64]
    nu: NDArray[np.float64]


def _octave_coefficients(res: Any, min_tau_s: float) -> _Octaves | None:
    """The octaves at the τ the regression uses (None: no τ)."""
    _tau, cyu, vu, vy, nu = regression_terms(res, min_tau_s)
    if len(cyu) == 0:
        return None
    c = cyu / vu
    r = np.maximum(vy - cyu**2 / vu, 1e-300)
    se = np.sqrt(r / (vu * nu))
    w = 1.0 / se**2
    return _Octaves(float(np.sum(w * c) / np.sum(w)), c, se, w, r, nu)


class CouplingTest(NamedTuple):
    """ĉ, its standard error, the octaves used, and the degrees of freedom the test's se rests
    on (∞ for the per-octave EDF model of ``_rho``); ``threshold`` the z that test needs.

    The test's statistic is its own combination of the octaves (``c_test``, ``se_test``,
    ``weights``): the one the octaves' covariance (the regressor's ``octave_spectra`` under
    the axis's noise) makes most precise, with non-negative weights
    (``least_variance_weights``). ĉ keeps the EDF model's inverse-variance weights for the
    estimate and its interval."""

    c: float
    se: float
    points: int
    dof: float
    #: the se of ĉ's 68 % interval: the spectrum's level from the AVAR's local slope
    #: (``OctaveSpectra._noise``'s ``shaped``); the test keeps white noise's level at
    #: every octave (its false-alarm rate was measured with it: the setback room's null axes)
    se_interval: float = math.inf
    #: the test's combination of the octaves, its se (white noise's level) and its weights
    #: (summing to 1, one per octave used); NaN/∞/() where there is no covariance
    c_test: float = math.nan
    se_test: float = math.inf
    weights: tuple[float, ...] = ()

    @property
    def z(self) -> float:
        """The test's statistic |c_test|/se_test (0 where it has no se)."""
        ok = math.isfinite(self.se_test) and self.se_test > 0 and math.isfinite(self.c_test)
        return abs(self.c_test) / self.se_test if ok else 0.0

    @property
    def threshold(self) -> float:
        """``Z_TEMPERATURE``, or where the se rests on few degrees of freedom more: the |t|
        of ``dof`` degrees of freedom at the per-trial share of the axis's false-alarm
        budget for the coupling search (``alarm.TEMPERATURE`` over ``SCAN_TRIALS``, what
        z ≥ 5 holds with room to spare for a normal z). An se estimated from a few slow
        octaves' noise is itself a random number, and z = ĉ/se is then a t: a null axis in
        a setback room passed z 5 at 5.8, its se resting on ≈ 6 degrees of freedom."""
        if not math.isfinite(self.dof):
            return Z_TEMPERATURE
        return max(Z_TEMPERATURE, t_two_sided(alarm.TEMPERATURE / SCAN_TRIALS,
                                              max(self.dof, 1.0)))


def least_variance_weights(V: NDArray) -> NDArray[np.float64]:
    """The non-negative weights w (Σw = 1) that make wᵀVw least for the octaves'
    covariance ``V`` (K, K): the most precise combination of the octaves' coefficients that
    never subtracts one octave from another. Unconstrained, the least-variance weights of
    strongly correlated neighbours come out of opposite signs: a difference that cancels
    their shared slow noise in the model, and that rests on the model's correlation being
    exact where it is least known; non-negative, an octave the others already carry is left
    out instead. Active set: the unconstrained solution on the
    octaves kept, the most negative dropped until none is, then any dropped octave whose
    gradient says it would lower the variance taken back."""
    V = np.asarray(V, dtype=float)
    K = len(V)
    if K == 0:
        return np.zeros(0)
    d = np.sqrt(np.maximum(np.diag(V), 1e-300))
    R = V / np.outer(d, d)  # scaled: the same weights for u = w·d
    on = np.ones(K, dtype=bool)
    u = np.zeros(K)
    for _ in range(4 * K):
        idx = np.flatnonzero(on)
        sol = np.linalg.lstsq(R[np.ix_(idx, idx)], 1.0 / d[idx], rcond=1e-12)[0]
        if np.any(sol <= 0):
            on[idx[int(np.argmin(sol))]] = False
            if not on.any():
                on[int(np.argmin(np.diag(V)))] = True
            continue
        u = np.zeros(K)
        u[idx] = sol
        grad = R @ u  # (V w)_j / d_j with w = u / d: the variance's slope along octave j
        lam = float(grad[idx] @ (1.0 / d[idx]) / np.sum(1.0 / d[idx] ** 2))
        off = np.flatnonzero(~on)
        better = off[grad[off] < lam / d[off] * (1 - 1e-9)] if len(off) else off
        if len(better) == 0:
            break
        on[better[int(np.argmin(grad[better] * d[better]))]] = True
    w = u / d
    s = float(np.sum(w))
    return w / s if s > 0 else np.full(K, 1.0 / K)


def coupling_test(res: Any, spectra: OctaveSpectra,
                  min_tau_s: float = 2 * DS18B20_CONVERSION_S) -> CouplingTest:
    """:func:`tempco_from_cov`'s ĉ with the se and its degrees of freedom from the octaves'
    covariance as this regressor (its ``spectra``, rows those of ``res``:
    ``octave_spectra``) and the axis's residual noise make it: it holds what the per-octave
    EDF cannot, the slow noise every octave of a trend or a slow cycle shares.

    The test reads its own combination (``least_variance_weights`` of that covariance): the
    EDF model's weights trust each slow octave as independent, and where a slow cycle (a
    day's) drives the regressor there, their shared red noise set the se and its few
    degrees of freedom (so a t threshold well above 5) while faster octaves (the HVAC's)
    held the evidence (docs/log/explain.md, chan23g)."""
    got = _octave_coefficients(res, min_tau_s)
    if got is None:
        return CouplingTest(0.0, math.inf, 0, math.inf)
    # ĉ keeps its weights (any weights give it without bias); its variance is this
    # covariance's, which for a white regressor is the EDF model's and for a trend is the
    # ends' (the EDF model, Σ of independent differences, is ×3 too wide there)
    rows = np.flatnonzero(_kept(res, min_tau_s))
    var, dof_iv = spectra.variance(rows, got.r, got.w, got.nu)
    if not (math.isfinite(var) and var > 0):
        # the spectra do not see an octave the Allan result holds (a regressor flat on the
        # block means they were taken on): no se from them, so none the test can pass with
        return CouplingTest(got.chat, math.inf, len(got.w), math.inf)
    var_iv, _ = spectra.variance(rows, got.r, got.w, got.nu, shaped=True)
    se_iv = math.sqrt(var_iv) if math.isfinite(var_iv) and var_iv > 0 else math.sqrt(var)
    wt = least_variance_weights(spectra.covariance(rows, got.r))
    var_t, dof = spectra.variance(rows, got.r, wt, got.nu)
    if not (math.isfinite(var_t) and var_t > 0):
        wt, var_t, dof = got.w / float(np.sum(got.w)), var, dof_iv
    return CouplingTest(got.chat, math.sqrt(var), len(got.w), dof, se_iv,
                        float(wt @ got.c), math.sqrt(var_t), tuple(float(x) for x in wt))


#: Lags after a hole in the temperature log that stay out of the regression (the lag filter
#: still carries the interpolated stretch: e^(−3) ≈ 5 % of it).
HOLE_SETTLE_LAGS = 3.0
#: Holes: per temperature channel, (first, last) slow-view blocks the log says nothing about.
Holes = dict[int, list[tuple[int, int]]]


def hole_mask(n: int, holes: list[tuple[int, int]], lag_s: float, rate_hz: float
              ) -> NDArray[np.bool_] | None:
    """Blocks kept by the regression (None: all): each hole and ``HOLE_SETTLE_LAGS`` lags
    after it are left out, so the interpolation across a hole is never taken for the axis's
    response (a 25-minute dropout put the lag at +34…47 s against a true 0)."""
    if not holes:
        return None
    keep = np.ones(n, dtype=bool)
    settle = math.ceil(HOLE_SETTLE_LAGS * abs(lag_s) * rate_hz)
    for a, b in holes:
        keep[max(0, a):min(n, b + 1 + settle)] = False
    return keep


def feed(sa: StreamingAllan, X: NDArray, keep: NDArray[np.bool_] | None) -> None:
    """``sa.update`` with the rows of ``X`` where ``keep`` is False left out as gaps (no Allan
    difference spans them)."""
    if keep is None:
        sa.update(X)
        return
    m = np.concatenate([[False], keep, [False]]).astype(np.int8)
    d = np.diff(m)
    for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True):
        sa.update(X[a:b])
        sa.gap()


def kept_runs(n: int, keep: NDArray[np.bool_] | None) -> list[tuple[int, int]]:
    """(start, end) of the runs of rows ``keep`` holds (all rows when None): the segments
    ``feed`` gives the accumulator."""
    if keep is None:
        return [(0, n)]
    m = np.concatenate([[False], keep, [False]]).astype(np.int8)
    d = np.diff(m)
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(),
                    strict=True))


@dataclass(frozen=True)
class OctaveSums:
    """Allan difference sums at octave m of C channels over some segments: ``n`` (K,)
    differences and ``s2`` (K, C, C) = Σ D Dᵀ, on the streaming cascade's stride grid. They
    add over disjoint parts (``+``) and give the Allan covariance (``cov``)."""

    ms: NDArray[np.int64]
    n: NDArray[np.int64]
    s2: NDArray[np.float64]

    def _padded(self, k: int) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """(n, s2) with zeros for the octaves past this one's (a part shorter than 2m, or
        all inside a hole, counted no difference there)."""
        pad = k - len(self.ms)
        if pad == 0:  # the usual case: np.pad's copy was most of a jackknife scan's cost
            return self.n, self.s2
        return (np.pad(self.n, (0, pad)), np.pad(self.s2, ((0, pad), (0, 0), (0, 0))))

    def _union(self, other: OctaveSums) -> NDArray[np.int64]:
        return self.ms if len(self.ms) >= len(other.ms) else other.ms

    def __add__(self, other: OctaveSums) -> OctaveSums:
        # the octaves of the longer: truncating to the shorter let one part inside a hole
        # (no octave) or a short one drop every long τ of the whole record's sums
        ms = self._union(other)
        (n1, s1), (n2, s2) = self._padded(len(ms)), other._padded(len(ms))
        return OctaveSums(ms, n1 + n2, s1 + s2)

    def __sub__(self, other: OctaveSums) -> OctaveSums:
        ms = self._union(other)
        (n1, s1), (n2, s2) = self._padded(len(ms)), other._padded(len(ms))
        return OctaveSums(ms, n1 - n2, s1 - s2)

    def cov(self) -> NDArray[np.float64]:
        """Allan covariance (K, C, C), NaN where no difference was counted (made once: the
        lag scan reads it for every axis; read-only)."""
        if "_cov" not in self.__dict__:
            c = self._make_cov()
            c.flags.writeable = False
            object.__setattr__(self, "_cov", c)
        return self.__dict__["_cov"]  # type: ignore[no-any-return]

    def _make_cov(self) -> NDArray[np.float64]:
        scale = NORM[2] * self.ms.astype(float) ** 2 * np.maximum(self.n, 1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where((self.n > 0)[:, None, None], self.s2 / scale[:, None, None],
                            np.nan)


def octave_sums(X: NDArray, keep: NDArray[np.bool_] | None = None, levels: int = 40,
                overlap: int = DEFAULT_OVERLAP) -> OctaveSums:
    """The difference sums ``StreamingAllan(C, rate).update`` (via ``feed(…, keep)``) holds
    after ``X`` (M, C), from the same difference kernel (``deviations.grid_sums``) on the
    same grids, without the noise identification (the lag scan needs only the covariance;
    the axis's EDF does not depend on the trial lag). A test holds it equal to the
    accumulator's covariance."""
    return octave_sums_by_part(X, np.array([0, len(X)]), keep, levels, overlap)[0]


def octave_sums_by_part(X: NDArray, edges: NDArray, keep: NDArray[np.bool_] | None = None,
                        levels: int = 40, overlap: int = DEFAULT_OVERLAP) -> list[OctaveSums]:
    """:func:`octave_sums` of ``X`` split among the contiguous parts [edges[g], edges[g+1]):
    each Allan difference of the whole record goes to the part that holds its middle, so
    the parts add up to the whole record's sums at *every* octave, and the whole minus one
    part is the record with that part's differences left out (the delete-a-group
    jackknife).

    Not the sums of each part on its own: those have no octave longer than half a part, so
    a jackknife on them fitted the lag and the coefficient on τ ≤ part/2 only (≈ 400 s on a
    4 h record, below the HVAC cycle's τ ≈ 900 s where the coupling shows most): the
    leave-one-out lags scattered twice as far as the record's own lag does and centred
    elsewhere (a faulty-log record: best lag 19 s, the ten leave-one-out lags −10…17 s)."""
    X = np.asarray(X, dtype=float)
    G = len(edges) - 1
    runs = kept_runs(len(X), keep)
    longest = max((b - a for a, b in runs), default=0)
    ms = [1 << k for k in range(levels) if 2 * (1 << k) <= longest]
    sums = [[DifferenceSums.zeros(X.shape[1]) for _ in ms] for _ in range(G)]
    for a, b in runs:
        if b - a < 2:
            continue
        p = segment_phase(X[a:b], False)
        for k, m in enumerate(ms):
            if 2 * m > b - a:
                break
            st = 1 if m <= overlap else m // overlap
            q = p[::st] if st > 1 else p
            sp = m // st
            n_d = len(q) - 2 * sp
            # difference j spans samples a + j·st … + 2m: it goes to the part of its middle
            cut = np.clip(-((a + m - np.asarray(edges, dtype=np.int64)) // st), 0, n_d)
            grid_sums_by_part(q, sp, cut, [sums[g][k] for g in range(G)])
    return [OctaveSums(np.asarray(ms, dtype=np.int64),
                       np.asarray([x.n for x in sg], dtype=np.int64),
                       np.asarray([x.s2 for x in sg], dtype=float).reshape(
                           len(ms), X.shape[1], X.shape[1])) for sg in sums]


@dataclass(frozen=True)
class AxesDifferences:
    """The axes' part of the lag scan's difference sums, the same for every trial lag: per
    octave (``ms``, stride ``st``, ``sp`` = m/st) the second differences ``d`` (n_k, C) of
    the centred axes ``centred`` (M, C), each part's (``edges``) Σ D Dᵀ ``gram`` (G, C, C)
    and its range of differences ``cuts`` (G + 1,), as ``octave_sums_by_part`` assigns them
    (:func:`lag_octave_sums`)."""

    centred: NDArray[np.float64]
    ms: list[int]
    st: list[int]
    sp: list[int]
    d: list[NDArray[np.float64]]
    cuts: list[NDArray[np.int64]]
    gram: list[NDArray[np.float64]]


def axes_differences(Y: NDArray, edges: NDArray, levels: int = 40,
                     overlap: int = DEFAULT_OVERLAP) -> AxesDifferences:
    """The axes' second differences at every octave of ``Y`` (M, C), for the parts
    [edges[g], edges[g+1]) (``[0, M]``: the whole record), once for all trial lags."""
    Yc = np.asarray(Y, dtype=float)
    Yc = Yc - Yc.mean(axis=0)
    M = len(Yc)
    ms = [1 << k for k in range(levels) if 2 * (1 << k) <= M]
    p = segment_phase(Yc, False)
    sts, sps, ds, cuts, grams = [], [], [], [], []
    e64 = np.asarray(edges, dtype=np.int64)
    for m in ms:
        st = 1 if m <= overlap else m // overlap
        q = p[::st] if st > 1 else p
        sp = m // st
        n_d = len(q) - 2 * sp
        e = q[sp:] - q[:-sp]
        d = np.ascontiguousarray(e[sp:] - e[:-sp])
        cut = np.clip(-((m - e64) // st), 0, n_d)
        sts.append(st)
        sps.append(sp)
        ds.append(d)
        cuts.append(cut)
        grams.append(np.array([gram(d[int(cut[g]):int(cut[g + 1])])
                               for g in range(len(cut) - 1)]))
    return AxesDifferences(Yc, ms, sts, sps, ds, cuts, grams)


def lag_octave_sums(axes: AxesDifferences, u: NDArray, lag_s: float, rate_hz: float
                    ) -> list[OctaveSums]:
    """``octave_sums_by_part(without_start(column_stack([Y, u]), lag_s, rate_hz), edges)``
    (no holes) from the axes' differences computed once (``axes_differences(Y, edges)``):
    the lag scan's sums with only the lagged temperature ``u`` differenced per lag.

    ``without_start`` takes from every column the mean and its multiple w of the start-up
    shape e^(−t/τ_L) (ẽ: e on its first n_e rows, 0 after); second differences drop the
    mean, so an axis's differences are D(Y) − D(ẽ)·w_Y, and its sums Σ D Dᵀ follow from the
    axes' own (``axes.gram``) by D(ẽ)'s products on its support (the first n_e rows): the
    same numbers as the general path to rounding (a test holds them together), at a quarter
    of its work for three axes. The general path stays for a record with holes (their
    settling changes the kept runs with the lag)."""
    C = axes.centred.shape[1]
    M = len(axes.centred)
    uc = without_start(np.asarray(u, dtype=float)[:, None], lag_s, rate_hz)[:, 0]
    pu = segment_phase(uc[:, None], False)[:, 0]
    # the start-up shape's phase and each axis's share of it (w_Y), as without_start has it
    w = np.zeros(C)
    pe: NDArray[np.float64] | None = None
    n_e = 0
    if lag_s != 0:
        n_e = min(M, math.ceil(37.0 * abs(lag_s) * rate_hz) + 1)
        e = np.exp(-np.arange(n_e) / (rate_hz * abs(lag_s)))
        mean_e = float(e.sum()) / M
        vv = float(np.einsum("i,i->", e, e)) - M * mean_e**2
        if vv > 0:
            w = (e @ axes.centred[:n_e]) / vv
            pe = np.empty(M + 1)
            pe[0] = 0.0
            np.cumsum(e, out=pe[1:n_e + 1])
            pe[n_e + 1:] = pe[n_e]
    G = len(axes.cuts[0]) - 1 if axes.cuts else 0
    n = np.zeros((G, len(axes.ms)), dtype=np.int64)
    s2 = np.zeros((G, len(axes.ms), C + 1, C + 1))
    # np.outer's products by broadcasting (the same multiplications, without its per-call
    # conversions: a lag scan makes this loop's few small products thousands of times)
    ww = w[:, None] * w[None, :]
    for k in range(len(axes.ms)):
        st, sp, dy, cut = axes.st[k], axes.sp[k], axes.d[k], axes.cuts[k]
        q = pu[::st] if st > 1 else pu
        eu = q[sp:] - q[:-sp]
        du = eu[sp:] - eu[:-sp]
        de: NDArray[np.float64] | None = None
        if pe is not None:
            # D(ẽ) is 0 (to the bit: its phase is constant there) from the first difference
            # that starts at or after n_e on
            ns = min(len(du), -(-n_e // st))
            qe = (pe[::st] if st > 1 else pe)[:ns + 2 * sp]
            ee = qe[sp:] - qe[:-sp]
            de = ee[sp:] - ee[:-sp]
        for g in range(G):
            j0, j1 = int(cut[g]), int(cut[g + 1])
            if j1 <= j0:
                continue
            yy = axes.gram[k][g]
            dug = du[j0:j1]
            yu = dy[j0:j1].T @ dug
            uu = float(dug @ dug)
            if de is not None and j0 < len(de):
                s1 = min(j1, len(de))
                a = dy[j0:s1].T @ de[j0:s1]
                e2 = float(de[j0:s1] @ de[j0:s1])
                yy = yy + (e2 * ww - a[:, None] * w[None, :] - w[:, None] * a[None, :])
                yy = 0.5 * (yy + yy.T)
                yu = yu - w * float(de[j0:s1] @ du[j0:s1])
            n[g, k] = j1 - j0
            s2[g, k, :C, :C] = yy
            s2[g, k, :C, C] = s2[g, k, C, :C] = yu
            s2[g, k, C, C] = uu
    ms = np.asarray(axes.ms, dtype=np.int64)
    return [OctaveSums(ms, n[g], s2[g]) for g in range(G)]


@dataclass(frozen=True)
class CovView:
    """What :func:`tempco_from_cov` reads of an Allan result (τ, covariance, EDF), from
    :class:`OctaveSums` with the axis's EDF scaled to the differences counted."""

    tau: NDArray[np.float64]
    cov: NDArray[np.float64]
    edf: NDArray[np.float64]


def covariance_block(c: NDArray[np.float64], idx: list[int]) -> NDArray[np.float64]:
    """``c[:, idx][:, :, idx]`` of a covariance stack (K, C, C) in one gather, not two: the
    same numbers in the same memory order (τ fastest), so every sum over it adds in the same
    order (the second index runs along the gathered block's first axis; the transpose has
    the plain indexing's strides: ``test_a_covariance_block_is_the_plain_indexing``)."""
    ia = np.asarray(idx, dtype=np.intp)
    return c[:, ia[None, :], ia[:, None]].transpose(0, 2, 1)


def cov_view(sums: OctaveSums, rate_hz: float, edf_ref: NDArray, n_ref: NDArray,
             cols: tuple[int, int] = (0, 1)) -> CovView:
    """The (axis, temperature) slice ``cols`` of ``sums`` with the axis's EDF ``edf_ref``
    (K,) of a reference count ``n_ref`` (K,) of differences scaled to this one's count (EDF
    is proportional to the differences for the lag's few settling blocks left out, or a
    jackknife's parts)."""
    k = min(len(sums.ms), len(edf_ref))
    cov = covariance_block(sums.cov()[:k], list(cols))
    with np.errstate(invalid="ignore", divide="ignore"):
        edf = np.asarray(edf_ref[:k], float) * sums.n[:k] / np.asarray(n_ref[:k], float)
    return CovView(sums.ms[:k] / rate_hz, cov, np.column_stack([edf, edf]))


def min_tau_for(lag_s: float, floor_s: float = 0.0) -> float:
    """The shortest τ (s) the regression uses for a trial lag: twice the DS18B20's conversion
    time, the channel's rounding floor ``floor_s`` (:func:`rounding_floor_tau`), and for a
    negative lag twice |lag|, below which the lead-lag's high-frequency gain makes the
    regressor mostly the readings' 0.0625 K rounding (an error in the variable that pulls ĉ
    towards 0: 5 % low at −60 s)."""
    base = max(2 * DS18B20_CONVERSION_S, floor_s)
    return max(base, 2.0 * -lag_s) if lag_s < 0 else base


#: DS18B20 resolution (K) and the white-noise variance of its rounding, q²/12 (K²).
DS18B20_STEP_K = 0.0625
#: The (step K, origin) of the readings of the channel being modelled: a log's own
#: (``screen.log_step``: a DS18B20 at 9–11 bits, a °F log taken as °C). Each log is read on its
#: own: the fit takes every channel's grid explicitly (``fit_thermal_axes``' ``grids``,
#: ``ThermalFit.grid``), and this context is set to the driving channel's only around what
#: reads it without an argument for it (a path's candidates and floors, ``with_paths``; a
#: path's signal, ``ThermalFit.signal``; the causes' rounding floors, engine's
#: ``_explain_channel``). Never the record's: a coarse log must leave a finer one's model as
#: it is.
_GRID: ContextVar[tuple[float, float]] = ContextVar("avard_reading_grid",
                                                     default=(DS18B20_STEP_K, 0.0))


def reading_step() -> tuple[float, float]:
    """The (step K, origin) of the readings in force (``reading_grid``), the DS18B20's 12-bit
    (0.0625, 0) unless set to the modelled channel's."""
    return _GRID.get()


@contextmanager
def reading_grid(grid: tuple[float, float] | None) -> Iterator[None]:
    """The thermal model's rounding terms on ``grid`` (step, origin) within the block (None:
    the 12-bit default)."""
    tok = _GRID.set((DS18B20_STEP_K, 0.0) if grid is None else grid)
    try:
        yield
    finally:
        _GRID.reset(tok)
#: How far a channel's AVAR must stand above its readings' rounding for a τ to enter the
#: regression: at 10 the rounding is ≤ 1/11 of the regressor's variance there.
ROUNDING_SNR = 10.0


def rounding_correlation_s(T: NDArray, rate_hz: float, step: float | None = None) -> float:
    """How long (s) the logged channel ``T`` (slow view) keeps one rounding error: a
    temperature moving at |dT/dt| crosses a 0.0625 K step every q/|dT/dt| s, and between
    crossings its rounding error is one slowly moving value of the sawtooth, not a new draw
    per reading; never less than the read interval (the rounding as white noise). |dT/dt|
    from 1-minute means (the differences of a rounded series are mostly its steps)."""
    T = np.asarray(T, dtype=float)
    if len(T) < 2:
        return DS18B20_CONVERSION_S
    slope = float(np.sqrt(np.mean(np.diff(T) ** 2))) * rate_hz
    k = max(1, round(60.0 * rate_hz))
    if len(T) > 4 * k:
        Tm = T[:len(T) // k * k].reshape(-1, k).mean(axis=1)
        slope = float(np.sqrt(np.mean(np.diff(Tm) ** 2))) * rate_hz / k
    q = reading_step()[0] if step is None else step
    return max(DS18B20_CONVERSION_S, q / slope if slope > 0 else math.inf)


def rounding_floor_tau(T: NDArray, rate_hz: float, snr: float = ROUNDING_SNR,
                       step: float | None = None) -> float:
    """The shortest octave τ (s) from which the logged channel ``T`` (slow view) varies at
    least ``snr`` times more than its readings' rounding, the rounding taken as a sawtooth:
    AVAR_T(τ) ≥ snr·(q²/12)·t_c/τ at that τ, t_c the time one rounding
    error lasts (``rounding_correlation_s``). Below it the regressor is mostly rounding: an
    error in the variable that pulls ĉ towards 0 and, as a longer trial lag smooths the
    steps away, favours positive lags.

    The rounding taken as white at the read interval (t_c = 0.75 s) put the floor of a
    slowly turning room ≈ 3 octaves too low: on the faulty-log benchmark records (a true lag
    of 0) the best lag came out +7 s on average with a spread of 15 s, the rounding-free
    log's 0.6 ± 10.6; with the sawtooth 1.2 ± 10.2 (12 seeds). ``thermal_paths`` found the
    same for the per-τ coefficients (0.2–0.9× the truth at τ 16–64 s)."""
    T = np.asarray(T, dtype=float)
    if len(T) < 16:
        return 0.0
    step = reading_step()[0] if step is None else step
    tc = rounding_correlation_s(T, rate_hz, step)
    sa = StreamingAllan(1, rate_hz)
    sa.update(T[:, None])
    res = sa.result()
    tau = np.asarray(res.tau, dtype=float)
    var = np.asarray(res.var, dtype=float)
    q = step**2 / 12.0 * tc / tau
    ok = np.isfinite(var) & (var >= snr * q)
    for i in range(len(tau)):
        # the first τ above the rounding, whatever the octaves after it: a cycle's AVAR
        # peaks below its period and dips towards its multiples, and for a drive of a step
        # or two's swing the next octave can sit in that dip under the bar; asked to pass
        # too, it put the floor past the cycle (or at ∞), leaving the coupling no τ (docs,
        # chan23g). Octaves in such a dip stay in the regression as they do beyond any
        # floor: their small AVAR_u weighs them little. (The rounding's model overstates
        # it below t_c, where the sawtooth's AVAR rises as τ²: an octave does not pass by
        # the model's error.)
        if ok[i]:
            return float(tau[i]) if i > 0 else 0.0
    return math.inf


def jackknife_tempco(y: NDArray, u: NDArray, rate_hz: float,
                     groups: int = JACKKNIFE_GROUPS,
                     min_tau_s: float = 2 * DS18B20_CONVERSION_S,
                     keep: NDArray[np.bool_] | None = None,
                     ref: Any | None = None,
                     weights: tuple[float, ...] = ()) -> tuple[float, float]:
    """(ĉ, se) of the Allan-covariance regression with a delete-a-group jackknife standard
    error: the record in ``groups`` contiguous parts, each its own segment (their difference
    sums add exactly, ``OctaveSums``); ĉ_(−g) from all parts but g;
    se² = (G−1)/G·Σ(ĉ_(−g) − mean)². The analytic se of :func:`tempco_from_cov` treats the
    Allan differences of the noise as independent across a slow regressor, which red noise
    (random walk, flicker at the HVAC period) violates; the jackknife does not assume it.
    ``ref``: the axis's Allan result on the whole record (its EDF, scaled to each
    leave-one-out count; computed here when not given). ``weights``: fixed weights of the
    octaves the whole record's regression uses (``CouplingTest.weights``, in τ order): ĉ
    and each ĉ_(−g) are then that combination of their octaves' Cov_A/AVAR_u, the test's
    statistic, not the inverse-variance one."""
    whole, rest = _jackknife_views(y, u, rate_hz, groups, keep, ref)
    return _jackknife_se(whole, rest, min_tau_s, weights)


def _jackknife_views(y: NDArray, u: NDArray, rate_hz: float, groups: int,
                     keep: NDArray[np.bool_] | None, ref: Any | None
                     ) -> tuple[CovView, list[CovView]]:
    """The whole record's covariance view and each delete-a-part one (one pass over the
    record: ``octave_sums_by_part``), for :func:`jackknife_tempco`."""
    M = len(y)
    X = np.column_stack([y, u])
    if ref is None:
        ref = allan2(y, u, rate_hz, keep)
    edf_ref = np.asarray(ref.edf, dtype=float)
    edf_ref = edf_ref[:, 0] if edf_ref.ndim == 2 else edf_ref
    n_ref = np.asarray(ref.n, dtype=float)
    edges = np.linspace(0, M, groups + 1).astype(int)
    parts = octave_sums_by_part(X, edges, keep)
    full = sum(parts[1:], start=parts[0])
    return (cov_view(full, rate_hz, edf_ref, n_ref),
            [cov_view(full - ps, rate_hz, edf_ref, n_ref) for ps in parts])


def _jackknife_se(whole: CovView, rest: list[CovView], min_tau_s: float,
                  weights: tuple[float, ...] = ()) -> tuple[float, float]:
    """(ĉ, its delete-a-group jackknife se) from :func:`_jackknife_views`, ĉ the
    inverse-variance combination or, with ``weights``, that fixed combination."""
    rows = np.flatnonzero(_kept(whole, min_tau_s))
    fixed = len(weights) == len(rows) and len(rows) > 0

    def one(view: CovView) -> float:
        if not fixed:
            return tempco_from_cov(view, min_tau_s)[0]
        cov = np.asarray(view.cov, dtype=float)[rows]
        with np.errstate(invalid="ignore", divide="ignore"):
            ck = cov[:, 0, 1] / cov[:, 1, 1]
        ok = np.isfinite(ck)
        w = np.asarray(weights, dtype=float)[ok]
        return float(w @ ck[ok] / np.sum(w)) if np.sum(w) > 0 else math.nan

    c_all = one(whole)
    c = np.asarray([one(v) for v in rest])
    if not np.all(np.isfinite(c)):
        return c_all, math.inf
    g = len(rest)
    return c_all, math.sqrt((g - 1) / g * float(np.sum((c - c.mean()) ** 2)))


def coefficient_se(se_jk: float, se_analytic: float) -> float:
    """The standard error of ĉ for its 68 % interval from its two estimates, the
    delete-a-group jackknife ``se_jk`` and the regressor's analytic ``se_analytic``
    (``CouplingTest.se_interval``): the larger.

    The jackknife's parts can be shorter than the noise's correlation at the regressor's
    period (its se then too small), the analytic model can miss a noise. Where both are
    right the larger of the two scattered estimates is above the deviation (by about half
    their spread), but the interval is ± one se on an error whose se is itself estimated,
    and the lag's share (delta method) falls short where the coefficient trades with a long
    lag: the root mean square of the two in its place lowered the coverage on every regime
    of the adversary's generator and further below 68 % where it was short
    (docs/log/2026-11-28-coef26.md). Infinite where either is."""
    return max(se_jk, se_analytic)


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
            with reading_grid(self.grid):
                return k * self.path.signal(temps[:, self.channel_index], y)
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


#: The longest negative lag tried (s): a DS18B20 in its TO-92 package on a plate lags the die
#: by its own thermal time constant, tens of seconds to a few minutes, never hours.
NEG_LAG_MAX_S = 1800.0
#: How much larger z² a channel whose best lag is at the end of the search (open) must reach
#: to be preferred over one with an interior optimum (Δ(−2 ln L) = Δz²: 9 is 3 σ).
OPEN_END_MARGIN = 9.0


def _lag_grid(record_s: float, rate_hz: float) -> NDArray[np.float64]:
    """Lags tried: negative (the logged sensor lags the die) from −``NEG_LAG_MAX_S`` (at most
    record/16), 0, and positive to record/4, log-spaced either side."""
    lo = max(4.0 / rate_hz, 4.0)
    hi = max(record_s / 4.0, 2 * lo)
    neg_hi = min(NEG_LAG_MAX_S, record_s / 16.0)
    neg = -np.geomspace(neg_hi, lo, 12) if neg_hi > 2 * lo else np.zeros(0)
    return np.concatenate([neg, [0.0], np.geomspace(lo, hi, 28)])


def _between(a: float, b: float) -> float:
    """The point between two neighbouring lags of the grid (geometric on one side of 0,
    arithmetic across it)."""
    return math.copysign(math.sqrt(a * b), a) if a * b > 0 else 0.5 * (a + b)


def without_start(cols: NDArray, lag_s: float, rate_hz: float) -> NDArray[np.float64]:
    """``cols`` (M, k) with the lag filter's start-up settling e^(−t/τ_L) projected out of
    every column (least squares, with an offset).

    The sensor's temperature when the record starts is unknown; ``lag_filter`` starts in
    steady state at T[0], so the lagged channel differs from the sensor's by β·e^(−t/τ_L).
    With both the axis and the lagged temperature residualised on that shape, their
    regression gives the coefficient of the model y = c·u + β'·e^(−t/τ_L) (Frisch–Waugh).
    Without it, a plate-logged channel with a 20-minute lag (the start-up difference
    three times the lagged swing) gave the coefficient and the lag at 0.75× the truth even
    without noise."""
    X = np.asarray(cols, dtype=float)
    if lag_s == 0:
        return X.copy()
    # e^(−t/τ_L) is below 1e-16 after 37 lags: its products are taken where it lives (the
    # whole-record products cost most of a lag scan), the mean's share added in closed form
    # (Xc has zero mean, so vᵀXc = eᵀXc)
    M = len(X)
    n_e = min(M, math.ceil(37.0 * abs(lag_s) * rate_hz) + 1)
    e = np.exp(-np.arange(n_e) / (rate_hz * abs(lag_s)))
    mean_e = float(e.sum()) / M
    # einsum, not e @ e: OpenBLAS's threaded ddot spent ~100× the arithmetic's CPU time on a
    # shared machine
    vv = float(np.einsum("i,i->", e, e)) - M * mean_e**2
    if not vv > 0:
        return X.copy()
    Xc = X - X.mean(axis=0)
    w = (e @ Xc[:n_e]) / vv
    Xc += mean_e * w
    Xc[:n_e] -= np.outer(e, w)
    return Xc


class ScanPoint(NamedTuple):
    """One trial lag of one axis: (lag s, ĉ, analytic se, z), and ``zg`` (G,) the z with
    each of the record's ``JACKKNIFE_GROUPS`` contiguous parts left out in turn (the lag's
    jackknife)."""

    lag: float
    c: float
    se: float
    z: float
    zg: NDArray[np.float64]


def _z(view: CovView, mt: float) -> tuple[float, float, float]:
    c, se, _n = tempco_from_cov(view, mt)
    return c, se, (abs(c) / se if se > 0 and math.isfinite(se) else 0.0)


def _scan(Y: NDArray, T: NDArray, lags: Any, rate_hz: float,
          holes: list[tuple[int, int]] | None = None, ref: Any | None = None,
          floor_s: float = 0.0, parts: bool = False) -> list[list[ScanPoint]]:
    """Per axis, a ``ScanPoint`` for every lag: one set of Allan difference sums of
    (axes…, lagged T) per lag serves all axes (``octave_sums``: the covariance alone; the
    axes' EDF, which does not depend on the lag, from ``ref``, their Allan result, computed
    once), and with ``parts`` one per contiguous part for the lag's jackknife; ``holes``
    (blocks at this rate) and their settling left out; τ from ``min_tau_for(lag, floor_s)``."""
    C = Y.shape[1]
    if ref is None:
        ref = _axes_reference(Y, rate_hz)
    edf = np.asarray(ref.edf, dtype=float).reshape(len(ref.tau), -1)
    n_ref = np.asarray(ref.n, dtype=float)
    edges = np.linspace(0, len(Y), JACKKNIFE_GROUPS + 1).astype(int)
    out: list[list[ScanPoint]] = [[] for _ in range(C)]
    # without holes the axes' differences are the same at every lag: taken once
    axes = None if holes else axes_differences(
        Y, edges if parts else np.array([0, len(Y)]))
    for L in lags:
        u = lag_filter(T, float(L), rate_hz)
        if axes is not None:
            got = lag_octave_sums(axes, u, float(L), rate_hz)
            pieces = got if parts else []
            whole = sum(got[1:], start=got[0]) if parts else got[0]
        else:
            X = without_start(np.column_stack([Y, u]), float(L), rate_hz)
            keep = hole_mask(len(Y), holes or [], float(L), rate_hz)
            # with parts, the whole record's sums are theirs added up (every difference
            # goes to one part): one pass over the record, not two
            pieces = octave_sums_by_part(X, edges, keep) if parts else []
            whole = sum(pieces[1:], start=pieces[0]) if pieces else octave_sums(X, keep)
        sums = whole
        mt = min_tau_for(float(L), floor_s)
        # the leave-one-out sums once per lag, for every axis (their covariance is cached)
        rests = [whole - ps for ps in pieces]
        for j in range(C):
            c, se, z = _z(cov_view(sums, rate_hz, edf[:, j], n_ref, (j, C)), mt)
            zg = np.array([_z(cov_view(rest, rate_hz, edf[:, j], n_ref, (j, C)), mt)[2]
                           for rest in rests])
            out[j].append(ScanPoint(float(L), c, se, z, zg))
    return out


def _merge(a: list[ScanPoint], b: list[ScanPoint]) -> list[ScanPoint]:
    """Two scans of one axis as one, sorted by lag, each lag once (a refinement's end points
    are grid points: counted twice they made the lag's interval end at the estimate)."""
    return sorted({p.lag: p for p in [*a, *b]}.values(), key=lambda p: p.lag)


def _refine(lags: list[float], best: float, n: int) -> list[float]:
    """``n`` lags between the neighbours of ``best`` in the sorted ``lags`` (geometric on
    one side of 0, linear across it)."""
    i = lags.index(best)
    if i == 0 or i == len(lags) - 1:
        return []
    a, b = lags[i - 1], lags[i + 1]
    if a * b > 0:
        return (math.copysign(1.0, a) * np.geomspace(abs(a), abs(b), n)).tolist()
    return np.linspace(a, b, n).tolist()


#: Lags closer than this (relative) are one lag to the scan.
SAME_LAG_REL = 1e-9


def _distinct(cands: set[float], have: set[float]) -> list[float]:
    """The lags of ``cands`` (sorted) that are neither in ``have`` nor the same as one of
    them or as each other to ``SAME_LAG_REL``. Overlapping refinements of several axes give
    one lag twice up to rounding (geometric steps from different ends: 2002.8092465883267
    and …287 s on a 12 h quiet-lab record). Scanned twice, the two held the same z to
    1e-12: which of them took the largest z (and so where the next refinement went) was
    decided by rounding, and a parabola through the best lag and such a neighbour
    (``_peak``) put its vertex where rounding put it (the other channel's lag 1970 or
    2003 s by the order of a sum, on that record; 3 of 8 records moved their lag or a
    held-out χ² when a sum's rounding changed)."""
    out: list[float] = []
    ref = np.array(sorted(have), dtype=float)
    for v in sorted(cands):
        if np.any(np.abs(ref - v) <= SAME_LAG_REL * np.maximum(np.abs(ref), abs(v))):
            continue
        if out and abs(out[-1] - v) <= SAME_LAG_REL * max(abs(v), abs(out[-1])):
            continue
        out.append(v)
    return out


def _axes_reference(Y: NDArray, rate_hz: float) -> Any:
    """The axes' Allan result (analyze's estimator, its EDF) that the lag scan's regressions
    weight by."""
    sa = StreamingAllan(Y.shape[1], rate_hz)
    sa.update(Y)
    return sa.result()


def fit_thermal(y: NDArray, temps: NDArray, names: list[str], rate_hz: float) -> ThermalFit:
    """The thermal model of one axis ``y``: :func:`fit_thermal_axes` for a single column."""
    return fit_thermal_axes(np.asarray(y, dtype=float)[:, None], temps, names, rate_hz)[0]


def fit_thermal_axes(Y: NDArray, temps: NDArray, names: list[str], rate_hz: float,
                     holes: Holes | None = None, lag_intervals: bool = True,
                     paths: bool = False,
                     warmups: dict[int, tuple[float, ...]] | None = None,
                     grids: Sequence[tuple[float, float] | None] | None = None
                     ) -> list[ThermalFit]:
    """The thermal model of every axis of ``Y`` (M, C) (slow view at ``rate_hz``) against the
    temperature channels ``temps`` (M, k) °C named ``names`` (see module doc). ``holes``: per
    channel, the blocks its log says nothing about (the input screen's dropouts, stuck runs,
    masked readings), left out of its regression with the lag's settling after them.
    ``lag_intervals`` False: no jackknife of the lag (the held-out halves need only the
    estimates); the lag's interval is then the estimate itself. ``paths``: for each axis
    whose coupling passes its test, the thermal path beyond one lag chosen by held-out
    likelihood (``thermal_paths.choose_path``) on its driving channel, beside the warm-ups
    ``warmups`` (``with_paths``). ``grids``: each channel's (step K, origin) (None, or a
    None entry: the 12-bit default; ``screen.ScreenLog.rounding_grid``): each channel's
    regressor, rounding floor and coefficient's interval on its own step, so a coarse log
    leaves a finer channel's fit as it is."""
    holes = holes or {}
    Y = np.asarray(Y, dtype=float)
    gs = channel_grids(grids, np.asarray(temps).reshape(len(Y), -1).shape[1])
    # the rounding floors stay the readings' own (``coarse_regressor``)
    raw, temps = temps, coarse_regressor(temps, gs)
    record_s = len(Y) / rate_hz
    # the lag scan runs on at most SCAN_POINTS block means (a 60 h record: 8 s blocks; the
    # lags sought are minutes); the chosen lag is then fitted on the whole slow view
    f = 1 << max(0, math.ceil(math.log2(len(Y) / SCAN_POINTS)))
    m = (len(Y) // f) * f
    Ys = Y[:m].reshape(-1, f, Y.shape[1]).mean(axis=1)
    Ts = temps[:m].reshape(-1, f, temps.shape[1]).mean(axis=1)
    rate_s = rate_hz / f
    grid = _lag_grid(record_s, rate_s)
    scans: dict[int, list[list[ScanPoint]]] = {}
    ref = _axes_reference(Ys, rate_s)
    for j in range(temps.shape[1]):
        hj = [(a // f, b // f) for a, b in holes.get(j, [])]
        floor = rounding_floor_tau(raw[:m].reshape(-1, f, raw.shape[1]).mean(axis=1)[:, j],
                                   rate_s, step=gs[j][0])
        per_axis = [sorted(sc, key=lambda p: p.lag)
                    for sc in _scan(Ys, Ts[:, j], grid, rate_s, hj, ref, floor)]
        # coarse to fine: twice between the neighbouring lags of each axis's best
        for n_fine in (13, 9):
            fine: set[float] = set()
            for sc in per_axis:
                lags = [p.lag for p in sc]
                fine.update(_refine(lags, lags[int(np.argmax([p.z for p in sc]))], n_fine))
            new = _distinct(fine, {p.lag for sc in per_axis for p in sc})
            if new:
                extra = _scan(Ys, Ts[:, j], new, rate_s, hj, ref, floor)
                per_axis = [_merge(a, b) for a, b in zip(per_axis, extra, strict=True)]
        if lag_intervals:
            per_axis = _with_lag_jackknife(per_axis, grid, Ys, Ts[:, j], rate_s, hj, ref,
                                           floor)
        scans[j] = per_axis
    floors = {j: rounding_floor_tau(raw[:, j], rate_hz, step=gs[j][0]) for j in scans}
    # each channel's held-out regressors (``holdout.channel_heldout``), built once for every
    # axis that scores the channel at the same lag (the same slow view of the same channel)
    columns: dict[int, dict[Column, NDArray[np.float64]]] = {}
    fits = [_pick(Y[:, a], temps, names, rate_hz, {j: scans[j][a] for j in scans}, holes,
                  floors, columns, {j: g[0] for j, g in enumerate(gs)})
            for a in range(Y.shape[1])]
    fits = [coarse_gain_se(replace(ft, grid=gs[ft.channel_index]), raw, temps) for ft in fits]
    return with_paths(fits, Y, temps, holes, floors, warmups) if paths else fits


def with_paths(fits: list[ThermalFit], Y: NDArray, temps: NDArray, holes: Holes | None = None,
               floors: dict[int, float] | None = None,
               warmups: dict[int, tuple[float, ...]] | None = None,
               given: dict[int, tuple[NDArray, ...]] | None = None) -> list[ThermalFit]:
    """``fits`` (``fit_thermal_axes`` of the columns of ``Y``) each with the thermal path
    chosen on its driving channel (``thermal_paths.choose_path``), on every axis: a response
    the one lag cannot follow (quadratic, hysteresis) may fail the one-lag test and pass its
    own. ``floors``: each channel's rounding floor (τ s), computed when not given;
    ``warmups``: per axis, the time constants (s) of the warm-ups found on it, fitted as
    nuisance beside every candidate; ``given``: per axis, the signals of the transients found
    on it, each a nuisance column of free size beside every candidate (``choose_path``)."""
    Y = np.asarray(Y, dtype=float)
    if floors is None:
        # each driving channel's on its own step (``ThermalFit.grid``)
        floors = {f.channel_index: rounding_floor_tau(temps[:, f.channel_index], f.rate_hz,
                                                      step=f.grid[0]) for f in fits}
    # the path regressors of a channel, built once for all the axes it drives (the same
    # slow view of the same channel: the same columns)
    columns: dict[int, dict[Column, NDArray[np.float64]]] = {}
    out = []
    for a, f in enumerate(fits):
        # the path's candidates, their rounding floors and texts on the driving channel's
        # own step (``reading_grid``, read where the path modules have no argument for it)
        with reading_grid(f.grid):
            out.append(_with_path(f, Y[:, a], temps, holes, floors,
                                  columns.setdefault(f.channel_index, {}),
                                  (warmups or {}).get(a, ()), (given or {}).get(a, ())))
    return out


def _with_path(fit: ThermalFit, y: NDArray, temps: NDArray, holes: Holes | None,
               floors: dict[int, float], columns: dict[Column, NDArray[np.float64]] | None = None,
               warmups: tuple[float, ...] = (), given: tuple[NDArray, ...] = ()) -> ThermalFit:
    """``fit`` with the thermal path chosen on its driving channel; when the path is not one
    lag, its linear coupling's coefficient and first lag stand in for the one lag's."""
    from dataclasses import replace

    pf = path_of(fit, y, temps, holes, floors, columns, warmups, given)
    if pf.kind == "one_lag":
        return replace(fit, path=pf) if fit.passed else fit
    s = pf.chosen
    # an extension passed its own test (its extra term's z at the paths' share, held out
    # better than one lag and than nothing): on an axis whose one-lag z failed, that test is
    # the claim's
    test = {} if fit.passed else {"z": s.z_extra, "threshold": pf.z_threshold}
    # the path's se is its regression's: a coarse log's gain uncertainty (``coarse_gain_se``)
    # is added to it as to the one lag's
    b, se = float(s.beta[0]), float(s.beta_se[0])
    return replace(fit, path=pf, coefficient=b, coef_se=math.hypot(se, fit.gain_rel * b),
                   lag_s=float(s.theta[0]), lag_lo=float(s.theta_lo[0]),
                   lag_hi=float(s.theta_hi[0]), lag_open=s.open_end, **test)


def path_of(fit: ThermalFit, y: NDArray, temps: NDArray, holes: Holes | None,
            floors: dict[int, float] | None = None,
            columns: dict[Column, NDArray[np.float64]] | None = None,
            warmups: tuple[float, ...] = (), given: tuple[NDArray, ...] = ()) -> PathFit:
    """The path choice (``thermal_paths.choose_path``'s ``PathFit``) of axis ``y`` on
    ``fit``'s driving channel, started from ``fit``'s one lag; ``floors`` each channel's
    rounding floor (computed when not given)."""
    from avard.core.explain.thermal_paths import choose_path

    j = fit.channel_index
    if floors is None or j not in floors:
        floors = {**(floors or {}), j: rounding_floor_tau(temps[:, j], fit.rate_hz,
                                                          step=fit.grid[0])}
    keep = hole_mask(len(y), (holes or {}).get(j, []), max(abs(fit.lag_s), 60.0),
                     fit.rate_hz)
    ref = fit.allan
    edf = np.asarray(ref.edf, dtype=float)
    edf = edf[:, 0] if edf.ndim == 2 else edf
    # an extension that explain's held-out measure cannot test is refused only where it would
    # be the claim's whole basis (the one lag failed its own test): on a null axis a slow
    # relay at 1837 s on 4 h passed its extra term's z untested; where the one lag is
    # claimed, a second path through a long lag is the better reading and the verdict says
    # whether the held-out test could run
    return choose_path(y, temps[:, j], fit.rate_hz, fit.lag_s, np.asarray(ref.tau, float),
                       edf, floors.get(j, 0.0), keep, columns, warmups,
                       held_only=not fit.passed, given=given)


def _pick(y: NDArray, temps: NDArray, names: list[str], rate_hz: float,
          best: dict[int, list[ScanPoint]], holes: Holes | None = None,
          floors: dict[int, float] | None = None,
          columns: dict[int, dict[Column, NDArray[np.float64]]] | None = None,
          steps: dict[int, float] | None = None) -> ThermalFit:
    """The driving channel and lag of one axis from its scans, with the profile interval;
    ``columns``: per channel, the held-out regressors other axes built (``_choose_channel``);
    ``steps``: each channel's reading step (K; default the 12-bit)."""
    zmax = {j: max(s.z for s in sc) for j, sc in best.items()}

    def at_end(sc: list[ScanPoint]) -> bool:
        k = int(np.argmax([s.z for s in sc]))
        return k in (0, len(sc) - 1)

    # a channel whose lag sits at the end of the search (open) is preferred over one with an
    # interior optimum only when its z² is larger by OPEN_END_MARGIN
    def rank(j: int) -> float:
        return zmax[j] ** 2 - (OPEN_END_MARGIN if at_end(best[j]) else 0.0)

    jb = max(zmax, key=rank)
    compared: dict[str, dict[str, float]] = {}
    note = ""
    # a channel whose readings never stand above their own rounding at any τ (rounding
    # floor infinite: a plate that barely moves) has no τ to regress on: it cannot drive
    usable = {j: sc for j, sc in best.items()
              if math.isfinite((floors or {}).get(j, 0.0))}
    if len(usable) > 1:
        jb, compared, note = _choose_channel(y, temps, names, rate_hz, usable, holes, floors,
                                             columns, steps)
    elif len(usable) == 1:
        jb = next(iter(usable))
    scan = best[jb]
    k = int(np.argmax([s.z for s in scan]))
    # the lag its interval is about (the estimator the leave-one-out lags are), not the grid
    # point: the fine grid's step (≈ 1 s at −60 s) is as large as the lag's spread there
    L = best_lag(scan, k)
    mt = min_tau_for(L, (floors or {}).get(jb, 0.0))
    u = lag_filter(temps[:, jb], L, rate_hz)
    yu = without_start(np.column_stack([y, u]), L, rate_hz)
    keep = hole_mask(len(y), (holes or {}).get(jb, []), L, rate_hz)
    res = allan2(yu[:, 0], yu[:, 1], rate_hz, keep)
    ms = np.rint(np.asarray(res.tau, dtype=float) * rate_hz).astype(np.int64)
    # the test's analytic se from this regressor's own octave covariance (once per axis:
    # the scan compares lags and channels under one common covariance, ``_rho``, which a
    # regressor's own made unequal: a 20-min lag on the ambient channel lost to the plate
    # through 59 s, its smoother regressor's octaves more alike)
    # a channel below its rounding at every τ (an infinite floor: a half of a record whose
    # drive is a step or two of the readings) leaves the test no τ: nothing to test
    test = (coupling_test(res, octave_spectra(yu[:, 1], ms, mt * rate_hz), mt)
            if math.isfinite(mt) else CouplingTest(0.0, math.inf, 0, math.inf))
    c = test.c
    # the record's parts once, for ĉ's jackknife and the test combination's
    views = _jackknife_views(yu[:, 0], yu[:, 1], rate_hz, JACKKNIFE_GROUPS, keep, res)
    se_jk = _jackknife_se(*views, mt)[1]
    # the test reads its own combination of the octaves (``coupling_test``), with its own
    # jackknife: the larger of the two se, as the jackknife's parts may be shorter than the
    # noise's correlation at the regressor's period, where it is too small itself; the
    # interval is ĉ's, with the spectrum's level from the AVAR's slope (``coefficient_se``)
    c_t, se_t, se_jk_t = c, test.se, se_jk
    if test.weights:
        c_t, se_t = test.c_test, test.se_test
        se_jk_t = _jackknife_se(*views, mt, test.weights)[1]
    se_test = max(se_jk_t, se_t)
    z = abs(c_t) / se_test if se_test > 0 and math.isfinite(c_t) else 0.0
    se = coefficient_se(se_jk, test.se_interval)
    lag_lo, lag_hi, open_lo, open_hi = lag_interval(scan, k)
    # ĉ is the coefficient at the chosen lag; the lag is an estimate too, and for a lag long
    # against the cycle (ωL ≫ 1) the two trade off (c/√(1 + ω²L²) is what the data fix):
    # the coefficient's interval carries the lag's by the delta method, dĉ/dL from the scan
    # (the test's z stays the fixed-lag one: the lag search is in its threshold)
    if 0 < k < len(scan) - 1 and not (open_lo or open_hi):
        se = math.hypot(se, _coef_slope(scan, k, lag_lo, lag_hi) * 0.5 * (lag_hi - lag_lo))
    others = {}
    for j, sc in best.items():
        if j != jb:
            kk = int(np.argmax([s.z for s in sc]))
            others[names[j]] = {"z": sc[kk].z, "lag_s": sc[kk].lag, "coefficient": sc[kk].c,
                                **compared.get(names[j], {})}
    return ThermalFit(names[jb], jb, c, se, L, min(lag_lo, L), max(lag_hi, L), z, rate_hz,
                      others, res, lag_open=open_hi or (open_lo and scan[0].lag < 0),
                      threshold=test.threshold, threshold_dof=test.dof,
                      scan_z=scan[k].z, channel_choice=compared.get(names[jb], {}),
                      channel_note=note)


#: How much lower a channel's held-out −2 ln L (``holdout.channel_heldout``) must be for it
#: to drive an axis rather than another channel: at least the margin ``thermal_paths`` asks
#: of a path over one lag (``HELDOUT_MARGIN``) ...
CHANNEL_MARGIN = 6.0
#: ... or this many standard errors of the difference, from its spread over the record's
#: parts (``holdout.ChannelPath.versus``): two channels that both describe the path differ
#: in held-out −2 ln L by the record's noise on a scale that grows with the coupling, not
#: by the fixed margin a nested model's extra term is held to. Student's t with the parts'
#: 9 degrees of freedom at 5 %, two-sided. To either is added what the readings' 0.0625 K
#: rounding through the worse channel's coupling makes up of its held-out deviance beyond
#: the better one's (``ChannelPath.rounding``): an error of the regressor, not of the path,
#: which a channel seen through a long lag smooths away.
CHANNEL_T = t_two_sided(0.05, 9)


def path_distance(lag_s: float) -> float:
    """How far a channel is from the die along the heat's path, for a lag of either sign: a
    positive lag is the lag itself (the channel upstream of the die); a negative lag −a is
    the lead-lag of a logged sensor 2a and a die a behind one point (``lag_filter``), so the
    path from the channel to the die runs back through that point, 3a long."""
    return lag_s if lag_s >= 0 else 3.0 * abs(lag_s)


def _choose_channel(y: NDArray, temps: NDArray, names: list[str], rate_hz: float,
                    best: dict[int, list[ScanPoint]], holes: Holes | None,
                    floors: dict[int, float] | None,
                    columns: dict[int, dict[Column, NDArray[np.float64]]] | None = None,
                    steps: dict[int, float] | None = None
                    ) -> tuple[int, dict[str, dict[str, float]], str]:
    """The channel that drives axis ``y``, by the held-out likelihood of each channel
    through its own lag (``holdout.channel_heldout``), not by the scan's z: (its index, per
    channel name what was compared, a note when the record does not tell channels apart).

    A channel whose scan's best lag sits at the end of the lags tried (open) pays
    ``OPEN_END_MARGIN`` beside one with an interior optimum. Channels whose held-out −2 ln L
    is within ``max(CHANNEL_MARGIN, CHANNEL_T·se)`` of the best, plus what the readings'
    rounding makes up of it beyond the best's (``ChannelPath.rounding``), describe the axis
    equally:
    the room seen through the plate's long lag is the plate's own path, and on a record
    that holds nothing the plate does not pass on, the two cannot be told apart (a long lag
    also filters the readings' rounding, so the farther channel often predicts a little
    better). Among those the more direct path is reported, by one fixed order, never by
    the record's luck: an interior optimum before an open one, then the channel nearest
    the die along the heat's path (``path_distance``: a longer lag on another channel is
    that path with the lags between them added, and a lag long against the drive's period
    trades with its coefficient, which it leaves unresolved), then the lower held-out
    −2 ln L. ``columns``: per channel, the held-out regressors already built for another axis
    (``holdout.channel_heldout``)."""
    from avard.core.explain.holdout import channel_heldout

    ks = {j: int(np.argmax([s.z for s in sc])) for j, sc in best.items()}
    lags0 = {j: best_lag(sc, ks[j]) for j, sc in best.items()}
    is_open = {j: ks[j] in (0, len(sc) - 1) for j, sc in best.items()}
    interior = not all(is_open.values())
    hp = channel_heldout(y, temps, lags0, rate_hz, floors, holes, columns, steps)
    # a channel whose held-out fit gave no number (NaN) can neither win nor tie
    cost = {j: (hp[j].heldout if math.isfinite(hp[j].heldout) else math.inf)
            + (OPEN_END_MARGIN if is_open[j] and interior else 0.0) for j in best}
    dist = {j: path_distance(lags0[j]) for j in best}
    j0 = min(cost, key=lambda j: (cost[j], dist[j]))
    spread = {j: hp[j].versus(hp[j0])[1] for j in best}
    need = {j: max(CHANNEL_MARGIN, CHANNEL_T * spread[j])
            + max(0.0, hp[j].rounding - hp[j0].rounding) for j in best}
    tied = [j0, *(j for j in best if j != j0 and cost[j] <= cost[j0] + need[j])]
    jb = min(tied, key=lambda j: (is_open[j], dist[j], cost[j]))
    compared = {names[j]: {"heldout": hp[j].heldout, "heldout_lag_s": lags0[j],
                           "heldout_coefficient": hp[j].coefficient,
                           "heldout_margin_vs_best": need[j],
                           "heldout_rounding": hp[j].rounding, "scan_z": best[j][ks[j]].z,
                           "open": float(is_open[j])}
                for j in best}
    note = ""
    if len(tied) > 1:
        others = [j for j in tied if j != jb]
        who = " and ".join(f"'{names[j]}' (through {lags0[j]:.4g} s)" for j in others)
        note = (f"{who} describe{'s' if len(others) == 1 else ''} the axis as well (held-out "
                f"−2 ln L within {max(need[j] for j in tied):.3g} of the best: "
                f"{CHANNEL_MARGIN:g} or {CHANNEL_T:.3g} standard errors of the difference "
                "over the record's parts, and the readings' rounding's share): this record "
                f"cannot tell the channels apart; '{names[jb]}', the more direct path (the "
                "nearest the die, interior), is reported, the other channel being that path "
                "seen through the lags between them, whose coefficient trades with its lag")
    elif jb != max(best, key=lambda j: best[j][ks[j]].z):
        note = (f"'{names[jb]}' predicts the held-out halves better than the channel of "
                "the larger scan z, by more than the margin")
    return jb, compared, note


def _coef_slope(scan: list[ScanPoint], k: int, lo: float, hi: float) -> float:
    """dĉ/dL over the lag's interval [lo, hi]: the least-squares slope of ĉ on the lags in it
    (the neighbours of ``k`` when fewer than three): ĉ jumps with z where a negative lag's
    shortest τ drops an octave, and the neighbours' difference across such a jump, times the
    interval's half-width, made a coefficient ±150 % wide."""
    x = np.array([p.lag for p in scan if lo <= p.lag <= hi])
    if len(x) < 3 or np.ptp(x) <= 0:
        return (scan[k + 1].c - scan[k - 1].c) / (scan[k + 1].lag - scan[k - 1].lag)
    c = np.array([p.c for p in scan if lo <= p.lag <= hi])
    return float(np.polyfit(x, c, 1)[0])


#: Coarse-grid lags either side of an axis's best lag that its lag's jackknife spans: the
#: leave-one-out best lags must have room to move (between the first neighbours only, a lag
#: of 0 s known to ±20 s at the HVAC period had a window of −16…−10 s, and the picks piled at
#: its ends).
JACKKNIFE_SPAN = 2
#: … and at least the lags round the best whose z is within this fraction of the largest: the
#: lag's uncertainty is in seconds, the coarse grid geometric, so near 0 two neighbours span
#: a few seconds where the z² over the lags is flat over tens.
JACKKNIFE_Z_DROP = 0.05


def _with_lag_jackknife(per_axis: list[list[ScanPoint]], grid: NDArray, Ys: NDArray,
                        T: NDArray, rate_hz: float, holes: list[tuple[int, int]], ref: Any,
                        floor: float) -> list[list[ScanPoint]]:
    """Each axis's scan with the parts' z (``ScanPoint.zg``) on the lags of its own window:
    those within ``JACKKNIFE_SPAN`` coarse-grid lags of its best, widened to the run of lags
    round it whose z is within ``JACKKNIFE_Z_DROP`` of the best's. One scan of the parts'
    sums serves the union of the windows (they cost a scan each: not the whole grid), each
    axis takes the points of its own window only (the union's other stretches made its
    leave-one-out lags jump between two windows). The points' own (lag, ĉ, se, z) stay the
    scan's: the estimate is not changed by its interval."""
    g = sorted(float(v) for v in grid)
    windows = []
    for sc in per_axis:
        k = int(np.argmax([p.z for p in sc]))
        b, z_min = sc[k].lag, (1.0 - JACKKNIFE_Z_DROP) * sc[k].z
        below = [v for v in g if v < b][-JACKKNIFE_SPAN:] or [b]
        above = [v for v in g if v > b][:JACKKNIFE_SPAN] or [b]
        lo, hi = k, k
        while lo > 0 and sc[lo - 1].z >= z_min:
            lo -= 1
        while hi < len(sc) - 1 and sc[hi + 1].z >= z_min:
            hi += 1
        # as far either side as the farther run end: the run stops at a jump of z (a
        # negative lag's shortest τ moving an octave), which the parts' regressions,
        # on one shortest τ, do not have
        w = max(b - below[0], above[-1] - b, b - sc[lo].lag, sc[hi].lag - b)
        windows.append((b - w, b + w))
    lags = sorted({p.lag for sc, (w0, w1) in zip(per_axis, windows, strict=True)
                   for p in sc if w0 <= p.lag <= w1})
    jk = _scan(Ys, T, lags, rate_hz, holes, ref, floor, parts=True)
    out = []
    for sc, parts, (w0, w1) in zip(per_axis, jk, windows, strict=True):
        zg = {p.lag: p.zg for p in parts if w0 <= p.lag <= w1}
        out.append([p._replace(zg=zg[p.lag]) if p.lag in zg else p for p in sc])
    return out


#: The lag estimator's kernel reaches from the largest z to the farther of the lags either
#: side where z² has fallen to this fraction of its largest (``_kernel_width``): the
#: profile's top, where 1/z² is a parabola in the lag. Wider, the quadratic reads the
#: profile's flanks, which are not symmetric (a lag acts through its phase, atan(ωL)): on
#: the typical-tempco records, whose z² is flat within 2 % over hundreds of seconds, a kernel
#: to where z² halves put 3 of 40 lags beyond 20 % of the truth (1 of 40 at this width, as
#: the three-point vertex).
LAG_KERNEL_DROP = 0.98
#: Times the kernel is re-centred on its own vertex.
LAG_KERNEL_STEPS = 3


def _lag_support(scan: list[ScanPoint]) -> list[ScanPoint]:
    """The lags the lag estimator reads: those that carry the parts' z (the jackknife's
    window, ``_with_lag_jackknife``), so the record and its leave-one-out parts are read on
    the same lags; all of them when there are fewer than three (no jackknife)."""
    sub = [p for p in scan if len(p.zg)]
    return sub if len(sub) >= 3 else list(scan)


def _kernel_width(x: NDArray, f: NDArray, k: int) -> float:
    """The kernel's half-width: from ``x[k]`` (the least ``f`` = 1/z²) to the farther of the
    nearest lags either side where ``f`` has risen to ``f[k]/LAG_KERNEL_DROP`` (the end of
    ``x`` where it never does), at least the next lag either side."""
    lim = f[k] / LAG_KERNEL_DROP
    lo = np.flatnonzero(f[:k] >= lim)
    hi = np.flatnonzero(f[k + 1:] >= lim)
    dl = x[k] - (x[lo[-1]] if len(lo) else x[0])
    dh = (x[k + 1 + hi[0]] if len(hi) else x[-1]) - x[k]
    step = max(x[min(k + 1, len(x) - 1)] - x[k], x[k] - x[max(k - 1, 0)])
    return float(max(dl, dh, step)) * (1.0 + 1e-9)


def _lag_vertex(x: NDArray, z: NDArray, k: int, h: float) -> tuple[float, bool]:
    """(lag, at an end): the vertex of the local quadratic of 1/z² over the lags ``x``, a
    biweight kernel of half-width ``h`` centred at ``x[k]`` and re-centred on its own vertex
    ``LAG_KERNEL_STEPS`` times; "at an end" when the vertex leaves ``x`` (kept on its end)
    or the quadratic opens downwards (then the lag of the largest z).

    1/z² is what the lag's profile likelihood moves with: a regression of y on the lagged
    channel leaves the share 1/(1 + z²/ν) ≈ ν/z² of the axis's variance, −2 ln L = ν ln of
    it, and a lag off by δ adds ∝ δ² to that share. It is a parabola round its least where
    z² itself is a sharp peak (1/(a + bδ²)): a parabola in z² over the jackknife's window
    (−95…−25 s round a −60 s lag) sat 10–20 s off the peak, and a three-point vertex sits on
    the fine grid's jags (z² is jagged at the grid's step: the readings' rounding smoothed a
    little more or less). The kernel weighs the points the data hold the lag by, smoothly,
    so the same function of the data serves the record and each leave-one-out part."""
    z = np.asarray(z, dtype=float)
    f = 1.0 / np.maximum(z * z, 1e-300)
    c = float(x[k])
    i = int(np.argmax(z))
    for _ in range(LAG_KERNEL_STEPS):
        u = (x - c) / h
        w = np.where(np.abs(u) < 1.0, (1.0 - u * u) ** 2, 0.0)
        on = w > 0
        if np.count_nonzero(on) < 3:
            break
        xs, fs, ws = x[on], f[on], np.sqrt(w[on])
        xm, sc = float(np.mean(xs)), float(np.ptp(xs)) or 1.0
        t = (xs - xm) / sc
        # scaled by the least f: 1/z² spans 1e-5…1e-2 between records
        A = np.column_stack([t * t, t, np.ones_like(t)]) * ws[:, None]
        qa, qb, _qc = np.linalg.lstsq(A, fs / f[i] * ws, rcond=None)[0]
        if not qa > 0:
            return float(x[i]), i in (0, len(x) - 1)
        c = xm - sc * qb / (2.0 * qa)
        if not x[0] < c < x[-1]:
            return float(np.clip(c, x[0], x[-1])), True
    return float(c), False


def _lag_estimate(scan: list[ScanPoint]) -> tuple[float, NDArray[np.float64], int, float]:
    """(lag, the support's lags, the index there of the largest z, kernel half-width) of a
    scan: ``_lag_vertex`` on ``_lag_support``."""
    sub = _lag_support(scan)
    x = np.array([p.lag for p in sub], dtype=float)
    z = np.array([p.z for p in sub], dtype=float)
    k = int(np.argmax(z))
    h = _kernel_width(x, 1.0 / np.maximum(z * z, 1e-300), k)
    return _lag_vertex(x, z, k, h)[0], x, k, h


def best_lag(scan: list[ScanPoint], k: int) -> float:
    """The axis's lag from its scan: the vertex of the local quadratic of 1/z² round the
    largest z (``_lag_vertex``), on the lags its jackknife reads, the same estimator each
    leave-one-out part's lag is (``lag_interval``). Not the grid point (the fine grid's
    step, ≈ 1 s at −60 s, is as wide as the lag's spread there), and not a different
    estimator from the interval's: a three-point vertex reported beside the jackknife of a
    window's parabola sat about the interval's half-width from its centre, and the
    negative-lag records' intervals held the truth in 50 %. ``k`` (the grid index of the
    largest z) is not used: the support's own largest is."""
    return _lag_estimate(scan)[0]


def lag_interval(scan: list[ScanPoint], k: int) -> tuple[float, float, bool, bool]:
    """(low, high, open low, open high): the lag's 68 % interval, the best lag (``best_lag``)
    ± t₀.₈₄(G−1) times its delete-a-group jackknife standard error: the same estimator on
    the z of the record with each of its ``JACKKNIFE_GROUPS`` parts left out (``ScanPoint.
    zg``, ``_with_lag_jackknife``), the same lags and kernel width, se² = (G−1)/G·Σ(L_(−g) −
    mean)², a t quantile for its G − 1 degrees of freedom, with the readings' time uncertainty
    ``READ_TIME_S`` added in quadrature (no part moves it); never narrower than half the grid's
    step either side of the lag (the lags tried resolve no finer); without the parts' z the
    estimate alone. A leave-one-out lag on the support's end carries that end of the
    interval to the support's end at least; open when that is the first or last lag tried.

    Not the profile of the analytic z² over the lags: the regressor carries noise the axis
    does not (the readings' rounding, the logger's own noise), and smoothing it away by a
    longer trial lag raises z² by a share of z² itself (≈ 500 at z 22), far above the Δ = 1
    that draws the interval: a true lag 0 came out at 26 s [24.7, 28.8] (68 %), and the
    intervals of 32 records held the true lag in none. The jackknife measures how far the
    best lag moves with the data, whatever moves it."""
    lags = [p.lag for p in scan]
    best, sl, kk, h = _lag_estimate(scan)
    sub = [p for p in scan if len(p.zg)]
    if len(sub) < 3:
        return best, best, k == 0, k == len(scan) - 1
    zg = np.array([p.zg for p in sub])  # (lags, G)
    G = zg.shape[1]
    picks = [_lag_vertex(sl, zg[:, g], kk, h) for g in range(G)]
    lg = np.array([p[0] for p in picks])
    se = math.sqrt((G - 1) / G * float(np.sum((lg - lg.mean()) ** 2)))
    se *= t_two_sided(0.32, G - 1)  # t₀.₈₄ of the jackknife's G − 1 dof
    # the readings' own time: a systematic no part of the record moves, so no jackknife sees
    se = math.hypot(se, READ_TIME_S)
    # the grid's resolution: half way to the lags tried either side of the estimate
    i = int(np.searchsorted(lags, best))
    below = best - lags[i - 1] if i > 0 else 0.0
    above = lags[i] - best if i < len(lags) and lags[i] > best else (
        lags[i + 1] - best if i + 1 < len(lags) else 0.0)
    lo, hi = best - max(se, 0.5 * below), best + max(se, 0.5 * above)
    # a leave-one-out lag on the support's end says the lag may be beyond it: that end of
    # the interval reaches the support's end at least, and is open when that is the
    # search's end
    at_lo = any(p[1] and p[0] <= sl[0] for p in picks)
    at_hi = any(p[1] and p[0] >= sl[-1] for p in picks)
    lo = min(lo, float(sl[0])) if at_lo else lo
    hi = max(hi, float(sl[-1])) if at_hi else hi
    open_lo = k == 0 or (at_lo and sl[0] <= lags[0])
    open_hi = k == len(scan) - 1 or (at_hi and sl[-1] >= lags[-1])
    return lo, hi, open_lo, open_hi


def min_detectable_tempco(n_white: float, b_inst: float, k_rrw: float, record_s: float,
                          amplitude_c: float, period_s: float, lag_s: float,
                          z: float = Z_TEMPERATURE, lag_rel: float | None = None) -> float:
    """Smallest coefficient (m/s²/K) the temperature test detects (z ≥ ``z`` on average) for a
    logged ±``amplitude_c`` sinusoid of ``period_s`` reaching the sensor through a first-order
    lag ``lag_s``, on noise N (m/s/√s), B (m/s²), K (m/s²·√s) over ``record_s``. With
    ``lag_rel``, the coefficient at which the lag's standard error is ``lag_rel``·lag instead.

    Derivation: the sensor sees a sinusoid of amplitude a = c·A/√(1 + ω²L²). A sinusoid's
    amplitude in noise of one-sided PSD S(f0) over T is known to σ_a = √(2·S(f0)/T), and with
    NIST SP 1065 Table 5, S(f) = 2N² + B²/(πf) + K²/(2π²f²) (white, flicker, random-walk rate
    noise whose AVAR is N²/τ, (2 ln2/π)B², K²τ/3). So z = a/σ_a and
    c_min = z·σ_a·√(1 + ω²L²)/A. The phase −atan(ωL) carries the lag: σ_φ = 1/z, hence
    σ_L/L = (1 + ω²L²)/(ωL·z).
    """
    s_f0 = noise_psd(1.0 / period_s, n_white, b_inst, k_rrw)
    sigma_a = math.sqrt(2 * s_f0 / record_s)
    wl = 2 * math.pi * lag_s / period_s
    if lag_rel is not None:
        z = (1 + wl**2) / (wl * lag_rel) if wl > 0 else math.inf
    return z * sigma_a * math.hypot(1.0, wl) / amplitude_c

"""A slow sinusoid found on the record's block means, handed to the printed EDF (issue 24).

A sinusoid of a few cycles per record adds a nearly deterministic part to the Allan variance
at long τ. Read as noise it is given the noise's EDF, and the printed intervals over-cover
(the coverage benchmark's "sine" rows: up to 87.5–90 %). Welch's line finder cannot see it:
its segments are at most an eighth of the record and it tests from their 7th bin on, i.e.
from (``LINE_LOBE`` + 5)·N/nperseg cycles per record. This module searches the band below,
from ``FROM_CYCLES`` up to there (at most ``TOP_SHARE`` of the block means' count, where
their averaging has not yet bent a sinusoid), on the block means the OADEV pass already
carries for the drift test (``drift.BlockMeans``, ≤ 256 means of the longest stretch without
a gap): no channel is read again.

**The test.** The Gaussian likelihood of the means under white, flicker and random-walk
noise (``drift.block_noise_cov``, as block means hold it; N and B at the AVAR fit's point
values, K *profiled* over
the drift test's range, four decades below to ``drift.K_SPAN`` times past the fit's upper K)
with an offset and a slope (a drift is not a sinusoid) against the same with a sinusoid of
free phase at frequency f: Λ(f) = −2 ln L₀ + 2 ln L₁, each with its own best K. Λ(f) is
χ²₂ at one f under the noise alone; its largest over the band must pass ``threshold``, the
level the largest of a χ²₂ process over W cycles per record passes with chance ``LEVEL``
(Rice's upcrossings, Davies 1987: the look-elsewhere cost). Why not against the fitted noise
at its upper bound (branch sine24): that noise holds the sinusoid's own AVAR (the fit gives
it to the random walk), so it hid every sinusoid of the 1 h and most of the 12 h records;
with K profiled the likelihood takes the walk only as far as the means themselves want it.

**Why it is cheap.** The drift test's whitening (``drift._Profile``: one Cholesky factor and
one eigen-decomposition) makes every K's covariance diagonal, so each K's statistic at every
frequency is a handful of weighted sums, one matrix product over the K grid per sum. The
band is scanned on a half-cycle grid and the best few peaks refined.

**What is resolved.** A peak past the threshold whose frequency interval (Λ within 1 of its
peak: profile likelihood, 68 %) lies inside the band, with its amplitude's lower 1σ above
zero. Its amplitude is the GLS one at the peak, less the noise's share of |â|² (its bias),
with the noise's standard deviation along â, corrected for the block average's
attenuation; both uncertainties carry into the AVAR (``avar_cov``). A sinusoid slower than
``FROM_CYCLES`` or at the band's top is said, not claimed.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from avard.core.allan.deviations import AllanResult
    from avard.core.model.fit import NoiseFit

__all__ = ["FROM_CYCLES", "LEVEL", "SlowSearch", "SlowSine", "avar_cov", "resolve_slow_sine",
           "search_slow_sine", "threshold", "welch_top_hz"]

#: The slowest frequency searched and resolved, in cycles per record (a period of half the
#: record: slower, a sinusoid is not told from the walk and the slope).
FROM_CYCLES = 2.0
#: The fastest searched is at most this share of the block means' count (their Nyquist is
#: half of it; above, the averaging bends and aliases a sinusoid).
TOP_SHARE = 0.4
#: The chance the largest statistic over the band passes the threshold on noise alone.
LEVEL = 0.01
#: The coarse grid's step (cycles per record) and how many of its peaks are refined.
COARSE_STEP, PEAKS = 0.5, 3
#: The refinement: ± this many cycles about a coarse peak, at this step.
FINE_HALF, FINE_STEP = 0.75, 1.0 / 32.0
#: K's profile: points on the drift test's range (``drift.K_SPAN``, ``drift.K_DECADES``).
K_POINTS = 25
#: A candidate is confirmed with the flicker's B profiled over these factors of the fit's.
B_FACTORS = (0.5, 0.71, 1.41, 2.0)
#: A line the Welch finder found within this many of its bins of a slow sinusoid is it.
LINE_BINS = 3.0
#: Fewest block means searched (as the drift test).
MIN_MEANS = 32


def welch_top_hz(n_samples: int, rate_hz: float) -> float:
    """The lowest frequency (Hz) Welch's line finder tests on a record of ``n_samples``:
    bin ``LINE_LOBE`` + 5 of analyze's segment (``spectrum.find_lines``)."""
    from avard.core.analysis.spectrum import LINE_LOBE, welch_nperseg

    return (LINE_LOBE + 5) * float(rate_hz) / welch_nperseg(int(n_samples))


def threshold(width_cycles: float, level: float = LEVEL) -> float:
    """The u that the largest χ²₂ statistic over a band of ``width_cycles`` cycles per record
    passes with chance at most ``level`` under the noise alone: P ≤ e^{−u/2}(1 +
    √(π/6)·W·√u), the chance at one frequency plus the statistic's expected upcrossings
    over the band (Rice; Davies 1987), whose correlation is a record-long window's (second
    spectral moment (2πT)²/12)."""
    c = math.sqrt(math.pi / 6.0) * max(width_cycles, 0.0)
    lo, hi = 0.0, 400.0
    for _ in range(80):  # bisection: the bound falls with u
        u = 0.5 * (lo + hi)
        if math.exp(-u / 2.0) * (1.0 + c * math.sqrt(u)) > level:
            lo = u
        else:
            hi = u
    return hi


@dataclass(frozen=True)
class SlowSine:
    """A slow sinusoid resolved on the block means: frequency (Hz) and amplitude (input unit,
    m/s² for acceleration), each with its 68 % interval; ``cycles`` in the record searched."""

    frequency_hz: float
    frequency_lo_hz: float
    frequency_hi_hz: float
    amplitude: float
    amplitude_lo: float
    amplitude_hi: float
    cycles: float
    #: its GLS cosine and sine coefficients on the block means searched (centres t_i, phase
    #: 2π·``cycles``·t_i/T, block-averaged as the means hold it): what ``less_sine`` takes off
    means_coef: tuple[float, float] = (0.0, 0.0)

    def less_sine(self, means: NDArray, block_s: float) -> NDArray[np.float64]:
        """``means`` (the block means searched, each ``block_s`` long) less this sinusoid
        as they hold it."""
        yb = np.asarray(means, dtype=float).reshape(-1)
        t = (np.arange(len(yb)) + 0.5) * block_s
        arg = 2.0 * np.pi * self.cycles * t / (len(yb) * block_s)
        c, s = self.means_coef
        return np.asarray(yb - c * np.cos(arg) - s * np.sin(arg))

    @property
    def label(self) -> str:
        """The fit component's label (as ``fit_noise`` names a sinusoid)."""
        return f"sinusoid {self.frequency_hz:.6g} Hz"


@dataclass(frozen=True)
class SlowSearch:
    """One channel's search: ``sine`` when one is resolved; ``note`` says what was found or
    why nothing is claimed; the band (cycles per record), the largest statistic (χ²₂ at
    one frequency) and the threshold it had to pass, where it peaked (Hz)."""

    sine: SlowSine | None
    note: str
    band_cycles: tuple[float, float] = (math.nan, math.nan)
    statistic: float = math.nan
    threshold: float = math.nan
    best_hz: float = math.nan

    def to_dict(self) -> dict[str, object]:
        def num(v: float) -> float | None:
            return v if math.isfinite(v) else None

        d: dict[str, object] = {
            "note": self.note,
            "band_cycles_per_record": [num(v) for v in self.band_cycles],
            "statistic": num(self.statistic), "threshold": num(self.threshold),
            "units": {"frequency_hz": "Hz", "amplitude": "m/s^2",
                      "statistic": "1 (chi2, 2 dof, at one frequency)"}}
        s = self.sine
        if s is not None:
            d.update({"frequency_hz": s.frequency_hz,
                      "frequency_interval_hz": [s.frequency_lo_hz, s.frequency_hi_hz],
                      "amplitude": s.amplitude,
                      "amplitude_interval": [s.amplitude_lo, s.amplitude_hi],
                      "cycles_per_record": s.cycles})
        return d


class _Scan:
    """Λ(f) with K profiled, on block means whitened once (``drift._Profile``)."""

    def __init__(self, yb: NDArray, block_s: float, n_white: float, b_inst: float,
                 k_scale: float, gm: tuple[float, float] | None = None) -> None:
        from avard.core.analysis.drift import K_DECADES, K_SPAN, _Profile

        j = len(yb)
        self.t = (np.arange(j) + 0.5) * block_s
        self.record_s = j * block_s
        self.gm = gm
        self.prof = _Profile(yb, self.t, block_s, n_white, b_inst, gm)
        top = K_SPAN * max(float(k_scale), n_white / self.record_s)
        ks = np.concatenate([[0.0], np.geomspace(top * 10.0**-K_DECADES, top, K_POINTS)])
        s = 1.0 + np.outer(ks * ks, self.prof.lam)  # (K, J): each K's covariance, rotated
        self.w = 1.0 / s
        self.logdet = self.prof.logdet0 + np.sum(np.log(s), axis=1)
        x0 = self.prof.white(np.column_stack([np.ones(j), self.t - self.t.mean()]))
        r = self.prof.wy
        self.x0, self.r = x0, r
        # H0 (offset and slope) at every K
        a00 = np.einsum("kj,ja,jb->kab", self.w, x0, x0)
        self.b0 = self.w @ (x0 * r[:, None])  # (K, 2)
        self.a00_inv = np.linalg.inv(a00)
        chi0 = self.w @ (r * r) - np.einsum("ka,kab,kb->k", self.b0, self.a00_inv, self.b0)
        self.nll0 = self.logdet + chi0

    def at(self, cycles: NDArray) -> tuple[NDArray, NDArray, NDArray]:
        """(Λ at each frequency (cycles per record), the sinusoid's two GLS coefficients
        (F, 2) and their covariance (F, 2, 2) at the best K there). Every K at once: each
        sum over the means is one product with the K grid's weights (K, J); the offset and
        slope are partialled out by their Schur complement, element by element."""
        arg = 2.0 * np.pi * np.outer(self.t / self.record_s, cycles)
        wc = self.prof.white(np.column_stack([np.cos(arg), np.sin(arg)]))
        f = len(cycles)
        c, s = wc[:, :f], wc[:, f:]
        w, x0, r = self.w, self.x0, self.r
        gcc, gss, gcs = w @ (c * c), w @ (s * s), w @ (c * s)  # (K, F)
        wr, w0, w1 = w * r, w * x0[:, 0], w * x0[:, 1]
        ec, es = wr @ c, wr @ s
        c0, c1, s0, s1 = w0 @ c, w1 @ c, w0 @ s, w1 @ s
        p = self.a00_inv
        p00, p01, p11 = p[:, 0, 0, None], p[:, 0, 1, None], p[:, 1, 1, None]
        pc0, pc1 = c0 * p00 + c1 * p01, c0 * p01 + c1 * p11
        ps0, ps1 = s0 * p00 + s1 * p01, s0 * p01 + s1 * p11
        gcc = gcc - (pc0 * c0 + pc1 * c1)
        gss = gss - (ps0 * s0 + ps1 * s1)
        gcs = gcs - (pc0 * s0 + pc1 * s1)
        b00, b01 = self.b0[:, 0, None], self.b0[:, 1, None]
        ec = ec - (pc0 * b00 + pc1 * b01)
        es = es - (ps0 * b00 + ps1 * b01)
        det = gcc * gss - gcs * gcs
        with np.errstate(divide="ignore", invalid="ignore"):
            red = (gss * ec * ec - 2.0 * gcs * ec * es + gcc * es * es) / det
        red = np.where(np.isfinite(red), red, 0.0)
        best = np.argmax(red - self.nll0[:, None], axis=0)  # the K with the least −2 ln L₁
        i = np.arange(f)
        stat = float(np.min(self.nll0)) - (self.nll0[best] - red[best, i])
        d, a, b, e1 = det[best, i], gcc[best, i], gss[best, i], gcs[best, i]
        cov = np.empty((f, 2, 2))
        cov[:, 0, 0], cov[:, 1, 1] = b / d, a / d
        cov[:, 0, 1] = cov[:, 1, 0] = -e1 / d
        e2 = np.stack([ec[best, i], es[best, i]], axis=-1)
        coef = np.einsum("fij,fj->fi", cov, e2)
        return np.maximum(stat, 0.0), coef, cov


def search_slow_sine(means: NDArray, block_s: float, n_white: float, b_inst: float,
                     k_scale: float, top_hz: float, *, level: float = LEVEL,
                     gm: tuple[float, float] | None = None) -> SlowSearch:
    """A slow sinusoid in one channel's block means (``means``, each over ``block_s``
    seconds, consecutive) from ``FROM_CYCLES`` cycles per record to ``top_hz`` (at most
    ``TOP_SHARE`` of the means' count), against white N, flicker B (the fit's values) and a
    random walk profiled up to ``drift.K_SPAN``·max(``k_scale``, N/T) (module docstring).
    ``gm``: a Gauss–Markov process (σ, T) known beside the noise (explain, once one is
    claimed), held in the fixed covariance: left out, its variance goes to the profiled
    walk, whose red spectrum hides a slow sinusoid. The threshold is unchanged: Λ(f) is
    χ²₂ at one f under whatever noise the covariance holds."""
    yb = np.asarray(means, dtype=float).reshape(-1)
    j = len(yb)
    if j < MIN_MEANS or not np.all(np.isfinite(yb)) or not n_white > 0:
        return SlowSearch(None, "not searched: too few block means or no white level")
    record_s = j * block_s
    top = min(float(top_hz) * record_s, TOP_SHARE * j)
    if top < FROM_CYCLES + 2.0:
        return SlowSearch(None, "not searched: the band below the line finder's is empty")
    band = (FROM_CYCLES, top)
    thr = threshold(top - FROM_CYCLES, level)
    try:
        scan = _Scan(yb, block_s, n_white, b_inst, k_scale, gm)
    except np.linalg.LinAlgError:
        return SlowSearch(None, "not searched: the noise covariance would not factor", band)
    grid = np.arange(FROM_CYCLES, top + 1e-9, COARSE_STEP)
    coarse = scan.at(grid)[0]
    # the coarse grid's local maxima, largest first, refined on a fine grid each
    peak = (coarse >= np.r_[-np.inf, coarse[:-1]]) & (coarse >= np.r_[coarse[1:], -np.inf])
    order = [int(k) for k in np.flatnonzero(peak)[np.argsort(-coarse[peak])][:PEAKS]]
    best: tuple[float, NDArray, NDArray, NDArray, NDArray] | None = None
    for k in order:
        fine = np.arange(max(FROM_CYCLES, grid[k] - FINE_HALF),
                         min(top, grid[k] + FINE_HALF) + 1e-9, FINE_STEP)
        st, coef, cov = scan.at(fine)
        if best is None or float(st.max()) > best[0]:
            best = (float(st.max()), fine, st, coef, cov)
    assert best is not None
    peak_stat, fine, st, coef, cov = best
    i = int(np.argmax(st))
    f_hat = float(fine[i])
    if peak_stat < thr:
        return SlowSearch(None, "none above the false-alarm level", band, peak_stat, thr,
                          f_hat / record_s)
    # a candidate: confirmed with the flicker's level profiled too (B at the fit's value
    # is itself an estimate; a B that fell low leaves the means' middle band in excess),
    # only here, where it costs a factor and a decomposition per B
    confirmed = _with_flicker_profiled(scan, st, yb, block_s, n_white, b_inst, k_scale, fine)
    if confirmed < thr:
        return SlowSearch(None, "none above the false-alarm level with the flicker level "
                          "profiled", band, confirmed, thr, f_hat / record_s)
    peak_stat = confirmed
    lo, hi = _within_one(fine, st, i)
    if 0 < i < len(fine) - 1:
        # a strong sinusoid's interval is narrower than the grid: the peak and its width
        # from the parabola through the three points about it
        y0, y1, y2 = float(st[i - 1]), float(st[i]), float(st[i + 1])
        curv = (y0 - 2.0 * y1 + y2) / FINE_STEP**2
        if curv < 0:
            shift = 0.5 * FINE_STEP * (y0 - y2) / (y0 - 2.0 * y1 + y2)
            half = math.sqrt(-2.0 / curv)  # Λ falls by 1 at ±half
            if half < 2.0 * FINE_STEP:
                f_hat += shift
                lo, hi = f_hat - half, f_hat + half
                _st, coef, cov = scan.at(np.array([f_hat]))
                i = 0
    if lo <= FROM_CYCLES or hi >= top or not (math.isfinite(lo) and math.isfinite(hi)):
        where = "slower than" if f_hat < 0.5 * (FROM_CYCLES + top) else "at the top of"
        return SlowSearch(None, f"not resolved: a slow signal of about {f_hat:.3g} cycles per "
                          f"record, its frequency interval reaching {where} the band "
                          f"({FROM_CYCLES:g}–{top:.3g} cycles): read as noise", band,
                          peak_stat, thr, f_hat / record_s)
    a, c2 = coef[i], cov[i]
    # the block average's attenuation of a sinusoid of f_hat cycles per record
    x = math.pi * f_hat / j
    gain = math.sin(x) / x if x > 0 else 1.0
    size2 = float(a @ a)
    unit = a / max(math.sqrt(size2), 1e-300)
    sd = math.sqrt(max(float(unit @ c2 @ unit), 0.0))
    amp = math.sqrt(max(size2 - float(np.trace(c2)), 0.0))
    if amp - sd <= 0:
        return SlowSearch(None, "not resolved: the amplitude's interval reaches zero", band,
                          peak_stat, thr, f_hat / record_s)
    sine = SlowSine(f_hat / record_s, lo / record_s, hi / record_s, amp / gain,
                    (amp - sd) / gain, (amp + sd) / gain, f_hat, (float(a[0]), float(a[1])))
    return SlowSearch(sine, f"a sinusoid of {f_hat:.3g} cycles per record", band, peak_stat,
                      thr, f_hat / record_s)


def _with_flicker_profiled(scan: _Scan, stat: NDArray, yb: NDArray, block_s: float,
                           n_white: float, b_inst: float, k_scale: float, cycles: NDArray
                           ) -> float:
    """The largest Λ over ``cycles`` with B profiled over ``B_FACTORS`` of ``b_inst`` beside
    K (``scan``: at ``b_inst`` itself, where Λ at ``cycles`` is ``stat``, the caller's
    ``scan.at(cycles)``): the least −2 ln L₀ over every B and K against the least −2 ln L₁
    at each frequency over every B and K."""
    nll0 = [float(np.min(scan.nll0))]
    nll1 = [nll0[0] - np.asarray(stat, dtype=float)]
    if b_inst > 0:
        for factor in B_FACTORS:
            try:
                other = _Scan(yb, block_s, n_white, b_inst * factor, k_scale, scan.gm)
            except np.linalg.LinAlgError:
                continue
            n0 = float(np.min(other.nll0))
            nll0.append(n0)
            nll1.append(n0 - other.at(cycles)[0])
    return float(np.max(min(nll0) - np.min(np.array(nll1), axis=0)))


def _within_one(f: NDArray, st: NDArray, i: int) -> tuple[float, float]:
    """Where Λ falls 1 below its peak at ``i`` either side (interpolated; ±inf where it does
    not within the grid)."""
    lim = float(st[i]) - 1.0
    below = np.flatnonzero(st[:i] < lim)
    above = np.flatnonzero(st[i + 1:] < lim)
    lo, hi = -math.inf, math.inf
    if below.size:
        a = int(below[-1])
        lo = float(np.interp(lim, [st[a], st[a + 1]], [f[a], f[a + 1]]))
    if above.size:
        b = i + 1 + int(above[0])
        hi = float(np.interp(lim, [st[b], st[b - 1]], [f[b], f[b - 1]]))
    return lo, hi


def avar_cov(sine: SlowSine, tau: NDArray[np.float64]) -> NDArray[np.float64]:
    """The covariance of the AVAR points at ``tau`` that the sinusoid's estimated amplitude
    and frequency carry (their 68 % half-widths as standard deviations): its AVAR is
    A²·b(τ; f) (IEEE 952 C.21), so δ = 2A·δA·b + A²·∂b/∂f·δf."""
    from avard.core.model.terms import sinusoid_avar

    a = sine.amplitude
    sd_a = 0.5 * (sine.amplitude_hi - sine.amplitude_lo)
    sd_f = 0.5 * (sine.frequency_hi_hz - sine.frequency_lo_hz)
    b = sinusoid_avar(tau, 1.0, sine.frequency_hz)
    v1 = 2.0 * a * sd_a * b
    f_lo = max(sine.frequency_hz - sd_f, 0.5 * sine.frequency_hz)
    v2 = 0.5 * a * a * (sinusoid_avar(tau, 1.0, sine.frequency_hz + sd_f)
                        - sinusoid_avar(tau, 1.0, f_lo))
    return np.asarray(np.outer(v1, v1) + np.outer(v2, v2))


def resolve_slow_sine(base: NoiseFit, fit: NoiseFit, allan: AllanResult, means: NDArray,
                      block_s: float, top_hz: float, refit: Callable[..., NoiseFit],
                      lines_hz: Sequence[float] = ()) -> tuple[SlowSearch, NoiseFit | None]:
    """The search on one channel's block means against ``base`` (the channel's AVAR fit:
    its N and B, K's range past its upper K), and where it resolves a sinusoid, the fit that
    sets the printed EDF: the noise refitted (``refit(allan, added_cov=...)``, the channel's
    own ``fit_noise`` arguments) on the AVAR less the sinusoid's, its uncertainty added to
    the AVAR's covariance (the walk and the flicker no longer made of it), the drift tested
    again beside it on the means less the sinusoid (``drift.resolve_drift``: whatever
    ``fit``, the channel's fit with the first test's verdict, said), and the sinusoid
    appended as a resolved part (``resolved_apart``: it may take the EDF past the record's
    support, ``signal_edf``). None where none is resolved or a refit fails, or where one of
    the line finder's ``lines_hz`` lies within ``LINE_BINS`` of its bins (``top_hz`` is its
    first tested, ``welch_top_hz``) of the sinusoid: near the band's top both see one
    sinusoid, and the fit holds it already."""
    from avard.core.analysis.drift import _k_upper, resolve_drift
    from avard.core.errors import FitError
    from avard.core.model.fit import Component
    from avard.core.model.terms import sinusoid_avar

    n_w = float(base.terms["velocity_random_walk"].value or 0.0)
    b_i = float(base.terms["bias_instability"].value or 0.0)
    search = search_slow_sine(means, block_s, n_w, b_i, _k_upper(base), top_hz)
    sine = search.sine
    if sine is None:
        return search, None
    from avard.core.analysis.spectrum import LINE_LOBE

    bin_hz = top_hz / (LINE_LOBE + 5)  # (top_hz is welch_top_hz: that bin's frequency)
    near = [f for f in lines_hz if abs(f - sine.frequency_hz) <= LINE_BINS * bin_hz]
    if near:
        return replace(search, sine=None, note=f"not resolved here: the line finder's line at "
                       f"{near[0]:.4g} Hz is this sinusoid"), None
    tau = np.asarray(allan.tau, dtype=float)
    added = avar_cov(sine, tau)
    less = replace(allan, var=np.asarray(allan.var, dtype=float)
                   - sinusoid_avar(tau, sine.amplitude, sine.frequency_hz))

    def beside(a: AllanResult, **kw: object) -> NoiseFit:
        more = kw.pop("added_cov", None)
        return refit(a, added_cov=added if more is None else added + np.asarray(more), **kw)

    try:
        noise = beside(less)
        # The drift is tested again here, on the means less the sinusoid and against the
        # noise refitted without it, whatever the first test (on the base fit) said: the
        # sinusoid's AVAR went to the base fit's walk, whose wider K range and the
        # sinusoid's own swing in the means hid a drift from that test (a drift and a
        # slow sinusoid together: the drift resolved in a seventh of the records it was
        # resolved in alone). The search fits an offset and a slope under both of its
        # hypotheses, so a drift does not hide the sinusoid in turn.
        noise = resolve_drift(noise, less, sine.less_sine(means, block_s), block_s,
                              beside)[0]
    except FitError as exc:
        return replace(search, sine=None, note=f"not resolved: the fit beside the sinusoid "
                       f"failed ({exc})"), None
    a, sd = sine.amplitude, 0.5 * (sine.amplitude_hi - sine.amplitude_lo)
    comp = Component(sine.label, "sinusoid", {"frequency_hz": sine.frequency_hz},
                     "amplitude", "m/s^2")
    k = len(noise.theta)
    cov = np.zeros((k + 1, k + 1))
    cov[:k, :k] = noise.theta_cov
    cov[k, k] = 4.0 * a * a * sd * sd + 2.0 * sd**4
    # (no TermEstimate: signal_edf counts a deterministic component without one as
    # resolved, and the terms stay the IEEE ones)
    return search, replace(noise, components=[*noise.components, comp],
                           theta=np.append(noise.theta, a * a), theta_cov=cov,
                           resolved_apart=(*noise.resolved_apart, sine.label))

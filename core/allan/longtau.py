"""The statistics beyond OADEV, with EDF and χ² bounds: ``statistic(name, y, rate, taus)``.

One entry point for every deviation avard can print (``STATISTICS``): the four difference
variances of ``deviations`` (ADEV, OADEV, HDEV, OHDEV, NIST SP 1065 eqs. 11, 12, 17, 18) and
the long-τ family of this package, which share one phase integration, one reflection and one
decimation (``extension``):

=========  ===============================  ============  ======================================
name       SP 1065                          τ reach       EDF (68.3 % bounds by SP 1065 eq. 40)
=========  ===============================  ============  ======================================
mdev       eq. 14 (``modified``)            T/3           Greenhall–Riley, modified (GR case 1)
tdev       eq. 15, τ/√3·MDEV (unit × s)     T/3           as MDEV
totdev     eq. 25 (``total``)               T/2           Table 7 (FM); OADEV's for PM
mtot       eq. 27                           T/3           Table 8, b·T/τ − c
ttot       eq. 28, τ/√3·MTOT (unit × s)     T/3           as MTOT
htot       eq. 29, OHDEV at m = 1           T/3           Table 9 (FM); OHDEV's for PM
theo1      eq. 30 (``theo``), τ = 0.75 m τ0  0.75 T        §5.2.14's forms (stand-in: below)
theobr     eq. 31                           0.75 T        as Theo1
theoh      eq. 32: OADEV to 10 % T, TheoBR  0.75 T        OADEV's, then as Theo1
=========  ===============================  ============  ======================================

Where SP 1065 and Stable32 differ (both are offered: ``edf_convention``):

* MTOT and TTOT: SP 1065 gives Table 8 (b·T/τ − c) at every τ. Stable32 prints MDEV's
  Greenhall–Riley EDF below AF 10 and from there b·T/τ − c with its own coefficients, not
  Table 8's (white FM 1.333, 1.89 against 1.10, 1.20; flicker PM 1.735, 3.0 against 1.20,
  1.40: its bounds are up to 6.5 % from Table 8's). Those were measured from its PHASE.DAT
  bounds and hold on an independent Stable32 run to 3.5e-4 (``STABLE32_MTOT_EDF``);
  ``"stable32"`` takes them (and Table 8 at the other α, where none was measured). They give
  more EDF than Table 8 (a narrower interval): ``"sp1065"`` stays the default.
* HTOT: SP 1065 gives Table 9 (FM types) and no EDF for the PM types; avard takes OHDEV's
  Greenhall–Riley EDF for the PM types and, below m = 16, the smaller of the two
  (``"sp1065"``, the default: the interval is never the narrower). Stable32 prints Table 9
  for the FM types from AF 16 on; below AF 16, and at white and flicker PM at every AF, it
  prints SP 1065's Table 5 "simple" EDF (Stein's, for AVAR) plus 2
  (``STABLE32_HTOT_SIMPLE_OFFSET``). That rule was measured: Table 5 alone left Stable32's
  flicker-PM bounds of PHASE.DAT (AF 128, 256) 0.3 % and 1.4 % away, and the EDF its bounds
  imply exceed Table 5's by 2.0–2.1 there, by 2.1–2.2 at flicker PM on an independent
  1253-point run (AF 100) and, within the rounding of the printed digits, on every other
  Table 5 row of both records (white PM at every AF; α 0, −1, −2 below AF 16). With the 2
  added, every such row of the three runs (PHASE.DAT with and without bias correction, the
  1253-point record) is reproduced within 1.8e-4 (tests/core/test_stable32_longtau.py).
  Not at AF 1, α −1, where Table 5's form is below one degree of freedom and Stable32 prints
  Table 9's to 3e-3. ``"stable32"`` takes that rule; at flicker PM its EDF is the larger
  (50.7 against OHDEV's 32.8 at PHASE.DAT's AF 128), so ``"sp1065"`` stays the default;
  simulated flicker PM shows both conservative there (HTOT's spread over 300 records of 1001
  points: EDF 82 and 42 at m = 128 and 256; tests/core/test_longtau.py).
* Bias: HTOT is divided by SP 1065's factor for its noise type (0.995 white FM, 0.851 flicker,
  0.771 random walk, 0.717 and 0.679 for α = −3, −4), as Stable32 prints it; TOTVAR by
  1 − a·τ/T (a = 0.481 flicker FM, 0.750 random-walk FM; SP 1065 §5.2.11); MTOT, TTOT and
  MDEV are not corrected (Stable32 1.60 prints them raw; 1.53 divided MTOT and TTOT by
  their bias against MVAR, 0.73 at white FM: ``mtot_bias=True`` does that). Theo1 is
  printed raw: it equals AVAR for white FM only; Stable32 rescales it by its α (by 1/1.659
  at flicker PM on PHASE.DAT, a factor SP 1065 does not give), avard does not. TheoBR and
  TheoH remove the bias from the data themselves, which is what they are for.
  ``debias=False`` prints every statistic raw.
* Theo1's EDF: SP 1065 §5.2.14's fitted forms per noise type (``edf.edf_theo1``), as
  Stable32 prints them (its Theo1 bounds on a 1253-point record reproduced within 3.2e-4).
  Where no form applies (random-walk FM from τ ≈ 0.6 T on, where the form falls below one
  degree of freedom and then below zero) the stand-in ``THEO_STAND_IN``: TOTVAR's Table 7
  row at T/τ, which the simulations show conservative; ``theo_edf_source`` says which, and
  ``--stat``'s table marks the stand-in's rows. Simulated coverage of the 68.3 % interval
  (300 records of 1001 points, tests/core/test_longtau.py, slow): 60–76 % wherever the EDF
  is ≥ 10 and τ ≤ 0.6 T; ≥ 60 % elsewhere. White PM beyond 0.6 T: the form claims up to
  1.5 times the EDF the records show, so the "sp1065" convention divides it by 1.5 there
  (``THEO1_WHITE_PM_EXCESS``); "stable32" prints the form raw, as Stable32 does.

Noise type α for the EDF: given, or the overlapping ADEV's identification (Stable32's rules,
``noise_id``) at the statistic's τ; beyond the OADEV's reach (τ > T/2) the α of its longest
τ is kept (as Stable32 keeps a shorter τ's α where too few averages remain).

Long records: ``max_points`` (per statistic class, ``MAX_POINTS``) bounds the samples a
statistic works on; a longer record is averaged by the smallest factor r that fits
(``extension.decimate``), so the statistic starts at τ = r·τ0 and its differences are r
samples apart (the result's ``stride``). MTOT, TTOT, HTOT and the Theo family cost N·m per τ
and get the smaller budget, as NIST recommends averaged data for them.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from avard.core.allan.deviations import AllanResult, allan_variance, validate_input
from avard.core.allan.edf import (
    TOTVAR_EDF,
    chi2_interval,
    edf_greenhall,
    edf_greenhall_modified,
    edf_table5,
    edf_theo1,
    edf_total,
)
from avard.core.allan.extension import centred_phase, decimate
from avard.core.allan.modified import mvar_sums
from avard.core.allan.theo import bias_ratio_terms, oavar_sums, theo1_sums
from avard.core.allan.total import subsequence_sums, totvar_sums
from avard.core.errors import DataError
from numpy.typing import ArrayLike, NDArray

__all__ = ["EDF_CONVENTIONS", "MAX_POINTS", "STATISTICS", "statistic"]

EDF_CONVENTIONS = ("sp1065", "stable32")
# Samples a statistic works on at most, by cost class: "linear" (N per τ) and "quadratic"
# (N·m per τ); beyond, the record is averaged (module docstring).
MAX_POINTS = {"linear": 1 << 22, "quadratic": 1 << 12}
# SP 1065 §5.2.13 HTOT bias (HTOT / HVAR) by α; §5.2.11 TOTVAR bias a in 1 − a·τ/T.
HTOT_BIAS = {0: 0.995, -1: 0.851, -2: 0.771, -3: 0.717, -4: 0.679}
TOTVAR_BIAS = {-1: 0.481, -2: 0.750}
# MTOT / MVAR by α (W. Riley, "CI2": Stable32 1.53 divided MTOT and TTOT by it, 1.60 does not).
MTOT_BIAS = {2: 0.94, 1: 0.83, 0: 0.73, -1: 0.70, -2: 0.69}
# Stable32's MTOT/TTOT bounds follow MDEV's EDF below this averaging factor (its decade runs
# at AF 10 already take the linear law below; its octave runs at AF 8 MDEV's EDF).
STABLE32_MTOT_SWITCH = 10
# ... and from there b·(T/τ) − c with these (b, c), which are not SP 1065's Table 8: measured
# from Stable32's PHASE.DAT bounds (least squares over its α 0 and α 1 rows at AF ≥ 10,
# T/τ = (N − 1)/m) and confirmed on an independent Stable32 run (a 1253-point record: its 9
# MTOT rows at AF ≥ 10 within 3.5e-4; tests/core/test_stable32_longtau.py). Other α: none
# measured, Table 8's.
STABLE32_MTOT_EDF = {0: (1.3333, 1.8935), 1: (1.7346, 3.0)}
# HTOT: Table 9 reproduces Stable32's bounds from this averaging factor on (not below).
HTOT_TABLE9_FROM = 16
# ... and where it does not (below AF 16, and at white and flicker PM), Table 5's simple EDF
# plus this: measured from its printed bounds (module docstring).
STABLE32_HTOT_SIMPLE_OFFSET = 2.0


@dataclass(frozen=True)
class Statistic:
    """One printable deviation: its variance kind, the data its kernel reads, its reach."""

    name: str
    kind: str  # the AllanResult kind
    cost: str  # "linear" or "quadratic" (MAX_POINTS)
    d: int  # order of the phase difference, for the noise-type range (α + 2d > 1)
    title: str


STATISTICS: dict[str, Statistic] = {s.name: s for s in (
    Statistic("adev", "avar", "linear", 2, "Allan deviation (non-overlapping)"),
    Statistic("oadev", "oavar", "linear", 2, "overlapping Allan deviation"),
    Statistic("hdev", "hvar", "linear", 3, "Hadamard deviation (non-overlapping)"),
    Statistic("ohdev", "ohvar", "linear", 3, "overlapping Hadamard deviation"),
    Statistic("mdev", "mvar", "linear", 2, "modified Allan deviation"),
    Statistic("tdev", "tvar", "linear", 2, "time deviation (input unit × s)"),
    Statistic("totdev", "totvar", "linear", 2, "total deviation"),
    Statistic("mtot", "mtotvar", "quadratic", 2, "modified total deviation"),
    Statistic("ttot", "ttotvar", "quadratic", 2, "time total deviation (input unit × s)"),
    Statistic("htot", "htotvar", "quadratic", 3, "Hadamard total deviation"),
    Statistic("theo1", "theo1", "quadratic", 2, "Theo1 deviation (τ = 0.75 m τ0)"),
    Statistic("theobr", "theobr", "quadratic", 2, "bias-removed Theo1 deviation"),
    Statistic("theoh", "theoh", "quadratic", 2, "hybrid TheoH deviation (OADEV, then TheoBR)"),
)}
_DIFFERENCE_KINDS = {"adev": "avar", "oadev": "oavar", "hdev": "phvar", "ohdev": "ohvar"}
_THEO = ("theo1", "theobr", "theoh")


def parse_statistics(text: str) -> list[str]:
    """``"oadev,totdev,theoh"`` → the names, checked; one clear error naming the bad one."""
    names = [t.strip().lower() for t in text.split(",") if t.strip()]
    if not names:
        raise DataError(f"--stat takes a comma-separated list of {', '.join(STATISTICS)}")
    for n in names:
        if n not in STATISTICS:
            raise DataError(f"statistic {n!r} is unknown; use any of {', '.join(STATISTICS)}")
    return list(dict.fromkeys(names))


def _grid(name: str, n_phase: int, taus: str | ArrayLike, rate_hz: float) -> NDArray[np.int64]:
    """Averaging factors (of the data the kernel reads) for a τ specification."""
    half, third = (n_phase - 1) // 2, (n_phase - 1) // 3
    reach = {"oadev": half, "totdev": half, "mdev": third, "tdev": third, "mtot": third,
             "ttot": third, "htot": third}.get(name, n_phase - 1)
    theo = name in _THEO
    if isinstance(taus, str):  # (unique: the reach may be an octave itself)
        ms: ArrayLike
        if taus == "octave":  # and the statistic's own reach, its longest τ
            ms = np.append(2 ** np.arange(int(math.log2(max(reach, 1))) + 1),
                           reach - (reach % 2 if theo else 0)) if reach >= 1 else []
        elif taus == "decade":
            ms = [b * 10**e for e in range(int(math.log10(max(reach, 1))) + 1) for b in (1, 2, 5)]
        elif taus == "all":
            ms = np.arange(1, reach + 1)
        else:
            raise DataError(f"taus={taus!r} is not a τ grid; use 'octave', 'decade', 'all' or "
                            "an array of τ in seconds")
        out = np.unique(np.asarray(ms, dtype=np.int64))
        out = out[(out >= 1) & (out <= reach)]
        if theo:
            out = out[out % 2 == 0]
        return out
    t = np.atleast_1d(np.asarray(taus, dtype=np.float64))
    if t.ndim != 1 or t.size == 0 or not np.all(np.isfinite(t)) or np.any(t <= 0):
        raise DataError("taus must be a non-empty 1-D array of finite τ > 0 in seconds")
    if theo:  # τ = 0.75 m τ0, m even
        ms = 2 * np.rint(t * rate_hz / 1.5)
    else:
        ms = np.rint(t * rate_hz)
    ms = np.unique(ms.astype(np.int64))
    return ms[(ms >= 1) & (ms <= reach)]


def _variances(name: str, y: NDArray[np.float64], x: NDArray[np.float64], m: int,
               rate_hz: float, tau: float) -> tuple[float, int]:
    """(raw variance, count of terms) of one statistic at one m on one channel."""
    if name in ("mdev", "tdev"):
        s, c = mvar_sums(x, m)
        v = s / (2.0 * m**4 * c) if c else math.nan
        return (v * tau * tau / 3.0 if name == "tdev" else v), c
    if name == "totdev":
        s, c = totvar_sums(x, m)
        return (s / (2.0 * m * m * c) if c else math.nan), c
    if name in ("mtot", "ttot"):
        s, c = subsequence_sums(x, m)
        v = s / (2.0 * m * m * c) if c else math.nan
        return (v * tau * tau / 3.0 if name == "ttot" else v), c
    if name == "htot":
        if m == 1:  # SP 1065: OHVAR at m = 1
            h = x[3:] - 3 * x[2:-1] + 3 * x[1:-2] - x[:-3]
            return float(h @ h) / (6.0 * h.size), int(h.size)
        s, c = subsequence_sums(y, m)
        return (s / (6.0 * c) if c else math.nan), c
    if name == "theo1":
        s, c = theo1_sums(x, m)
        return (s / (0.75 * c * m * m) if c else math.nan), c
    raise DataError(f"no kernel for {name!r}")  # pragma: no cover - registry and code agree


def _oavar(x: NDArray[np.float64], m: int) -> float:
    s, c = oavar_sums(x, m)
    return s / (2.0 * m * m * c) if c else math.nan


def _theo1(x: NDArray[np.float64], m: int) -> float:
    s, c = theo1_sums(x, m)
    return s / (0.75 * c * m * m) if c else math.nan


def theobr_ratio(x: NDArray[np.float64]) -> float:
    """TheoBR's bias ratio (SP 1065 eq. 31): the mean of AVAR(9 + 3i)/Theo1(12 + 4i),
    i = 0 … n; NaN when the record is too short for it (n < 0)."""
    n = bias_ratio_terms(x.shape[0])
    if n < 0:
        return math.nan
    return float(np.mean([_oavar(x, 9 + 3 * i) / _theo1(x, 12 + 4 * i) for i in range(n + 1)]))


def theoh_split(n_phase: int) -> int:
    """k of TheoH (SP 1065 eq. 32): the longest AVAR averaging factor within 10 % of the
    record, (N − 1)/10; TheoBR takes over beyond τ = k·τ0."""
    return max(1, (n_phase - 1) // 10)


def statistic(
    name: str,
    y: ArrayLike,
    rate_hz: float,
    taus: str | ArrayLike = "octave",
    *,
    alpha: int | ArrayLike | None = None,
    ci: float = 0.683,
    quantiles: str = "exact",
    edf_convention: str = "sp1065",
    debias: bool = True,
    mtot_bias: bool = False,
    max_points: int | None = None,
    names: Sequence[str] | None = None,
) -> AllanResult:
    """One statistic of ``STATISTICS`` on rate samples (N,) or (N, C), as an ``AllanResult``
    whose ``kind`` names it (``var`` is the variance: the deviation's square), with EDF, α and
    χ² bounds at level ``ci``; see the module docstring for every convention. ``max_points``
    overrides ``MAX_POINTS`` for this call; ``alpha`` fixes the noise type (one value, or one
    per τ). ``mtot_bias=True`` divides MTOT and TTOT by their bias against MVAR
    (``MTOT_BIAS``, as Stable32 1.53 printed them; 1.60 prints them raw, the default)."""
    if name not in STATISTICS:
        raise DataError(f"statistic {name!r} is unknown; use any of {', '.join(STATISTICS)}")
    if edf_convention not in EDF_CONVENTIONS:
        raise DataError(f"edf_convention={edf_convention!r} is unknown; use {EDF_CONVENTIONS}")
    st = STATISTICS[name]
    if name in _DIFFERENCE_KINDS:
        kind = _DIFFERENCE_KINDS[name]
        a0, _, _ = validate_input(y, rate_hz)
        kw = {"stride": a0.shape[0]} if kind == "phvar" else {}  # non-overlapping: stride m
        res = allan_variance(y, rate_hz, taus, kind=kind, alpha=alpha, ci=ci,
                             quantiles=quantiles, names=names, **kw)
        return res
    a, _, one_d = validate_input(y, rate_hz)
    rate_hz = float(rate_hz)
    limit = int(max_points or MAX_POINTS[st.cost])
    r = max(1, -(-a.shape[0] // limit))
    yd = decimate(a.astype(np.float64, copy=False), r)
    rate_d = rate_hz / r
    n_phase = yd.shape[0] + 1
    if n_phase < 4:
        raise DataError(f"{a.shape[0]} samples are too few for {name}")
    ms = _grid(name, n_phase, taus, rate_d)
    use_avar = np.zeros(ms.size, dtype=bool)
    if name == "theoh":  # OADEV to τ_k = k·τ0, TheoBR (τ = 0.75 m τ0) beyond
        k_split = theoh_split(n_phase)
        avar_ms = _grid("oadev", n_phase, taus, rate_d)
        avar_ms = avar_ms[avar_ms <= k_split]
        ms = np.concatenate([avar_ms, ms[0.75 * ms > k_split]])
        use_avar = np.arange(ms.size) < avar_ms.size
    if ms.size == 0:
        raise DataError(f"the record ({a.shape[0]} samples) is too short for {name} at these τ")
    c = yd.shape[1]
    theo = name in _THEO
    tau = np.where(use_avar, 1.0, 0.75 if theo else 1.0) * ms / rate_d
    var = np.full((ms.size, c), np.nan)
    count = np.zeros(ms.size, dtype=np.int64)
    for ch in range(c):
        x = centred_phase(yd[:, ch])
        ratio = theobr_ratio(x) if name in ("theobr", "theoh") else 1.0
        if name in ("theobr", "theoh") and not math.isfinite(ratio):
            raise DataError(f"{name} needs at least 90 phase points (averaged); got {n_phase}")
        for k, m in enumerate(ms.tolist()):
            if use_avar[k]:
                s, cnt = oavar_sums(x, m)
                var[k, ch] = s / (2.0 * m * m * cnt) if cnt else math.nan
            else:
                kern = "theo1" if theo else name
                v, cnt = _variances(kern, yd[:, ch], x, m, rate_d, float(tau[k]))
                var[k, ch] = v * ratio if theo else v
            count[k] = cnt
    alphas = _alphas(alpha, yd, rate_d, tau, var, st.d)
    edf = np.full_like(var, np.nan)
    for k, m in enumerate(ms.tolist()):
        for ch in range(c):
            e = _edf(name, int(alphas[k, ch]), m, n_phase, edf_convention,
                     bool(use_avar[k]), float(tau[k] * rate_d))
            edf[k, ch] = e
            if mtot_bias and name in ("mtot", "ttot"):
                var[k, ch] /= MTOT_BIAS[int(alphas[k, ch])]
            if debias:
                var[k, ch] = _debiased(name, var[k, ch], int(alphas[k, ch]),
                                       float(tau[k] * rate_d), n_phase)
    lo, hi = chi2_interval(var, edf, ci, quantiles)
    squeeze: Callable[[NDArray], NDArray] = (lambda v: v[:, 0]) if one_d else (lambda v: v)
    return AllanResult(
        kind=st.kind, rate_hz=rate_hz, tau=tau, m=ms * r, stride=np.full(ms.size, r, np.int64),
        var=squeeze(var), n=count, edf=squeeze(edf), lo=squeeze(lo), hi=squeeze(hi),
        alpha=squeeze(alphas.astype(np.float64)), ci=ci, cov=None,
        names=tuple(names) if names else (), quantiles=quantiles)


def _alphas(alpha: int | ArrayLike | None, yd: NDArray[np.float64], rate_d: float,
            tau: NDArray[np.float64], var: NDArray[np.float64], d: int) -> NDArray[np.int64]:
    """α per (τ, channel): given, or the OADEV's identification at the same τ (the longest
    τ it reaches where the statistic goes further)."""
    lowest = 2 - 2 * d
    if alpha is not None:
        a = np.asarray(alpha, dtype=np.float64)
        if a.ndim == 1 and a.shape[0] == var.shape[0]:
            a = a[:, None]
        try:
            a = np.broadcast_to(a, var.shape)
        except ValueError as exc:
            raise DataError(f"alpha has shape {a.shape}; give one value or one per τ "
                            f"({var.shape[0]})") from exc
        if not np.all(np.isfinite(a)) or np.any(np.rint(a) != a) or np.any(a > 2) \
                or np.any(a < lowest):
            raise DataError(f"alpha must be integers in [{lowest}, 2] for this statistic")
        return a.astype(np.int64)
    n = yd.shape[0]
    m_id = np.clip(np.rint(tau * rate_d).astype(np.int64), 1, max(1, n // 2))
    uniq = np.unique(m_id)
    ident = allan_variance(yd, rate_d, uniq / rate_d, kind="oavar")
    got = np.asarray(ident.alpha, dtype=np.float64).reshape(uniq.size, -1)
    out = got[np.searchsorted(uniq, m_id)]
    return np.clip(out, lowest, 2).astype(np.int64)


def _edf(name: str, alpha: int, m: int, n_phase: int, convention: str, avar_part: bool,
         tau_over_tau0: float) -> float:
    """The EDF of one statistic at one m (of the data the kernel reads)."""
    if name in ("mdev", "tdev"):
        return edf_greenhall_modified(alpha, 2, m, n_phase)
    if name == "totdev":
        e = edf_total("totvar", alpha, m, n_phase)
        return e if math.isfinite(e) else edf_greenhall(alpha, 2, m, 1, n_phase)
    if name in ("mtot", "ttot"):
        if convention == "stable32" and m < STABLE32_MTOT_SWITCH:
            return edf_greenhall_modified(alpha, 2, m, n_phase)
        if convention == "stable32" and alpha in STABLE32_MTOT_EDF:
            b, c = STABLE32_MTOT_EDF[alpha]
            e = b * (n_phase - 1) / m - c
            return e if e > 0 else math.nan
        return edf_total("mtotvar", alpha, m, n_phase)
    if name == "htot":
        ohdev = edf_greenhall(alpha, 3, m, 1, n_phase)
        if convention == "stable32":  # Table 5 + 2 below AF 16 and at PM, Table 9 else
            e5 = edf_table5(alpha, m, n_phase) if not (alpha == -1 and m == 1) else math.nan
            if (m < HTOT_TABLE9_FROM or alpha > 0) and math.isfinite(e5):
                return e5 + STABLE32_HTOT_SIMPLE_OFFSET
            e9 = edf_total("htotvar", alpha, m, n_phase)
            return e9 if math.isfinite(e9) else ohdev
        e = edf_total("htotvar", alpha, m, n_phase) if m > 1 else math.nan
        if not math.isfinite(e):
            return ohdev
        # below m = 16 Table 9 claims more than OHDEV's Greenhall–Riley EDF (exact for the
        # OHVAR that HTOT is at m = 1): the smaller, so the interval is never the narrower
        return min(e, ohdev) if m < HTOT_TABLE9_FROM else e
    if avar_part:  # TheoH's OADEV part
        mm = max(1, round(tau_over_tau0))
        return edf_greenhall(alpha, 2, mm, 1, n_phase)
    # Theo family: SP 1065's forms where one applies, else the stand-in (``theo_edf_source``)
    e = edf_theo1(alpha, m, n_phase)
    if not math.isfinite(e):
        return _theo_stand_in(alpha, n_phase, tau_over_tau0)
    if (convention != "stable32" and alpha == 2 and e >= 10.0
            and 0.75 * m > THEO1_WHITE_PM_FROM * n_phase):
        return e / THEO1_WHITE_PM_EXCESS
    return e


#: White PM beyond τ = 0.6 T: SP 1065's Theo1 form claims up to 1.5 times the EDF the
#: records' spread shows (simulated, 200 records each of 500, 1000 and 2000 points: 1.15–1.50
#: from 0.6 T to 0.72 T; tests/core/test_longtau.py), so under the "sp1065" convention the
#: form is divided by that excess there (the interval errs wide, never narrow); "stable32"
#: prints the form as Stable32 does. Not at the last τ (0.75 T), where the form falls to
#: about 3.4 and the records show 2.7–4.7.
THEO1_WHITE_PM_FROM = 0.6
THEO1_WHITE_PM_EXCESS = 1.5


THEO_STAND_IN = "TOTVAR's Table 7 at T/τ (no SP 1065 form applies)"


def _theo_stand_in(alpha: int, n_phase: int, tau_over_tau0: float) -> float:
    """TOTVAR's Table 7 row of the noise type at T/τ (white FM's for the PM types): where
    SP 1065's Theo1 forms give nothing (random-walk FM beyond τ ≈ 0.63 T), an EDF whose
    intervals held the ensemble value in ≥ 62 % of simulated records (tests/core/
    test_longtau.py), so no narrower than the data support."""
    b, c = TOTVAR_EDF[min(0, max(-2, alpha))]
    e = b * (n_phase - 1) / tau_over_tau0 - c
    return e if e > 0 else math.nan


def theo_edf_source(alpha: int, m: int, n_phase: int) -> str:
    """Where the EDF of Theo1 (and TheoBR, TheoH beyond OADEV) at the Theo1 averaging factor
    m on ``n_phase`` phase points comes from: "SP 1065" (§5.2.14's forms, as Stable32) or
    ``THEO_STAND_IN``; the table and JSON of ``--stat`` say which, per τ."""
    return "SP 1065" if math.isfinite(edf_theo1(alpha, m, n_phase)) else THEO_STAND_IN


def _debiased(name: str, v: float, alpha: int, tau_over_tau0: float, n_phase: int) -> float:
    """SP 1065's bias corrections where they apply (module docstring)."""
    if name == "htot" and tau_over_tau0 > 1 and alpha in HTOT_BIAS:
        return v / HTOT_BIAS[alpha]
    if name == "totdev" and alpha in TOTVAR_BIAS:
        return v / (1.0 - TOTVAR_BIAS[alpha] * tau_over_tau0 / (n_phase - 1))
    return v

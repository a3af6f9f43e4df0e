"""Each sensor's own noise separated from what the bed does, by two or three co-located sensors.

Sensors bolted to one plate see the same input c(t) (the bed's motion) plus their own noise
eᵢ(t): yᵢ = c + eᵢ. With the noises uncorrelated with each other and with c, the Allan
covariance of two sensors is the common part and the rest of each sensor's Allan variance is
its own noise (Groslambert covariance, Vernotte et al. 2016; allantools ``gcodev``):

    σ²_c = Cov_A(y₁, y₂),     σ²_{e,i} = σ²_A(yᵢ) − Cov_A(y₁, y₂)                     (1)

With three sensors the three-cornered hat (Gray & Allan 1974; allantools
``three_cornered_hat_phase``) takes each sensor's noise from the Allan variances of the
pairwise differences, in which the common input cancels exactly:

    σ²_{e,1} = ½ [σ²_A(y₁ − y₂) + σ²_A(y₁ − y₃) − σ²_A(y₂ − y₃)]   (and cyclically)     (2)

and the common part is the mean of the three pairwise Allan covariances. Every Allan variance
and covariance here is the fully overlapping one (NIST SP 1065 eq. 14, its covariance form for
two series) from :func:`avard.core.allan.deviations.allan_variance`, the project's one batch
estimator.

**Intervals.** Each estimate is the mean of products ½ UₖVₖ of two second-difference series
(for (1): U = D₁, V = D₁ − D₂; for (2): U = D₁ − D₂, V = D₁ − D₃; for the common part
U = D₁, V = D₂), with E[½U²] = P, E[½V²] = Q and E[½UV] = S the variance sought. For Gaussian
U, V one product is λ₊χ²₁ − λ₋χ²₁ with λ± = (√(PQ) ± S)/2 (the eigenvalues of the quadratic
form), so the estimate is distributed as

    Ŝ = (λ₊ X − λ₋ Y) / ν,   X, Y ~ χ²_ν independent,  Var Ŝ = (PQ + S²)/ν            (3)

with ν the equivalent degrees of freedom of the overlapping estimator (Greenhall's EDF, SP
1065 eq. 41, for the noise identified on U's and V's series): their geometric mean, which the
Cauchy–Schwarz inequality makes a lower bound of the product's EDF when U and V differ in
noise type (Σρ_Uρ_V ≤ (Σρ_U² Σρ_V²)^½ over the lags).

The interval is a Neyman construction in S ≥ 0 (:func:`covariance_interval`): each S tested
gets (3) with P and Q at the observed P̂ and Q̂, i.e. the other sensors' parts P − S and
Q − S evaluated at the S tested (never below 0), not at the estimate Ŝ. Holding them at Ŝ
mis-states the spread where another part's estimate is negative and clipped to 0 (a sensor
far below the bed: at S = 0 the modelled spread collapsed, half the estimates fell above
its 68 % quantile). Each S accepts the central ``ci`` of (3), or everything below its
``ci`` quantile where S lies below the sensitivity S* (the upper end a zero estimate gets;
the boundary S ≥ 0 as in Feldman & Cousins 1998): every S is covered at ``ci``, no interval
is empty, and an upper end is never below S*, so an estimate far below 0 gets S*, never an
end pulled towards 0. Where S = 0 accepts the estimate the result is an **upper limit**:
never a negative variance or a NaN.
A coverage test on records from a generator written apart from the simulator
(tests/support/colocated.py) holds the self-noise intervals to their nominal 68 %.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from avard.core.allan.chi2 import chi2_ppf_grid
from avard.core.allan.cross import PairMoments
from avard.core.allan.deviations import AllanResult, allan_variance
from avard.core.errors import AvardError, DataError, FormatError
from avard.core.io.rates import rates_compatible
from numpy.typing import ArrayLike, NDArray

#: Estimates at τ with fewer non-overlapping averages than this are not reported.
MIN_AVERAGES = 2
#: χ² quantile points per axis of the grid that represents (3); the interval ends are good to
#: about 1/_GRID of probability.
_GRID = 64
_BISECT = 40
#: Below this EDF P̂ and Q̂ are too uncertain to be held in the interval's spread (fewer
#: than about 5 averages): covariance_interval widens to the hull of two constructions.
_FEW_NU = 4.0


# -- the estimator --------------------------------------------------------------------------

@dataclass(frozen=True)
class Part:
    """One separated Allan variance over τ: the estimate (may be ≤ 0), its interval
    [lo, hi] (lo = 0 where ``upper_limit``), the EDF of (3) behind it, in (m/s²)²."""

    var: NDArray[np.float64]
    lo: NDArray[np.float64]
    hi: NDArray[np.float64]
    upper_limit: NDArray[np.bool_]
    edf: NDArray[np.float64]

    @property
    def dev(self) -> NDArray[np.float64]:
        """The ADEV where it is resolved from 0, NaN where only an upper limit is known."""
        return np.where(self.upper_limit, np.nan, np.sqrt(np.clip(self.var, 0.0, None)))

    def to_dict(self) -> dict[str, Any]:
        ul = self.upper_limit
        return {"adev": [None if u else math.sqrt(max(v, 0.0)) for v, u in zip(self.var, ul,
                                                                             strict=True)],
                "adev_lo": [None if u else math.sqrt(v) for v, u in zip(self.lo, ul,
                                                                       strict=True)],
                "adev_hi": [math.sqrt(v) for v in self.hi],
                "upper_limit": [bool(u) for u in ul],
                "edf": [float(v) for v in self.edf]}


@dataclass(frozen=True)
class Verdict:
    """Where the common input lies below a sensor's own noise: per τ "below" (the common
    part's upper end under the self-noise's lower end), "above" (the reverse) or "not
    resolved"; ``factor`` the self-noise ADEV over the common ADEV (estimates) and
    ``factor_at_least`` the factor the intervals guarantee (NaN where not resolved below)."""

    state: tuple[str, ...]
    factor: NDArray[np.float64]
    factor_at_least: NDArray[np.float64]

    def below_runs(self) -> list[tuple[int, int]]:
        """The runs of consecutive τ indices [first, last] resolved "below"."""
        runs: list[tuple[int, int]] = []
        for k, st in enumerate(self.state):
            if st != "below":
                continue
            if runs and runs[-1][1] == k - 1:
                runs[-1] = (runs[-1][0], k)
            else:
                runs.append((k, k))
        return runs


@dataclass(frozen=True)
class AxisSeparation:
    """The separation of one axis: the τ, each sensor's self-noise, the common part."""

    axis: str
    tau: NDArray[np.float64]
    m: NDArray[np.int64]
    averages: NDArray[np.int64]
    self_noise: tuple[Part, ...]
    common: Part
    verdicts: tuple[Verdict, ...]
    fits: tuple[Any, ...] = ()            # NoiseFit | None per sensor
    fit_problems: tuple[str | None, ...] = ()

    def self_result(self, i: int, rate_hz: float, ci: float) -> AllanResult:
        """Sensor ``i``'s self-noise as a single-channel AllanResult (for the one fit):
        τ where it is only an upper limit are left out (var NaN)."""
        p = self.self_noise[i]
        var = np.where(p.upper_limit, np.nan, p.var)
        k = len(self.tau)
        return AllanResult(kind="oavar", rate_hz=rate_hz, tau=self.tau, m=self.m,
                           stride=np.ones(k, np.int64), var=var, n=self.averages * self.m,
                           edf=p.edf, lo=p.lo, hi=p.hi, alpha=np.full(k, np.nan), ci=ci)


@dataclass(frozen=True)
class Separation:
    """Self-noise and common mode of 2 or 3 co-located sensors, per axis (SI: m/s²)."""

    sensors: tuple[str, ...]
    method: str                       # "groslambert covariance" | "three-cornered hat"
    rate_hz: float
    n_samples: int
    ci: float
    axes: tuple[AxisSeparation, ...]
    notes: tuple[str, ...] = ()
    sources: tuple[str, ...] = ()
    filter_corner_hz: float | None = None

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "method": self.method, "sensors": list(self.sensors), "rate_hz": self.rate_hz,
            "n_samples": self.n_samples, "ci": self.ci, "notes": list(self.notes),
            "sources": list(self.sources), "units": {"adev": "m/s^2", "tau": "s"},
            "axes": {}}
        for ax in self.axes:
            d: dict[str, Any] = {"tau": [float(t) for t in ax.tau],
                                 "m": [int(v) for v in ax.m],
                                 "averages": [int(a) for a in ax.averages],
                                 "common": ax.common.to_dict(), "sensors": {}}
            for i, name in enumerate(self.sensors):
                v = ax.verdicts[i]
                fit = ax.fits[i] if ax.fits else None
                d["sensors"][name] = {
                    "self_noise": ax.self_noise[i].to_dict(),
                    "verdict": {"state": list(v.state),
                                "factor": [_num(f) for f in v.factor],
                                "factor_at_least": [_num(f) for f in v.factor_at_least],
                                "common_below_self_tau_ranges_s": [
                                    [float(ax.tau[a]), float(ax.tau[b])]
                                    for a, b in v.below_runs()]},
                    "fit": None if fit is None else fit.to_dict(),
                    "fit_problem": ax.fit_problems[i] if ax.fit_problems else None}
            out["axes"][ax.axis] = d
        return out


    @classmethod
    def from_dict(cls, d: object) -> Separation:
        """THE decoder of a separation map (:meth:`to_dict`: ``avard separate --json`` and
        the ``separation`` field of the service's ``avar`` record). Every list is checked
        against the τ count, so a ragged or hostile map is refused with one
        ``FormatError`` naming what is wrong. Variances come back as ADEV²: NaN where only an
        upper limit is known (the map never carries a negative estimate); the fits are not
        rebuilt (``fits`` empty; the live service sends none)."""
        if not isinstance(d, dict):
            raise FormatError(f"a separation is a map, not {type(d).__name__}")
        try:
            sensors = tuple(_strings(d["sensors"], "sensors"))
            if len(sensors) not in PAIRS:
                raise FormatError(f"a separation has 2 or 3 sensors, not {len(sensors)}")
            axes_in = d["axes"]
            if not isinstance(axes_in, dict) or not axes_in:
                raise FormatError("a separation's axes must be a non-empty map")
            axes = []
            for name, ax in axes_in.items():
                if not isinstance(ax, dict):
                    raise FormatError(f"axis {name!r} is not a map")
                tau = _floats(ax["tau"], f"{name}.tau")
                k = len(tau)
                m = _ints(ax["m"], f"{name}.m", k) if "m" in ax else \
                    np.rint(tau * float(d["rate_hz"])).astype(np.int64)
                per = ax["sensors"]
                if not isinstance(per, dict) or set(per) != set(sensors):
                    raise FormatError(f"axis {name!r} must hold every sensor of "
                                      f"{list(sensors)}")
                own = tuple(_part(per[s]["self_noise"], f"{name}.{s}", k) for s in sensors)
                verdicts = tuple(_verdict_of(per[s]["verdict"], f"{name}.{s}", k)
                                 for s in sensors)
                problems = tuple(p if isinstance(p := per[s].get("fit_problem"), str) else None
                                 for s in sensors)
                axes.append(AxisSeparation(str(name), tau, m,
                                           _ints(ax["averages"], f"{name}.averages", k), own,
                                           _part(ax["common"], f"{name}.common", k), verdicts,
                                           (), problems))
            return cls(sensors, str(d["method"]), float(d["rate_hz"]), int(d["n_samples"]),
                       float(d["ci"]), tuple(axes), tuple(_strings(d.get("notes", []), "notes")),
                       tuple(_strings(d.get("sources", []), "sources")))
        except KeyError as exc:
            raise FormatError(f"a separation map lacks {exc}; it is not one") from None
        except (TypeError, ValueError, OverflowError, AttributeError) as exc:
            raise FormatError(f"a separation map does not decode: {exc}") from None


def _strings(v: Any, what: str) -> list[str]:
    if not isinstance(v, list | tuple) or not all(isinstance(x, str) for x in v):
        raise FormatError(f"separation {what} must be a list of strings")
    return list(v)


def _floats(v: Any, what: str, k: int | None = None) -> NDArray[np.float64]:
    """A list of numbers or nulls (NaN) of length ``k``."""
    if not isinstance(v, list | tuple) or (k is not None and len(v) != k):
        raise FormatError(f"separation {what} must be a list of {k if k is not None else ''} "
                          "numbers".replace("  ", " "))
    return np.array([np.nan if x is None else float(x) for x in v], dtype=np.float64)


def _ints(v: Any, what: str, k: int) -> NDArray[np.int64]:
    if not isinstance(v, list | tuple) or len(v) != k or \
            not all(isinstance(x, int) and not isinstance(x, bool) for x in v):
        raise FormatError(f"separation {what} must be a list of {k} integers")
    return np.array(v, dtype=np.int64)


def _part(d: Any, what: str, k: int) -> Part:
    if not isinstance(d, dict):
        raise FormatError(f"separation {what} is not a map")
    ul = d["upper_limit"]
    if not isinstance(ul, list | tuple) or len(ul) != k or \
            not all(isinstance(u, bool) for u in ul):
        raise FormatError(f"separation {what}.upper_limit must be a list of {k} booleans")
    upper = np.array(ul, dtype=bool)
    adev, lo, hi = (_floats(d[key], f"{what}.{key}", k) for key in ("adev", "adev_lo",
                                                                     "adev_hi"))
    if np.any(np.isnan(adev) != upper) or np.any(np.isnan(hi)) or np.any(hi < 0) \
            or np.any(adev < 0):
        raise FormatError(f"separation {what}: an ADEV is given exactly where it is not an "
                          "upper limit, and every upper end is a number ≥ 0")
    return Part(adev**2, np.where(upper, 0.0, lo**2), hi**2, upper,
                _floats(d["edf"], f"{what}.edf", k))


def _verdict_of(d: Any, what: str, k: int) -> Verdict:
    if not isinstance(d, dict):
        raise FormatError(f"separation {what}.verdict is not a map")
    state = _strings(d["state"], f"{what}.verdict.state")
    if len(state) != k or not set(state) <= {"below", "above", "not resolved"}:
        raise FormatError(f"separation {what}.verdict.state must be {k} of below, above, "
                          "not resolved")
    return Verdict(tuple(state), _floats(d["factor"], f"{what}.verdict.factor", k),
                   _floats(d["factor_at_least"], f"{what}.verdict.factor_at_least", k))


def _num(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def separate(accels: Sequence[ArrayLike], rate_hz: float, *, sensors: Sequence[str],
             axes: Sequence[str], taus: str | ArrayLike = "octave", ci: float = 0.683,
             fit: bool = True, filter_corner_hz: float | None = None,
             notes: Sequence[str] = (), sources: Sequence[str] = (),
             overlap: int | None = None) -> Separation:
    """Separate 2 or 3 aligned records (each (N, C) in m/s² at ``rate_hz``, the same N and
    channels ``axes``) into each sensor's self-noise and the common input, per τ and axis
    (eqs. 1–3 of the module docstring); with ``fit`` the IEEE terms of each self-noise by
    :func:`avard.core.model.fit.fit_noise`. The Allan moments are fully overlapping, or with
    ``overlap`` S the partially overlapping ones the service's streaming accumulators keep
    (stride m/S above m = S; core/allan/cross.py), which the live separation equals."""
    ys = [np.asarray(a, dtype=np.float64) for a in accels]
    ys = [y[:, None] if y.ndim == 1 else y for y in ys]
    s = len(ys)
    if s not in (2, 3):
        raise DataError(f"separate takes 2 or 3 co-located sensors, not {s}")
    if len(sensors) != s or len(set(sensors)) != s:
        raise DataError(f"{s} records need {s} distinct sensor names, got {list(sensors)}")
    shape = ys[0].shape
    if any(y.shape != shape for y in ys) or shape[1] != len(axes):
        raise DataError("the records must be aligned first: the same samples and axes "
                        f"(shapes {[y.shape for y in ys]}, axes {list(axes)})")
    if not (0.0 < ci < 1.0):
        raise DataError(f"ci={ci}: a confidence level is between 0 and 1")
    out = []
    for c, axis in enumerate(axes):
        out.append(_separate_axis([y[:, c] for y in ys], float(rate_hz), axis, taus, ci,
                                  fit, filter_corner_hz, overlap))
    method = "groslambert covariance" if s == 2 else "three-cornered hat"
    return Separation(tuple(sensors), method, float(rate_hz), int(shape[0]), ci, tuple(out),
                      tuple(notes), tuple(sources), filter_corner_hz)


PAIRS = {2: ((0, 1),), 3: ((0, 1), (0, 2), (1, 2))}


def _separate_axis(cols: list[NDArray[np.float64]], rate: float, axis: str,
                   taus: str | ArrayLike, ci: float, fit: bool,
                   filter_corner_hz: float | None, overlap: int | None) -> AxisSeparation:
    s = len(cols)
    pairs = PAIRS[s]
    diffs = [cols[i] - cols[j] for i, j in pairs]
    if overlap is None:
        res = allan_variance(np.column_stack(cols + diffs), rate, taus, kind="oavar", ci=ci)
    else:
        res = allan_variance(np.column_stack(cols + diffs), rate, taus, kind="pavar", ci=ci,
                             overlap=overlap)
    moments = {pair: PairMoments.from_result(res, pair[0], pair[1], s + k, len(cols[0]))
               for k, pair in enumerate(pairs)}
    sep = separate_moments(moments, s, axis, ci)
    return _fitted(sep, rate, ci, filter_corner_hz) if fit else sep


def _fitted(sep: AxisSeparation, rate: float, ci: float,
            filter_corner_hz: float | None) -> AxisSeparation:
    """The axis with the IEEE terms fitted to each sensor's self-noise (the one fit)."""
    fits, problems = [], []
    for i in range(len(sep.self_noise)):
        f, problem = _fit(sep.self_result(i, rate, ci), filter_corner_hz)
        fits.append(f)
        problems.append(problem)
    return replace(sep, fits=tuple(fits), fit_problems=tuple(problems))


def separate_moments(moments: Mapping[tuple[int, int], PairMoments], n_sensors: int,
                     axis: str, ci: float = 0.683) -> AxisSeparation:
    """THE estimator: each of ``n_sensors`` (2 or 3) sensors' self-noise and the common part
    at the τ every pair has (eqs. 1–3), from the Allan moments of each pair (i, j), i < j
    (``PAIRS``): the batch path (:func:`separate`) and the service's streaming accumulators
    (core/allan/cross.py) both hand it :class:`PairMoments`. A sensor's own Allan variance
    and EDF are the mean over the pairs it is in (the same number when the pairs cover the
    same samples; pairs with different losses cover slightly different ones). τ with fewer
    than :data:`MIN_AVERAGES` averages (over the fewest samples of any pair) are left out."""
    s = n_sensors
    pairs = PAIRS.get(s)
    if pairs is None or set(moments) != set(pairs):
        raise DataError(f"the separation takes the moments of every pair of 2 or 3 sensors "
                        f"({pairs}), not {sorted(moments)}")
    ms = [moments[p].m[moments[p].n > 0] for p in pairs]
    m_all = ms[0]
    for other in ms[1:]:
        m_all = np.intersect1d(m_all, other)
    got = {p: moments[p].at(m_all) for p in pairs}
    n_total = min(g.n_samples for g in got.values())
    averages = n_total // m_all
    finite = np.ones(len(m_all), dtype=bool)
    for g in got.values():
        finite &= np.isfinite(g.edf_a) & np.isfinite(g.edf_b) & np.isfinite(g.edf_d)
    keep = (averages >= MIN_AVERAGES) & finite
    if not np.any(keep):
        raise DataError(f"axis {axis}: the records are too short for a single Allan "
                        f"covariance with {MIN_AVERAGES} averages")
    got = {p: g.at(m_all[keep]) for p, g in got.items()}
    first = got[pairs[0]]
    tau, m = first.tau, first.m
    var, edf = [], []
    for i in range(s):       # each sensor's own Allan variance, from the pairs it is in
        mine = [(g.var_a, g.edf_a) if p[0] == i else (g.var_b, g.edf_b)
                for p, g in got.items() if i in p]
        var.append(np.mean([v for v, _ in mine], axis=0))
        edf.append(np.mean([e for _, e in mine], axis=0))

    def pair(i: int, j: int) -> PairMoments:
        return got[(min(i, j), max(i, j))]

    est, big_p, big_q, nu = [], [], [], []
    for i in range(s):
        if s == 2:
            d = pair(0, 1)
            est.append(var[i] - d.cov)                                     # (1)
            big_p.append(var[i])
            big_q.append(d.var_d)
            nu.append(np.sqrt(edf[i] * d.edf_d))
        else:
            j, k = (x for x in range(3) if x != i)
            dij, dik, djk = pair(i, j), pair(i, k), pair(j, k)
            est.append(0.5 * (dij.var_d + dik.var_d - djk.var_d))          # (2)
            big_p.append(dij.var_d)
            big_q.append(dik.var_d)
            nu.append(np.sqrt(dij.edf_d * dik.edf_d))
    est.append(np.mean([got[p].cov for p in pairs], axis=0))
    if s == 2:
        big_p.append(var[0])
        big_q.append(var[1])
    else:    # the mean of three covariances varies less than one: (3) for one is wider
        mean_a = np.mean(np.column_stack(var), axis=1)
        big_p.append(mean_a)
        big_q.append(mean_a)
    nu.append(np.min(np.column_stack(edf), axis=1))

    k = len(tau)
    lo, hi, upper, nu_eff = covariance_interval(
        np.concatenate(est), np.concatenate(big_p), np.concatenate(big_q),
        np.concatenate(nu), ci)
    parts = [Part(np.concatenate(est)[q * k:(q + 1) * k], lo[q * k:(q + 1) * k],
                  hi[q * k:(q + 1) * k], upper[q * k:(q + 1) * k], nu_eff[q * k:(q + 1) * k])
             for q in range(s + 1)]
    self_parts, common_part = tuple(parts[:s]), parts[s]
    verdicts = tuple(_verdict(p, common_part) for p in self_parts)
    return AxisSeparation(axis, tau, m, averages[keep], self_parts, common_part, verdicts)


def _fit(result: AllanResult, filter_corner_hz: float | None) -> tuple[Any, str | None]:
    from avard.core.model.fit import fit_noise

    try:
        return fit_noise(result, filter_corner_hz=filter_corner_hz, ci=result.ci), None
    except AvardError as exc:
        return None, str(exc)


def _verdict(own: Part, common: Part) -> Verdict:
    below = common.hi < own.lo
    above = ~common.upper_limit & (common.lo > own.hi)
    state = tuple("below" if b else "above" if a else "not resolved"
                  for b, a in zip(below, above, strict=True))
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = np.where(own.upper_limit | common.upper_limit, np.nan,
                          np.sqrt(own.var / common.var))
        least = np.where(below & (common.hi > 0), np.sqrt(own.lo / common.hi), np.nan)
        least = np.where(below & (common.hi <= 0), np.inf, least)
    return Verdict(state, factor, least)


class _Spread:
    """The distribution (3) of the estimates Ŝ at S tested, on one χ²_ν quantile grid: the
    other parts P − S and Q − S either evaluated at the S tested (``at_tested``: P, Q held
    at P̂, Q̂) or held at ``ref`` (P̂ − ref, Q̂ − ref), never below 0."""

    def __init__(self, big_p: NDArray[np.float64], big_q: NDArray[np.float64],
                 x_over: NDArray[np.float64], ref: NDArray[np.float64] | None) -> None:
        self.p, self.q, self.x_over = big_p, big_q, x_over
        self.b_p = None if ref is None else np.clip(big_p - ref, 0.0, None)
        self.b_q = None if ref is None else np.clip(big_q - ref, 0.0, None)

    def cdf(self, s_true: NDArray[np.float64], x: NDArray[np.float64],
            at: NDArray[np.intp]) -> NDArray[np.float64]:
        """P(Ŝ ≤ x | S = s_true) for the estimates ``at``."""
        if self.b_p is None or self.b_q is None:
            r = np.sqrt(np.maximum(self.p[at], s_true) * np.maximum(self.q[at], s_true))
        else:
            r = np.sqrt((s_true + self.b_p[at]) * (s_true + self.b_q[at]))
        lp, lm = (r + s_true) / 2.0, (r - s_true) / 2.0
        xo = self.x_over[:, at]
        vals = lp * xo[:, None, :] - lm * xo[None, :, :]
        return np.mean(vals <= x, axis=(0, 1))

    def solve(self, level: float, x: NDArray[np.float64], at: NDArray[np.intp],
              top: NDArray[np.float64]) -> NDArray[np.float64]:
        """The S in [0, top] at which P(Ŝ ≤ x | S) falls to ``level`` (it falls with S)."""
        a, b = np.zeros(len(at)), top.copy()
        for _ in range(_BISECT):
            mid = (a + b) / 2.0
            below = self.cdf(mid, x, at) <= level
            b = np.where(below, mid, b)
            a = np.where(below, a, mid)
        return b

    def top(self, x: NDArray[np.float64], tail: float) -> NDArray[np.float64]:
        """An S above the upper end of every estimate ``x`` (grown until so)."""
        every = np.arange(len(x))
        top = 4.0 * np.maximum.reduce([np.abs(x), self.p, self.q, np.full_like(x, 1e-300)])
        for _ in range(200):
            need = self.cdf(top, x, every) > tail
            if not np.any(need):
                break
            top = np.where(need, top * 2.0, top)
        return top


def _belt(s_hat: NDArray[np.float64], spread: _Spread, ci: float
          ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """The Neyman belt with the boundary S ≥ 0: each S accepts the central ``ci``, or all
    below its ``ci`` quantile where S lies below the sensitivity S*."""
    tail = (1.0 - ci) / 2.0
    every = np.arange(len(s_hat))
    s_plus = np.clip(s_hat, 0.0, None)
    # hi: the S whose central region starts at the estimate; an estimate below 0 gets S*
    upper_end = spread.solve(tail, s_plus, every, spread.top(s_plus, tail))
    # lo = 0 where S = 0 accepts the estimate: below S = 0's ci quantile
    upper_limit = spread.cdf(np.zeros_like(s_hat), s_hat, every) <= ci
    lower_end = np.zeros_like(s_hat)
    two = np.flatnonzero(~upper_limit)
    if len(two):
        central = spread.solve(1.0 - tail, s_hat[two], two, upper_end[two])
        lower_end[two] = central
        # where that lies below S* the S accepting the estimate are the one-sided ones
        near = spread.cdf(central, np.zeros(len(two)), two) > tail
        if np.any(near):
            at = two[near]
            s_star = spread.solve(tail, np.zeros(len(at)), at, upper_end[at])
            one_sided = spread.solve(ci, s_hat[at], at, upper_end[at])
            lower_end[at] = np.minimum(one_sided, s_star)
    return lower_end, upper_end, upper_limit


def _central_with_floor(s_hat: NDArray[np.float64], big_p: NDArray[np.float64],
                        big_q: NDArray[np.float64], x_over: NDArray[np.float64], ci: float
                        ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """The central ``ci`` inversion of (3) with the other parts held at the estimate, an
    upper limit where its lower end reaches 0, that limit never below a zero estimate's."""
    tail = (1.0 - ci) / 2.0
    both = np.concatenate([s_hat, np.zeros_like(s_hat)])      # the zero estimates ride along
    spread = _Spread(np.concatenate([big_p, big_p]), np.concatenate([big_q, big_q]),
                     np.concatenate([x_over, x_over], axis=1), both)
    every = np.arange(len(both))
    hi = spread.solve(tail, both, every, spread.top(both, tail))
    k = len(s_hat)
    upper_end = np.maximum(hi[:k], hi[k:])                    # the floor
    mine = np.arange(k)
    upper_limit = 1.0 - spread.cdf(np.zeros(k), s_hat, mine) > tail
    lower_end = np.zeros(k)
    two = np.flatnonzero(~upper_limit)
    if len(two):
        lower_end[two] = spread.solve(1.0 - tail, s_hat[two], two, upper_end[two])
    return lower_end, upper_end, upper_limit


def covariance_interval(est: ArrayLike, big_p: ArrayLike, big_q: ArrayLike, nu: ArrayLike,
                        ci: float = 0.683) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                                    NDArray[np.bool_], NDArray[np.float64]]:
    """The ``ci`` interval [lo, hi] of variances S ≥ 0 estimated by Ŝ = mean ½UV (eq. 3),
    from the estimate, P̂ and Q̂ (the estimated E[½U²], E[½V²]) and the EDF ν;
    ``upper_limit`` where lo is 0; and the EDF of a χ² with the same relative variance,
    2S²/Var Ŝ (for the fit's weights).

    A Neyman construction (module docstring): each hypothesised S gets the distribution (3)
    with P and Q at P̂ and Q̂ (the other parts P − S and Q − S evaluated at the S tested, never
    below 0), and accepts the central ``ci`` of it, or everything below its ``ci`` quantile
    where S lies below the sensitivity S* (the upper end a zero estimate gets: the physical
    boundary S ≥ 0, as Feldman & Cousins' unified construction treats it). The interval is
    the S that accept the estimate: no interval is empty, and an upper end is never below S*.

    Below ν = :data:`_FEW_NU` (fewer than about 5 averages) P̂ and Q̂ are too uncertain to be
    held: there the interval is the hull of this one and the central inversion with the other
    parts held at the estimate and a zero estimate's upper end as floor (wider there)."""
    s_hat = np.asarray(est, dtype=np.float64)
    nu = np.clip(np.asarray(nu, dtype=np.float64), 1.0, None)
    big_p = np.clip(np.asarray(big_p, dtype=np.float64), 0.0, None)
    big_q = np.clip(np.asarray(big_q, dtype=np.float64), 0.0, None)
    x_over = chi2_ppf_grid((np.arange(_GRID) + 0.5) / _GRID, nu) / nu
    lower_end, upper_end, upper_limit = _belt(s_hat, _Spread(big_p, big_q, x_over, None), ci)
    few = np.flatnonzero(nu < _FEW_NU)
    if len(few):
        lo2, hi2, ul2 = _central_with_floor(s_hat[few], big_p[few], big_q[few],
                                            x_over[:, few], ci)
        lower_end[few] = np.minimum(lower_end[few], lo2)
        upper_end[few] = np.maximum(upper_end[few], hi2)
        upper_limit[few] |= ul2
        lower_end[upper_limit] = 0.0
    s_plus = np.clip(s_hat, 0.0, None)
    var_hat = (big_p * big_q + s_plus**2) / nu
    with np.errstate(divide="ignore", invalid="ignore"):
        nu_eff = np.where(var_hat > 0, 2.0 * s_plus**2 / var_hat, 0.0)
    return lower_end, upper_end, upper_limit, nu_eff


# -- the records ----------------------------------------------------------------------------

@dataclass(frozen=True)
class SensorRecord:
    """One co-located sensor's record as separate needs it: samples (N, C) m/s², channel
    names, the fitted rate and its standard uncertainty (0 when unknown), the CLOCK_REALTIME
    of the first sample (None when the record has no time), the file."""

    accel: NDArray[np.float64]
    names: tuple[str, ...]
    rate_hz: float
    rate_u_hz: float = 0.0
    t0_s: float | None = None
    source: str = ""
    meta: dict[str, Any] = field(default_factory=dict)
    sensor_name: str | None = None        # the recording header's sensor.name, when it has one


def read_sensor(path: str | Path, *, rate_hz: float | None = None) -> SensorRecord:
    """THE place separate reads a record (through core/io/readers.py; to become the record
    source's ``open_record``): samples, rate, its uncertainty and start time."""
    from avard.core.io.readers import load_record

    rec = load_record(path, rate_hz=rate_hz)
    meta = rec.meta
    t0, rate_u, name = None, 0.0, None
    headers = meta.get("headers") or []
    if headers and isinstance(headers[0].get("sensor"), dict):
        got = headers[0]["sensor"].get("name")
        name = got if isinstance(got, str) and got else None
    index = meta.get("index")
    if headers and index is not None and len(index):
        h = headers[0]
        if isinstance(h.get("t_real"), int | float) and isinstance(h.get("i0"), int):
            t0 = float(h["t_real"]) + (int(index[0]) - int(h["i0"])) / rec.rate_hz
        tb = headers[-1].get("timebase") or {}
        if isinstance(tb.get("odr_u_hz"), int | float) and math.isfinite(tb["odr_u_hz"]):
            rate_u = float(tb["odr_u_hz"])
    return SensorRecord(np.asarray(rec.accel, dtype=np.float64), tuple(rec.names),
                        float(rec.rate_hz), rate_u, t0, str(path), dict(meta), name)


@dataclass(frozen=True)
class Aligned:
    """Records cut to their common stretch: (N, C) each at one rate, and what was done."""

    accels: tuple[NDArray[np.float64], ...]
    rate_hz: float
    axes: tuple[str, ...]
    notes: tuple[str, ...]


def align(records: Sequence[SensorRecord], channels: Sequence[str] | None = None) -> Aligned:
    """Cut 2 or 3 records to the samples they share: by time when every record has a start
    time (refusing records that do not overlap), else by index (said in the notes); at one
    rate, resampling (averages over the common sample interval) only when the rates are not
    compatible by core/io/rates.py's rule."""
    if len(records) not in (2, 3):
        raise DataError(f"separate takes 2 or 3 records of co-located sensors, not "
                        f"{len(records)}")
    axes = [n for n in records[0].names if all(n in r.names for r in records[1:])]
    if channels:
        missing = [c for c in channels if c not in axes]
        if missing:
            raise DataError(f"--channels {', '.join(missing)}: not a channel every record has "
                            f"(shared: {', '.join(axes) or 'none'})")
        axes = list(channels)
    if not axes:
        raise DataError("the records share no channel name; they cannot be compared axis by "
                        "axis (name the axes alike, e.g. x y z)")
    notes: list[str] = []
    first = records[0]
    same_rate = all(rates_compatible(first.rate_hz, r.rate_hz, first.rate_u_hz, r.rate_u_hz)
                    for r in records[1:])
    rate = min(r.rate_hz for r in records) if not same_rate else \
        float(np.mean([r.rate_hz for r in records]))
    cols = [[r.names.index(a) for a in axes] for r in records]
    timed = all(r.t0_s is not None for r in records)
    if timed:
        starts = [float(r.t0_s) for r in records]  # type: ignore[arg-type]
        ends = [t + len(r.accel) / r.rate_hz for t, r in zip(starts, records, strict=True)]
        t_a, t_b = max(starts), min(ends)
        if t_b <= t_a:
            raise DataError("the records do not overlap in time (" + "; ".join(
                f"{r.source or i}: {s:.3f}–{e:.3f} s" for i, (r, s, e) in
                enumerate(zip(records, starts, ends, strict=True))) + "); co-located sensors "
                "must be recorded at the same time")
        notes.append(f"aligned by time: {t_b - t_a:.6g} s shared by every record")
    else:
        t_a = 0.0
        starts = [0.0] * len(records)
        t_b = min(len(r.accel) / r.rate_hz for r in records)
        notes.append("aligned by index: not every record carries its start time, so their "
                     "first samples are taken as simultaneous")
    if same_rate:
        offs = _tick_offsets(starts, records, t_a) if timed else [0] * len(records)
        n = min(len(r.accel) - o for o, r in zip(offs, records, strict=True))
        accels = tuple(r.accel[o:o + n][:, c] for o, r, c in zip(offs, records, cols,
                                                                  strict=True))
    else:
        n = math.floor((t_b - t_a) * rate + 1e-9)
        accels = tuple(_resample(r.accel[:, c], r.rate_hz, s, t_a, rate, n)
                       for r, c, s in zip(records, cols, starts, strict=True))
        notes.append("resampled to " + f"{rate:.10g} Hz: the rates " + ", ".join(
            f"{r.rate_hz:.10g}" for r in records) + " Hz are not one rate by core/io/rates.py's"
            " rule; each new sample is the average over its interval (short τ are smoothed)")
    if n < 4:
        raise DataError(f"the records share only {max(n, 0)} samples; too few to separate")
    return Aligned(accels, rate, tuple(axes), tuple(notes))


def _tick_offsets(starts: Sequence[float], records: Sequence[SensorRecord],
                  t_a: float) -> list[int]:
    """Each record's first sample of the common stretch, by the live aligner's rule
    (daemon/service/separation_stage.Aligner): the first record's samples are the ticks,
    from the first whose nearest sample in every record exists; every other record's sample
    at a tick is the one nearest in time. (Rounding each record from ``t_a`` on its own
    would pair sensors that started a fraction of a sample apart differently from the live
    separation.)"""
    ref = records[0]
    o0 = max(0, math.ceil((t_a - starts[0]) * ref.rate_hz - 0.5 - 1e-9))
    tick = starts[0] + o0 / ref.rate_hz
    return [o0, *(max(0, round((tick - s) * r.rate_hz))
                  for s, r in zip(starts[1:], records[1:], strict=True))]


def _resample(y: NDArray[np.float64], rate: float, t0: float, t_a: float, new_rate: float,
              n: int) -> NDArray[np.float64]:
    """Averages of the rate samples ``y`` over [t_a + k/new_rate, t_a + (k+1)/new_rate): the
    phase (running integral) read at the new sample edges, differenced (what an Allan
    variance at the new rate sees)."""
    phase = np.concatenate([np.zeros((1, y.shape[1])), np.cumsum(y, axis=0) / rate])
    t_old = t0 + np.arange(len(phase)) / rate
    edges = t_a + np.arange(n + 1) / new_rate
    at = np.column_stack([np.interp(edges, t_old, phase[:, c]) for c in range(y.shape[1])])
    return np.diff(at, axis=0) * new_rate


# -- recordings of several runs: aligned run by run, as the live separation aligns them -------

#: How far (in samples) the live aligner lets the fitted position of a partner's sample move
#: from the one in use before it slips (daemon/service/separation_stage.SLIP_SAMPLES).
_SLIP_SAMPLES = 0.75


@dataclass(frozen=True)
class AlignedRun:
    """One run of 2 or 3 co-located sensors' recordings on the first sensor's ticks:
    ``index`` (S, n) each sensor's own sample index at each tick (−1 where it has none),
    ``accel`` (S, n, A) m/s² (meaningless where the index is −1)."""

    run: str
    index: NDArray[np.int64]
    accel: NDArray[np.float64]


def _runs_of(rec: SensorRecord) -> dict[str, tuple[dict[str, Any], NDArray[np.intp]]]:
    """A recording's runs: run id → (the first header of it, the rows of its samples)."""
    headers = [h for h in rec.meta.get("headers") or [] if isinstance(h.get("i0"), int)]
    index = np.asarray(rec.meta.get("index"), dtype=np.int64)
    if not headers or len(index) != len(rec.accel):
        raise DataError(f"{rec.source or 'a record'}: aligning run by run needs a recording "
                        "(its headers and sample indices)")
    starts = np.array([int(h["i0"]) for h in headers], dtype=np.int64)
    order = np.argsort(starts, kind="stable")
    starts = starts[order]
    which = np.searchsorted(starts, index, side="right") - 1    # the header each sample follows
    out: dict[str, tuple[dict[str, Any], NDArray[np.intp]]] = {}
    for k in range(len(starts)):
        h = headers[int(order[k])]
        rows = np.flatnonzero(which == k)
        run = str(h.get("run"))
        if run in out:                         # a header copy of the same run
            out[run] = (out[run][0], np.concatenate([out[run][1], rows]))
        elif len(rows):
            out[run] = (h, rows)
    return out


def _time_line(h: dict[str, Any], rate: float) -> tuple[float, int, float]:
    t = h.get("t_real")
    r = h.get("rate_hz", rate)
    if not isinstance(t, int | float) or not isinstance(r, int | float) or not r > 0:
        raise DataError(f"run {h.get('run')!r}: its header has no time (t_real) or rate")
    return float(t), int(h["i0"]), float(r)


def aligned_runs(records: Sequence[SensorRecord]) -> list[AlignedRun]:
    """Recordings of 2 or 3 co-located sensors aligned run by run (a restart, in a rig all
    sensors' recordings change run together), by the live aligner's rule
    (daemon/service/separation_stage.Aligner): in each run the first sensor's indices are the
    ticks, from its first sample of the run to its last; another sensor's sample at a tick is
    the one its run's time line (header ``t_real`` at ``i0``, ``rate_hz``) puts nearest the
    tick's time at the run's first tick, then the next one per tick (no slip: a constant
    offset within a run); a tick is kept up to the first whose sample of another sensor
    lies beyond that sensor's last of the run (the live aligner's rule at stop).
    Runs not in every recording are left out (none shared: an empty list). The same
    function aligns the tail a live separation replays after a restart
    (daemon/service/rig_separation.py)."""
    if len(records) not in (2, 3):
        raise DataError(f"separate takes 2 or 3 records of co-located sensors, not "
                        f"{len(records)}")
    runs = [_runs_of(r) for r in records]
    out: list[AlignedRun] = []
    ref_runs = sorted(runs[0].items(), key=lambda kv: int(kv[1][0]["i0"]))
    for run, (h0, rows0) in ref_runs:
        if not all(run in r for r in runs[1:]):
            continue
        idx0 = np.asarray(records[0].meta["index"])[rows0]
        ticks = np.arange(int(idx0.min()), int(idx0.max()) + 1, dtype=np.int64)
        t0, i0, r0 = _time_line(h0, records[0].rate_hz)
        t_tick = t0 + (ticks - i0) / r0
        keep = len(ticks)
        partner: list[NDArray[np.int64]] = [ticks]
        for rec, rr in zip(records[1:], runs[1:], strict=True):
            h, rows = rr[run]
            ts, i_s, rs = _time_line(h, rec.rate_hz)
            x = i_s + (t_tick - ts) * rs
            own = np.asarray(rec.meta["index"])[rows]
            first = int(np.rint(x[0]))
            keep = min(keep, int(own.max()) + 1 - first)     # up to its last of the run
            partner.append(first + np.arange(len(ticks), dtype=np.int64))
        if keep <= 0:
            continue
        n_s, n_ax = len(records), records[0].accel.shape[1]
        index = np.full((n_s, keep), -1, dtype=np.int64)
        accel = np.zeros((n_s, keep, n_ax))
        for s, (rec, rr) in enumerate(zip(records, runs, strict=True)):
            rows = rr[run][1]
            own = np.asarray(rec.meta["index"])[rows]
            order = np.argsort(own, kind="stable")
            own, rows = own[order], rows[order]
            want = partner[s][:keep]
            pos = np.minimum(np.searchsorted(own, want), len(own) - 1)
            ok = own[pos] == want
            index[s, ok] = want[ok]
            accel[s, ok] = rec.accel[rows[pos[ok]]]
        out.append(AlignedRun(run, index, accel))
    return out


def is_multi_run(records: Sequence[SensorRecord]) -> bool:
    """Whether any record is a recording holding more than one run (a restart) or a loss (a
    jump in its sample index): such records are separated run by run
    (:func:`separate_runs`: a gap at every missing row), never as one stretch whose
    differences would straddle the loss (a record without runs beside them is then refused
    by :func:`aligned_runs`, not concatenated)."""
    def segmented(r: SensorRecord) -> bool:
        index = r.meta.get("index")
        if index is None or not len(index):
            return False
        hs = r.meta.get("headers") or []
        return len({h.get("run") for h in hs}) > 1 or bool(np.any(np.diff(index) != 1))
    return any(segmented(r) for r in records)


def separation_of_pairs(pairs: Mapping[tuple[int, int], Any], sensors: Sequence[str],
                        rate_hz: float, ci: float, notes: Sequence[str] = (),
                        sources: Sequence[str] = ()) -> Separation:
    """The separation of what pair accumulators (:class:`~avard.core.allan.cross.CrossAllan`
    per pair of ``PAIRS``) hold, τ labelled with ``rate_hz``: the live separation's and
    :func:`separate_runs`'s one way from the pairs to the result. DataError while no τ has
    enough averages in every pair."""
    moments = {p: acc.moments(ci) for p, acc in pairs.items()}
    first = next(iter(pairs.values()))
    axes = tuple(separate_moments({p: m[c] for p, m in moments.items()}, len(sensors), ax, ci)
                 for c, ax in enumerate(first.axes))
    axes = tuple(replace(ax, tau=ax.m / float(rate_hz)) for ax in axes)
    method = "groslambert covariance" if len(sensors) == 2 else "three-cornered hat"
    n = min(acc.n_samples for acc in pairs.values())
    return Separation(tuple(sensors), method, float(rate_hz), n, ci, axes, tuple(notes),
                      tuple(sources))


def separate_runs(runs: Sequence[AlignedRun], rate_hz: float, *, sensors: Sequence[str],
                  axes: Sequence[str], ci: float = 0.683, overlap: int = 8,
                  fit: bool = False, filter_corner_hz: float | None = None,
                  notes: Sequence[str] = (), sources: Sequence[str] = ()) -> Separation:
    """Separate recordings aligned run by run (:func:`aligned_runs`): each pair's streaming
    Allan moments (partially overlapping, stride m/``overlap``: the live separation's) fed
    every run's rows, a gap at each missing row and between runs, so no difference straddles
    a restart or a loss; with ``fit`` the IEEE terms of each self-noise, as :func:`separate`
    (the live separation has none)."""
    from avard.core.allan.cross import CrossAllan

    s = len(sensors)
    if s not in PAIRS:
        raise DataError(f"separate takes 2 or 3 co-located sensors, not {s}")
    if not runs:
        raise DataError("the recordings share no run; co-located sensors must be recorded "
                        "by one rig at the same time")
    pairs = {p: CrossAllan(rate_hz, axes=axes, overlap=overlap,
                           sensors=(sensors[p[0]], sensors[p[1]])) for p in PAIRS[s]}
    for run in runs:
        for (i, j), acc in pairs.items():
            acc.feed(run.index[i], run.index[j], run.accel[i], run.accel[j])
            acc.gap()
    note = (f"aligned run by run ({len(runs)} run{'s' if len(runs) != 1 else ''}: a restart "
            "is a gap for every pair); "
            f"partially overlapping Allan moments (stride m/{overlap} above m = {overlap}), "
            "as the live separation keeps them")
    sep = separation_of_pairs(pairs, sensors, rate_hz, ci, (*notes, note), sources)
    if not fit:
        return sep
    return replace(sep, filter_corner_hz=filter_corner_hz, axes=tuple(
        _fitted(ax, rate_hz, ci, filter_corner_hz) for ax in sep.axes))

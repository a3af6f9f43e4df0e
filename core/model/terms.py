"""Closed-form Allan variance of the IEEE noise terms and of the extra components.

Every function returns AVAR σ²(τ) in (m/s²)² for an accelerometer whose output is rate data
y in m/s² (IEEE Std 952-1997 Annex C, IEEE Std 1293-2018, El-Sheimy et al. 2008, NIST SP 1065
§5.2). Statistically independent components add in AVAR, so every model here is *linear in the
squared coefficients* θ = value²; ``fit.py`` relies on that to fit with non-negative least
squares.

Besides the AVAR curves this module holds each component's power spectral density. The fit
needs them to model the covariance of the AVAR estimates at different τ (neighbouring
overlapping estimates share data): see :func:`avar_covariance_kernels`.

Conventions for the spectral part: discrete-time, two-sided PSD S(ν) of the sample sequence y,
ν in cycles per sample on [−½, ½], so that var(y) = ∫ S(ν) dν. The overlapping AVAR at
τ = m·τ0 is then σ²(τ) = ∫ S(ν)|H_m(ν)|² dν with |H_m|² = 2 sin⁴(πνm) / (m² sin²(πν))
(NIST SP 1065 eq. 12 written as a filter).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from functools import lru_cache

import numpy as np
from avard.core.errors import FitError
from numpy.typing import ArrayLike, NDArray

TERMS = (
    "quantization",
    "velocity_random_walk",
    "bias_instability",
    "rate_random_walk",
    "rate_ramp",
)

#: SI unit of each coefficient (accelerometer; rate data in m/s²).
UNITS = {
    "quantization": "m/s",
    "velocity_random_walk": "m/s/sqrt(s)",
    "bias_instability": "m/s^2",
    "rate_random_walk": "m/s^2/sqrt(s)",
    "rate_ramp": "m/s^3",
}

#: Short symbols used in tables and plots.
SYMBOLS = {
    "quantization": "Q",
    "velocity_random_walk": "N",
    "bias_instability": "B",
    "rate_random_walk": "K",
    "rate_ramp": "R",
}

#: ADEV log-log slope of each term (IEEE 952 Table C.1).
SLOPES = {
    "quantization": -1.0,
    "velocity_random_walk": -0.5,
    "bias_instability": 0.0,
    "rate_random_walk": 0.5,
    "rate_ramp": 1.0,
}

#: The bias-instability floor: ADEV = sqrt(2 ln2 / π)·B ≈ 0.6643·B.
BI_FACTOR = math.sqrt(2.0 * math.log(2.0) / math.pi)


def _tau(tau: ArrayLike) -> NDArray[np.float64]:
    t = np.asarray(tau, dtype=float)
    if np.any(~np.isfinite(t)) or np.any(t <= 0):
        raise FitError("averaging times tau must be finite and > 0 s")
    return t


def term_avar(term: str, tau: ArrayLike, value: float) -> NDArray[np.float64]:
    """AVAR of one IEEE term with coefficient ``value`` (in ``UNITS[term]``) at ``tau`` (s).

    Q: 3Q²/τ²; N: N²/τ; B: (2 ln2/π)B²; K: K²τ/3; R: R²τ²/2 (IEEE 952 Annex C, Table C.1).
    """
    t = _tau(tau)
    v2 = float(value) ** 2
    if term == "quantization":
        return 3.0 * v2 / t**2
    if term == "velocity_random_walk":
        return v2 / t
    if term == "bias_instability":
        return np.full_like(t, BI_FACTOR**2 * v2)
    if term == "rate_random_walk":
        return v2 * t / 3.0
    if term == "rate_ramp":
        return v2 * t**2 / 2.0
    raise FitError(f"unknown noise term {term!r}; choose one of {', '.join(TERMS)}")


def sinusoid_avar(tau: ArrayLike, amplitude: float, frequency_hz: float,
                  rate_hz: float | None = None) -> NDArray[np.float64]:
    """AVAR of A·sin(2πf0 t): A²·(sin²(πf0τ)/(πf0τ))² (IEEE 952 eq. C.21), the continuous
    average's. The peak ADEV is ≈ 0.7246·A at τ ≈ 0.371/f0.

    With ``rate_hz``, of the sinusoid sampled at that rate and averaged over m = τ·rate
    samples: the mean's gain is sin(πf0τ)/(m·sin(πf0/rate)), so πf0τ in the denominator
    becomes m·sin(πf0/rate). The two differ where f0 is not small beside the rate (a 3.1 Hz
    line sampled at 10 Hz: the continuous form is 28 % low at every τ).
    """
    t = _tau(tau)
    return float(amplitude) ** 2 * _unit_sine_avar(t, np.float64(frequency_hz), rate_hz)


def _unit_sine_avar(t: NDArray, f: NDArray | np.float64, rate_hz: float | None
                    ) -> NDArray[np.float64]:
    """``sinusoid_avar`` of unit amplitude, broadcast over τ ``t`` and frequencies ``f``."""
    x = math.pi * f * t
    den = x if rate_hz is None else t * float(rate_hz) * np.sin(math.pi * f / float(rate_hz))
    return np.asarray((np.sin(x) ** 2 / den) ** 2, dtype=np.float64)


#: Frequencies a swept line's band is averaged over (the mean of sin⁴(πfτ)/(πfτ)² over the
#: band needs its oscillation in f, period 1/τ, sampled at the longest τ it still shapes).
SWEEP_POINTS = 256


def swept_sinusoid_avar(tau: ArrayLike, amplitude: float, lo_hz: float, hi_hz: float,
                        rate_hz: float | None = None) -> NDArray[np.float64]:
    """AVAR of a line of amplitude A swept at a steady rate over [lo_hz, hi_hz] (a pump whose
    speed drifts): where τ is short beside the sweep, the record is a succession of steady
    sinusoids, and its AVAR the mean of ``sinusoid_avar`` over the frequencies it passes
    through, equally long at each (its sampled form with ``rate_hz``). Where τ spans many
    periods of the band's spread (τ ≫ 1/(hi − lo)) the steady line's nulls at τ = k/f fill
    in: the mean tends to (3/8)·A²/(πτ)² times the band's mean of 1/f²."""
    t = _tau(tau)
    f = np.linspace(float(lo_hz), float(hi_hz), SWEEP_POINTS)
    return float(amplitude) ** 2 * np.mean(_unit_sine_avar(t[:, None], f[None, :], rate_hz),
                                           axis=1)


def gauss_markov_avar(tau: ArrayLike, sigma: float, T: float) -> NDArray[np.float64]:
    """AVAR of a first-order Gauss–Markov rate noise of standard deviation σ and correlation
    time T (IEEE 952 eq. C.25 with q_c²T/2 = σ²):

        σ²(τ) = (2σ²T/τ)·[1 − (T/2τ)(3 − 4e^{−τ/T} + e^{−2τ/T})].

    Peak ADEV ≈ 0.6174·σ at τ ≈ 1.893·T; for τ ≫ T it is white noise with N² = 2σ²T.
    """
    t = _tau(tau)
    if T <= 0:
        raise FitError("Gauss-Markov correlation time T must be > 0 s")
    x = t / float(T)
    # for x → 0 the bracket cancels catastrophically; its series is x²/3 − x³/4 + 7x⁴/60 − …
    # (so σ²(τ) → 2σ²τ/(3T): a rate random walk with K² = 2σ²/T, as it must)
    small = x < 1e-2
    br = np.empty_like(x)
    xs = x[small]
    br[small] = xs**2 / 3.0 - xs**3 / 4.0 + 7.0 * xs**4 / 60.0
    xl = x[~small]
    br[~small] = 1.0 - (3.0 - 4.0 * np.exp(-xl) + np.exp(-2.0 * xl)) / (2.0 * xl)
    return 2.0 * float(sigma) ** 2 * float(T) / t * br


# --------------------------------------------------------------------------------------------
# The ADXL355's own low-pass filter acting on white noise


def _butterworth(rate_hz: float, corner_hz: float, order: int
                 ) -> tuple[NDArray[np.complex128], NDArray[np.complex128], float]:
    """(zeros, poles, gain) of the Butterworth low-pass at ``corner_hz``: the simulator's own
    design (``sim.linear_filter.butterworth_lowpass_zpk``, numpy, held to
    ``scipy.signal.butter``), so the model and the simulated chip are one filter, and a fit
    of an ADXL355 record loads no scipy (scipy.signal is ~0.5 CPU-s and ~70 MB to import,
    several seconds on a Raspberry Pi)."""
    from avard.core.sim.linear_filter import butterworth_lowpass_zpk

    wn = corner_hz / (rate_hz / 2.0)
    if not 0.0 < wn < 1.0:
        raise FitError(
            f"filter corner {corner_hz} Hz must lie between 0 and the Nyquist frequency "
            f"{rate_hz / 2} Hz"
        )
    return butterworth_lowpass_zpk(order, wn)


def _filter_key(rate_hz: float, corner_hz: float) -> float:
    """The one number the filter's effect depends on, its corner in units of the Nyquist
    frequency, to 7 significant digits: the key of the caches below. Keyed by the rate
    itself, every snapshot of a running service (whose fitted rate moves by parts per
    million from one snapshot to the next) missed them and paid the whole filter
    computation again (a ~6× CPU rise after the first `snapshot` request, issue 26). A
    relative change of 5e-8 in the corner changes the AVAR factors by less than that."""
    wn = float(corner_hz) / (float(rate_hz) / 2.0)
    if not 0.0 < wn < 1.0:
        raise FitError(
            f"filter corner {corner_hz} Hz must lie between 0 and the Nyquist frequency "
            f"{rate_hz / 2} Hz"
        )
    return float(f"{wn:.7g}")


@lru_cache(maxsize=32)
def _lowpass_autocov_wn(wn: float, order: int) -> NDArray[np.float64]:
    """Autocovariance r(k), k = 0…L, of unit-variance white noise through a Butterworth low-pass
    (``order``) at ``corner_hz``, normalised to unit DC gain. The ADXL355 datasheet does not give
    its decimation filter; a 2nd-order Butterworth at ODR/4 reproduces the documented corner and
    is what the simulator uses. The impulse response is truncated where it has decayed to 1e-12.
    """
    from avard.core.sim.linear_filter import ModalFilter

    zeros, poles, gain = _butterworth(2.0, wn, order)   # rate 2: the corner is wn
    n = 64
    while True:
        imp = np.zeros((1, n))
        imp[0, 0] = 1.0
        h = ModalFilter.from_zpk(zeros, poles, gain).run(imp)[0]  # the impulse response
        if np.max(np.abs(h[-8:])) < 1e-12 * np.max(np.abs(h)) or n > 1 << 20:
            break
        n *= 2
    h = h / h.sum()
    r = np.correlate(h, h, mode="full")[len(h) - 1 :]
    return r


def _avar_from_autocov(m: NDArray[np.int64], r: NDArray[np.float64]) -> NDArray[np.float64]:
    """Overlapping AVAR at integer m (in units of τ0) of a stationary sequence with
    autocovariance r(k) (r(k) = 0 beyond len(r)):

        σ²(m) = [Var(S₁) − Cov(S₁, S₂)] / m²,  S = sum of m consecutive samples,
        Var(S₁) = Σ_{|k|<m} (m − |k|) r(k),  Cov(S₁,S₂) = Σ_{k=1}^{2m−1} min(k, 2m−k) r(k).
    """
    out = np.empty(len(m))
    L = len(r)
    for i, mi in enumerate(m):
        k1 = np.arange(1, min(mi, L))
        var_s = mi * r[0] + 2.0 * np.sum((mi - k1) * r[k1])
        k2 = np.arange(1, min(2 * mi, L))
        cov_s = np.sum(np.minimum(k2, 2 * mi - k2) * r[k2])
        out[i] = (var_s - cov_s) / mi**2
    return out


def lowpass_white_avar(
    tau: ArrayLike, N: float, rate_hz: float, corner_hz: float, *, order: int = 2
) -> NDArray[np.float64]:
    """AVAR of white noise of density N (m/s/√s) sampled at ``rate_hz`` after a low-pass at
    ``corner_hz`` (the ADXL355 filter at ODR/4). Exact for the discrete filter: computed from
    the filtered noise's autocovariance at m = round(τ·rate). For τ ≫ 1/corner it tends to
    N²/τ; at a few samples it falls below that line, as the datasheet filter does.
    """
    t = _tau(tau)
    m = np.maximum(np.rint(t * rate_hz).astype(np.int64), 1)
    wn = _filter_key(rate_hz, corner_hz)
    unit = (_lowpass_white_unit(m.tobytes(), wn, int(order)) if m.ndim == 1
            else _avar_from_autocov(m, _lowpass_autocov_wn(wn, int(order))))
    # per-sample variance of the white input is N²·fs (one-sided PSD 2N², allan.md)
    return float(N) ** 2 * rate_hz * unit


@lru_cache(maxsize=256)
def _lowpass_white_unit(m_bytes: bytes, wn: float, order: int) -> NDArray[np.float64]:
    """``_avar_from_autocov`` of the filter's autocovariance at the averaging factors
    ``m_bytes`` (int64): the same numbers for every fit on these τ, and its loop over m was
    the costliest part of building a fit's columns (the Gauss–Markov scan builds a fit per
    correlation time, each with the filtered white column and its covariance kernels)."""
    out = _avar_from_autocov(np.frombuffer(m_bytes, dtype=np.int64),
                             _lowpass_autocov_wn(wn, order))
    out.setflags(write=False)
    return out


def lowpass_gain2(nu: NDArray[np.float64], rate_hz: float, corner_hz: float,
                  order: int = 2) -> NDArray[np.float64]:
    """|G(ν)|² of the same Butterworth low-pass (unit DC gain), ν in cycles per sample:
    gain²·Π|e^{2πiν} − z_i|² / Π|e^{2πiν} − p_k|² from its zeros and poles."""
    zeros, poles, gain = _butterworth(rate_hz, corner_hz, order)
    e = np.exp(2j * np.pi * np.asarray(nu, dtype=np.float64))[..., None]
    num = np.prod(np.abs(e - zeros) ** 2, axis=-1)
    den = np.prod(np.abs(e - poles) ** 2, axis=-1)
    return gain**2 * num / den


# --------------------------------------------------------------------------------------------
# Model AVAR for a parameter set (used by fit.py, report/plot, and the explain pipeline)


def component_avar(cause: str, tau: ArrayLike, params: Mapping[str, float], *,
                   rate_hz: float | None = None) -> NDArray[np.float64]:
    """AVAR of one named component with its parameters.

    ``cause`` is an IEEE term name (params ``{"value": ...}``), ``"sinusoid"``
    (``amplitude``, ``frequency_hz``; swept at a steady rate with ``sweep_lo_hz`` and
    ``sweep_hi_hz``), ``"gauss_markov"`` (``sigma``, ``T``) or ``"filter"``
    / ``"lowpass_white"`` (``N``, ``corner_hz``, optional ``order``; needs ``rate_hz``).
    """
    if cause in TERMS:
        return term_avar(cause, tau, params["value"])
    if cause == "sinusoid":
        lo, hi = params.get("sweep_lo_hz", math.nan), params.get("sweep_hi_hz", math.nan)
        if math.isfinite(lo) and math.isfinite(hi) and 0 < lo < hi:
            return swept_sinusoid_avar(tau, params["amplitude"], lo, hi, rate_hz)
        return sinusoid_avar(tau, params["amplitude"], params["frequency_hz"], rate_hz)
    if cause == "gauss_markov":
        T = params["T"] if "T" in params else params["time_constant_s"]
        return gauss_markov_avar(tau, params["sigma"], T)
    if cause in ("filter", "lowpass_white"):
        if rate_hz is None:
            raise FitError("the filter component needs the sample rate (rate_hz)")
        return lowpass_white_avar(tau, params["N"], rate_hz, params["corner_hz"],
                                  order=int(params.get("order", 2)))
    if cause == "white":
        # unfiltered white noise of density N, e.g. the rounding to the LSB after the filter
        return term_avar("velocity_random_walk", tau, params["N"])
    if cause == "lowpass_flicker":
        if rate_hz is None:
            raise FitError("the filtered flicker component needs the sample rate (rate_hz)")
        return lowpass_flicker_avar(tau, params["value"], rate_hz, params["corner_hz"],
                                    order=int(params.get("order", 2)))
    raise FitError(
        f"unknown model component {cause!r}; use an IEEE term, 'sinusoid', 'gauss_markov' "
        "or 'filter'"
    )


def model_avar(
    tau: ArrayLike,
    terms: Mapping[str, float | None],
    extra: tuple[Mapping, ...] | list[Mapping] = (),
    *,
    rate_hz: float | None = None,
) -> NDArray[np.float64]:
    """Total model AVAR: Σ term_avar(term, τ, value) over ``terms`` (None = absent) plus each
    ``extra`` component ``{"cause": ..., "params": {...}}``. Independent components add."""
    t = _tau(tau)
    total = np.zeros_like(t)
    for name, value in terms.items():
        if value is not None:
            total += term_avar(name, t, value)
    for comp in extra:
        total += component_avar(comp["cause"], t, comp["params"], rate_hz=rate_hz)
    return total


# --------------------------------------------------------------------------------------------
# Spectral side: PSD of each component per unit θ, and the covariance of AVAR estimates

PsdFn = Callable[[NDArray[np.float64]], NDArray[np.float64]]


@lru_cache(maxsize=512)  # one function per component: its values on the nodes are cached
def term_psd(term: str, rate_hz: float) -> PsdFn | None:
    """Two-sided discrete PSD per unit θ = value² (cycles/sample), or None for deterministic
    terms (rate ramp), which add no estimator variance of their own.

    Q: white phase noise of variance Q², y = Δx/τ0 → 4 fs² sin²(πν); N: fs (per-sample
    variance N²fs); B: 1/(2π|ν|) (so that AVAR = (2 ln2/π)B²); K: τ0 / (4 sin²(πν)).
    """
    fs = float(rate_hz)
    if term == "quantization":
        return lambda nu: 4.0 * fs**2 * np.sin(np.pi * nu) ** 2
    if term == "velocity_random_walk":
        return lambda nu: np.full_like(nu, fs)
    if term == "bias_instability":
        return lambda nu: 1.0 / (2.0 * np.pi * np.abs(nu))
    if term == "rate_random_walk":
        return lambda nu: 1.0 / (4.0 * fs * np.sin(np.pi * nu) ** 2)
    if term == "rate_ramp":
        return None
    raise FitError(f"unknown noise term {term!r}")


@lru_cache(maxsize=512)  # one function per component: its values on the nodes are cached
def gauss_markov_psd(rate_hz: float, T: float) -> PsdFn:
    """PSD per unit σ² of a first-order Gauss–Markov process: fs·2T/(1 + (2πνfsT)²)."""
    fs = float(rate_hz)
    return lambda nu: fs * 2.0 * T / (1.0 + (2.0 * np.pi * nu * fs * T) ** 2)


@lru_cache(maxsize=512)  # one function per component: its values on the nodes are cached
def lowpass_flicker_psd(rate_hz: float, corner_hz: float, order: int = 2) -> PsdFn:
    """PSD per unit B² of flicker (bias-instability) noise through the low-pass."""
    fs = float(rate_hz)
    return lambda nu: lowpass_gain2(nu, fs, corner_hz, order) / (2.0 * np.pi * np.abs(nu))


@lru_cache(maxsize=512)  # one function per component: its values on the nodes are cached
def lowpass_white_psd(rate_hz: float, corner_hz: float, order: int = 2) -> PsdFn:
    """PSD per unit N² of white noise through the low-pass: fs·|G(ν)|²."""
    fs = float(rate_hz)
    return lambda nu: fs * lowpass_gain2(nu, fs, corner_hz, order)


@lru_cache(maxsize=256)
def _mean_sin4_product(r: float) -> float:
    """Average over x of sin⁴(x)·sin⁴(r·x): 35/128 for r = 1, → (3/8)² for large or
    incommensurate r. Integer r are periodic in π; others are averaged over a long window."""
    if r > 32:
        return 9.0 / 64.0
    span = np.pi if abs(r - round(r)) < 1e-9 else 400.0 * np.pi
    n = int(max(4096, 64 * r * span / np.pi))
    x = (np.arange(n) + 0.5) * (span / n)
    return float(np.mean(np.sin(x) ** 4 * np.sin(r * x) ** 4))


@lru_cache(maxsize=4096)
def _pair_quadrature(mk: int, ml: int, c: float = 4.0) -> tuple[NDArray, NDArray]:
    """Nodes ν and weights w with Σ w·g(ν) ≈ ∫₀^½ g(ν)|H_mk(ν)|²|H_ml(ν)|² dν for a slowly
    varying g. Below c/ml both oscillations are resolved; between c/ml and c/mk the fast one is
    replaced by its mean 3/8 when it is ≥ 16× faster (else resolved); above c/mk the product
    of both is replaced by its mean (commensurate averages for octave ratios)."""
    if mk > ml:
        mk, ml = ml, mk
    r = ml / mk
    half = 0.5

    def hk2(nu: NDArray, m: int) -> NDArray:
        return 2.0 * np.sin(np.pi * nu * m) ** 4 / (m**2 * np.sin(np.pi * nu) ** 2)

    nodes: list[NDArray] = []
    weights: list[NDArray] = []

    def midpoint(a: float, b: float, step: float) -> tuple[NDArray, float]:
        n = max(int(np.ceil((b - a) / step)), 1)
        return a + (np.arange(n) + 0.5) * ((b - a) / n), (b - a) / n

    nu1 = min(half, c / ml)
    x, h = midpoint(0.0, nu1, 1.0 / (32.0 * ml))
    nodes.append(x)
    weights.append(h * hk2(x, mk) * hk2(x, ml))
    if nu1 < half:
        nu2 = min(half, c / mk)
        if nu2 > nu1:
            if r >= 16:
                x, h = midpoint(nu1, nu2, 1.0 / (32.0 * mk))
                w = h * hk2(x, mk) * 2.0 * (3.0 / 8.0) / (ml**2 * np.sin(np.pi * x) ** 2)
            else:
                x, h = midpoint(nu1, nu2, 1.0 / (32.0 * ml))
                w = h * hk2(x, mk) * hk2(x, ml)
            nodes.append(x)
            weights.append(w)
        if nu2 < half:
            # log-spaced midpoints: the remaining factors vary slowly on a log scale
            edges = np.geomspace(nu2, half, 129)
            x = np.sqrt(edges[1:] * edges[:-1])
            widths = np.diff(edges)
            pbar = _mean_sin4_product(r)
            w = widths * 4.0 * pbar / (mk**2 * ml**2 * np.sin(np.pi * x) ** 4)
            nodes.append(x)
            weights.append(w)
    return np.concatenate(nodes), np.concatenate(weights)


@lru_cache(maxsize=64)
def _kernel_nodes(mkey: tuple[int, ...]) -> tuple[NDArray, NDArray, NDArray, list[tuple[int, int]]]:
    """The quadrature of every pair of averaging factors (``_pair_quadrature``), concatenated:
    (ν, weights, each pair's first node, the pairs). The same for every fit on these τ."""
    K = len(mkey)
    pairs = [(k, j) for k in range(K) for j in range(k, K)]
    quads = [_pair_quadrature(mkey[k], mkey[j]) for k, j in pairs]
    nu = np.concatenate([q[0] for q in quads])
    w = np.concatenate([q[1] for q in quads])
    starts = np.cumsum([0] + [len(q[0]) for q in quads[:-1]])
    for a in (nu, w, starts):
        a.setflags(write=False)
    return nu, w, starts, pairs


@lru_cache(maxsize=128)
def _pair_integrals(mkey: tuple[int, ...], pa: PsdFn | None, pb: PsdFn | None
                    ) -> NDArray[np.float64]:
    """2∫ s_a s_b |H_k|²|H_l|² dν for every pair (k, l) of ``mkey``: cached per pair of
    component PSDs (the PSD functions are cached per component, ``term_psd`` …), so a scan
    that varies one component (a Gauss–Markov T) recomputes only that component's share."""
    _nu, w, starts, _pairs = _kernel_nodes(mkey)
    if pa is None or pb is None:
        return np.zeros(len(starts))
    sa = _psd_on(mkey, pa)
    sb = sa if pb is pa else _psd_on(mkey, pb)
    out = 2.0 * np.add.reduceat(w * sa * sb, starts)
    out.setflags(write=False)
    return out


@lru_cache(maxsize=32)
def _psd_on(mkey: tuple[int, ...], p: PsdFn) -> NDArray[np.float64]:
    """A component's PSD on the nodes of ``mkey``."""
    out = np.asarray(p(_kernel_nodes(mkey)[0]), dtype=np.float64)
    out.setflags(write=False)
    return out


def avar_covariance_kernels(m: ArrayLike, psds: list[PsdFn | None]) -> NDArray[np.float64]:
    """Kernels G[k, l, a, b] = 2∫₀^½ s_a(ν)s_b(ν)|H_mk|²|H_ml|² dν for the AVAR estimates at
    averaging factors m (K,) and unit component PSDs s_a (None = deterministic, zero).

    For a Gaussian process with PSD S = Σ θ_a s_a, the overlapping AVAR estimates over M
    differences have, to first order in 1/M (Whittle; Greenhall & Riley 2003 §2),
        Cov(σ̂²_k, σ̂²_l) ≈ 2/M · ∫_{−½}^{½} S²|H_k|²|H_l|² dν = (2/M)·θᵀ G[k, l] θ.
    The correlation matrix built from these is what makes the fit's intervals honest.
    """
    mkey = tuple(int(x) for x in np.asarray(m, dtype=np.int64))
    K, A = len(mkey), len(psds)
    G = np.zeros((K, K, A, A))
    for a in range(A):
        for b in range(a, A):
            G[:, :, a, b] = G[:, :, b, a] = _pair_square(mkey, psds[a], psds[b])
    return G


@lru_cache(maxsize=128)
def _pair_square(mkey: tuple[int, ...], pa: PsdFn | None, pb: PsdFn | None
                 ) -> NDArray[np.float64]:
    """``_pair_integrals`` of a pair of components as the symmetric (K, K) matrix of τ pairs
    (read-only): the kernels of a fit are assembled from these, the same for every fit with
    these components on these τ."""
    _nu, _w, _starts, pairs = _kernel_nodes(mkey)
    kk = np.array([k for k, _ in pairs], dtype=np.intp)
    jj = np.array([j for _, j in pairs], dtype=np.intp)
    out = np.zeros((len(mkey), len(mkey)))
    out[kk, jj] = out[jj, kk] = _pair_integrals(mkey, pa, pb)
    out.setflags(write=False)
    return out


def lowpass_flicker_avar(
    tau: ArrayLike, B: float, rate_hz: float, corner_hz: float, *, order: int = 2
) -> NDArray[np.float64]:
    """AVAR of bias-instability (flicker) noise of coefficient B after the sensor's low-pass:
    the floor (2 ln2/π)·B² (IEEE 952 eq. C.14) times ``lowpass_flicker_ratio`` at
    m = round(τ·rate). The chip filters all of its noise, not only the white part; without
    this factor a fit that starts at one sample describes the flicker wrongly by 62 % at m = 1
    and 20 % at m = 2."""
    t = _tau(tau)
    m = np.maximum(np.rint(t * rate_hz).astype(np.int64), 1)
    wn = _filter_key(rate_hz, corner_hz)
    ratio = np.array([_flicker_ratio_one(int(mi), wn, int(order)) for mi in m])
    return term_avar("bias_instability", t, B) * ratio


@lru_cache(maxsize=4096)
def _flicker_ratio_one(m: int, wn: float, order: int) -> float:
    """``lowpass_flicker_ratio`` at one m for the corner ``wn`` (units of Nyquist: rate 2)
    — the costly part of a fit (a 400 001-point integral per m), computed once per
    (m, normalised corner) for the whole run (see :func:`_filter_key`)."""
    # The filter's effect falls like 1/m² (≈ 0.6/m² at ODR/4): below 4e-8 beyond m = 4096.
    if m > 4096:
        return 1.0
    return float(lowpass_flicker_ratio([m], 2.0, wn, order)[0])


def lowpass_flicker_ratio(m: ArrayLike, rate_hz: float, corner_hz: float,
                          order: int = 2) -> NDArray[np.float64]:
    """AVAR of flicker (1/f, bias-instability) noise after the low-pass divided by its AVAR
    without it, at averaging factors m: ∫S|G|²|H_m|²dν / ∫S|H_m|²dν with S ∝ 1/|ν| (the
    discrete form of NIST SP 1065 eq. 12). For the ADXL355 filter (2nd order, ODR/4) it is
    ≈ 0.38 at m = 1, 0.80 at 2, 0.97 at 4 and 0.99 at 8: the chip filters the flicker too,
    which ``lowpass_white_avar`` alone does not describe."""
    mm = np.atleast_1d(np.asarray(m, dtype=float))
    x, nu, g2, s2 = _flicker_grid(_filter_key(rate_hz, corner_hz), int(order))
    out = np.empty(len(mm))
    for i, mi in enumerate(mm):
        num = den = 0.0
        # in slices sharing their end points (the trapezoid rule adds up exactly): a few MB
        # of temporaries instead of tens, which the service's RSS would keep as its peak
        for a in range(0, len(x) - 1, _GRID_SLICE):
            b = min(a + _GRID_SLICE + 1, len(x))
            h2 = 2.0 * np.sin(np.pi * nu[a:b] * mi) ** 4 / (mi**2 * s2[a:b])
            num += float(np.trapezoid(h2 * g2[a:b], x[a:b]))
            den += float(np.trapezoid(h2, x[a:b]))
        out[i] = num / den
    return out


#: Points of the log-frequency grid of :func:`lowpass_flicker_ratio`, and its slices.
_GRID_N = 400_001
_GRID_SLICE = 50_000


@lru_cache(maxsize=8)
def _flicker_grid(wn: float, order: int) -> tuple[NDArray[np.float64], ...]:
    """The grid of :func:`lowpass_flicker_ratio` for the normalised corner ``wn``: ln ν, ν,
    |G(ν)|² and sin²(πν), computed once per corner (they do not depend on m). S(ν)dν = dν/ν
    = d ln ν: a log grid down to where |H_m|² ∝ ν² has made the integrand negligible."""
    x = np.linspace(math.log(1e-9), math.log(0.5), _GRID_N)
    nu = np.exp(x)
    g2 = np.empty_like(nu)
    for a in range(0, _GRID_N, _GRID_SLICE):
        g2[a:a + _GRID_SLICE] = lowpass_gain2(nu[a:a + _GRID_SLICE], 2.0, wn, order)
    s2 = np.sin(np.pi * nu) ** 2
    for arr in (x, nu, g2, s2):
        arr.flags.writeable = False
    return x, nu, g2, s2

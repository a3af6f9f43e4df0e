"""The octave cross-spectra of axis and temperature and the coupling test on them
(``coupling_test``)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
from avard.core.allan.beta import t_two_sided
from avard.core.explain import alarm
from numpy.typing import NDArray

if TYPE_CHECKING:
    pass
from avard.core.explain.thermal_fit.settings import DS18B20_CONVERSION_S, SCAN_TRIALS, Z_TEMPERATURE
from avard.core.explain.thermal_fit.signals import _kept, _rho, regression_terms

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

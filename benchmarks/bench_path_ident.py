"""Can any method tell two thermal paths from a dT/dt term on the weekend path rows' room?

    python -m benchmarks path_ident [--truth two_path|rate|hysteresis] [--seeds 1,2,3]
                                    [--compressor] [--fmax HZ] [--rounded] [--reconstruct]

The non-centrality λ between the row's true signal and the best rival model: the weekend
generator's (``tests/support/weekend.py``) accelerometer signal of ``rows_paths``' two-path
or dT/dt row made *without noise*, and each candidate (one lag; a lag and a dT/dt term; two
lags; a lag and a quadratic term) fitted to it by generalised least squares in the frequency
domain, the metric the noise PSD of the rows' N, B, K (``causes.noise_psd``): λ = Σ_f
|Δ(f)|²/(S(f)·T/4) over the FFT bins up to ``--fmax`` (the rival's lag on a grid, its
coefficients by GLS). λ is what the best possible test sees of the difference: a 95 % choice
between two models needs λ ≳ 11 (P(right) = Φ(√λ/2)). Readings are not rounded unless
``--rounded`` (the rounding is an error in the regressor, not information about the path), so
λ is an upper bound for any estimator. docs/log/explain.md ("Which thermal paths a record can
tell apart") gives the figures: HVAC only 0.1–2.3, with the compressor 45–52 (28–38 below
the paths' τ floor, ``--fmax 0.00244``).

``--truth hysteresis``: the hysteresis row's signal (the generator's relay: ±h by the sign of
the die's last move beyond 0.05 K) against one lag and two hysteresis models beside a lag,
each on its grid: the play (``_play``, explain's candidate before) on the lagged channel
smoothed through 30 s, and a non-ideal relay of width w (``thermal_paths._relay``, the
Preisach elementary hysteron, explain's candidate now). ``--reconstruct`` (with
``--rounded``): the regressors built from the temperature behind the readings
(``thermal_paths.crossing_reconstruction``: a natural cubic spline through the times the
rounded readings cross (k + ½)·0.0625 K, kept inside each reading's own cell), the rounding
an error in the regressor. docs/log/explain.md ("Hysteresis: a relay on the temperature behind
the readings") gives the figures.

The ``rate`` rival here is c·u_L + r·du_L/dt, which holds two paths (0, L) exactly
(r·du_L/dt = (r/L)·(T − u_L)): explain's dT/dt candidate is r·dT/dt of the channel itself
since lag23, which does not. ``record_resolves`` (paths23c) measures explain's candidate on
each record's own drive, in the time domain with the noise's exact covariance and the
lags' start states as nuisances: λ 1.3–110 on the two-path row's default seeds
(docs/log/explain.md, "Two paths on one drive line: what each record resolves").
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

DEC = 10  # 10 Hz → 1 Hz block means
LAGS = (0, 15, 30, 60, 120, 240, 480, 900, 1800, -15, -30, -60, -120, -240)
LAGS_2 = (60, 120, 240, 480, 870, 900, 1800, 3600)


def _signals(row: object, seed: int, compressor: float) -> tuple[NDArray, NDArray]:
    from tests.support.weekend import make

    w = replace(row.weekend, N=0.0, B=0.0, K=0.0, compressor_c=compressor)  # type: ignore[attr-defined]
    acc, temps, _names, _truth = make(seed, w)
    T = temps[:, 0]
    have = np.flatnonzero(np.isfinite(T))
    T = np.interp(np.arange(len(T)), have, T[have])
    n = len(T) // DEC * DEC
    return acc[:n, 0].reshape(-1, DEC).mean(1), T[:n].reshape(-1, DEC).mean(1)


def _lambda(y: NDArray, X: NDArray, fmax: float) -> float:
    from avard.core.explain.causes import noise_psd

    from benchmarks.bench_explain_weekend import B, K, N

    A = np.column_stack([y, X])
    F = np.fft.rfft(A - A.mean(axis=0), axis=0)[1:]  # rate 1 Hz: Δt = 1
    T_s = float(len(y))
    f = np.arange(1, len(F) + 1) / T_s
    F, f = F[f <= fmax], f[f <= fmax]
    w = 1.0 / np.sqrt(np.array([noise_psd(x, N, B, K) for x in f]) * T_s / 4)
    Fw = F * w[:, None]
    M = np.vstack([Fw[:, 1:].real, Fw[:, 1:].imag])
    b = np.concatenate([Fw[:, 0].real, Fw[:, 0].imag])
    beta, *_ = np.linalg.lstsq(M, b, rcond=None)
    r = b - M @ beta
    return float(r @ r)


LAGS_H = (0, 15, 30, 60, -15, -30, -60, -120, -180, -240)
WIDTHS_H = (0.025, 0.05, 0.1, 0.2)


def _play(v: NDArray, w: float) -> NDArray:
    """(v − P_w[v])/(w/2): the play (backlash) operator's normalised lead over its output, +1
    after a rise, −1 after a fall, crossing over while ``v`` turns back by ``w`` (P starts at
    v[0]); explain's hysteresis candidate before the relay on the reconstructed temperature."""
    h = 0.5 * w
    track = np.empty(len(v))
    p = float(v[0])
    for i, x in enumerate(np.asarray(v, dtype=float).tolist()):
        if x - p > h:
            p = x - h
        elif p - x > h:
            p = x + h
        track[i] = p
    return (np.asarray(v, dtype=float) - track) / h


def _hysteresis_rivals(T: NDArray) -> dict[str, list[tuple[tuple[float, ...], NDArray]]]:
    from avard.core.explain.thermal_fit import lag_filter
    from avard.core.explain.thermal_paths.columns import _relay
    from avard.core.explain.thermal_paths.settings import RATE_SMOOTH_S

    u = {L: lag_filter(T, float(L), 1.0) for L in LAGS_H}
    v = {L: lag_filter(u[L], RATE_SMOOTH_S, 1.0) for L in LAGS_H}
    return {
        "one_lag": [((L,), u[L][:, None]) for L in LAGS_H],
        "play": [((L, w), np.column_stack([u[L], _play(v[L], w)]))
                 for L in LAGS_H for w in WIDTHS_H],
        "relay": [((L, w), np.column_stack([u[L], _relay(v[L], w)]))
                  for L in LAGS_H for w in WIDTHS_H],
    }


def _rivals(T: NDArray) -> dict[str, list[tuple[tuple[float, ...], NDArray]]]:
    from avard.core.explain.thermal_fit import lag_filter

    def u(L: float) -> NDArray:
        return lag_filter(T, L, 1.0)

    out: dict[str, list[tuple[tuple[float, ...], NDArray]]] = {
        "one_lag": [((L,), u(L)[:, None]) for L in LAGS],
        "rate": [((L,), np.column_stack([u(L), (u(L) - lag_filter(u(L), 30.0, 1.0)) / 30.0]))
                 for L in LAGS],
        "quadratic": [((L,), np.column_stack([u(L), (u(L) - u(L).mean()) ** 2])) for L in LAGS],
        "two_path": [((a, b), np.column_stack([u(a), u(b)]))
                     for a in LAGS if a >= 0 for b in LAGS_2 if b > a],
    }
    return out


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks path_ident")
    ap.add_argument("--truth", choices=("two_path", "rate", "hysteresis"), default="two_path")
    ap.add_argument("--seeds", default="1,2,3")
    ap.add_argument("--compressor", type=float, default=0.0,
                    help="the compressor's amplitude (°C; the compressor rows use 1)")
    ap.add_argument("--fmax", type=float, default=1.0, help="highest frequency counted (Hz)")
    ap.add_argument("--rounded", action="store_true",
                    help="keep the readings' 0.0625 K rounding (errors in the regressors)")
    ap.add_argument("--reconstruct", action="store_true",
                    help="regressors from the readings' mid-level crossings (with --rounded)")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import tests.support.weekend as wk
    from benchmarks.bench_explain_weekend import rows_paths

    if not args.rounded:
        wk.STEP_C = 1e-9  # readings as read, not rounded (this process only)
    row = next(r for r in rows_paths() if r.mechanism == args.truth
               and r.name.startswith("path: "))
    print(f"truth: {row.name} ({row.minimum}); compressor ±{args.compressor:g} °C; "
          f"f ≤ {args.fmax:g} Hz; readings {'rounded' if args.rounded else 'not rounded'}"
          + (", reconstructed from their crossings" if args.reconstruct else ""))
    rivals = _hysteresis_rivals if args.truth == "hysteresis" else _rivals
    for seed in (int(s) for s in args.seeds.split(",")):
        y, T = _signals(row, seed, args.compressor)
        if args.reconstruct:
            from avard.core.explain.thermal_paths.columns import crossing_reconstruction

            T = crossing_reconstruction(T)
        best = {k: min(((_lambda(y, X, args.fmax), th) for th, X in v), key=lambda t: t[0])
                for k, v in rivals(T).items()}
        print(f"seed {seed}: " + ", ".join(
            f"{k} λ {lam:.3g} (θ {', '.join(f'{x:g}' for x in th)})"
            for k, (lam, th) in best.items()), flush=True)
    print("a 95 % choice between the truth and its best rival needs λ ≳ 11 "
          f"(P(right) = Φ(√λ/2)); Φ(√λ/2) at λ = 2: {0.5 * (1 + math.erf(1 / 2)):.2f}")
    return 0


# --------------------------------------------------------------------------------------------
# what one record of the two-path row resolves (paths23c): GLS in the time domain on block
# means with the noise's exact covariance, the lag filters' start states as nuisances

#: Samples per block mean of the identifiability calculation (40 s at 10 Hz)
ID_BLOCK = 400
#: The non-centrality a 95 % choice between two models needs: Φ(√λ/2) = 0.95
LAMBDA_95 = (2 * 1.6448536269514722) ** 2
#: The rival dT/dt term's static lags (s) the calculation tries
RATE_LAGS = (0, 5, 10, 15, 20, 30, 45, 60, 90, 120, 180, 240, 360, 480, 600, 900, 1200, 1800)


def block_noise_cov(n: int, m: int, rate_hz: float, n_white: float, b_inst: float,
                    k_rrw: float) -> NDArray:
    """The exact covariance of the means of ``m``-sample blocks of the weekend generator's
    noise over ``n`` samples: white (N²·rate per sample), a random walk from zero at the
    record's start (K²·Δt·(min(i, j) + 1)) and Kasdin's flicker filter run from the start
    (Σ_k h_(i−k)·h_(j−k), h the generator's coefficients): both start at the record's start,
    so neither is stationary, and the block means' covariance is summed directly."""
    nb = n // m
    dt = 1.0 / rate_hz
    C = np.eye(nb) * n_white**2 * rate_hz / m
    i = np.arange(nb * m).reshape(nb, m) + 1.0
    mid = i.mean(axis=1)
    rw = np.minimum.outer(mid, mid)
    for a in range(nb):
        rw[a, a] = float(np.minimum.outer(i[a], i[a]).mean())
    C += k_rrw**2 * dt * rw
    k = np.arange(1, n)
    h = np.concatenate([[1.0], np.cumprod((k - 1 + 0.5) / k)])
    hc = np.concatenate([[0.0], np.cumsum(h)])
    starts = np.arange(nb) * m
    for k0 in range(0, n, 4000):
        kk = np.arange(k0, min(n, k0 + 4000))
        hi = np.clip(starts[:, None] + m - kk[None, :], 0, n)
        lo = np.clip(starts[:, None] - kk[None, :], 0, n)
        A = (hc[hi] - hc[lo]) / m
        C += b_inst**2 * (A @ A.T)
    return C


def record_resolves(weekend: Any, seed: int, truth: dict[str, float],
                    whiten: NDArray) -> dict[str, float]:
    """What record ``seed`` of a two-path row (``weekend``: lag 0 and c₂ through the plate's
    900 s) can resolve, from its own noise-free drive (the logged channel not rounded) and
    ``whiten`` (the Cholesky factor of the inverse block-noise covariance,
    ``block_noise_cov``): ``lambda_rate``, the non-centrality between the true signal and
    the best dT/dt term of explain's candidate (c·u_L + r·dT/dt of the channel, L on
    ``RATE_LAGS``, the start state a nuisance); ``sd_coefficient``, ``sd_coefficient_2``,
    ``sd_lag_s``, ``sd_lag_2_s``: the Cramér–Rao standard deviations of the two-path
    model's four parameters, all unknown (the start states and an offset nuisances)."""
    from avard.core.explain.thermal_fit import lag_filter
    from avard.core.explain.thermal_paths import path_columns
    from avard.core.explain.thermal_paths.columns import Column

    import tests.support.weekend as wk

    w = replace(weekend, N=0.0, B=0.0, K=0.0)
    old = wk.STEP_C
    wk.STEP_C = 1e-12
    try:
        acc, temps, _names, _truth = wk.make(seed, w)
    finally:
        wk.STEP_C = old
    rate = float(w.rate_hz)
    n = len(acc)
    T = temps[:, 0]
    have = np.flatnonzero(np.isfinite(T))
    T = np.interp(np.arange(n), have, T[have])
    m = ID_BLOCK
    nb = n // m

    def blocks(x: NDArray) -> NDArray:
        return np.asarray(x[:nb * m].reshape(nb, m).mean(axis=1))

    t = (np.arange(nb) + 0.5) * m / rate
    y = blocks(acc[:, 0])

    def resid(X: NDArray) -> float:
        A, b = whiten.T @ X, whiten.T @ y
        beta, *_ = np.linalg.lstsq(A, b, rcond=None)
        r = b - A @ beta
        return float(r @ r)

    u = {L: blocks(lag_filter(T, float(L), rate)) for L in RATE_LAGS}
    dT = blocks(path_columns(T, [Column("rate", 0.0)], rate)[:, 0])
    one = np.ones(nb)
    # a warm-up the record holds (``weekend.warmups``) is a nuisance of free size beside the
    # rival, as the start state is and as explain fits it beside every candidate: its size
    # is no evidence between the two readings (beside the two-path model the warm-up's
    # e^(−t/900 s) is its own second start state, the ``exp(-t / L2)`` of ``J`` below;
    # left out of the rival, a dT/dt term through a short lag could not fit it and the
    # warm-up's own size was read as a separation of 20–105 on records whose rival with it
    # beside sits at 0.5–6)
    wu = [np.exp(-t / T_w) for _size, T_w in weekend.warmups]
    lam = min(resid(np.column_stack([u[L], dT, one, *wu] + ([np.exp(-t / L)] if L else [])))
              for L in RATE_LAGS)
    c1, c2, L2 = truth["coefficient"], truth["coefficient_2"], truth["lag_2_s"]
    u2 = {d: blocks(lag_filter(T, L2 + d, rate)) for d in (-1.0, 1.0)}
    J = np.column_stack([u[0], c1 * (blocks(lag_filter(T, 1.0, rate)) - u[0]),
                         0.5 * (u2[1.0] + u2[-1.0]), c2 * 0.5 * (u2[1.0] - u2[-1.0]),
                         one, np.exp(-t / L2)])
    A = whiten.T @ J
    sd = np.sqrt(np.diag(np.linalg.inv(A.T @ A))[:4])
    return {"lambda_rate": lam, "sd_coefficient": float(sd[0]), "sd_lag_s": float(sd[1]),
            "sd_coefficient_2": float(sd[2]), "sd_lag_2_s": float(sd[3])}

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
λ is an upper bound for any estimator. docs/explain.md ("Which thermal paths a record can
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
an error in the regressor. docs/explain.md ("Hysteresis: a relay on the temperature behind
the readings") gives the figures.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import replace
from pathlib import Path

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
    from avard.core.explain.thermal_paths import RATE_SMOOTH_S, _relay

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
            from avard.core.explain.thermal_paths import crossing_reconstruction

            T = crossing_reconstruction(T)
        best = {k: min(((_lambda(y, X, args.fmax), th) for th, X in v), key=lambda t: t[0])
                for k, v in rivals(T).items()}
        print(f"seed {seed}: " + ", ".join(
            f"{k} λ {lam:.3g} (θ {', '.join(f'{x:g}' for x in th)})"
            for k, (lam, th) in best.items()), flush=True)
    print("a 95 % choice between the truth and its best rival needs λ ≳ 11 "
          f"(P(right) = Φ(√λ/2)); Φ(√λ/2) at λ = 2: {0.5 * (1 + math.erf(1 / 2)):.2f}")
    return 0

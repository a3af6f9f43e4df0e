"""The stated minima tables of docs/explain.md ("Stated minima": temperature, warm-up and
bias step, excursion, drift, Gauss–Markov, sinusoid), printed as Markdown.

    .venv/bin/python docs/scripts/explain_minima.py
"""

from __future__ import annotations

from avard.core.explain.causes import (
    min_detectable_sinusoid,
    min_detectable_step,
    min_detectable_warmup,
)
from avard.core.explain.gauss_markov import min_detectable_gauss_markov
from avard.core.explain.thermal_fit import min_detectable_tempco
from avard.core.explain.transients import min_detectable_warmup_in_fit
from avard.core.explain.transients.minima import min_detectable_drift, min_detectable_excursion

B, K, RATE = 2e-5, 2e-6, 10.0
RECORDS_H = (1, 4, 24, 60)


def _g(v: float) -> str:
    return "—" if v == float("inf") else f"{v:.2g}"


def gauss_markov() -> None:
    ts = (10.0, 30.0, 120.0, 600.0, 3600.0)
    print("| record | N (m/s/√s) | " + " | ".join(f"T {t:g} s" for t in ts) + " |")
    print("|---|---|" + "---|" * len(ts))
    for h in RECORDS_H:
        for n in (1.6e-4, 4e-4):
            cells = []
            for t in ts:
                d = min_detectable_gauss_markov(n, B, K, t, h * 3600, RATE)
                p = min_detectable_gauss_markov(n, B, K, t, h * 3600, RATE, rel=0.1)
                cells.append(f"{_g(d)} / {_g(p)}")
            print(f"| {h} h | {n:g} | " + " | ".join(cells) + " |")


def temperature() -> None:
    lags = (120.0, 300.0, 600.0, 1200.0)
    print("| record | N (m/s/√s) | " + " | ".join(f"lag {lag / 60:g} min" for lag in lags) + " |")
    print("|---|---|" + "---|" * len(lags))
    for h in RECORDS_H:
        for n in (8e-5, 1.6e-4, 4e-4):
            args = (n, B, K, h * 3600, 0.5, 1800.0)
            cells = [f"{_g(min_detectable_tempco(*args, lag))} / "
                     f"{_g(min_detectable_tempco(*args, lag, lag_rel=0.1))}" for lag in lags]
            print(f"| {h} h | {n:g} | " + " | ".join(cells) + " |")


def transients() -> None:
    ts, recs = (300.0, 900.0, 3600.0), (1, 4, 24)
    print("| N (m/s/√s) | " + " | ".join(f"warm-up T {t / 60:g} min" for t in ts) + " | "
          + " | ".join(f"step, {h} h record" for h in recs) + " |")
    print("|---|" + "---|" * (len(ts) + len(recs)))
    for n in (8e-5, 1.6e-4, 4e-4):
        cells = [_g(min_detectable_warmup(n, B, K, t)) for t in ts]
        cells += [_g(min_detectable_step(n, B, K, h * 3600)) for h in recs]
        print(f"| {n:g} | " + " | ".join(cells) + " |")


def compound() -> None:
    print("| record | excursion 1000 s | excursion record/8 | warm-up in the fit, T 900 s | "
          "warm-up in the fit, T record/4 | drift (m/s³) | drift, K = 0 |")
    print("|---|---|---|---|---|---|---|")
    n = 1.6e-4
    for h in RECORDS_H:
        s = h * 3600.0
        cells = [min_detectable_excursion(n, B, K, s, 1000.0),
                 min_detectable_excursion(n, B, K, s, s / 8),
                 min_detectable_warmup_in_fit(n, B, K, s, 900.0),
                 min_detectable_warmup_in_fit(n, B, K, s, s / 4),
                 min_detectable_drift(n, B, K, s), min_detectable_drift(n, B, 0.0, s)]
        print(f"| {h} h | " + " | ".join(_g(c) for c in cells) + " |")


def sinusoid() -> None:
    fs = (0.01, 0.137, 1.0)
    print("| record | N (m/s/√s) | " + " | ".join(f"{f:g} Hz" for f in fs) + " |")
    print("|---|---|" + "---|" * len(fs))
    for h in RECORDS_H:
        for n in (8e-5, 1.6e-4, 4e-4):
            cells = [_g(min_detectable_sinusoid(n, B, K, h * 3600, RATE, f)) for f in fs]
            print(f"| {h} h | {n:g} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    print(f"Temperature coefficient (m/s²/K), detected / lag to 10 %; ±0.5 °C, 30-minute cycle "
          f"on the logged channel; B {B:g} m/s², K {K:g} m/s²·√s\n")
    temperature()
    print(f"\nWarm-up size and bias step (m/s²), window contrast at 6 robust σ; B {B:g}, "
          f"K {K:g}\n")
    transients()
    print(f"\nCompound search, z = 5 standard errors in the GLS fit (m/s²; drift m/s³); "
          f"N 1.6e-4, B {B:g}, K {K:g}\n")
    compound()
    print()
    print(f"Gauss–Markov σ (m/s²), detected / σ and T to 10 %; B {B:g} m/s², K {K:g} "
          f"m/s²·√s, {RATE:g} Hz\n")
    gauss_markov()
    print(f"\nSinusoid amplitude (m/s²), analyze's line finder; B {B:g}, K {K:g}, {RATE:g} Hz\n")
    sinusoid()

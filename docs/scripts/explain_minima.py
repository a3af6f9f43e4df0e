"""The stated minima tables of docs/explain.md (Gauss–Markov and sinusoid), printed as
Markdown.

    .venv/bin/python docs/scripts/explain_minima.py
"""

from __future__ import annotations

from avard.core.explain.causes import min_detectable_sinusoid
from avard.core.explain.gauss_markov import min_detectable_gauss_markov

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


def sinusoid() -> None:
    fs = (0.01, 0.137, 1.0)
    print("| record | N (m/s/√s) | " + " | ".join(f"{f:g} Hz" for f in fs) + " |")
    print("|---|---|" + "---|" * len(fs))
    for h in RECORDS_H:
        for n in (8e-5, 1.6e-4, 4e-4):
            cells = [_g(min_detectable_sinusoid(n, B, K, h * 3600, RATE, f)) for f in fs]
            print(f"| {h} h | {n:g} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    print(f"Gauss–Markov σ (m/s²), detected / σ and T to 10 %; B {B:g} m/s², K {K:g} "
          f"m/s²·√s, {RATE:g} Hz\n")
    gauss_markov()
    print(f"\nSinusoid amplitude (m/s²), analyze's line finder; B {B:g}, K {K:g}, {RATE:g} Hz\n")
    sinusoid()

"""The held-out test's level and power on simulated halves (heldpow28, issue 23 item 5).

    OMP_NUM_THREADS=1 nice .venv/bin/python docs/scripts/heldpow28_lab.py \
        --seeds 5000-5299 --drive 0
    OMP_NUM_THREADS=1 nice .venv/bin/python docs/scripts/heldpow28_lab.py \
        --seeds 5000-5299 --drive 15

Each record is a described sensor (white + Kasdin flicker + random walk at the weekend
benchmark's levels, 10 Hz, explain's 1.6 s slow view, ``--hours`` long) plus, with
``--drive D``, a sinusoid of D·B whose period is 1.1–2.5× the record (random phase): a drive
slower than the record, outside every candidate. Both halves are judged as the verdict
judges an axis that claims nothing (``holdout._fold`` both ways, the χ² of the sum), with the
held-out scatter from

- ``none``: no noise-term scatter (before heldcal27);
- ``whole``: the terms fitted on the whole fit part (heldcal27, main at 7da0aa2);
- ``short``: the terms fitted below its longest octaves (this branch's ``_scatter_model``);

and ``focus``: beside the branch's χ², a score test of the held-out residual on the long-τ
terms (random walk, rate ramp) with the test's own covariance, Q ~ χ²(2) per fold, the
smaller fold's p doubled; ``short+focus`` the two tests together (the smaller p doubled).
Printed: how many records fall below 1 / 5 / 10 %.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from avard.core.explain import holdout as ho
from avard.core.explain.verdict import _chi2_sf
from avard.core.model import fit as F
from avard.core.model.fit import problem as fit_problem

N, B, K = 1.6e-4, 2e-5, 2e-6
RATE, BLOCK = 10.0, 16
LONG = ("rate_random_walk", "rate_ramp")


def _flicker(n: int, rng: np.random.Generator) -> np.ndarray:
    k = np.arange(1, n)
    h = np.concatenate([[1.0], np.cumprod((k - 0.5) / k)])
    size = 1 << math.ceil(math.log2(2 * n))
    w = rng.standard_normal(n)
    return np.fft.irfft(np.fft.rfft(w, size) * np.fft.rfft(h, size), size)[:n]


def axis(seed: int, hours: float, drive: float) -> tuple[np.ndarray, float]:
    rng = np.random.default_rng(seed)
    n = int(hours * 3600 * RATE)
    a = (N * math.sqrt(RATE) * rng.standard_normal(n) + B * _flicker(n, rng)
         + K * math.sqrt(1 / RATE) * np.cumsum(rng.standard_normal(n)))
    m = (n // BLOCK) * BLOCK
    y, rb = a[:m].reshape(-1, BLOCK).mean(axis=1), RATE / BLOCK
    if drive:
        r2 = np.random.default_rng(seed + 777)
        period = len(y) / rb * r2.uniform(1.1, 2.5)
        t = np.arange(len(y)) / rb
        y = y + drive * B * np.sin(2 * np.pi * t / period + r2.uniform(0, 2 * np.pi))
    return y, rb


def _focus_q(model, result, rng, extra_cov):  # type: ignore[no-untyped-def]
    idx = fit_problem._usable(result, 3.0, 8.0, rng)
    cols = [k for k, c in enumerate(model.components) if c.label in LONG]
    if len(idx) < 3 or not cols:
        return math.nan, 0
    tau = np.asarray(result.tau, float)[idx]
    comps = model.components
    X = np.column_stack([c.basis(tau, float(result.rate_hz)) for c in comps])
    th = np.asarray(model.theta, float)
    stride = np.asarray(getattr(result, "stride", np.ones_like(result.m)))[idx]
    C = F.avar_estimate_covariance(comps, th, np.asarray(result.m)[idx],
                                   fit_problem._n_samples(result)[idx], float(result.rate_hz),
                                   stride)
    cov = np.array(model.theta_cov, float)
    for k, c in enumerate(comps):
        te = model.terms.get(c.label)
        if te is not None and not te.present and te.upper:
            cov[k, k] += (te.upper**2 / model.z_present) ** 2
    C = C + X @ cov @ X.T + np.asarray(extra_cov, float)[np.ix_(idx, idx)]
    r = np.asarray(result.var, float)[idx] - X @ th
    G = X[:, cols]
    W = np.linalg.inv(C)
    b = G.T @ W @ r
    return float(b @ np.linalg.solve(G.T @ W @ G, b)), len(cols)


def p_values(y: np.ndarray, rb: float) -> dict[str, float]:
    h = len(y) // 2
    A = ho.Part(y[:h], 0.0, "first half", True)
    Bp = ho.Part(y[h:], h / rb, "second half", False)
    out: dict[str, float] = {}
    real_sm, real_ns, real_mc = ho._scatter_model, ho._noise_scatter, ho.model_chi2
    qs: list[tuple[float, int]] = []

    def mc(model, result, rng=None, **kw):  # type: ignore[no-untyped-def]
        if "extra_cov" in kw:
            qs.append(_focus_q(model, result, rng, kw["extra_cov"]))
        return real_mc(model, result, rng, **kw)

    try:
        for name in ("none", "whole", "short"):
            ho._scatter_model = real_sm if name == "short" else (lambda a, m: m)
            ho._noise_scatter = real_ns if name != "none" else (
                lambda m, r: np.zeros((len(r.m), len(r.m))))
            ho.model_chi2 = mc if name == "short" else real_mc
            folds = [ho._fold(f, g, ho.Claims(), rb, True, None, None)
                     for f, g in ((A, Bp), (Bp, A))]
            out[name] = _chi2_sf(sum(f.chi2_ext_pred for f in folds),
                                 sum(f.n_points for f in folds))
    finally:
        ho._scatter_model, ho._noise_scatter, ho.model_chi2 = real_sm, real_ns, real_mc
    pf = [_chi2_sf(q, k) for q, k in qs if k]
    out["focus"] = min(1.0, 2 * min(pf)) if pf else 1.0
    out["short+focus"] = min(1.0, 2 * min(out["short"], out["focus"]))
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", default="5000-5299")
    ap.add_argument("--hours", type=float, default=4.0)
    ap.add_argument("--drive", type=float, default=0.0, help="the slow drive, in units of B")
    a = ap.parse_args()
    lo, _, hi = a.seeds.partition("-")
    P: dict[str, list[float]] = {}
    for s in range(int(lo), int(hi or lo) + 1):
        for k, v in p_values(*axis(s, a.hours, a.drive)).items():
            P.setdefault(k, []).append(v)
    print(f"{a.hours:g} h, drive {a.drive:g}·B, seeds {a.seeds}: records below 1 / 5 / 10 %")
    for k, v in P.items():
        p = np.asarray(v)
        print(f"  {k:12s} {np.sum(p < .01):4d} {np.sum(p < .05):4d} {np.sum(p < .1):4d}"
              f"   of {len(p)}")


if __name__ == "__main__":
    main()

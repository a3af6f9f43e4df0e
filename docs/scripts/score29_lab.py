"""Is heldpow28's focused held-out test worth a second p-value in the verdict? (score29,
issue 23 item 5.)

    OMP_NUM_THREADS=1 nice .venv/bin/python docs/scripts/score29_lab.py --seeds 5000-5299 --drive 0
    OMP_NUM_THREADS=1 nice .venv/bin/python docs/scripts/score29_lab.py --seeds 5000-5299 --drive 15
    OMP_NUM_THREADS=1 nice .venv/bin/python docs/scripts/score29_lab.py --matched \
        --seeds 5000-5299,1000-1299 --drive 15

The records are ``heldpow28_lab.py``'s (white + Kasdin flicker + random walk at the weekend
levels, 10 Hz, 1.6 s slow view; ``--drive D``: a sinusoid of D·B with a period 1.1–2.5× the
record). Each is judged as the verdict judges an axis that claims nothing: both folds of
``holdout._fold`` (the tree's held-out covariance: prediction, noise scatter from
``_scatter_model``), and the χ² p of the folds' sum (``chi2``: what the verdict tests today).
Beside it, the focused score test of the held-out residual on the random-walk and ramp
columns (``heldpow28_lab._focus_q``, the χ²'s own covariance) in two forms:

- ``min``: per fold Q ~ χ²(k), the smaller fold's p doubled (heldpow28's);
- ``sum``: Q of both folds added, ~ χ²(k_A + k_B).

and the family "χ² or focus", each at a share of the family level L (Bonferroni: the
family's false rate ≤ L whatever their dependence): ``w`` the χ²'s share, the focus test's
1 − w. Printed: records the family rejects at L = 1 / 5 / 10 % (the verdict uses 1 %).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import heldpow28_lab as lab
from avard.core.explain import holdout as ho
from avard.core.explain.verdict import _chi2_sf

LEVELS = (0.01, 0.05, 0.10)
SHARES = (1.0, 0.9, 0.8, 0.5, 0.0)


def p_values(y: np.ndarray, rb: float) -> dict[str, float]:
    """The χ² p and the two focus p of one record (both folds)."""
    h = len(y) // 2
    A = ho.Part(y[:h], 0.0, "first half", True)
    Bp = ho.Part(y[h:], h / rb, "second half", False)
    real = ho.model_chi2
    qs: list[tuple[float, int]] = []

    def mc(model, result, rng=None, **kw):  # type: ignore[no-untyped-def]
        if "extra_cov" in kw:
            qs.append(lab._focus_q(model, result, rng, kw["extra_cov"]))
        return real(model, result, rng, **kw)

    ho.model_chi2 = mc
    try:
        folds = [ho._fold(f, g, ho.Claims(), rb, True, None, None)
                 for f, g in ((A, Bp), (Bp, A))]
    finally:
        ho.model_chi2 = real
    out = {"chi2": _chi2_sf(sum(f.chi2_ext_pred for f in folds),
                            sum(f.n_points for f in folds))}
    ok = [(q, k) for q, k in qs if k and np.isfinite(q)]
    out["min"] = min(1.0, 2 * min(_chi2_sf(q, k) for q, k in ok)) if ok else 1.0
    out["sum"] = _chi2_sf(sum(q for q, _ in ok), sum(k for _, k in ok)) if ok else 1.0
    return out


def _ps(seeds: str, hours: float, drive: float) -> dict[str, np.ndarray]:
    P: dict[str, list[float]] = {}
    for rng in seeds.split(","):
        lo, _, hi = rng.partition("-")
        for s in range(int(lo), int(hi or lo) + 1):
            for k, v in p_values(*lab.axis(s, hours, drive)).items():
                P.setdefault(k, []).append(v)
    return {k: np.asarray(v) for k, v in P.items()}


def matched(seeds: str, hours: float, drive: float) -> None:
    """Each family at the verdict's 1 % against the χ² alone at the level that rejects as
    many of the same seeds' nulls: a second test earns its place only if it finds more of
    the drive at equal false rate, not by rejecting more of everything."""
    null, drv = _ps(seeds, hours, 0.0), _ps(seeds, hours, drive)
    n = len(null["chi2"])
    print(f"{hours:g} h, seeds {seeds} ({n} records), drive {drive:g}·B: at family level 1 %")
    print(f"  {'family':24s} {'nulls':>5s} {'drive':>5s}   χ² alone at the level of as many "
          "nulls: level, nulls, drive")
    for form in ("min", "sum"):
        for w in (0.9, 0.8, 0.5):
            L = 0.01
            fn = int(np.sum((null["chi2"] < w * L) | (null[form] < (1 - w) * L)))
            fd = int(np.sum((drv["chi2"] < w * L) | (drv[form] < (1 - w) * L)))
            lvl = float(np.sort(null["chi2"])[fn - 1]) if fn else 0.0
            cn = int(np.sum(null["chi2"] <= lvl)) if fn else 0
            cd = int(np.sum(drv["chi2"] <= lvl)) if fn else 0
            print(f"  {f'chi2 {w:.0%} + {form} {1 - w:.0%}':24s} {fn:5d} {fd:5d}   "
                  f"{lvl:.3g}, {cn}, {cd}")
    cn, cd = int(np.sum(null["chi2"] < 0.01)), int(np.sum(drv["chi2"] < 0.01))
    print(f"  {'chi2 alone':24s} {cn:5d} {cd:5d}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", default="5000-5299")
    ap.add_argument("--hours", type=float, default=4.0)
    ap.add_argument("--drive", type=float, default=0.0, help="the slow drive, in units of B")
    ap.add_argument("--matched", action="store_true",
                    help="nulls and the drive on the same seeds (comma-separated ranges): "
                    "each family at 1 %% against the χ² alone at the level that rejects as "
                    "many nulls")
    a = ap.parse_args()
    if a.matched:
        matched(a.seeds, a.hours, a.drive or 15.0)
        return
    lo, _, hi = a.seeds.partition("-")
    P: dict[str, list[float]] = {}
    for s in range(int(lo), int(hi or lo) + 1):
        for k, v in p_values(*lab.axis(s, a.hours, a.drive)).items():
            P.setdefault(k, []).append(v)
    p = {k: np.asarray(v) for k, v in P.items()}
    print(f"{a.hours:g} h, drive {a.drive:g}·B, seeds {a.seeds} ({len(p['chi2'])} records): "
          "rejected at family level 1 / 5 / 10 %")
    for form in ("min", "sum"):
        for w in SHARES:
            rej = [int(np.sum((p["chi2"] < w * L) | (p[form] < (1 - w) * L))) for L in LEVELS]
            name = "chi2 alone" if w == 1.0 else f"{form} alone" if w == 0.0 else \
                f"chi2 {w:.0%} + {form} {1 - w:.0%}"
            if w == 1.0 and form == "sum":
                continue
            print(f"  {name:24s} {rej[0]:4d} {rej[1]:4d} {rej[2]:4d}")


if __name__ == "__main__":
    main()

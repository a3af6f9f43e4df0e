"""The weekend benchmark with heldpow28's focused held-out test computed in the shadow
(score29, issue 23 item 5): what wiring it into the verdict would change, axis by axis.

    OMP_NUM_THREADS=1 nice .venv/bin/python docs/scripts/score29_shadow.py \
        --cases 10 --rows null --jobs 1
    OMP_NUM_THREADS=1 nice .venv/bin/python docs/scripts/score29_shadow.py \
        --outside --cases 4 --jobs 1

The arguments are ``python -m benchmarks explain_weekend``'s (``--jobs 1`` only: the shadow
is collected in this process), and its table is printed unchanged: nothing here alters a
verdict. Beside it, every axis the held-out test judged (its ``verdict.heldout_p`` set) gets
the focused test of its folds (``heldpow28_lab._focus_q``: the score of the held-out residual
on the random-walk and ramp columns with the χ²'s own covariance, Q ~ χ²(k) per fold, the
smaller fold's p doubled), and the family the verdict would test if it were wired: χ² at
``ALPHA``·w, focus at ``ALPHA``·(1 − w) (Bonferroni, w = ½). Printed per row: axes judged,
held-out χ² p and focus p below 1 / 5 / 10 % (χ² < 1 %: today's held-out failures), the
family's rejections,
and the verdicts that would change (explained → unexplained; unexplained → explained where
only the held-out χ² failed, between ALPHA·w and ALPHA).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import heldpow28_lab as lab
from avard.core.explain import holdout as ho
from avard.core.explain.verdict import ALPHA, _chi2_sf

from benchmarks import bench_explain_weekend as bench

W = 0.5
LEVELS = (0.01, 0.05, 0.10)
_axis: list[str] = [""]
_row: list[str] = [""]
_qs: dict[str, list[tuple[float, int]]] = {}
#: per row: (seed, axis, in-sample p, held-out χ² p, focus p, explained)
rows: dict[str, list[tuple[int, str, float, float, float, bool]]] = {}


def _install() -> None:
    real_mc, real_channel, real_explain = ho.model_chi2, ho._channel, bench.explain_weekend
    real_plain, real_outside = bench.score_record, bench.score_outside_record

    def mc(model, result, rng=None, **kw):  # type: ignore[no-untyped-def]
        if "extra_cov" in kw:
            _qs.setdefault(_axis[0], []).append(lab._focus_q(model, result, rng,
                                                             kw["extra_cov"]))
        return real_mc(model, result, rng, **kw)

    def channel(name, *a, **kw):  # type: ignore[no-untyped-def]
        _axis[0] = name
        return real_channel(name, *a, **kw)

    def explain(w: Any, seed: int, heldout: bool = False) -> tuple[Any, float]:
        _qs.clear()
        ex, cpu = real_explain(w, seed, heldout=heldout)
        name = _row[0]
        for ax, ch in ex.channels.items():
            v = ch.verdict
            if v is None or v.heldout_p is None:
                continue
            pf = [_chi2_sf(q, k) for q, k in _qs.get(ax, []) if k and q == q]
            fp = min(1.0, 2 * min(pf)) if pf else 1.0
            rows.setdefault(name, []).append((seed, ax, v.p_value, v.heldout_p, fp,
                                              v.explained))
        return ex, cpu

    def plain(r, seed, heldout=True):  # type: ignore[no-untyped-def]
        _row[0] = r.name
        return real_plain(r, seed, heldout=heldout)

    def outside(r, seed, heldout=True):  # type: ignore[no-untyped-def]
        _row[0] = r.name
        return real_outside(r, seed, heldout=heldout)

    ho.model_chi2, ho._channel, bench.explain_weekend = mc, channel, explain
    bench.score_record, bench.score_outside_record = plain, outside


def _report() -> None:
    print(f"\nshadow: heldpow28's focus test beside the held-out χ² (family: χ² at "
          f"{W * ALPHA:.2%}, focus at {(1 - W) * ALPHA:.2%})")
    print(f"{'row':34s} {'axes':>5s} {'χ² p<1/5/10%':>13s} {'focus<1/5/10%':>14s} "
          f"{'family':>7s} {'expl→unexpl':>12s} {'unexpl→expl':>12s}")
    for name, got in rows.items():
        chi = "/".join(str(sum(h < L for _s, _a, _p, h, _f, _e in got)) for L in LEVELS)
        foc = "/".join(str(sum(f < L for _s, _a, _p, _h, f, _e in got)) for L in LEVELS)
        fam = [h < W * ALPHA or f < (1 - W) * ALPHA for _s, _a, _p, h, f, _e in got]
        worse = [f"{s} {a}" for (s, a, _p, _h, _f, e), r in zip(got, fam, strict=True)
                 if e and r]
        # unexplained today only by the held-out χ² (in sample passes), and the family
        # would not reject (a held-out test could not run: heldout_p None, not listed)
        better = [f"{s} {a}" for (s, a, p, h, _f, e), r in zip(got, fam, strict=True)
                  if not e and not r and p >= ALPHA and h < ALPHA]
        print(f"{name:34s} {len(got):5d} {chi:>13s} {foc:>14s} {sum(fam):7d} {len(worse):12d} "
              f"{len(better):12d}  {' '.join(worse + better)}")


def main() -> int:
    argv = sys.argv[1:]
    if "--jobs" in argv and argv[argv.index("--jobs") + 1] != "1":
        raise SystemExit("--jobs 1 only: the shadow is collected in this process")
    _install()
    rc = bench.main(argv)
    _report()
    return rc


if __name__ == "__main__":
    sys.exit(main())

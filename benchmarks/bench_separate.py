"""``python -m benchmarks separate [--records N] [--seed S]``: the coverage of ``avard
separate``'s self-noise intervals and the bias of its fitted N, on records from a generator
written apart from core/sim (tests/support/colocated.py), 2 and 3 sensors, the common input
0.1–10× the sensors' white level, different N/B/K per sensor; and its cost (CPU seconds per
record, against one overlapping ADEV of the same samples measured in the same run).

Prints the table docs/separate.md quotes. The slow test tests/core/test_separate_coverage.py
runs :func:`coverage_run` and holds its figures to the issue's bounds.
"""

from __future__ import annotations

import argparse
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
from avard.core.allan.deviations import oavar
from avard.core.analysis.separate import separate

from tests.support.colocated import draw_record

#: Coverage is counted at τ with at least this many non-overlapping averages.
MIN_AVERAGES = 5
#: The common input's level over the sensors' white level in the far-below check: the
#: sensors' own noise 0.1× down to 0.01× the common input.
FAR_RATIOS = (10.0, 100.0)


@dataclass
class Coverage:
    tau: np.ndarray                      # (K,) s
    averages: np.ndarray                 # (K,)
    held: dict[int, np.ndarray]          # sensors → (K,) intervals that held the truth
    total: dict[int, np.ndarray]         # sensors → (K,) intervals counted
    upper_limits: np.ndarray             # (K,) of them upper limits
    n_within: int                        # fitted N within 10 %, records with ratio ≤ 3
    n_fitted: int                        # ... of so many sensor fits
    n_no_fit: int                        # fits that failed (counted as misses)
    cpu_per_record_s: float
    cpu_oadev_per_record_s: float
    records: int
    #: sensors → (intervals, K) the upper end over the truth, as ADEV (√ of the variances)
    hi_over_truth: dict[int, np.ndarray] = field(default_factory=dict)
    #: sensors → (intervals, K) whether each was an upper limit
    was_limit: dict[int, np.ndarray] = field(default_factory=dict)
    #: sensors → (intervals, K) whether each held the truth
    held_each: dict[int, np.ndarray] = field(default_factory=dict)

    def rate_of(self, limits: bool) -> np.ndarray:
        """Per τ, the share holding the truth among the upper limits (``limits``) or the
        two-sided intervals, both sensor counts together (NaN where there are none)."""
        held = np.concatenate([self.held_each[s] for s in sorted(self.held_each)])
        lim = np.concatenate([self.was_limit[s] for s in sorted(self.was_limit)])
        pick = lim if limits else ~lim
        with np.errstate(invalid="ignore", divide="ignore"):
            return (held & pick).sum(axis=0) / pick.sum(axis=0)

    def limit_over_truth(self, s: int, q: float = 0.5) -> np.ndarray:
        """Per τ, the ``q`` quantile of (upper limit / truth) as ADEV over the upper limits
        only (NaN at τ with none): how loose an upper limit is."""
        r = np.where(self.was_limit[s], self.hi_over_truth[s], np.nan)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)     # a τ with no upper limit
            return np.nanquantile(r, q, axis=0)

    def rate(self, s: int | None = None) -> np.ndarray:
        held = sum(self.held.values()) if s is None else self.held[s]
        total = sum(self.total.values()) if s is None else self.total[s]
        return np.asarray(held) / np.maximum(np.asarray(total), 1)


def coverage_run(records: int = 120, seed: int = 2026, length: int = 1 << 17,
                 rate_hz: float = 20.0, ratios: tuple[float, float] | None = None,
                 fit: bool = True) -> Coverage:
    """Coverage over ``records`` (alternately 2 and 3 sensors); ``ratios`` (lo, hi): the
    common input's level over the sensors' white level drawn log-uniform in it (default the
    generator's 0.1–10); ``fit`` False skips the fits (no N figures)."""
    rng = np.random.default_rng(seed)
    ratio_of = {} if ratios is None else {"ratio": None}
    hot: dict[int, list[np.ndarray]] = {}
    got: dict[int, list[np.ndarray]] = {}
    lim: dict[int, list[np.ndarray]] = {}
    held: dict[int, np.ndarray] = {}
    total: dict[int, np.ndarray] = {}
    upper = None
    tau = averages = None
    n_within = n_fitted = n_no_fit = 0
    cpu = cpu_ref = 0.0
    for r in range(records):
        s = 2 if r % 2 == 0 else 3
        if ratios is not None:
            ratio_of["ratio"] = float(10 ** rng.uniform(*np.log10(ratios)))
        rec = draw_record(rng, s, length=length, rate_hz=rate_hz, **ratio_of)
        t0 = time.process_time()
        sep = separate(list(rec.y[:, :, None]), rate_hz, sensors=[f"s{i}" for i in range(s)],
                       axes=["z"], fit=fit)
        cpu += time.process_time() - t0
        t0 = time.process_time()
        oavar(rec.y[0], rate_hz)
        cpu_ref += time.process_time() - t0
        ax = sep.axes[0]
        if tau is None:
            tau, averages = ax.tau, ax.averages
            upper = np.zeros(len(tau), int)
        assert np.array_equal(ax.tau, tau)
        h = held.setdefault(s, np.zeros(len(tau), int))
        t = total.setdefault(s, np.zeros(len(tau), int))
        for i, noise in enumerate(rec.sensors):
            truth = noise.avar(ax.m, length, rate_hz)
            part = ax.self_noise[i]
            ok = (part.lo <= truth) & (truth <= part.hi)
            h += ok
            got.setdefault(s, []).append(ok)
            t += 1
            upper += part.upper_limit
            hot.setdefault(s, []).append(np.sqrt(part.hi / truth))
            lim.setdefault(s, []).append(part.upper_limit.copy())
            if fit and rec.ratio <= 3.0:
                n_fitted += 1
                fit = ax.fits[i]
                est = None if fit is None else fit.terms["velocity_random_walk"].value
                if est is None:
                    n_no_fit += 1
                elif abs(est / noise.n - 1.0) <= 0.10:
                    n_within += 1
    assert tau is not None and averages is not None and upper is not None
    return Coverage(tau, averages, held, total, upper, n_within, n_fitted, n_no_fit,
                    cpu / records, cpu_ref / records, records,
                    {k: np.array(v) for k, v in hot.items()},
                    {k: np.array(v) for k, v in lim.items()},
                    {k: np.array(v) for k, v in got.items()})


def table(cov: Coverage) -> str:
    lines = ["| τ (s) | averages | 2 sensors | 3 sensors | all | upper limits | of which "
             "held | two-sided held |", "|---:|---:|---:|---:|---:|---:|---:|---:|"]
    r2, r3, ra = cov.rate(2), cov.rate(3), cov.rate()
    r_ul, r_two = cov.rate_of(True), cov.rate_of(False)

    def pc(x: float) -> str:
        return "–" if not np.isfinite(x) else f"{100 * x:.1f} %"

    for k, t in enumerate(cov.tau):
        mark = "" if cov.averages[k] >= MIN_AVERAGES else " (< 5 averages, not held)"
        lines.append(f"| {t:.4g} | {cov.averages[k]} | {100 * r2[k]:.1f} % | "
                     f"{100 * r3[k]:.1f} % | {100 * ra[k]:.1f} %{mark} | "
                     f"{cov.upper_limits[k]} | {pc(r_ul[k])} | {pc(r_two[k])} |")
    return "\n".join(lines)


def far_table(cov: Coverage) -> str:
    """The far-below table: coverage and how loose the upper limits are, per τ."""
    lines = ["| τ (s) | averages | 2 sensors | 3 sensors | upper limits (2 / 3) | "
             "median limit/truth (2 / 3) | least limit/truth (2 / 3) |",
             "|---:|---:|---:|---:|---:|---:|---:|"]
    r2, r3 = cov.rate(2), cov.rate(3)
    med = {s: cov.limit_over_truth(s) for s in (2, 3)}
    least = {s: cov.limit_over_truth(s, 0.0) for s in (2, 3)}
    n_lim = {s: cov.was_limit[s].sum(axis=0) for s in (2, 3)}

    def f(x: float) -> str:
        return "–" if not np.isfinite(x) else f"{x:.2f}"

    for k, t in enumerate(cov.tau):
        mark = "" if cov.averages[k] >= MIN_AVERAGES else " (< 5 averages)"
        lines.append(f"| {t:.4g} | {cov.averages[k]} | {100 * r2[k]:.1f} % | "
                     f"{100 * r3[k]:.1f} %{mark} | {n_lim[2][k]} / {n_lim[3][k]} | "
                     f"{f(med[2][k])} / {f(med[3][k])} | {f(least[2][k])} / "
                     f"{f(least[3][k])} |")
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks separate")
    ap.add_argument("--records", type=int, default=120)
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--far", action="store_true",
                    help="the sensors' own noise 0.1–0.01× the common input (common 10–100× "
                         "their white level): coverage and how loose the upper limits are")
    args = ap.parse_args(argv)
    if args.far:
        cov = coverage_run(args.records, args.seed, ratios=FAR_RATIOS, fit=False)
        print(f"{cov.records} records (half 2, half 3 sensors), 2^17 samples at 20 Hz, the "
              "common input 10–100× the sensors' white level (log-uniform); 68 % self-noise "
              "intervals holding the generator's exact Allan variance (an upper limit holds "
              "when above the truth), and the upper limits over the truth as ADEV:")
        print(far_table(cov))
        return 0
    cov = coverage_run(args.records, args.seed)
    print(f"{cov.records} records (half 2, half 3 sensors), 2^17 samples at 20 Hz each; "
          "68 % self-noise intervals holding the generator's exact Allan variance:")
    print(table(cov))
    print(f"fitted N within 10 %: {cov.n_within} of {cov.n_fitted} sensor fits where the common "
          f"input is ≤ 3× the white level ({100 * cov.n_within / max(cov.n_fitted, 1):.1f} %; "
          f"{cov.n_no_fit} fits failed)")
    print(f"CPU per record: separate {cov.cpu_per_record_s:.3f} s, one OADEV of one sensor "
          f"{cov.cpu_oadev_per_record_s:.3f} s (ratio "
          f"{cov.cpu_per_record_s / cov.cpu_oadev_per_record_s:.1f}; process time, machine "
          "shared)")
    return 0

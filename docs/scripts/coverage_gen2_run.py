"""Issue 24's coverage check on records from tests/support/coverage_gen2.py (adv25).

The generator is written apart from the project's (flicker by a Kasdin–Walter filter, other
corners, other sinusoid periods and drift slopes); the interval counted is the one
``avard analyze`` prints, through ``benchmarks.bench_coverage.printed`` (the record as a
one-channel stream through ``analysis.engine.analyze`` with the default options), at every
printed τ with at least ``MIN_AVERAGES`` non-overlapping averages (n // m ≥ 5).

    OMP_NUM_THREADS=1 nice .venv/bin/python docs/scripts/coverage_gen2_run.py check
    OMP_NUM_THREADS=1 nice .venv/bin/python docs/scripts/coverage_gen2_run.py run \
        --hours 1,12,60 --mixes plain,sine,drift,both --records 200
    .venv/bin/python docs/scripts/coverage_gen2_run.py table --hours 1,12,60
    .venv/bin/python docs/scripts/coverage_gen2_run.py repro --hours 1 --mixes plain \
        --index 39 --save /tmp/r.npz
    .venv/bin/python docs/scripts/coverage_gen2_run.py ensemble --hours 1,12,60 \
        --mixes sine,both

``run`` appends one JSON line per record to OUT/cov2-{hours}h-{mix}-s{seed}.jsonl (so a run
cut short keeps its records and a second run continues the same stream of seeds);
``table`` prints per (length, mix) and τ: coverage with its binomial SE, the shares below
and above the interval, the mean printed EDF, the EDF the estimates scatter with about the
truth, mean α, the white-FM EDF of the OADEV at that m and N (exact, own computation, and
the project's ``fm_support_edf``), and how many records printed an EDF above it.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from tests.support import coverage_gen2 as gen  # noqa: E402

# hours: (rate Hz, white–flicker corner s, flicker–walk corner s, sinusoid period as a
# fraction of the record)
LENGTHS = {1: (10.0, 10.0, 1000.0, 1 / 3), 12: (1.0, 300.0, 10000.0, 1 / 10),
           60: (1.0, 10.0, 2000.0, 1 / 20)}
MIXES = ("plain", "sine", "drift", "both")
SINE_GAIN = 1.5  # the sinusoid's AVAR at τ = P/2 is 1.5× the noise's there
DRIFT_AT = 1 / 20  # the drift's AVAR equals the noise's at m = n/20
MIN_AVERAGES = 5
BAND = (0.60, 0.76)


def setup(hours: int, mix: str) -> tuple[int, float, gen.Levels]:
    rate, twf, tfr, frac = LENGTHS[hours]
    n = round(hours * 3600 * rate)
    period = n * frac if mix in ("sine", "both") else 0.0
    lv = gen.levels(n, twf, tfr, rate, sine_period=period,
                    sine_gain=SINE_GAIN if period else 0.0,
                    drift_at=DRIFT_AT if mix in ("drift", "both") else 0.0)
    return n, rate, lv


def white_fm_edf(n: int, m: int) -> float:
    """Exact EDF of the fully overlapping AVAR of n white rate samples at m:
    2(EQ)²/Var Q for Q = Σ_p Δ_p², Δ_p the M = n − 2m + 1 overlapping Allan differences,
    whose autocovariance is c(k)/m², c(k) = 2m − 3k (k ≤ m), −(2m − k) (m < k < 2m)."""
    big_m = n - 2 * m + 1
    k = np.arange(0, min(2 * m, big_m))
    c = np.where(k <= m, 2 * m - 3 * k, -(2 * m - k)).astype(float)
    s = c[0] ** 2 * big_m + 2.0 * np.sum((big_m - k[1:]) * c[1:] ** 2)
    return float((big_m * c[0]) ** 2 / s)


def cmd_check(args: argparse.Namespace) -> int:
    """The closed-form truth against the mean over generated records (own OADEV)."""
    for hours in [int(h) for h in args.hours.split(",")]:
        for mix in args.mixes.split(","):
            n, rate, lv = setup(hours, mix)
            ms = 2 ** np.arange(0, int(math.log2(n // MIN_AVERAGES)) + 1)
            rng = np.random.default_rng([args.seed, hours, MIXES.index(mix), 99])
            t0 = time.process_time()
            ratio, se, t = gen.check_truth(lv, n, ms, args.records, rng)
            print(f"{hours} h {mix}: {args.records} records, {time.process_time() - t0:.0f} s CPU; "
                  f"levels {lv}")
            for m, r, s, tv in zip(ms, ratio, se, t, strict=True):
                print(f"    τ {m / rate:9.1f} s  closed form {tv:.4e}  mean/closed {r:.4f} "
                      f"± {s:.4f}  ({(r - 1) / s:+.1f} SE)  burn-in bias ≤ "
                      f"{gen.burn_bias(n, m) * lv.f2 / max(tv, 1e-300):.1e}")
    return 0


def out_path(args: argparse.Namespace, hours: int, mix: str) -> Path:
    return Path(args.out) / f"cov2-{hours}h-{mix}-s{args.seed}.jsonl"


def cmd_run(args: argparse.Namespace) -> int:
    from benchmarks import bench_coverage as bc

    Path(args.out).mkdir(parents=True, exist_ok=True)
    for hours in [int(h) for h in args.hours.split(",")]:
        for mix in args.mixes.split(","):
            n, rate, lv = setup(hours, mix)
            path = out_path(args, hours, mix)
            done = sum(1 for _ in path.open()) if path.exists() else 0
            rng = np.random.default_rng([args.seed, hours, MIXES.index(mix), 2525])
            for _ in range(done):  # the same stream of records whatever the split
                gen.record(lv, n, rng)
            t0 = time.process_time()
            for i in range(done, args.records):
                y, _clean = gen.record(lv, n, rng)
                nf = len(bc.SLOW_FOUND)
                try:
                    r, _share, _ = bc.printed(y, rate)
                except Exception as exc:  # a traceback is a finding: keep the record's seed
                    with path.open("a") as f:
                        f.write(json.dumps({"i": i, "error": repr(exc)}) + "\n")
                    continue
                keep = (n // r.m) >= MIN_AVERAGES
                row = {"i": i, "m": r.m[keep].tolist(), "stride": r.stride[keep].tolist(),
                       "var": r.var[keep].tolist(), "lo": r.lo[keep].tolist(),
                       "hi": r.hi[keep].tolist(), "edf": r.edf[keep].tolist(),
                       "alpha": r.alpha[keep].tolist(),
                       "slow": bool(bc.SLOW_FOUND[nf]) if len(bc.SLOW_FOUND) > nf else None,
                       "verdict": bc.DRIFT_VERDICT[-1] if bc.DRIFT_VERDICT else None}
                with path.open("a") as f:
                    f.write(json.dumps(row) + "\n")
                if i == done or (i + 1) % 25 == 0:
                    print(f"{hours} h {mix}: record {i + 1}/{args.records}, "
                          f"{(time.process_time() - t0) / (i + 1 - done):.1f} s CPU a record",
                          flush=True)
    return 0


def cmd_table(args: argparse.Namespace) -> int:
    from avard.core.allan.noise_id import fm_support_edf

    print("| record | mix | records | τ counted (s) | lowest | highest | τ outside 60–76 % "
          "(share ± SE) | EDF > white-FM (at m > 1) | EDF > fm_support_edf |")
    print("|---|---|---|---|---|---|---|---|---|")
    details = []
    for hours in [int(h) for h in args.hours.split(",")]:
        for mix in args.mixes.split(","):
            path = out_path(args, hours, mix)
            if not path.exists():
                continue
            rows = [json.loads(s) for s in path.open()]
            errors = [r for r in rows if "error" in r]
            rows = [r for r in rows if "error" not in r][: args.records]
            if not rows:
                continue
            n, rate, lv = setup(hours, mix)
            ms = np.array(rows[0]["m"])
            if any(r["m"] != rows[0]["m"] for r in rows):
                print(f"  ({hours} h {mix}: the printed τ grid differs between records)")
                k = min(len(r["m"]) for r in rows)
                ms = ms[:k]
            else:
                k = len(ms)
            arr = {key: np.array([r[key][:k] for r in rows], dtype=float)
                   for key in ("var", "lo", "hi", "edf", "alpha", "stride")}
            t = gen.truth(lv, ms)
            sig = gen.signal_avar(lv, ms) / t
            inside = (arr["lo"] <= t) & (t <= arr["hi"])
            share = inside.mean(axis=0)
            se = np.sqrt(share * (1 - share) / len(rows))
            below = (t < arr["lo"]).mean(axis=0)
            above = (t > arr["hi"]).mean(axis=0)
            seen = 2 * t**2 / np.mean((arr["var"] - t) ** 2, axis=0)
            bias = arr["var"].mean(axis=0) / t
            wfm = np.array([white_fm_edf(n, int(m)) for m in ms])
            proj = np.array([fm_support_edf(2, int(m), 1, n + 1) for m in ms])
            over = (arr["edf"] > wfm * (1 + 1e-3)).sum(axis=0)  # (Greenhall's form: 0.03 %)
            over_cap = (arr["edf"] > proj * (1 + 1e-6)).sum(axis=0)
            out = [f"{m / rate:g} ({s:.1%} ± {e:.1%})" for m, s, e in zip(ms, share, se,
                                                                          strict=True)
                   if not BAND[0] <= s <= BAND[1]]
            slow = sum(1 for r in rows if r.get("slow"))
            print(f"| {hours} h at {rate:g} Hz | {mix} | {len(rows)} | {ms[0] / rate:g}–"
                  f"{ms[-1] / rate:g} ({len(ms)}) | {share.min():.1%} | {share.max():.1%} | "
                  f"{', '.join(out) or 'none'} | {int(over.sum())} ({int(over[ms > 1].sum())}) | "
                  f"{int(over_cap.sum())} |")
            counts = {v: sum(1 for r in rows if r.get("verdict") == v)
                      for v in ("resolved", "floor", "neither")}
            lines = [f"{hours} h {mix} ({len(rows)} records; {len(errors)} tracebacks; slow "
                     f"sinusoid resolved in {slow}; drift verdicts {counts}):"]
            lines.append("    τ (s)    cover   ±SE   below  above  EDF mean  EDF seen  "
                         "mean/truth  α mean  signal  wFM EDF  (support)  >wFM  >support  "
                         "max EDF/wFM")
            for j in range(k):
                lines.append(
                    f"  {ms[j] / rate:8.1f}  {share[j]:6.1%} {se[j]:5.1%}  {below[j]:5.1%} "
                    f"{above[j]:5.1%}  {arr['edf'][:, j].mean():8.1f}  {seen[j]:8.1f}  "
                    f"{bias[j]:9.3f}  {arr['alpha'][:, j].mean():6.2f}  {sig[j]:6.1%}  "
                    f"{wfm[j]:8.1f}  {proj[j]:8.1f}  {int(over[j]):5d}  {int(over_cap[j]):5d}  "
                    f"{arr['edf'][:, j].max() / wfm[j]:6.3f}")
            # the split by what the record resolved: a part resolved apart raises the EDF
            slow_f = np.array([bool(r.get("slow")) for r in rows])
            verdict = np.array([r.get("verdict") or "" for r in rows])
            groups = [("slow sinusoid resolved", slow_f), ("not resolved", ~slow_f)]
            groups += [(f"drift {v}", verdict == v) for v in ("resolved", "floor", "neither")]
            for name, sel in groups:
                if sel.sum() and (mix != "plain" or name.startswith("drift")):
                    sub_seen = 2 * t**2 / np.mean((arr["var"][sel] - t) ** 2, axis=0)
                    lines.append(f"    {name} ({int(sel.sum())}): cover "
                                 + " ".join(f"{v:.0%}" for v in inside[sel].mean(axis=0))
                                 + " | EDF mean/seen " + " ".join(
                                     f"{a:.0f}/{b:.0f}" for a, b in
                                     zip(arr["edf"][sel].mean(axis=0)[-5:], sub_seen[-5:],
                                         strict=True)) + " (last 5 τ)")
            details.append("\n".join(lines))
    if args.detail:
        print()
        print("\n\n".join(details))
    return 0


def cmd_repro(args: argparse.Namespace) -> int:
    """Record ``--index`` of one (length, mix, seed) stream again, written as an .npz that
    ``avard analyze`` reads (``--save``), and its printed EDF against the white-FM EDF."""
    from benchmarks import bench_coverage as bc

    hours, mix = int(args.hours), args.mixes
    n, rate, lv = setup(hours, mix)
    rng = np.random.default_rng([args.seed, hours, MIXES.index(mix), 2525])
    for _ in range(args.index):
        gen.record(lv, n, rng)
    y, _clean = gen.record(lv, n, rng)
    if args.save:
        np.savez(args.save, accel=y[:, None], rate_hz=rate)
    r, _share, _ = bc.printed(y, rate)
    keep = (n // r.m) >= MIN_AVERAGES
    t = gen.truth(lv, r.m[keep])
    for j in np.flatnonzero(keep):
        w = white_fm_edf(n, int(r.m[j]))
        flag = "  <-- above the white-FM EDF" if r.edf[j] > w * (1 + 1e-3) else ""
        print(f"τ {r.tau[j]:9.1f} s  var {r.var[j]:.4e}  truth {t[j]:.4e}  interval "
              f"[{r.lo[j]:.4e}, {r.hi[j]:.4e}]  α {r.alpha[j]:5.2f}  EDF {r.edf[j]:10.2f}  "
              f"white-FM EDF {w:10.2f}{flag}")
    return 0


def cmd_paired(args: argparse.Namespace) -> int:
    """The first ``--records`` records of a 'both' stream analysed three times: as drawn,
    less their sinusoid, less their drift; the drift test's verdict and the slow sinusoid
    search's each time, and the coverage at the longest printed τ."""
    from benchmarks import bench_coverage as bc

    hours = int(args.hours)
    n, rate, lv = setup(hours, "both")
    rng = np.random.default_rng([args.seed, hours, MIXES.index("both"), 2525])
    ramp = lv.drift * np.arange(n, dtype=float)
    tally: dict[str, dict[str, int]] = {}
    for _ in range(args.records):
        y, clean = gen.record(lv, n, rng)
        sine = clean - ramp
        for name, yy, part in (("as drawn", y, lv), ("less the sinusoid", y - sine,
                                                        gen.Levels(lv.s2, lv.f2, lv.q2,
                                                                   drift=lv.drift)),
                               ("less the drift", y - ramp,
                                gen.Levels(lv.s2, lv.f2, lv.q2, lv.amplitude, lv.period))):
            r, _share, _ = bc.printed(yy, rate)
            keep = np.flatnonzero((n // r.m) >= MIN_AVERAGES)
            j = keep[-1]
            t = float(gen.truth(part, r.m[j:j + 1])[0])
            d = tally.setdefault(name, {})
            for key in (f"drift {bc.DRIFT_VERDICT[-1]}",
                        "sinusoid resolved" if bc.SLOW_FOUND[-1] else "sinusoid not resolved",
                        "longest τ covered" if r.lo[j] <= t <= r.hi[j] else "longest τ missed"):
                d[key] = d.get(key, 0) + 1
    for name, d in tally.items():
        print(f"{hours} h both, {args.records} records, {name}: "
              + ", ".join(f"{k} {v}" for k, v in sorted(d.items())))
    return 0


def _gen_psd(lv: gen.Levels):  # type: ignore[no-untyped-def]
    """The generator's noise as a two-sided PSD in cycles per sample (the convention of
    ``analysis.cross_term``: AVAR = ∫ S|H_m|²): white s², Kasdin–Walter flicker
    σ_f²/|1 − e^(−2πiν)| = σ_f²/(2 sin πν), random walk q²/(4 sin² πν)."""
    def psd(nu: np.ndarray) -> np.ndarray:
        sn = np.abs(np.sin(np.pi * np.asarray(nu, dtype=float)))
        with np.errstate(divide="ignore"):
            return lv.s2 + lv.f2 / (2 * sn) + lv.q2 / (4 * sn * sn)
    return psd


def ensemble_edf(lv: gen.Levels, n: int, ms: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the EDF of the generator's noise alone, the EDF of the whole ensemble) of the OADEV
    at each m: the noise mixture's Greenhall–Riley quadratic form at the generator's own
    composition, and 2T²/(2N²/ν + S_r·c_r + S_s·c_s + S_s²·p), T the truth, S_r and S_s the
    drift's and the random-phase sinusoid's AVAR, c their exact cross terms with the
    noise under its true spectrum (``cross_term_variance``) and p the sinusoid's own spread
    over its phase (``signal_edf.phase_spread``). Written from the generator's definitions;
    the project supplies the quadrature (checked against the closed-form AVAR)."""
    from avard.core.allan.edf import edf_mixture
    from avard.core.analysis.cross_term import cross_term_variance
    from avard.core.analysis.signal_edf import phase_spread

    psd = _gen_psd(lv)
    noise_nu, whole = [], []
    for m in (int(v) for v in ms):
        big_m = n - 2 * m + 1
        lev = np.array([lv.s2 / m, lv.f2 * gen.flicker_unit_avar(np.array([m]))[0],
                        lv.q2 * (2 * m * m + 1) / (6 * m)])
        nu = edf_mixture((0, -1, -2), lev, 2, m, 1, n + 1, rate_data=True)
        big_n = float(gen.noise_avar(lv, np.array([m]))[0])
        s_r = 0.5 * (lv.drift * m) ** 2
        s_s = float(gen.signal_avar(lv, np.array([m]))[0]) - s_r
        var = 2 * big_n**2 / nu
        if s_r > 0:
            var += s_r * cross_term_variance(psd, m, big_m, 0.0)
        if lv.amplitude and s_s > 0:
            f0 = 1.0 / lv.period
            var += s_s * cross_term_variance(psd, m, big_m, f0) + s_s**2 * float(
                phase_spread(np.array([big_m]), f0)[0])
        noise_nu.append(nu)
        whole.append(2 * (big_n + s_r + s_s) ** 2 / var)
    return np.array(noise_nu), np.array(whole)


def cmd_ensemble(args: argparse.Namespace) -> int:
    """The stored records (``run``'s OUT) against the generator's exact ensemble: per τ the
    deterministic part's share of the truth, the noise's own EDF, the whole ensemble's EDF
    (``ensemble_edf``), the record's support (white FM's EDF), the mean printed EDF and the
    EDF the estimates scatter with, the coverage as printed, at the ensemble's EDF and at
    the support; then, split by the slow-sinusoid search's verdict and the drift test's,
    the estimates' mean over the truth, the mean printed EDF and the coverage (a verdict
    made of the same record selects on its estimate)."""
    from scipy.stats import chi2

    def cover(nu: np.ndarray, v: np.ndarray, t: float) -> np.ndarray:
        lo = nu * v / chi2.ppf(0.5 + 0.683 / 2, nu)
        hi = nu * v / chi2.ppf(0.5 - 0.683 / 2, nu)
        return (lo <= t) & (t <= hi)

    for hours in [int(h) for h in args.hours.split(",")]:
        for mix in args.mixes.split(","):
            path = out_path(args, hours, mix)
            if not path.exists():
                continue
            rows = [r for r in (json.loads(s) for s in path.open()) if "error" not in r]
            rows = rows[: args.records]
            n, rate, lv = setup(hours, mix)
            k = min(len(r["m"]) for r in rows)
            ms = np.array(rows[0]["m"][:k])
            var = np.array([r["var"][:k] for r in rows])
            edf = np.array([r["edf"][:k] for r in rows])
            t = gen.truth(lv, ms)
            share = gen.signal_avar(lv, ms) / t
            noise_nu, whole = ensemble_edf(lv, n, ms)
            wfm = np.array([white_fm_edf(n, int(m)) for m in ms])
            slow = np.array([bool(r.get("slow")) for r in rows])
            verdict = np.array([r.get("verdict") or "" for r in rows])
            print(f"{hours} h {mix} ({len(rows)} records):")
            print("    τ (s)   signal  noise EDF  ensemble EDF  support  printed  seen   "
                  "cover: printed  at ensemble  at support")
            for j in range(k):
                v = var[:, j]
                seen = 2 * t[j] ** 2 / np.mean((v - t[j]) ** 2)
                print(f"  {ms[j] / rate:8.1f}  {share[j]:6.1%}  {noise_nu[j]:9.1f}  "
                      f"{whole[j]:12.1f}  {wfm[j]:7.1f}  {edf[:, j].mean():7.1f}  {seen:5.1f}"
                      f"   {cover(edf[:, j], v, t[j]).mean():6.1%}  "
                      f"{cover(np.full(len(v), whole[j]), v, t[j]).mean():11.1%}  "
                      f"{cover(np.full(len(v), wfm[j]), v, t[j]).mean():10.1%}")
            groups = [("slow sinusoid resolved", slow), ("slow sinusoid not resolved", ~slow)]
            groups += [(f"drift {g}", verdict == g) for g in ("resolved", "floor", "neither")]
            for name, sel in groups:
                if sel.sum() < 5 or sel.all():
                    continue
                cells = []
                for j in range(max(0, k - 3), k):
                    held = cover(edf[sel, j], var[sel, j], t[j]).mean()
                    cells.append(f"{ms[j] / rate:g} s mean/truth "
                                 f"{var[sel, j].mean() / t[j]:.3f} printed "
                                 f"{edf[sel, j].mean():.1f} cover {held:.0%}")
                print(f"    {name} ({int(sel.sum())}), last 3 τ: " + "; ".join(cells))
    return 0


def cmd_drift(args: argparse.Namespace) -> int:
    """The calibration of analyze's time-domain drift test on these records, as
    ``bench_coverage.drift_test`` measures it on the project's: per record the test's signed
    z and the slope's 68 % profile interval (``drift.channel_drift`` on the block means, the
    AVAR fit as analyze makes it), and how often that interval holds the true slope (0 on
    the plain mix)."""
    from avard.core.analysis import drift as dr

    from benchmarks import bench_coverage as bc

    for hours in [int(h) for h in args.hours.split(",")]:
        for mix in args.mixes.split(","):
            n, rate, lv = setup(hours, mix)
            rng = np.random.default_rng([args.seed, hours, MIXES.index(mix), 77])
            z, held, clear = [], 0, 0
            for _ in range(args.records):
                y, _clean = gen.record(lv, n, rng)
                lik = bc.record_drift(y, rate)
                if lik is None:
                    continue
                z.append(lik.z)
                held += lik.slope_lo <= lv.drift * rate <= lik.slope_hi
                clear += lik.slope_lo > 0 or lik.slope_hi < 0
            za = np.array(z)
            k = max(1, len(za))
            print(f"{hours} h {mix}: {len(za)} records tested; past analyze's level "
                  f"{np.mean(np.abs(za) >= dr.two_sided_z(dr.LEVEL)):.1%}; z mean "
                  f"{za.mean():+.2f}, spread {za.std():.2f}; the slope's 68 % interval holds "
                  f"the true slope in {held / k:.1%} (± {math.sqrt(0.683 * 0.317 / k):.1%}), "
                  f"is clear of zero in {clear / k:.1%}", flush=True)
    return 0


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("command", choices=("check", "run", "table", "repro", "paired",
                                           "drift", "ensemble"))
    ap.add_argument("--hours", default="1")
    ap.add_argument("--mixes", default="plain,sine,drift")
    ap.add_argument("--records", type=int, default=200)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default="/tmp/adv25-cov2")
    ap.add_argument("--detail", action="store_true")
    ap.add_argument("--index", type=int, default=0, help="repro: the record's index")
    ap.add_argument("--save", default="", help="repro: write the record here (.npz)")
    args = ap.parse_args(argv)
    return {"check": cmd_check, "run": cmd_run, "table": cmd_table,
            "repro": cmd_repro, "paired": cmd_paired, "drift": cmd_drift,
            "ensemble": cmd_ensemble}[args.command](args)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

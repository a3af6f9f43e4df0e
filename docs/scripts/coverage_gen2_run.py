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
                                           "drift"))
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
            "repro": cmd_repro, "paired": cmd_paired, "drift": cmd_drift}[args.command](args)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

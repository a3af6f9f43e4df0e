"""Run `avard explain --json` on adversary_gen3's records and tabulate (adv26).

    OMP_NUM_THREADS=1 nice .venv/bin/python docs/scripts/adversary_gen3_run.py run \
        --kinds remount,order2 --hours 4,12 --seeds 1-20 --out /tmp/adv26/runs.jsonl
    .venv/bin/python docs/scripts/adversary_gen3_run.py table /tmp/adv26/runs.jsonl

One record at a time, each `avard explain REC --json` in its own process (nice, one BLAS
thread); each record's line holds its truth and, per axis, the verdict, the claimed findings
(cause, mechanism, params, intervals, model_dependent) and the thermal dict's z.

Scoring:

- unexplained classes (x and y carry a mechanism outside the candidate set): an axis says
  "unexplained" when its verdict's `explained` is false. "In the check's domain" means the
  extended fit fails its χ² test at 1 % by explain's own numbers (in-sample p < 0.01, or the
  held-out χ² beyond χ²(n) at 1 % and 5·n) *or* by the generator's oracle (the best of one
  lag, two lags, one lag + dT/dt and one lag + a quadratic, fitted to the noise-free truth
  signal, leaves a residual Allan variance ≥ 10× the noise's at some octave).
- ``order2`` axes said to fit by two paths: the printed response at the drive
  (`gain_at_drive`, `phase_at_drive_rad`) against the truth's c·(1 + iω·15 s)/(1 + iωτ₂)²
  (the logged channel is the plate through the DS18B20's own 15 s).
  A "confident wrong cause" is a claimed temperature finding on such an axis printed with an
  interval on its first coefficient narrower than ±10 % while the verdict says it fits.
- null classes: a false claim is any claimed finding other than analyze's lines (sinusoid,
  periodic), as the project's benchmarks count them; lines are counted apart.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from tests.support import adversary_gen3 as gen

LINES = ("sinusoid", "periodic")


def _seeds(s: str) -> list[int]:
    out: list[int] = []
    for part in s.split(","):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b or a) + 1))
    return out


def run(kinds: list[str], hours: list[float], seeds: list[int], out: str) -> None:
    avard = str(Path(sys.executable).with_name("avard"))
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    done = set()
    if Path(out).exists():
        for line in Path(out).read_text().splitlines():
            r = json.loads(line)
            done.add((r["kind"], r["seed"], r["hours"]))
    with open(out, "a") as fo, tempfile.TemporaryDirectory() as tmp:
        for seed in seeds:
            for h in hours:
                for kind in kinds:
                    if (kind, seed, h) in done:
                        continue
                    p = Path(tmp) / f"{kind}_{seed}_{h:g}.npz"
                    truth = gen.make_record(kind, seed, h, p)
                    truth.pop("_signals", None)
                    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
                    pr = subprocess.run(["nice", "timeout", "900", avard, "explain", str(p),
                                         "--json"], capture_output=True, text=True, env=env,
                                        check=False)
                    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
                    rec = {"kind": kind, "seed": seed, "hours": h, "truth": truth,
                           "rc": pr.returncode,
                           "cpu": r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime,
                           "stderr": pr.stderr[-1500:]}
                    if pr.returncode == 0:
                        d = json.loads(pr.stdout)
                        sc = d.get("screened") or {}
                        rec["screened"] = {"counts": sc.get("counts"),
                                           "notes": sc.get("notes"),
                                           "refused": sc.get("refused")}
                        rec["temperature_unused"] = d.get("temperature_unused")
                        rec["axes"] = {a: _axis(c) for a, c in d["channels"].items()}
                    fo.write(json.dumps(rec, default=float) + "\n")
                    fo.flush()
                    for q in (p, Path(str(p) + ".truth.json")):
                        q.unlink(missing_ok=True)
                    print(kind, seed, h, pr.returncode, f"{rec['cpu']:.1f}", flush=True)


def _axis(c: dict) -> dict:
    th = c.get("thermal") or {}
    return {"verdict": {k: c["verdict"].get(k) for k in ("explained", "tested", "chi2_dof", "dof",
                                                         "p_value", "heldout_chi2", "heldout_n",
                                                         "heldout_p", "line")},
            "findings": [{k: f.get(k) for k in ("cause", "claimed", "params", "intervals",
                                                "model_dependent", "mechanism", "channel",
                                                "statistic", "threshold",
                                                "intervals_if_model_held")}
                         for f in c["findings"]],
            "thermal_z": th.get("z"), "thermal_passed": th.get("passed"),
            "thermal_mechanism": th.get("mechanism")}


def _claimed(ax: dict, lines: bool = False) -> list[dict]:
    return [f for f in ax["findings"] if f["claimed"] and ((f["cause"] in LINES) == lines)]


def _narrow(f: dict, rel: float = 0.10) -> bool:
    """The finding's first coefficient-like parameter printed with an interval within ±rel."""
    iv = f.get("intervals") or {}
    pa = f.get("params") or {}
    for k in ("coefficient", "gain_at_drive", "size", "sigma", "amplitude", "rate"):
        if k in iv and iv[k] and pa.get(k):
            lo, hi = iv[k]
            v = pa[k]
            return v != 0 and (hi - lo) / 2 <= rel * abs(v)
    return False


def _heldout_fails(v: dict) -> bool:
    n, x, p = v.get("heldout_n"), v.get("heldout_chi2"), v.get("heldout_p")
    return p is not None and x is not None and n and p < 0.01 and x > 5 * n


def upper95(k: int, n: int) -> float:
    """Clopper–Pearson one-sided 95 % upper bound of a binomial rate (bisection)."""
    if n == 0:
        return 1.0
    if k >= n:
        return 1.0
    lo, hi = k / n, 1.0
    for _ in range(60):
        mid = (lo + hi) / 2
        cdf = sum(math.comb(n, i) * mid**i * (1 - mid) ** (n - i) for i in range(k + 1))
        lo, hi = (mid, hi) if cdf > 0.05 else (lo, mid)
    return hi


def table(path: str, detail: bool = False) -> list[str]:
    recs = [json.loads(x) for x in Path(path).read_text().splitlines()]
    out: list[str] = []
    out.append("| class | hours | records (rc≠0) | axes | in domain | unexplained in domain | "
               "said to fit in domain | confident wrong (fits, ±10 %) | claimed causes (axes) | "
               "CPU-s/record |")
    out.append("|---|---|---|---|---|---|---|---|---|---|")
    fails: list[str] = []
    for kind in gen.UNEXPLAINED:
        for h in sorted({r["hours"] for r in recs if r["kind"] == kind}):
            rs = [r for r in recs if r["kind"] == kind and r["hours"] == h]
            bad = sum(r["rc"] != 0 for r in rs)
            axes = dom = unx = fit = wrong = 0
            causes: dict[str, int] = {}
            for r in rs:
                if r["rc"] != 0:
                    fails.append(f"{kind} seed {r['seed']} {h:g} h: rc {r['rc']}")
                    continue
                for a in "xy":
                    ax = r["axes"][a]
                    v = ax["verdict"]
                    axes += 1
                    orc = r["truth"]["axes"][a].get("oracle") or {}
                    in_dom = ((v.get("p_value") is not None and v["p_value"] < 0.01)
                              or _heldout_fails(v)
                              or orc.get("resid_over_noise_max", 0) >= 10)
                    cl = _claimed(ax)
                    for f in cl:
                        key = f["cause"] + (f"/{f['mechanism']}" if f.get("mechanism") else "")
                        causes[key] = causes.get(key, 0) + 1
                    if not in_dom:
                        continue
                    dom += 1
                    if not v["explained"]:
                        unx += 1
                    else:
                        fit += 1
                        nw = [f for f in cl if _narrow(f)]
                        wrong += bool(nw)
                        fails.append(
                            f"{kind} seed {r['seed']} {h:g} h axis {a}: said to fit "
                            f"(χ²/dof {v['chi2_dof']:.3g}, p {v['p_value']:.3g}, held out "
                            f"{v['heldout_chi2']} on {v['heldout_n']}), oracle ({orc.get('best')}) residual "
                            f"{orc.get('resid_over_noise_max', float('nan')):.3g}× noise; claims "
                            + (", ".join(f"{f['cause']}/{f.get('mechanism')} {f['params']}"
                                         f" {f['intervals']}" for f in cl) or "none"))
            cpu = sum(r["cpu"] for r in rs) / max(1, len(rs))
            share = f"{unx}/{dom}" + (f" = {100 * unx / dom:.0f} %" if dom else "")
            out.append(f"| {kind} | {h:g} | {len(rs)} ({bad}) | {axes} | {dom} | {share} | {fit} | "
                       f"{wrong} | {', '.join(f'{k} {v}' for k, v in sorted(causes.items()))} | "
                       f"{cpu:.1f} |")
    out.append("")
    out.append("| null class | hours | records (rc≠0) | axes | false claims (axes) | 95 % upper | "
               "claims | line findings (axes) | unexplained axes | CPU-s/record |")
    out.append("|---|---|---|---|---|---|---|---|---|---|")
    tot_ax = tot_fc = 0
    for kind in gen.NULLS:
        for h in sorted({r["hours"] for r in recs if r["kind"] == kind}):
            rs = [r for r in recs if r["kind"] == kind and r["hours"] == h]
            bad = sum(r["rc"] != 0 for r in rs)
            axes = fc = ln = unx = 0
            causes: dict[str, int] = {}
            for r in rs:
                if r["rc"] != 0:
                    fails.append(f"{kind} seed {r['seed']} {h:g} h: rc {r['rc']}: "
                                 + r["stderr"].strip().splitlines()[-1][:200])
                    continue
                for a, ax in r["axes"].items():
                    axes += 1
                    cl = _claimed(ax)
                    fc += bool(cl)
                    ln += bool(_claimed(ax, lines=True))
                    unx += not ax["verdict"]["explained"]
                    for f in cl:
                        causes[f["cause"]] = causes.get(f["cause"], 0) + 1
                        fails.append(f"{kind} seed {r['seed']} {h:g} h axis {a}: false "
                                     f"{f['cause']} {f['params']} (stat {f['statistic']}, "
                                     f"threshold {f['threshold']})")
            tot_ax += axes
            tot_fc += fc
            cpu = sum(r["cpu"] for r in rs) / max(1, len(rs))
            out.append(f"| {kind} | {h:g} | {len(rs)} ({bad}) | {axes} | {fc} | "
                       f"{100 * upper95(fc, axes):.1f} % | "
                       f"{', '.join(f'{k} {v}' for k, v in sorted(causes.items())) or '—'} | "
                       f"{ln} | {unx} | {cpu:.1f} |")
    out.append(f"| all nulls | | | {tot_ax} | {tot_fc} | {100 * upper95(tot_fc, tot_ax):.1f} % "
               "| | | | |")
    if detail:
        out.append("")
        out += ["- " + f for f in fails]
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser()
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--kinds", default=",".join(gen.KINDS))
    r.add_argument("--hours", default="4,12")
    r.add_argument("--seeds", default="1-10")
    r.add_argument("--out", required=True)
    t = sub.add_parser("table")
    t.add_argument("file")
    t.add_argument("--detail", action="store_true")
    a = ap.parse_args(argv)
    if a.cmd == "run":
        run(a.kinds.split(","), [float(x) for x in a.hours.split(",")], _seeds(a.seeds), a.out)
    else:
        print("\n".join(table(a.file, a.detail)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

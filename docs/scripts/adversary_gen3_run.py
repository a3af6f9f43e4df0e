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
  (the logged channel is the plate through the DS18B20's own 15 s; on the ambient channel,
  the room through 30 s, the plate's own lag τ_p is in the path too).
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


def _order2(recs: list[dict]) -> list[str]:
    """Two paths' printed response at the drive against the two-pole truth's."""
    rows = ["| order2 hours | axes with a two-path claim | gain within 20 % | gain in its 68 % "
            "interval | phase within 0.1 rad | phase in its interval | median half-width of "
            "the gain's interval |", "|---|---|---|---|---|---|---|"]
    for h in sorted({r["hours"] for r in recs if r["kind"] == "order2"}):
        n = g20 = gin = p01 = pin = 0
        widths = []
        for r in recs:
            if r["kind"] != "order2" or r["hours"] != h or r["rc"] != 0:
                continue
            for a in "xy":
                t = r["truth"]["axes"][a]
                for f in _claimed(r["axes"][a]):
                    pa, iv = f["params"] or {}, f["intervals"] or {}
                    if f["cause"] != "temperature" or "gain_at_drive" not in pa:
                        continue
                    w = 2 * math.pi / pa["drive_period_s"]
                    hh = t["coefficient"] * (1 + 1j * w * 15.0) / (1 + 1j * w * t["pole_s"]) ** 2
                    if f.get("channel") == "ambient":     # the room: the plate's lag is in
                        hh *= (1 + 1j * w * 30.0) / (1 + 1j * w * 15.0) / (
                            1 + 1j * w * r["truth"]["tau_plate_s"])
                    gain, ph = abs(hh), math.atan2(hh.imag, hh.real)
                    n += 1
                    g20 += abs(pa["gain_at_drive"] / gain - 1) <= 0.2
                    dph = (pa["phase_at_drive_rad"] - ph + math.pi) % (2 * math.pi) - math.pi
                    p01 += abs(dph) <= 0.1
                    if "gain_at_drive" in iv:
                        lo, hi = iv["gain_at_drive"]
                        gin += lo <= gain <= hi
                        widths.append((hi - lo) / 2 / pa["gain_at_drive"])
                    if "phase_at_drive_rad" in iv:
                        lo, hi = iv["phase_at_drive_rad"]
                        pin += lo <= pa["phase_at_drive_rad"] - dph <= hi
        med = f"{100 * sorted(widths)[len(widths) // 2]:.1f} %" if widths else "—"
        rows.append(f"| {h:g} | {n} | {g20} | {gin} | {p01} | {pin} | {med} |")
    return rows


def table(path: str, detail: bool = False) -> list[str]:
    recs = [json.loads(x) for x in Path(path).read_text().splitlines()]
    out: list[str] = []
    out.append("| class | hours | records | axes | D1: in-sample p < 1 % | unexplained in D1 | "
               "D2: in-sample or held-out p < 1 % | unexplained in D2 | D3: oracle ≥ 10× | "
               "unexplained in D3 | said to fit in D2 ∪ D3 (±10 % claim) | unexplained, a "
               "±10 % interval printed (held-out p < 1 %) | claimed causes (axes) "
               "| CPU-s/record |")
    out.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    fails: list[str] = []

    def pct(k: int, n: int) -> str:
        return f"{k}/{n}" + (f" = {100 * k / n:.0f} %" if n else "")

    for kind in gen.UNEXPLAINED:
        for h in sorted({r["hours"] for r in recs if r["kind"] == kind}):
            rs = [r for r in recs if r["kind"] == kind and r["hours"] == h]
            bad = sum(r["rc"] != 0 for r in rs)
            axes = 0
            dn = [0, 0, 0]
            du = [0, 0, 0]
            fit = wrong = printed = printed_hr = 0
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
                    d1 = v.get("p_value") is not None and v["p_value"] < 0.01
                    hp = v.get("heldout_p")
                    d2 = d1 or (hp is not None and hp < 0.01)
                    d3 = orc.get("resid_over_noise_max", 0) >= 10
                    unx = not v["explained"]
                    for i, d in enumerate((d1, d2, d3)):
                        dn[i] += d
                        du[i] += d and unx
                    cl = _claimed(ax)
                    for f in cl:
                        key = f["cause"] + (f"/{f['mechanism']}" if f.get("mechanism") else "")
                        causes[key] = causes.get(key, 0) + 1
                    if unx and (d2 or d3) and any(_narrow(f) for f in cl):
                        printed += 1
                        printed_hr += hp is not None and hp < 0.01
                        fails.append(
                            f"{kind} seed {r['seed']} {h:g} h axis {a}: unexplained, printed "
                            f"(held out {v['heldout_chi2']} on {v['heldout_n']}, p {hp}): "
                            + ", ".join(f"{f['cause']}/{f.get('mechanism')} {f['params']}"
                                        f" {f['intervals']}" for f in cl if _narrow(f)))
                    if not (d2 or d3) or unx:
                        continue
                    fit += 1
                    nw = [f for f in cl if _narrow(f)]
                    wrong += bool(nw)
                    why = "D2 (held-out p < 1 % within 5·n)" if d2 else "D3 only"
                    fails.append(
                        f"{kind} seed {r['seed']} {h:g} h axis {a}: said to fit, {why} "
                        f"(χ²/dof {v['chi2_dof']:.3g}, p {v['p_value']:.3g}, held out "
                        f"{v['heldout_chi2']} on {v['heldout_n']}, p {hp}), oracle "
                        f"({orc.get('best')}) residual "
                        f"{orc.get('resid_over_noise_max', float('nan')):.3g}× noise; claims "
                        + (", ".join(f"{f['cause']}/{f.get('mechanism')} {f['params']}"
                                     f" {f['intervals']}" for f in cl) or "none"))
            cpu = sum(r["cpu"] for r in rs) / max(1, len(rs))
            out.append(f"| {kind} | {h:g} | {len(rs)}" + (f" ({bad} failed)" if bad else "")
                       + f" | {axes} | {dn[0]} | {pct(du[0], dn[0])} | {dn[1]} | "
                       f"{pct(du[1], dn[1])} | {dn[2]} | {pct(du[2], dn[2])} | {fit} ({wrong}) | "
                       f"{printed} ({printed_hr}) | "
                       f"{', '.join(f'{k} {v}' for k, v in sorted(causes.items())) or '—'} | "
                       f"{cpu:.1f} |")
    out.append("")
    out += _order2(recs)
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

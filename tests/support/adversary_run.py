"""Run ``avard explain --json`` on records of the adversary's generator and score them.

    python -m tests.support.adversary_run run OUT.jsonl PLAN.json   # one explain at a time
    python -m tests.support.adversary_run table OUT.jsonl [...]     # the Markdown rows
    python -m tests.support.adversary_run coverage HOURS N SEED0    # issue 24's ADEV intervals

PLAN.json is a list of ``[kind, seed, hours or null, {make_record keywords}]``. Each record
is written to a temporary directory, explained with one BLAS thread under ``nice``, scored
against its truth file and removed; CPU seconds are the child's user + system time.

Scoring (issue 23's checks, per record): *cause* — x claims the hidden cause (temperature;
for the compound class a warm-up or one of its events; drift; a periodic finding); *right* —
also the channel (plate), the mechanism (one lag, a negative lag, two paths, quadratic,
dT/dt, hysteresis) or, for the compound class, the warm-up and both up-then-down events and
nothing more; *params* — coefficient within 20 %, lag within 20 % or 30 s, the mechanism's
own term within 20 % (for dT/dt its r − c·L and no lag; warm-up size and T;
drift rate); *false* — any claim but analyze's
steady lines on y or z (the null axes); *unexplained* — of the records not right, those
whose x says UNEXPLAINED.
"""

from __future__ import annotations

import collections
import json
import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

from tests.support import adversary_gen as gen

EXPECT = {
    "faulty_coupled": "one_lag",
    "typical24": "one_lag",
    "neglag": "one_lag",
    "twopath": "two_path",
    "quadratic": "quadratic",
    "dtdt": "rate",
    "hysteresis": "hysteresis",
}
EXTRA = {
    "quadratic": ("quadratic", "q_mps2_per_k2"),
    "dtdt": ("rate_coupling", "r_mps2_per_k_per_s"),
    "hysteresis": ("hysteresis", "h_mps2"),
}


def run(out: str, plan_file: str) -> None:
    avard = str(Path(sys.executable).with_name("avard"))
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    with open(out, "a") as fo, tempfile.TemporaryDirectory() as tmp:
        for item in json.loads(Path(plan_file).read_text()):
            kind, seed, hours = item[:3]
            kw = dict(item[3]) if len(item) > 3 else {}
            if "logged" in kw:
                kw["logged"] = tuple(kw["logged"])
            p = Path(tmp) / f"{kind}_{seed}.npz"
            truth = gen.make_record(kind, seed, p, hours, **kw)
            truth["kw"] = item[3] if len(item) > 3 else {}
            r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
            pr = subprocess.run(
                ["nice", "timeout", "900", avard, "explain", str(p), "--json"],
                capture_output=True,
                text=True,
                env=env,
                check=False,
            )
            r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
            rec = {
                "kind": kind,
                "seed": seed,
                "truth": truth,
                "rc": pr.returncode,
                "cpu": r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime,
                "stderr": pr.stderr[-2000:],
            }
            if pr.returncode == 0:
                d = json.loads(pr.stdout)
                rec["screened"] = d.get("screened")
                rec["axes"] = {
                    a: {
                        "findings": c["findings"],
                        "thermal": c["thermal"],
                        "verdict": c["verdict"],
                        "terms": c["extended"].get("terms"),
                    }
                    for a, c in d["channels"].items()
                }
            fo.write(json.dumps(rec, default=float) + "\n")
            fo.flush()
            p.unlink()
            print(kind, seed, pr.returncode, f"{rec['cpu']:.1f}", flush=True)


def _close(a: float | None, b: float | None, rel: float = 0.2, abs_: float = 0.0) -> bool:
    return a is not None and b is not None and abs(a - b) <= max(rel * abs(b), abs_)


def _label(r: dict) -> str:
    tr, k = r["truth"], r["kind"]
    kw = tr.get("kw", {})
    out = k + (" (plate only)" if kw.get("logged") == ["plate"] else "")
    if k in ("compound", "typical24"):
        out += f" {tr['hours']:g} h"
    if "factor" in kw:
        out += f" ×{kw['factor']:g}"
    if "pump_band_hz" in kw:
        out += f" band {kw['pump_band_hz']:g} Hz"
    return out


def _score_x(k: str, t: dict, c: list[dict], xf: list[dict]) -> tuple[bool, bool, bool, str]:
    """(cause, right, params, note) of axis x."""
    if k in EXPECT:
        temp = [f for f in c if f["cause"] == "temperature"]
        if not temp:
            return False, False, False, ""
        f, p = temp[0], temp[0]["params"]
        plate = f.get("channel") == "plate"
        right = plate and f.get("mechanism") == EXPECT[k] and (k != "neglag" or p["lag_s"] < 0)
        p20 = plate and _close(p.get("coefficient"), t["coefficient_mps2_per_k"])
        # a dT/dt term beside a lag of 0: the lag and r are one parameter to first order, and
        # r − c·L (reported as rate_coupling) is what the record resolves (docs/explain.md)
        if k != "dtdt" or not right:
            p20 = p20 and _close(p.get("lag_s"), t["lag_s"], 0.2, 30.0)
        if k in EXTRA and right:
            p20 = p20 and _close(p.get(EXTRA[k][0]), t[EXTRA[k][1]])
        return True, right, p20, "" if plate else "ambient"
    if k == "compound":
        wu = [f for f in c if f["cause"] == "warmup"]
        ev = [f for f in c if f["cause"] in ("bias_step", "excursion")]

        def hit(a: float, b: float) -> bool:
            return any(
                f["cause"] == "excursion"
                and abs(f["params"]["start_s"] - a) < 60
                and abs(f["params"]["end_s"] - b) < 60
                for f in ev
            )

        st, e = t["steps"], t["excursion"]
        n_ok = hit(st[0]["t_s"], st[1]["t_s"]) + hit(e["start_s"], e["end_s"])
        p20 = (
            bool(wu)
            and _close(wu[0]["params"]["size"], t["warmup"]["size"])
            and _close(wu[0]["params"]["time_constant_s"], t["warmup"]["time_constant_s"])
        )
        return (
            bool(wu) or n_ok > 0,
            bool(wu) and n_ok == 2 and len(ev) == 2,
            p20,
            f"w{int(bool(wu))}e{n_ok}/{len(ev)}",
        )
    if k == "drift":
        d = [f for f in c if f["cause"] == "drift"]
        return bool(d), bool(d), bool(d) and _close(d[0]["params"]["rate"], t["rate_mps3"]), ""
    if k == "pump":
        d = [f for f in xf if f["claimed"] and f["cause"] in ("periodic", "sinusoid")]
        return bool(d), len(d) == 1 and d[0]["cause"] == "periodic", False, f"{len(d)} lines"
    return False, False, False, ""


def table(files: list[str]) -> list[str]:
    rows: dict[str, collections.Counter] = {}
    notes: dict[str, list[str]] = collections.defaultdict(list)
    for fn in files:
        for line in open(fn):
            r = json.loads(line)
            label = _label(r)
            row = rows.setdefault(label, collections.Counter())
            row["n"] += 1
            row["cpu"] += r["cpu"]
            if r["rc"] != 0:
                row["error"] += 1
                continue
            tr, ax = r["truth"], r["axes"]
            claims = {
                a: [f for f in ax[a]["findings"] if f["claimed"] and f["cause"] != "sinusoid"]
                for a in ax
            }
            for a in "yz" if tr["axes"]["x"]["cause"] is not None else "xyz":
                row["null"] += 1
                row["false"] += bool(claims[a])
                row["unexpl_null"] += not ax[a]["verdict"]["explained"]
            if tr["axes"]["x"]["cause"] is None:
                continue
            cause, right, p20, note = _score_x(
                r["kind"], tr["axes"]["x"], claims["x"], ax["x"]["findings"]
            )
            row["cause"] += cause
            row["right"] += right
            row["p20"] += p20
            row["wrong"] += not right
            row["wrong_unexpl"] += (not right) and not ax["x"]["verdict"]["explained"]
            if note:
                notes[label].append(note)
    out = [
        "| class | records | cause on x | right (channel, mechanism) | params ≤ 20 % | false "
        'claims (null axes) | "unexplained" where not right | null axes unexplained | '
        "CPU s/record | notes |",
        "|---" * 10 + "|",
    ]
    for label, r in rows.items():
        hidden = r["n"] - (r["null"] == 3 * r["n"]) * r["n"]
        err = f" errors {r['error']}" if r["error"] else ""
        note = ", ".join(f"{k} {v}" for k, v in collections.Counter(notes[label]).items())
        cells = (
            ("—", "—", "—", "—")
            if not hidden
            else (
                f"{r['cause']}/{r['n']}",
                f"{r['right']}/{r['n']}",
                f"{r['p20']}/{r['n']}",
                f"{r['wrong_unexpl']}/{r['wrong']}",
            )
        )
        out.append(
            f"| {label} | {r['n']} | {cells[0]} | {cells[1]} | {cells[2]} | "
            f"{r['false']}/{r['null']} | {cells[3]} | {r['unexpl_null']}/{r['null']} | "
            f"{r['cpu'] / r['n']:.1f} | {note}{err} |"
        )
    return out


def coverage(hours: float, n: int, seed0: int) -> list[str]:
    """Issue 24's check on this generator: ``avard analyze --json`` of ``n`` records of white
    + flicker + random walk (the drift class with no drift), and how often each printed τ's
    68 % ADEV interval holds the closed-form ADEV of the generated processes, at τ ≥ 1 s
    with ≥ 5 non-overlapping averages, per rate and decade of τ."""
    import math

    avard = str(Path(sys.executable).with_name("avard"))
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    hit: collections.Counter = collections.Counter()
    tot: collections.Counter = collections.Counter()
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "noise.npz"
        for seed in range(seed0, seed0 + n):
            tr = gen.make_record("drift", seed, p, hours, 0.0)
            pr = subprocess.run(
                ["nice", avard, "analyze", str(p), "--json"],
                capture_output=True,
                text=True,
                env=env,
                check=True,
            )
            d = json.loads(pr.stdout)
            for ax in "xyz":
                c = d["channels"][ax]
                for tau, lo, hi in zip(c["tau_s"], c["adev_lo"], c["adev_hi"], strict=True):
                    if tau < 1.0 or tau > hours * 3600 / 5:
                        continue
                    key = (tr["rate_hz"], 10 ** min(3, math.floor(math.log10(tau))))
                    tot[key] += 1
                    hit[key] += lo <= math.sqrt(gen.avar(tau, *tr["noise"][ax])) <= hi
    return [
        f"{r:g} Hz, τ from {t:g} s: {hit[(r, t)]}/{tot[(r, t)]} = {hit[(r, t)] / tot[(r, t)]:.0%}"
        for r, t in sorted(tot)
    ]


if __name__ == "__main__":  # pragma: no cover - a command-line tool
    if sys.argv[1] == "run":
        run(sys.argv[2], sys.argv[3])
    elif sys.argv[1] == "coverage":
        print("\n".join(coverage(float(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]))))
    else:
        print("\n".join(table(sys.argv[2:])))

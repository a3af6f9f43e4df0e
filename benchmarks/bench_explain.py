"""`avard explain` against `avard analyze` on the same file: peak memory and time, in one run;
then detection power on records from a generator written apart from the simulator.

    python -m benchmarks explain [--hours 60] [--file REC.npz] [--cases 20] [--skip-power]

Part 1 (resources). A `paper-table3` record (``avard simulate --preset paper-table3 --hours H
--seed 1``, or ``--file``) is analysed by ``avard analyze`` and explained by ``avard explain``,
each in its own process (``--json``, output discarded); the table gives each one's peak
resident memory (ru_maxrss) and wall time, and explain's ratio to analyze (targets: memory
≤ 2×, time ≤ 3×). analyze is the reference measured in the same run.

Part 2 (detection power, tests/support/hidden.py: a generator written apart from the
simulator). Per case kind, ``--cases`` records of 4 h at 10 Hz (N 1.6e-4 m/s/√s, B 2e-5 m/s²,
K 2e-6 m/s²·√s) are explained: "temperature" hides 3× the stated minimum coefficient
(``thermal_fit.min_detectable_tempco``, lag to 10 %) behind a 5-minute first-order lag on the
logged ambient channel, on x; "warmup" and "bias_step" hide 3× their stated minimum
(``causes.min_detectable_warmup`` / ``_step``) on every axis, "warmup+step" both in one
record (each must be found with its parameters); "null" hides nothing.
"""

from __future__ import annotations

import argparse
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

_CHILD = """
import resource, sys, time
from avard.daemon import cli
t0 = time.perf_counter()
rc = cli.main(sys.argv[1:])
dt = time.perf_counter() - t0
print(f"@@ {rc} {dt:.3f} {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss}", file=sys.stderr)
"""


def _measure(args: list[str]) -> tuple[float, float]:
    """(wall s, peak RSS MB) of one CLI command in a fresh process."""
    p = subprocess.run([sys.executable, "-c", _CHILD, *args], capture_output=True, text=True,
                       check=False)
    line = [ln for ln in p.stderr.splitlines() if ln.startswith("@@ ")]
    if not line:
        raise SystemExit(f"{' '.join(args)} failed:\n{p.stderr[-2000:]}")
    _, rc, dt, rss = line[-1].split()
    if rc != "0":
        raise SystemExit(f"{' '.join(args)} exited {rc}:\n{p.stderr[-2000:]}")
    return float(dt), int(rss) / 1024.0


def resources(path: str) -> None:
    t_an, m_an = _measure(["analyze", path, "--json"])
    t_ex, m_ex = _measure(["explain", path, "--json"])
    print(f"{'command':10s} {'wall s':>8s} {'peak MB':>8s} {'time ×':>7s} {'memory ×':>9s}")
    print(f"{'analyze':10s} {t_an:8.1f} {m_an:8.0f} {1.0:7.2f} {1.0:9.2f}")
    print(f"{'explain':10s} {t_ex:8.1f} {m_ex:8.0f} {t_ex / t_an:7.2f} {m_ex / m_an:9.2f}")
    print(f"targets: time ≤ 3× ({'met' if t_ex <= 3 * t_an else 'NOT met'}), memory ≤ 2× "
          f"({'met' if m_ex <= 2 * m_an else 'NOT met'})")


def power(cases: int, seed0: int) -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from avard.core.explain.causes import min_detectable_step, min_detectable_warmup
    from avard.core.explain.engine import explain_file
    from avard.core.explain.thermal_fit import min_detectable_tempco

    from tests.support.hidden import Truth, make_record, save

    hours, rate, n_w, b_i, k_r = 4.0, 10.0, 1.6e-4, 2e-5, 2e-6
    amp, period, lag, t_w, t_step = 0.5, 1800.0, 300.0, 900.0, 5000.0
    targs = (n_w, b_i, k_r, hours * 3600, amp, period, lag)
    c_min = max(min_detectable_tempco(*targs), min_detectable_tempco(*targs, lag_rel=0.1))
    w_min = min_detectable_warmup(n_w, b_i, k_r, t_w)
    s_min = min_detectable_step(n_w, b_i, k_r, hours * 3600)
    print(f"\ndetection power: {cases} records per kind, {hours:g} h at {rate:g} Hz, N {n_w:g} "
          f"m/s/√s, B {b_i:g} m/s², K {k_r:g} m/s²·√s; effect on x at 3× the stated minimum "
          f"(docs/explain.md):")
    print(f"  temperature: ±{amp:g} °C {period / 60:g}-min cycle, lag {lag:g} s, minimum "
          f"{c_min:.3g} m/s²/K (lag to 10 %), hidden {3 * c_min:.3g}")
    print(f"  warmup: T {t_w:g} s, minimum {w_min:.3g} m/s², hidden {3 * w_min:.3g}")
    print("  gauss_markov: σ 2e-4 m/s², T 120 s (no stated minimum yet)")
    print(f"  bias_step: at {t_step:g} s, minimum {s_min:.3g} m/s², hidden {3 * s_min:.3g}")
    print("  warmup+step: both of the above in the same record")
    kinds = {
        "temperature": Truth(coefficient=(3 * c_min, 0.0, 0.0), lag_s=lag),
        "warmup": Truth(warmup=(3 * w_min, t_w)),
        "gauss_markov": Truth(gauss_markov=(2e-4, 120.0)),
        "bias_step": Truth(step=(t_step, 3 * s_min)),
        "warmup+step": Truth(warmup=(3 * w_min, t_w), step=(t_step, 3 * s_min)),
        "null": Truth(),
    }

    def right(kind: str, p: dict[str, float]) -> bool:
        if kind == "temperature":
            return (math.isclose(p["coefficient"], 3 * c_min, rel_tol=0.2)
                    and math.isclose(p["lag_s"], lag, rel_tol=0.2))
        if kind == "gauss_markov":
            return (math.isclose(p["sigma"], 2e-4, rel_tol=0.2)
                    and math.isclose(p["time_constant_s"], 120.0, rel_tol=0.2))
        if kind == "warmup":
            return (math.isclose(p["size"], 3 * w_min, rel_tol=0.2)
                    and math.isclose(p["time_constant_s"], t_w, rel_tol=0.2))
        return (math.isclose(p["size"], 3 * s_min, rel_tol=0.2)
                and abs(p["time_s"] - t_step) < 0.01 * hours * 3600)

    print(f"\n{'kind':12s} {'cases':>5s} {'detected':>9s} {'params ok':>10s} "
          f"{'false claims':>13s} {'lines (analyze)':>16s}")
    with tempfile.TemporaryDirectory() as d:
        for j, (kind, truth) in enumerate(kinds.items()):
            n = det = par = false = lines = 0
            for i in range(cases):
                # warm-up and step act on every axis of the generator; temperature on x
                rec, _ = make_record(seed0 + 1000 * j + i, hours=hours, rate_hz=rate, N=n_w,
                                     B=b_i, K=k_r, truth=truth, logged=("ambient",))
                ex = explain_file(str(save(rec, Path(d) / "r.npz")))
                n += 1
                hidden_on = {"temperature": ["x"], "null": []}.get(kind, ["x", "y", "z"])
                ok_det, ok_par, bad = True, True, False
                for a, ch in ex.channels.items():
                    mine = [f for f in ch.claimed if f.cause != "sinusoid"]
                    lines += sum(f.cause == "sinusoid" for f in ch.claimed)
                    # "warmup+step" hides both: each must be found, with its parameters
                    want = {"warmup+step": ["warmup", "bias_step"]}.get(kind, [kind])
                    hit = {f.cause: f for f in mine if f.cause in want and a in hidden_on}
                    bad |= any(f.cause not in want or a not in hidden_on for f in mine)
                    if a in hidden_on:
                        ok_det &= len(hit) == len(want)
                        ok_par &= len(hit) == len(want) and all(
                            right(c, f.params) for c, f in hit.items())
                det += ok_det if kind != "null" else not bad
                par += ok_par if kind != "null" else not bad
                false += bad
            print(f"{kind:12s} {n:5d} {det / n:9.0%} {par / n:10.0%} {false / n:13.0%} "
                  f"{lines:16d}")
    print("detected: the cause claimed on every axis it was hidden on (null: nothing claimed);"
          " params ok: also within 20 %; false claims: records with any other claim; lines: "
          "sinusoids analyze's line finder put in the base model (all axes, not hidden)")


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks explain")
    ap.add_argument("--hours", type=float, default=60.0)
    ap.add_argument("--file", help="an existing record instead of simulating one")
    ap.add_argument("--cases", type=int, default=20)
    ap.add_argument("--seed0", type=int, default=9000)
    ap.add_argument("--skip-power", action="store_true")
    ap.add_argument("--skip-resources", action="store_true")
    args = ap.parse_args(argv)
    if not args.skip_resources:
        with tempfile.TemporaryDirectory() as d:
            path = args.file
            if path is None:
                path = str(Path(d) / "table3.npz")
                t0 = time.perf_counter()
                subprocess.run([sys.executable, "-m", "avard.daemon.cli", "simulate",
                                "--preset", "paper-table3", "--hours", str(args.hours),
                                "--seed", "1", "--out", path], check=True,
                               stdout=subprocess.DEVNULL)
                print(f"paper-table3, {args.hours:g} h, seed 1 (simulated in "
                      f"{time.perf_counter() - t0:.0f} s)")
            resources(path)
    if not args.skip_power:
        power(args.cases, args.seed0)
    return 0

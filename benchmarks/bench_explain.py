"""`avard explain` against `avard analyze` on the same file: peak memory and time, in one run;
then detection power on records from a generator written apart from the simulator.

    python -m benchmarks explain [--hours 60] [--file REC.npz] [--cases 20] [--skip-power]

Part 1 (resources). A `paper-table3` record (``avard simulate --preset paper-table3 --hours H
--seed 1``, or ``--file``) is analysed by ``avard analyze`` and explained by ``avard explain``,
each in its own process (``--json``, output discarded); the table gives each one's peak
resident memory (ru_maxrss) and wall time, and explain's ratio to analyze (targets: memory
≤ 2×, time ≤ 3×). analyze is the reference measured in the same run.

Part 2 (detection power, tests/support/hidden.py). Per case kind, ``--cases`` records of 4 h at
10 Hz (N 1.6e-4 m/s/√s, B 2e-5 m/s², K 2e-6 m/s²·√s... see the generator) are explained:
"temperature" hides 3× the stated minimum detectable coefficient (docs/explain.md) behind a
first-order lag on the logged ambient channel; "null" hides nothing. Detected = the cause
claimed on the axis with the coefficient and lag within 20 %; false claim = any cause claimed
that was not hidden.
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
    from avard.core.explain import explain_file
    from avard.core.thermal_fit import min_detectable_tempco

    from tests.support.hidden import Truth, make_record, save

    hours, rate, n_white, amp, period, lag = 4.0, 10.0, 1.6e-4, 0.5, 1800.0, 300.0
    c_min = min_detectable_tempco(n_white, 2e-5, 2e-6, hours * 3600, amp, period, lag)
    print(f"\ndetection power: {cases} records per kind, {hours:g} h at {rate:g} Hz, ±{amp:g} "
          f"°C {period / 60:g}-min cycle, lag {lag:g} s; stated minimum {c_min:.3g} m/s²/K, "
          f"hidden at 3× = {3 * c_min:.3g} m/s²/K")
    rows = {"temperature": [0, 0, 0], "null": [0, 0, 0]}  # cases, detected/clean, false
    with tempfile.TemporaryDirectory() as d:
        for kind in rows:
            for i in range(cases):
                c = 3 * c_min if kind == "temperature" else 0.0
                rec, _ = make_record(seed0 + i + (0 if c else 5000), hours=hours, rate_hz=rate,
                                     N=n_white, truth=Truth(coefficient=(c, 0.0, 0.0),
                                                            lag_s=lag), logged=("ambient",))
                ex = explain_file(str(save(rec, Path(d) / "r.npz")))
                r = rows[kind]
                r[0] += 1
                claimed = {(a, f.cause): f for a, ch in ex.channels.items() for f in ch.claimed}
                hit = claimed.get(("x", "temperature"))
                false = [k for k in claimed if not (kind == "temperature" and k == ("x",
                                                                                    "temperature"))]
                if kind == "temperature" and hit is not None:
                    ok = (math.isclose(hit.params["coefficient"], c, rel_tol=0.2)
                          and math.isclose(hit.params["lag_s"], lag, rel_tol=0.2))
                    r[1] += ok
                elif kind == "null":
                    r[1] += not claimed
                r[2] += bool(false)
    print(f"{'kind':12s} {'cases':>5s} {'detected/clean':>15s} {'false claims':>13s}")
    for k, (n, good, false) in rows.items():
        print(f"{k:12s} {n:5d} {good / n:15.0%} {false / n:13.0%}")


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

"""adv29: the statistical cases (tests/support/adversary_gen4.py), each written to OUTDIR with
its truth file and run through `avard explain --json --channels ch0`, one at a time.

    OMP_NUM_THREADS=1 nice .venv/bin/python docs/scripts/adv29_explain_cases.py OUTDIR [CASE ...]

Prints per record: the verdict line, the claimed causes with their parameters, the extended
fit's K, and the truth. Cases (seeds as run for docs/log/2026-11-29-adv29.md):

  coupling_step   one lag + one bias step (2 h, lag 120 s, step 4e-4 at 30 % / 70 %), seeds 3, 4
  linstep         no lag + a step (4 h, at 30 %), seed 1
  gm_sine         Gauss–Markov (1.7e-4, 30 s) + slow sine (1.5e-4, 90 min), 4 h, seeds 1–3;
                  gm_only, sine_only the controls
  relay           linear coupling + relay (c > 0), 4 h, seeds 1–6; relay_step: + a step at a switch
  remount_warm    coupling flipping sign at mid-record + a warm-up, 4 h, seeds 1, 2
  neg05           negative lag (log 300 s behind the die) on a 0.5 K log, 4 h, seeds 1, 2
  step_in_gap     one lag + a step inside a 25-min dropout of the log, 4 h, seeds 41, 42
  faulty_*        interleaved / units / clockstep / late_start_warm logs (2–3 h), seed 1
  gm_step         Gauss–Markov (1.7e-4, 30 s) + a step 4e-4 / 8e-4 / 1.6e-3 at 30 %, 4 h;
                  white_step the control: white noise of the same long-τ level (N 1.32e-3)
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from tests.support import adversary_gen4 as g

AVARD = str(Path(sys.executable).with_name("avard"))


def _white_step(size: float, seed: int = 8):
    acc, _rng = g.base(4.0, 10.0, 2, seed, n_density=1.32e-3)
    i = int(0.3 * acc.shape[0])
    acc[i:, 0] += size
    return g.pack(acc, 10.0), {"x": {"bias_step": size, "step_t_s": i / 10.0}, "N": 1.32e-3}


def _step_in_gap(seed: int):
    arrays, truth = g.coupling_step(hours=4.0, seed=seed, lag_s=120.0, at_frac=0.5)
    t = arrays["temperature_c"]
    n = t.shape[0]
    t[n // 2 - 7500: n // 2 + 7500] = float("nan")   # a 25-minute dropout around the step
    truth["dropout_s"] = [(n // 2 - 7500) / 10.0, (n // 2 + 7500) / 10.0]
    return arrays, truth


def builders():
    b = {}
    for s in (3, 4):
        b[f"coupling_step30_{s}"] = lambda s=s: g.coupling_step(hours=2.0, seed=s, lag_s=120.0)
        b[f"coupling_step70_{s}"] = lambda s=s: g.coupling_step(hours=2.0, seed=s, lag_s=120.0,
                                                                at_frac=0.7)
    b["linstep_1"] = lambda: g.coupling_step(hours=4.0, seed=1, room_amp=1.5)
    for s in (1, 2, 3):
        b[f"gm_sine_{s}"] = lambda s=s: g.gm_plus_slow_sine(seed=s, sigma=1.7e-4, t_s=30.0,
                                                            amp=1.5e-4)
        b[f"gm_only_{s}"] = lambda s=s: g.gm_plus_slow_sine(seed=s, sigma=1.7e-4, t_s=30.0,
                                                            amp=0.0)
    b["sine_only_1"] = lambda: g.gm_plus_slow_sine(seed=1, sigma=0.0, amp=1e-4)
    for s in range(1, 7):
        b[f"relay_{s}"] = lambda s=s: g.relay_step_at_switch(seed=s, step=0.0)
    for s in (1, 2):
        b[f"relay_step_{s}"] = lambda s=s: g.relay_step_at_switch(seed=s)
        b[f"remount_warm_{s}"] = lambda s=s: g.remount_warmup(seed=s)
        b[f"neg05_{s}"] = lambda s=s: g.negative_lag_coarse(seed=s)
    for k in ("interleaved", "units", "clockstep"):
        b[f"faulty_{k}_1"] = lambda k=k: g.faulty_log(k, seed=1)
    for s in (7, 8, 9, 10):
        b[f"gm_step4_{s}"] = lambda s=s: g.gm_step(seed=s)
    for size in (8e-4, 1.6e-3):
        b[f"gm_step_{size:g}_8"] = lambda size=size: g.gm_step(seed=8, step=size)
        b[f"white_step_{size:g}_8"] = lambda size=size: _white_step(size)
    for s in (41, 42):
        b[f"step_in_gap_{s}"] = lambda s=s: _step_in_gap(s)
    b["faulty_late_start_warm_1"] = lambda: g.faulty_log("late_start_warm", hours=3.0, seed=1)
    return b


def main() -> None:
    out = Path(sys.argv[1])
    out.mkdir(parents=True, exist_ok=True)
    b = builders()
    env = dict(os.environ, OMP_NUM_THREADS="1")
    for name in sys.argv[2:] or list(b):
        arrays, truth = b[name]()
        path = g.save(out / f"{name}.npz", arrays, truth)
        p = subprocess.run([AVARD, "explain", str(path), "--json", "--channels", "ch0"],
                           capture_output=True, text=True, env=env, timeout=600)
        print(f"=== {name}  rc={p.returncode}  truth x: {json.dumps(truth.get('x'))}")
        if p.returncode:
            print("   ", p.stderr.strip().splitlines()[-1][:300])
            continue
        d = json.loads(p.stdout)
        ch = d["channels"]["ch0"]
        print("   ", ch["verdict"]["line"][:220])
        for f in ch["findings"]:
            if f["claimed"]:
                iv = {k: [round(v[0], 9), round(v[1], 9)] for k, v in f["intervals"].items()}
                print(f"    CLAIMED {f['cause']}: {json.dumps(f['params'])[:200]} {iv}")
        k = ch["extended"]["terms"]["rate_random_walk"]
        print(f"    extended K: present={k['present']} {k['value']} [{k['lo']}, {k['hi']}]"
              f"  holdout_gain={d['holdout_gain']}")


if __name__ == "__main__":
    main()

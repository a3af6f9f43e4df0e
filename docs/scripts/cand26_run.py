"""Explain adversary dT/dt records with r at a multiple of the separation minimum (cand26).

The adversary's generator sets r = 3·5σ_a/(ωa) (the stated minimum against zero); here r is
rescaled, per record, to ``mult`` × the smallest r a fit tells from every one-lag reading
(``cand26_minimum.r_min_sep`` on the HVAC triangle's odd harmonics at the die, the
compressor's square wave's where the record has one), c kept at the generator's 3×. Each
record is written, explained (``avard explain --json``, one thread, nice) and scored as
``tests.support.adversary_run`` does (its JSON lines; ``table`` reads them).

    python docs/scripts/cand26_run.py OUT.jsonl MULT SEED0 SEED1
"""

from __future__ import annotations

import json
import math
import os
import resource
import subprocess
import sys
import tempfile
import types
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from cand26_minimum import r_min_sep, triangle_lines

from tests.support import adversary_gen as gen


def square_lines(period: float, amp: float, duty: float = 0.4, k_max: int = 15,
                 tau_plate: float = 1100.0, tau_die: float = 45.0):
    """The compressor's square wave (``gen.square``: +amp for ``duty``, −amp·duty/(1−duty)
    after) as its harmonics at the die: (amplitude K, ω)."""
    x = np.linspace(0, 1, 1 << 12, endpoint=False)
    s = np.where(x < duty, amp, -amp * duty / (1 - duty))
    co = 2 * np.abs(np.fft.rfft(s)) / len(x)
    out = []
    for k in range(1, k_max + 1):
        w = 2 * math.pi * k / period
        out.append((float(co[k]) / (math.hypot(1, w * tau_plate) * math.hypot(1, w * tau_die)),
                    w))
    return out


def drive(seed: int):
    rng0 = np.random.default_rng([seed, gen.KINDS.index("dtdt"), 7919])
    rng0.choice([8.0, 10.0, 12.5])
    P, A = float(rng0.uniform(1300, 2300)), float(rng0.uniform(0.5, 0.9))
    lines = triangle_lines({}, P, A)
    if rng0.uniform() < 0.5:
        lines += square_lines(float(rng0.uniform(600, 1100)), 0.25)
    return lines


def record(seed: int, mult: float, path: Path) -> dict:
    lines = drive(seed)
    T = 4 * 3600.0
    sig = [math.sqrt(2 * gen.psd(w / (2 * math.pi), *gen.DEFAULT_NOISE["x"]) / T)
           for _, w in lines]
    with tempfile.TemporaryDirectory() as d:
        t0 = gen.make_record("dtdt", seed, Path(d) / "a.npz", logged=("plate",))
    x = t0["axes"]["x"]
    c, r0 = x["coefficient_mps2_per_k"], x["r_mps2_per_k_per_s"]
    lead = r0 / c > 0
    rm = r_min_sep(lines, sig, c, lead=lead)
    scale = mult * rm / r0
    real = gen.np
    proxy = types.SimpleNamespace(**{k: getattr(real, k) for k in dir(real)
                                     if not k.startswith("__")})
    proxy.gradient = lambda *a, **k: scale * real.gradient(*a, **k)
    gen.np = proxy
    try:
        truth = gen.make_record("dtdt", seed, path, logged=("plate",))
    finally:
        gen.np = real
    truth["axes"]["x"]["r_mps2_per_k_per_s"] = r0 * scale
    truth["axes"]["x"]["r_min_sep"] = rm
    truth["kw"] = {"logged": ["plate"], "factor": round(3 * scale, 2)}
    return truth


def main(out: str, mult: float, s0: int, s1: int) -> None:
    avard = str(Path(sys.executable).with_name("avard"))
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    with open(out, "a") as fo, tempfile.TemporaryDirectory() as tmp:
        for seed in range(s0, s1 + 1):
            p = Path(tmp) / f"dtdt_{seed}.npz"
            truth = record(seed, mult, p)
            r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
            pr = subprocess.run(["nice", "timeout", "900", avard, "explain", str(p), "--json"],
                                capture_output=True, text=True, env=env, check=False)
            r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
            rec = {"kind": "dtdt", "seed": seed, "truth": truth, "rc": pr.returncode,
                   "cpu": r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime,
                   "stderr": pr.stderr[-2000:]}
            if pr.returncode == 0:
                d = json.loads(pr.stdout)
                rec["axes"] = {a: {"findings": c["findings"], "thermal": c["thermal"],
                                   "verdict": c["verdict"], "terms": c["extended"].get("terms")}
                               for a, c in d["channels"].items()}
            fo.write(json.dumps(rec, default=float) + "\n")
            fo.flush()
            print(seed, pr.returncode, truth["kw"]["factor"], flush=True)


if __name__ == "__main__":
    main(sys.argv[1], float(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]))

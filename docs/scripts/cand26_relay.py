"""Why the relay predicts the adversary's hysteresis records' held-out halves no better than
one lag (cand26): explain one record three ways and print the path choice's scores.

- ``code``: as explain runs;
- ``die``: every relay column built from the true die temperature (no 0.0625 K readings,
  no reconstruction), through the candidate's own lag and width grid;
- ``exact``: every relay column the generator's own hysteresis (its play operator on the
  true die at its width), so the relay's shape and switch times are the truth's.

    python docs/scripts/cand26_relay.py SEED0 SEED1 [MODE ...]   # FACTOR=6 to scale c and h
"""

from __future__ import annotations

import math
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
import avard.core.explain.thermal_paths as tp
from avard.core.explain.engine import explain_file
from avard.core.explain.thermal_fit import lag_filter
from avard.core.explain.thermal_paths import choose as choose_mod
from avard.core.explain.thermal_paths.columns import _relay
from avard.core.io.source import open_record
from cand26_separation import caught

from tests.support import adversary_gen as gen

FACTOR = float(os.environ.get("FACTOR", "3"))


def run(seed: int, mode: str, kind: str = "hysteresis") -> list[str]:
    truth, temps = caught(kind, seed, FACTOR, logged=("plate",))
    ts, die = temps["ts"], temps["die"]
    x = truth["axes"]["x"]
    orig_cols = choose_mod.path_columns
    exact = gen.play(die, x["width_k"]) if "width_k" in x else None

    def cols(T, cs, rate_hz, done=None):
        out = orig_cols(T, cs, rate_hz, done)
        if mode == "code":
            return out
        tj = (np.arange(len(T)) + 0.5) / rate_hz
        d = np.interp(tj, ts, die)
        for i, c in enumerate(cs):
            if c.kind != "relay":
                continue
            if mode == "die":
                v = _relay(lag_filter(d, c.lag, rate_hz), c.width)
            else:
                v = np.interp(tj, ts, exact)
            out[:, i] = v - v.mean()
        return out

    calls: list = []
    orig_choose = tp.choose_path

    def spy(*a, **k):
        pf = orig_choose(*a, **k)
        calls.append((k.get("held_only"), len(k.get("given") or ()), pf))
        return pf

    choose_mod.path_columns = cols
    tp.choose_path = spy
    try:
        with tempfile.TemporaryDirectory() as dd:
            p = Path(dd) / "r.npz"
            truth = gen.make_record(kind, seed, p, logged=("plate",), factor=FACTOR)
            ex = explain_file(open_record(str(p)))
    finally:
        choose_mod.path_columns = orig_cols
        tp.choose_path = orig_choose
    d = ex.to_dict()["channels"]["x"]
    claims = [f for f in d["findings"] if f["claimed"]]
    mech = [f.get("mechanism") for f in claims if f["cause"] == "temperature"]
    lines = [f"{kind} {seed} {mode}: x → {mech or '—'} "
             f"{[f['cause'] for f in claims if f['cause'] != 'temperature']}"]
    for held_only, n_given, pf in calls:
        h = pf.scores.get("hysteresis")
        if h is None:
            continue
        lines.append(f"   held_only={held_only} given {n_given} chosen {pf.kind}: "
                     f"hyst matched {h.matched:+.1f} "
                     f"z {h.z_extra:.2f} (thr {pf.z_threshold:.2f}) "
                     f"θ {tuple(round(v, 3) for v in h.theta)} "
                     f"h {h.beta[1]:.3g} (truth {x.get('h_mps2', math.nan):.3g}, "
                     f"w {2 * x.get('width_k', math.nan):.3f}) open {h.open_end} "
                     f"none−one {pf.none_heldout - pf.scores['one_lag'].heldout:+.1f}")
    return lines


if __name__ == "__main__":
    s0, s1 = int(sys.argv[1]), int(sys.argv[2])
    modes = sys.argv[3:] or ["code", "die", "exact"]
    for sd in range(s0, s1 + 1):
        for m in modes:
            print("\n".join(run(sd, m)), flush=True)

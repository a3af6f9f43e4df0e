"""Would the dT/dt term beat two paths held out with its column built on the temperature
behind the readings (cand26 prototype, not in explain)? Explains adversary dT/dt records
(the generator as committed: r at 3× the minimum against one lag) two ways:

- ``code``: the "rate" column the derivative of the readings smoothed forward and back
  through 30 s (``path_columns``);
- ``behind``: the same smoothing of the crossing reconstruction T̂ (``crossing_reconstruction``,
  as the relay and the quadratic columns are built), so the 0.0625 K staircase's derivative
  is not in the regressor.

    python docs/scripts/cand26_ratecol.py SEED [SEED ...]
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from avard.core.explain.engine import explain_file
from avard.core.explain.thermal_fit import lag_filter
from avard.core.explain.thermal_paths import choose as choose_mod
from avard.core.explain.thermal_paths.columns import crossing_reconstruction
from avard.core.explain.thermal_paths.settings import RATE_SMOOTH_S
from avard.core.io.source import open_record

from tests.support import adversary_gen as gen


def run(seed: int, mode: str) -> str:
    orig = choose_mod.path_columns

    def cols(T, cs, rate_hz, done=None):
        out = orig(T, cs, rate_hz, done)
        if mode == "code":
            return out
        for i, c in enumerate(cs):
            if c.kind != "rate":
                continue
            u = lag_filter(crossing_reconstruction(T), c.lag, rate_hz)
            x = (u - lag_filter(u, RATE_SMOOTH_S, rate_hz)) / RATE_SMOOTH_S
            x = lag_filter(x[::-1], RATE_SMOOTH_S, rate_hz)[::-1]
            out[:, i] = x - x.mean()
        return out

    choose_mod.path_columns = cols
    try:
        with tempfile.TemporaryDirectory() as d:
            p = Path(d) / "r.npz"
            truth = gen.make_record("dtdt", seed, p, logged=("plate",))
            ex = explain_file(open_record(str(p))).to_dict()["channels"]["x"]
    finally:
        choose_mod.path_columns = orig
    tc = [f for f in ex["findings"] if f["claimed"] and f["cause"] == "temperature"]
    path = (ex["thermal"] or {}).get("path") or {}
    m = path.get("heldout_matched_minus_one_lag", {})
    c = truth["axes"]["x"]["coefficient_mps2_per_k"]
    return (f"dtdt {seed} {mode} c{'+' if c > 0 else '-'}: "
            f"{tc[0].get('mechanism') if tc else '—'} | "
            + " ".join(f"{k} {v:+.1f}" for k, v in m.items() if k != "one_lag"))


if __name__ == "__main__":
    for s in sys.argv[1:]:
        for mode in ("code", "behind"):
            print(run(int(s), mode), flush=True)

"""How far the adversary's dT/dt truth is from every one-lag reading (cand26, issue 23 item 4).

For a record of ``tests/support/adversary_gen`` (its noise-free die temperature, caught as the
generator computes it), the non-centrality of the hidden signal c·T + r·dT/dt against

- zero for r (c known): λ₀ = what the stated minimum r_min = 5σ_a/(ωa) is built on (z² = 25 at 1×);
- the closest one-lag reading c'·lag(T, L') (L' of either sign, a negative one the project's
  lead-lag 2T − lag(T, |L'|)), c' free: λ_sep, what a choice between one lag and dT/dt can rest on.

Both in the frequency domain on the axis's noise PSD (λ = Σ_k 2|D_k|²/(T·S(f_k)), D the
difference's DFT (Hann window, its power restored), f_k ≥ 1/T); the estimator's AVAR view
and its held-out halves are not modelled, so read the numbers as the record's content, not
the code's score.

    python docs/scripts/cand26_separation.py dtdt 400 419 [factor [shortest period s]]

The shortest period counted (default none): what explain's fit sees, whose octave τ start at
the channel's rounding floor (``choose_path``'s ``min_tau``), reaches periods of about 2τ.
"""

from __future__ import annotations

import math
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from tests.support import adversary_gen as gen


def caught(kind: str, seed: int, factor: float = 3.0, **kw):
    """(truth, die temperature on the generator's 1 s grid) of one record."""
    box: dict = {}
    orig = gen._die_swing

    def spy(temps):
        box["temps"] = temps
        return orig(temps)

    gen._die_swing = spy
    try:
        with tempfile.TemporaryDirectory() as d:
            truth = gen.make_record(kind, seed, Path(d) / "r.npz", factor=factor, **kw)
    finally:
        gen._die_swing = orig
    return truth, box["temps"]


def lag1(x: np.ndarray, L: float) -> np.ndarray:
    """The project's one-lag column on a 1 s grid: lag(x, L), or 2x − lag(x, |L|) for L < 0."""
    if L == 0:
        return x.copy()
    a = math.exp(-1.0 / abs(L))
    y = np.empty_like(x)
    p = x[0]
    for i, v in enumerate(x.tolist()):
        p = a * p + (1 - a) * v
        y[i] = p
    return y if L > 0 else 2 * x - y


def weights(n: int, nbk) -> tuple[np.ndarray, np.ndarray]:
    f = np.fft.rfftfreq(n, 1.0)
    s = np.array([gen.psd(max(fk, 1e-9), *nbk) for fk in f])
    return f, s


#: the highest frequency counted (Hz): ``CAP_PERIOD_S`` below, inf for the whole spectrum
F_CAP = math.inf


def lam(d: np.ndarray, f: np.ndarray, s: np.ndarray) -> float:
    n = len(d)
    w = np.hanning(n)
    D = np.fft.rfft((d - d.mean()) * w) / math.sqrt(np.mean(w * w))
    ok = (f >= 1.0 / n) & (f <= F_CAP)
    return float(np.sum(2 * np.abs(D[ok]) ** 2 / (n * s[ok])))


def separation(kind: str, seed: int, factor: float = 3.0, **kw) -> dict:
    truth, temps = caught(kind, seed, factor, **kw)
    die = temps["die"] - temps["die"].mean()
    x = truth["axes"]["x"]
    c, r = x["coefficient_mps2_per_k"], x.get("r_mps2_per_k_per_s", 0.0)
    if kind == "hysteresis":
        extra = x["h_mps2"] * gen.play(temps["die"], x["width_k"])
    else:
        extra = r * np.gradient(die)
    sig = c * die + extra
    f, s = weights(len(die), gen.DEFAULT_NOISE["x"])
    lam0 = lam(extra, f, s)
    best = (math.inf, 0.0, 0.0)
    # L' on a fine grid both ways; c' by least squares in the same metric
    n = len(die)
    w = np.hanning(n)
    ok = (f >= 1.0 / n) & (f <= F_CAP)
    Sg = np.fft.rfft((sig - sig.mean()) * w)[ok]
    for L in np.concatenate([-np.geomspace(5, 3600, 60)[::-1], [0.0], np.geomspace(5, 3600, 60)]):
        u = lag1(die, float(L))
        U = np.fft.rfft((u - u.mean()) * w)[ok]
        wt = 1.0 / s[ok]
        cp = float(np.real(np.sum(wt * Sg * U.conj())) / np.sum(wt * np.abs(U) ** 2))
        lm = lam(sig - cp * u, f, s)
        if lm < best[0]:
            best = (lm, float(L), cp)
    return {"kind": kind, "seed": seed, "factor": factor, "c": c, "r": r,
            "r_over_c_s": r / c if c else math.nan, "hvac_s": None,
            "lam0": lam0, "lam_sep": best[0], "L_best": best[1], "c_best": best[2],
            "die_amp": truth.get("die_amplitude_k")}


if __name__ == "__main__":
    kind, s0, s1 = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    factor = float(sys.argv[4]) if len(sys.argv) > 4 else 3.0
    if len(sys.argv) > 5:
        F_CAP = 1.0 / float(sys.argv[5])
    for sd in range(s0, s1 + 1):
        o = separation(kind, sd, factor, logged=("plate",))
        print(f"{kind} {sd} ×{factor:g}: c {o['c']:+.3g} r {o['r']:.3g} "
              f"r/c {o['r_over_c_s']:+.0f} s "
              f"λ0 {o['lam0']:.0f} λ_sep {o['lam_sep']:.1f} at L' {o['L_best']:+.0f} s "
              f"c' {o['c_best']:+.3g}", flush=True)

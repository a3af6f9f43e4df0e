"""The dT/dt term's stated minimum against one lag, on drive lines (cand26 prototype).

λ(r) = min over one-lag readings (c', L' of either sign) of Σ_lines (a/σ_a(f))²·|c + jωr −
c'·H(ω, L')|², H = 1/(1 + jωL') for L' ≥ 0 and the lead-lag (1 + 2jωa)/(1 + jωa), a = −L',
for L' < 0 (``thermal_fit.lag_filter``); r_min: the smallest |r| with λ = z² (z = 5), the
sign of r/c given. Compared here with the full-record λ_sep of ``cand26_separation``.

    python docs/scripts/cand26_minimum.py dtdt 400 419
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from tests.support import adversary_gen as gen


def H(w: np.ndarray, L: float) -> np.ndarray:
    if L >= 0:
        return 1.0 / (1 + 1j * w * L)
    a = -L
    return (1 + 2j * w * a) / (1 + 1j * w * a)


def separation(lines, sig, c: float, r: float) -> tuple[float, float, float]:
    """(λ, L', c') of the closest one-lag reading of c·T + r·dT/dt on ``lines`` ((a, ω))."""
    a = np.array([x[0] for x in lines])
    w = np.array([x[1] for x in lines])
    q = (a / np.array(sig)) ** 2
    G = c + 1j * w * r
    best = (math.inf, 0.0, 0.0)
    grid = np.concatenate([-np.geomspace(1, 1e5, 400)[::-1], [0.0], np.geomspace(1, 1e5, 400)])
    for L in grid:
        h = H(w, float(L))
        cp = float(np.sum(q * np.real(G * h.conj())) / np.sum(q * np.abs(h) ** 2))
        lm = float(np.sum(q * np.abs(G - cp * h) ** 2))
        if lm < best[0]:
            best = (lm, float(L), cp)
    return best


def triangle_lines(truth: dict, spec_period: float, room_amp: float, tau_plate=1100.0,
                   tau_die=45.0, k_max: int = 15):
    out = []
    for k in range(1, k_max + 1, 2):
        w = 2 * math.pi * k / spec_period
        ak = 8 * room_amp / (math.pi**2 * k * k)
        ak /= math.hypot(1, w * tau_plate) * math.hypot(1, w * tau_die)
        out.append((ak, w))
    return out


if __name__ == "__main__":
    from cand26_separation import caught

    kind, s0, s1 = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    for sd in range(s0, s1 + 1):
        truth, temps = caught(kind, sd, 3.0, logged=("plate",))
        rng0 = np.random.default_rng([sd, gen.KINDS.index(kind), 7919])
        rng0.choice([8.0, 10.0, 12.5])
        P, A = float(rng0.uniform(1300, 2300)), float(rng0.uniform(0.5, 0.9))
        comp = rng0.uniform() < 0.5
        lines = triangle_lines(truth, P, A)
        T = 4 * 3600.0
        sig = [math.sqrt(2 * gen.psd(w / (2 * math.pi), *gen.DEFAULT_NOISE["x"]) / T)
               for _, w in lines]
        x = truth["axes"]["x"]
        c, r = x["coefficient_mps2_per_k"], x["r_mps2_per_k_per_s"]
        lm, L, cp = separation(lines, sig, c, r)
        lm1, _, _ = separation(lines[:1], sig[:1], c, r)
        print(f"{sd}: P {P:.0f} comp {comp} c {c:+.3g} r/c {r / c:+.0f}: lines λ {lm:.1f} "
              f"(fundamental only {lm1:.1f}) at L' {L:+.0f} die a {truth['die_amplitude_k']:.3f}"
              f" vs line-1 {lines[0][0]:.3f}", flush=True)


def r_min_sep(lines, sig, c: float, lead: bool, z: float = 5.0) -> float:
    """The smallest |r| whose λ against every one-lag reading reaches z² (inf if none ≤ 1e6·
    the against-zero minimum)."""
    q0 = sum((a * w / s) ** 2 for (a, w), s in zip(lines, sig, strict=True))
    r0 = z / math.sqrt(q0)  # the against-zero minimum on these lines
    sgn = 1.0 if (lead == (c > 0)) else -1.0
    lo, hi = r0, r0
    while separation(lines, sig, c, sgn * hi)[0] < z * z:
        lo, hi = hi, hi * 2
        if hi > 1e6 * r0:
            return math.inf
    for _ in range(40):
        mid = math.sqrt(lo * hi)
        if separation(lines, sig, c, sgn * mid)[0] < z * z:
            lo = mid
        else:
            hi = mid
    return hi

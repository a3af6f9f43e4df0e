"""The stated minima of dT/dt and hysteresis against one lag, on the benchmark's record, three
ways: the whole spectrum (cand26's), and as explain's fit sees it (τ from the rounding floor
up, ``thermal_paths.minima.*_fit``). Usage: .venv/bin/python docs/scripts/cand26b_numbers.py"""

import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from avard.core.explain.thermal_paths import min_detectable_path
from avard.core.explain.thermal_paths import minima as mm

from benchmarks import bench_explain_weekend as bw

N, B, K, rec = bw.N, bw.B, bw.K, bw.HOURS * 3600
base, A, c = bw._path_base()
w = 2 * math.pi / bw.PERIOD
hvac = ((A, bw.PERIOD),)
floor = mm.rounding_floor(hvac, bw.RATE, rec)
c2tc = c * c * mm._Q_STEP**2 / 12 * mm.rounding_time(hvac)
print(f"die swing {A:.4g} K, c {c:.4g}, floor {floor:.4g} s, t_c {mm.rounding_time(hvac):.4g} s")
r_zero = min_detectable_path("rate", N, B, K, rec, A, bw.PERIOD, 0.0, 870.0, lags_known=True)
r_all = mm.min_detectable_rate(N, B, K, rec, hvac, c, lead=True)
r_fit = mm.min_detectable_rate_fit(N, B, K, rec, hvac, c, True, floor, c2tc)
print(f"HVAC dT/dt lead: zero {r_zero:.4g}  whole {r_all:.4g}  fit {r_fit:.4g}")
comp = tuple((a / math.hypot(1.0, 2 * math.pi / p * bw.PLATE_TAU)
              / math.hypot(1.0, 2 * math.pi / p * 30.0), p)
             for a, p in bw.compressor_harmonics())
lines = hvac + comp
floor_c = mm.rounding_floor(lines, bw.RATE, rec)
c2tc_c = c * c * mm._Q_STEP**2 / 12 * mm.rounding_time(lines)
for lead in (True, False):
    ra = mm.min_detectable_rate(N, B, K, rec, lines, c, lead=lead)
    rf = mm.min_detectable_rate_fit(N, B, K, rec, lines, c, lead, floor_c, c2tc_c)
    print(f"compressor dT/dt lead={lead}: floor {floor_c:.4g} whole {ra:.4g} fit {rf:.4g}")
h_old = min_detectable_path("hysteresis", N, B, K, rec, A, bw.PERIOD, 0.0, 870.0)
U = np.array([A + 0j])
for sgn in (1, -1):
    hf = mm.min_detectable_hysteresis_fit(N, B, K, rec, bw.PERIOD, U, sgn * c, 0.05, floor, c2tc)
    print(f"hysteresis c sign {sgn}: stated today {h_old:.4g}  fit {hf:.4g}")
# the whole spectrum with the same separation (weights (1/σ_a)², every harmonic)
per = bw.PERIOD / np.arange(1, 40)
sig2 = np.array([2 * mm.noise_psd(1 / p, N, B, K) / rec for p in per])
Wall = 1 / sig2
Uk = np.zeros(39, complex)
Uk[0] = A
R = mm.relay_harmonics(Uk, 0.05)
for sgn in (1, -1):
    def lam(h: float, s: int = sgn) -> float:
        return mm.one_lag_separation_fit(per, Uk, s * c * Uk + h * R, Wall)[0]
    hw = mm._bisect_size(lam, 1e-6, 5)
    print(f"hysteresis whole spectrum vs one lag, c sign {sgn}: {hw:.4g}")
Wf = mm.fit_weights(N, B, K, rec, per, floor, c2tc)
print("W/(1/σ²) by harmonic 1,3,5,7,9:", [f"{Wf[k]/Wall[k]:.3g}" for k in (0, 2, 4, 6, 8)])
# the deviance (the fit's own, model-based) at each minimum, and the same λ on W ∝ 1/σ²
print("deviance ΔD at the fit minimum (hysteresis c>0, h_fit):")
hf = mm.min_detectable_hysteresis_fit(N, B, K, rec, bw.PERIOD, U, c, 0.05, floor, c2tc)
s2 = mm._sig2(N, B, K, rec, per)
for fac in (1, 3):
    lz = mm.one_lag_separation_fit(per, Uk, c * Uk + fac * hf * R, Wf, s2)
    ld = mm.one_lag_separation_fit(per, Uk, c * Uk + fac * hf * R, Wf)
    print(f"  {fac}×: λ_z {lz[0]:.3g}  ΔD {ld[0]:.3g}  L' {lz[1]:.3g}")

"""A deterministic drift tested in the time domain against the random walk that can make the same
wander (``test_drift``), by the one test analyze uses too."""

from __future__ import annotations

import math

import numpy as np
from avard.core.analysis.drift import DRIFT_BLOCKS, drift_likelihood
from avard.core.explain import alarm
from avard.core.explain import causes as cz
from avard.core.explain.transients.scan import NoiseOf, _column, signal_of
from avard.core.model.triangular import LowerSolver
from numpy.typing import NDArray

# --------------------------------------------------------------------------------------------
# drift against a random walk


def _slope_fit(yb: NDArray, t: NDArray, dt: float, noise: dict[str, float],
               cols: list[NDArray]) -> tuple[float, float]:
    """(slope, its standard error) of block means ``yb`` on ``cols`` + the centred time by
    GLS with the noise N, B, K of ``noise``, the error scaled by √(Birge ratio) when the
    whitened residual's χ²/dof exceeds 1 (a noise model the data do not follow widens it)."""
    c = cz._noise_cov(t, dt, noise.get("N", 0.0), noise.get("B", 0.0), noise.get("K", 0.0),
                      noise.get("GM_sigma", 0.0), noise.get("GM_T", 0.0))
    L = LowerSolver(np.linalg.cholesky(c))
    a = L.solve(np.column_stack([*cols, t - t.mean()]))
    wy = L.solve(yb)
    coef, *_ = np.linalg.lstsq(a, wy, rcond=None)
    r = wy - a @ coef
    s2 = max(1.0, float(r @ r) / max(1, len(r) - a.shape[1]))
    return float(coef[-1]), math.sqrt(float(np.linalg.pinv(a.T @ a)[-1, -1]) * s2)


def test_drift(y: NDArray, rate_hz: float, noise: dict[str, float],
               transients: list[cz.Candidate], alpha: float = alarm.DRIFT,
               noise_of: NoiseOf | None = None) -> cz.Candidate:
    """A deterministic drift (``params``: ``rate`` in m/s² per s) against a random walk, by
    the time-domain likelihood ratio with K profiled (module doc); ``transients`` found on
    the axis are fitted beside it. Passed when the ratio exceeds χ²(1)'s quantile at
    ``alpha`` and the slope's interval at that z excludes zero.

    The rate and its 68 % interval come from the GLS fit with the noise ``noise_of`` gives
    for the axis with the transients and the drift removed (given; else ``noise``): the K
    the likelihood picks beside a fitted slope is the one the slope leaves least of, at the
    boundary K = 0 on a quarter of the benchmark's drift records, and the slope's standard
    error at that K held the true rate on half of them. A drift fitted into the noise (the
    axis's AVAR read the ramp as K and B) is the same circularity as a step's (module doc):
    its interval is drawn on the noise with it removed."""
    b = max(1, len(y) // DRIFT_BLOCKS)
    yb = cz.block_means(y, b)
    dt = b / rate_hz
    t = (np.arange(len(yb)) + 0.5) * dt
    z_thr = alarm.bonferroni_z(alpha, 1)
    n_w = noise.get("N", 0.0)
    if not (noise.get("K", 0.0) > 0 or n_w > 0):
        return cz.Candidate("drift", False, evidence="drift test: no noise level to test "
                            "against (N and K are zero)")
    base = [_column(c.cause, c.params, t, dt) for c in transients]
    try:
        # analyze's test (analysis/drift.py): K profiled past the noise's own K
        lik = drift_likelihood(yb, t, dt, n_w, noise.get("B", 0.0), noise.get("K", 0.0), base)
    except np.linalg.LinAlgError:
        return cz.Candidate("drift", False, evidence="drift test: the noise covariance would "
                            "not factor")
    z, slope = abs(lik.z), lik.slope
    if noise_of is not None:
        ramp = slope * ((np.arange(len(y)) + 0.5) / rate_hz - 0.5 * len(y) / rate_hz)
        noise = noise_of(signal_of(transients, len(y), rate_hz) + ramp)
    try:
        slope, se = _slope_fit(yb, t, dt, noise, [np.ones_like(t), *base])
    except np.linalg.LinAlgError:
        se = lik.slope_se
    k_hat0, k_hat1 = lik.k_walk, lik.k_drift
    passed = lik.passes(z_thr) and abs(slope) >= z_thr * se
    edge = " (K at the top of its grid)" if lik.at_edge else ""
    if lik.step_like:
        edge += "; one line per half fits better (a step, not a drift)"
    ev = (f"time-domain likelihood ratio of a drift against a random walk, K profiled: "
          f"√Δ(−2 ln L) = {z:.3g} (test: ≥ {z_thr:.3g}, χ²(1) at {alpha:g}); the walk alone "
          f"wants K {k_hat0:.3g}, with the drift K {k_hat1:.3g} m/s²·√s{edge}; drift "
          f"{slope:.3g} ± {se:.2g} m/s³ (68 %, GLS on the noise N {noise.get('N', 0.0):.3g}, "
          f"B {noise.get('B', 0.0):.3g}, K {noise.get('K', 0.0):.3g} of the axis "
          f"{'with the drift removed' if noise_of is not None else 'as given'})")
    return cz.Candidate("drift", passed, {"rate": slope},
                        z, z_thr, ev, intervals={"rate": [slope - se, slope + se]})

"""The 68 % profile over θ on the grid: the jackknife, the profile's Δ, a grid cell's
neighbours, the likelihood-weighted average, an open end."""

from __future__ import annotations

import math

import numpy as np
from avard.core.explain.thermal_paths.columns import Trial
from avard.core.explain.thermal_paths.settings import PROFILE_DELTA
from numpy.typing import NDArray


def _jk_se(est: NDArray) -> NDArray[np.float64]:
    """The delete-a-part jackknife standard error of each column of ``est`` (G, p):
    √((G − 1)/G·Σ(x_(−g) − mean)²)."""
    G = len(est)
    return np.asarray(np.sqrt((G - 1) / G * np.sum((est - est.mean(axis=0)) ** 2, axis=0)),
                      dtype=float)


def profile_delta(dev: float, nu: NDArray, n_params: int, two_sided: bool = False) -> float:
    """The Δ(−2 ln L) of a 68 % profile interval on one parameter for a best fit of deviance
    ``dev`` on differences ``nu`` (ν_k per τ) with ``n_params`` fitted: ``PROFILE_DELTA``
    times the Birge factor dev/dof where it exceeds 1 (the residual scatters more than the
    weights say: the deviance's scale is that much too small), never less; ``two_sided``:
    times the Birge factor either way, the deviance put on its own scale. The weights are
    the one-lag residual, which on a record with a second path or a dT/dt term holds the
    signal one lag leaves: the best extension's deviance is then 0.1–0.3 of its dof, and
    Δ = 1 on that scale is a 3–7 unit step on the data's, a profile that reached grid
    points far along the two paths' ridge (two paths' intervals held the truth in 30 of
    34)."""
    dof = float(np.sum(nu)) - n_params
    birge = dev / dof if dof > 0 else math.inf
    return PROFILE_DELTA * (birge if two_sided else max(1.0, birge))


def _grid_cell(ts: list[Trial], i: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Per coordinate of θ, half way from trial ``i``'s grid value to its neighbours along
    that coordinate's grid (the value itself at the grid's ends)."""
    lo, hi = [], []
    for d, x in enumerate(ts[i].theta):
        vals = sorted({t.theta[d] for t in ts})
        k = vals.index(x)
        lo.append(0.5 * (vals[k - 1] + x) if k > 0 else x)
        hi.append(0.5 * (vals[k + 1] + x) if k + 1 < len(vals) else x)
    return np.array(lo), np.array(hi)


def _about(ts: list[Trial], i: int, d: int) -> list[int] | None:
    """The grid points on coordinate ``d``'s line through trial ``i`` (every other
    coordinate as ``i``'s) just below ``i``, ``i`` itself and just above, in θ_d's order;
    None where ``i`` is that line's end (a bound, no neighbour to interpolate with)."""
    line = sorted((t.theta[d], j) for j, t in enumerate(ts)
                  if all(t.theta[e] == ts[i].theta[e] for e in range(len(t.theta)) if e != d))
    k = [j for _x, j in line].index(i)
    if not 0 < k < len(line) - 1:
        return None
    return [j for _x, j in line[k - 1:k + 2]]


def _refined(ts: list[Trial], devs: NDArray, i: int) -> tuple[float, ...]:
    """θ of trial ``i`` refined coordinate-wise by a parabola in ln(θ) (θ > 0) through its
    grid neighbours along that coordinate (the others fixed)."""
    th = list(ts[i].theta)
    for d in range(len(th)):
        js = _about(ts, i, d)
        if js is not None and ts[js[0]].theta[d] > 0:
            x = np.log(np.array([ts[j].theta[d] for j in js]))
            f = np.array([float(devs[j]) for j in js])
            den = (x[0] - x[1]) * (x[0] - x[2]) * (x[1] - x[2])
            a = (x[2] * (f[1] - f[0]) + x[1] * (f[0] - f[2]) + x[0] * (f[2] - f[1])) / den
            b = (x[2] ** 2 * (f[0] - f[1]) + x[1] ** 2 * (f[2] - f[0])
                 + x[0] ** 2 * (f[1] - f[2])) / den
            if a > 0:
                th[d] = float(np.exp(np.clip(-b / (2 * a), x[0], x[2])))
    return tuple(th)


def _weights(devs: NDArray, delta: float) -> NDArray[np.float64]:
    """Each grid point's likelihood relative to the best, exp(−ΔD/2) with the deviance's
    scale ``delta`` (``profile_delta``: 1, or the Birge factor), normalised, over the
    points within ``delta`` of the best (the 68 % profile's, as the intervals' widening):
    over the whole grid the many points 2–3 σ off (ΔD 5–9, a tenth of the weight on the
    hysteresis row's seed 30000) carried sizes far from the ridge's (h 0.5× and −0.5×) into
    the average's spread, ±27 % on a size the records scatter by ±8 %."""
    dd = devs - devs.min()
    w = np.where(dd <= delta, np.exp(-dd / (2.0 * delta)), 0.0)
    return np.asarray(w / w.sum(), dtype=float)


def _averaged(fits: list[NDArray], devs: NDArray, n: int,
              delta: float) -> NDArray[np.float64]:
    """The first ``n`` coefficients averaged over the grid of θ, each grid point weighed by
    its likelihood (``_weights``): θ a nuisance integrated out on the grid, not chosen."""
    w = _weights(devs, delta)
    return np.asarray(np.einsum("j,ji->i", w, np.array([f[:n] for f in fits])), dtype=float)


def _averaged_theta(ts: list[Trial], devs: NDArray, delta: float) -> tuple[float, ...]:
    """θ averaged over its grid as ``_averaged`` (a width, > 0 on a geometric grid, in ln)."""
    w = _weights(devs, delta)
    th = np.array([t.theta for t in ts], dtype=float)
    out = []
    for d in range(th.shape[1]):
        x = th[:, d]
        out.append(float(np.exp(w @ np.log(x))) if np.all(x > 0) else float(w @ x))
    return tuple(out)


def _at_end(ts: list[Trial], i: int, leads: bool = False) -> bool:
    """θ of trial ``i`` at the end of its grid: a lag at the longest lag tried (``leads``:
    or at the longest lead, a search's edge too), a width (the hysteresis's) at its widest.
    The shortest lag, 0 or the one-lag fit's own, is a value, not a search's edge, and so
    is the narrowest width (``WIDTHS_K[0]``, a fifth of the readings' 0.0625 K step): a
    relay narrower than the temperature behind the readings resolves is an ideal one (it
    switches on the last move's sign), and the switch time a narrower relay would move is
    the lag's, which trades with the width along a ridge and has grid on both sides of the
    best point. Read as an edge it kept the relay from records whose best point sat there
    with its lag inside its grid: a relay against a coupling of the other sign (the
    adversary's c < 0 records), where two paths or no coupling were claimed instead."""
    for d in range(len(ts[i].theta)):
        vals = sorted({t.theta[d] for t in ts})
        ends = (vals[0], vals[-1]) if leads and d == 0 and vals[0] < 0 else (vals[-1],)
        if len(vals) > 2 and ts[i].theta[d] in ends:
            return True
    return False

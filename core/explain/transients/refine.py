"""The found transients' times and T refined on a finer grid with their profiles' intervals
(``refine_compound``)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from avard.core.explain import causes as cz
from avard.core.explain.transients.scan import _NONLINEAR, _column, _gls
from numpy.typing import NDArray


def _grid_for(c: cz.Candidate, key: str, g: cz._Gls) -> NDArray[np.float64]:
    """The profile grid of one nonlinear parameter around its value."""
    record_s = len(g.t) * g.dt
    v = c.params[key]
    if key == "time_constant_s":
        # below the scan's shortest T (2 blocks) as well: its column is the block average,
        # and a warm-up of T 611 s on 60 h (422 s blocks) was held at 842 s, the grid's end
        return np.geomspace(max(v / 8, g.dt / 4), max(min(v * 8, record_s / 2), 4 * g.dt),
                            cz.T_GRID)
    lo, hi = 4 * g.dt, record_s - 4 * g.dt
    if c.cause == "excursion":  # the edges may not cross
        if key == "start_s":
            hi = c.params["end_s"] - g.dt
        else:
            lo = c.params["start_s"] + g.dt
    half = 6 * g.dt
    return np.linspace(max(v - half, lo), min(v + half, hi), 97)


#: Points of a change point's profile where its likelihood lives (``_time_profile``).
TIME_FINE = 129
#: The fewest of them the likelihood's bulk must span before the zoom stops.
TIME_SPAN = 24


def _time_profile(g: cz._Gls, c: cz.Candidate, key: str, others: list[NDArray],
                  grid: NDArray, chi: NDArray
                  ) -> tuple[NDArray, tuple[NDArray, NDArray, NDArray]]:
    """A change point's profile (χ², size, its variance) on a grid fine enough for its
    likelihood: zoomed onto where the likelihood on ``grid`` (``chi``) is not negligible,
    again while its bulk spans fewer than ``TIME_SPAN`` points. A step many block σ tall is
    located to a small fraction of a block: on the coarse grid (an eighth of a block, 21 s on
    24 h) its likelihood sat on one or two points, and the interval drawn from them was the
    grid's spacing, not the likelihood's width (a change point's time and size held the
    truth in about half the 68 % intervals on 24 h)."""
    for _zoom in range(3):
        w = np.exp(-(chi - chi.min()) / 2.0)
        live = np.flatnonzero(w > 1e-6)
        bulk = np.count_nonzero(w > 0.01)
        if bulk >= TIME_SPAN and len(grid) >= TIME_FINE:
            break
        a, b = max(int(live[0]) - 1, 0), min(int(live[-1]) + 1, len(grid) - 1)
        if not grid[b] > grid[a]:
            break
        grid = np.linspace(float(grid[a]), float(grid[b]), TIME_FINE)
        shapes = np.column_stack([_column(c.cause, {**c.params, key: float(v)}, g.t, g.dt)
                                  for v in grid])
        chi, size, var = g.profile(g.white(shapes), others)
    return grid, (chi, size, var)


def refine_compound(y: NDArray, rate_hz: float, noise: dict[str, float],
                    cands: list[cz.Candidate]) -> list[cz.Candidate]:
    """``cands`` fitted together by GLS with the noise ``noise``: parameters and 68 %
    intervals (module doc). On a covariance that will not factor they come back unchanged."""
    g = _gls(y, rate_hz, noise)
    if g is None or not cands:
        return cands
    cands = list(cands)
    prof: dict[tuple[int, str], tuple[NDArray, NDArray, NDArray, NDArray]] = {}
    for _round in range(2):
        for i, c in enumerate(cands):
            others = [g.white(_column(o.cause, o.params, g.t, g.dt))
                      for j, o in enumerate(cands) if j != i]
            for key in _NONLINEAR[c.cause]:
                grid = _grid_for(c, key, g)
                shapes = np.column_stack([_column(c.cause, {**c.params, key: float(v)},
                                                  g.t, g.dt) for v in grid])
                chi, size, var = g.profile(g.white(shapes), others)
                if key == "time_constant_s":
                    best = cz._vertex(grid, chi)
                else:
                    grid, (chi, size, var) = _time_profile(g, c, key, others, grid, chi)
                    best = cz._weight_interval(grid, chi, 1.0)[1]
                cands[i] = c = replace(c, params={**c.params, key: float(best)})
                prof[(i, key)] = (grid, chi, size, var)
    cols = [g.white(_column(c.cause, c.params, g.t, g.dt)) for c in cands]
    chi, coef, cov = g.chi2(cols)
    n_par = 2 + sum(1 + len(_NONLINEAR[c.cause]) for c in cands)
    dof = max(1, len(g.yb) - n_par)
    s2 = max(1.0, chi / dof)
    out: list[cz.Candidate] = []
    together = f" ({len(cands)} effects fitted together)" if len(cands) > 1 else ""
    for i, c in enumerate(cands):
        iv: dict[str, list[float]] = {}
        # the size's variance with every shape held, and what each nonlinear parameter's
        # uncertainty adds to it: its profile envelope's half-width² less that (an
        # excursion's size moves with both edges; the envelope over one edge alone left the
        # other's share out, and its interval held the truth in 61 % of model-exact draws)
        held = float(cov[2 + i, 2 + i]) * s2
        spread = held
        for key in _NONLINEAR[c.cause]:
            grid, chi_p, sz, var = prof[(i, key)]
            if key == "time_constant_s":
                iv[key] = list(cz._profile_interval(grid, chi_p, s2))
            else:
                lo, _mid, hi = cz._weight_interval(grid, chi_p, s2)
                iv[key] = [lo, hi]
            lo, hi = cz._size_interval(chi_p, sz, var, s2)
            spread += max(0.0, (0.5 * (hi - lo)) ** 2 - held)
        size = float(coef[2 + i])
        # centred on the joint fit's size (the profile's is at the grid's best point)
        half = math.sqrt(spread)
        iv["size"] = [size - half, size + half]
        params = {**c.params, "size": size}
        text = "; ".join(f"{k} {params[k]:.5g} [{iv[k][0]:.5g}, {iv[k][1]:.5g}]"
                         for k in (*_NONLINEAR[c.cause], "size"))
        test = c.detail.get("test", c.evidence)
        out.append(replace(c, params=params, intervals=iv, detail={**c.detail, "test": test},
                           evidence=f"{test}; joint GLS fit{together}, χ²/dof "
                           f"{chi / dof:.3g}: {text} (SI units, 68 %)"))
    return out

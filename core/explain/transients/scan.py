"""The transient search's ground: the slow view's block means whitened by the noise's GLS
(``causes._Gls``), each family's column (step, excursion, warm-up), the scan of every edge and
T for the largest |z|, and the joint sizes of what was found."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from avard.core.explain import alarm
from avard.core.explain import causes as cz
from avard.core.model import terms as mdl
from numpy.typing import NDArray

#: Noise levels ("N", "B", "K") of the axis with the given slow-view signal removed.
NoiseOf = Callable[[NDArray[np.float64]], dict[str, float]]

#: Most block means the search and the joint fit use (longer views are averaged further).
MAX_BLOCKS = 512
#: Most grid times a step or an excursion edge is scanned at: every block boundary. On a
#: long record the random walk dominates each block's noise, and a step's whitened column is
#: then nearly an impulse at the boundary it crosses: a grid of every second boundary sees a
#: step inside a skipped block only by the part of it its block mean carries (a 60 h
#: record's up edges were missed so, and its excursions read as permanent steps).
GRID = MAX_BLOCKS
#: Most effects found on one axis.
MAX_EFFECTS = 8
#: A proposal enters the forward search when its z reaches this fraction of its threshold.
FORWARD_MARGIN = 0.75
#: Two opposite steps are one excursion when their sum is within this many standard errors
#: of zero (at 2, one excursion in ten of the benchmark's 1 h records stayed two steps: the
#: random walk moves the level between the edges).
PAIR_SIGMA = 3.0
#: Points of the warm-up's T scan (log grid from 2 blocks to a quarter of the record).
T_SCAN = 48

TRANSIENT_CAUSES = ("bias_step", "excursion", "warmup")


@dataclass(frozen=True)
class _Proposal:
    cause: str
    params: dict[str, float]
    z: float
    threshold: float
    trials: int

    @property
    def margin(self) -> float:
        return abs(self.z) / self.threshold


def _column(cause: str, p: dict[str, float], t: NDArray, dt: float) -> NDArray[np.float64]:
    """The block-averaged shape of a unit effect (size 1) on block centres ``t``."""
    if cause == "bias_step":
        return np.asarray(cz._step_blocks(t, dt, [p["time_s"]])[:, 0])
    if cause == "excursion":
        h = cz._step_blocks(t, dt, [p["start_s"], p["end_s"]])
        return np.asarray(h[:, 0] - h[:, 1])
    if cause == "warmup":
        # e^(−s/T) averaged over each block [t − dt/2, t + dt/2] (the record starts at 0):
        # the point value at the centre read a warm-up's size high by sinh(x)/x, x = dt/2T
        # (2 % at T 600 s on a 60 h record's 422 s blocks), and T below a block not at all
        T = p["time_constant_s"]
        return np.asarray(T / dt * np.exp(-(t - dt / 2) / T) * -np.expm1(-dt / T))
    raise ValueError(f"{cause} is not a compound transient")  # a bug


def _gls(y: NDArray, rate_hz: float, noise: dict[str, float]) -> cz._Gls | None:
    try:
        return cz._Gls(y, rate_hz, noise, MAX_BLOCKS)
    except np.linalg.LinAlgError:
        return None


def _residual(g: cz._Gls, fixed: list[NDArray]) -> tuple[NDArray, NDArray, float]:
    """(Q, whitened residual, Birge s²) with [1, t] and the ``fixed`` whitened columns out."""
    q, _ = np.linalg.qr(np.column_stack([g.wbase, *fixed]))
    r = g.wy - q @ (q.T @ g.wy)
    dof = max(1, len(r) - q.shape[1])
    return q, r, max(1.0, float(r @ r) / dof)


#: A column whose projection keeps less than this fraction of its norm² is taken as already
#: in the fit (a step where one was found): its z would be round-off over round-off.
_COLLINEAR = 1e-6


def _norms(wc: NDArray, c: NDArray) -> tuple[NDArray, NDArray]:
    """(c'·c' floored, whether the projected column keeps enough of the whitened one)."""
    d = np.einsum("ij,ij->j", c, c)
    ok = d > _COLLINEAR * np.einsum("ij,ij->j", wc, wc)
    return np.maximum(d, 1e-300), ok


def _edge_grid(g: cz._Gls) -> NDArray[np.float64]:
    """The times a step or an excursion edge is scanned at: block boundaries, 4 blocks from
    either end, at most ``GRID`` of them (the Bonferroni counts are of these)."""
    M = len(g.t)
    stride = max(1, math.ceil((M - 8) / GRID))
    return np.asarray(np.arange(4, M - 3, stride) * g.dt, dtype=np.float64)


def _t_grid(g: cz._Gls) -> NDArray[np.float64]:
    """The warm-up's time constants scanned: a log grid from 2 blocks to a quarter of the
    record (``T_SCAN`` of them, the warm-up family's Bonferroni count)."""
    return np.geomspace(2 * g.dt, len(g.t) * g.dt / 4, T_SCAN)


def _scan(g: cz._Gls, fixed: list[NDArray], alpha: float) -> list[_Proposal]:
    """Each family's best proposal on the residual of ``g`` with ``fixed`` out (module doc)."""
    t, dt = g.t, g.dt
    q, r, s2 = _residual(g, fixed)
    s = math.sqrt(s2)
    share = alpha / len(TRANSIENT_CAUSES)
    out: list[_Proposal] = []
    # steps and excursions: edges on a grid of block boundaries, 4 blocks from either end
    edges = _edge_grid(g)
    wc = g.white(cz._step_blocks(t, dt, edges))
    c = wc - q @ (q.T @ wc)
    a = c.T @ r
    d, ok = _norms(wc, c)
    z = np.where(ok, a / np.sqrt(d) / s, 0.0)
    i = int(np.argmax(np.abs(z)))
    n_steps = len(edges)
    out.append(_Proposal("bias_step", {"time_s": float(edges[i]), "size": float(a[i] / d[i])},
                         float(z[i]), alarm.bonferroni_z(share, n_steps), n_steps))
    if n_steps >= 3:
        S = c.T @ c
        num = a[:, None] - a[None, :]
        den = d[:, None] + d[None, :] - 2.0 * S
        iu = np.triu_indices(n_steps, k=2)  # at least two grid steps long
        raw = np.einsum("ij,ij->j", wc, wc)
        # a box already in the fit (or collinear with it) leaves nothing to test
        live = den[iu] > _COLLINEAR * (raw[iu[0]] + raw[iu[1]])
        zz = np.where(live, num[iu] / np.sqrt(np.maximum(den[iu], 1e-300)) / s, 0.0)
        k = int(np.argmax(np.abs(zz)))
        i0, i1 = int(iu[0][k]), int(iu[1][k])
        out.append(_Proposal("excursion", {"start_s": float(edges[i0]),
                                           "end_s": float(edges[i1]),
                                           "size": float(num[i0, i1] / den[i0, i1])},
                             float(zz[k]), alarm.bonferroni_z(share, len(zz)), len(zz)))
    warm = _warmup_proposal(g, q, r, s, share)
    if warm is not None:
        out.append(warm)
    return out


def _warmup_proposal(g: cz._Gls, q: NDArray, r: NDArray, s: float, share: float
                     ) -> _Proposal | None:
    """The warm-up family's best proposal e^(−t/T) (T on a log grid from 2 blocks to a
    quarter of the record) on the whitened residual ``r`` with the columns of ``q`` out."""
    t, dt = g.t, g.dt
    record_s = len(t) * dt
    if not record_s / 4 > 2 * dt:
        return None
    grid = _t_grid(g)
    wc = g.white(np.column_stack([_column("warmup", {"time_constant_s": float(T)}, t, dt)
                                  for T in grid]))
    c = wc - q @ (q.T @ wc)
    a = c.T @ r
    d, ok = _norms(wc, c)
    z = np.where(ok, a / np.sqrt(d) / s, 0.0)
    i = int(np.argmax(np.abs(z)))
    return _Proposal("warmup", {"time_constant_s": float(grid[i]), "size": float(a[i] / d[i])},
                     float(z[i]), alarm.bonferroni_z(share, T_SCAN), T_SCAN)


def warmup_beyond_start(y: NDArray, rate_hz: float, noise: dict[str, float],
                        lag_s: float) -> cz.Candidate:
    """A warm-up e^(−t/T) of ``y`` (an axis with its thermal signal removed, the lag filter
    started in steady state) tested against the lag filter's unknown start state, the
    settling e^(−t/|lag_s|) with any size, which is in the null model (with the offset and
    the slope): the warm-up family's scan and threshold of the compound search
    (``find_compound``'s first stage), on the residual of that model. A warm-up whose T is
    near the lag is collinear with the start state and is not seen here; one that passes is
    more than the start state can make, whatever its size.

    This is no claim: ``engine`` removes a warm-up that passes before it chooses the thermal
    path and fits the start state, which a warm-up otherwise takes over (the start state
    absorbs it, or a path with a long second lag or a dT/dt term does), and the compound
    search then tests and claims it as usual."""
    g = _gls(y, rate_hz, noise)
    if g is None:
        return cz.Candidate("warmup", False, evidence="the noise covariance is singular")
    fixed = [g.white(np.exp(-g.t / abs(lag_s)))] if lag_s else []
    q, r, s2 = _residual(g, fixed)
    p = _warmup_proposal(g, q, r, math.sqrt(s2), alarm.TRANSIENTS / len(TRANSIENT_CAUSES))
    if p is None:
        return cz.Candidate("warmup", False, evidence="the record is too short for a warm-up")
    return _as_candidate(p, f", beside the lag filter's start state (e^(−t/{abs(lag_s):.4g} s))"
                         if lag_s else "")


def _as_candidate(p: _Proposal, note: str) -> cz.Candidate:
    ev = (f"largest {p.cause.replace('_', ' ')} of {p.trials} tried is {abs(p.z):.3g} σ by "
          f"generalised least squares with the noise fitted with the other effects removed "
          f"(test: ≥ {p.threshold:.3g}, the Bonferroni split of the axis's false-alarm level "
          f"{alarm.ALPHA_AXIS:g} over its trials){note}")
    return cz.Candidate(p.cause, p.margin >= 1.0, dict(p.params), abs(p.z), p.threshold, ev)


def signal_of(cands: list[cz.Candidate], n: int, rate_hz: float) -> NDArray[np.float64]:
    """The summed signal of ``cands`` on n samples at ``rate_hz``."""
    total = np.zeros(n)
    for c in cands:
        total += cz.cause_signal(c, n, rate_hz)
    return total


def _joint_sizes(g: cz._Gls, cands: list[cz.Candidate]) -> list[cz.Candidate]:
    """The sizes of ``cands`` fitted together by GLS (their shapes held)."""
    if not cands:
        return cands
    cols = [g.white(_column(c.cause, c.params, g.t, g.dt)) for c in cands]
    _chi, coef, _ = g.chi2(cols)
    return [replace(c, params={**c.params, "size": float(coef[2 + i])})
            for i, c in enumerate(cands)]


def robust_noise(y: NDArray, rate_hz: float, n_white: float, gm_T: float = 0.0
                 ) -> dict[str, float]:
    """N, B, K for the forward search, from a robust Allan variance of ``y`` (block means at
    ``rate_hz`` per second): at each octave τ, (1.4826·MAD of the differences of adjacent
    τ-means)²/2, which equals the AVAR for Gaussian noise (NIST SP 1065 eq. 6 with a robust
    spread) and is moved little by the few differences a step or an excursion not yet
    removed makes, where the plain AVAR reads them as random walk. N is the caller's (the
    short τ, where transients show nothing); B² and K² ≥ 0 are fitted by least squares
    relative to the robust AVAR, each τ weighted by its number of differences. With
    ``gm_T`` > 0 (a Gauss–Markov process found on the axis) its σ² at that time constant is
    fitted beside them (``GM_sigma``, ``GM_T``): its AVAR bump is no random walk, and read as
    one it would raise the floor of every step (a step under a walk is one increment)."""
    from avard.core.model.nnls import nnls  # the noise fit's: not scipy.optimize's import

    taus, v, w = [], [], []
    m = 1
    while len(y) // m >= 17:
        yb = cz.block_means(y, m)
        d = np.diff(yb)
        taus.append(m / rate_hz)
        v.append((1.4826 * float(np.median(np.abs(d - np.median(d))))) ** 2 / 2.0)
        w.append(math.sqrt(len(d)))
        m *= 2
    tau, var, wt = np.array(taus), np.array(v), np.array(w)
    ok = var > 0
    gm = {"GM_sigma": 0.0, "GM_T": gm_T} if gm_T > 0 else {}
    if np.count_nonzero(ok) < 3:
        return {"N": n_white, "B": 0.0, "K": 0.0, **gm}
    tau, var, wt = tau[ok], var[ok], wt[ok]
    rest = var - n_white**2 / tau
    cols = [np.full_like(tau, 0.6643**2), tau / 3.0]
    if gm:
        cols.append(mdl.gauss_markov_avar(tau, 1.0, gm_T))
    a = np.column_stack(cols) * (wt / var)[:, None]
    # columns to unit norm first, as the noise fit does (B² and K² differ by decades)
    scale = np.linalg.norm(a, axis=0)
    scale[scale == 0] = 1.0
    coef, _ = nnls(a / scale, rest * wt / var)
    coef = coef / scale
    if gm:
        gm["GM_sigma"] = math.sqrt(coef[2])
    return {"N": n_white, "B": math.sqrt(coef[0]), "K": math.sqrt(coef[1]), **gm}


def _on_grid(c: cz.Candidate, g: cz._Gls) -> list[dict[str, float]]:
    """``c``'s parameters with each nonlinear one (a time, an edge, T) moved to one of the two
    scanned values around it: the shapes its family's Bonferroni count is of. The refinement
    moves them between grid points, and on a random walk a change point's whitened column is
    nearly an impulse, its z different at every block: a z maximised there is maximised over
    more trials than the threshold counts (a null axis's excursion at 6.1 σ refined, against
    5.84, from grid boxes of at most 5.5 σ)."""
    edges, taus = _edge_grid(g), _t_grid(g)
    keys = _NONLINEAR[c.cause]
    near: list[list[float]] = []
    for key in keys:
        grid = taus if key == "time_constant_s" else edges
        j = int(np.searchsorted(grid, c.params[key]))
        near.append(sorted({float(grid[k]) for k in (j - 1, j) if 0 <= k < len(grid)}))
    # an excursion the scan tries is at least two grid steps long
    min_len = 1.5 * (edges[1] - edges[0]) if len(edges) > 1 else 0.0
    return [p for p in ({**c.params, **dict(zip(keys, v, strict=True))}
                        for v in itertools.product(*near))
            if c.cause != "excursion" or p["end_s"] - p["start_s"] >= min_len]


def _z_in_fit(g: cz._Gls, cands: list[cz.Candidate], on_grid: bool = False) -> list[float]:
    """Each candidate's |z| with the others' columns in the fit (Birge-scaled); ``on_grid``:
    the largest over its shapes on the scan's grid (``_on_grid``), the z its threshold is
    for, 0 when none is on it."""
    cols = [g.white(_column(c.cause, c.params, g.t, g.dt)) for c in cands]
    out = []
    for i, col in enumerate(cols):
        q, r, s2 = _residual(g, cols[:i] + cols[i + 1:])
        shapes = ([g.white(_column(cands[i].cause, p, g.t, g.dt)) for p in _on_grid(cands[i], g)]
                  if on_grid else [col])
        best = 0.0
        for sh in shapes:
            c = sh - q @ (q.T @ sh)
            cc = float(c @ c)
            if cc > _COLLINEAR * float(sh @ sh):
                best = max(best, abs(float(c @ r)) / math.sqrt(cc * s2))
        out.append(best)
    return out


_NONLINEAR = {"bias_step": ("time_s",), "excursion": ("start_s", "end_s"),
              "warmup": ("time_constant_s",)}

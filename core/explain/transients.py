"""Compound transients of one axis: several bias steps, excursions (a step up and back down),
a warm-up and a deterministic drift, found one after another and fitted together.

Everything acts on the slow view's block means (at most ``MAX_BLOCKS`` of them), by
generalised least squares with the noise covariance of white, flicker and random-walk noise
N, B, K (``causes._Gls``): the data and every column are whitened, so a column's z is
c'·r/√(c'·c') with c' the whitened column and r the whitened residual, both with the offset,
the slope and the effects already found projected out (Frisch–Waugh–Lovell).

**The search** (``find_compound``), one effect per stage, up to ``MAX_EFFECTS``:

1. the noise is the caller's fit of the axis with every effect found so far removed
   (``NoiseOf``), so an effect found does not raise the floor that hides the next one;
2. three families are scanned on the residual: a step at every block boundary (≤ ``GRID``
   of them, 4 blocks from either end), an excursion at every pair of them (its up and its
   down the same size), a warm-up e^(−t/T) on a log grid of T; each family's largest |z|
   is compared with its Bonferroni threshold (``alarm.bonferroni_z`` at its share of the
   axis's level over its number of trials), and the family that passes by the largest
   margin proposes;
3. the proposal is tested again with the noise refitted with it removed as well: a single
   step's own AVAR reads as random walk, and K made of the step would hide it (the issue's
   2e-4 m/s² step at 12.8 σ, not claimed); it is kept when it still passes there, and its
   size is then checked by its interval (``causes.size_z``) at the same z.

The z's are divided by √(Birge ratio) of the whitened residual when that exceeds 1: a
noise model the record does not follow widens the test instead of passing everything.

**Which edges are one excursion** (``_pairing``): after the joint fit every excursion is
its two steps, and the steps are paired anew, before the backward test, after each effect
it drops and before the final test: of the pairings that nest like brackets (nothing
unpaired inside a pair), each pair a
return to the level before within ``PAIR_SIGMA`` standard errors, the one with the most
excursions, the fewest nested inside one of the other sign (with equal sizes the same
signal as two in a row), then the largest likelihood. An excursion's edge whose partner
pairs as well with an edge left alone is tested as a step (``_weakest_edge``): on a long
record the walk's level shifts took true edges as partners.

**The drift** (``test_drift``): a slope b·t against the random walk that can make the same
wander, in the time domain, by the one test analyze uses too (``analysis.drift``): the
offset, the found transients and, under the alternative, the slope are fitted by GLS with K
profiled over a range reaching well past the noise's own K (N and B held at the fitted
values: they are set by the short τ, where a drift shows nothing); the likelihood ratio is
χ²(1) under a random walk with no drift, tested at its share of the axis's level, and a
drift whose two halves want two lines (a step) is not one. The AVAR cannot tell a ramp from
a random walk on one record (both rise at long τ); the time domain can: a drift's
increments are all of one sign and size, a walk's are not.

**The test in the joint fit** (``confirm_compound``): each effect's z on the scan's grid
and its size's distance from zero (``_size_zs``: a lone warm-up's by the likelihood ratio
at zero) must both reach its family's threshold.

**The joint fit** (``refine_compound``): the nonlinear parameters (step times, excursion
edges, T) are profiled one at a time with the others held, two rounds; 68 % intervals: a
time from its profile likelihood (``causes._weight_interval``, a change point's χ² is no
parabola), T by Δχ² = s² (``causes._profile_interval``), a size from its own profile
envelope (``causes._size_interval``) with the other effects' columns in the fit; s² the
Birge ratio max(1, χ²/dof).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from avard.core.analysis.drift import DRIFT_BLOCKS, drift_likelihood
from avard.core.explain import alarm
from avard.core.explain import causes as cz
from avard.core.model.triangular import LowerSolver
from numpy.typing import NDArray

__all__ = ["MAX_EFFECTS", "NoiseOf", "confirm_compound", "find_compound",
           "min_detectable_warmup_in_fit", "refine_compound", "robust_noise", "signal_of",
           "test_drift", "warmup_beyond_start"]

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


def robust_noise(y: NDArray, rate_hz: float, n_white: float) -> dict[str, float]:
    """N, B, K for the forward search, from a robust Allan variance of ``y`` (block means at
    ``rate_hz`` per second): at each octave τ, (1.4826·MAD of the differences of adjacent
    τ-means)²/2, which equals the AVAR for Gaussian noise (NIST SP 1065 eq. 6 with a robust
    spread) and is moved little by the few differences a step or an excursion not yet
    removed makes, where the plain AVAR reads them as random walk. N is the caller's (the
    short τ, where transients show nothing); B² and K² ≥ 0 are fitted by least squares
    relative to the robust AVAR, each τ weighted by its number of differences."""
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
    if np.count_nonzero(ok) < 3:
        return {"N": n_white, "B": 0.0, "K": 0.0}
    tau, var, wt = tau[ok], var[ok], wt[ok]
    rest = var - n_white**2 / tau
    a = np.column_stack([np.full_like(tau, 0.6643**2), tau / 3.0]) * (wt / var)[:, None]
    # columns to unit norm first, as the noise fit does (B² and K² differ by decades)
    scale = np.linalg.norm(a, axis=0)
    scale[scale == 0] = 1.0
    coef, _ = nnls(a / scale, rest * wt / var)
    coef = coef / scale
    return {"N": n_white, "B": math.sqrt(coef[0]), "K": math.sqrt(coef[1])}


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


def _edges(c: cz.Candidate) -> list[float]:
    if c.cause == "bias_step":
        return [c.params["time_s"]]
    if c.cause == "excursion":
        return [c.params["start_s"], c.params["end_s"]]
    return []


def _normalise(tent: list[cz.Candidate], tol: float, step_threshold: float
               ) -> list[cz.Candidate]:
    """The forward search's proposals as atoms: every excursion becomes its two steps, each
    with its own size and the step family's ``step_threshold`` (a step at a grid time is in
    that family's Bonferroni count, whichever family proposed it; its edges kept the
    excursion family's larger one, 5.71 for 4.90), and steps at one time (within ``tol`` s)
    become one. Which edges
    belong together is decided after the joint fit, by ``_pairing``: the greedy order
    picks the box of the largest margin, and on a record with a step after an excursion that
    is often the excursion's down edge paired with the later step (one box of their mean
    size, its up edge left a lone step), which no refinement of the box's edges undoes."""
    out: list[cz.Candidate] = []
    for c in tent:
        if c.cause == "excursion":
            sz = c.params["size"]
            out += [replace(c, cause="bias_step", threshold=step_threshold,
                            params={"time_s": c.params["start_s"], "size": sz}),
                    replace(c, cause="bias_step", threshold=step_threshold,
                            params={"time_s": c.params["end_s"], "size": -sz})]
        else:
            out.append(c)
    steps = sorted((c for c in out if c.cause == "bias_step"), key=lambda c: c.params["time_s"])
    merged: list[cz.Candidate] = []
    for c in steps:
        if merged and c.params["time_s"] - merged[-1].params["time_s"] <= tol:
            m = merged[-1]
            keep = m if abs(m.params["size"]) >= abs(c.params["size"]) else c
            # the parts' intervals do not hold for their sum: none until it is refitted
            merged[-1] = replace(keep, params={**keep.params, "size": m.params["size"]
                                               + c.params["size"]}, intervals={})
        else:
            merged.append(c)
    return [c for c in out if c.cause != "bias_step"] + merged


def _pair_excursions(cands: list[cz.Candidate], alpha: float) -> list[cz.Candidate]:
    """Steps read as excursions: in time order, a step and a later one of the opposite sign
    with nothing unpaired between them (nested like brackets) are one excursion when their
    sizes are consistent with a return to the level before (|s₁ + s₂| within ``PAIR_SIGMA``
    combined standard errors); its size the mean of |s₁| and |s₂| with the first's sign. It
    is then tested as an excursion (the family's threshold at its most trials)."""
    steps = sorted((c for c in cands if c.cause == "bias_step"),
                   key=lambda c: c.params["time_s"])
    rest = [c for c in cands if c.cause != "bias_step"]

    def se(c: cz.Candidate) -> float:
        lo, hi = c.intervals.get("size", [math.nan, math.nan])
        return 0.5 * (hi - lo)

    stack: list[cz.Candidate] = []
    out: list[cz.Candidate] = []
    for c in steps:
        if stack:
            a = stack[-1]
            s1, s2 = a.params["size"], c.params["size"]
            tol = PAIR_SIGMA * math.hypot(se(a), se(c))
            if s1 * s2 < 0 and math.isfinite(tol) and abs(s1 + s2) <= tol:
                stack.pop()
                size = math.copysign(0.5 * (abs(s1) + abs(s2)), s1)
                out.append(cz.Candidate(
                    "excursion", True, {"start_s": a.params["time_s"],
                                        "end_s": c.params["time_s"], "size": size},
                    min(a.statistic, c.statistic),
                    # the excursion family's test (its most trials: every pair of grid times)
                    alarm.bonferroni_z(alpha / len(TRANSIENT_CAUSES), GRID * (GRID - 1) // 2),
                    f"two steps that return to the level before them (sizes {s1:.3g} and "
                    f"{s2:.3g} m/s², their sum within twice its standard error): "
                    f"{a.detail.get('test', a.evidence)}; and {c.detail.get('test', c.evidence)}"))
                continue
        stack.append(c)
    return rest + out + stack


# --------------------------------------------------------------------------------------------
# which edges belong together: the pairing by the joint fit's likelihood (trans24h)

#: Most pairings of one record's edges whose likelihoods are compared (past it, the greedy
#: brackets of ``_pair_excursions``).
MAX_PAIRINGS = 512


def _atoms(cands: list[cz.Candidate], step_threshold: float) -> list[cz.Candidate]:
    """``cands`` with every excursion as its two steps (sizes ±, the step family's
    ``step_threshold``; each keeps the box's size interval, signed, for ``_pairing``'s
    test of a return to the level before, and no other)."""
    out: list[cz.Candidate] = []
    for c in cands:
        if c.cause == "excursion":
            sz = c.params["size"]
            lo, hi = c.intervals.get("size", [math.nan, math.nan])
            out += [replace(c, cause="bias_step", threshold=step_threshold,
                            intervals={"size": [lo, hi]},
                            params={"time_s": c.params["start_s"], "size": sz}),
                    replace(c, cause="bias_step", threshold=step_threshold,
                            intervals={"size": [-hi, -lo]},
                            params={"time_s": c.params["end_s"], "size": -sz})]
        else:
            out.append(c)
    return out


def _matchings(n: int, ok: Callable[[int, int], bool]) -> list[list[tuple[int, int]]] | None:
    """Every matching of edges 0 … n−1 (in time order) that nests like brackets, whose pairs
    ``ok`` allows, with the most pairs: a pair holds nothing unpaired between its edges (an
    edge left alone inside a pair is the walk's, or a step's; the fit sees no return to the
    level before across it, and a weak edge far away paired with a lone step made a box
    that passed on the step's strength). None when there are more than ``MAX_PAIRINGS``."""
    from functools import cache

    @cache
    def inner(lo: int, hi: int) -> tuple[tuple[tuple[int, int], ...], ...] | None:
        """The perfect bracket matchings of lo … hi−1 (every edge paired)."""
        if lo >= hi:
            return ((),)
        out: list[tuple[tuple[int, int], ...]] = []
        for j in range(lo + 1, hi, 2):
            if ok(lo, j):
                a, b = inner(lo + 1, j), inner(j + 1, hi)
                if a is None or b is None or len(out) + len(a) * len(b) > MAX_PAIRINGS:
                    return None
                out += [((lo, j), *x, *y) for x in a for y in b]
        return tuple(out)

    @cache
    def every(lo: int) -> tuple[tuple[tuple[int, int], ...], ...] | None:
        """The bracket matchings of lo … n−1, edges alone only outside every pair."""
        if lo >= n:
            return ((),)
        rest = every(lo + 1)
        if rest is None:
            return None
        out = list(rest)
        for j in range(lo + 1, n, 2):
            if ok(lo, j):
                a, b = inner(lo + 1, j), every(j + 1)
                if a is None or b is None or len(out) + len(a) * len(b) > MAX_PAIRINGS:
                    return None
                out += [((lo, j), *x, *y) for x in a for y in b]
        return tuple(out)

    found = every(0)
    if found is None:
        return None
    most = max(len(m) for m in found)
    return [list(m) for m in found if len(m) == most]


def _columns(g: cz._Gls, rest: list[cz.Candidate], steps: list[cz.Candidate],
             pairs: list[tuple[int, int]]) -> list[NDArray]:
    """Whitened columns: ``rest`` (warm-ups), a box for each pair of ``steps`` and a step
    for each edge alone."""
    paired = {i for p in pairs for i in p}
    cols = [g.white(_column(c.cause, c.params, g.t, g.dt)) for c in rest]
    cols += [g.white(_column("excursion", {"start_s": steps[i].params["time_s"],
                                           "end_s": steps[j].params["time_s"]}, g.t, g.dt))
             for i, j in pairs]
    cols += [g.white(_column("bias_step", s.params, g.t, g.dt))
             for k, s in enumerate(steps) if k not in paired]
    return cols


def _pairing(g: cz._Gls, cands: list[cz.Candidate], step_threshold: float, alpha: float
             ) -> tuple[list[cz.Candidate], float]:
    """(``cands`` with their edges paired into excursions, the fit's χ²): of the pairings of
    opposite steps that nest like brackets (no two excursions cross, and nothing unpaired sits
    inside one: an excursion with a lasting step inside it reads as three steps, which are all
    claimed, the return to the level not said), each pair's sizes consistent with a return to
    the level before (|s₁ + s₂| within ``PAIR_SIGMA`` standard errors of their sum, from the
    GLS fit with every edge free), the one with the most excursions whose joint fit has the
    largest likelihood. The greedy brackets (``_pair_excursions``) paired the nearest
    consistent edges in time: a step the walk made inside a long excursion then took one of its
    edges, and two excursions were read as nested or joined across each other."""
    atoms = _atoms(cands, step_threshold)
    steps = sorted((c for c in atoms if c.cause == "bias_step"), key=lambda c: c.params["time_s"])
    rest = [c for c in atoms if c.cause != "bias_step"]
    free = _columns(g, rest, steps, [])
    chi, coef, cov = g.chi2(free)
    dof = max(1, len(g.yb) - 2 - 2 * len(free))
    s2 = max(1.0, chi / dof)
    k0 = 2 + len(rest)
    size = [float(coef[k0 + k]) for k in range(len(steps))]

    def se(c: cz.Candidate) -> float:
        lo, hi = c.intervals.get("size", [math.nan, math.nan])
        return 0.5 * (hi - lo)

    def ok(i: int, j: int) -> bool:
        if size[i] * size[j] >= 0:
            return False
        # the sum's standard error in this fit, or (where wider) from the two sizes' own
        # 68 % intervals, which hold what their times' uncertainty adds (on a long record a
        # step's size is nearly its block's jump, and where in the block it sits moves it)
        var = (cov[k0 + i, k0 + i] + cov[k0 + j, k0 + j] + 2 * cov[k0 + i, k0 + j]) * s2
        wide = math.hypot(se(steps[i]), se(steps[j]))
        tol = max(math.sqrt(max(var, 0.0)), wide if math.isfinite(wide) else 0.0)
        return abs(size[i] + size[j]) <= PAIR_SIGMA * tol

    found = _matchings(len(steps), ok)
    if found is None:
        paired = _pair_excursions(_joint_sizes(g, atoms), alpha)
        return paired, g.chi2([g.white(_column(c.cause, c.params, g.t, g.dt))
                               for c in paired])[0]
    def nested(m: list[tuple[int, int]]) -> int:
        # an excursion inside one of the other sign: with equal sizes it is the same signal
        # as two of one sign one after the other, the level back to where it was between
        # them (the simpler reading); their sizes then differ by the walk alone, and which
        # of the two pairings fits better is the walk's draw
        return sum(1 for i, j in m for k, e in m
                   if i < k < e < j and size[i] * size[k] < 0)

    best_key: tuple[int, float] = (10**9, math.inf)
    best_chi, best = math.inf, found[0]
    for m in found:
        c2 = g.chi2(_columns(g, rest, steps, m))[0]
        if (nested(m), c2) < best_key:
            best_key, best_chi, best = (nested(m), c2), c2, m
    paired_idx = {i for p in best for i in p}
    out = list(rest)
    for i, j in best:
        a, c = steps[i], steps[j]
        s1, s2_ = size[i], size[j]
        out.append(cz.Candidate(
            "excursion", True, {"start_s": a.params["time_s"], "end_s": c.params["time_s"],
                                "size": math.copysign(0.5 * (abs(s1) + abs(s2_)), s1)},
            min(a.statistic, c.statistic),
            # the excursion family's test (its most trials: every pair of grid times)
            alarm.bonferroni_z(alpha / len(TRANSIENT_CAUSES), GRID * (GRID - 1) // 2),
            f"two steps that return to the level before them (sizes {s1:.3g} and "
            f"{s2_:.3g} m/s², their sum within {PAIR_SIGMA:g} of its standard errors; of the "
            f"pairings of the edges, the joint fit's most likely): "
            f"{a.detail.get('test', a.evidence)}; and {c.detail.get('test', c.evidence)}"))
    out += [s for k, s in enumerate(steps) if k not in paired_idx]
    return _joint_sizes(g, out), best_chi


def _weakest_edge(g: cz._Gls, cands: list[cz.Candidate], step_threshold: float, alpha: float
                  ) -> tuple[float, cz.Candidate, list[cz.Candidate]] | None:
    """(its margin, the edge as a step, the candidates without it, paired anew) of the
    weakest excursion edge whose removal leaves as many excursions (its partner pairs with
    an edge that was alone): that edge is then an edge and a size more than the fit
    without it, a step's test, by the likelihood ratio of the two fits (on the noise
    ``g``, Birge-scaled). On a long record the random walk makes level shifts: a shift
    inside a long excursion took one of its edges as its partner, the box it made passed
    as a box on the strength of the true edge, and the excursion's other edge was left as a
    permanent step. None when no excursion's edge is so."""
    n_exc = sum(c.cause == "excursion" for c in cands)
    if n_exc == 0 or not any(c.cause == "bias_step" for c in cands):
        return None
    cols = [g.white(_column(c.cause, c.params, g.t, g.dt)) for c in cands]
    chi, _coef, _ = g.chi2(cols)
    dof = max(1, len(g.yb) - 2 - 2 * len(cols))
    s2 = max(1.0, chi / dof)
    best: tuple[float, cz.Candidate, list[cz.Candidate]] | None = None
    for i, c in enumerate(cands):
        if c.cause != "excursion":
            continue
        others = cands[:i] + cands[i + 1:]
        for key, other in (("start_s", "end_s"), ("end_s", "start_s")):
            sign = 1.0 if key == "start_s" else -1.0
            keep = next(a for a in _atoms([c], step_threshold)
                        if a.params["time_s"] == c.params[other])
            reduced, chi_r = _pairing(g, [*others, keep], step_threshold, alpha)
            if sum(o.cause == "excursion" for o in reduced) < n_exc:
                continue
            z = math.sqrt(max(0.0, chi_r - chi) / s2) / step_threshold
            if best is None or z < best[0]:
                lone = replace(c, cause="bias_step", threshold=step_threshold, intervals={},
                               params={"time_s": c.params[key], "size": sign * c.params["size"]})
                best = (z, lone, reduced)
    return best


def find_compound(y: NDArray, rate_hz: float, noise_of: NoiseOf,
                  alpha: float = alarm.TRANSIENTS) -> tuple[list[cz.Candidate],
                                                            list[cz.Candidate]]:
    """(found, not found) on one axis's slow view ``y`` at ``rate_hz`` blocks per second:
    the effects that passed, fitted together with 68 % intervals (``refine_compound``), and
    the ones proposed that did not pass (their evidence says why; when none was proposed,
    each family's best). ``noise_of(signal)``: N, B, K of the axis with ``signal`` removed.
    ``alpha``: this search's share of the axis's false-alarm level (``alarm``).

    Forward, then backward: effects are proposed one at a time, the noise refitted with the
    ones proposed so far removed, while the best proposal reaches ``FORWARD_MARGIN`` of its
    threshold (an effect not yet removed raises the floor of the others, so a real one may
    sit below its threshold until they are out); then each proposal is tested in the joint
    fit against the noise with all proposals removed, and the weakest that fails its
    threshold is dropped, the noise refitted, until all pass."""
    n = len(y)
    tent: list[cz.Candidate] = []
    first: list[cz.Candidate] = []
    n_white = noise_of(np.zeros(n)).get("N", 0.0)
    for _stage in range(MAX_EFFECTS):
        noise = robust_noise(y - signal_of(tent, n, rate_hz), rate_hz, n_white)
        g = _gls(y, rate_hz, noise)
        if g is None:
            break
        fixed = [g.white(_column(c.cause, c.params, g.t, g.dt)) for c in tent]
        props = _scan(g, fixed, alpha)
        # the step family's threshold (its trials are the grid's times, the same at every
        # stage): an excursion's edge, once a step of its own, is tested at it
        step_threshold = next(p.threshold for p in props if p.cause == "bias_step")
        if not tent:
            first = [_as_candidate(p, "") for p in props]
        best = max(props, key=lambda p: p.margin)
        if best.margin < FORWARD_MARGIN:
            break
        tent = _joint_sizes(g, [*tent, _as_candidate(best, "")])
    if tent:
        # the proposals' shapes refined together (the scan's grid T and times are coarse,
        # and what a misplaced shape leaves behind reads as noise in the test below)
        tol = 4 * len(y) / rate_hz / MAX_BLOCKS
        tent = _normalise(tent, tol, step_threshold)
        tent = refine_compound(y, rate_hz, robust_noise(y - signal_of(tent, n, rate_hz),
                                                        rate_hz, n_white), tent)
        # edges the refinement drew to one time are one step: two steps a sample apart are
        # collinear, their sizes huge and opposite, and read as an excursion they would hide
        # the step they stand for
        tent = _normalise(tent, tol, step_threshold)
        # two steps that return to the level before them are tested as one excursion
        g = _gls(y, rate_hz, robust_noise(y - signal_of(tent, n, rate_hz), rate_hz, n_white))
        tent = (_pairing(g, tent, step_threshold, alpha)[0] if g is not None
                else _pair_excursions(tent, alpha))
    dropped: list[cz.Candidate] = []
    while tent:
        g = _gls(y, rate_hz, noise_of(signal_of(tent, n, rate_hz)))
        if g is None:
            return [], first
        zs = _z_in_fit(g, tent, on_grid=True)
        margins = [z / c.threshold for z, c in zip(zs, tent, strict=True)]
        k = int(np.argmin(margins))
        edge = _weakest_edge(g, tent, step_threshold, alpha)
        if edge is not None and edge[0] < min(1.0, margins[k]):
            # an excursion's edge whose partner pairs as well with an edge left alone: the
            # two are one edge and a size more than the other pairing, tested as a step
            z_e, lone, tent = edge
            dropped.append(replace(lone, passed=False, statistic=z_e * step_threshold,
                                   threshold=step_threshold, intervals={}, evidence=(
                f"{lone.evidence}; not claimed: an edge at {lone.params['time_s']:.6g} s whose "
                f"excursion's other edge pairs as well with an edge the fit left alone; "
                f"against that fit, in the joint fit with the noise with every effect "
                f"proposed removed, it is {z_e * step_threshold:.3g} σ by its likelihood "
                f"ratio (test: ≥ {step_threshold:.3g}, a step's)")))
            continue
        if margins[k] >= 1.0:
            # every one passes its test in the joint fit (a proposal may have come in below
            # its threshold, or as the edge of an excursion that did not pass)
            tent = [replace(c, statistic=z, passed=True) for c, z in zip(tent, zs, strict=True)]
            break
        c = tent.pop(k)
        dropped.append(replace(c, passed=False, statistic=zs[k], evidence=c.evidence + (
            f"; not claimed: in the joint fit, against the noise with every effect proposed "
            f"removed, it is {zs[k]:.3g} σ (test: ≥ {c.threshold:.3g})")))
        # the edges left pair anew: an edge dropped may have held one of a pair's places
        tent = _pairing(g, tent, step_threshold, alpha)[0]
    if not tent:
        return [], dropped or first
    noise = noise_of(signal_of(tent, n, rate_hz))
    out = refine_compound(y, rate_hz, noise, tent)
    g = _gls(y, rate_hz, noise)
    out = (_pairing(g, out, step_threshold, alpha)[0] if g is not None
           and any(c.cause == "bias_step" for c in out) else _pair_excursions(out, alpha))
    kept, lost = confirm_compound(y, rate_hz, noise_of, out)
    return kept, dropped + lost


def confirm_compound(y: NDArray, rate_hz: float, noise_of: NoiseOf,
                     cands: list[cz.Candidate]) -> tuple[list[cz.Candidate], list[cz.Candidate]]:
    """(claimed, not claimed): ``cands`` fitted together (``refine_compound``) against the
    noise with all of them removed, and each tested in that fit, the fit they are reported
    with: its z on the scan's grid (``_z_in_fit``) and its size's distance from zero in
    standard errors (``_size_zs``) must both reach its threshold; the one furthest
    below is dropped and the rest refitted until all pass. The statistic and the sentence of
    a claim are this test's: a claim never stands on an earlier fit's z (a pair of steps
    read as one excursion, a refit after a transient was taken out) nor on a threshold other
    than the one it states."""
    n = len(y)
    dropped: list[cz.Candidate] = []
    cands = list(cands)
    while cands:
        noise = noise_of(signal_of(cands, n, rate_hz))
        cands = refine_compound(y, rate_hz, noise, cands)
        g = _gls(y, rate_hz, noise)
        if g is None:
            return [], dropped + [replace(c, passed=False, intervals={}, evidence=c.evidence + (
                "; not claimed: the noise covariance would not factor")) for c in cands]
        zs = _z_in_fit(g, cands, on_grid=True)
        szs = _size_zs(g, cands)
        margins = [min(z, sz) / c.threshold for z, sz, c in zip(zs, szs, cands, strict=True)]
        k = int(np.argmin(margins))
        if margins[k] >= 1.0:
            return [replace(c, passed=True, statistic=z, evidence=(
                f"claimed: {_final_test(z, sz, c.threshold, len(cands))}; the search: "
                f"{c.evidence}")) for z, sz, c in zip(zs, szs, cands, strict=True)], dropped
        dropped.append(replace(cands[k], passed=False, statistic=zs[k], intervals={},
                               evidence=cands[k].evidence + "; not claimed: " + _final_test(
                                   zs[k], szs[k], cands[k].threshold, len(cands))
                               + _trend_note(cands[k], noise, n / rate_hz)))
        cands.pop(k)
    return [], dropped


def _size_zs(g: cz._Gls, cands: list[cz.Candidate]) -> list[float]:
    """Each size's distance from zero in standard errors, for ``confirm_compound``'s test.

    A step's or an excursion's: its 68 % interval's half on zero's side, scaled
    (``causes.size_z``). A warm-up's, where it is the only one: the likelihood ratio of size
    zero, √(Δχ²/s²) at its fitted T with the other effects' sizes refitted (the profile
    envelope's value at zero is the fit without it, whatever T). With the offset and the
    slope in the fit a long T's e^(−t/T) is mostly their line, its size trades against T
    along a curved ridge, and the 68 % half-width scaled linearly puts zero far nearer than
    the likelihood does (a warm-up of T ≥ record/6 many σ as a shape was not claimed). Two
    warm-ups keep the scaled half-width: their columns can trade with each other (two
    opposite ones a grid step apart in T), which the ratio at one's zero, the other's T
    held, does not see."""
    if sum(c.cause == "warmup" for c in cands) != 1:
        return [cz.size_z(c) for c in cands]
    refined = _z_in_fit(g, cands)   # (each effect's profile: only where a lone warm-up asks)
    return [z if c.cause == "warmup" else cz.size_z(c)
            for z, c in zip(refined, cands, strict=True)]


def _trend_note(c: cz.Candidate, noise: dict[str, float], record_s: float) -> str:
    """A warm-up not claimed whose size is below its stated minimum in the compound fit
    (``min_detectable_warmup_in_fit``, the offset, the slope and T fitted beside it): at a
    long T that minimum is several times the lone warm-up's, and the finding says so."""
    if c.cause != "warmup":
        return ""
    T = c.params["time_constant_s"]
    m = min_detectable_warmup_in_fit(noise.get("N", 0.0), noise.get("B", 0.0),
                                     noise.get("K", 0.0), record_s, T, c.threshold)
    if abs(c.params["size"]) >= m:
        return ""
    return (f"; its size {abs(c.params['size']):.3g} m/s² is below the stated minimum of a "
            f"warm-up of T {T:.4g} s ({T / record_s:.2g} of the record) on this record and "
            f"noise, {m:.3g} m/s² ({c.threshold:.3g} standard errors with the offset, the "
            f"slope and T fitted beside it: a warm-up this long is told from the record's "
            f"trend only above it)")


def _final_test(z: float, size_z: float, threshold: float, n_effects: int) -> str:
    """The sentence of ``confirm_compound``'s test of one effect."""
    together = f" with {n_effects - 1} other effects" if n_effects > 1 else ""
    return (f"in the joint fit{together}, against the noise with every effect claimed removed,"
            f" it is {z:.3g} σ on the scan's grid and its size {size_z:.3g} standard errors "
            f"from zero (test: both ≥ {threshold:.3g}, its family's Bonferroni split of the "
            f"axis's false-alarm level {alarm.ALPHA_AXIS:g})")


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


_NONLINEAR = {"bias_step": ("time_s",), "excursion": ("start_s", "end_s"),
              "warmup": ("time_constant_s",)}


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


# --------------------------------------------------------------------------------------------
# drift against a random walk


def _slope_fit(yb: NDArray, t: NDArray, dt: float, noise: dict[str, float],
               cols: list[NDArray]) -> tuple[float, float]:
    """(slope, its standard error) of block means ``yb`` on ``cols`` + the centred time by
    GLS with the noise N, B, K of ``noise``, the error scaled by √(Birge ratio) when the
    whitened residual's χ²/dof exceeds 1 (a noise model the data do not follow widens it)."""
    c = cz._noise_cov(t, dt, noise.get("N", 0.0), noise.get("B", 0.0), noise.get("K", 0.0))
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


def min_detectable_excursion(n_white: float, b_inst: float, k_rrw: float, record_s: float,
                             duration_s: float, z: float = 5.0, blocks: int = 1024) -> float:
    """The stated minimum of an excursion (m/s²): z standard errors of its size in the GLS
    fit (its Fisher information) with noise N, B, K over ``record_s``, the excursion
    ``duration_s`` long in the middle of the record."""
    dt = record_s / blocks
    t = (np.arange(blocks) + 0.5) * dt
    g_cov = cz._noise_cov(t, dt, n_white, b_inst, k_rrw)
    L = np.linalg.cholesky(g_cov)
    t0 = 0.5 * (record_s - duration_s)
    cols = np.column_stack([np.ones_like(t), t, _column(
        "excursion", {"start_s": t0, "end_s": t0 + duration_s}, t, dt)])
    a = np.linalg.solve(L, cols)
    return float(z * math.sqrt(np.linalg.inv(a.T @ a)[2, 2]))


def min_detectable_warmup_in_fit(n_white: float, b_inst: float, k_rrw: float,
                                 record_s: float, time_constant_s: float, z: float = 5.0,
                                 blocks: int = MAX_BLOCKS) -> float:
    """The stated minimum of a warm-up in the compound fit (m/s²): z standard errors of its
    size by GLS with noise N, B, K over ``record_s``, with the offset, the slope and its T
    fitted beside it (the Fisher information with the column ∂/∂T; a scale of that column
    leaves the size's error unchanged, so the minimum does not depend on the size). For
    T ≪ record it is ``causes.min_detectable_warmup``'s regime; from T ≈ record/6 on, the
    line and T take most of e^(−t/T) and the minimum rises well above it."""
    dt = record_s / blocks
    t = (np.arange(blocks) + 0.5) * dt
    L = np.linalg.cholesky(cz._noise_cov(t, dt, n_white, b_inst, k_rrw))
    e = np.exp(-t / time_constant_s)
    a = np.linalg.solve(L, np.column_stack([np.ones_like(t), t, e,
                                            t / time_constant_s**2 * e]))
    return float(z * math.sqrt(np.linalg.inv(a.T @ a)[2, 2]))


def min_detectable_drift(n_white: float, b_inst: float, k_rrw: float, record_s: float,
                         z: float = 5.0, blocks: int = DRIFT_BLOCKS) -> float:
    """The stated minimum of a drift (m/s³): z standard errors of its slope in the GLS fit
    with noise N, B, K over ``record_s`` (the Fisher information of the slope, the random
    walk in the covariance)."""
    dt = record_s / blocks
    t = (np.arange(blocks) + 0.5) * dt
    L = np.linalg.cholesky(cz._noise_cov(t, dt, n_white, b_inst, k_rrw))
    a = np.linalg.solve(L, np.column_stack([np.ones_like(t), t - t.mean()]))
    return float(z * math.sqrt(np.linalg.inv(a.T @ a)[1, 1]))

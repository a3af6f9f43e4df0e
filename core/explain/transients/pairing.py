"""Which edges are one excursion: after a joint fit every excursion is its two steps, paired anew
by brackets that nest, each a return to the level before (``_pairing``), and an edge whose
partner pairs as well with another tested as a step (``_weakest_edge``)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace

from avard.core.explain import alarm
from avard.core.explain import causes as cz
from avard.core.explain.transients.scan import (
    GRID,
    PAIR_SIGMA,
    TRANSIENT_CAUSES,
    _column,
    _joint_sizes,
)
from numpy.typing import NDArray


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

"""The compound search of one axis (``find_compound``): one effect a stage, each tested against
the noise refitted with it and the others removed, then refitted together and tested again
(``confirm_compound``)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from avard.core.explain import alarm
from avard.core.explain import causes as cz
from avard.core.explain.transients.minima import min_detectable_warmup_in_fit
from avard.core.explain.transients.pairing import (
    _normalise,
    _pair_excursions,
    _pairing,
    _weakest_edge,
)
from avard.core.explain.transients.refine import refine_compound
from avard.core.explain.transients.scan import (
    FORWARD_MARGIN,
    MAX_BLOCKS,
    MAX_EFFECTS,
    NoiseOf,
    _as_candidate,
    _column,
    _gls,
    _joint_sizes,
    _scan,
    _z_in_fit,
    robust_noise,
    signal_of,
)
from numpy.typing import NDArray


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
    noise0 = noise_of(np.zeros(n))
    n_white = noise0.get("N", 0.0)
    # a Gauss–Markov process the caller's noise carries (its T; its σ refitted each stage)
    gm_T = noise0.get("GM_T", 0.0)

    def robust(r: NDArray) -> dict[str, float]:
        return robust_noise(r, rate_hz, n_white, gm_T)

    for _stage in range(MAX_EFFECTS):
        noise = robust(y - signal_of(tent, n, rate_hz))
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
        tent = refine_compound(y, rate_hz, robust(y - signal_of(tent, n, rate_hz)), tent)
        # edges the refinement drew to one time are one step: two steps a sample apart are
        # collinear, their sizes huge and opposite, and read as an excursion they would hide
        # the step they stand for
        tent = _normalise(tent, tol, step_threshold)
        # two steps that return to the level before them are tested as one excursion
        g = _gls(y, rate_hz, robust(y - signal_of(tent, n, rate_hz)))
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

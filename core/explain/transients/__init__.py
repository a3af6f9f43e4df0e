"""Compound transients of one axis: several bias steps, excursions (a step up and back down),
a warm-up and a deterministic drift, found one after another and fitted together.

Everything acts on the slow view's block means (at most ``MAX_BLOCKS`` of them), by
generalised least squares with the noise covariance of white, flicker and random-walk noise
N, B, K (``causes._Gls``): the data and every column are whitened, so a column's z is
c'·r/√(c'·c') with c' the whitened column and r the whitened residual, both with the offset,
the slope and the effects already found projected out (Frisch–Waugh–Lovell). Where the
caller's noise carries a Gauss–Markov process (``GM_sigma``, ``GM_T``: ``engine.channel``
runs the search again once one is claimed on the axis) its block-averaged covariance is part
of that noise, and ``robust_noise`` fits its σ at that T: read as random walk, its bump would
make a step one increment of the walk.

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

from avard.core.explain.transients.drift import test_drift
from avard.core.explain.transients.minima import min_detectable_warmup_in_fit
from avard.core.explain.transients.refine import refine_compound
from avard.core.explain.transients.scan import (
    MAX_EFFECTS,
    NoiseOf,
    robust_noise,
    signal_of,
    warmup_beyond_start,
)
from avard.core.explain.transients.search import confirm_compound, find_compound

__all__ = ["MAX_EFFECTS", "NoiseOf", "confirm_compound", "find_compound",
           "min_detectable_warmup_in_fit", "refine_compound", "robust_noise", "signal_of",
           "test_drift", "warmup_beyond_start"]

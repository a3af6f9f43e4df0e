"""The honest "unexplained": whether the extended model (analyze's terms plus the claimed
causes) describes the axis, in-sample and on held-out data, and what follows when it does not.

A χ² test of the extended fit, at ``ALPHA`` (1 %):

- in-sample: the generalised χ² of ``fit_noise`` (χ²/dof × dof, covariance as the fit models
  it) against χ²(dof);
- held out: the extended model's held-out χ² (``holdout``, summed over the folds) against
  χ²(n), n the held-out τ: each τ's residual weighed by the variance of the measurement and
  of the prediction, the latter the noise terms' and the claimed mechanism's parameters,
  fitted on the other half, carried to the predicted AVAR and, for the noise terms, to the
  held-out estimator's scatter too (``holdout._noise_scatter``: a half that under-reads a
  random walk or a flicker no longer weighs the other half's long τ with too small a
  variance; ``holdout.Fold.chi2_ext_pred``), and no ratio over n (one that excused correct
  records also hid wrong ones). On described sensors it then fails near ``ALPHA`` (halves
  of white + flicker + random walk: 1–1.7 % at 1 %, somewhat conservative on 1 h records;
  ``tests/core/test_heldout_calibration.py``). A screened temperature log's interpolation
  error is still not carried (the holes themselves are gaps of the held-out Allan
  variance), so a correct coupling seen through a faulty log can fail it: it then says
  "unexplained" and keeps its intervals (below). Not applied to an axis whose claims are
  only events (a warm-up, a step predicts nothing in other data, by design).

When either fails, the axis is **unexplained**: one line beside the gain gives χ²/dof with its
p-value, the held-out χ²/n with its p-value and the τ ranges where the extended model still
misses by more than 3 σ with their sizes (in σ, and as the measured ADEV over the model's).
An extended fit whose χ² cannot be tested (no dof, χ² not finite) is never said to fit: the
line says "NOT TESTED" and the axis is treated as unexplained (its parameters model-dependent).

Where the held-out test was asked for an axis with a claimed mechanism that predicts other
data (not only events) and could not run (its held-out fit failed: e.g. a lag whose start
state leaves too little of each half), the in-sample χ² alone does not say the axis is
described: the in-sample fit holds the mechanism's own parameters, chosen on that very
record, and a wrong mechanism passes it (an adversary's null axis read as hysteresis at a
lag of 1837 s on 4 h). The line then says "NOT HELD OUT" with the reason, the axis is not
explained and the claimed causes' parameters are model-dependent (their intervals are
printed, marked so: no held-out data rejected them either).

When the axis is unexplained the claimed causes' parameters are *model-dependent* (the best
values of a model the data reject), and where the data reject the mechanism no interval is
printed for them (a ±3 % interval of a rejected mechanism is a confident wrong answer);
``--json`` keeps them under ``intervals_if_model_held``. The mechanism is rejected
(``Verdict.heldout_rejects``) when the held-out test fails and either the in-sample test fails
too (both the data it was fitted on and the data it predicts reject it) or the held-out χ² lies
beyond ``HELDOUT_RATIO``·n. A held-out failure alone, with the in-sample fit passing and χ²
within that ratio, says "unexplained" but keeps the intervals: a correct coupling seen
through a faulty temperature log predicts the other half only roughly (the interpolation
over its holes is not carried), and withholding its intervals would remove correct ones.

The compensated ADEV is given only where it does not make the ADEV worse than the
uncompensated one beyond the latter's 68 % interval at any τ (fitted or not: the user reads
the whole curve): a compensation that adds variance somewhere removes the wrong signal (two
thermal paths through one lag made the ADEV 1.4× worse at τ 2–5 min).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, TypedDict

import numpy as np
from numpy.typing import NDArray

__all__ = ["ALPHA", "HELDOUT_RATIO", "MisfitRange", "Verdict", "compensation_worse_at", "judge"]

#: The level of the χ² tests that say "unexplained".
ALPHA = 0.01
#: A held-out failure beyond this many times n rejects the mechanism (its intervals withheld)
#: even where the in-sample fit passes: correct thermal records reach a few times n on 2 h
#: halves, a mechanism the held-out data reject lies far beyond (two thermal paths through one
#: lag: 15·n). It no longer decides "unexplained" (the held-out test at ``ALPHA`` does).
HELDOUT_RATIO = 5.0


class MisfitRange(TypedDict):
    """One contiguous τ range where a model misses the measured AVAR by ≥ 3 σ
    (``engine.misfit_ranges``): its ends (s), the largest z there, the measured ADEV over the
    model's at that τ (NaN where either is not positive), "above" or "below"."""

    tau_range_s: list[float]
    max_sigma: float
    adev_ratio: float
    direction: str


def _chi2_sf(x: float, k: float) -> float:
    """P(χ²_k > x)."""
    if not (math.isfinite(x) and k > 0):
        return math.nan
    # the project's χ² tail (scipy's to 1e-10 relative, tests/core/test_beta.py), as analyze
    # uses: importing scipy.stats for one p-value cost explain more CPU than its fits
    from avard.core.allan.chi2 import chi2_sf

    return float(chi2_sf(x, k))


@dataclass(frozen=True)
class Verdict:
    """Whether the extended model describes one axis (see the module's doc)."""

    explained: bool
    chi2_dof: float
    dof: int
    p_value: float
    heldout_chi2: float | None = None
    heldout_n: int = 0
    heldout_p: float | None = None
    misfit: list[MisfitRange] = field(default_factory=list)
    #: False when the extended fit's χ² could not be tested (no dof, χ² not finite): then
    #: ``explained`` is False too (nothing said it fits)
    tested: bool = True
    #: why the held-out test asked for this axis's claims could not run (then ``explained``
    #: is False); None when it ran, was not asked, or does not apply (events only)
    heldout_missing: str | None = None
    #: what may cause the misfit though the model has no term for it, in words (a log of the
    #: chosen channel on a coarser step than the thermal model's rounding assumes); said
    #: only when the axis is not explained
    suspect: str | None = None
    #: the coupling-change line (``coupling_change``) where one one-lag coupling does not
    #: describe the record's parts alike; said in the line, and it does not overrule the χ²
    #: tests: the same one-lag projection of a path that is not one lag differs between
    #: parts whose temperature spectra differ, where one coupling fits the whole (review27b)
    changed: str | None = None

    @property
    def heldout_fails(self) -> bool:
        """The held-out χ² test fails at ``ALPHA`` (the axis is then unexplained)."""
        return self.heldout_p is not None and self.heldout_p < ALPHA

    @property
    def heldout_rejects(self) -> bool:
        """The data reject the claimed mechanism: no interval is printed (module doc)."""
        return self.heldout_fails and (
            self.p_value < ALPHA or (self.heldout_chi2 is not None
                                     and self.heldout_chi2 > HELDOUT_RATIO * self.heldout_n))

    def line(self) -> str:
        """The one line beside the gain."""
        if self.suspect and not self.explained:
            return f"{self._line()}; a possible cause: {self.suspect}"
        return self._line()

    def _line(self) -> str:
        ins = f"χ²/dof {self.chi2_dof:.3g} on {self.dof} dof (p {self.p_value:.2g})"
        held = ""
        if self.heldout_p is not None:
            held = (f", held out χ² {self.heldout_chi2:.4g} on n = {self.heldout_n} τ "
                    f"(p {self.heldout_p:.2g})")
        changed = ("; the one-lag coupling differs before and after a time (CHANGED below)"
                   if self.changed is not None else "")
        if self.explained:
            return f"the extended model fits: {ins}{held} (test at {ALPHA:.0%}){changed}"
        if self.tested and self.heldout_missing is not None and self.p_value >= ALPHA:
            return (f"NOT HELD OUT: the held-out test of the claimed mechanism could not run "
                    f"({self.heldout_missing}); in sample {ins} (test at {ALPHA:.0%}), which "
                    "the mechanism's own fitted parameters pass whether or not it is the "
                    f"right one{changed}; the claimed causes' parameters are model-dependent")
        if not self.tested:
            return (f"NOT TESTED: the extended fit's χ² cannot be tested ({ins}){held}; the "
                    "claimed causes' parameters are model-dependent")
        where = "; ".join(_misfit_text(r) for r in self.misfit) or "no single τ range beyond 3 σ"
        return (f"UNEXPLAINED: the extended model still misfits, {ins}{held}; {where}{changed}; "
                "the claimed causes' parameters are model-dependent")

    def to_dict(self) -> dict[str, Any]:
        return {"explained": self.explained, "tested": self.tested,
                "chi2_dof": self.chi2_dof, "dof": self.dof,
                "p_value": self.p_value, "heldout_chi2": self.heldout_chi2,
                "heldout_n": self.heldout_n, "heldout_p": self.heldout_p,
                "heldout_missing": self.heldout_missing,
                "possible_cause": None if self.explained else self.suspect,
                "coupling_changed": self.changed,
                "alpha": ALPHA, "misfit": self.misfit, "line": self.line()}


def judge(chi2_dof: float, dof: int, misfit: Sequence[MisfitRange],
          heldout_chi2: float | None = None, heldout_n: int = 0,
          heldout_missing: str | None = None, changed: str | None = None) -> Verdict:
    """The verdict from the extended fit's χ²/dof and dof, its misfit ranges, and (when
    measured) its held-out χ² on n τ. ``heldout_missing``: why a held-out test asked for
    this axis's claims could not run (the axis is then not explained, module doc);
    ``changed``: the coupling-change line, said beside the tests' outcome. The
    held-out χ² is the one with the prediction's own variance (``holdout.Fold``), tested
    against χ²(n) as it stands."""
    p = _chi2_sf(chi2_dof * dof, dof)
    hp = (None if heldout_chi2 is None or heldout_n <= 0 or not math.isfinite(heldout_chi2)
          else _chi2_sf(heldout_chi2, heldout_n))
    held_bad = hp is not None and hp < ALPHA
    tested = math.isfinite(p)
    missing = heldout_missing if hp is None else None
    bad = not tested or p < ALPHA or held_bad or missing is not None
    return Verdict(not bad, chi2_dof, dof, p, heldout_chi2 if hp is not None else None,
                   heldout_n if hp is not None else 0, hp, list(misfit) if bad else [], tested,
                   missing, changed=changed)


def _misfit_text(r: MisfitRange) -> str:
    """One misfit range: where, which way, how far in σ and, when known, in ADEV."""
    size = f"up to {r['max_sigma']:+.3g} σ"
    ratio = r.get("adev_ratio")
    if ratio is not None and math.isfinite(ratio):
        size += f", ADEV {ratio:.3g}× the model's"
    return (f"{r['direction']} at τ {r['tau_range_s'][0]:.3g}…{r['tau_range_s'][1]:.3g} s "
            f"({size})")


def compensation_worse_at(tau: NDArray, hi: NDArray, comp_var: NDArray) -> list[float]:
    """The τ (every one where both exist, fitted or not) where the compensated AVAR exceeds
    the uncompensated one's upper 68 % bound ``hi`` (the compensation added variance there)."""
    c, h = np.asarray(comp_var, dtype=float), np.asarray(hi, dtype=float)
    ok = np.isfinite(c) & np.isfinite(h)
    worse = np.zeros(len(c), dtype=bool)
    worse[ok] = c[ok] > h[ok]
    return [float(t) for t in np.asarray(tau, dtype=float)[worse]]

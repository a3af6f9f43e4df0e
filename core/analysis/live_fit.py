"""The fit of a decimated Allan curve (the service's cascade) and the intervals it prints,
by analyze's rules: one function for the live snapshot and for ``analyze --estimator cascade``.

The service's ``StreamingAllan`` keeps, above m = 8, only the differences every m/8
samples (``core/allan/streaming.py``); analyze's OADEV keeps all of them. On the same
samples the two curves differ by that decimation alone: the cascade's estimate is a subset
mean of the OADEV's differences, so their difference scatters with about 1/ν_c − 1/ν_o of
the estimate's relative variance (ν the EDFs; the cascade keeps ≥ 98 % of the OADEV's,
NIST SP 1065 §5.3 with a stride), a few per cent of the estimate at the fit's longest τ.
The fit (``fit.fit_noise``) is the same function on either curve, but its decisions are
thresholds (the presence test at z 2.33, the longest-τ and beyond-the-fit checks, flicker
against random walk): where the record sits near one, the two curves fall on either side of
it, and the live fit claimed B, K or R where analyze of the same samples did not (7 of 216
axes of 12 quiet-lab seeds at 10–75 min; issue 24). So a decimated curve's claim must hold
with that much to spare (``decimation_guard``):

* **a margin on every threshold.** The curve is fitted again with the presence level
  raised by ``DECIMATION_MARGIN_Z`` (every test of the fit takes its level from it); a term
  claimed at the fit's own level but not at the raised one is "not yet resolved". The z of
  a claimed term moved by 0.07 (standard deviation) between the two curves on 78 axes.
* **another reading as good.** A claimed bias instability, rate random walk or rate ramp
  (the terms that make the long end of the curve) is fitted away: when the curve refitted
  without it (the other terms free to take its place) is within the margin's Δχ²,
  (2.33 + 0.5)² − 2.33², in Gaussian likelihood (χ² + ln det C, each model with its own
  covariance), the record reads as well without it, and which of the two readings a fit
  picks rests on a few per cent at its longest τ: "not yet resolved" too. K and R read the
  long end together: one of them in doubt flags the other (as ``fit.with_long_tau_refuted``
  does).

Measured on 252 axes of quiet-lab, datasheet and paper-table3 records of 10 min–2 h: the
live claims analyze's of the same samples did not make went from 6 to 0; what it costs is
claims held back ("not yet resolved" where analyze claims): none of paper-table3's strong
B and K, most of quiet-lab's B and K (its air-conditioning and warm-up read as noise),
3 of 18 on 2 h of datasheet noise (docs/log/analysis.md, "One fit, live and offline").

The flagged term keeps its value in the model (the curve needs it) and shows no interval
and no time to target; ``signal_edf`` counts only resolved terms, so the printed EDF then
reads it as noise. An undecimated curve (analyze's OADEV) is the reference and is returned
as fitted.

The printed intervals at each τ: ``signal_edf.with_signal_edf`` (the EDF the fit supports),
the same call analyze makes, on the guarded fit.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
from avard.core.analysis.signal_edf import with_signal_edf
from avard.core.errors import FitError

if TYPE_CHECKING:
    from avard.core.allan.deviations import AllanResult
    from avard.core.model.fit import NoiseFit

__all__ = ["DECIMATION_MARGIN_Z", "NEAR_THRESHOLD", "OTHER_READING", "ChannelFit",
           "decimation_guard", "fit_channel", "is_not_resolved"]

#: What a decimated curve's claim must clear above each of the fit's thresholds, in the
#: presence test's z: the cascade's z of a claimed term differed from the OADEV's by 0.07
#: (standard deviation; at most 0.16) over 78 quiet-lab and datasheet axes, so 0.5 is about
#: seven of them.
DECIMATION_MARGIN_Z = 0.5
#: The long-end terms a record of minutes can read one for another.
LONG_END_TERMS = ("bias_instability", "rate_random_walk", "rate_ramp")
#: Note on a term claimed at the fit's level but not with the decimation's margin.
NEAR_THRESHOLD = ("not yet resolved: the service's decimated Allan curve shows this term only "
                  "near the fit's threshold, where analyze's full curve of the same samples "
                  "may fall on the other side; a longer record, or avard analyze, decides")
#: Note on a long-end term the curve reads as well without (another term takes its place).
OTHER_READING = ("not yet resolved: the curve fits as well without this term (another "
                 "long-τ term takes its place); a longer record decides")


def is_not_resolved(note: str | None) -> bool:
    """Whether a term's note says "not yet resolved" (``fit.NOT_RESOLVED`` or this
    module's): displays then show the value without an interval or a time to target."""
    return note is not None and note.startswith("not yet resolved")


@dataclass(frozen=True)
class ChannelFit:
    """One channel's fit and its Allan curve with the EDF and bounds the fit supports
    (``signal_edf.with_signal_edf``): what analyze prints, on the live snapshot."""

    fit: NoiseFit
    allan: AllanResult


def _decimated(allan: AllanResult) -> bool:
    stride = np.asarray(getattr(allan, "stride", np.ones(1)))
    return bool(np.any(stride > 1))


def _claimed(fit: NoiseFit) -> list[str]:
    return [k for k, t in fit.terms.items() if t.present and t.note is None]


def _neg_log_lik(fit: NoiseFit) -> float:
    return fit.chi2_dof * fit.dof + fit.log_det_cov if fit.dof > 0 else math.nan


def decimation_guard(fit: NoiseFit, allan: AllanResult, *, fit_kw: Mapping[str, object],
                     terms: Sequence[str] | None = None) -> NoiseFit:
    """``fit`` of ``allan`` with the claims a decimated curve cannot hold flagged "not yet
    resolved" (module docstring); ``fit`` itself when the curve is not decimated or every
    claim holds. ``fit_kw``: the keywords ``fit`` was made with (``fit.fit_noise``'s)."""
    from avard.core.model.fit import fit_noise
    from avard.core.model.terms import TERMS

    if not _decimated(allan):
        return fit
    claimed = _claimed(fit)
    if not claimed:
        return fit
    all_terms = tuple(TERMS if terms is None else terms)
    kw = dict(fit_kw)
    if fit.filter_corner_hz is None:
        kw["filter_corner_hz"] = None  # fit_noise found the record has no such filter
    notes: dict[str, str] = {}
    try:
        strict = fit_noise(allan, terms=all_terms, **{
            **kw, "z_present": fit.z_present + DECIMATION_MARGIN_Z})  # type: ignore[arg-type]
        kept = set(_claimed(strict))
    except FitError:
        kept = set()
    notes.update({t: NEAR_THRESHOLD for t in claimed if t not in kept})
    nll = _neg_log_lik(fit)
    # the likelihood margin the decimation can move: the presence test's Δχ² = z² moved by
    # the margin on z
    crit = (fit.z_present + DECIMATION_MARGIN_Z) ** 2 - fit.z_present ** 2
    for t in claimed:
        if t in notes or t not in LONG_END_TERMS or not math.isfinite(nll):
            continue
        try:
            other = fit_noise(allan, terms=[u for u in all_terms if u != t],
                              **kw)  # type: ignore[arg-type]
        except FitError:
            continue
        same_range = (other.tau_min_s, other.tau_max_s) == (fit.tau_min_s, fit.tau_max_s)
        if same_range and _neg_log_lik(other) < nll + crit:
            notes[t] = OTHER_READING
    if not notes:
        return fit
    # the long end is read by K and R together (``fit.with_long_tau_refuted`` flags both):
    # one of them in doubt leaves the other's reading of that end in doubt too
    from avard.core.model.fit.results import LONG_TAU_TERMS

    doubt = [notes[t] for t in LONG_TAU_TERMS if t in notes]
    if doubt:
        notes.update({t: doubt[0] for t in LONG_TAU_TERMS if t in claimed and t not in notes})
    return replace(fit, terms={k: replace(v, note=notes[k]) if k in notes else v
                               for k, v in fit.terms.items()})


def fit_channel(allan: AllanResult, *, ci: float = 0.683,
                filter_corner_hz: float | None = None, **fit_kw: object) -> ChannelFit:
    """THE fit of one channel's Allan curve as the live views show it: ``fit.fit_noise``,
    ``decimation_guard`` on a decimated curve, and the curve with the EDF the fit supports
    (``signal_edf.with_signal_edf``, analyze's rule). ``FitError`` when it cannot be fitted."""
    from avard.core.model.fit import fit_noise

    kw = {"ci": ci, "filter_corner_hz": filter_corner_hz, **fit_kw}
    fit = decimation_guard(fit_noise(allan, **kw), allan,  # type: ignore[arg-type]
                           fit_kw=kw)
    return ChannelFit(fit, with_signal_edf(allan, fit))

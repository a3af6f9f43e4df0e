"""analyze's test of a fitted rate ramp against the TOTVAR out to T/2 (issue 24).

The fit reads the long-τ terms from the OADEV it was given. analyze's OADEV stops at N/4
(Stable32's range), one octave beyond the fit (which keeps τ with ≥ 8 averages), so the fit's
own refutation (``fit._refuted_beyond``) has one point to test a ramp against; the service's
cascade reaches N/2.3 and has two. On 12 seeds × 41 and 55 min × 3 axes of ``quiet-lab``
(no ramp) analyze claimed a ramp resolved on 5 of 72 axes against the live fit's 2
(``python -m benchmarks ramp_refute``).

So when a fit claims R resolved, the channel is read once more and its TOTVAR (NIST SP 1065
eq. 25, which reaches T/2 with more EDF than the OADEV there) is computed at the octave τ
beyond the fit, out to T/2, on the channel averaged to at most ``DECIMATED_POINTS`` (the
estimator at τ ≥ T/8 barely changes when its differences are r samples apart instead of
one: τ ≥ 4096·r·τ0 there). The fitted model is tested against it with the one refutation of the
long-τ terms (``fit.refuted_by``: non-central χ² with the model's own uncertainty), each
component's part of the expectation carried through TOTVAR's bias (``fit.LongTauCurve``),
and the EDF is SP 1065 Table 7's for the model's dominant noise type at that τ. Refuted, the
long-τ terms are flagged "not yet resolved", as the live fit flags them.

Only a ramp triggers the re-read (a record with only a rate random walk is not read again,
which keeps analyze's cost on long records, where K is usual): K, itself noise, scatters too
much at two to eight averages to be refuted this way (``fit._deficit_z``). A record that
cannot be read again (a one-shot stream) is not tested; the fit stands as the OADEV gave it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable

import numpy as np
from avard.core.allan.edf import edf_total
from avard.core.allan.extension import centred_phase, decimate
from avard.core.allan.total import ramp_totvar_ratio, totvar_sums
from avard.core.model.fit import (
    CAUSE_ALPHA,
    LongTauCurve,
    NoiseFit,
    refuted_by,
    with_long_tau_refuted,
)
from numpy.typing import NDArray

__all__ = ["DECIMATED_POINTS", "check_ramp", "totvar_curve"]

#: The channel is averaged by the smallest power of two that leaves at most this many points.
DECIMATED_POINTS = 1 << 16
_Blocks = Iterable[tuple[NDArray[np.float64], bool]]


def check_ramp(fit: NoiseFit, read: Callable[[], _Blocks], n_samples: int, rate_hz: float, *,
               min_averages: float = 8.0) -> NoiseFit:
    """``fit`` as it is, or with its long-τ terms flagged "not yet resolved" when it claims
    a rate ramp resolved that the channel's TOTVAR beyond the fit refutes. ``read()``: the
    channel read again ((n, 1) samples, True where a segment ends); called (and the record
    opened again) only when a ramp is claimed."""
    ramp = fit.terms.get("rate_ramp")
    if ramp is None or not ramp.present or ramp.note is not None:
        return fit
    curve = totvar_curve(fit, read(), n_samples, rate_hz, min_averages=min_averages)
    if curve is None or not refuted_by(fit, curve):
        return fit
    return with_long_tau_refuted(fit)


def totvar_curve(fit: NoiseFit, blocks: _Blocks, n_samples: int, rate_hz: float, *,
                 min_averages: float = 8.0) -> LongTauCurve | None:
    """The TOTVAR of the channel at the octave τ beyond ``fit`` (fewer than
    ``min_averages`` averages, longer than its longest τ) and at T/2, on the longest segment
    of ``blocks``; None when no such τ exists."""
    r = 1 << max(0, math.ceil(math.log2(max(1, n_samples) / DECIMATED_POINTS)))
    y = _longest_segment(blocks, r)
    n_phase = y.shape[0] + 1
    reach = (n_phase - 1) // 2
    if reach < 1:
        return None
    octaves = 2 ** np.arange(int(math.log2(reach)) + 1)
    ms = np.unique(np.append(octaves, reach))
    ms = ms[(ms * r / rate_hz > fit.tau_max_s * (1 + 1e-9)) & ((n_phase - 1) / ms < min_averages)]
    if ms.size == 0:
        return None
    x = centred_phase(y)
    tau = ms * r / rate_hz
    var = np.empty(ms.size)
    for k, m in enumerate(ms.tolist()):
        s, c = totvar_sums(x, m)
        var[k] = s / (2.0 * m * m * c)
    edf = np.array([edf_total("totvar", _dominant_alpha(fit, t), int(m), n_phase)
                    for t, m in zip(tau, ms, strict=True)])
    ramp = np.array([ramp_totvar_ratio(n_phase, int(m)) for m in ms])
    ok = np.isfinite(var) & (var > 0) & np.isfinite(edf) & (edf > 0)
    return LongTauCurve("totvar", tau[ok], var[ok], edf[ok], record_s=(n_phase - 1) * r / rate_hz,
                        ramp_factor=ramp[ok])


def _dominant_alpha(fit: NoiseFit, tau: float) -> int:
    """α (Table 7's row) of the fitted noise component with the largest AVAR at τ."""
    best, alpha = -math.inf, 0
    for c, th in zip(fit.components, fit.theta, strict=True):
        if c.psd(fit.rate_hz) is None or th <= 0:
            continue
        part = float(th * c.basis(np.array([tau]), fit.rate_hz)[0])
        if part > best:
            # SP 1065 Table 7 has rows for the FM types only: white-like components,
            # quantization included, are read as white FM at long τ
            best, alpha = part, min(0, CAUSE_ALPHA.get(c.cause, 0))
    return alpha


def _longest_segment(blocks: _Blocks, r: int) -> NDArray[np.float64]:
    """r-averages of the longest stretch of ``blocks`` without a segment end (no average
    straddles a gap)."""
    best: NDArray[np.float64] = np.zeros(0)
    pieces: list[NDArray[np.float64]] = []
    rest = np.zeros(0)
    for a, end in blocks:
        col = np.concatenate([rest, np.asarray(a, dtype=np.float64).reshape(-1)])
        k = col.shape[0] // r * r
        if k:
            pieces.append(decimate(col[:k], r))
        rest = col[k:]
        if end:
            best = _longer(best, pieces)
            pieces, rest = [], np.zeros(0)
    return _longer(best, pieces)


def _longer(best: NDArray[np.float64], pieces: list[NDArray[np.float64]]) -> NDArray[np.float64]:
    seg = np.concatenate(pieces) if pieces else np.zeros(0)
    return seg if seg.shape[0] > best.shape[0] else best

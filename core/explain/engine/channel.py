"""One axis explained: its causes tested, claimed, removed and the noise refitted."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from avard.core.analysis.results import Analysis, ChannelAnalysis
from avard.core.analysis.spectrum import LineGroup, line_components, line_groups
from avard.core.errors import FitError
from avard.core.explain import causes as cz
from avard.core.explain import coupling_change as cchange
from avard.core.explain.causes import Finding
from avard.core.explain.engine.compound import _compound, _label, _rounding_gain
from avard.core.explain.engine.misfit import _used, misfit_ranges
from avard.core.explain.engine.removal import (
    _noise_levels,
    _signal_variations,
    _thermal_signal,
    removal_covariance,
    removed_avar,
)
from avard.core.explain.engine.results import ChannelExplanation
from avard.core.explain.engine.slow import MIN_SLOW_POINTS
from avard.core.explain.engine.thermal import _thermal_keep
from avard.core.explain.gauss_markov import scan_gauss_markov
from avard.core.explain.thermal_fit import (
    ThermalFit,
    signal_avar_on,
)
from avard.core.io.screen import ScreenLog
from avard.core.model.fit import NoiseFit, fit_noise
from numpy.typing import NDArray


def _explain_channel(ch: ChannelAnalysis, y_slow: NDArray, rate_b: float,
                     temps: NDArray | None, thermal: ThermalFit | None, an: Analysis,
                     meta: dict[str, Any], always_compensate: bool = False,
                     holes: ScreenLog | None = None,
                     settled: NDArray | None = None) -> ChannelExplanation:
    allan = ch.allan
    tau = np.asarray(allan.tau, dtype=float)
    base = ch.fit
    used = _used(base, tau)
    model_v = base.model_avar(tau)
    misfit = misfit_ranges(tau[used], allan.var[used], model_v[used], allan.edf[used])
    findings: list[Finding] = []
    curves: dict[str, NDArray[np.float64]] = {}
    signal = np.zeros(len(y_slow))
    with_start = False
    comp_var: NDArray[np.float64] | None = None
    thermal_only: NDArray[np.float64] | None = None
    work = y_slow
    if len(y_slow) >= MIN_SLOW_POINTS:
        if thermal is not None and temps is not None:
            f = thermal.finding()
            f.claimed = thermal.passed
            findings.append(f)
            if thermal.passed or always_compensate:
                d, with_start = _thermal_signal(thermal, temps, y_slow, rate_b, settled)
                thermal_only = removed_avar(allan.var, tau, y_slow, d, rate_b)
                if thermal.passed:
                    signal += d
                    curves["temperature"] = signal_avar_on(d, rate_b, tau)
        work = y_slow - signal
    corner = an.meta.get("filter_corner_hz")
    lsb = meta.get("lsb_mps2")
    kw: dict[str, Any] = {}
    if corner is not None and isinstance(lsb, int | float) and lsb > 0:
        kw["rounding_lsb"] = float(lsb)
    extra: list[dict[str, Any]] = [{"cause": "sinusoid", "params": ln}
                                   for ln in line_components(ch.lines)]

    # the transients' search asks for the same removed signal more than once (nothing
    # found: the search's first noise and the drift test's are both "nothing removed"); each
    # answer costs an Allan pass over the slow view and a GLS fit, so it is kept by content
    # (and by the Gauss–Markov time constant the noise carries, ``gm_T``)
    noise_seen: dict[tuple[float, bytes], dict[str, float]] = {}
    gm_T = 0.0

    def noise_without(d: NDArray[np.float64]) -> dict[str, float]:
        """N, B, K of analyze's model fitted to the axis with the thermal signal and ``d``
        removed: each transient is tested against noise with the others (and itself) out.
        Where a Gauss–Markov process was claimed on the axis (``gm_T`` > 0), its σ at that
        T is fitted beside them and carried (``GM_sigma``, ``GM_T``): left out, its bump is
        read as random walk, and a step under a walk is one increment (the rounds below)."""
        key = (gm_T, np.ascontiguousarray(d, dtype=float).tobytes())
        if key not in noise_seen:
            noise_seen[key] = _noise_of_removed(d)
        return dict(noise_seen[key])

    def _noise_of_removed(d: NDArray[np.float64]) -> dict[str, float]:
        if not np.any(d) and not np.any(signal) and not gm_T:
            return _noise_levels(base)
        cv = removed_avar(allan.var, tau, y_slow, signal + d, rate_b)
        ratio = cv / np.where(allan.var > 0, allan.var, 1.0)
        comp = ([{"cause": "gauss_markov", "params": {"T": gm_T}}] if gm_T else [])
        try:
            fit = fit_noise(replace(allan, var=cv, lo=allan.lo * ratio, hi=allan.hi * ratio),
                            filter_corner_hz=corner, extra=[*extra, *comp], **kw)
        except FitError:
            return _noise_levels(base)
        out = _noise_levels(fit)
        if gm_T:
            gm_e = next(e for e in fit.extra if e["cause"] == "gauss_markov")
            sigma = gm_e["params"].get("sigma")
            out["GM_sigma"] = float(sigma) if gm_e["present"] and sigma else 0.0
            out["GM_T"] = gm_T
        return out

    # the covariance of the compensated points that the removed signal's parameters carry
    # (``removal_covariance``): set by each ``extend``, given to every fit of those points
    added: NDArray[np.float64] | None = None

    def extend(cands: list[cz.Candidate]) -> tuple[NDArray[np.float64], NoiseFit, Any]:
        """(compensated AVAR, extended fit, its Allan result) with the thermal signal and the
        passed transients ``cands`` removed, from the Allan covariance of the axis and that
        signal; refitted exactly as analyze fits (its terms, lines, filter, LSB)."""
        nonlocal added
        total = signal.copy()
        for i, c in enumerate(cands):
            d = cz.cause_signal(c, len(y_slow), rate_b)
            total += d
            curves[_label(c, i, cands)] = signal_avar_on(d, rate_b, tau)
        keep = _thermal_keep(thermal if "temperature" in curves else None, holes,
                             len(y_slow), rate_b)
        cv = removed_avar(allan.var, tau, y_slow, total, rate_b, keep)
        ratio = cv / np.where(allan.var > 0, allan.var, 1.0)
        comp = replace(allan, var=cv, lo=allan.lo * ratio, hi=allan.hi * ratio)
        # the removed signal's parameters are estimates: their uncertainty enters the same
        # GLS fit as a covariance of the compensated points (one set of intervals)
        added = removal_covariance(
            allan.var, tau, y_slow, total, rate_b,
            _signal_variations(thermal if "temperature" in curves else None, temps,
                               y_slow if settled is None else y_slow - settled,
                               with_start, cands, rate_b), keep)
        try:
            fit = fit_noise(comp, filter_corner_hz=corner, extra=extra, added_cov=added,
                            **kw)
        except FitError as exc:
            raise FitError(f"channel {ch.name}, the model with the found causes: {exc}") \
                from exc
        return cv, fit, comp

    start = 0.0
    if with_start and thermal is not None:
        # what the lag filter's fitted start state can leave: the removed signal's swing
        # over its first three lags
        head = signal[:max(2, math.ceil(3 * abs(thermal.lag_s) * rate_b))]
        start = float(np.ptp(head))
    thermal_curve = {k: v for k, v in curves.items() if k == "temperature"}

    def one_round() -> _Round:
        """The transients (with the noise ``noise_without`` gives at the current ``gm_T``),
        the model extended by them, and the Gauss–Markov scan of what is left."""
        nonlocal added
        curves.clear()
        curves.update(thermal_curve)
        added = None
        trans: list[cz.Candidate] = []
        missed: list[cz.Candidate] = []
        change = None  # coupling_change: whether one coupling describes the record
        if len(y_slow) >= MIN_SLOW_POINTS:
            trans, missed = _compound(work, rate_b, noise_without, thermal, holes, start)
            change, trans, missed = cchange.check(y_slow, temps, thermal, trans, missed, work,
                                                  rate_b, noise_without, holes)
        cv: NDArray[np.float64] | None = None
        ext: NoiseFit = base
        current: Any = allan
        if curves or trans:
            cv, ext, current = extend(trans)
        gm, gm_fit = scan_gauss_markov(current, ext, corner, extra,
                                       kw if added is None else {**kw, "added_cov": added})
        gm, gm_fit = _gm_floors(gm, gm_fit, thermal, temps)
        return _Round(trans, missed, change, cv, ext, current, gm, gm_fit, dict(curves))

    rnd = one_round()
    # an effect must not raise the floor that hides another (issue 23, item 3), across the
    # cause families: the transients are searched before the Gauss–Markov scan, on a noise
    # of N, B, K alone, where a Gauss–Markov bump reads as random walk and hides a step many
    # σ tall. Once a process is claimed the search runs again with it in the noise (its T
    # from the scan, its σ refitted with each removed signal), and the scan again on what
    # that search leaves, until the process's T stays inside its interval (``GM_ROUNDS``).
    for _ in range(GM_ROUNDS):
        if not rnd.gm.claimed or len(y_slow) < MIN_SLOW_POINTS:
            break
        T = float(rnd.gm.params["time_constant_s"])
        if gm_T:
            t_lo, t_hi = rnd.gm.intervals.get("time_constant_s", [T, T])
            if t_lo <= gm_T <= t_hi:
                break
        gm_T = T
        rnd = one_round()
    curves.clear()
    curves.update(rnd.curves)
    comp_var, ext, current, gm, gm_fit = rnd.comp_var, rnd.ext, rnd.current, rnd.gm, rnd.gm_fit
    trans = rnd.trans + rnd.missed
    for cand in trans:
        findings.append(Finding(cand.cause, cand.passed, dict(cand.params),
                                dict(cand.intervals) if cand.passed else {},
                                cand.statistic, cand.threshold, cand.evidence))
    findings.append(gm)
    if gm_fit is not None:
        ext = gm_fit
    change = rnd.change
    findings += [_periodic_finding(g) for g in line_groups(ch.lines)]
    findings = cchange.mark(change, findings)
    out = ChannelExplanation(ch.name, ch, ext, findings, misfit, thermal, comp_var, curves,
                             thermal_only)
    if ext is not base:
        ext_var = np.asarray(current.var, dtype=float)
        eu = _used(ext, tau)
        out.ext_misfit = misfit_ranges(tau[eu], ext_var[eu], ext.model_avar(tau)[eu],
                                       allan.edf[eu])
    else:
        out.ext_misfit = misfit
    if comp_var is not None:
        out.compensation_worse_s = out._worse(comp_var)
    return out


#: Most extra rounds of the transient search with a claimed Gauss–Markov process in its noise.
GM_ROUNDS = 2


@dataclass
class _Round:
    """One round of ``_explain_channel``'s transient search, extension and Gauss–Markov scan."""

    trans: list[cz.Candidate]
    missed: list[cz.Candidate]
    change: Any
    comp_var: NDArray[np.float64] | None
    ext: NoiseFit
    current: Any
    gm: Finding
    gm_fit: NoiseFit | None
    curves: dict[str, NDArray[np.float64]]


def _gm_floors(gm: Finding, gm_fit: NoiseFit | None, thermal: ThermalFit | None,
               temps: NDArray | None) -> tuple[Finding, NoiseFit | None]:
    """The Gauss–Markov finding with the floors of an axis with a claimed coupling: the
    logged temperature's rounding through it, and a relay's (``PathFit.relay_floor``)."""
    # a bump that passed the scan's statistic, claimed or not for another reason (T not
    # located): the rounding floor is said too, it is the reason that holds for the bump's σ
    if ((gm.claimed or gm.statistic >= gm.threshold) and thermal is not None
            and thermal.passed):
        floor = cz.gauss_markov_rounding_floor(_rounding_gain(thermal), thermal.grid[0])
        # and where a relay is chosen or named beside the path kept, what its switch times
        # leave (``PathFit.relay_floor``): the removed relay's switch times are uncertain by
        # its own intervals, and one lag kept leaves a named relay's odd harmonics
        rf, rwhy = ((0.0, "") if thermal.path is None or temps is None
                    else thermal.path.relay_floor(temps[:, thermal.channel_index]))
        if gm.params.get("sigma", 0.0) < floor:
            gm = replace(gm, claimed=False, intervals={} if gm.claimed else gm.intervals,
                         evidence=gm.evidence + (
                f"; not claimed: σ is below {floor:.3g} m/s², the RMS of the logged "
                f"temperature's {thermal.grid[0]:g} K rounding through the coupling "
                f"({_rounding_gain(thermal):.3g} m/s²/K), which can look like a bump"))
            gm_fit = None
        elif gm.params.get("sigma", 0.0) < rf:
            gm = replace(gm, claimed=False, intervals={} if gm.claimed else gm.intervals,
                         evidence=gm.evidence + f"; not claimed: σ is below {rwhy}")
            gm_fit = None
    return gm, gm_fit


def _periodic_finding(g: LineGroup) -> Finding:
    """One periodic disturbance of analyze's line finder (``spectrum.line_groups``) as one
    finding: a steady line alone is a "sinusoid"; a line with harmonics or sidebands, or a
    drifting line, is "periodic", with its harmonics, modulation and frequency band."""
    params = {"frequency_hz": g.frequency_hz, "amplitude": g.amplitude}
    iv = ({"amplitude": [g.amplitude_lo, g.amplitude_hi]}
          if math.isfinite(g.amplitude_lo) and math.isfinite(g.amplitude_hi) else {})
    what = [f"{g.kind}: {g.members} line(s) of analyze's line finder (spectrum.find_lines) "
            "taken as one disturbance"]
    if len(g.harmonics) > 1:
        params["harmonics"] = float(len(g.harmonics))
        what.append("harmonics " + ", ".join(str(k) for k in g.harmonics))
    if g.modulation_hz is not None:
        params["modulation_hz"] = g.modulation_hz
        what.append(f"sidebands ±{g.modulation_hz:.4g} Hz (a modulation)")
    if g.band_hz is not None:
        params["frequency_lo_hz"], params["frequency_hi_hz"] = g.band_hz
        what.append(f"its frequency moves over {g.band_hz[0]:.5g}–{g.band_hz[1]:.5g} Hz; the "
                    "amplitude is that of the band's whole power")
    cause = "periodic" if len(what) > 1 else "sinusoid"
    return Finding(cause, True, params, iv, math.nan, math.nan,
                   "; ".join(what) + "; part of the base model (analyze's sinusoids)")

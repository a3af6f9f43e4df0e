"""One axis explained: its causes tested, claimed, removed and the noise refitted."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from avard.core.analysis.results import Analysis, ChannelAnalysis
from avard.core.analysis.slow_sine import SlowSine, avar_cov
from avard.core.analysis.spectrum import LineGroup, line_components, line_groups
from avard.core.errors import FitError
from avard.core.explain import alarm
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
    # the covariance of the AVAR points that a slow sinusoid's estimated amplitude and
    # frequency carry, once one is resolved beside a Gauss–Markov process (below)
    sine_added: NDArray[np.float64] | None = None

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
        if sine_added is not None:
            added = added + sine_added
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
        acov = added if added is not None else sine_added
        gm, gm_fit = scan_gauss_markov(current, ext, corner, extra,
                                       kw if acov is None else {**kw, "added_cov": acov})
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
    # the same rule for a slow sinusoid: analyze's search (``slow_sine.py``) holds no
    # Gauss–Markov process in its noise, so the process's variance went to the walk it
    # profiles and hid the sinusoid, which the extended fit then read as random walk. Once a
    # process is claimed, the search runs again on the slow view less the claimed signals,
    # with the process in its covariance; a sinusoid resolved there joins the fit's
    # sinusoids and the round is run once more beside it.
    slow_found: Finding | None = None
    if rnd.gm.claimed and len(y_slow) >= MIN_SLOW_POINTS:
        slow_found, comp_sine, sine = _slow_sine_beside_gm(ch, an, work, rnd, rate_b)
        if comp_sine is not None and sine is not None:
            extra.append(comp_sine)
            sine_added = avar_cov(sine, tau)
            noise_seen.clear()
            again = one_round()
            if again.gm.claimed:
                rnd = again
            else:  # the process went with the sinusoid: neither is kept from this search
                extra.pop()
                sine_added = None
                noise_seen.clear()
                slow_found = None
    curves.clear()
    curves.update(rnd.curves)
    comp_var, ext, current, gm, gm_fit = rnd.comp_var, rnd.ext, rnd.current, rnd.gm, rnd.gm_fit
    trans = rnd.trans + rnd.missed
    for cand in trans:
        findings.append(Finding(cand.cause, cand.passed, dict(cand.params),
                                dict(cand.intervals) if cand.passed else {},
                                cand.statistic, cand.threshold, cand.evidence))
    findings.append(gm)
    if slow_found is not None:
        findings.append(slow_found)
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


def _slow_sine_beside_gm(ch: ChannelAnalysis, an: Analysis, work: NDArray, rnd: _Round,
                         rate_b: float
                         ) -> tuple[Finding | None, dict[str, Any] | None, SlowSine | None]:
    """analyze's slow-sinusoid search (``slow_sine.search_slow_sine``) on the block means of
    ``work`` (the slow view less the thermal signal) less the round's claimed transients,
    with the round's claimed Gauss–Markov process (σ, T) in its noise and N, B of the fit
    beside it: (the finding, the sinusoid as a fit component with the search's amplitude
    fixed, the sinusoid) where one is resolved and neither analyze's search nor its line
    finder has it already; else Nones. The amplitude is the search's, not refitted on the
    AVAR: there a sinusoid of a few cycles per record and the walk share the long τ, and
    the fit may give either all of it (as analyze's ``resolve_slow_sine``, which removes
    the sinusoid's AVAR and carries its uncertainty, ``slow_sine.avar_cov``)."""
    from avard.core.analysis.drift import DRIFT_BLOCKS, _k_upper
    from avard.core.analysis.slow_sine import LINE_BINS, search_slow_sine, welch_top_hz
    from avard.core.analysis.spectrum import LINE_LOBE

    if ch.slow is not None and ch.slow.sine is not None:
        return None, None, None
    sigma = float(rnd.gm.params.get("sigma", 0.0))
    T = float(rnd.gm.params.get("time_constant_s", 0.0))
    fit = rnd.gm_fit if rnd.gm_fit is not None else rnd.ext
    if not (sigma > 0 and T > 0):
        return None, None, None
    r = np.asarray(work, dtype=float).copy()
    for c in rnd.trans:
        r -= cz.cause_signal(c, len(r), rate_b)
    j = min(DRIFT_BLOCKS, len(r))
    per = len(r) // j
    if per < 1:
        return None, None, None
    means = r[:j * per].reshape(j, per).mean(axis=1)
    if not np.all(np.isfinite(means)):
        return None, None, None
    n_w = float(fit.terms["velocity_random_walk"].value or 0.0)
    # B where the fit beside the process has it, else the most it allows (its upper limit):
    # the process takes some of the flicker's AVAR, and a flicker left out of the search's
    # noise is an excess at the means' long scales that it reads as a slow sinusoid (its
    # confirmation profiles B about this value, none about zero)
    bt = fit.terms["bias_instability"]
    b_i = float((bt.value if bt.present else bt.upper) or 0.0)
    top_hz = welch_top_hz(int(an.n_samples), float(an.rate_hz))
    # explain's own claim, so at its share of the axis's level (analyze's 1 % is the base
    # model's line finder, outside it): a GM bump alone passed the 1 % threshold 1 time in 30
    search = search_slow_sine(means, per / rate_b, n_w, b_i, _k_upper(fit), top_hz,
                              gm=(sigma, T), level=alarm.SLOW_SINE_GM)
    s = search.sine
    if s is None:
        return None, None, None
    bin_hz = top_hz / (LINE_LOBE + 5)
    lines = [float(e["params"]["frequency_hz"]) for e in line_components(ch.lines)]
    if any(abs(f - s.frequency_hz) <= LINE_BINS * bin_hz for f in lines):
        return None, None, None
    params = {"frequency_hz": s.frequency_hz, "amplitude": s.amplitude}
    finding = Finding(
        "sinusoid", True, dict(params),
        {"frequency_hz": [s.frequency_lo_hz, s.frequency_hi_hz],
         "amplitude": [s.amplitude_lo, s.amplitude_hi]},
        search.statistic, search.threshold,
        f"a slow sinusoid of {s.cycles:.3g} cycles per record (period {1.0 / s.frequency_hz:.4g} "
        f"s), below the line finder's band: analyze's slow-sinusoid search on the block "
        f"means less the claimed signals, with the claimed Gauss–Markov process (σ "
        f"{sigma:.3g} m/s², T {T:.3g} s) in its noise (Λ {search.statistic:.3g} against "
        f"{search.threshold:.3g}); modelled in the extended fit beside it")
    return finding, {"cause": "sinusoid", "params": params}, s


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

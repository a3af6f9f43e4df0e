"""The thermal fits of every axis: each channel's one-lag coupling, the path beside the
record's transients, and the samples a log's holes leave."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from avard.core.explain import causes as cz
from avard.core.explain import transients as tr
from avard.core.explain.path_switches import apart_from_path
from avard.core.explain.thermal_fit import (
    ThermalFit,
    fit_thermal_axes,
    with_paths,
)
from avard.core.explain.thermal_fit.axes import path_of
from avard.core.explain.thermal_fit.holes import hole_mask
from avard.core.explain.thermal_paths import (
    both_readings,
    rate_reading,
    reads_as_rate,
    second_path_reading,
)
from avard.core.explain.thermal_paths.readings import holds_beside
from avard.core.io.screen import ScreenLog
from numpy.typing import NDArray


def _thermal_fits(Y: NDArray, temps: NDArray, tnames: list[str], rate_b: float,
                  holes: dict[int, list[tuple[int, int]]] | None,
                  noise: list[dict[str, float]],
                  grids: list[tuple[float, float] | None] | None = None
                  ) -> tuple[list[ThermalFit | None], list[NDArray[np.float64] | None]]:
    """(each axis's thermal model with its path, each axis's warm-up beyond the lag
    filter's start state or None). A warm-up at the record's start is taken over by the
    thermal model's start state (its own settling e^(−t/τ_L), of any size) or, on an axis
    whose warm-up is not near the lag, by a path with a long second lag or a dT/dt term
    (issue 23: a 2.4e-3 m/s², 15-minute warm-up beside a 5-minute lag was read as two paths or
    a rate term, or left unclaimed as the start state's); taken out before the path is
    chosen, it takes a quadratic's or a second path's own start with it. So the one-lag fit
    comes first, a warm-up that passes the compound search's warm-up test against the start
    state (``transients.warmup_beyond_start``) on the axis with that coupling removed gives
    its T, and the path is chosen with the warm-up as a nuisance beside every candidate
    (``thermal_paths.choose_path``'s ``warmups``: its size fitted jointly with each, on the
    axis as recorded). The warm-up is then tested again beside the path chosen, and one that
    passes is ``_explain_channel``'s, which fits no start state beside it. It is claimed, or
    not, by the compound search as any warm-up. ``grids``: each log's (step, origin), None
    for the 12-bit default (``fit_thermal_axes``)."""
    fits = fit_thermal_axes(Y, temps, tnames, rate_b, holes, grids=grids)
    settled: list[NDArray[np.float64] | None] = [None] * len(fits)
    nzs: dict[int, dict[str, float]] = {}
    found: dict[int, tuple[float, ...]] = {}
    first: dict[int, NDArray[np.float64]] = {}
    moved: set[int] = set()  # found only without the one lag's start state
    for a, th in enumerate(fits):
        # every axis: a quadratic or a relay the one lag cannot follow may fail the one-lag
        # test and pass its own (``with_paths``), beside a warm-up as well
        r = Y[:, a] - th.signal(temps)
        # the noise of the axis with the coupling out, by the robust Allan variance that
        # a few large differences (the warm-up's) move little: analyze's fit counts the
        # thermal cycle as noise (K 6× the truth beside a 2e-3 m/s²/K coupling)
        nz = nzs[a] = tr.robust_noise(r, rate_b, noise[a]["N"])
        c = tr.warmup_beyond_start(r, rate_b, nz, th.lag_s)
        if not c.passed and th.lag_s:
            # the one lag's own start state is no reference where the warm-up moved that
            # lag: beside a quadratic a 900 s warm-up pulled it to a lead of −398 s, whose
            # start state e^(−t/398) took the warm-up up (4.4–4.6 σ against 4.64). Found
            # here it is only a nuisance beside the paths; it is tested again beside the
            # path chosen (below) and claimed, or not, by the compound search
            c = tr.warmup_beyond_start(r, rate_b, nz, 0.0)
            if c.passed:
                moved.add(a)
        if c.passed:
            # its T and size refined by the compound search's joint fit, without the
            # start state (the scan's size is the share left beside it)
            c = tr.refine_compound(r, rate_b, nz, [c])[0]
            if c.params["time_constant_s"] > len(Y) / rate_b / 4:
                # refined beyond the scan's longest T (a quarter of the record): a slow
                # trend of the record, not a warm-up to hold beside the paths (T 6105 s on
                # a 4 h record beside a plain 300 s lag: two paths won beside it)
                moved.discard(a)
                continue
            found[a] = (float(c.params["time_constant_s"]),)
            first[a] = cz.cause_signal(c, len(Y), rate_b)
    # the path chosen with the warm-up beside every candidate, its size fitted jointly with
    # each (``choose_path``'s ``warmups``), on the axis as recorded: a warm-up taken out
    # before the choice took a quadratic's own start with it (q·(u − ū)² is largest where
    # the temperature is farthest from its mean, often the record's first minutes: the
    # warm-up came out 1.5× its size, and the quadratic row beside a real warm-up was right
    # on 1 of 40), or a second path's (the two-path + compressor row), and one left in was
    # taken over by a path with a long second lag or a dT/dt term
    out: list[ThermalFit | None] = list(with_paths(fits, Y, temps, holes, warmups=found))
    # what was found may be a path's own start: a second path through the plate's long lag
    # settles with the plate, and one lag leaves that start in its residual (a "warm-up" of
    # T 3266 s on a two-path + compressor record: beside it, two paths ran to their grid's
    # end and a dT/dt term was chosen, where two paths alone predict the record better by
    # 70). So the path is also chosen with nothing beside it, and an extension chosen there
    # whose signal from the logged temperature alone (nothing of free size or time constant)
    # leaves no warm-up beyond the start state explains that start itself: it is kept, and
    # no warm-up, where it also predicts the held-out halves better than one lag by the
    # margin with the warm-up beside it (the two-path + compressor record: by 102, there
    # at its grid's end). One whose gain is the warm-up's is not: the logged temperature
    # settles at the start too, and a dT/dt term with a 424 s lag read a 900 s warm-up
    # beside one lag from that settling (its Δ −55 alone, +1.3 beside the warm-up). Nor is
    # one of the mechanism chosen beside the warm-up: both choices name the same path, and
    # the one with nothing beside it differs only in having read the warm-up into that
    # path's own parameters (a dT/dt term beside a 900 s warm-up: chosen both ways, alone
    # with the rate term taking the warm-up from the temperature's start, r and c 20–40 %
    # off and the warm-up never claimed; or alone two paths of opposite sign that nearly
    # cancel, 381 and 480 s, the dT/dt term's own limit), so the fit made beside the
    # warm-up stands and the warm-up is tested beside it below (``_same_path``) — where
    # the warm-up is still beyond the start state beside that fit; where it is not, it was
    # that path's own start (a second path through the plate's 900 s, chosen both ways:
    # beside the "warm-up", T 2471 s, its L2 came out 628 s, alone 1005 s) and the fit
    # alone, which explains it, is kept as before
    # (only where an extension gains over one lag beside the warm-up as ``_gain_beside``
    # asks, other than the one chosen there where the warm-up stands beside it: elsewhere
    # the choice alone cannot replace it, and it is a second path choice on the axis)
    stands = {a: o is not None and o.passed and tr.warmup_beyond_start(
        Y[:, a] - o.signal(temps), rate_b, nzs[a], o.lag_s).passed
        for a in found if (o := out[a]) is not None and o.mechanism != "one_lag"}
    back = [a for a in found if (o := out[a]) is not None and o.path is not None
            and any(k != "one_lag" and (k != o.mechanism or not stands.get(a, False))
                    and _gain_beside(o, k) for k in o.path.scores)]
    alone = dict(zip(back, with_paths([fits[a] for a in back], Y[:, back], temps, holes),
                     strict=True))
    # two paths in the dT/dt term's limit chosen beside the warm-up are that term's reading
    # where the choice alone reads as the term too (``_rate_beside``): read so before the
    # choice alone is weighed against it, with the warm-up tested beside the term
    for a, th in alone.items():
        if (o := out[a]) is not None and (rr := _rate_beside(o, th)) is not None:
            out[a] = rr
            stands[a] = rr.passed and tr.warmup_beyond_start(
                Y[:, a] - rr.signal(temps), rate_b, nzs[a], rr.lag_s).passed
    for a, th in alone.items():
        o = out[a]
        if (o is not None and th.mechanism != "one_lag"
                and not (stands.get(a, False) and _same_path(th, o))
                and _gain_beside(o, th.mechanism)
                and not tr.warmup_beyond_start(Y[:, a] - th.signal(temps), rate_b, nzs[a],
                                               th.lag_s).passed):
            out[a] = th
            del found[a]
    # the path choice starts from the one lag's fit (its lag, its Allan reference, its
    # test), which the warm-up moved (a 900 s warm-up beside a 300 s lag: 313–345 s; beside
    # a lag of 0, z 5.3 against 6.2 for a coupling at 3× its minimum); where that start
    # chose an extension or failed its test, or its start state took the warm-up up (found
    # only without it: a lead of −398 s kept beside a lag-0 coupling, c 0.57 of the truth),
    # the one lag is refitted without the warm-up's first estimate and the path chosen again
    # beside it; an axis whose one lag passes and stays keeps its fit (a refit is 15 % of
    # explain's CPU on a 12 h quiet-lab record)
    redo = [a for a in found if (th := out[a]) is not None
            and (th.mechanism != "one_lag" or not th.passed or a in moved)]
    base: list[ThermalFit] = list(fits)  # each axis's one lag, the path choice's start
    if redo:
        Yw = Y[:, redo] - np.column_stack([first[a] for a in redo])
        refit = fit_thermal_axes(Yw, temps, tnames, rate_b, holes, grids=grids)
        again = with_paths(refit, Y[:, redo], temps, holes,
                           warmups={i: found[a] for i, a in enumerate(redo)})
        for a, th, b0 in zip(redo, again, refit, strict=True):
            out[a], base[a] = th, b0
    # and so again on the refit's choice; where the choice alone is two paths of their own
    # response and the dT/dt term stands beside the warm-up, or two paths in its limit, the
    # finding names both readings (``thermal_paths.second_path_reading``, ``both_readings``)
    for a in found:
        if (th := out[a]) is not None and (r := _rate_beside(th, alone.get(a))) is not None:
            out[a] = r
        if ((th := out[a]) is not None and th.path is not None
                and (al := alone.get(a)) is not None and al.path is not None
                and (pf := (second_path_reading(th.path, al.path)
                            or both_readings(th.path, al.path))) is not None):
            out[a] = replace(th, path=pf)
    _beside_transients(out, base, Y, temps, holes, found, rate_b, noise)
    # the warm-up is then a cause of its own where it is still beyond the start state beside
    # the path chosen (its T and size refitted there, on the axis less that path's signal)
    for a in found:
        th = out[a]
        if th is None or not th.passed:
            continue
        r = Y[:, a] - th.signal(temps)
        c = tr.warmup_beyond_start(r, rate_b, nzs[a], th.lag_s)
        if c.passed:
            settled[a] = cz.cause_signal(tr.refine_compound(r, rate_b, nzs[a], [c])[0],
                                         len(Y), rate_b)
    return out, settled


def _beside_transients(out: list[ThermalFit | None], base: list[ThermalFit], Y: NDArray,
                       temps: NDArray, holes: dict[int, list[tuple[int, int]]] | None,
                       found: dict[int, tuple[float, ...]], rate_b: float,
                       noise: list[dict[str, float]]) -> None:
    """``out`` with each path whose extension is the whole claim (the one lag failed its own
    test) kept only where an extension is still chosen with the transients the compound
    search finds on the axis (as recorded: nothing coupled is claimed there) beside every
    candidate (``with_paths``'s ``given``); elsewhere the one lag's failed fit, no claim.
    The path choice sees no transient but a warm-up: on a 1 h record with no coupling a
    relay's two or three switches took the warm-up and a bias step, passed its extra term's
    test and predicted the held-out halves better than nothing by the margin, and the axis
    claimed a temperature coupling with hysteresis (issue 23's compound 1 h row). Where one
    lag passes, the coupling's claim stands on its own test, and the path is not asked."""
    for a, th in enumerate(out):
        b0 = base[a]
        if th is None or not th.passed or b0.passed or th.mechanism == "one_lag":
            continue
        y = Y[:, a]
        cands, _ = tr.find_compound(
            y, rate_b, lambda d, y=y, n=noise[a]["N"]: tr.robust_noise(y - d, rate_b, n))
        # less those the path's own switches make: a relay's at every turn of the drive
        # read as excursions, one a cycle, took the relay (``path_switches``)
        out[a], cands = apart_from_path(th, [c for c in cands if c.cause != "drift"], temps)
        # beside those that remain, also where none does: the path must still be chosen
        # with nothing but the warm-up beside it
        sig = tuple(cz.cause_signal(c, len(y), rate_b) for c in cands)
        # the claim is every reading it names (two paths or a dT/dt term, which one drive
        # line does not tell apart: no interval on either): it holds where one of them does
        # (two paths beside a warm-up lost their claim where the dT/dt term named beside
        # them held beside the transients and two paths' lag there left no half to test)
        pf = path_of(b0, y, temps, holes, warmups=found.get(a, ()), given=sig)
        named = (th.mechanism, *(th.path.alternatives if th.path is not None else ()))
        if not any(holds_beside(pf, k) for k in named):
            out[a] = b0


def _same_path(alone: ThermalFit, beside: ThermalFit) -> bool:
    """Whether the path chosen with nothing beside the warm-up (``alone``) is the mechanism
    chosen beside it: the same candidate, or two paths where the dT/dt term was chosen
    beside it and two paths are that term's reading with a parameter more
    (``thermal_paths.reads_as_rate``)."""
    if alone.mechanism == beside.mechanism:
        return True
    return (alone.mechanism == "two_path" and beside.mechanism == "rate"
            and alone.path is not None and beside.path is not None
            and reads_as_rate(alone.path, beside.path))


def _rate_beside(beside: ThermalFit, alone: ThermalFit | None) -> ThermalFit | None:
    """``beside`` (the path chosen with the warm-up beside every candidate) with the dT/dt
    term chosen, where two paths in its limit were chosen there, the term passes every test
    too (``thermal_paths.rate_reading``) and the choice made with nothing beside the warm-up
    (``alone``) reads as the term as well: the term itself, or two paths in its limit. Beside
    a warm-up, two such paths bring two start states of free size and a lag on the
    derivative that take up what the warm-up's fixed shapes leave, and beat a true dT/dt
    term by 6–11 held out; but a second path through a long lag settles at the start as a
    warm-up does, so beside the warm-up two true paths fall into that limit too, and only
    the choice without it, where the record's start is the second path's, tells them: two
    paths of their own response there (not in the limit) leave the choice beside the
    warm-up as it was. None where nothing changes."""
    if beside.path is None or alone is None or alone.path is None:
        return None
    pf = rate_reading(beside.path, alone.path)
    if pf is None:
        return None
    s = pf.chosen
    # where one lag failed its test, the axis's z is the chosen extension's extra term's
    # (``thermal_fit.with_paths``): it becomes the dT/dt term's, not the two paths' it was
    was = beside.path.chosen
    test = {"z": s.z_extra} if math.isclose(beside.z, was.z_extra) else {}
    return replace(beside, path=pf, coefficient=float(s.beta[0]),
                   coef_se=float(s.beta_se[0]), lag_s=float(s.theta[0]),
                   lag_lo=float(s.theta_lo[0]), lag_hi=float(s.theta_hi[0]),
                   lag_open=s.open_end, **test)


def _gain_beside(th: ThermalFit | None, kind: str) -> bool:
    """Whether the path ``kind`` predicts the held-out halves better than one lag by the
    margin an extension needs in ``th``'s path choice (made with a warm-up beside every
    candidate); False where that choice kept no path (one lag failed its test and no
    extension passed)."""
    pf = None if th is None else th.path
    if pf is None or kind not in pf.scores:
        return False
    return pf.scores[kind].heldout < pf.scores["one_lag"].heldout - pf.margin


def _log_holes(log: ScreenLog | None, tnames: list[str], rate_b: float
               ) -> dict[int, list[tuple[int, int]]]:
    """Per temperature column, the (first, last) slow-view blocks (``rate_b`` blocks per
    second) of every hole of a second or more the screen found in that log (a dropout, a
    masked reading, a stuck run): blocks where the log says nothing of the temperature."""
    if log is None:
        return {}
    return {j: log.hole_blocks(nm, rate_b) for j, nm in enumerate(tnames)}


def _thermal_keep(thermal: ThermalFit | None, screen: ScreenLog | None, n: int,
                  rate_b: float) -> NDArray[np.bool_] | None:
    """The slow-view blocks the extended fit's Allan variance reads (None: all) for an axis
    whose claimed thermal cause (``thermal``, None when none is claimed) runs on a logged
    temperature: every hole of a second or more in that log (``_log_holes``) and the lag's
    settling after it (``thermal_fit.hole_mask``, the longest lag of a two-path fit) are
    gaps. There the removed signal is made of interpolated temperature; what it leaves in
    the axis is the hole, never the model's misfit (a hole in a log is not a cause)."""
    if thermal is None or screen is None:
        return None
    holes = _log_holes(screen, [thermal.channel], rate_b).get(0, [])
    lag = abs(thermal.lag_s)
    if thermal.path is not None and thermal.path.kind == "two_path":
        lag = max(abs(x) for x in thermal.path.chosen.theta[:2])
    return hole_mask(n, holes, lag, rate_b)

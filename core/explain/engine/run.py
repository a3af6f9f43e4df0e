"""Explain's entry points: a record source or a block stream in, an Explanation out."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import replace
from typing import Any

import numpy as np
from avard.core.allan.streaming import StreamingAllan
from avard.core.analysis.engine import ProgressFn, analyze
from avard.core.analysis.results import Analysis
from avard.core.blas import one_blas_thread
from avard.core.errors import DataError
from avard.core.explain.engine.channel import _explain_channel
from avard.core.explain.engine.misfit import Block, _why_unused
from avard.core.explain.engine.removal import _noise_levels
from avard.core.explain.engine.results import ChannelExplanation, Explanation
from avard.core.explain.engine.slow import MIN_SLOW_POINTS, Held, SlowView, StageFn, _SlowTap
from avard.core.explain.engine.thermal import _log_holes, _thermal_fits
from avard.core.explain.holdout import (
    Holdout,
    check_compatible,
    holdout_file,
    holdout_split,
)
from avard.core.explain.options import DEFAULT_EXPLAIN, ExplainOptions
from avard.core.explain.thermal_fit import (
    ThermalFit,
)
from avard.core.io.screen import ScreenLog
from avard.core.io.screen.stream import ScreenedSource
from avard.core.io.source import RecordSource, StreamSource
from numpy.typing import NDArray


def _unknown_temperature(temperature: str, meta: dict[str, Any]) -> None:
    tnames = list(meta.get("temperature_names") or [])
    raise DataError(f"temperature channel {temperature!r} is not in this record; its "
                    "temperature channels are " + (", ".join(tnames) or "none"))


@one_blas_thread  # a library entry point (core/blas.py): the pool's workers busy-wait
def explain_file(source: RecordSource, options: ExplainOptions = DEFAULT_EXPLAIN, *,
                 holdout: RecordSource | None = None, progress: ProgressFn | None = None,
                 stage: StageFn | None = None) -> Explanation:
    """Explain ``source`` (``core.io.source.open_record``: an .npz, a CSV or a recording).
    ``options`` are analyze's plus explain's (``ExplainOptions``). ``holdout``: a second
    record of the same sensor (same rate and channels, checked before any work) that the
    models fitted here predict; without it the record's halves predict each other."""
    meta = source.info.as_meta()
    if holdout is not None:
        check_compatible(meta, holdout.info.as_meta(), holdout.info.source)
        _check_scale(source, holdout)
    temperature = options.temperature
    if temperature is not None and temperature not in (meta.get("temperature_names") or []):
        _unknown_temperature(temperature, meta)
    # The base is `avard analyze` of the record itself, the same call: the same passes (one
    # per channel group whose OADEV histories fit its budget, so the same peak memory; one
    # pass over every channel, as explain_stream must do with blocks from anywhere, would
    # hold all axes' histories at once, 3x analyze's peak on a 60 h record). Its first pass
    # reads every column and the temperatures through the one screen and feeds the slow
    # view (``FirstPassTap``): the record is read, screened and its temperatures decoded
    # once. Only a parallel analysis, whose workers read the chunks, leaves the slow view to
    # one more read.
    if not source.rereadable:
        return explain_stream(source, options, holdout=holdout, progress=progress,
                              stage=stage)
    screened = (source if isinstance(source, ScreenedSource)
                else ScreenedSource(source, options.temperature_units))
    tap = _SlowTap(source.info.rate_hz, source.info.n_samples, len(source.info.names),
                   len(source.info.temperature_names))
    an = analyze(screened, options, progress=progress, tap=tap)
    an.meta["screen"] = screened.log      # as analyze says it of a source it screens itself
    if not tap.complete:
        if stage is not None:
            stage("reading the record's slow view (block means)")
        # a fresh screen: the parallel chunks' verdicts told the log nothing of the
        # temperatures, which this read screens
        return explain_stream(source.source if isinstance(source, ScreenedSource) else source,
                              options, holdout=holdout, progress=progress, stage=stage,
                              base=an)
    return _explained(an, tap.slow, screened.log, meta, options, _held(holdout, options, meta),
                      stage)


#: Two records of one sensor whose sample-to-sample noise differs by more than this factor on
#: an axis are not in one unit (a record in g reads 9.81× smaller, in mg 102× larger) or not
#: of one sensor: the held-out test would measure the unit (a gain of −1.4e6 had been printed)
SCALE_RATIO = 8.0


def _noise_scale(source: RecordSource) -> NDArray[np.float64] | None:
    """Each axis's sample-to-sample noise on the record's first block: the robust scale of
    its first differences / √2 (the white and quantisation noise, which no slow drift or
    thermal signal moves); None where the block is too short or the source reads once."""
    if not source.rereadable:
        return None
    for blk in source.blocks(1 << 15):
        a = np.asarray(blk[0], dtype=float).reshape(len(blk[0]), -1)
        d = np.diff(a, axis=0)
        d = d[np.all(np.isfinite(d), axis=1)]
        if len(d) < 64:
            return None
        return np.asarray(1.4826 * np.median(np.abs(d - np.median(d, axis=0)), axis=0)
                          / np.sqrt(2.0), dtype=float)
    return None


def _check_scale(source: RecordSource, holdout: RecordSource) -> None:
    """One line (DataError, exit 2) before any work where the held-out record's noise on an
    axis is more than ``SCALE_RATIO`` times the record's either way."""
    s0, s1 = _noise_scale(source), _noise_scale(holdout)
    if s0 is None or s1 is None or len(s0) != len(s1):
        return
    for name, a, b in zip(source.info.names, s0, s1, strict=True):
        if a > 0 and b > 0 and max(a / b, b / a) > SCALE_RATIO:
            raise DataError(f"--holdout {holdout.info.source}: its sample-to-sample noise on "
                            f"{name} is {b / a:.3g}× the record's ({b:.3g} against {a:.3g} "
                            "m/s²): not the same unit (a record in g reads 9.81× smaller, in "
                            "mg 102× larger) or not the same sensor; give a record of the same "
                            "sensor in m/s²")


def _held(holdout: RecordSource | None, options: ExplainOptions, meta: dict[str, Any]
          ) -> Held | None:
    """The held-out record, checked against this record's, read through the same input
    screen as the record (``ScreenedSource``: the same rules, ``--temperature-units`` alike,
    so a °F log is converted or refused as the record's is): its 85 °C values, read errors
    and spikes are masked, its shocks cut out, its dropouts and stuck runs listed."""
    if holdout is None:
        return None
    h_meta = holdout.info.as_meta()
    check_compatible(meta, h_meta, str(h_meta.get("source", "holdout")))
    screened = (holdout if isinstance(holdout, ScreenedSource)
                else ScreenedSource(holdout, options.temperature_units))
    return h_meta, _unused_held(screened.blocks(options.block), screened,
                                list(h_meta.get("temperature_names") or [])), screened


def _unused_held(blocks: Iterable[Block], screened: ScreenedSource, tnames: list[str]
                 ) -> Iterator[Block]:
    """``blocks`` handed on as they are; once read, each held-out log that the record's rule
    (``_why_unused``) would not use is refused in the held-out screen's log, with that rule's
    reason, so that no prediction runs through it: a log of one value throughout (no
    variation to predict from) predicted the held-out axis as flat and called a correct
    model's gain −3e3 ("UNEXPLAINED") where the record's own side said "not used". Judged on
    the screened readings (each log's least and greatest, and how many), in bounded memory;
    a log the screen refused keeps the screen's reason."""
    k = len(tnames)
    lo, hi = np.full(k, np.inf), np.full(k, -np.inf)
    count = np.zeros(k, dtype=np.int64)
    for blk in blocks:
        temp = blk[1]
        if k and temp is not None and np.asarray(temp).size:
            t = np.asarray(temp, dtype=float).reshape(len(blk[0]), -1)
            fin = np.isfinite(t)
            count += fin.sum(axis=0)
            lo = np.minimum(lo, np.where(fin, t, np.inf).min(axis=0, initial=np.inf))
            hi = np.maximum(hi, np.where(fin, t, -np.inf).max(axis=0, initial=-np.inf))
        yield blk
    log = screened.log
    if log is None:
        return
    for j, nm in enumerate(tnames):
        # fewer than two readings: holdout_file says so itself ("no readings once screened")
        why = None if count[j] < 2 else _why_unused(np.array([lo[j], hi[j]]))
        if why is not None:
            log.refused.setdefault(nm, why)


@one_blas_thread
def explain_stream(source: RecordSource, options: ExplainOptions = DEFAULT_EXPLAIN, *,
                   holdout: RecordSource | None = None, progress: ProgressFn | None = None,
                   stage: StageFn | None = None, base: Analysis | None = None) -> Explanation:
    """``explain_file`` on blocks from anywhere (``core.io.source.StreamSource``: accel
    (n, C) m/s², temperature (n, k) °C or None, segment end). ``holdout``: a second record of
    the same sensor. ``base``: analyze's result for these blocks when the caller has it
    (``explain_file`` after a parallel analysis); the blocks then feed only the slow view."""
    # one screen for the slow view and the analysis: analyze is handed the screened blocks
    screened = (source if isinstance(source, ScreenedSource)
                else ScreenedSource(source, options.temperature_units))
    meta = source.info.as_meta()
    blocks = screened.blocks(options.block)
    held = _held(holdout, options, meta)
    tnames = list(meta.get("temperature_names") or [])
    if options.temperature is not None and options.temperature not in tnames:
        _unknown_temperature(options.temperature, meta)
    tap = _SlowTap(float(meta["rate_hz"]), meta.get("n_samples"), len(meta["names"]),
                   len(tnames))

    def tee() -> Iterator[tuple[NDArray[np.float64], bool]]:
        for accel, temp, end in blocks:
            a = np.asarray(accel, dtype=float).reshape(len(accel), -1)
            tap.update(a, temp)
            yield a, end

    if base is None:
        an = analyze(StreamSource(source.info, ((a, None, end) for a, end in tee())),
                     replace(options, screen=False), progress=progress)
        an.meta["screen"] = screened.log
    else:
        an = base
        for _ in tee():
            pass
    return _explained(an, tap.slow, screened.log, meta, options, held, stage)


def _explained(an: Analysis, slow: SlowView, screen: ScreenLog | None, meta: dict[str, Any],
               options: ExplainOptions, held: Held | None,
               stage: StageFn | None) -> Explanation:
    """The explanation of ``an`` (analyze's result) from the slow view of the same screened
    blocks (``screen``: that screen's log), whichever read fed it."""
    temperature, heldout = options.temperature, options.heldout
    rate = float(meta["rate_hz"])
    names = list(meta["names"])
    tnames = list(meta.get("temperature_names") or [])
    b = slow.b
    rate_b = rate / b
    stuck = [[(x.start_s, x.end_s) for x in screen.stretches
              if x.channel == nm and x.kind == "stuck"] for nm in tnames] if screen else []
    y_slow, t_slow = slow.finish(stuck, rate_b)
    # the channels asked for (all, or ``--temperature``'s), each usable or said why not
    why = {j: _why_unused(None if t_slow is None else t_slow[:, j],
                          None if screen is None else screen.refused.get(tnames[j]))
           for j in range(len(tnames)) if temperature in (None, tnames[j])}
    if len(y_slow) < MIN_SLOW_POINTS:
        # too short for the time-domain causes: every log said unused, with why (a 100 s
        # record with a strong coupling had said "fits" with no word of temperature)
        short = (f"the record's slow view holds {len(y_slow)} blocks of {b / rate:.3g} s, "
                 f"fewer than the {MIN_SLOW_POINTS} the time-domain causes (temperature, "
                 "transients, drift, Gauss–Markov) need: not tested on a record this short")
        why = {j: w if w is not None else short for j, w in why.items()}
    t_ok = [j for j, w in why.items() if w is None]
    unused = {tnames[j]: w for j, w in why.items() if w is not None}
    t_allan: dict[str, Any] = {}
    if t_slow is not None and t_ok and len(t_slow) >= 16:
        sa = StreamingAllan(len(t_ok), rate_b, names=[tnames[j] for j in t_ok])
        sa.update(t_slow[:, t_ok])
        res = sa.result()
        for i, j in enumerate(t_ok):
            t_allan[tnames[j]] = res.channel(i) if len(t_ok) > 1 else res
    cols = [names.index(nm) for nm in an.channels]
    th_fits: list[ThermalFit | None] = [None] * len(cols)
    if t_slow is not None and t_ok and len(y_slow) >= MIN_SLOW_POINTS:
        if stage is not None:
            stage("fitting the thermal model")
        # the screen's holes in each log: gaps of its regression, never the axis's response
        holes = ({i: screen.hole_blocks(tnames[j], rate_b) for i, j in enumerate(t_ok)}
                 if screen is not None else None)
        # each log on its own step and origin (``screen.log_step``): a coarse log's
        # reconstruction and rounding leave a finer log's fit as it is
        grids = [None if screen is None else screen.rounding_grid(tnames[k]) for k in t_ok]
        th_fits, settled = _thermal_fits(y_slow[:, cols], t_slow[:, t_ok],
                                         [tnames[k] for k in t_ok], rate_b, holes,
                                         [_noise_levels(ch.fit) for ch in an.channels.values()],
                                         grids)
    else:
        settled = [None] * len(cols)
    out: dict[str, ChannelExplanation] = {}
    for (name, ch), th, w0 in zip(an.channels.items(), th_fits, settled, strict=True):
        if stage is not None:
            stage(f"explaining channel {name}")
        j = names.index(name)
        out[name] = _explain_channel(ch, y_slow[:, j], rate_b,
                                     None if t_slow is None else t_slow[:, t_ok],
                                     th, an, meta, always_compensate=temperature is not None,
                                     holes=screen, settled=w0)
    if not heldout and held is None:
        for ch_ex in out.values():
            ch_ex.judge(None, screen=screen)
        return Explanation(an, out, t_allan, b / rate, screen=screen,
                           temperature_unused=unused)
    if stage is not None:
        stage("measuring the gain on held-out data")
    ho = _holdout(out, y_slow, t_slow, tnames, names, rate_b, b, meta, held, screen)
    for name, ch_ex in out.items():
        ch_ex.judge(ho.channels.get(name), ho.reason, screen)
    return Explanation(an, out, t_allan, b / rate, ho, screen=screen,
                       temperature_unused=unused)


def _holdout(out: dict[str, ChannelExplanation], y_slow: NDArray, t_slow: NDArray | None,
             tnames: list[str], names: list[str], rate_b: float, b: int, meta: dict[str, Any],
             holdout: Held | None, screen: ScreenLog | None = None) -> Holdout:
    """The held-out measure (:mod:`avard.core.explain.holdout`): the record's halves, or the second
    record streamed through the input screen and a slow view with the same block (bounded
    memory). Each record's screen holes (``screen``: the record's) are gaps to the held-out
    estimators on whichever side of a fold its blocks are, as they are to its own fit."""
    holes = _log_holes(screen, tnames, rate_b)
    if holdout is None:
        return holdout_split(out, y_slow, t_slow, tnames, names, rate_b,
                             str(meta.get("source", "stream")), holes)
    h_meta, h_blocks, h_screened = holdout
    view = SlowView(b, len(names), len(tnames))
    for accel, temp, _end in h_blocks:
        a = np.asarray(accel, dtype=float).reshape(len(accel), -1)
        has_t = tnames and temp is not None and np.asarray(temp).size
        view.update(a, temp if has_t else None)
    log = h_screened.log
    held_rate_b = float(h_meta["rate_hz"]) / b
    # as for the record (``_explained``): a stuck run is no reading of the temperature, and
    # every hole of a second or more is a gap of the held-out Allan variance of an axis
    # whose prediction runs through that log
    stuck = [[(x.start_s, x.end_s) for x in log.stretches
              if x.channel == nm and x.kind == "stuck"] for nm in tnames] if log else []
    y_h, t_h = view.finish(stuck, held_rate_b)
    refused = ({j: log.refused[nm] for j, nm in enumerate(tnames) if nm in log.refused}
               if log is not None else {})
    # each side's τ in seconds of its own fitted rate (the rates agree by core.io.rates' rule,
    # they are not equal)
    return holdout_file(out, y_slow, t_slow, y_h, t_h, tnames, names, rate_b,
                        str(h_meta.get("source", "holdout")), held_rate_b=held_rate_b,
                        held_holes=_log_holes(log, tnames, held_rate_b),
                        held_refused=refused, screen=log)

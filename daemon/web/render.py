"""The page's parts as HTML fragments with SVG drawn here, on the server.

No plotting library and no script reaches the browser for the plots: every fragment is plain
HTML + inline SVG, so the page works offline on a lab network and without JavaScript (the
small hand-written ``static/app.js`` only swaps fragments in when an update arrives). All
text from the service is escaped. SI units everywhere: τ in s, ADEV in m/s², °C, run time in
s/min/h.

Each fragment is a function of a :class:`~avard.daemon.web.state.RunState` (called with its
lock held) and returns a string; :func:`fragments` gives them all, keyed by the id of the page
element they fill.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Iterable, Sequence
from html import escape
from typing import Any

import numpy as np
from avard.core.analysis.live_fit import is_not_resolved
from avard.core.model.terms import SYMBOLS
from avard.daemon.commands.watch import fmt_duration, time_to_target
from avard.daemon.web.state import SILENT_S, RunState, Series, Snapshot

log = logging.getLogger(__name__)

AXES = ("x", "y", "z")
#: Colour per channel (colour-blind-safe Okabe–Ito palette).
COLOURS = {"x": "#0072B2", "y": "#D55E00", "z": "#009E73"}
OTHER_COLOURS = ("#CC79A7", "#E69F00", "#56B4E9", "#000000", "#999999")
GAP_COLOURS = {"overrun": "#D55E00", "bus_error": "#CC79A7", "restart": "#0072B2",
               "disk_full": "#E69F00", "subscriber_loss": "#999999"}
W, H = 640, 400                 # SVG user units; the page scales it to the screen width
# margins: left, right, top, bottom; room for the phone's larger text (style.css) so that no
# tick label meets an axis label at any width (tests/daemon/test_web_browser.py checks 412 px)
ML, MR, MT, MB = 84, 16, 14, 52


def fragments(state: RunState, target: float) -> dict[str, str]:
    """Every fragment of the page (id → HTML)."""
    return {**common_fragments(state), **target_fragments(state, target)}


def common_fragments(state: RunState) -> dict[str, str]:
    """The fragments every viewer shares."""
    return {"status": guarded(status_html, state), "adev": guarded(adev_html, state),
            "separation": guarded(separation_html, state),
            "temps": guarded(temperatures_html, state),
            "timeline": guarded(timeline_html, state)}


def target_fragments(state: RunState, target: float) -> dict[str, str]:
    """The fragments that depend on the viewer's target."""
    return {"fit": guarded(fit_html, state, target),
            "targets": guarded(targets_html, state, target)}


def guarded(part: Callable[..., str], *args: Any) -> str:
    """One fragment; data from a newer or broken service must not end the page (the other
    fragments and later updates go on), so a failure becomes a line in its place."""
    try:
        return part(*args)
    except (ValueError, TypeError, KeyError, IndexError, AttributeError,
            ArithmeticError) as exc:
        log.warning("cannot draw %s: %s: %s", part.__name__, type(exc).__name__, exc)
        return (f'<p class="waiting">Cannot draw this from the data received '
                f"({escape(type(exc).__name__)}: {escape(str(exc))}).</p>")


# ---- numbers ------------------------------------------------------------------------------


def _e(v: float | None, digits: int = 3) -> str:
    return "—" if v is None or not math.isfinite(v) else f"{v:.{digits}e}"


def _g(v: float | None, digits: int = 4) -> str:
    return "—" if v is None or not math.isfinite(v) else f"{v:.{digits}g}"


def _bytes(n: Any) -> str:
    if not isinstance(n, int | float) or n < 0:
        return "unknown"
    for unit, size in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n:.0f} B"


def _unit(unit: str) -> str:
    """SI units as printed: m/s^2 → m/s², m/s/sqrt(s) → m/s/√s."""
    return unit.replace("sqrt(s)", "√s").replace("^2", "²").replace("^3", "³")


def _time_unit(span_s: float) -> tuple[str, float]:
    if span_s < 600:
        return "s", 1.0
    if span_s < 7200:
        return "min", 60.0
    return "h", 3600.0


def _sqrt(a: Any) -> np.ndarray:
    x = np.asarray(a, dtype=float)
    with np.errstate(invalid="ignore"):
        return np.where(np.isfinite(x) & (x >= 0), np.sqrt(np.abs(x)), np.nan)


def _nice_ticks(lo: float, hi: float, n: int = 5) -> list[float]:
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo:
        return [lo] if math.isfinite(lo) else []
    raw = (hi - lo) / n
    mag = 10 ** math.floor(math.log10(raw))
    step = next(s * mag for s in (1, 2, 2.5, 5, 10) if s * mag >= raw)
    first = math.ceil(lo / step) * step
    return [first + k * step for k in range(int((hi - first) / step + 1e-9) + 1)]


class _Frame:
    """A plot area: data → SVG coordinates, axes and grid (log or linear per axis)."""

    def __init__(self, x: tuple[float, float], y: tuple[float, float], *, logx: bool,
                 logy: bool, w: int = W, h: int = H) -> None:
        self.logx, self.logy, self.w, self.h = logx, logy, w, h
        self.x0, self.x1 = (math.log10(v) for v in x) if logx else x
        self.y0, self.y1 = (math.log10(v) for v in y) if logy else y
        if self.x1 <= self.x0:
            self.x1 = self.x0 + 1
        if self.y1 <= self.y0:
            self.y1 = self.y0 + 1

    def px(self, x: float) -> float:
        v = math.log10(x) if self.logx else x
        return ML + (v - self.x0) / (self.x1 - self.x0) * (self.w - ML - MR)

    def py(self, y: float) -> float:
        v = math.log10(y) if self.logy else y
        return self.h - MB - (v - self.y0) / (self.y1 - self.y0) * (self.h - MT - MB)

    def axes(self, xlabel: str, ylabel: str, xfmt: Any = _g, yfmt: Any = _g) -> str:
        out = [f'<rect class="plot-bg" x="{ML}" y="{MT}" width="{self.w - ML - MR}" '
               f'height="{self.h - MT - MB}"/>']
        # a y tick label at the bottom corner and an x tick label at the left one would
        # meet: the corner keeps the y label
        corner = any(self.py(v) > self.h - MB - 12
                     for v in self._ticks(self.y0, self.y1, self.logy))
        for v in self._ticks(self.x0, self.x1, self.logx):
            x = self.px(v)
            label = "" if corner and x < ML + 24 else (
                f'<text class="tick" x="{x:.1f}" y="{self.h - MB + 17}" '
                f'text-anchor="middle">{xfmt(v)}</text>')
            out.append(f'<line class="grid" x1="{x:.1f}" y1="{MT}" x2="{x:.1f}" '
                       f'y2="{self.h - MB}"/>{label}')
        for v in self._ticks(self.y0, self.y1, self.logy):
            y = self.py(v)
            out.append(f'<line class="grid" x1="{ML}" y1="{y:.1f}" x2="{self.w - MR}" '
                       f'y2="{y:.1f}"/><text class="tick" x="{ML - 5}" y="{y + 4:.1f}" '
                       f'text-anchor="end">{yfmt(v)}</text>')
        out.append(f'<text class="label" x="{(ML + self.w - MR) / 2:.0f}" y="{self.h - 8}" '
                   f'text-anchor="middle">{escape(xlabel)}</text>')
        out.append(f'<text class="label" transform="translate(21 {(MT + self.h - MB) / 2:.0f}) '
                   f'rotate(-90)" text-anchor="middle">{escape(ylabel)}</text>')
        return "".join(out)

    @staticmethod
    def _ticks(a: float, b: float, log: bool) -> list[float]:
        if log:
            return [10.0 ** k for k in range(math.ceil(a - 1e-9), math.floor(b + 1e-9) + 1)]
        return _nice_ticks(a, b)


def _svg(body: str, label: str, cls: str, h: int = H) -> str:
    return (f'<svg class="{cls}" viewBox="0 0 {W} {h}" role="img" aria-label="{escape(label)}" '
            f'xmlns="http://www.w3.org/2000/svg">{body}</svg>')


def _path(points: Iterable[tuple[float, float]]) -> str:
    pts = [f"{x:.1f},{y:.1f}" for x, y in points]
    return ("M" + " L".join(pts)) if pts else ""


# ---- ADEV ---------------------------------------------------------------------------------


def _log_range(values: np.ndarray) -> tuple[float, float]:
    v = values[np.isfinite(values) & (values > 0)]
    if not len(v):
        return 1e-6, 1e-3
    return 10 ** math.floor(math.log10(v.min())), 10 ** math.ceil(math.log10(v.max()))


def adev_svg(snap: Snapshot, fits: dict[str, Any], *, title: str = "ADEV") -> str:
    """Log-log ADEV of the x/y/z channels with their intervals and the fitted model curve."""
    d = snap.data
    tau = d.tau
    cols = [(c, n) for c, n in enumerate(d.names) if n in AXES]
    avar, lo, hi = d.avar, d.lo, d.hi
    adev, adev_lo, adev_hi = _sqrt(avar), _sqrt(lo), _sqrt(hi)
    idx = [c for c, _ in cols]
    shown = np.concatenate([adev[:, idx].ravel(), adev_lo[:, idx].ravel(),
                            adev_hi[:, idx].ravel()]) if idx else np.zeros(0)
    ok_tau = tau[np.isfinite(tau) & (tau > 0)]
    frame = _Frame(_log_range(ok_tau), _log_range(shown), logx=True, logy=True)
    body = [frame.axes("τ [s]", "Allan deviation [m/s²]", xfmt=_decade, yfmt=_decade)]
    for c, name in cols:
        colour = COLOURS[name]
        parts = [f'<g class="adev-axis" data-axis="{name}" stroke="{colour}" fill="{colour}">']
        n_points = 0
        for k, t in enumerate(tau):
            v, a, b = adev[k, c], adev_lo[k, c], adev_hi[k, c]
            if not (t > 0 and math.isfinite(v) and v > 0):
                continue
            x, y = frame.px(t), frame.py(v)
            if math.isfinite(a) and math.isfinite(b) and a > 0 and b >= a:
                parts.append(f'<line class="ci" x1="{x:.1f}" y1="{frame.py(a):.1f}" '
                             f'x2="{x:.1f}" y2="{frame.py(b):.1f}"/>')
            parts.append(f'<circle class="pt" cx="{x:.1f}" cy="{y:.1f}" r="3">'
                         f'<title>{name}: τ = {t:.4g} s, ADEV {v:.3e} m/s² '
                         f'[{_e(a)}, {_e(b)}]</title></circle>')
            n_points += 1
        fit = fits.get(name)
        if fit is not None:
            parts.append(_model_path(frame, fit, ok_tau))
        parts.append("</g>")
        body.append("".join(parts).replace('class="adev-axis"',
                                           f'class="adev-axis" data-points="{n_points}"', 1))
    body.append(_legend([(n, COLOURS[n]) for _, n in cols]
                        + ([("model (fit)", "#444")] if fits else []), dashed_last=bool(fits)))
    return _svg("".join(body), title, "plot adev")


def _model_path(frame: _Frame, fit: Any, tau: np.ndarray) -> str:
    """The fitted model's ADEV over the τ range of the plot (dashed)."""
    if not len(tau):
        return ""
    grid = np.geomspace(tau.min(), tau.max(), 80)
    try:
        model = _sqrt(fit.model_avar(grid))
    except (ValueError, TypeError, AttributeError):
        return ""
    pts = [(frame.px(t), frame.py(v)) for t, v in zip(grid, model, strict=True)
           if math.isfinite(v) and v > 0]
    return f'<path class="model" d="{_path(pts)}"/>' if pts else ""


def _decade(v: float) -> str:
    k = round(math.log10(v))
    return "1" if k == 0 else f"10{_superscript(k)}"


def _superscript(k: int) -> str:
    return str(k).translate(str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹"))


def _legend(items: Sequence[tuple[str, str]], *, dashed_last: bool = False) -> str:
    out = ['<g class="legend">']
    x = ML + 8
    for k, (name, colour) in enumerate(items):
        dash = ' stroke-dasharray="5 3"' if dashed_last and k == len(items) - 1 else ""
        out.append(f'<line x1="{x}" y1="{MT + 12}" x2="{x + 18}" y2="{MT + 12}" '
                   f'stroke="{colour}" stroke-width="2.5"{dash}/><text class="tick" '
                   f'x="{x + 22}" y="{MT + 16}">{escape(name)}</text>')
        x += 34 + 11 * len(name)  # room for the larger phone font too
    out.append("</g>")
    return "".join(out)


def adev_html(state: RunState) -> str:
    latest = state.snapshot
    snap = state.shown()   # its fit's intervals (analyze's EDF rule) once it is fitted
    if snap is None:
        return '<p class="waiting">No Allan snapshot yet (the service sends one every ' \
               '<code>allan.snapshot_interval_s</code>).</p>'
    ci = snap.data.ci
    fitted = state.fitted
    note = ("model curve: fit of this snapshot" if fitted is latest else
            "model curve: fit of an earlier snapshot" if fitted is not None else
            "model curve: fit pending")
    out = [f'<p class="note">{snap.n_samples} samples = {fmt_duration(snap.duration_s)} of '
           f'data; bars: {100 * ci:.1f} % intervals; {note}.</p>',
           adev_svg(snap, state.fits if fitted is not None else {})]
    if state.compensated is not None:
        out.append('<h3>Temperature-compensated ADEV</h3>')
        out.append(adev_svg(state.compensated, {}, title="temperature-compensated ADEV"))
    else:
        out.append('<p class="note">Temperature-compensated ADEV: not provided by this '
                   'service.</p>')
    return "".join(out)


# ---- self-noise against common mode ------------------------------------------------------

#: Colours of the co-located sensors' self-noise; the common mode is drawn in COMMON_COLOUR.
SENSOR_COLOURS = ("#0072B2", "#D55E00", "#009E73")
COMMON_COLOUR = "#444444"


def _points(frame: _Frame, tau: np.ndarray, part: Any, label: str, shape: str) -> tuple[
        list[str], int, int]:
    """One separated part's points: an estimate with its interval bar, or, where only an upper
    limit is known, a downward triangle at the limit with a bar down to the plot's floor."""
    out, n_est, n_ul = [], 0, 0
    adev = _sqrt(part.var)
    lo, hi = _sqrt(part.lo), _sqrt(part.hi)
    floor = frame.h - MB
    for k, t in enumerate(tau):
        if not (t > 0 and math.isfinite(hi[k]) and hi[k] > 0):
            continue
        x = frame.px(t)
        if part.upper_limit[k]:
            y = frame.py(hi[k])
            out.append(f'<line class="ci ul" x1="{x:.1f}" y1="{y:.1f}" x2="{x:.1f}" '
                       f'y2="{floor:.1f}" stroke-dasharray="2 3"/><path class="ul" '
                       f'd="M{x - 5:.1f},{y - 4:.1f} L{x + 5:.1f},{y - 4:.1f} L{x:.1f},'
                       f'{y + 4:.1f} Z"><title>{escape(label)}: τ = {t:.4g} s, ADEV '
                       f'below {hi[k]:.3e} m/s² (upper limit: not resolved from 0)</title>'
                       f'</path>')
            n_ul += 1
            continue
        v = adev[k]
        if not (math.isfinite(v) and v > 0):
            continue
        y = frame.py(v)
        if math.isfinite(lo[k]) and lo[k] > 0:
            out.append(f'<line class="ci" x1="{x:.1f}" y1="{frame.py(lo[k]):.1f}" '
                       f'x2="{x:.1f}" y2="{frame.py(hi[k]):.1f}"/>')
        mark = (f'<circle class="pt" cx="{x:.1f}" cy="{y:.1f}" r="3">' if shape == "circle"
                else f'<rect class="pt" x="{x - 3.5:.1f}" y="{y - 3.5:.1f}" width="7" '
                     'height="7">')
        out.append(f'{mark}<title>{escape(label)}: τ = {t:.4g} s, ADEV {v:.3e} m/s² '
                   f'[{_e(lo[k])}, {_e(hi[k])}]</title>'
                   f'{"</circle>" if shape == "circle" else "</rect>"}')
        n_est += 1
    return out, n_est, n_ul


def separation_svg(sep: Any, axis: Any) -> str:
    """One axis: each sensor's self-noise ADEV and the common mode's (the bed), log-log, m/s²,
    with their intervals; upper limits as ▽."""
    tau = np.asarray(axis.tau, dtype=float)
    parts = [*axis.self_noise, axis.common]
    shown = np.concatenate([np.concatenate([_sqrt(p.var), _sqrt(p.hi),
                                            np.where(p.upper_limit, np.nan, _sqrt(p.lo))])
                            for p in parts])
    ok_tau = tau[np.isfinite(tau) & (tau > 0)]
    frame = _Frame(_log_range(ok_tau), _log_range(shown), logx=True, logy=True)
    body = [frame.axes("τ [s]", "Allan deviation [m/s²]", xfmt=_decade, yfmt=_decade)]
    legend = []
    names = [*sep.sensors, "common mode"]
    for q, part in enumerate(parts):
        own = q < len(sep.sensors)
        colour = SENSOR_COLOURS[q % len(SENSOR_COLOURS)] if own else COMMON_COLOUR
        label = f"{names[q]} self-noise, {axis.axis}" if own else f"common mode, {axis.axis}"
        pts, n_est, n_ul = _points(frame, tau, part, label, "circle" if own else "square")
        role = "self" if own else "common"
        body.append(f'<g class="sep-part" data-role="{role}" data-name="{escape(names[q])}" '
                    f'data-points="{n_est}" data-limits="{n_ul}" stroke="{colour}" '
                    f'fill="{colour}">{"".join(pts)}</g>')
        legend.append((names[q][:14] if own else "common", colour))
    body.append(_legend(legend))
    return _svg("".join(body), f"self-noise against common mode, axis {axis.axis}",
                "plot separation")


def _runs(states: Sequence[str], want: str) -> list[tuple[int, int]]:
    """Runs [first, last] of consecutive τ indices whose verdict is ``want``."""
    runs: list[tuple[int, int]] = []
    for k, st in enumerate(states):
        if st == want:
            if runs and runs[-1][1] == k - 1:
                runs[-1] = (runs[-1][0], k)
            else:
                runs.append((k, k))
    return runs


def _bed_below(sep: Any, axis: Any) -> str:
    """Per sensor: where the bed's input is resolved below the sensor's own noise, where
    above it, and that nothing is resolved when neither."""
    items = []
    for i, name in enumerate(sep.sensors):
        v = axis.verdicts[i]
        said = []
        for want, text in (("below", "bed below own noise"), ("above", "bed above own noise")):
            runs = _runs(v.state, want)
            if not runs:
                continue
            spans = ", ".join(f"{_g(axis.tau[a], 3)}–{_g(axis.tau[b], 3)} s" if a != b
                              else f"{_g(axis.tau[a], 3)} s" for a, b in runs)
            by = ""
            if want == "below":
                least = np.asarray(v.factor_at_least, dtype=float)
                finite = least[np.isfinite(least)]
                by = f" (own noise ≥ {_g(float(finite.min()), 3)}× the bed's)" \
                    if len(finite) else ""
            said.append(f"{text} at τ {spans}{by}")
        if not said:
            said.append("bed against own noise not resolved at any τ yet")
        items.append(f"<li>{escape(name)}: {'; '.join(said)}</li>")
    return f'<ul class="recent">{"".join(items)}</ul>'


def separation_html(state: RunState) -> str:
    sep = state.separation
    rig = state.header.get("rig")
    if sep is None and isinstance(rig, dict) and len(rig.get("sensors") or []) >= 2:
        return ('<p class="waiting">No live separation yet: the service computes it from the '
                'sensors\' aligned samples once a minute of them is in and every pair has '
                'an Allan difference at some τ.</p>')
    if sep is None:
        return ('<p class="waiting">No live separation: it needs two or three co-located '
                'sensors in the service (each sensor\'s self-noise against the common mode '
                'then comes with every Allan snapshot).</p>')
    rate = float(sep.rate_hz) or 1.0
    out = [f'<p class="note">{escape(sep.method)} of {escape(", ".join(sep.sensors))}: '
           f'{sep.n_samples} aligned samples = {fmt_duration(sep.n_samples / rate)}; bars: '
           f'{100 * sep.ci:.1f} % intervals; ▽ an upper limit (the estimate is not resolved '
           f'from 0). ADEV in m/s², τ in s.</p>', '<div class="sep-axes">']
    for axis in sep.axes:
        out.append(f'<div class="sep-axis" data-axis="{escape(axis.axis)}"><h3>axis '
                   f'{escape(axis.axis)}</h3>{separation_svg(sep, axis)}'
                   f'{_bed_below(sep, axis)}</div>')
    out.append("</div>")
    return "".join(out)


# ---- fit and time to target ----------------------------------------------------------------


def fit_html(state: RunState, target: float) -> str:
    if not state.fits:
        return ('<p class="waiting">Fit pending (fitted here from the latest snapshot, with '
                '<code>avard.core.model.fit</code>).</p>')
    T = state.fitted.duration_s if state.fitted is not None else 0.0
    ci = state.fitted.data.ci if state.fitted is not None else 0.683
    head = (f"<tr><th>term</th>{''.join(f'<th>{a}</th>' for a in state.fits)}</tr>")
    terms: list[str] = []
    for fit in state.fits.values():
        terms.extend(t for t in fit.terms if t not in terms)
    rows = []
    for term in terms:
        cells = []
        for fit in state.fits.values():
            est = fit.terms.get(term)
            cells.append(f"<td>{_term_cell(est, T, target)}</td>")
        label = f"{escape(SYMBOLS.get(term, term))} <small>{escape(term.replace('_', ' '))}</small>"
        rows.append(f'<tr data-term="{escape(term)}"><th>{label}</th>{"".join(cells)}</tr>')
    return (f'<p class="note">IEEE 952 terms, value [{100 * ci:.1f} % interval] in SI units; '
            f'"absent" when the data do not resolve the term (upper bound in brackets); '
            f'time until the interval is within ±{100 * target:.3g} % (width ∝ 1/√duration).'
            f'</p><div class="scroll"><table class="fit">{head}{"".join(rows)}</table></div>')


def _term_cell(est: Any, T: float, target: float) -> str:
    if est is None:
        return "—"
    unit = escape(_unit(str(getattr(est, "unit", ""))))
    if not getattr(est, "present", False) or est.value is None:
        hi = est.hi
        bound = f" <small>(&lt; {_e(hi)} {unit})</small>" if isinstance(hi, float) else ""
        return f'<span class="absent">absent</span>{bound}'
    if is_not_resolved(getattr(est, "note", None)):  # no interval, no time to target
        return (f"{_e(est.value)} <small>{unit}</small>"
                f'<br><small class="absent">not yet resolved</small>')
    more = time_to_target(est.value, est.lo, est.hi, T, target)
    return (f"{_e(est.value)} <small>[{_e(est.lo, 2)}, {_e(est.hi, 2)}] {unit}</small>"
            f"<br><small>{_when(more)}</small>")


def _when(more: float | None) -> str:
    if more is None:
        return "time to target: ?"
    return "target reached" if more == 0 else f"~{fmt_duration(more)} more"


def targets_html(state: RunState, target: float) -> str:
    """Per τ and axis: relative half-width of the ADEV interval and the time until ±target."""
    snap = state.shown()
    if snap is None:
        return '<p class="waiting">Waiting for an Allan snapshot.</p>'
    d = snap.data
    tau = d.tau
    cols = [(c, n) for c, n in enumerate(d.names) if n in AXES]
    avar, lo, hi = d.avar, d.lo, d.hi
    T = snap.duration_s
    rows = []
    for k, t in enumerate(tau):
        cells = []
        for c, _ in cols:
            v, a, b = (float(x) for x in _sqrt([avar[k, c], lo[k, c], hi[k, c]]))
            if not (math.isfinite(v) and v > 0 and math.isfinite(a) and math.isfinite(b)):
                cells.append("<td>—</td>")
                continue
            w = (b - a) / (2 * v)
            more = time_to_target(v, a, b, T, target)
            cls = "reached" if more == 0 else "pending"
            cells.append(f'<td class="{cls}">±{100 * w:.3g} %<br><small>{_when(more)}'
                         f"</small></td>")
        rows.append(f'<tr><th>{t:.4g}</th>{"".join(cells)}</tr>')
    head = "".join(f"<th>{n}</th>" for _, n in cols)
    return (f'<p class="note">After {fmt_duration(T)}: the ADEV interval\'s relative '
            f'half-width at each τ, and the run time still needed until it is within '
            f'±{100 * target:.3g} % (EDF ∝ duration; an estimate, rough while τ is near the '
            f'run length).</p><div class="scroll"><table class="targets"><tr><th>τ [s]</th>'
            f'{head}</tr>{"".join(rows)}</table></div>')


# ---- temperatures --------------------------------------------------------------------------


def temperatures_svg(series: dict[str, Series], span_s: float) -> str:
    xs = [x for s in series.values() for x in s.x]
    ys = [y for s in series.values() for y in s.y]
    unit, scale = _time_unit(max([span_s, *xs]) if xs else span_s)
    x0, x1 = (min(xs), max(xs)) if xs else (0.0, 1.0)
    y0, y1 = (min(ys), max(ys)) if ys else (20.0, 25.0)
    pad = max(0.05, 0.1 * (y1 - y0))
    frame = _Frame((x0 / scale, max(x1, x0 + 1) / scale), (y0 - pad, y1 + pad),
                   logx=False, logy=False, h=300)
    body = [frame.axes(f"run time [{unit}]", "temperature [°C]")]
    legend = []
    for k, (name, s) in enumerate(sorted(series.items())):
        colour = OTHER_COLOURS[k % len(OTHER_COLOURS)]
        pts = [(frame.px(x / scale), frame.py(y)) for x, y in zip(s.x, s.y, strict=True)]
        body.append(f'<path class="series" data-channel="{escape(name)}" stroke="{colour}" '
                    f'd="{_path(pts)}"/>')
        legend.append((_short(name), colour))
    body.append(_legend(legend))
    return _svg("".join(body), "temperatures over the run", "plot temps", h=300)


def _short(name: str) -> str:
    """DS18B20 ids are long; the plot's legend shows the part after the family code."""
    return name[3:] if name.startswith("28-") else name


def temperatures_html(state: RunState) -> str:
    if not state.temperatures:
        return '<p class="waiting">No temperature readings yet.</p>'
    latest = ", ".join(
        f"{escape(_short(k))} {'—' if v is None else f'{v:.2f}'} °C"
        for k, v in sorted(state.latest_temps.items()))
    return (f'<p class="note">Latest: {latest}. {escape(temperatures_span(state))}, thinned to '
            f'at most {max(s.max_points for s in state.temperatures.values())} points per '
            'channel.</p>' + temperatures_svg(state.temperatures, state.run_time(None)))


def temperatures_span(state: RunState) -> str:
    """What the temperature plot covers, said as it is: the live stream starts when avard web
    did; only with ``--history`` does it hold the run before."""
    since = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime(state.started))
    if state.history is not None and state.history_records:
        return f"The run from the recording in {state.history}, then live"
    if state.history is not None:
        return (f"Since avard web started ({since}); nothing was read from --history "
                f"{state.history}")
    return (f"Since avard web started ({since}); start it with --history DIR to show the "
            "run before")


# ---- status and time line ------------------------------------------------------------------


def status_html(state: RunState) -> str:
    st, stats = state.status, state.stats
    ppm = state.rate_ppm
    rate = st.get("rate_hz")
    disk = st.get("disk") if isinstance(st.get("disk"), dict) else {}
    gaps = sum(state.gaps_by_reason.values())
    gap_s = sum(state.gap_samples_by_reason.values()) / (state.nominal_odr_hz or 1.0)
    rows = [
        ("run", escape(str(st.get("run") or (state.runs[-1] if state.runs else "?")))
         + (f" <small>({len(state.runs)} runs seen)</small>" if len(state.runs) > 1 else "")),
        ("samples", f"{st.get('samples', '—')} in this run; {stats.samples_received} "
                    f"received here"),
        ("rate", f"{rate:.6g} Hz fitted ODR, {ppm:+.1f} ppm from nominal"
         if isinstance(rate, int | float) and ppm is not None else "pending"),
        ("gaps", f'<span class="{"bad" if gaps else "good"}">{gaps} '
                 f'gap{"" if gaps == 1 else "s"}, {gap_s:.3g} s of samples missing</span>; '
                 f"overruns {st.get('overruns', '—')}, bus errors "
                 f"{st.get('bus_errors', '—')}, clock steps {st.get('clock_steps', '—')}"),
        ("this link", f"{stats.messages_lost} messages and {stats.samples_lost} samples lost "
                      f"between service and this page; {stats.samples_unexplained} "
                      "unexplained"),
        ("disk", f"{escape(str(disk.get('state', 'not recording')))}, "
                 f"{_bytes(disk.get('free_bytes'))} free, {_bytes(disk.get('bytes'))} in "
                 f"the current segment" if disk else "not reported"),
        ("uptime", f"service {fmt_duration(float(st.get('sim_time_s', 0.0)))}; this page's "
                   f"server {fmt_duration(time.time() - state.started)}"),
        ("subscribers", f"{st.get('subscribers', '—')} on the service (this server is one)"),
    ]
    age = "" if state.status_received is None else \
        f"status {fmt_duration(state.clock() - state.status_received)} old"
    return (_silence(state) + '<dl class="status">'
            + "".join(f"<dt>{k}</dt><dd>{v}</dd>" for k, v in rows)
            + f'</dl><p class="note">{age}</p>')


def _silence(state: RunState) -> str:
    """A warning when nothing has come from the service for a while: is it still running?"""
    if state.last_message is None:
        return ('<p class="alarm">Nothing received from the service yet: is it running, and '
                "is the endpoint right?</p>")
    quiet = state.clock() - state.last_message
    if quiet < SILENT_S:
        return ""
    return (f'<p class="alarm">Nothing received from the service for {fmt_duration(quiet)}: '
            "is it still running? (What is shown is as it last was.)</p>")


def timeline_svg(state: RunState) -> str:
    h = 126
    end = max(state.run_time(None), max((i.t_s for i in state.timeline), default=0.0), 1.0)
    unit, scale = _time_unit(end)
    frame = _Frame((0.0, end / scale), (0.0, 1.0), logx=False, logy=False, h=h)
    body = [f'<line class="axis" x1="{ML}" y1="{h - MB + 4}" x2="{W - MR}" y2="{h - MB + 4}"/>']
    for v in _nice_ticks(0.0, end / scale):
        x = frame.px(v)
        body.append(f'<text class="tick" x="{x:.1f}" y="{h - MB + 20}" '
                    f'text-anchor="middle">{_g(v)}</text>')
    body.append(f'<text class="label" x="{(ML + W - MR) / 2:.0f}" y="{h - 10}" '
                f'text-anchor="middle">run time [{unit}]</text>')
    body.append(f'<text class="tick" x="{ML - 6}" y="{MT + 16}" text-anchor="end">gaps</text>'
                f'<text class="tick" x="{ML - 6}" y="{MT + 42}" text-anchor="end">events</text>')
    for item in state.timeline:
        x = frame.px(item.t_s / scale)
        title = escape(f"{item.name} at {item.t_s:.1f} s: {item.detail}")
        if item.kind == "gap":
            width = max(3.0, frame.px((item.t_s + item.samples / (state.nominal_odr_hz or 1))
                                      / scale) - x)
            colour = GAP_COLOURS.get(item.name, "#D55E00")
            body.append(f'<g class="tl-item" data-kind="gap" data-name="{escape(item.name)}">'
                        f'<rect x="{x - 1:.1f}" y="{MT + 3}" width="{width:.1f}" height="18" '
                        f'fill="{colour}"><title>{title}</title></rect></g>')
        else:
            body.append(f'<g class="tl-item" data-kind="event" data-name="{escape(item.name)}">'
                        f'<path d="M{x:.1f},{MT + 30} l5,9 l-10,0 z" fill="#444">'
                        f'<title>{title}</title></path></g>')
    return _svg("".join(body), "gaps and events over the run", "plot timeline", h=h)


def timeline_html(state: RunState) -> str:
    counts = [f"{n} × {escape(r)} ({state.gap_samples_by_reason[r]} samples)"
              for r, n in sorted(state.gaps_by_reason.items())]
    events = [f"{n} × {escape(name)}" for name, n in sorted(state.events_by_name.items())]
    recent = list(state.timeline)[-8:]
    items = "".join(
        f'<li class="{i.kind}"><b>{escape(i.name)}</b> at {i.t_s:.1f} s '
        f'<small>{escape(i.detail)}</small></li>' for i in reversed(recent))
    return (timeline_svg(state)
            + f'<p class="note">Gaps: {", ".join(counts) or "none"}. Events: '
              f'{", ".join(events) or "none"}. Seen since this server started; the time axis '
              'is sample index / nominal ODR, so restarts keep their place.</p>'
            + (f'<ul class="recent">{items}</ul>' if items else ""))

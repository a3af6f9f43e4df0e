"""Live terminal view of a running service: rate, loss, temperatures, ADEV, fit, time to target.

Subscribes to ENDPOINT (every topic), asks the request socket for the latest Allan snapshot on
join, and redraws every ``--interval`` seconds:

* rate: the service's fitted ODR and the rate at which samples arrive here;
* samples received, lost in transport (sequence and index holes), lost in the service (gap
  records), per-topic message counts;
* the latest temperatures (DS18B20 and the ADXL355's own sensor), °C;
* ADEV at a few τ with its confidence interval (from the streamed Allan snapshot);
* the noise-term fit with intervals — the service's when its ``avar`` record carries one,
  otherwise fitted here from the snapshot (``avard.core.model.fit``) — and for every coefficient an
  estimate of how long until its interval is narrower than ``--target`` (relative half-width).

Time to target: an interval's relative width scales as 1/√EDF, and the EDF at a fixed τ grows
in proportion to the record duration T (NIST SP 1065 §5.2: EDF ≈ N/m × const for the
overlapping estimators), so a coefficient with relative half-width w after T seconds reaches
w_target after about T·(w / w_target)². It is an estimate: the long-τ terms (bias instability,
rate random walk) are read at τ values whose EDF grows this way only once τ ≪ T.
"""

from __future__ import annotations

import argparse
import logging
import math
import shutil
import sys
import time
from typing import Any

import numpy as np
from avard.core.allan.streaming import AllanSnapshot
from avard.core.analysis.live_fit import is_not_resolved
from avard.core.errors import ConfigError, FormatError, NetworkError
from avard.core.model.terms import SYMBOLS
from avard.daemon.commands._options import check_seconds
from avard.daemon.net.subscriber import (
    Message,
    StreamStats,
    add_client_arguments,
    subscriber_from_args,
)
from avard.daemon.service.snapshots import ACCEL_CHANNELS, fit_intervals, snapshot_fits

log = logging.getLogger(__name__)

NAME = "watch"
HELP = "live view of a service: rate, loss, temperatures, ADEV, fit and time to target"



def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_client_arguments(parser)
    parser.add_argument("--interval", type=float, default=2.0, metavar="S",
                        help="redraw every S seconds (default 2)")
    parser.add_argument("--once", action="store_true",
                        help="print one view as soon as an Allan snapshot is known, then exit")
    parser.add_argument("--count", type=int, default=None, metavar="N",
                        help="print N views, then exit")
    parser.add_argument("--target", type=float, default=0.1, metavar="REL",
                        help="target relative half-width of each coefficient's interval "
                             "(default 0.1 = ±10 %%)")
    parser.add_argument("--taus", default="0.1,1,10,100,1000", metavar="LIST",
                        help="τ values in s to show ADEV at (nearest octave; default "
                             "0.1,1,10,100,1000)")
    parser.add_argument("--no-fit", action="store_true",
                        help="do not fit here when the service sends no fit")
    parser.add_argument("--wait", type=float, default=10.0, metavar="S",
                        help="with --once/--count: give up when no snapshot arrives within S s")


def fmt_duration(seconds: float) -> str:
    """Seconds as a short human duration (s, min, h, d)."""
    if not math.isfinite(seconds):
        return "never"
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    if seconds < 172800:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86400:.1f} d"


def time_to_target(value: float | None, lo: float | None, hi: float | None,
                   duration_s: float, target: float) -> float | None:
    """Seconds more until the interval's relative half-width is ≤ ``target``.

    Width ∝ 1/√EDF and EDF ∝ duration, so the duration needed is T·(w/target)² with
    w = (hi − lo) / (2·value). 0 when reached, None when it cannot be estimated.
    """
    if value is None or lo is None or hi is None or not value or duration_s <= 0:
        return None
    w = (hi - lo) / (2.0 * abs(value))
    if not math.isfinite(w) or w < 0:
        return None
    return max(0.0, duration_s * (w / target) ** 2 - duration_s)


_PRETTY_UNITS = {"m/s^2": "m/s²", "degC": "°C"}


def _unit(name: str, declared: str | None = None) -> str:
    """The channel's unit: as the snapshot declares it, else m/s² for x/y/z and °C."""
    if declared:
        return _PRETTY_UNITS.get(declared, declared)
    return "m/s²" if name in ACCEL_CHANNELS else "°C"


class WatchView:
    """The state behind the terminal view, updated message by message."""

    def __init__(self, *, target: float = 0.1, taus: tuple[float, ...] = (0.1, 1, 10, 100),
                 fit_locally: bool = True, clock: Any = time.monotonic) -> None:
        self.target = target
        self.taus = taus
        self.fit_locally = fit_locally
        self.clock = clock
        self.run: str | None = None
        self.sensor: str | None = None   # a rig's sensor, from its records
        self.odr_hz: float | None = None
        self.temps: dict[str, float | None] = {}
        self.chip_temp_c: float | None = None
        self.snapshot: AllanSnapshot | None = None
        self.snapshot_end: int | None = None   # the index after the snapshot's last sample
        self.snapshot_at: float | None = None  # self.clock() when it arrived
        self._fits: dict[str, dict[str, Any]] = {}
        self._fit_due = False                  # a snapshot without the service's fit
        self.fits_computed = 0
        self.fit_source = ""
        self.started_at = clock()
        self.last_message_at: float | None = None
        self.newest_end: int | None = None     # the index after the newest sample received
        self.status: dict[str, Any] = {}
        self.events: list[str] = []
        self._rate_t0: float | None = None
        self._rate_n0 = 0
        self._rate: float | None = None
        self._samples = 0

    # ---- updates --------------------------------------------------------------------------

    def set_snapshot(self, snapshot: dict[str, Any] | None, fit: Any = None, *,
                     i_end: int | None = None) -> None:
        """A new Allan snapshot (dict of AllanSnapshot.to_dict()) and optional service fit.

        Without the service's fit, the fit here is made when the view is next looked at
        (:attr:`fits`), for the newest snapshot only: a view behind a fast service skips the
        snapshots it had no time for instead of fitting every stale one."""
        if not snapshot:
            return
        if "snapshot" in snapshot:  # the request socket answers with the whole avar record
            i_end = snapshot.get("i_end", i_end)
            snapshot, fit = snapshot["snapshot"], snapshot.get("fit", fit)
        try:
            self.snapshot = AllanSnapshot.from_dict(snapshot)   # the one decoder
        except FormatError as exc:  # not a snapshot this avard understands
            log.warning("ignoring an unreadable Allan snapshot: %s", exc)
            return
        self.odr_hz = self.odr_hz or self.snapshot.rate_hz
        self.snapshot_end = int(i_end) if isinstance(i_end, int) else None
        self.snapshot_at = self.clock()
        self._fits = {}
        self._fit_due = False
        if isinstance(fit, dict) and fit:
            self._fits = {"x": fit} if "terms" in fit else {
                k: v for k, v in fit.items() if isinstance(v, dict) and "terms" in v}
            self.fit_source = "service"
            self._take_intervals(self._fits)
        elif self.fit_locally:
            self._fit_due = True
            self.fit_source = "fitted here"

    @property
    def fits(self) -> dict[str, dict[str, Any]]:
        """The fit of the current snapshot: the service's, or made here once on demand."""
        if self._fit_due:
            self._fit_due = False
            self._fits = self._fit_here()
            self.fits_computed += 1
        return self._fits

    def update(self, msg: Message) -> None:
        rec = msg.record
        self.run = rec["run"]
        self.sensor = rec.get("sensor_name", self.sensor)     # a rig's sensor
        kind = rec["kind"]
        self.last_message_at = self.clock()
        if kind == "raw":
            self.newest_end = int(rec["i0"]) + int(rec["n"])
            now = self.clock()
            self._samples += rec["n"]
            if self._rate_t0 is None:
                self._rate_t0, self._rate_n0 = now, self._samples
            elif now - self._rate_t0 >= 1.0:
                self._rate = (self._samples - self._rate_n0) / (now - self._rate_t0)
                self._rate_t0, self._rate_n0 = now, self._samples
            self.odr_hz = _num(rec.get("rate_hz")) or self.odr_hz
            if rec.get("chip_temp_c") is not None:
                self.chip_temp_c = float(rec["chip_temp_c"])
        elif kind == "temp":
            for name, value in zip(rec["names"], rec["values_c"], strict=False):
                self.temps[str(name)] = value
        elif kind == "avar":
            self.set_snapshot(rec["snapshot"], rec.get("fit"), i_end=rec.get("i_end"))
        elif kind == "status":
            self.status = rec["status"]
            self.odr_hz = _num(self.status.get("rate_hz")) or self.odr_hz
        elif kind in ("event", "gap"):
            what = rec.get("name") or f"gap of {rec.get('n')} samples ({rec.get('reason')})"
            self.events = [*self.events[-4:], str(what)]

    def _fit_here(self) -> dict[str, dict[str, Any]]:
        """Fit each acceleration channel of the snapshot (the service's one snapshot fit,
        ``snapshots.snapshot_fits``); its ADEV intervals then are those the fit supports."""
        if self.snapshot is None:
            return {}
        fits = snapshot_fits(self.snapshot)
        self.snapshot = fit_intervals(self.snapshot, fits)
        return {name: cf.fit.to_dict() for name, cf in fits.items()}

    def _take_intervals(self, fits: dict[str, dict[str, Any]]) -> None:
        """The ADEV intervals the service's fit supports (its ``edf``/``lo``/``hi`` per τ:
        what analyze prints), where it sent them for this snapshot's τ."""
        snap = self.snapshot
        if snap is None:
            return
        lo, hi = np.array(snap.lo, dtype=float), np.array(snap.hi, dtype=float)
        for c, name in enumerate(snap.names):
            f = fits.get(name, {})
            a, b = f.get("lo"), f.get("hi")
            if isinstance(a, list) and isinstance(b, list) and len(a) == len(b) == len(snap.tau):
                lo[:, c], hi[:, c] = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
        from dataclasses import replace

        self.snapshot = replace(snap, lo=lo, hi=hi)

    # ---- rendering ------------------------------------------------------------------------

    def duration_s(self) -> float:
        snap = self.snapshot
        if snap is None:
            return 0.0
        n, rate = snap.n_samples, snap.rate_hz or self.odr_hz
        return n / rate if n and rate else 0.0

    def render(self, stats: StreamStats, endpoint: str = "", *, width: int | None = None,
               height: int | None = None) -> str:
        """The view as text. With a terminal's ``width`` × ``height`` it fits: no line is
        longer than ``width`` (nothing wraps) and there are at most ``height`` lines, the
        essentials first (rate, loss, temperatures, ADEV at a few τ with intervals, the fit
        with the time to the target interval). Each of the ADEV and fit sections has a full
        form (value [interval] per channel) and a compact one (value −lo/+hi % per channel,
        side by side); the full form is used where it fits, the compact one where it does not.
        Without a size (output not a terminal) every line is shown in full."""
        w = width if width is not None else 10_000
        h = height if height is not None else 10_000
        which = f"  sensor {self.sensor}" if self.sensor else ""
        head = [f"avard watch {endpoint}  run {self.run or '?'}{which}  (SI units)"]
        odr = f"{self.odr_hz:.4f} Hz fitted ODR" if self.odr_hz else "ODR unknown"
        here = f"{self._rate:.1f} samples/s arriving" if self._rate else "arrival rate pending"
        head.append(f"rate      {odr}; {here}")
        head.append(
            f"samples   {stats.samples_received} received; lost in transport "
            f"{stats.samples_lost}; service gaps {stats.samples_service_gap}; unexplained "
            f"{stats.samples_unexplained}")
        temps = [f"{k} {'—' if v is None else f'{v:.2f}'} °C" for k, v in self.temps.items()]
        if self.chip_temp_c is not None:
            temps.append(f"chip {self.chip_temp_c:.1f} °C")
        head.append("temps     " + (", ".join(temps) if temps else "none yet"))
        head.append(self._render_age(endpoint))
        extra = ["messages  " + ", ".join(
            f"{t} {s.received} ({s.lost} lost)" for t, s in sorted(stats.topics.items()))
            + (f"; {stats.bad_messages} undecodable" if stats.bad_messages else "")]
        if self.events:
            extra.append("events    " + "; ".join(self.events))
        # a snapshot or fit from a newer or broken service must not end the view
        try:
            self.fits  # noqa: B018 (fitted first: the ADEV's intervals are those it supports)
        except (ValueError, TypeError, KeyError, IndexError, AttributeError) as exc:
            log.debug("no fit for this view: %s", exc)
        adev = self._section("ADEV", self._render_adev, w)
        fit = self._section("fit", self._render_fit, w)
        # the full forms first; then compact ones until the essentials fit the height
        for a, f in ((0, 0), (0, -1), (-1, -1)):
            body = adev[a] + fit[f]
            if len(head) + len(body) <= h:
                break
        lines = head + body
        # the message counts and events where there is room: after the essentials if the
        # terminal is short, in their usual place (under the loss line) otherwise
        if len(lines) + len(extra) <= h:
            lines = head[:3] + extra + head[3:] + body
        if len(lines) > h:
            lines = [*lines[:max(h - 1, 0)], "… (a taller terminal shows more)"][:h]
        return "\n".join(_clip(ln, w) for ln in lines) + "\n"

    def _render_age(self, endpoint: str) -> str:
        """How old the view is: plainly when nothing arrives, else how far the snapshot
        (ADEV and fit) lags the newest sample received and when it arrived."""
        now = self.clock()
        if self.last_message_at is None:
            return (f"data      nothing received from {endpoint or 'the service'} in "
                    f"{fmt_duration(now - self.started_at)}: is the service running there, "
                    "and are the endpoint and keys right?")
        quiet = now - self.last_message_at
        if quiet >= 10:
            return (f"data      nothing new for {fmt_duration(quiet)}: the view below is "
                    "that old (service stopped or network down?)")
        if self.snapshot is None or self.snapshot_at is None:
            return "data      arriving; no Allan snapshot yet"
        age = f"snapshot received {fmt_duration(now - self.snapshot_at)} ago"
        rate = self.odr_hz
        if self.snapshot_end is not None and self.newest_end is not None and rate:
            behind = max(self.newest_end - self.snapshot_end, 0) / rate
            age += f", {fmt_duration(behind)} of data behind the newest sample"
        return f"data      arriving; {age}"

    def _section(self, part: str, render: Any, width: int) -> list[list[str]]:
        """The variants of a section that fit ``width``, full first (at least one)."""
        try:
            variants = render(width)
        except (ValueError, TypeError, KeyError, IndexError, AttributeError) as exc:
            return [[f"{part:<10}unreadable ({type(exc).__name__}: {exc})"]]
        fitting = [v for v in variants if all(len(ln) <= width for ln in v)]
        return fitting or variants[-1:]

    def _render_adev(self, width: int = 10_000) -> list[list[str]]:
        """ADEV at the chosen τ: full rows (value [lo, hi] per channel; accelerometer
        channels alone when all do not fit) and compact rows (value −lo/+hi %)."""
        snap = self.snapshot
        if snap is None or len(snap.tau) == 0:
            return [["ADEV      no Allan snapshot yet"]]
        tau, avar, lo, hi = snap.tau, snap.avar, snap.lo, snap.hi
        names = list(snap.names)
        ci = snap.ci
        units = [_unit(n) for n in names]
        rows = []
        for want in self.taus:
            k = int(np.argmin(np.abs(np.log(tau / want))))
            if k in rows or not 0.5 <= tau[k] / want <= 2.0:
                continue
            rows.append(k)
        title = (f"ADEV      {snap.n_samples} samples = "
                 f"{fmt_duration(self.duration_s())}; value [{100 * ci:.1f} % interval]")
        accel = [c for c, n in enumerate(names) if n in ACCEL_CHANNELS] or list(range(len(names)))

        def table(cols: list[int], full: bool) -> list[str]:
            cw = 31 if full else 21
            out = [title if full else title.replace("value [", "value −lo/+hi [", 1),
                   "  τ [s]    " + "".join(f"{names[c] + ' [' + units[c] + ']':<{cw}}"
                                           for c in cols).rstrip()]
            for k in rows:
                cells = []
                for c in cols:
                    v, a, b = (math.sqrt(x) if x >= 0 and math.isfinite(x) else float("nan")
                               for x in (avar[k, c], lo[k, c], hi[k, c]))
                    cells.append((f"{v:.3e} [{a:.2e}, {b:.2e}]" if full
                                  else f"{v:.3e} {_pct_pair(v, a, b)}").ljust(cw))
                out.append((f"  {tau[k]:<9.4g}" + "".join(cells)).rstrip())
            return out

        every = list(range(len(names)))
        return [table(every, True), table(accel, True), table(every, False),
                table(accel, False)]

    def _render_fit(self, width: int = 10_000) -> list[list[str]]:
        """The fit: full (one line per channel and term) and compact (one line per term,
        the accelerometer channels side by side: value ±half-width %, time to target)."""
        if not self.fits:
            return [["fit       none yet"]]
        T = self.duration_s()
        target = f"±{100 * self.target:.0f} %"
        full = [f"fit       ({self.fit_source}; value [interval]; more time until "
                f"{target}, assuming width ∝ 1/√duration)"]
        for ch, fit in self.fits.items():
            full.append(f"  {ch}:")
            for term, est in fit.get("terms", {}).items():
                if not isinstance(est, dict):
                    continue
                unit = est.get("unit", "")
                if not est.get("present") or est.get("value") is None:
                    hi = est.get("hi")
                    bound = f" (< {hi:.3e} {unit})" if isinstance(hi, int | float) else ""
                    full.append(f"    {term:<22} not resolved{bound}")
                    continue
                v, a, b = est["value"], est.get("lo"), est.get("hi")
                if is_not_resolved(est.get("note")):  # no interval, no time to target
                    full.append(f"    {term:<22} {v:.3e} {unit:<14} not yet resolved")
                    continue
                interval = (f"[{a:.3e}, {b:.3e}]" if a is not None and b is not None
                            else "[?]")
                full.append(f"    {term:<22} {v:.3e} {interval} {unit:<14} "
                            f"{self._when(v, a, b, T, long=True)}")
        chans = list(self.fits)
        terms: list[str] = []
        for fit in self.fits.values():
            terms += [t for t, e in fit.get("terms", {}).items()
                      if isinstance(e, dict) and t not in terms]
        compact = [f"fit       ({self.fit_source}) value ±half-width, time until {target}",
                   "  " + f"{'term':<15}" + "".join(f"{c:<21}" for c in chans).rstrip()]
        for term in terms:
            unit = ""
            cells = []
            for ch in chans:
                est = self.fits[ch].get("terms", {}).get(term)
                if not isinstance(est, dict):
                    cells.append("—".ljust(21))
                    continue
                unit = unit or _pretty(str(est.get("unit", "")))
                v, a, b = est.get("value"), est.get("lo"), est.get("hi")
                if not est.get("present") or v is None:
                    cell = f"< {b:.2e}" if isinstance(b, int | float) else "absent"
                elif is_not_resolved(est.get("note")):
                    cell = f"{v:.3e} not yet resolved"
                else:
                    half = (f"±{_pct((b - a) / (2 * abs(v)) * 100)}%"
                            if a is not None and b is not None and v else "±?")
                    cell = f"{v:.3e} {half} {self._when(v, a, b, T, long=False)}"
                cells.append(cell.ljust(21))
            label = f"{SYMBOLS.get(term, term[:1].upper())} [{unit}]"
            compact.append("  " + f"{label:<15}" + "".join(cells).rstrip())
        return [full, compact]

    def _when(self, v: float, a: float | None, b: float | None, T: float, *,
              long: bool) -> str:
        more = time_to_target(v, a, b, T, self.target)
        if more is None:
            return "?"
        if more == 0:
            return "reached" if long else "ok"
        return f"~{fmt_duration(more)} more" if long else fmt_duration(more).replace(" ", "")


def _pretty(unit: str) -> str:
    return unit.replace("^2", "²").replace("^3", "³").replace("sqrt(s)", "√s")


def _pct(p: float) -> str:
    return f"{p:.1f}" if p < 9.95 else f"{p:.0f}"


def _pct_pair(v: float, a: float, b: float) -> str:
    """An interval [a, b] around v as −x/+y % (asymmetric at long τ, where EDF is small)."""
    if not (v > 0 and math.isfinite(a) and math.isfinite(b)):
        return "[?]"
    return f"-{_pct((v - a) / v * 100)}/+{_pct((b - v) / v * 100)}%"


def _clip(line: str, width: int) -> str:
    """A line cut to the terminal's width (a wrapped line would push the view off screen)."""
    return line if len(line) <= width else line[:max(width - 1, 0)] + "…"


def _num(x: Any) -> float | None:
    return float(x) if isinstance(x, int | float) and math.isfinite(x) and x > 0 else None


def run(args: argparse.Namespace) -> int:
    try:
        taus = tuple(float(t) for t in args.taus.split(",") if t.strip())
    except ValueError:
        raise ConfigError(f"--taus {args.taus!r}: give comma-separated seconds, "
                          "e.g. 0.1,1,10") from None
    for value, option in ((args.interval, "--interval"), (args.wait, "--wait")):
        check_seconds(value, option)
    if args.count is not None and args.count < 1:
        raise ConfigError(f"--count {args.count}: give a number of views ≥ 1")
    if not (math.isfinite(args.target) and args.target > 0):
        raise ConfigError(f"--target {args.target:g}: give the relative half-width to reach, "
                          "above 0 (0.1 = ±10 %)")
    limit = 1 if args.once else args.count
    view = WatchView(target=args.target, taus=taus, fit_locally=not args.no_fit)
    sub = subscriber_from_args(args)
    out = sys.stdout
    clear = out.isatty() and limit is None
    printed = 0
    try:
        sub.connect()
        view.set_snapshot(sub.snapshot)
        start = time.monotonic()
        next_draw = start + (0 if limit else args.interval)
        while limit is None or printed < limit:
            msg = sub.recv(0.1)
            if msg is not None:
                view.update(msg)
            now = time.monotonic()
            if limit is not None and view.snapshot is None:
                if now - start > args.wait:
                    if sub.stats.bad_messages and not sub.stats.messages_received:
                        raise NetworkError(f"nothing readable from {args.endpoint} within "
                                           f"{args.wait:g} s: {sub.stats.not_avard()}")
                    raise NetworkError(f"no Allan snapshot from {args.endpoint} within "
                                       f"{args.wait:g} s (is the service running?)")
                continue
            if now >= next_draw:
                # what queued up meanwhile first, so the view shows the newest snapshot
                # (only that one is fitted) rather than one a redraw behind
                for _ in range(100_000):
                    if (queued := sub.recv(0)) is None:
                        break
                    view.update(queued)
                # on a terminal: its size now (it may have been resized); one line is kept
                # free so the cursor line does not scroll the view's first line away
                size = shutil.get_terminal_size() if out.isatty() else None
                text = view.render(sub.stats, args.endpoint,
                                   width=size.columns if size else None,
                                   height=size.lines - 1 if size else None)
                out.write(("\x1b[H\x1b[2J" if clear else "") + text
                          + ("" if clear else "\n"))
                out.flush()
                printed += 1
                next_draw = now + args.interval
    except KeyboardInterrupt:
        pass
    finally:
        sub.close()
    return 0

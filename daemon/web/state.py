"""What the web view knows about the run: the latest Allan snapshot and fit, and the history.

:class:`RunState` is fed the subscriber's decoded messages (one thread) and read by the
renderers (the web server's thread) under its lock. It keeps the whole run so far, so a
viewer who opens the page on Sunday sees Friday's temperatures and gaps:

* the temperature series of every channel (DS18B20 and the ADXL355's own sensor), thinned by
  :class:`Series` to a bounded number of points that always span the whole run;
* every gap and event on a time line (the newest :data:`MAX_EVENTS`, with counts by reason
  that are never thinned);
* the latest status map, header and Allan snapshot; the fit of the snapshot is made on
  demand by the caller (it costs seconds, see :func:`avard.daemon.service.snapshots.fit_snapshot`).

Time on the run's axis is the sample index divided by the nominal ODR: the index continues
across service restarts (the restart becomes a gap), so one axis holds the whole run.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import Counter, deque
from dataclasses import dataclass, field
from typing import Any

from avard.core.allan.streaming import AllanSnapshot
from avard.core.analysis.separate import Separation
from avard.core.errors import FormatError
from avard.daemon.net.subscriber import Message, StreamStats
from avard.daemon.service.snapshots import separation_of

log = logging.getLogger(__name__)

#: Seconds without any message after which the page says the service is silent (it sends
#: raw blocks many times a second and status every few seconds).
SILENT_S = 15.0
#: Record kinds read from the service's recording (``avard web --history DIR``).
HISTORY_KINDS = ("header", "temp", "gap", "event")
#: Events and gaps kept for the time line (a 60-h run with a gap a minute fits).
MAX_EVENTS = 5000
#: Points a temperature series keeps before it halves its resolution.
MAX_POINTS = 2000
#: Chip temperature arrives with raw blocks (~100/s); one point per this many run seconds.
CHIP_SERIES_STEP_S = 1.0


class Series:
    """(x, y) points of a whole run in bounded memory.

    Every point is kept until ``max_points``; then every other point is dropped and from then
    on only every 2nd (4th, …) new point is kept, so the series always spans the whole run
    with evenly thinned resolution.
    """

    def __init__(self, max_points: int = MAX_POINTS) -> None:
        if max_points < 4:
            raise ValueError("a series needs room for at least 4 points")
        self.max_points = max_points
        self.x: list[float] = []
        self.y: list[float] = []
        self._stride = 1
        self._count = 0     # points offered so far; point k is kept while k % stride == 0

    def append(self, x: float, y: float) -> None:
        k, self._count = self._count, self._count + 1
        if k % self._stride:
            return
        self.x.append(x)
        self.y.append(y)
        if len(self.x) >= self.max_points:
            # the kept points are k = 0, s, 2s, …: every other one is k = 0, 2s, 4s, …
            self.x, self.y = self.x[::2], self.y[::2]
            self._stride *= 2

    def __len__(self) -> int:
        return len(self.x)


@dataclass
class TimelineItem:
    """One gap or event on the run's time line; ``t_s`` is run time (index / nominal ODR)."""

    kind: str           # "gap" or "event"
    name: str           # the gap's reason or the event's name
    t_s: float
    samples: int = 0    # gaps: samples missing
    run: str = ""
    detail: str = ""


@dataclass
class Snapshot:
    """The newest Allan snapshot (decoded by ``AllanSnapshot.from_dict``) and when it
    arrived."""

    data: AllanSnapshot
    received: float
    n_samples: int

    @property
    def rate_hz(self) -> float:
        return float(self.data.rate_hz or 0.0)

    @property
    def duration_s(self) -> float:
        rate = self.rate_hz
        return self.n_samples / rate if rate > 0 else 0.0


@dataclass
class RunState:
    """The run as seen from the web process (see the module docstring). Thread-safe."""

    lock: threading.RLock = field(default_factory=threading.RLock)
    started: float = field(default_factory=time.time)
    history: str | None = None   # the recording read first (``--history``), if any
    history_records: int = 0     # records read from it
    clock: Any = time.monotonic
    runs: list[str] = field(default_factory=list)
    header: dict[str, Any] = field(default_factory=dict)
    status: dict[str, Any] = field(default_factory=dict)
    status_received: float | None = None
    last_message: float | None = None    # when anything last came from the service (clock)
    snapshot: Snapshot | None = None
    compensated: Snapshot | None = None
    separation: Separation | None = None    # the live separation of co-located sensors
    fits: dict[str, Any] = field(default_factory=dict)   # axis → NoiseFit of ``fitted``
    fitted: Snapshot | None = None
    #: ``fitted`` with the ADEV intervals its fit supports (analyze's EDF rule), or None
    fitted_intervals: Snapshot | None = None
    temperatures: dict[str, Series] = field(default_factory=dict)
    latest_temps: dict[str, float | None] = field(default_factory=dict)
    timeline: deque[TimelineItem] = field(default_factory=lambda: deque(maxlen=MAX_EVENTS))
    gaps_by_reason: Counter[str] = field(default_factory=Counter)
    gap_samples_by_reason: Counter[str] = field(default_factory=Counter)
    events_by_name: Counter[str] = field(default_factory=Counter)
    last_index: int = 0
    version: int = 0           # bumped on every change a viewer should see
    stats: StreamStats = field(default_factory=StreamStats)
    _next_chip_t: float = -math.inf
    _prev_run_end: int | None = None      # the old run's last index, until the new run's
    _restart_gap_seen: bool = False       # first raw block (or gap record) settles it
    # run → (newest index, newest t_mono) read from the recording, to skip them when live
    _history_end: dict[str, tuple[int, float]] = field(default_factory=dict)

    # ---- the run's clock --------------------------------------------------------------------

    @property
    def nominal_odr_hz(self) -> float:
        for src in (self.header.get("nominal_odr_hz"), self.header.get("rate_hz"),
                    self.status.get("rate_hz")):
            if isinstance(src, int | float) and src > 0:
                return float(src)
        return 0.0

    def run_time(self, index: int | None) -> float:
        """Run time in s of a sample index (the newest known one when None)."""
        odr = self.nominal_odr_hz or 1.0
        return (self.last_index if index is None else int(index)) / odr

    @property
    def rate_ppm(self) -> float | None:
        """The service's fitted ODR relative to nominal, ppm (None before both are known)."""
        rate, nominal = self.status.get("rate_hz"), self.header.get("nominal_odr_hz")
        if isinstance(rate, int | float) and isinstance(nominal, int | float) and nominal > 0:
            return (float(rate) / float(nominal) - 1.0) * 1e6
        return None

    # ---- updates ----------------------------------------------------------------------------

    def join(self, header: dict[str, Any] | None, snapshot: dict[str, Any] | None) -> None:
        """What the request socket answered on join (either may be None)."""
        with self.lock:
            if header:
                self.header = header
                self._note_run(str(header.get("run", "")))
                if isinstance(header.get("i0"), int):
                    self.last_index = max(self.last_index, header["i0"])
            if snapshot:
                self.set_snapshot(snapshot)
            self.version += 1

    def set_snapshot(self, record: dict[str, Any]) -> None:
        """An ``avar`` record (or the request socket's answer, the same record)."""
        self._set_separation(record)
        try:
            snap = AllanSnapshot.from_dict(record.get("snapshot"))   # the one decoder
            comp = record.get("compensated")  # a temperature-compensated snapshot
            compensated = AllanSnapshot.from_dict(comp) if isinstance(comp, dict) else None
        except FormatError as exc:  # ragged arrays from a newer/broken peer
            log.warning("ignoring an unreadable Allan snapshot: %s", exc)
            return
        if len(snap.tau) == 0:
            return  # one without any τ yet (the service's first)
        with self.lock:
            now = self.clock()
            self.snapshot = Snapshot(snap, now, snap.n_samples)
            if compensated is not None:
                self.compensated = Snapshot(compensated, now, compensated.n_samples)
            self.version += 1

    def _set_separation(self, record: dict[str, Any]) -> None:
        """The record's live separation, if it carries one; one that does not decode is
        ignored (logged), and the Allan snapshot beside it is still taken."""
        try:
            sep = separation_of(record)
        except FormatError as exc:
            log.warning("ignoring an unreadable live separation: %s", exc)
            return
        if sep is not None:
            with self.lock:
                self.separation = sep
                self.version += 1

    def update(self, msg: Message, stats: StreamStats | None = None) -> None:
        """A message from the subscriber."""
        rec = msg.record
        with self.lock:
            self.last_message = self.clock()
            if stats is not None:
                self.stats = stats
            if not self._in_history(rec):
                self._apply(rec)

    def replay(self, rec: dict[str, Any]) -> None:
        """A record of the service's recording, read before the live stream (oldest first):
        headers, temperatures, gaps and events; the rest is left to the live stream."""
        kind = rec.get("kind")
        if kind not in HISTORY_KINDS:
            return
        with self.lock:
            self._apply(rec)
            run = str(rec.get("run", ""))
            i0, t = rec.get("i0"), rec.get("t_mono")
            end_i0, end_t = self._history_end.get(run, (-1, -math.inf))
            self._history_end[run] = (max(end_i0, i0) if isinstance(i0, int) else end_i0,
                                      max(end_t, t) if isinstance(t, int | float) else end_t)

    def history_done(self, records: int = 0) -> None:
        """The recording has been read (``records`` of it): the live stream takes over."""
        with self.lock:
            self.history_records = records
            self._prev_run_end = None  # the recording's own restart gaps are in already
            self.version += 1

    def _in_history(self, rec: dict[str, Any]) -> bool:
        """True for a live record the recording already gave (same run, not newer)."""
        end = self._history_end.get(str(rec.get("run", "")))
        if end is None or rec.get("kind") not in ("temp", "gap", "event"):
            return False
        i0, t = rec.get("i0"), rec.get("t_mono")
        if isinstance(i0, int):
            return i0 <= end[0]
        return isinstance(t, int | float) and t <= end[1]

    def _apply(self, rec: dict[str, Any]) -> None:
        with self.lock:
            self._note_run(str(rec.get("run", "")))
            kind = rec.get("kind")
            if kind == "gap" and rec.get("reason") == "restart":
                self._restart_gap_seen = True
            i0 = rec.get("i0")
            if isinstance(i0, int):
                end = i0 + int(rec.get("n", 0) or 0) if kind in ("raw", "gap") else i0
                self.last_index = max(self.last_index, end)
            if kind == "raw" and self._prev_run_end is not None:
                self._restart_between_runs(rec)
            if kind == "raw":
                chip = rec.get("chip_temp_c")
                if isinstance(chip, int | float):
                    self._temperature("chip", self.run_time(rec["i0"]), float(chip))
                return  # raw blocks alone do not change the page (status records do)
            if kind == "temp":
                t = self.run_time(rec["i0"])
                for name, value in zip(rec["names"], rec["values_c"], strict=False):
                    self._temperature(str(name), t, value)
            elif kind == "avar":
                self.set_snapshot(rec)
            elif kind == "status":
                self.status = dict(rec["status"])
                self.status_received = self.clock()
                if isinstance(self.status.get("index"), int):
                    self.last_index = max(self.last_index, self.status["index"])
            elif kind == "header":
                self.header = rec
            elif kind == "gap":
                self._gap(rec)
            elif kind == "event":
                self._event(rec)
            self.version += 1

    def _note_run(self, run: str) -> None:
        if run and (not self.runs or self.runs[-1] != run):
            if self.runs:  # the service restarted: a marker on the time line
                self.timeline.append(TimelineItem("event", "new run", self.run_time(None),
                                                  run=run, detail=f"run {run}"))
                self.events_by_name["new run"] += 1
                self._prev_run_end, self._restart_gap_seen = self.last_index, False
            self.runs.append(run)

    def _restart_between_runs(self, rec: dict[str, Any]) -> None:
        """The first raw block of a new run: if the service's ``restart`` gap record did not
        reach us (it is published the moment the new run's socket binds, before a subscriber
        can reconnect), the samples between the runs become a ``restart`` gap here."""
        prev, self._prev_run_end = self._prev_run_end, None
        if self._restart_gap_seen or prev is None or rec["i0"] < prev:
            return
        n = int(rec["i0"]) - prev
        self.gaps_by_reason["restart"] += 1
        self.gap_samples_by_reason["restart"] += n
        self.timeline.append(TimelineItem(
            "gap", "restart", self.run_time(prev), samples=n, run=str(rec.get("run", "")),
            detail=f"{n} samples ({n / (self.nominal_odr_hz or 1.0):.3g} s) between the "
                   "runs not seen here (service restart; its gap record came before this "
                   "server reconnected)"))

    def _temperature(self, name: str, t: float, value: Any) -> None:
        ok = isinstance(value, int | float) and math.isfinite(value)
        self.latest_temps[name] = float(value) if ok else None
        if not ok:
            return
        if name == "chip":
            if t < self._next_chip_t:
                return
            self._next_chip_t = t + CHIP_SERIES_STEP_S
        self.temperatures.setdefault(name, Series()).append(t, float(value))

    def _gap(self, rec: dict[str, Any]) -> None:
        reason = str(rec.get("reason", "unknown"))
        n = int(rec.get("n", 0) or 0)
        self.gaps_by_reason[reason] += 1
        self.gap_samples_by_reason[reason] += n
        self.timeline.append(TimelineItem(
            "gap", reason, self.run_time(rec.get("i0")), samples=n, run=str(rec.get("run", "")),
            detail=f"{n} samples ({n / (self.nominal_odr_hz or 1.0):.3g} s) lost: {reason}"))

    def _event(self, rec: dict[str, Any]) -> None:
        name = str(rec.get("name", "event"))
        self.events_by_name[name] += 1
        detail = rec.get("detail")
        text = ", ".join(f"{k}={v}" for k, v in detail.items()) if isinstance(detail, dict) \
            else ""
        self.timeline.append(TimelineItem("event", name, self.run_time(rec.get("i0")),
                                          run=str(rec.get("run", "")), detail=text[:200]))

    # ---- the fit ----------------------------------------------------------------------------

    def fit_due(self) -> Snapshot | None:
        """The snapshot to fit when the current fit belongs to an older one, else None."""
        with self.lock:
            snap = self.snapshot
            return None if snap is None or snap is self.fitted else snap

    def set_fits(self, fits: dict[str, Any], snapshot: Snapshot,
                 intervals: AllanSnapshot | None = None) -> None:
        """The fit of ``snapshot`` (kept even when a newer snapshot arrived meanwhile: the
        page says which snapshot the fit belongs to); ``intervals``: its data with the ADEV
        intervals the fit supports (``snapshots.fit_intervals``)."""
        with self.lock:
            self.fits, self.fitted = fits, snapshot
            self.fitted_intervals = None if intervals is None else \
                Snapshot(intervals, snapshot.received, snapshot.n_samples)
            self.version += 1

    def shown(self) -> Snapshot | None:
        """The snapshot to draw: the latest, with its fit's intervals once it is fitted."""
        with self.lock:
            snap = self.snapshot
            if snap is not None and snap is self.fitted and self.fitted_intervals is not None:
                return self.fitted_intervals
            return snap

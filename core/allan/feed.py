"""The Allan feed: one definition of "what the accumulators saw", shared by the service and
the offline replay.

:class:`AllanFeed` turns raw and temperature records into the (n, 3 + k) blocks the streaming
accumulators take; :class:`Segmenter` is the one rule for where their segments end. Neither
reads files: the recording's walk (``avard.core.io.recording.walk``) hands them records, and
``avard.core.allan.replay`` replays a recording directory into them.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np
from avard.core.errors import DataError, FormatError


def nominal_of(header: dict[str, Any]) -> float | None:
    """A header's nominal output data rate (Hz: the ODR setting, not the fitted rate), or
    None when it does not say (recordings of older versions)."""
    v = header.get("nominal_odr_hz")
    return float(v) if isinstance(v, int | float) and v > 0 else None


def scale_of(header: dict[str, Any]) -> float:
    """A header's ``scale_m_s2_per_count`` (m/s² per count), or FormatError naming the run."""
    scale = header.get("scale_m_s2_per_count")
    if not isinstance(scale, int | float) or not scale > 0:
        raise FormatError(f"header of run {header.get('run')!r} has no positive "
                          "scale_m_s2_per_count; this recording cannot be converted to m/s²")
    return float(scale)


class Segmenter:
    """The one rule for where the accumulators' segments end: at every gap record, every run
    change (a header of another run) and every jump in the sample index. :class:`AllanFeed`
    breaks its segments by it; ``load_recording`` records the same breaks for ``avard
    analyze`` (``meta["segment_bounds"]``), so both average over exactly the same stretches."""

    def __init__(self) -> None:
        self.run: str | None = None
        self.next_index: int | None = None
        self.n = 0                      # raw samples seen
        self.bounds: list[int] = [0]    # sample counts where a segment starts, then the end

    def starts_segment(self, rec: dict[str, Any]) -> bool:
        """Whether ``rec`` ends the current segment (before its own samples, if any)."""
        kind = rec["kind"]
        cut = False
        if kind == "header" and rec["run"] != self.run:
            self.run, cut = rec["run"], True
        elif kind == "gap":
            cut = True
        elif kind == "raw":
            i0 = int(rec["i0"])
            cut = self.next_index is not None and i0 != self.next_index
        if cut:
            self.next_index = None
            if self.bounds[-1] != self.n:
                self.bounds.append(self.n)
        if kind == "raw":
            self.next_index = int(rec["i0"]) + int(rec["n"])
            self.n += int(rec["n"])
        return cut

    def segment_bounds(self) -> list[int]:
        """0, every break, N: consecutive pairs are the segments' [start, stop) in samples."""
        return self.bounds + ([self.n] if self.bounds[-1] != self.n else [])


class AllanFeed:
    """Builds the (n, 3 + k) blocks the streaming Allan accumulators see, from raw and
    temperature records, identically in the service and in an offline replay.

    Channels are the three axes in m/s² (counts × the header's scale) followed by the
    temperature channels in °C, each held at its last reading (zero-order hold) from the
    sample index the reading was stamped with. Feeding starts only once every temperature
    channel has a first reading (a hold needs a value to hold); samples before that are
    counted in ``skipped``. A jump in the sample index, an explicit gap or a new run ends the
    segment (``StreamingAllan.gap()``), so no Allan cluster straddles lost samples.

    ``sink`` is anything with ``update(block)`` and ``gap()`` (a StreamingAllan).
    """

    def __init__(self, sink: Any, scale_m_s2_per_count: float, temp_names: list[str]) -> None:
        self.sink = sink
        self.scale = float(scale_m_s2_per_count)
        self.temp_names = list(temp_names)
        self._col = {name: 3 + i for i, name in enumerate(self.temp_names)}
        self._held = np.full(len(self.temp_names), np.nan)
        self._pending: list[tuple[int, np.ndarray]] = []   # (i0, held values from i0 on)
        self.next_index: int | None = None
        #: The index after the last sample this feed accounts for (fed, or skipped for want
        #: of a temperature reading); None until told (the service sets it to its start
        #: index, a restore to what the checkpoint held plus the replay). Unlike
        #: ``next_index`` it survives a gap: a checkpoint's ``i_end`` is this, so the restore
        #: replays exactly the samples after it, never the ones the accumulators hold.
        self.covered: int | None = None
        #: The index the accumulators started from (empty then): they can never hold more
        #: than ``covered - origin`` samples, whatever retention deleted since. None when
        #: unknown (a checkpoint written before this was kept).
        self.origin: int | None = None
        self.fed = 0
        self.skipped = 0
        self._open = False          # samples fed since the last gap()
        self.run: str | None = None
        #: The nominal ODR (Hz) of the samples the accumulators hold: set by the first run's
        #: header, or by whoever built the accumulators at a configured rate (the service,
        #: for its live feed and at its restore). A run at another ODR cannot join them
        #: (their τ are counted in samples).
        self.nominal_hz: float | None = None
        self._segments = Segmenter()

    @property
    def channels(self) -> list[str]:
        return ["x", "y", "z", *self.temp_names]

    # -- state for checkpoints -------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        """What the feed needs to continue exactly: held temperatures, pending readings."""
        return {"next_index": self.next_index, "covered": self.covered, "origin": self.origin,
                "held": [float(v) for v in self._held],
                "pending": [[int(i), [float(v) for v in h]] for i, h in self._pending],
                "temp_names": list(self.temp_names), "scale": self.scale, "open": self._open,
                "run": self.run, "nominal_hz": self.nominal_hz}

    @classmethod
    def from_state(cls, sink: Any, state: dict[str, Any]) -> AllanFeed:
        """The feed of :meth:`state`, feeding ``sink`` (the restored accumulators)."""
        feed = cls(sink, float(state["scale"]), list(state["temp_names"]))
        feed.next_index = state["next_index"]
        covered, origin = state.get("covered"), state.get("origin")
        feed.covered = None if covered is None else int(covered)
        feed.origin = None if origin is None else int(origin)
        feed._held = np.array(state["held"], dtype=float)
        feed._pending = [(int(i), np.array(h, dtype=float)) for i, h in state["pending"]]
        feed._open = bool(state.get("open", False))
        feed.run = feed._segments.run = state.get("run")
        nominal = state.get("nominal_hz")
        feed.nominal_hz = float(nominal) if isinstance(nominal, int | float) else None
        feed._segments.next_index = feed.next_index
        return feed

    # -- records -------------------------------------------------------------------------
    def apply(self, rec: dict[str, Any]) -> None:
        """Feed one record as the service did: a new run's header starts a new segment with
        that run's scale and temperature channels (held values start unknown, as in a freshly
        started service); raw, temp and gap records go to :meth:`raw`, :meth:`temp`,
        :meth:`gap`; other kinds are not data."""
        kind = rec["kind"]
        if self._segments.starts_segment(rec):
            self.gap()
        if kind == "header":
            if rec["run"] != self.run:
                self._same_rate(rec)
                self.run = rec["run"]
                self.scale = scale_of(rec)
                self.temp_names = list(rec.get("temperature_channels", []))
                self._col = {name: 3 + i for i, name in enumerate(self.temp_names)}
                self._held = np.full(len(self.temp_names), np.nan)
                self._pending = []
        elif kind == "raw":
            self.raw(int(rec["i0"]), rec["counts"])
        elif kind == "temp":
            self.temp(int(rec["i0"]), rec["names"], rec["values_c"])
        elif kind == "gap":
            self.gap()

    def _same_rate(self, header: dict[str, Any]) -> None:
        """A new run must be at the accumulators' nominal ODR: their τ are sample counts, so
        samples at another rate would be averaged as if they were these (no error, a wrong
        curve). Raises DataError naming both rates; the first run known sets the rate."""
        nominal = nominal_of(header)
        if nominal is None:
            return
        if self.nominal_hz is None:
            self.nominal_hz = nominal
        elif nominal != self.nominal_hz:
            raise DataError(
                f"run {header.get('run')!r} was recorded at a nominal {nominal:g} Hz and the "
                f"accumulators hold samples at {self.nominal_hz:g} Hz: one set of Allan "
                "accumulators holds one output data rate; keep each rate in its own data "
                "directory, or analyse each run separately (avard analyze --run RUN)")

    def replay(self, records: Iterable[dict[str, Any]], *, after: int | None = None) -> int:
        """Feed every record of ``records`` (as :func:`walk` yields them), skipping samples
        and readings before index ``after`` (what a checkpoint already holds), whatever run
        wrote them. Returns the number of samples fed."""
        n0 = self.fed
        if after is not None:
            self.cover(after)
        for rec in records:
            kind = rec["kind"]
            if after is not None and kind in ("raw", "temp", "gap"):
                i0 = int(rec["i0"])
                if kind == "raw" and i0 + int(rec["n"]) <= after:
                    continue
                if kind == "raw" and i0 < after:
                    rec = dict(rec, i0=after, n=i0 + int(rec["n"]) - after,
                               counts=rec["counts"][after - i0:])
                elif kind != "raw" and i0 < after:
                    continue
            self.apply(rec)
        return self.fed - n0

    def temp(self, i0: int, names: list[str], values_c: list[float | None]) -> None:
        """A temperature reading valid from sample index ``i0`` on (None = failed read)."""
        held = self._pending[-1][1].copy() if self._pending else self._held.copy()
        for name, value in zip(names, values_c, strict=True):
            col = self._col.get(name)
            if col is not None and value is not None:
                held[col - 3] = float(value)
        self._pending.append((int(i0), held))

    def cover(self, index: int) -> None:
        """Every sample before ``index`` is accounted for (never moves back)."""
        if self.covered is None or index > self.covered:
            self.covered = int(index)

    def gap(self) -> None:
        """Samples are missing here: end the accumulators' segment."""
        if self._open:
            self.sink.gap()
            self._open = False
        self.next_index = None

    def raw(self, i0: int, counts: np.ndarray) -> None:
        """A block of raw counts (n, 3) for samples ``[i0, i0 + n)``."""
        n = int(counts.shape[0])
        if n == 0:
            return
        if self.next_index is not None and i0 != self.next_index:
            self.gap()
        self.next_index = i0 + n
        self.cover(i0 + n)
        block = np.empty((n, 3 + len(self.temp_names)))
        block[:, :3] = np.asarray(counts, dtype=np.float64) * self.scale
        # Piecewise-constant temperature columns: apply the pending readings in order.
        start = 0
        held = self._held
        while self._pending and self._pending[0][0] < i0 + n:
            at, values = self._pending.pop(0)
            cut = max(0, at - i0)
            block[start:cut, 3:] = held
            start = max(start, cut)
            held = values
        block[start:, 3:] = held
        self._held = held
        if len(self.temp_names):
            known = ~np.isnan(block[:, 3:]).any(axis=1)
            if not known.all():
                first = int(np.argmax(known)) if known.any() else n
                self.skipped += first
                block = block[first:]
        if block.shape[0]:
            self.sink.update(block)
            self.fed += block.shape[0]
            self._open = True

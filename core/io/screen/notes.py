"""What the screen found and how it is said: a log's note (``LogNote``), a screened record's
counts and stretches (``Screened``, ``ScreenLog``), and the block every screening pass reads."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from avard.core.io.screen.log_step import coarse_cause, coarse_text, is_coarse
from numpy.typing import NDArray


@dataclass(frozen=True)
class LogNote:
    """What the screen found of one temperature log as a whole: ``kind`` (held,
    held_unknown, fahrenheit, off_grid, celsius_assumed, coarse_step; two joined by '+') and
    its one line of text."""
    kind: str
    text: str
    #: a log read in several stretches (held, as it is): {start_s, end_s, read, cadence_samples}
    stretches: tuple[dict[str, Any], ...] = ()

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"kind": self.kind, "text": self.text}
        if self.stretches:
            out["stretches"] = [dict(x) for x in self.stretches]
        return out

    def joined(self, other: LogNote) -> LogNote:
        """One line per channel: this note and ``other`` together."""
        return LogNote(f"{self.kind}+{other.kind}", f"{self.text}; {other.text}",
                       self.stretches + other.stretches)


@dataclass(frozen=True)
class Screened:
    """One masked (or, for a dropout, missing) stretch: the channel, what it is, its first and
    last sample (record index) and time (s from the record's start), and how many samples
    (acceleration) or readings (temperature) were masked."""

    channel: str
    kind: str
    first: int
    last: int
    start_s: float
    end_s: float
    count: int
    #: the axes a held acceleration held (the rows are cut on every axis)
    axes: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "channel": self.channel, "kind": self.kind, "start_s": self.start_s,
            "end_s": self.end_s, "first_sample": self.first, "last_sample": self.last,
            "count": self.count}
        if self.axes:
            out["axes"] = list(self.axes)
        return out


KIND_TEXT = {"startup_glitch": "start-up glitch", "shock": "isolated shock",
             "held_accel": "held acceleration (identical samples)",
             "read_error": "read error (-127 °C or out of range)",
             "power_on_85": "85.0 °C power-on value", "spike": "spike",
             "dropout": "dropout (no reading)", "stuck": "stuck reading",
             "log_starts_late": "log starts late (no reading from the record's start)",
             "log_ends_early": "log ends early (no reading to the record's end)"}
# the plural where an "s" at the end would land inside the kind's parenthesis
_KIND_PLURAL = {"read_error": "read errors (-127 °C or out of range)",
                "held_accel": "held accelerations (identical samples)",
                "dropout": "dropouts (no reading)",
                "log_starts_late": "logs start late (no reading from the record's start)",
                "log_ends_early": "logs end early (no reading to the record's end)"}


def _kind_text(kind: str, n: int) -> str:
    """``n`` stretches of ``kind`` in words: "1 dropout (no reading)", "2 read errors (…)"."""
    if n == 1:
        return f"1 {KIND_TEXT.get(kind, kind)}"
    return f"{n} {_KIND_PLURAL.get(kind) or KIND_TEXT.get(kind, kind) + 's'}"


#: The kinds cut out of the acceleration (every axis's rows)
ACCEL_KINDS = ("startup_glitch", "shock", "held_accel")


@dataclass
class ScreenLog:
    """What the screen masked, filled while the blocks stream (``screen_blocks``)."""

    rate_hz: float
    stretches: list[Screened] = field(default_factory=list)
    done: bool = False
    #: readings judged per temperature channel (filled at the end of the read)
    readings: dict[str, int] = field(default_factory=dict)
    #: per temperature channel, what the screen found of the log as a whole (a held log
    #: read as readings, readings off the DS18B20's grid, a log in °F): {kind, text}
    notes: dict[str, LogNote] = field(default_factory=dict)
    #: temperature channels the thermal model must not use, with why (a log in °F)
    refused: dict[str, str] = field(default_factory=dict)
    #: the logs' units as asked (``--temperature-units``): auto, C or F
    units: str = "auto"
    #: per temperature channel, the (step K, origin) of its readings' grid (``log_step``;
    #: None: on no grid found), filled at the end of the read; the thermal model's rounding
    #: assumes the DS18B20's 12-bit ``DS18B20_STEP_C``
    steps: dict[str, tuple[float, float] | None] = field(default_factory=dict)

    def coarse(self, channel: str, cause: bool = False) -> str | None:
        """``channel``'s readings' step in words (``coarse_text``; ``cause``: as a possible
        cause of a misfit, ``coarse_cause``) when it is coarser than the DS18B20's 12-bit
        0.0625 K (a DS18B20 at 9–11 bits, a °F log taken as °C, a coarse print); None
        otherwise."""
        grid = self.steps.get(channel)
        if grid is None or not is_coarse(grid[0]):
            return None
        return coarse_cause(grid) if cause else coarse_text(grid)

    def rounding_grid(self, channel: str) -> tuple[float, float] | None:
        """The (step, origin) of ``channel``'s own readings where it is coarser than the
        12-bit 0.0625 K and the log is used (not refused); None otherwise (the 12-bit
        default). Each log is read on its own step and origin: a coarse log leaves the
        reconstruction, the regressor and the rounding floors of a finer one as they are."""
        grid = self.steps.get(channel)
        if grid is None or channel in self.refused or self.coarse(channel) is None:
            return None
        return grid

    def counts(self) -> dict[str, int]:
        """Stretches per kind."""
        out: dict[str, int] = {}
        for s in self.stretches:
            out[s.kind] = out.get(s.kind, 0) + 1
        return out

    def samples_masked(self) -> int:
        """Acceleration samples cut out (every axis)."""
        return sum(s.count for s in self.stretches if s.kind in ACCEL_KINDS)

    def holes(self, channel: str) -> list[tuple[float, float]]:
        """(start, end) s of the stretches of a temperature channel where the log says
        nothing about the temperature (masked readings, dropouts, stuck runs, the span
        before a late log's first reading and after an early-ending log's last)."""
        return [(s.start_s, s.end_s) for s in self.stretches if s.channel == channel]

    def hole_blocks(self, channel: str, rate_hz: float, first: int = 0
                    ) -> list[tuple[int, int]]:
        """The holes of a second or more (``holes``) as (first, last) block indices at
        ``rate_hz`` blocks per second, counted from block ``first`` (a part of the record):
        the spans the thermal regression leaves out (``thermal_fit.hole_mask``)."""
        return [(math.floor(h0 * rate_hz) - first, math.ceil(h1 * rate_hz) - first)
                for h0, h1 in self.holes(channel) if h1 - h0 >= 1.0]

    def to_dict(self) -> dict[str, Any]:
        return {"counts": self.counts(), "samples_masked": self.samples_masked(),
                "stretches": [s.to_dict() for s in self.stretches],
                "notes": {k: v.to_dict() for k, v in self.notes.items()},
                "refused": dict(self.refused),
                "temperature_units": self.units,
                "reading_steps": {k: None if v is None else
                                  {"step_k": v[0], "origin_k": v[1],
                                   "coarse": bool(self.coarse(k))}
                                  for k, v in self.steps.items()},
                "rules": ("acceleration: a sample > 12 robust σ of the sample scale from the "
                          "median of its 17 neighbours (any axis), cut out as a gap, the "
                          "scale never below the grid's quantisation (q/√12) on a grid "
                          "coarse against the noise, nor, where the median is below that, "
                          "the distances' RMS below their 98th percentile; a run of "
                          "identical samples on an axis (held or stuck: a repeated frame) "
                          "longer than its axis's own chance of a repeat makes likely at "
                          "1e-6 per record of up to 2^25 samples (the tail of the axis's "
                          "own run lengths, counted as runs: the decay from the length 200 "
                          "runs reach to the length 20 reach, 1 + 3/√20 longer; the longer "
                          "of the whole read's and the runs' from its own block on; at "
                          "least 16 samples), cut out as a gap on every axis; "
                          "temperature: -127 °C / out of range, 85.0 °C > 0.5 K from its "
                          "neighbours, single-reading spikes > 0.5 K, dropouts > 10 s (and "
                          "8 reading intervals), the same before a log's first reading and "
                          "after its last, runs of one value > 30 min and 10x the channel's "
                          "95th-percentile run; a log all 85.0 °C refused (a DS18B20 that "
                          "never converted); "
                          "a log with a value on every sample that changes only on a regular "
                          "cadence is held (judged over the whole log, stretch by stretch): "
                          "its readings are each change and one every cadence after it "
                          "until the next, across a dropout too; readings off the 0.0625 K "
                          "grid (under half of the distinct values on it) are noted, and "
                          "refused as °F where most are on a DS18B20's grid in °F "
                          "(32 + 0.1125·k), unless --temperature-units says C or F (F: "
                          "converted to °C before every rule); each log's reading step "
                          "found from its distinct values (the largest step with >= 95 % of "
                          "them on one grid and two pairs exactly one step apart: a "
                          "DS18B20's 9-12 bits in °C or °F, a print's 0.1, or the values' "
                          "own spacing), a step coarser than the 12-bit 0.0625 K noted "
                          "(the thermal model then reconstructs the temperature from the "
                          "readings' crossings and takes its rounding on that step)"),
                "units": {"start_s": "s", "end_s": "s"}}

    def lines(self, limit: int = 8) -> list[str]:
        """The text: one summary line, then up to ``limit`` stretches with their times, then
        one line per temperature channel the screen has a note on."""
        notes = [f"  temperature {ch}: {n.text}" for ch, n in self.notes.items()]
        if not self.stretches:
            if any("power_on_85" in n.kind.split("+") for n in self.notes.values()):
                # not "no 85 °C": a log all 85 °C is masked by no per-reading rule, its note says
                return ["screened: nothing masked reading by reading", *notes]
            return ["screened: nothing masked (no glitch, shock, held acceleration, read "
                    "error, 85 °C, spike, dropout or stuck reading)", *notes]
        c = self.counts()
        head = "screened: " + ", ".join(_kind_text(k, n) for k, n in sorted(c.items()))
        if self.samples_masked():
            head += f"; {self.samples_masked()} acceleration samples cut out as gaps"
        out = [head]
        for s in self.stretches[:limit]:
            unit = "sample" if s.kind in ACCEL_KINDS else "reading"
            ch = f"{s.channel} ({', '.join(s.axes)})" if s.axes else s.channel
            out.append(f"  {ch}: {KIND_TEXT.get(s.kind, s.kind)} at "
                       f"{s.start_s:.6g}–{s.end_s:.6g} s ({s.count} "
                       f"{unit}{'' if s.count == 1 else 's'})")
        if len(self.stretches) > limit:
            out.append(f"  … and {len(self.stretches) - limit} more (--json lists all)")
        return out + notes


# --------------------------------------------------------------------------------------------
# the stream

#: (accel (n, C) m/s², temperature (n, k) °C or None, ends a segment)
Block = tuple[NDArray[np.float64], NDArray[np.float64] | None, bool]

"""Screening of a record's inputs before any estimator sees them: what a weekend's logs really
hold besides the sensor's noise, each masked, counted and listed with its time.

One screen for ``avard analyze`` and ``avard explain`` alike: ``ScreenedSource`` (the one
segment iterator of both) passes its blocks through :func:`screen_blocks`. Nothing is interpolated
here; a masked stretch is a *gap* to the estimators.

**Acceleration** (all axes together: a shock or a corrupted frame is an event of the sensor,
and one rule for every axis keeps the passes that read the axes in groups on the same samples).
A sample is an outlier when, on some axis, it leaves the median of its 17 neighbours by more
than ``SHOCK_Z`` times the block's robust scale of that kind of distance (the median absolute
distance of a sample from its 17 neighbours' mean / 0.6745: the fast part of the noise, which
random walk and flicker do not touch, and which a chip filter's correlated samples keep
consistent with the test); the 17-sample median follows a step or a slow drift, so only
stretches of at most 8 samples stand out (a step is never masked). Outliers within
``SHOCK_MARGIN`` samples of each other make one stretch, widened by that margin (the chip's
filter spreads a shock), and the stretch is cut out: the block is split there and a segment
ends before it, so no Allan difference and no spectrum segment straddles it. In the first
second of a record it is a ``startup_glitch``, later a ``shock``. At ``SHOCK_Z`` = 12 a
Gaussian record of 10^10 samples has no false mask (P(|z| > 12) ≈ 4e-33 per sample). On a
record whose grid is coarse against its noise (noise below about one LSB) the distances take
a few discrete values and their median is 0 or a fraction of a step: ±1 LSB samples were cut
as shocks. There the scale is never below the grid's quantisation (q/√12 of the step q, the
smallest change the block's axis makes, its 16/17 share in the distance), and where the
median's scale is below that, never below the distances' RMS below their 98th percentile
either (``grid_scale``), so a shock must stand ≥ 3.4 LSB out whatever the noise, and nothing
is cut from quantisation; where the median stands above the quantisation it is kept (the
RMS would take a block's bursts of vibration for its noise).

A **held acceleration** (``held_accel``: a stuck FIFO, a driver repeating its last frame) is a
run of identical samples on an axis longer than the axis's own chance of a repeat makes likely
at ``HELD_ALARM`` per record (``held_threshold``, ``HeldAccel``: judged over the whole read in
bounded memory, a run across blocks one stretch). It is cut out as a gap on every axis, like a
shock, and its rows are left out of the shock rule's scale.

**Temperature** (each DS18B20 channel, readings where the column is finite):

- ``read_error``: −127 °C (the driver's value for a failed CRC or a missing device) or any
  reading outside the DS18B20's range (−55…125 °C);
- ``power_on_85``: exactly 85.0 °C (the power-on-reset register) more than ``JUMP_C`` from the
  nearest good readings on either side (a room at 85 °C would have neighbours near 85);
- ``spike``: a single reading more than ``JUMP_C`` from both neighbours, which agree with each
  other to within ``JUMP_C``/2 (a room or a plate does not move 0.5 K and back in two
  readings; that is 8 steps of the 0.0625 K resolution);
- ``dropout``: no reading for longer than ``DROPOUT_S`` (and ``DROPOUT_READINGS`` reading
  intervals); nothing to mask, but listed: explain never names a cause on another channel
  in such a hole (a hole in a log is not a cause);
- ``log_starts_late`` / ``log_ends_early``: no reading between the record's start and the
  log's first reading, or between its last reading and the record's end, for longer than a
  dropout by the same rule: a hole like a dropout (the gaps between readings are all the
  dropout rule sees; a log that stops midway and never comes back had none);
- a log whose every reading is 85.0 °C is a DS18B20 that never converted (its power-on
  value, forever): noted and refused for the thermal model (the per-reading rule has no good
  neighbour to judge it by);
- ``stuck``: a run of one identical value longer than ``STUCK_MIN_S`` *and* ``STUCK_FACTOR``
  times the 95th percentile of the channel's own runs. A DS18B20 in a stable room reads the
  same 0.0625 K step for hours, which is normal: its runs are all long, so the rule, made of
  the record's own statistics, does not fire; in a room whose readings change every few
  minutes a run of hours is not the room. Masked like a dropout (the value is not evidence of
  the temperature).

Masked temperature readings become NaN (the slow view then has no reading there).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from avard.core.allan import kernels
from avard.core.io.source import RecordFormat
from numpy.typing import NDArray

__all__ = ["ScreenLog", "Screened", "screen_accel", "screen_blocks", "screen_record",
           "screen_temperature", "stuck_runs"]

#: Robust σ of the sample scale an acceleration outlier must exceed.
SHOCK_Z = 12.0
#: Half-window of the running median (samples): stretches up to this long stand out.
SHOCK_HALF = 8
#: Samples around an outlier that go with it (and that join two outliers into one stretch).
SHOCK_MARGIN = 2
#: Seconds after a record's start where an outlier is a start-up glitch.
STARTUP_S = 1.0
#: The DS18B20's range (°C) and its error value.
DS18B20_MIN_C, DS18B20_MAX_C, DS18B20_ERROR_C = -55.0, 125.0, -127.0
#: The power-on-reset value.
POWER_ON_C = 85.0
#: A jump (K) a room or a plate cannot make and undo between two readings.
JUMP_C = 0.5
#: A hole in a temperature log longer than this (s) and this many reading intervals.
DROPOUT_S, DROPOUT_READINGS = 10.0, 8.0
#: The stuck rule: longer than this (s) and this factor times the channel's 95th-percentile run.
STUCK_MIN_S, STUCK_FACTOR = 1800.0, 10.0
#: The DS18B20's resolution (K): its readings (9–12 bits) are multiples of this.
DS18B20_STEP_C = 0.0625
#: A log is off the DS18B20's grid when fewer than this share of its readings lie on it.
OFF_GRID_SHARE = 0.5
#: Readings on the DS18B20's °C grid whose median lies here (°F of a 10–40 °C room): a note
#: that °C is assumed.
FAHRENHEIT_ROOM = (50.0, 104.0)
#: A log in °F: at least this share of its distinct values on a DS18B20's grid in °F
#: (32 + 0.1125·k), of at least this many distinct values (and off the °C grid).
FAHRENHEIT_SHARE, FAHRENHEIT_MIN_VALUES = 0.8, 5
#: ... at a °F room's values, fewer suffice: a value lands on the °F grid within the printing
#: by chance about one time in nine, so three together about once in 800 (a stable room
#: dwells on few values)
FAHRENHEIT_MIN_VALUES_ROOM = 3
#: A log printed this coarsely (every value a multiple of it) holds neither grid: its
#: rounding is wider than both the °C grid's and the °F grid's steps
COARSE_PRINT = 0.1
#: A value is on a grid within this (°C or °F): a logger printing 2 decimals rounds a grid
#: point by up to 0.005, and the float rounding of its text adds a little.
PRINT_TOL = 0.006
#: Temperature channels that are no DS18B20 (avard's own ADXL355 die temperature, on its own
#: ~0.11 K step): the DS18B20 grid's units rule does not judge them.
NOT_DS18B20 = frozenset({"chip"})
#: ``--temperature-units``: judged from the readings (auto), or said by the user: °C (never
#: refused as °F) or °F (converted to °C before any rule, the 85 °C and −127 °C values
#: included: 185 °F and −196.6 °F)
TEMPERATURE_UNITS = ("auto", "C", "F")


def temperature_units(text: str | None) -> str:
    """``--temperature-units``'s value: "auto", "C" or "F" (any case, a leading ° allowed);
    a ConfigError (one line) otherwise."""
    from avard.core.errors import ConfigError

    word = "auto" if text is None else str(text).strip().lstrip("°")
    for u in TEMPERATURE_UNITS:
        if word.lower() == u.lower():
            return u
    raise ConfigError(f"--temperature-units {text}: give auto (judged from the readings), "
                      "C or F (the logs' units, said for every temperature log)")


#: Held-log detection, on a channel's first rows: a value on at least this share of them.
HELD_DENSE = 0.95
#: A common divisor k of n run lengths is a cadence when k^n reaches this (chance ≤ 1e-4),
#: with at least this many runs.
HELD_CHANCE, HELD_MIN_COMMON = 1e4, 3
#: A cadence that is no whole number of samples: read from the first this many changes, at
#: least this many, their phases' coherence at least this, among at most this many cadences.
HELD_EVENTS, HELD_MIN_EVENTS, HELD_COHERENCE, HELD_MAX_CANDIDATES = 64, 32, 0.9, 400_000
#: Runs that pin a common divisor as the cadence, not a multiple of it (2^-14 ≈ 6e-5),
#: waited for where the log allows.
HELD_PIN_RUNS = 14
#: A dense log whose first rows hold too few runs is judged on up to this many rows.
HELD_WAIT_SAMPLES = 1 << 19
#: A held stretch found after the first rows (the whole log is watched, block by block):
#: the chance of a log read on every sample showing it, at most 1/this a test
HELD_SWITCH_CHANCE = 1e9
#: The changes of value kept per channel for that test (bounded, whatever the record's length)
HELD_RING = 128
#: A cadence that is no whole number of samples: a run's length within a sample's rounding
#: and this share of it (a logger's clock against the sampler's) of a multiple of it
HELD_TOL_SAMPLES, HELD_TOL_DRIFT = 1.0, 1e-4
#: Stretches named in a log's note (the JSON lists all)
HELD_NOTE_STRETCHES = 8
#: A steady ramp (cannot tell): this share of the runs one multiple of the cadence and of
#: the changes one sign.
RAMP_SHARE = 0.9


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
# acceleration


def _running_median(a: NDArray[np.float64], idx: NDArray[np.intp], half: int
                    ) -> NDArray[np.float64]:
    """Median of a[i − half … i + half] (clipped to the array) at the indices ``idx``."""
    out = np.empty(len(idx))
    for k, i in enumerate(idx):
        out[k] = np.median(a[max(0, i - half):i + half + 1])
    return out


def _local_residual(col: NDArray[np.float64], half: int) -> NDArray[np.float64]:
    """col minus the mean of its 2·half + 1 neighbours (reflected at the ends, so a glitch in
    the first samples still stands out), by one cumulative sum: the high-pass statistic whose
    robust spread scales the outlier test."""
    x = np.pad(col - col[0], half, mode="reflect")
    c = np.empty(len(x) + 1)
    c[0] = 0.0
    np.cumsum(x, out=c[1:])
    w = 2 * half + 1
    return np.asarray(col - col[0] - (c[w:] - c[:-w]) / w, dtype=float)


#: ``_median_floor``'s guess: this share of the median of every ``FLOOR_STRIDE``-th value, far
#: enough below the median that the count proves it (the guess's spread on a block's 1024
#: values is ~4 %), near enough that a block without outliers stays below the test.
FLOOR_SHARE, FLOOR_STRIDE = 0.85, 16


def _median_floor(x: NDArray[np.float64]) -> float:
    """A number proven ≤ ``np.median(x)``, or 0.0 when the cheap guess cannot be proven.

    The guess v is ``FLOOR_SHARE`` of the median of a subsample; it is a floor when at most
    (n − 1) // 2 values lie below it, for then the middle order statistic(s), and their
    mean, are ≥ v. A count and a subsample's median cost a fraction of the median of all
    values (a partition whose time depends on the data: 60–220 µs a block's axis)."""
    n = len(x)
    if n < 2 * FLOOR_STRIDE:
        return 0.0
    v = FLOOR_SHARE * float(np.median(x[::FLOOR_STRIDE]))
    if not v > 0 or int(np.count_nonzero(x < v)) > (n - 1) // 2:
        return 0.0
    return v


#: |N(0, 1)| below its 98th percentile (2.326): the RMS there is this share of σ
#: (√(1 − 2·2.326·φ(2.326)/0.98)); the top 2 % hold any shock and are left out of the RMS.
TRIM_Q, TRIM_RMS = 0.98, 0.9346
#: the quantisation's share of a sample's distance from its 17 neighbours' mean: the grid
#: step q rounds each sample by up to q/2 (RMS q/√12), and that distance keeps 16/17 of it.
GRID_SHARE = math.sqrt(16.0 / 17.0 / 12.0)
#: the trimmed RMS (used where the median collapsed below the quantisation) is capped at this
#: many times the quantisation: it restores the spread of noise of ~1/3 LSB the median lost
#: (≈ 1.3× the quantisation), and no more; a block a third of it in vibration bursts would
#: raise it above a 20 LSB shock
GRID_RMS_CAP = 2.0
#: changes between samples a block's axis needs before its smallest one is taken as its grid
GRID_MIN_CHANGES = 16


def grid_step(col: NDArray[np.float64]) -> float:
    """The column's grid step (its smallest non-zero change between samples, above the
    floating rounding of its values), 0.0 where it changes fewer than ``GRID_MIN_CHANGES``
    times."""
    d = np.abs(np.diff(col))
    tiny = 64.0 * np.finfo(float).eps * float(np.max(np.abs(col))) if len(col) else 0.0
    d = d[d > tiny]
    # a column that changes a few times shows no grid (one shock on a dead axis is no step)
    return float(d.min()) if len(d) >= GRID_MIN_CHANGES else 0.0


def grid_scale(col: NDArray[np.float64], dist: NDArray[np.float64], scale: float) -> float:
    """A floor of the robust scale on a record whose grid is coarse against its noise (the
    grid step above a quarter of ``scale``, or a scale of 0): the grid's own quantisation
    (q/√12, its share in the distance), and, only where the median's ``scale`` is below that
    (a discrete distribution's median collapsed to 0 or a fraction of a step), the distances'
    RMS below their 98th percentile, at most ``GRID_RMS_CAP`` times the quantisation. Not
    above it: where the median stands at or over the
    quantisation it measures the noise, robust to bursts of vibration holding up to half the
    block, which the RMS is not (20–30 % of a block in ±30 LSB bursts raised the RMS above
    a 40–80 LSB shock's distance, and the shock stayed in). On a record finer than its noise,
    0.0 (the median's scale stands)."""
    q = grid_step(col)
    if not q > 0 or (scale > 0 and q < 0.25 * scale):
        return 0.0
    floor = GRID_SHARE * q
    d = dist[np.isfinite(dist)]
    if not len(d) or scale >= floor:
        return floor
    top = float(np.quantile(d, TRIM_Q))
    low = d[d <= top]
    rms = float(np.sqrt(np.mean(low * low))) / TRIM_RMS if len(low) else 0.0
    return min(max(floor, rms), GRID_RMS_CAP * floor)


def screen_accel(a: NDArray[np.float64], held: NDArray[np.bool_] | None = None
                 ) -> NDArray[np.bool_]:
    """Rows of ``a`` (n, C) that are outliers on some axis (the rule in the module's doc),
    with their margin. The scale is the robust spread of the sample's distance from its
    neighbours' mean (the same statistic, so a chip filter's correlated samples, whose first
    differences are small against their spread, are not taken for shocks); the median of the
    neighbours is taken only where that distance already stands out. ``held``: rows cut as
    held acceleration, left out of the scale (their distances are 0: a block half held had
    its scale collapse, and its live samples cut as shocks) and never shocks."""
    n = len(a)
    bad = np.zeros(n, dtype=bool)
    if n < 2 * SHOCK_HALF + 2:
        return bad
    kern = kernels.compiled()
    dist = np.empty(n)
    for j in range(a.shape[1]):
        col = np.asarray(a[:, j], dtype=float)
        if kern is not None:  # the compiled pass (general path: _local_residual)
            kern.local_residual(col, SHOCK_HALF, dist)
        else:
            np.abs(_local_residual(col, SHOCK_HALF), out=dist)
        if held is not None and held.any():
            dist[held] = 0.0
            live = dist[~held]
            if len(live) < 2 * SHOCK_HALF + 2:
                continue
        else:
            live = dist
        # every 4th sample gives the median to a few % on a block (and a quarter the work)
        sub = live[::4]
        low = _median_floor(sub)
        if low > 0 and float(dist.max()) <= 0.5 * SHOCK_Z * (low / 0.6745):
            # no candidate under the exact scale either: it is ≥ low / 0.6745 (division and
            # product by positive constants keep the order), so the block's median, the
            # costliest step of the screen, is taken only where a sample could stand out
            continue
        scale = float(np.median(sub)) / 0.6745
        # a moving window sum leaves a rounding residue where the exact distance is 0: on a
        # record on its LSB grid most samples equal their neighbours' mean, and a scale made
        # of that residue (1e-21 of a 4e-5 m/s² step) cut every step as a shock; below the
        # sum's own rounding the scale is 0, as the exact median is
        if not scale > 4.0 * len(col) * np.finfo(float).eps * float(np.ptp(col)):
            scale = 0.0
        # (a scale of 0: every sample whose distance is not 0 is a candidate)
        cand = np.flatnonzero(dist > 0.5 * SHOCK_Z * scale)
        if not len(cand):
            continue
        # on a coarse grid the median of a few discrete distances is no scale: never below
        # what the grid's quantisation and the distances' own spread support
        scale = max(scale, grid_scale(col, sub, scale))
        if not scale > 0:
            continue
        # an outlier of k ≤ SHOCK_HALF samples stands at least half out of the mean too
        cand = cand[dist[cand] > 0.5 * SHOCK_Z * scale]
        if not len(cand):
            continue
        med = _running_median(col, cand, SHOCK_HALF)
        out = cand[np.abs(col[cand] - med) > SHOCK_Z * scale]
        bad[out] = True
    if bad.any():
        idx = np.flatnonzero(bad)
        for m in range(1, SHOCK_MARGIN + 1):
            bad[np.clip(idx - m, 0, n - 1)] = True
            bad[np.clip(idx + m, 0, n - 1)] = True
    return bad


def _runs(mask: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """[first, last] of each run of True."""
    if not mask.any():
        return []
    m = np.concatenate([[False], mask, [False]]).astype(np.int8)
    d = np.diff(m)
    return list(zip(np.flatnonzero(d == 1).tolist(), (np.flatnonzero(d == -1) - 1).tolist(),
                    strict=True))


# a held (stuck) accelerometer: a run of identical samples its own noise makes implausible

#: A false alarm of the held rule at most this often per record (per axis) ...
HELD_ALARM = 1e-6
#: ... of up to this many samples (2^25: 74 h at 125 Hz, beyond the daemon's 60 h records); a
#: longer record is counted by the rows seen
HELD_RECORD_SAMPLES = 1 << 25
#: A held stretch is at least this many identical samples whatever its chance (a repeated
#: frame or two is no stretch the estimators need cut), and the parallel chunks (which judge
#: each block on its own) send the record to one read where a block holds half of it
#: (``held_suspect``: a run across a block boundary has half its length on one side)
HELD_MIN_RUN = 16
#: Runs of an axis reaching a length, at least, for the chance of going on from there to be
#: measured (an axis with fewer runs than this is not judged: its chance of a repeat is
#: unknown)
HELD_MIN_RUNS = 200
#: Runs of an axis reaching a length, for the tail's decay to be measured to there (the
#: longest few: a held stretch or two among them do not move it)
HELD_TAIL_RUNS = 20
#: The decay length measured on the tail's runs is taken this much longer (1 + 3/√20: three
#: standard errors of a rate of 20 counts)
HELD_TAIL_MARGIN = 1.0 + 3.0 / math.sqrt(20.0)
#: Runs of this length and longer are counted together (the histogram's bound)
HELD_HIST = 4096


def held_threshold(hist: NDArray[np.int64], rows: int, seen: int | None = None) -> float:
    """The shortest run of identical samples an axis's noise makes implausible, from the
    lengths of its runs (``hist[L]``: runs of L samples, the last bin HELD_HIST and more)
    over ``rows`` samples (of ``seen`` read so far, ``rows`` by default); inf where the axis
    has too few runs to tell.

    A quiet axis on a coarse grid repeats values legitimately, and a chip filter's correlated
    samples repeat in clusters, so the chance is measured on the axis itself, by counts of
    *runs* (a held stretch is one run whatever its length, so it cannot raise the chance that
    clears it): the length L_a that ``HELD_MIN_RUNS`` runs reach and the length L_b that
    ``HELD_TAIL_RUNS`` reach give the tail's decay length λ (runs reaching a length fall e-fold
    every λ samples: a geometric tail, the chance of a repeat independent of the run so far,
    measured on the longest runs, so a mixture of quiet and busy hours has its tail from the
    quiet ones), taken ``HELD_TAIL_MARGIN`` longer for the few runs it is measured on. From
    L_b on, P(run ≥ L_b + x) = F(L_b)·e^(−x/λ); the threshold is the length the runs of a
    record (``HELD_RECORD_SAMPLES`` rows, or the rows seen, at the axis's runs per row) reach
    by chance ``HELD_ALARM`` times, at least ``HELD_MIN_RUN``."""
    ge = np.cumsum(hist[::-1])[::-1].astype(float)  # ge[L]: runs of L samples or more
    n1 = float(ge[1]) if len(ge) > 1 else 0.0
    if n1 < HELD_MIN_RUNS or rows <= 0:
        return math.inf
    la = int(np.flatnonzero(ge >= HELD_MIN_RUNS)[-1])
    lb = int(np.flatnonzero(ge >= HELD_TAIL_RUNS)[-1])
    if lb >= HELD_HIST:
        return math.inf  # runs beyond the histogram are common: nothing to measure
    beyond = max(float(ge[lb + 1]), 0.5)  # the first length fewer runs reach
    lam = (lb + 1 - la) / math.log(float(ge[la]) / beyond) * HELD_TAIL_MARGIN
    runs = n1 / rows * max(HELD_RECORD_SAMPLES, rows if seen is None else seen)
    extra = lam * math.log(max(1.0, runs * float(ge[lb]) / n1 / HELD_ALARM))
    return float(max(HELD_MIN_RUN, lb + math.ceil(extra)))


def _max_run(col: NDArray[np.float64]) -> int:
    """The longest run of identical consecutive samples in ``col``."""
    if not len(col):
        return 0
    ch = np.flatnonzero(col[1:] != col[:-1])
    edges = np.concatenate([[-1], ch, [len(col) - 1]])
    return int(np.max(np.diff(edges)))


def held_suspect(a: NDArray[np.float64]) -> bool:
    """Whether the block (judged on its own, as a parallel chunk does) holds a run of at least
    half ``HELD_MIN_RUN`` identical samples on an axis: then a held stretch may lie here (a run
    across the block's boundary has half its length on one side), and the record is read
    through the whole-record screen (``HeldAccel``) instead. A conservative test: it never
    misses a held stretch, and sends a quiet, coarsely quantised record to one read."""
    half = HELD_MIN_RUN // 2
    return any(_max_run(np.asarray(a[:, j])) >= half for j in range(a.shape[1]))


class HeldAccel:
    """The held-acceleration rule over a whole read, block by block in bounded memory: per
    axis a histogram of run lengths, each block's own (trimmed) while its rows may still be
    judged, and the runs long enough to be candidates that reach rows not yet judged.

    Per axis: a repeated frame repeats every axis, so each axis's own rule sees it; a stuck
    channel of one axis is seen too; and a row cut when any axis says so is the verdict the
    parallel chunks (each judging its own axes) can form. The blocks are ``feed``-ed in order,
    ahead of the rows judged (the screen hands a block on once the next is read, and waits
    while ``undecided``); ``verdict`` judges a block's rows. A run is held when its length
    clears the longer of two thresholds (``held_threshold``): the whole read's, and that of
    the runs from the run's own block on (so an axis that turns quiet, its runs long, is
    judged by its new noise, and not before that noise is measured; a held stretch in a busy
    record has the busy runs after it). A run judged held stays held on the rows that come
    later; a run still open is judged again on the next block, and one longer than
    ``HELD_WAIT_SAMPLES`` by the whole read's threshold alone."""

    def __init__(self) -> None:
        self.rows = 0
        self.last: NDArray[np.float64] | None = None
        self.start: NDArray[np.int64] | None = None  # record row where each open run began
        self.hist: NDArray[np.int64] | None = None
        #: per axis, runs of ≥ HELD_MIN_RUN samples reaching rows not yet judged: [first, last]
        #: (last the run's end so far for the open one)
        self.cand: list[NDArray[np.int64]] = []  # per axis, (k, 2)
        #: per axis, whether each candidate is judged held
        self.held: list[NDArray[np.bool_]] = []
        #: the blocks' own run histograms (per axis, trimmed) while they may be needed:
        #: (offset, rows, [hist per axis])
        self.blocks: list[tuple[int, int, list[NDArray[np.int64]]]] = []
        self._cache: dict[int, tuple[int, float]] = {}

    def feed(self, off: int, a: NDArray[np.float64]) -> None:
        n, c = a.shape
        if not n:
            return
        first = self.last is None
        if self.last is None:
            self.last = np.asarray(a[0], dtype=float).copy()
            self.start = np.full(c, off, dtype=np.int64)
            self.hist = np.zeros((c, HELD_HIST + 1), dtype=np.int64)
            self.cand = [np.zeros((0, 2), dtype=np.int64) for _ in range(c)]
            self.held = [np.zeros(0, dtype=bool) for _ in range(c)]
        assert self.start is not None and self.hist is not None
        own: list[NDArray[np.int64]] = []
        for j in range(c):
            col = np.asarray(a[:, j], dtype=float)
            new = np.flatnonzero(col[1:] != col[:-1]) + 1
            if not first and not col[0] == self.last[j]:
                new = np.concatenate([[0], new])
            begins = np.concatenate([[self.start[j]], off + new])
            lengths = np.minimum(np.diff(begins), HELD_HIST)  # the runs completed here
            h = np.bincount(lengths).astype(np.int64) if len(lengths) else np.zeros(
                1, dtype=np.int64)
            self.hist[j, :len(h)] += h
            own.append(h)
            cand, held = self.cand[j], self.held[j]
            was = False
            if len(cand) and cand[-1, 0] == self.start[j]:
                # the open run, seen again below (completed or still open), its verdict kept
                was = bool(held[-1])
                cand, held = cand[:-1], held[:-1]
            k = np.flatnonzero(lengths >= HELD_MIN_RUN)
            new_c = np.column_stack([begins[k], begins[k + 1] - 1]).astype(np.int64)
            self.start[j] = begins[-1]
            if off + n - self.start[j] >= HELD_MIN_RUN:
                new_c = np.vstack([new_c, [[self.start[j], off + n - 1]]]).astype(np.int64)
            new_h = np.zeros(len(new_c), dtype=bool)
            if was and len(new_c) and new_c[0, 0] == begins[0]:
                new_h[0] = True
            self.cand[j] = np.vstack([cand, new_c]) if len(new_c) else cand
            self.held[j] = np.concatenate([held, new_h])
            self.last[j] = col[-1]
        self.blocks.append((off, n, own))
        self.rows = off + n

    def _since(self, j: int, first: int) -> tuple[NDArray[np.int64], int]:
        """Axis j's runs completed in the blocks from the one holding row ``first`` on."""
        h = np.zeros(HELD_HIST + 1, dtype=np.int64)
        rows = 0
        for off, n, own in self.blocks:
            if off + n > first:
                h[:len(own[j])] += own[j]
                rows += n
        return h, rows

    def _whole(self, j: int) -> float:
        """Axis j's threshold by the whole read so far (kept until the next block is fed)."""
        assert self.hist is not None
        if self._cache.get(j, (-1, 0.0))[0] != self.rows:
            self._cache[j] = (self.rows, held_threshold(self.hist[j], self.rows))
        return self._cache[j][1]

    def _threshold(self, j: int, first: int, last: int) -> float:
        k = self._whole(j)
        if last - first + 1 >= k and last - first + 1 < HELD_WAIT_SAMPLES:
            h, rows = self._since(j, first)
            k = max(k, held_threshold(h, rows, self.rows))
        return k

    def undecided(self) -> bool:
        """An open run the whole read's threshold would hold, not yet judged held because the
        runs after its start are too few to tell: the screen waits for more blocks (at most
        ``HELD_WAIT_SAMPLES`` rows)."""
        if self.hist is None:
            return False
        for j, cand in enumerate(self.cand):
            if len(cand) and cand[-1, 1] == self.rows - 1 and not self.held[j][-1]:
                first, last = int(cand[-1, 0]), int(cand[-1, 1])
                if (last - first + 1 >= self._whole(j)
                        and not last - first + 1 >= self._threshold(j, first, last)):
                    return True
        return False

    def verdict(self, off: int, n: int) -> NDArray[np.bool_]:
        """(n, axes): the rows [off, off + n) held on each axis."""
        c = 0 if self.hist is None else self.hist.shape[0]
        out = np.zeros((n, c), dtype=bool)
        if self.hist is None or not n:
            return out
        for j in range(c):
            cand, held = self.cand[j], self.held[j]
            if not len(cand):
                continue
            f, la = cand[:, 0], cand[:, 1]
            here = (la >= off) & (f < off + n)
            # only a run longer than the whole read's threshold is judged further
            for i in np.flatnonzero(here & ~held & (la - f + 1 >= self._whole(j))):
                held[i] = la[i] - f[i] + 1 >= self._threshold(j, int(f[i]), int(la[i]))
            for i in np.flatnonzero(here & held):
                out[max(int(f[i]), off) - off:min(int(la[i]), off + n - 1) - off + 1, j] = True
            keep = la >= off + n
            self.cand[j], self.held[j] = cand[keep], held[keep]
        # a block's own runs are needed while a candidate or a row still to judge is in it
        low = min([off + n, *(int(cand[:, 0].min()) for cand in self.cand if len(cand))])
        self.blocks = [b for b in self.blocks if b[0] + b[1] > low]
        return out


# --------------------------------------------------------------------------------------------
# temperature


def screen_temperature(values: NDArray[np.float64]) -> list[tuple[int, str]]:
    """(position in ``values``, kind) of the readings to mask in one channel's sequence of
    readings (the rule in the module's doc: read errors, 85 °C power-on values, spikes)."""
    v = np.asarray(values, dtype=float)
    out: list[tuple[int, str]] = []
    err = (v == DS18B20_ERROR_C) | (v < DS18B20_MIN_C) | (v > DS18B20_MAX_C)
    good = ~err
    for i in np.flatnonzero(err):
        out.append((int(i), "read_error"))
    gi = np.flatnonzero(good & (v != POWER_ON_C))
    for i in np.flatnonzero(good & (v == POWER_ON_C)):
        k = np.searchsorted(gi, i)
        near = [v[gi[k - 1]]] if k > 0 else []
        near += [v[gi[k]]] if k < len(gi) else []
        if near and min(abs(POWER_ON_C - x) for x in near) > JUMP_C:
            out.append((int(i), "power_on_85"))
            good[i] = False
    g = np.flatnonzero(good)
    if len(g) >= 3:
        x = v[g]
        left, mid, right = x[:-2], x[1:-1], x[2:]
        spike = ((np.abs(mid - left) > JUMP_C) & (np.abs(mid - right) > JUMP_C)
                 & (np.abs(left - right) < 0.5 * JUMP_C))
        for i in g[1:-1][spike]:
            out.append((int(i), "spike"))
    return sorted(out)


def stuck_runs(times_s: NDArray[np.float64], values: NDArray[np.float64]
               ) -> list[tuple[int, int]]:
    """[first, last] positions (in the readings) of runs of one value that the channel's own
    statistics make implausible: longer than ``STUCK_MIN_S`` and ``STUCK_FACTOR`` times the
    95th percentile of its runs (a stable room's runs are all long, and none is flagged)."""
    v = np.asarray(values, dtype=float)
    t = np.asarray(times_s, dtype=float)
    if len(v) < 3:
        return []
    change = np.flatnonzero(np.diff(v) != 0) + 1
    starts = np.concatenate([[0], change])
    ends = np.concatenate([change - 1, [len(v) - 1]])
    dur = t[ends] - t[starts]
    if len(dur) < 3:
        return []  # one or two runs: nothing to compare a run with (a stable room)
    limit = max(STUCK_MIN_S, STUCK_FACTOR * float(np.percentile(dur, 95)))
    return [(int(a), int(b)) for a, b, d in zip(starts, ends, dur, strict=True) if d > limit]


# --------------------------------------------------------------------------------------------
# the stream

#: (accel (n, C) m/s², temperature (n, k) °C or None, ends a segment)
Block = tuple[NDArray[np.float64], NDArray[np.float64] | None, bool]


class _TempTrack:
    """One temperature channel's readings seen so far, for the rules that need the
    neighbours or the whole record (spikes across blocks, dropouts, stuck runs): each
    reading's sample index and value, in arrays grown by doubling. A reading is a finite
    value on a row of a block, NaN between readings (what every record source hands over,
    core/io/source.py), so this holds ~1 entry per second of record whatever the sample
    rate: ``len(track)`` counts the readings kept."""

    def __init__(self) -> None:
        self._idx = np.zeros(64, dtype=np.int64)
        self._val = np.zeros(64)
        self._n = 0

    def __len__(self) -> int:
        return self._n

    def add(self, offset: int, col: NDArray[np.float64]) -> None:
        ok = np.flatnonzero(np.isfinite(col))
        k = len(ok)
        if not k:
            return
        if self._n + k > len(self._idx):
            size = max(2 * len(self._idx), self._n + k)
            self._idx = np.resize(self._idx, size)
            self._val = np.resize(self._val, size)
        self._idx[self._n:self._n + k] = ok + offset
        self._val[self._n:self._n + k] = col[ok]
        self._n += k

    def arrays(self) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """(sample indices, values) of the readings kept (views, not copies)."""
        return self._idx[:self._n], self._val[:self._n]


class _Undecided(Exception):
    """``held_cadence`` on a dense log with too few runs yet: more of the log may tell."""


def held_cadence(col: NDArray[np.float64], final: bool = True) -> tuple[float, str]:
    """(c, why) for one channel's first rows of temperatures ``col``: c ≥ 2 the cadence in
    samples (not always whole: 0.75 s at 10 Hz is 7.5) of a *held* log (a value on every row
    that changes only on reading instants: a logger that repeats its last reading on each
    sample), 0.0 for a log of readings; ``why`` a note where a dense log's cadence cannot be
    told ('' otherwise).

    The rule: a value on at least ``HELD_DENSE`` of the rows, and the n lengths of its
    complete runs of one value (a room dwells many readings on one 0.0625 K step, so a run is
    often many readings long) all a whole number of one cadence c: exactly (a common divisor
    c ≥ 2: conversions on the sample grid), or within one sample (``_fractional_cadence``:
    readings at a cadence that is no whole number of samples, or a jittering clock), for at
    least 90 % of them. Chance must not do it: n runs of a log read on every sample are all
    multiples of c with a chance of about c^-n, and that must be below 1/``HELD_CHANCE``
    with n ≥ ``HELD_MIN_COMMON``; within a sample, ``HELD_MIN_EVENTS`` changes must agree
    on the cadence (a coherence of 0.9 among ~10^5 candidates has a chance < 1e-6 there).
    A log read on every sample (a thermistor, a DS18B20 at ≤ 1.33 Hz) has runs of no common
    cadence and is left as it is; a dense log with too few runs to tell is left as it is
    and said. A steady ramp read on every sample without noise has runs all of one length
    and changes all one way, which a held log whose every reading changes has too: where at
    least ``RAMP_SHARE`` of the runs are one multiple of the cadence and of the changes one
    sign (``_steady_ramp``) the log is left as it is and said ("cannot tell"); a held log in
    a room that dwells and turns (runs of several multiples, changes both ways) is still
    read as readings. Where the first changes lie too far apart for the cadences to be tried
    (more than ``HELD_MAX_CANDIDATES``), it is said too. Density is judged over the finite
    span (a log whose first rows are NaN is judged from its first value) or by its finite
    rows' neighbours (``_dense``: a held log with a dropout is still dense), and its runs
    between changes of two finite rows (``_clean_runs``). This is the verdict on a
    channel's first rows; the rest of the log is watched stretch by stretch (``_Dehold``:
    a log held from midway on, or read on every sample from midway on). ``final``
    False: the caller can wait for more of the log (``_Undecided`` is
    raised where more runs could decide, and where a common divisor rests on fewer than
    ``HELD_PIN_RUNS`` runs: it may be a multiple of the cadence)."""
    v = np.asarray(col, dtype=float)
    fin = np.isfinite(v)
    f = np.flatnonzero(fin)
    if not _dense(fin, f):
        return 0.0, ""
    if not final and len(f) < 2:
        raise _Undecided
    x = v[f]
    p, lengths = _clean_runs(v, fin)
    starts = np.concatenate([[f[0]], p])
    n = len(lengths)
    g = int(np.gcd.reduce(lengths.astype(np.int64))) if n else 0
    if g >= 2 and n >= HELD_MIN_COMMON and n * math.log(g) >= math.log(HELD_CHANCE):
        if n < HELD_PIN_RUNS and not final:
            # held, but its cadence may be a multiple of the true one (n runs are all even
            # multiples with a chance of 2^-n): more of the log pins it
            raise _Undecided
        if _steady_ramp(lengths, g, x):
            return 0.0, _cannot_tell(n, len(v), "all one length and its changes one way "
                                     "(a steady ramp): cannot tell")
        return float(g), ""
    c, _n, capped = _fractional_cadence(starts[1:])
    if c > 0:
        if _steady_ramp(lengths, c, x):
            return 0.0, _cannot_tell(n, len(v), "all one length and its changes one way "
                                     "(a steady ramp): cannot tell")
        return c, ""
    if capped:
        # too many cadences to try on the span of its first changes (a room that changes
        # seldom at a high rate): no verdict either way, and said
        return 0.0, _cannot_tell(n, len(v), "too far apart to read a cadence: cannot tell")
    if len(f) >= 2 * len(starts) and (g >= 2 or n < HELD_MIN_EVENTS):
        # runs of two samples or more on average, and too few of them to tell
        if not final:
            raise _Undecided
        return 0.0, _cannot_tell(n, len(v), "too few to tell")
    return 0.0, ""


def _dense(fin: NDArray[np.bool_], f: NDArray[np.intp]) -> bool:
    """A value on (nearly) every row: at least ``HELD_DENSE`` of the finite span finite (a
    log that starts late or ends early is judged where it is), or of the finite rows that
    many followed by a finite row (its NaN in a few long stretches, dropouts, not one
    between each reading: a held log with a hole is still held)."""
    if not len(f):
        return False
    if len(f) >= HELD_DENSE * (int(f[-1]) - int(f[0]) + 1):
        return True
    pairs = int(np.count_nonzero(fin[:-1] & fin[1:]))
    return len(f) >= 2 and pairs >= HELD_DENSE * (len(f) - 1)


def _clean_runs(v: NDArray[np.float64], fin: NDArray[np.bool_]
                ) -> tuple[NDArray[np.intp], NDArray[np.int64]]:
    """(p, lengths): the rows where the value changes between two finite rows (a held log's
    reading instants; a change across NaN is not one, its reading may lie in the hole), and
    the lengths of the complete runs between two of them with no NaN between (a run cut by
    a dropout is no multiple of anything)."""
    p = np.flatnonzero(fin[1:] & fin[:-1] & (v[1:] != v[:-1])) + 1
    cnan = np.concatenate([[0], np.cumsum(~fin)])
    d = np.diff(p).astype(np.int64)
    return p, d[cnan[p[1:]] == cnan[p[:-1]]]


def _cannot_tell(n: int, rows: int, why: str) -> str:
    """The note on a dense log that cannot be told held or read on every sample."""
    return (f"a value on every sample, its {n} complete runs of one value in its first "
            f"{rows} samples {why} a log held at each reading (each reading "
            "repeated until the next) from one read on every sample: taken as read on every "
            "sample (if held, its lag is late by half a reading interval; judged on its first "
            "rows, the rest of the log watched for a held stretch)")


def _steady_ramp(lengths: NDArray[np.int64], c: float, x: NDArray[np.float64]) -> bool:
    """A constant ramp read on every sample: at least ``RAMP_SHARE`` of the runs one
    multiple of ``c`` (within a sample) and of the changes one sign. Its runs are all one
    length and its steps one way, which is what a held log whose every reading changes reads
    too: the two cannot be told apart, and de-holding a log read on every sample would keep
    one row of each run and read the temperature up to a run early."""
    if not len(lengths):
        return False
    m = np.rint(lengths / c).astype(np.int64)
    same = float(np.max(np.bincount(m - m.min()))) / len(m)
    d = np.diff(x)
    d = d[d != 0]
    if not len(d):
        return False
    one_way = max(np.count_nonzero(d > 0), np.count_nonzero(d < 0)) / len(d)
    return bool(same >= RAMP_SHARE and one_way >= RAMP_SHARE)


def _fractional_cadence(starts: NDArray[np.int64]) -> tuple[float, int, bool]:
    """(c, n, capped): a cadence c (samples, ≥ 2.5, not always whole) on which the first
    ``HELD_EVENTS`` change positions ``starts`` of a dense log lie, each within a sample's
    rounding (their phases' coherence |mean e^(2πi p/c)| ≥ ``HELD_COHERENCE``: a reading
    instant rounded up to the next sample is at most one sample late, a phase of at most
    1/c), the largest such c, and the n positions it rests on; (0.0, n) where none;
    ``capped`` where there were more than ``HELD_MAX_CANDIDATES`` cadences to try (none
    tried: the caller says it cannot tell).
    Candidates: the cadences of which the shortest run is a whole number within a sample,
    on a grid fine enough that the phase across the positions' span moves < 1/8 cycle."""
    p = np.asarray(starts[:HELD_EVENTS], dtype=float)
    n = len(p)
    if n < HELD_MIN_EVENTS:
        return 0.0, n, False
    p = p - p[0]
    span = float(p[-1])
    gmin = float(np.min(np.diff(p)))
    grids = []
    for j in range(1, int((gmin + 1.0) / 2.5) + 1):
        lo, hi = max(2.5, (gmin - 1.0) / j), (gmin + 1.0) / j
        if hi > lo:
            grids.append(np.arange(lo, hi, lo * lo / (8.0 * span)))
    if not grids:
        return 0.0, n, False
    c = np.concatenate(grids)
    if len(c) > HELD_MAX_CANDIDATES:
        return 0.0, n, True
    best = 0.0
    for k in range(0, len(c), 4096):
        cc = c[k:k + 4096]
        r = np.abs(np.exp(2j * np.pi * p[None, :] / cc[:, None]).mean(axis=1))
        hit = cc[r >= HELD_COHERENCE]
        if len(hit):
            best = max(best, float(hit.max()))
    return best, n, False


class _Stretch:
    """One stretch of a temperature log read one way: from row ``start`` on, as it is
    (``k`` 0) or held at each reading on a cadence of ``k`` samples, its reading instants
    found from ``anchor`` (a change of value between two finite rows: a reading, -1 until
    one is seen). ``runs``: complete runs found on the cadence (the evidence, for a whole
    cadence shrunk to a divisor); ``why``: what is said of a stretch read as it is;
    ``whole``: a cadence of a whole number of samples (a common divisor, exact), else read
    from the changes' phases, with its uncertainty ``dk`` (samples)."""

    __slots__ = ("anchor", "dk", "fit", "k", "runs", "start", "whole", "why")

    def __init__(self, start: int, k: float, anchor: int = -1, runs: int = 0,
                 why: str = "", whole: bool = True, dk: float = 0.0) -> None:
        self.start, self.k, self.anchor, self.runs, self.why = start, k, anchor, runs, why
        self.whole, self.dk = whole or k <= 0, dk
        # a cadence that is no whole number: the straight line through its changes (row
        # against reading count from the first: n, Σm, Σx, Σm², Σmx), refined as the log
        # goes on, so a long constant stretch's readings do not drift off their instants
        self.fit = [-1.0, 0.0, 0.0, 0.0, 0.0, 0.0]

    def refine(self, p: NDArray[np.int64]) -> None:
        """Take the changes ``p`` (on this stretch's cadence, ascending) into its cadence's
        fit, as far as their reading counts are beyond doubt (the cadence's uncertainty over
        their distance from the first below half a cadence: the fit then narrows it)."""
        if self.whole or not len(p):
            return
        f = self.fit
        if f[0] < 0:
            f[0] = float(p[0])
        x_all = np.asarray(p, dtype=float) - f[0]
        while len(x_all):
            lim = math.inf if self.dk <= 0 else 0.4 * self.k * self.k / self.dk
            n_take = int(np.searchsorted(x_all, lim, side="right"))
            if not n_take:
                return
            x, x_all = x_all[:n_take], x_all[n_take:]
            m = np.rint(x / self.k)
            f[1] += len(x)
            f[2] += float(m.sum())
            f[3] += float(x.sum())
            f[4] += float((m * m).sum())
            f[5] += float((m * x).sum())
            den = f[1] * f[4] - f[2] * f[2]
            if f[1] < HELD_MIN_EVENTS or not den > 0:
                continue
            k = (f[1] * f[5] - f[2] * f[3]) / den
            if abs(k - self.k) >= 0.5:
                return
            self.k = k
            # three standard errors of the slope, for residuals of a sample's rounding
            # (σ ≈ 0.5 sample, on the safe side of √(1/12))
            self.dk = 1.5 / math.sqrt(den / f[1])


def _on_cadence(d: NDArray[np.int64], k: float, whole: bool = True, dk: float = 0.0
                ) -> NDArray[np.bool_]:
    """Run lengths ``d`` that a held log on a cadence of ``k`` samples makes: whole
    multiples of a whole cadence; within a sample's rounding (and the logger's clock drift,
    ``HELD_TOL_DRIFT`` of the run, and the cadence's own uncertainty ``dk`` times the
    readings it spans) of a multiple ≥ 1 of a cadence that is no whole number."""
    d = np.asarray(d, dtype=float)
    if whole:
        return np.asarray(d % k == 0) & (d > 0)
    m = np.rint(d / k)
    tol = HELD_TOL_SAMPLES + HELD_TOL_DRIFT * d + m * dk
    return np.asarray((m >= 1) & (np.abs(d - m * k) <= tol))


def _phase_dk(p: NDArray[np.int64], k: float) -> float:
    """The uncertainty of a cadence read from the phases of the changes ``p``
    (``_fractional_cadence``: coherence ≥ 0.9 allows the phase to slide about a quarter of
    a cycle across their span)."""
    span = float(p[-1] - p[0]) if len(p) >= 2 else 0.0
    return 0.3 * k * k / span if span > 0 else 0.5


class _Dehold:
    """One temperature channel read as readings, stretch by stretch over the whole log.

    The first rows are judged by ``held_cadence`` (the screen waits for them); from there on
    every block is watched (``observe``, before the block is handed on: its rows and the one
    block before it can still be read anew), in bounded memory (the last ``HELD_RING``
    changes of value) and a cost linear in the rows:

    - in a held stretch every change of value between two finite rows must lie on the
      cadence from the change before it (``_on_cadence``); a whole cadence may shrink to a
      divisor the stretch's runs still make significant; a change off it ends the stretch
      there (the log is read as it is from that change on). A change across NaN (a dropout)
      is not judged, and the reading instants go on from the last change before the hole
      (its first value after the hole is a repeat of a reading made inside it, or on a
      reading instant that lies on the same cadence: either way no reading's phase is lost);
    - in a stretch read as it is, the latest complete runs are tested at each block for a
      held stretch that has begun (a whole cadence: their common divisor, at a chance of
      at most 1/``HELD_SWITCH_CHANCE`` for a log read on every sample, the test being made
      at every block; a cadence that is no whole number: the last ``HELD_EVENTS`` changes'
      phases, ``_fractional_cadence``), which then starts at its first run's change (its
      rows still waiting are read anew; the screen waits, at most ``HELD_WAIT_SAMPLES``
      rows, while such a test is close). A steady ramp is not taken (``_steady_ramp``: it
      cannot be told from a held log) and said.

    A held stretch becomes each reading instant's row (each change, and one every cadence
    after it until half a cadence before the next), NaN between, which is what a
    recording's source hands over (core/io/source.py: one reading per conversion, a stuck
    value included): a stable room's long constant stretch stays readings of its value, not
    one reading and a hole."""

    def __init__(self) -> None:
        self.k: float | None = None  # the first rows' verdict: undecided; 0; ≥ 2 the cadence
        self.why = ""
        self.segs: list[_Stretch] = []  # the stretches not yet wholly handed on, in order
        self.history: list[_Stretch] = []  # every stretch, for the note
        self.rows = 0  # rows observed
        self.released = 0  # rows handed on (read as their stretch says: fixed)
        # the watch: the last row's value, the last change, a NaN since it, the last
        # HELD_RING changes (row, value after it, the run before it complete)
        self._prev, self._prev_fin = math.nan, False
        self._last, self._nan_since = -1, True
        self._rp = np.zeros(0, dtype=np.int64)
        self._rv = np.zeros(0)
        self._rc = np.zeros(0, dtype=bool)
        self._since_try = 0
        self.close = False  # a held stretch's test is close: the screen may wait for it
        self.dense = False  # a value seen on two consecutive rows (a held stretch may come)
        # the reading: the row before the next block's value, the last reading instant
        self._aprev = math.nan
        self._aanchor = -1

    def decide(self, col: NDArray[np.float64], final: bool) -> bool:
        """Judge the log on ``col`` (its first rows, as many as the screen has waited
        for); False where it cannot yet and more rows may tell (not ``final``)."""
        if self.k is not None:
            return True
        try:
            self.k, self.why = held_cadence(col, final)
        except _Undecided:
            return False
        whole, dk = float(self.k).is_integer(), 0.0
        if self.k and not whole:
            v = np.asarray(col, dtype=float)
            dk = _phase_dk(_clean_runs(v, np.isfinite(v))[0][:HELD_EVENTS], self.k)
        self._begin(_Stretch(0, self.k, why=self.why, whole=whole, dk=dk))
        return True

    def _begin(self, seg: _Stretch) -> None:
        """A new stretch from ``seg.start`` (which replaces a stretch of no rows yet; rows
        handed on are read as they were)."""
        seg.start = max(seg.start, self.released)
        while self.segs and self.segs[-1].start >= seg.start:
            self.segs.pop()
            self.history.pop()
        self.segs.append(seg)
        self.history.append(seg)

    # -- the watch ----------------------------------------------------------------------

    def observe(self, off: int, col: NDArray[np.float64]) -> None:
        """Watch the block of rows ``off`` … (after ``decide``): judge its changes of value
        against the stretch being read, and test for a held stretch beginning."""
        v = np.asarray(col, dtype=float)
        n = len(v)
        if not n:
            return
        fin = np.isfinite(v)
        vv = np.concatenate([[self._prev], v])
        ff = np.concatenate([[self._prev_fin], fin])
        pair = ff[1:] & ff[:-1]
        self.dense = self.dense or bool(pair.any())
        i = np.flatnonzero(pair & (vv[1:] != vv[:-1]))  # block rows
        cnan = np.concatenate([[0], np.cumsum(~fin)])
        p = i + off
        conn = np.empty(len(i), dtype=bool)
        if len(i):
            conn[0] = self._last >= 0 and not self._nan_since and cnan[i[0]] == 0
            conn[1:] = cnan[i[1:]] == cnan[i[:-1]]
        d = np.diff(np.concatenate([[self._last], p])).astype(np.int64)
        j = 0
        while j < len(p):
            seg = self.segs[-1]
            if seg.k <= 0:
                break
            if seg.anchor < 0:
                seg.anchor = int(p[j])
                seg.refine(p[j:j + 1])
                j += 1
                continue
            ok = _on_cadence(d[j:], seg.k, seg.whole, seg.dk) | ~conn[j:]
            bad = np.flatnonzero(~ok)
            if not len(bad):
                seg.runs += int(np.count_nonzero(conn[j:]))
                seg.refine(p[j:][conn[j:]])
                break
            b = j + int(bad[0])
            seg.runs += int(np.count_nonzero(conn[j:b]))
            seg.refine(p[j:b][conn[j:b]])
            if seg.whole and _on_cadence(d[b:b + 1], seg.k, False)[0]:
                # a reading a sample late or early on a whole cadence: a jittering clock,
                # not the log read otherwise; read from here within a sample (each change
                # its own reading, as for a cadence that is no whole number)
                seg.whole = False
                j = b
                continue
            g = math.gcd(int(seg.k), int(d[b])) if seg.whole else 0
            if g >= 2 and seg.runs < HELD_PIN_RUNS:
                # a whole cadence read from few runs may be a multiple of the log's (n runs
                # are all even multiples with a chance of 2^-n): its divisor (every change so
                # far lies on it too); a cadence pinned by many runs is not shrunk by one run
                # (a log read on every sample makes it a multiple of 2 one time in two)
                seg.k = float(g)
                seg.runs += 1
                j = b + 1
                continue
            self._begin(_Stretch(int(p[b]), 0.0, why="its changes leave the cadence"))
            j = b + 1
        # the changes watched: the ring of the last ones before this block, and the block's
        rp = np.concatenate([self._rp, p])
        rv = np.concatenate([self._rv, v[i]])
        rc = np.concatenate([self._rc, conn])
        self._rp, self._rv, self._rc = rp[-HELD_RING:], rv[-HELD_RING:], rc[-HELD_RING:]
        self._since_try += len(p)
        if len(p):
            self._last = int(p[-1])
            self._nan_since = bool(cnan[n] - cnan[i[-1]] > 0)
        else:
            self._nan_since = self._nan_since or bool(cnan[n] > 0)
        self._prev, self._prev_fin = float(v[-1]), bool(fin[-1])
        self.rows = off + n
        self.close = False
        if self.segs[-1].k <= 0:
            self._watch(rp, rv, rc)

    def _watch(self, rp: NDArray[np.int64], rv: NDArray[np.float64],
               rc: NDArray[np.bool_]) -> None:
        """In a stretch read as it is: has a held one begun among the latest runs (the
        changes ``rp``, the values after them ``rv``, the run before each complete ``rc``:
        the last block's and the ring's before it)?"""
        seg = self.segs[-1]
        keep = rp >= seg.start
        rp, rv, rc = rp[keep], rv[keep], rc[keep]
        if len(rp) < 2:
            return
        runs = np.diff(rp).astype(np.int64)
        ok = rc[1:]
        # a whole cadence: the common divisor of the newest complete runs, the count of
        # runs that makes it least likely by chance (c^-n)
        r = runs[::-1]
        stop = np.flatnonzero(~ok[::-1])
        r = r[:int(stop[0]) if len(stop) else len(r)]
        gs = np.gcd.accumulate(r) if len(r) else r
        gs = gs[:int(np.argmax(gs < 2)) if (gs < 2).any() else len(gs)]
        score, nr, g = 0.0, 0, 0
        if len(gs):
            scores = np.arange(1, len(gs) + 1) * np.log(gs.astype(float))
            m = int(np.argmax(scores))
            score, nr, g = float(scores[m]), m + 1, int(gs[m])
        if nr >= HELD_MIN_COMMON and score >= math.log(HELD_SWITCH_CHANCE):
            first = len(rp) - 1 - nr
            if _steady_ramp(runs[first:], float(g), rv[first:]):
                seg.why = ("its runs all one length and its changes one way (a steady "
                           "ramp): cannot tell a held log from one read on every sample")
                return
            self._begin(_Stretch(int(rp[first]), float(g), int(rp[first]), nr))
            return
        # close: two runs or more whose divisor is already unlikely by chance (one long run
        # alone is a stable room's, read on every sample or not)
        self.close = nr >= 2 and score >= math.log(HELD_CHANCE)
        # a cadence that is no whole number of samples: the last changes' phases
        if self._since_try < HELD_MIN_EVENTS or len(rp) < HELD_EVENTS:
            return
        self._since_try = 0
        c, _n, _capped = _fractional_cadence(rp[-HELD_EVENTS:])
        if not c > 0:
            return
        dk = _phase_dk(rp[-HELD_EVENTS:], c)
        on = _on_cadence(runs, c, False, dk) & ok
        nr = len(runs) - (int(np.flatnonzero(~on)[-1]) + 1 if (~on).any() else 0)
        if nr < HELD_MIN_EVENTS:
            return
        first = len(rp) - 1 - nr
        if _steady_ramp(runs[first:], c, rv[first:]):
            seg.why = ("its runs all one length and its changes one way (a steady ramp): "
                       "cannot tell a held log from one read on every sample")
            return
        seg = _Stretch(int(rp[first]), c, int(rp[first]), nr, whole=False, dk=dk)
        seg.refine(rp[first:])
        self._begin(seg)

    # -- the reading ----------------------------------------------------------------------

    def apply(self, off: int, col: NDArray[np.float64]) -> NDArray[np.float64]:
        """The block of rows ``off`` … read as its stretches say (handed on: fixed)."""
        col = np.asarray(col, dtype=float)
        n = len(col)
        if not n or not self.segs:
            return col
        fin = np.isfinite(col)
        vv = np.concatenate([[self._aprev], col])
        ff = np.concatenate([[math.isfinite(self._aprev)], fin])
        change = np.flatnonzero(ff[1:] & ff[:-1] & (vv[1:] != vv[:-1])) + off
        lone = fin & ~ff[:-1] & ~np.concatenate([fin[1:], [True]])
        out = col
        # the stretches over these rows (those ended before them dropped: bounded)
        while len(self.segs) > 1 and self.segs[1].start <= off:
            self.segs.pop(0)
        for s_i, seg in enumerate(self.segs):
            lo = max(seg.start, off)
            hi = min(self.segs[s_i + 1].start if s_i + 1 < len(self.segs) else off + n,
                     off + n)
            if seg.k <= 0:
                self._aanchor = -1
                continue
            if hi <= lo:
                continue
            k = seg.k
            a = change[(change >= lo) & (change < hi)]
            pos = []
            if seg.start <= self._aanchor < lo:
                # the stretch goes on from the last reading instant before these rows (across
                # a dropout too: its phase is the logger's, not the hole's)
                starts = np.concatenate([[self._aanchor], a])
            else:
                anc = seg.anchor if seg.anchor >= 0 else int(a[0]) if len(a) else lo
                if anc > lo:
                    # the stretch's first rows: its instants run back from its first reading
                    back = np.arange(1, int((anc - lo) / k) + 2)
                    pos.append(anc - np.floor(k * back + 0.5).astype(np.int64))
                starts = (np.concatenate([[anc], a[a > anc]]) if anc < hi
                          else np.zeros(0, dtype=np.int64))
            if len(starts):
                # each instant's readings: it, and one every cadence until half a cadence
                # before the next change (an open run: to the rows' end)
                nxt = np.concatenate([starts[1:], [hi + 0.5 * k]]).astype(float)
                extra = np.maximum(np.floor((nxt - starts) / k - 0.5), 0).astype(np.int64)
                # an instant before these rows: from its first reading among them (a long
                # constant stretch costs its rows, not its rows times its blocks)
                skip = np.zeros(len(starts), dtype=np.int64)
                skip[0] = max(0, math.floor((lo - int(starts[0])) / k) - 1)
                cnt = np.maximum(extra + 1 - skip, 0)
                base = np.repeat(starts, cnt)
                step = (np.arange(int(cnt.sum())) - np.repeat(np.cumsum(cnt) - cnt, cnt)
                        + np.repeat(skip, cnt))
                pos.append(base + np.floor(k * step + 0.5).astype(np.int64))
                self._aanchor = int(starts[-1])
            pp = np.concatenate(pos) if pos else np.zeros(0, dtype=np.int64)
            pp = pp[(pp >= lo) & (pp < hi)]
            keep = np.zeros(hi - lo, dtype=bool)
            keep[pp - lo] = True
            # a reading alone between NaN is a reading whatever its phase (a held log never
            # writes one: the log has gone over to NaN between readings)
            keep |= lone[lo - off:hi - off]
            if out is col:
                out = col.copy()
            piece = out[lo - off:hi - off]
            piece[~keep] = np.nan
        self._aprev = float(col[-1])
        self.released = off + n
        return out

    # -- the note -------------------------------------------------------------------------

    def note(self, rate_hz: float) -> LogNote | None:
        hist = self.history
        if not hist:
            return None
        if len(hist) == 1:
            start, k, why = hist[0].start, hist[0].k, hist[0].why
            if k:
                since = "" if start <= 0 else f" from {start / rate_hz:.6g} s"
                return LogNote("held", (
                    f"held at each reading (a value on every sample, changing only on a "
                    f"{k:.4g}-sample cadence, {k / rate_hz:.3g} s): read as "
                    f"readings{since} (each run's first sample, and one every {k:.4g} "
                    "samples while it lasts; the rest NaN)"))
            return LogNote("held_unknown", why) if why else None
        parts, stretches = [], []
        for m, seg in enumerate(hist):
            start, k, why = seg.start, seg.k, seg.why
            end = hist[m + 1].start if m + 1 < len(hist) else self.rows
            span = f"{start / rate_hz:.6g}–{end / rate_hz:.6g} s"
            stretches.append({"start_s": start / rate_hz, "end_s": end / rate_hz,
                              "read": "held" if k else "as_is",
                              "cadence_samples": k if k else None})
            if k:
                parts.append(f"{span} held at each reading ({k:.4g}-sample cadence, "
                             f"{k / rate_hz:.3g} s): read as readings")
            else:
                parts.append(f"{span} read as it is" + (f" ({why})" if why else ""))
        shown = parts[:HELD_NOTE_STRETCHES]
        more = len(parts) - len(shown)
        kind = "held" if any(x.k for x in hist) else "held_unknown"
        return LogNote(kind, (
            f"a value on every sample, read in {len(hist)} stretches (its whole log "
            "judged): " + "; ".join(shown) + (f"; … and {more} more (--json lists all)"
                                                if more else "")
            + " (a held stretch: each change and one reading every cadence after it, the "
            "rest NaN)"), tuple(stretches))


def _grid_share(v: NDArray[np.float64], origin: float, step: float, tol: float) -> float:
    """The share of the distinct values ``v`` within ``tol`` of the grid origin + k·step."""
    r = (v - origin) / step
    return float(np.mean(np.abs(r - np.rint(r)) * step <= tol))


def is_coarse(step: float) -> bool:
    """Whether readings on ``step`` (K) are coarser than the DS18B20's 12-bit 0.0625 K, the
    step the thermal model's 12-bit path assumes (its straight-line de-rounding, its
    regressor as logged)."""
    return step > DS18B20_STEP_C * (1.0 + 1e-6)


#: Candidate steps (K) of a temperature log's readings, coarsest first: the DS18B20's four
#: resolutions (9–12 bits) in °C, the same read in °F and taken as °C (1.8× each), a logger
#: printing to 0.1 or 0.01.
LOG_STEPS_K = (0.9, 0.5, 0.45, 0.25, 0.225, 0.125, 0.1125, 0.1, 0.0625, 0.01)
#: The DS18B20's resolutions (K), 9 to 12 bits, and each one's bits.
DS18B20_BITS = {0.5: 9, 0.25: 10, 0.125: 11, 0.0625: 12}
#: A step holds a log when at least this share of its distinct values lie on its grid.
LOG_STEP_SHARE = 0.95
#: ... and its on-grid distinct values hold this many pairs exactly one step apart. A room's
#: temperature is continuous, so a finer log's readings pass every level between two they
#: visit: neighbours one coarse step apart with no reading between them are the coarse
#: step's mark, where two or three values alone could be a stable room's dwell on any grid.
LOG_STEP_NEIGHBOURS = 2
#: The least number of distinct values that can show a step of the values' own spacing
#: (one no candidate holds): fewer could be any spacing by chance.
LOG_STEP_OWN_VALUES = 8
#: Readings at most this far apart (s) that differ by a whole coarse step show it in time
#: when their distinct values cannot (a stable room on two or three levels): a room or a
#: plate does not move 0.1 K in a few seconds, so a log whose every change between such
#: readings is one step q (and at least ``LOG_STEP_NEIGHBOURS`` of them) reads on q; a
#: finer log of the same room passes the levels between (``log_step``'s ``times``).
LOG_STEP_JUMP_S = 5.0


def _on_step(u: NDArray[np.float64], q: float, neighbours: int = LOG_STEP_NEIGHBOURS
             ) -> tuple[float, float] | None:
    """(q, origin) when the distinct values ``u`` hold the grid origin + k·q (module
    constants ``LOG_STEP_*``), None when they do not; the origin their most common
    remainder (0 for a grid through 0 within the print)."""
    # on the grid within a 2-decimal print (``PRINT_TOL``), a fine step within a tenth of it
    tol = min(PRINT_TOL, q / 10.0)
    r = np.mod(u, q)
    bins, counts = np.unique(np.rint(r / tol).astype(np.int64), return_counts=True)
    m0 = float(bins[int(np.argmax(counts))]) * tol
    dm = np.abs(r - m0)
    best: tuple[float, NDArray[np.float64]] | None = None
    for origin in (0.0, float(np.median(r[np.minimum(dm, q - dm) <= tol]))):
        d = np.abs(r - origin)
        on = u[np.minimum(d, q - d) <= tol]
        if best is None or len(on) > len(best[1]):
            best = (origin, on)
    assert best is not None
    origin, on = best
    if len(on) < LOG_STEP_SHARE * len(u):
        return None
    if np.count_nonzero(np.abs(np.diff(on) - q) <= 2 * tol) < neighbours:
        return None
    return q, (0.0 if min(origin, q - origin) <= tol else round(origin, 4))


def log_step(values: NDArray, times: NDArray | None = None) -> tuple[float, float] | None:
    """(step K, origin) of a temperature log's readings, judged on its distinct values (the
    error and power-on values left out): the coarsest candidate (``LOG_STEPS_K``) whose grid
    holds them (``_on_step``); failing every candidate, the values' own spacing (their
    median difference, with at least ``LOG_STEP_OWN_VALUES`` values) if it holds them.

    A log too stable to show its step in its distinct values (two or three levels: a
    12-bit log dwelling on levels 0.125 apart has the same set) is judged in time where the
    readings' ``times`` (s) are given (``_step_in_time``): every change between readings at
    most ``LOG_STEP_JUMP_S`` apart whole coarse steps, most of them one, at least
    ``LOG_STEP_NEIGHBOURS`` times, is that step. Failing that, a log on the 12-bit grid
    keeps the DS18B20's 0.0625 K; None when the log is on no grid (a logger's fine or
    unrounded values)."""
    v = np.asarray(values, dtype=float)
    ok = np.isfinite(v) & (v != DS18B20_ERROR_C) & (v != POWER_ON_C)
    v = v[ok]
    u = np.unique(np.round(v, 6))
    if len(u) == 0:
        return (DS18B20_STEP_C, 0.0)
    for q in LOG_STEPS_K:
        found = _on_step(u, q)
        if found is not None:
            return found
    if times is not None:
        found = _step_in_time(v, np.asarray(times, dtype=float)[ok], u)
        if found is not None:
            return found
    if _grid_share(u, 0.0, DS18B20_STEP_C, PRINT_TOL) >= LOG_STEP_SHARE:
        return (DS18B20_STEP_C, 0.0)
    if len(u) >= LOG_STEP_OWN_VALUES:
        q = round(float(np.median(np.diff(u))), 4)
        if q > 0.0:
            return _on_step(u, q)
    return None


def _step_in_time(v: NDArray[np.float64], t: NDArray[np.float64], u: NDArray[np.float64]
                  ) -> tuple[float, float] | None:
    """(q, origin) of readings ``v`` at times ``t`` (s), distinct values ``u``, where every
    change between readings at most ``LOG_STEP_JUMP_S`` apart is a whole number of one
    coarse candidate step q (within the print) and most of them one q, at least
    ``LOG_STEP_NEIGHBOURS`` of them, and the values hold q's grid (``_on_step`` without its
    neighbour pairs); None otherwise. (A genuine fast move, a door or a touch, jumps more
    than one step between neighbouring readings now and then; a finer log's room never
    jumps a coarse step at all.)"""
    if len(v) < 2:
        return None
    d = np.abs(np.diff(v))[np.diff(t) <= LOG_STEP_JUMP_S]
    d = d[d > PRINT_TOL]
    if len(d) < LOG_STEP_NEIGHBOURS:
        return None
    for q in LOG_STEPS_K:
        if not is_coarse(q):
            continue
        k = np.round(d / q)
        tol = 2 * min(PRINT_TOL, q / 10.0)
        if (np.all((k >= 1) & (np.abs(d - k * q) <= k * tol))
                and np.count_nonzero(k == 1) > len(d) / 2):
            return _on_step(u, q, neighbours=0)
    return None


def _coarse_what(grid: tuple[float, float]) -> str:
    """What a coarse grid may be: "a 0.25 K step (a DS18B20 at 10 bits?)"."""
    q, origin = grid
    fbits = {round(1.8 * k, 4): b for k, b in DS18B20_BITS.items()}
    what = (f"a DS18B20 at {DS18B20_BITS[q]} bits?" if q in DS18B20_BITS and origin == 0.0
            else f"a DS18B20 at {fbits[round(q, 4)]} bits read in °F and taken as °C?"
            if round(q, 4) in fbits else "a log printed to 0.1?" if q == COARSE_PRINT
            else "another logger's resolution?")
    return f"a {q:g} K step ({what})"


def coarse_text(grid: tuple[float, float]) -> str:
    """A coarse grid in words, for a log's note: "readings on a 0.25 K step (a DS18B20 at 10
    bits?), coarser than the 12-bit 0.0625 K: the thermal model takes the temperature
    behind them from their crossings and its rounding on that step"."""
    return (f"readings on {_coarse_what(grid)}, coarser than the 12-bit "
            f"{DS18B20_STEP_C:g} K: the thermal model takes the temperature behind them from "
            "their crossings and its rounding on that step")


def coarse_cause(grid: tuple[float, float]) -> str:
    """A coarse grid as a possible cause of an unexplained axis's misfit, in words."""
    return (f"it reads on {_coarse_what(grid)}, coarser than the 12-bit "
            f"{DS18B20_STEP_C:g} K: the temperature behind its readings, reconstructed from "
            "their crossings, may be off by more than the model carries")


def units_note(values: NDArray[np.float64]) -> tuple[LogNote | None, str | None]:
    """(note, refusal) on a channel's readings as a whole, judged on its distinct values (a
    stable room's one value, which may sit on any grid by chance, counts once).

    A refusal needs positive evidence: most values (``FAHRENHEIT_SHARE``) on a DS18B20's grid
    *in °F* (32 + 1.8·0.0625·k = 32 + 0.1125·k °F, within ``PRINT_TOL``: a logger printing
    2 decimals) and under ``OFF_GRID_SHARE`` on its °C grid (multiples of 0.0625, within the
    same printing), with at least ``FAHRENHEIT_MIN_VALUES`` values (``…_ROOM`` at a °F room's
    values): a DS18B20 read in °F,
    refused for the thermal model (a coupling per K from °F is 1.8× too small, silently).
    Another logger's °C (a thermistor's 0.01 K, a 0.001 K logger) is on neither grid: off the
    °C grid it is taken as °C with a note (which says to convert it if it is °F: off both
    grids, °F cannot be told from a heated plate's °C); on the °C grid at a °F room's values
    (``FAHRENHEIT_ROOM``), a note that °C is assumed. A log printed to 0.1 (``COARSE_PRINT``)
    holds neither grid: at a °F room's values the note says that °C and °F cannot be told
    apart and °C is assumed (no refusal without evidence; a heated plate's °C is kept)."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v) & (v != DS18B20_ERROR_C) & (v != POWER_ON_C)
          & (v >= DS18B20_MIN_C) & (v <= DS18B20_MAX_C)]
    if len(v) < 8:
        return None, None
    u = np.unique(v)
    on = _grid_share(u, 0.0, DS18B20_STEP_C, PRINT_TOL)
    on_f = _grid_share(u, 32.0, 1.8 * DS18B20_STEP_C, PRINT_TOL)
    med = float(np.median(v))
    lo, hi = FAHRENHEIT_ROOM
    room_f = lo <= med <= hi
    least = FAHRENHEIT_MIN_VALUES_ROOM if room_f else FAHRENHEIT_MIN_VALUES
    coarse = bool(np.all(np.abs(u / COARSE_PRINT - np.rint(u / COARSE_PRINT)) < 1e-6))
    if coarse and room_f:
        return LogNote("units_unknown", (
            f"printed to {COARSE_PRINT:g}, which holds neither the DS18B20's 0.0625 K grid nor "
            f"its 0.1125 °F grid: median {med:.4g} is a {(med - 32) / 1.8:.3g} °C room in °F "
            f"or {med:.4g} °C, and this log cannot tell which; taken as °C (if it is °F, "
            "convert it: a coupling per K from °F is 1.8× too small)")), None
    if on < OFF_GRID_SHARE and on_f >= FAHRENHEIT_SHARE and len(u) >= least:
        why = (f"taken for °F: {100 * on_f:.0f} % of its {len(u)} distinct readings are on a "
               f"DS18B20's grid in °F (32 + 0.1125·k) and {100 * (1 - on):.0f} % off its "
               f"0.0625 K grid in °C (median {med:.4g}); a coupling per K from °F would be "
               "1.8× too small; not used (write the log in °C)")
        return LogNote("fahrenheit", (
            f"{100 * on_f:.0f} % of its distinct readings on a DS18B20's grid in °F "
            f"(32 + 0.1125·k), median {med:.4g}: a log in °F, not used by the thermal "
            "model")), why
    if on < OFF_GRID_SHARE:
        return LogNote("off_grid", (
            f"{100 * (1 - on):.0f} % of its distinct readings off the DS18B20's 0.0625 K grid "
            f"(another logger's?), median {med:.4g}: taken as °C; if it is °F, convert "
            "it")), None
    if room_f:
        return LogNote("celsius_assumed", (
            f"readings on the DS18B20's 0.0625 K grid with median {med:.4g}: taken as °C "
            f"(a DS18B20 logged in °F would read {lo:g}–{hi:g} too, but on its 0.1125 °F "
            "grid)")), None
    return None, None


def _never_converted(values: NDArray[np.float64]) -> LogNote | None:
    """The note on a log whose every reading is 85.0 °C (at least three): a DS18B20 that
    never converted a temperature, its power-on register read forever. The per-reading rule
    masks an 85 °C reading by its good neighbours, and such a log has none, so it passed
    as a room at 85 °C."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if len(v) < 3 or not np.all(v == POWER_ON_C):
        return None
    return LogNote("power_on_85", (
        f"85.0 °C throughout ({len(v)} readings): a DS18B20's power-on value, the sensor never "
        "converted a temperature; not used by the thermal model"))


def _celsius_evidence(values: NDArray[np.float64]) -> str:
    """For a log converted from °F as the user asked: what speaks against it, "" where
    nothing does. The evidence mirrors ``units_note``'s for °F: most distinct readings as
    given (before the conversion) on the DS18B20's 0.0625 K grid in °C and under half on
    its grid in °F, of at least ``FAHRENHEIT_MIN_VALUES`` values (a stable room's one value
    may sit on any grid by chance)."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)] * 1.8 + 32.0   # the readings as the log gave them
    v = v[(v != DS18B20_ERROR_C) & (v != POWER_ON_C)]
    u = np.unique(np.round(v, 9))
    if len(u) < FAHRENHEIT_MIN_VALUES:
        return ""
    on = _grid_share(u, 0.0, DS18B20_STEP_C, PRINT_TOL)
    on_f = _grid_share(u, 32.0, 1.8 * DS18B20_STEP_C, PRINT_TOL)
    if on < FAHRENHEIT_SHARE or on_f >= OFF_GRID_SHARE:
        return ""
    return (f"; its readings look like °C ({100 * on:.0f} % of its {len(u)} distinct readings "
            f"on the 0.0625 K grid, {100 * on_f:.0f} % on a DS18B20's grid in °F): if they are, "
            "a coupling per K from them is 1.8× too large")


def fahrenheit_columns(temperature_names: Sequence[str], units: str,
                       check_units: bool = True) -> list[int]:
    """The temperature columns ``--temperature-units F`` converts: every log the units rule
    judges (avard's own die temperature and a recording's logs are °C whatever is said: the
    daemon writes them); none unless ``units`` is "F"."""
    if units != "F" or not check_units:
        return []
    return [j for j, nm in enumerate(temperature_names) if nm not in NOT_DS18B20]


def to_celsius(blk: Block, columns: Sequence[int]) -> Block:
    """The block with its temperature ``columns`` converted from °F to °C (a copy)."""
    if not columns or blk[1] is None:
        return blk
    t0 = np.array(blk[1], dtype=float)
    tv = t0.reshape(len(blk[0]), -1)
    # to 1e-9 K: a DS18B20's °F reading converts back onto its 0.0625 K grid exactly (the
    # float residue of the division put every reading 1e-15 off it, and the thermal model
    # reads a DS18B20's rounding from that grid)
    tv[:, list(columns)] = np.round((tv[:, list(columns)] - 32.0) / 1.8, 9)
    return blk[0], t0, blk[2]


def screen_blocks(blocks: Iterator[Block], rate_hz: float, names: Sequence[str],
                  temperature_names: Sequence[str], log: ScreenLog,
                  columns: Sequence[int] | None = None,
                  bad_rows: Callable[[int, NDArray[np.float64], NDArray[np.bool_]],
                                     NDArray[np.bool_]] | None = None,
                  check_units: bool = True,
                  held_rows: Callable[[int, int], NDArray[np.bool_]] | None = None,
                  on_verdict: Callable[[int, NDArray[np.bool_], NDArray[np.bool_]], None]
                  | None = None) -> Iterator[Block]:
    """``blocks`` (all accel columns) with the outlying acceleration rows cut out (a segment
    ends before each cut) and the bad temperature readings set to NaN; what was masked goes
    to ``log``. ``columns``: the accel columns to hand on (after screening on all).
    ``bad_rows(offset, block, held rows)``: the block's outlying rows (default ``screen_accel``; a
    ``ScreenedSource`` hands the first read's verdicts to its later reads). Held acceleration
    (``HeldAccel``, over the whole read: each block is fed to it when read, and judged when
    handed on, a block later) is cut likewise; ``held_rows(offset, n)`` gives its verdict
    instead ((n, axes) held flags: a later read's, which may read fewer axes).
    ``on_verdict(offset, cut rows, held flags)``: each block's verdicts, for a later read.

    Temperature readings are judged with one block of look-ahead (a spike's right-hand
    neighbour may be in the next block), so each block is handed on when the next has been
    read; the stuck and dropout rules need the whole channel and are applied at the end
    (they mask nothing analyze reads; explain masks its slow view by ``log.holes``).
    ``check_units``: judge each log's units by the DS18B20's grid (``units_note``; off for a
    recording, whose daemon writes °C itself). ``log.units`` (``--temperature-units``): "C"
    takes every log as °C (a °F verdict is said, not acted on), "F" converts each log the
    units rule judges to °C as it is read (before every rule: 85 °C is 185 °F)."""
    tnames = list(temperature_names)
    to_c = fahrenheit_columns(tnames, log.units, check_units)
    tracks = [_TempTrack() for _ in tnames]
    held = [_Dehold() for _ in tnames]
    pending: list[tuple[int, Block]] = []
    offset = 0
    start_n = round(STARTUP_S * rate_hz)
    cols = None if columns is None else list(columns)
    detector = HeldAccel() if held_rows is None else None
    # the log's held stretch that may go on into the next block (its index)
    held_at = [-1]

    def emit(off: int, blk: Block, last: bool) -> Iterator[Block]:
        a, t, end = blk
        if t is not None and tnames:
            t = _mask_readings(off, t, tracks, tnames, log, rate_hz, final=last)
        flags = (detector.verdict(off, len(a)) if detector is not None
                 else held_rows(off, len(a)) if held_rows is not None
                 else np.zeros((len(a), 0), dtype=bool))
        held: NDArray[np.bool_] = (np.asarray(flags.any(axis=1), dtype=bool) if flags.shape[1]
                                   else np.zeros(len(a), dtype=bool))
        shock = (bad_rows(off, a, held) if bad_rows is not None
                 else screen_accel(a, held) if held.any() else screen_accel(a))
        if on_verdict is not None:
            on_verdict(off, shock, flags)
        for f, l_ in _runs(shock & ~held):
            kind = "startup_glitch" if off + f < start_n else "shock"
            log.stretches.append(Screened("accel", kind, off + f, off + l_, (off + f) / rate_hz,
                                          (off + l_ + 1) / rate_hz, l_ - f + 1))
        for f, l_ in _runs(held):
            axes = tuple(str(names[j]) if j < len(names) else str(j)
                         for j in range(flags.shape[1]) if flags[f:l_ + 1, j].any())
            k = held_at[0]
            prev = log.stretches[k] if 0 <= k < len(log.stretches) else None
            if prev is not None and prev.kind == "held_accel" and prev.last + 1 == off + f:
                # a held stretch across the blocks' boundary: one stretch
                log.stretches[k] = Screened(
                    "accel", "held_accel", prev.first, off + l_, prev.start_s,
                    (off + l_ + 1) / rate_hz, prev.count + l_ - f + 1,
                    tuple(x for x in names if x in prev.axes or x in axes) or prev.axes)
                continue
            held_at[0] = len(log.stretches)
            log.stretches.append(Screened("accel", "held_accel", off + f, off + l_,
                                          (off + f) / rate_hz, (off + l_ + 1) / rate_hz,
                                          l_ - f + 1, axes))
        runs = _runs(shock | held)
        pos = 0
        pieces: list[Block] = []
        for f, l_ in runs:
            if f > pos:
                pieces.append((a[pos:f], None if t is None else t[pos:f], True))
            pos = l_ + 1
        if pos < len(a):
            pieces.append((a[pos:], None if t is None else t[pos:], end))
        elif pieces:
            pieces[-1] = (pieces[-1][0], pieces[-1][1], True)
        for pa, pt, pe in pieces:
            yield (pa if cols is None else pa[:, cols]), pt, pe

    def take(off: int, blk: Block) -> Block:
        """The block's temperatures read as readings (a held log's) and tracked."""
        a, t, end = blk
        if t is not None and tnames:
            tt = np.asarray(t, dtype=float).reshape(len(a), -1)
            given = [tt[:, j] for j in range(tt.shape[1])]
            cols_t = [d.apply(off, c) for c, d in zip(given, held, strict=True)]
            if any(c is not g for c, g in zip(cols_t, given, strict=True)):
                # a held log read as readings: the block hands the readings on, NaN between
                tt = np.stack(cols_t, axis=1)
                blk = (a, tt if np.ndim(t) == 2 else tt[:, 0], end)
            for j, tr in enumerate(tracks):
                tr.add(off, tt[:, j])
        return blk

    # a log with a value on every row whose first block holds too few runs to tell a held
    # log is judged on more of it: the blocks wait (at most HELD_WAIT_SAMPLES rows, a few
    # MB) until every channel is judged; a log of readings is judged on its first block
    waiting: list[tuple[int, Block]] = []
    waited = 0

    def judge(final: bool) -> bool:
        ok = True
        for j, d in enumerate(held):
            if d.k is not None:
                continue
            col = np.concatenate([
                np.full(len(b[0]), np.nan) if b[1] is None
                else np.asarray(b[1], dtype=float).reshape(len(b[0]), -1)[:, j]
                for _, b in waiting])
            ok = d.decide(col, final) and ok
        return ok

    def observe(blks: list[tuple[int, Block]]) -> None:
        """Each channel's log watched over these blocks (``_Dehold.observe``)."""
        for off_w, (a, t, _end) in blks:
            tt = (np.full((len(a), len(tnames)), np.nan) if t is None
                  else np.asarray(t, dtype=float).reshape(len(a), -1))
            for j, d in enumerate(held):
                d.observe(off_w, tt[:, j])

    observed = 0  # the waiting blocks already watched
    for blk in blocks:
        blk = to_celsius(blk, to_c)
        if detector is not None:
            detector.feed(offset, np.asarray(blk[0], dtype=float))
        waiting.append((offset, blk))
        offset += len(blk[0])
        waited += len(blk[0])
        if tnames and not judge(waited >= HELD_WAIT_SAMPLES):
            continue
        observe(waiting[observed:])
        observed = len(waiting)
        # every block but the newest is handed on (a held stretch found in it may begin in
        # the block before: a log with a value on consecutive rows only), or none while a
        # channel's test for a held stretch is close (at most HELD_WAIT_SAMPLES rows)
        if ((any(d.close for d in held) or (detector is not None and detector.undecided()))
                and sum(len(b[0]) for _, b in waiting) < HELD_WAIT_SAMPLES):
            continue
        hold = 1 if any(d.dense for d in held) else 0
        while len(waiting) > hold:
            off_w, b_w = waiting.pop(0)
            observed -= 1
            pending.append((off_w, take(off_w, b_w)))
        while len(pending) > 1:
            off, b = pending.pop(0)
            yield from emit(off, b, False)
    if waiting:
        judge(True)
        observe(waiting[observed:])
        for off_w, b_w in waiting:
            pending.append((off_w, take(off_w, b_w)))
    while pending:
        off, b = pending.pop(0)
        yield from emit(off, b, not pending)
    _whole_record_rules(tracks, tnames, log, rate_hz, offset)
    log.readings = {name: len(tr) for name, tr in zip(tnames, tracks, strict=True)}
    for name, tr, d in zip(tnames, tracks, held, strict=True):
        note = d.note(rate_hz)
        if note is not None:
            log.notes[name] = note
        if not check_units or name in NOT_DS18B20:
            unit, refused = None, None
            if log.units == "F":
                unit = LogNote("units_given", (
                    "not converted from °F: " + ("avard's own die temperature" if check_units
                                                 else "a recording's log") + " is °C"))
        elif log.units == "F":
            unit, refused = LogNote("units_given", "converted from °F to °C as asked "
                                    "(--temperature-units F)"
                                    + _celsius_evidence(tr.arrays()[1])), None
        else:
            unit, refused = units_note(tr.arrays()[1])
            if log.units == "C":
                # said by the user: taken as °C, and what the readings looked like said
                evidence = ("" if refused is None else
                            refused.split("; a coupling")[0].removeprefix("taken for °F: "))
                seen = ("" if unit is None else f" (its readings look like °F: {evidence})"
                        if refused is not None else f" (its readings: {unit.text})")
                unit, refused = LogNote("units_given", "taken as °C as asked "
                                        f"(--temperature-units C){seen}"), None
        grid = log_step(tr.arrays()[1], tr.arrays()[0] / rate_hz) if len(tr) else None
        if grid is not None and ((check_units and name not in NOT_DS18B20)
                                 or (grid[1] == 0.0 and grid[0] in DS18B20_BITS)):
            # avard's own logs (the die's ~0.11 K LSB, a recording's) only on a DS18B20
            # resolution the data show: the candidates' print tolerance would take the die's
            # 0.1105 K for a °F DS18B20's 0.1125
            log.steps[name] = grid
        coarse = log.coarse(name)
        if refused is None and coarse is not None:
            # said beside the log's other note, under its kind: its rounding is not the one
            # the thermal model's rounding terms assume (a refused log is used by no model)
            unit = (LogNote("coarse_step", coarse) if unit is None else
                    LogNote(unit.kind, f"{unit.text}; {coarse}", unit.stretches))
        if unit is not None:
            # one line per channel: a held log's note and its units' note joined
            log.notes[name] = unit if note is None else note.joined(unit)
        if refused is not None:
            log.refused[name] = refused
        dead = _never_converted(tr.arrays()[1])
        if dead is not None and name not in NOT_DS18B20:
            log.notes[name] = (dead if name not in log.notes
                               else log.notes[name].joined(dead))
            log.refused.setdefault(name, dead.text)
    log.stretches.sort(key=lambda s: (s.start_s, s.channel))
    log.done = True


def _mask_readings(off: int, t: NDArray[np.float64], tracks: list[_TempTrack],
                   tnames: list[str], log: ScreenLog, rate_hz: float, final: bool
                   ) -> NDArray[np.float64]:
    """The block's temperatures with the readings the per-reading rules reject set to NaN,
    judged on every reading seen so far (this block's neighbours included)."""
    t = np.array(t, dtype=float).reshape(len(t), -1)
    for j, tr in enumerate(tracks):
        idx, val = tr.arrays()
        # the neighbours that matter: the few readings either side of this block
        lo = max(0, int(np.searchsorted(idx, off)) - 4)
        hi = min(len(idx), int(np.searchsorted(idx, off + len(t))) + 4)
        for p, kind in screen_temperature(val[lo:hi]):
            i = int(idx[lo + p])
            if not off <= i < off + len(t):
                continue
            t[i - off, j] = np.nan
            log.stretches.append(Screened(tnames[j], kind, i, i, i / rate_hz, i / rate_hz, 1))
    return t


def _whole_record_rules(tracks: list[_TempTrack], tnames: list[str], log: ScreenLog,
                        rate_hz: float, n_samples: int) -> None:
    """Dropouts, a log's late start and early end, and stuck runs: rules that need the
    channel's whole record (``n_samples``: the record's rows)."""
    for j, tr in enumerate(tracks):
        idx, val = tr.arrays()
        if len(idx) < 3:
            continue
        sec = idx / rate_hz
        gaps = np.diff(sec)
        typical = float(np.median(gaps))
        hole = max(DROPOUT_S, DROPOUT_READINGS * typical)
        for k in np.flatnonzero(gaps > hole):
            log.stretches.append(Screened(tnames[j], "dropout", int(idx[k]) + 1,
                                          int(idx[k + 1]) - 1, float(sec[k]),
                                          float(sec[k + 1]), 0))
        # the record's start and end bound the log as a reading would: a span there without
        # a reading, longer than a dropout by the same rule, says nothing of the temperature
        # either (a log with NaN between readings starts and ends within a reading interval)
        end_s = n_samples / rate_hz
        if sec[0] > hole:
            log.stretches.append(Screened(tnames[j], "log_starts_late", 0, int(idx[0]) - 1,
                                          0.0, float(sec[0]), 0))
        if end_s - sec[-1] > hole:
            log.stretches.append(Screened(tnames[j], "log_ends_early", int(idx[-1]) + 1,
                                          n_samples - 1, float(sec[-1]), end_s, 0))
        for a, b in stuck_runs(sec, val):
            log.stretches.append(Screened(tnames[j], "stuck", int(idx[a]), int(idx[b]),
                                          float(sec[a]), float(sec[b]), b - a + 1))


def screen_record(meta: dict[str, Any], blocks: Iterator[Block],
                  columns: Sequence[int] | None = None) -> Iterator[Block]:
    """``screen_blocks`` of a record's blocks (every accel column), its ``ScreenLog`` put in
    ``meta["screen"]`` for the results (analyze's and explain's text, JSON and report)."""
    log = ScreenLog(float(meta["rate_hz"]))
    meta["screen"] = log
    return screen_blocks(blocks, log.rate_hz, list(meta["names"]),
                         list(meta.get("temperature_names") or []), log, columns)


class ScreenedSource:
    """A record source read through the input screen (``screen_blocks``): what analyze and
    explain read. Every read screens alike (the same blocks, the same rule); ``log`` is the
    first complete read's ``ScreenLog``, for the results. The screen judges every accel
    axis, so it reads all of them and hands on the ``columns`` asked for."""

    def __init__(self, source: Any, units: str = "auto") -> None:
        self.source = source
        #: the logs' units as asked (``--temperature-units``: auto, C or F)
        self.units = temperature_units(units)
        self.log: ScreenLog | None = None
        # the first complete read's verdicts, per block size: {offset: outlying rows} (only
        # blocks with any), so later passes (one per channel group) cut the very same rows
        # without judging every axis again (the neighbours' medians cost as much as the
        # OADEV of a long record)
        self._verdicts: dict[int, dict[int, NDArray[np.intp]]] = {}
        #: ... and its held acceleration: {offset: (rows, their (rows, axes) held flags)}
        self._held: dict[int, dict[int, tuple[NDArray[np.intp], NDArray[np.bool_]]]] = {}

    @property
    def info(self) -> Any:
        return self.source.info

    def judged_clean(self, block: int) -> None:
        """The record's acceleration was judged elsewhere, block by block in blocks of
        ``block`` samples (the chunks of a parallel analysis, ``parallel.ScreenCut``
        otherwise), and nothing is to be cut: later reads take that verdict, and the log
        says the screen ran."""
        self.judged(block, {})

    def judged(self, block: int, cuts: Mapping[int, NDArray[np.intp]]) -> None:
        """The record's acceleration was judged elsewhere on every axis, block by block in
        blocks of ``block`` samples (the chunks of a parallel analysis, which found rows to
        cut: ``parallel.ScreenCut``): ``cuts`` {block offset: rows cut} for the blocks with
        any. Later reads cut those rows without judging again, and the next complete read's
        log says what was cut (nothing cut: the log says the screen ran)."""
        self._verdicts[block] = dict(cuts)
        # the chunks' verdicts hold no held acceleration: a chunk that sees a run that may be
        # one sends the record to be judged whole (``held_suspect``)
        self._held[block] = {}
        if not cuts and self.log is None:
            self.log = ScreenLog(float(self.source.info.rate_hz), done=True, units=self.units)

    @property
    def rereadable(self) -> bool:
        return bool(self.source.rereadable)

    def blocks(self, block: int = 1 << 16, *, columns: Sequence[int] | None = None,
               temperature: bool = True, verify: bool = True) -> Iterator[Block]:
        info = self.source.info
        log = ScreenLog(float(info.rate_hz), units=self.units)
        if self.log is None:
            self.log = log
        known = self._verdicts.get(block)
        held_known = self._held.get(block, {})
        n_axes = len(info.names)
        # judged once on every axis; later reads take only the columns asked for
        raw = self.source.blocks(block, columns=None if known is None else columns,
                                 temperature=temperature, verify=verify)
        found: dict[int, NDArray[np.intp]] = {}

        def judged(off: int, a: NDArray[np.float64], held: NDArray[np.bool_]
                   ) -> NDArray[np.bool_]:
            if known is not None:
                bad = np.zeros(len(a), dtype=bool)
                bad[known.get(off, np.empty(0, dtype=np.intp))] = True
                return bad
            bad = screen_accel(a, held) if held.any() else screen_accel(a)
            if bad.any():
                found[off] = np.flatnonzero(bad)
            return bad

        found_held: dict[int, tuple[NDArray[np.intp], NDArray[np.bool_]]] = {}

        def held_rows(off: int, n: int) -> NDArray[np.bool_]:
            out = np.zeros((n, n_axes), dtype=bool)
            if off in held_known:
                rows, flags = held_known[off]
                out[rows] = flags
            return out

        def keep(off: int, _cut: NDArray[np.bool_], flags: NDArray[np.bool_]) -> None:
            if flags.shape[1] and flags.any():
                rows = np.flatnonzero(flags.any(axis=1))
                found_held[off] = (rows, flags[rows])

        yield from screen_blocks(raw, log.rate_hz, list(info.names),
                                 list(info.temperature_names), log,
                                 columns if known is None else None, judged,
                                 check_units=info.format is not RecordFormat.RECORDING,
                                 held_rows=None if known is None else held_rows,
                                 on_verdict=keep if known is None else None)
        if known is None and log.done:
            self._verdicts[block] = found
            self._held[block] = found_held

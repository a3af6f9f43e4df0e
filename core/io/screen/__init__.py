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

**Temperature** (each DS18B20 channel, readings where the column is not NaN):

- ``read_error``: −127 °C (the driver's value for a failed CRC or a missing device), ±inf,
  or any reading outside the DS18B20's range (−55…125 °C);
- ``power_on_85``: exactly 85.0 °C (the power-on-reset register) more than ``JUMP_C`` from the
  nearest good readings on either side (a room at 85 °C would have neighbours near 85);
- ``spike``: one to ``GLITCH_READINGS`` (3) readings in a row each more than ``JUMP_C`` from
  both neighbours, which agree with each other to within ``JUMP_C``/2 (a room or a plate does
  not move 0.5 K and back within a few readings; that is 8 steps of the 0.0625 K
  resolution);
- ``dropout``: no reading for longer than ``DROPOUT_S`` (and ``DROPOUT_READINGS`` reading
  intervals); nothing to mask, but listed: explain never names a cause on another channel
  in such a hole (a hole in a log is not a cause);
- ``log_starts_late`` / ``log_ends_early``: no reading between the record's start and the
  log's first reading, or between its last reading and the record's end, for longer than a
  dropout by the same rule: a hole like a dropout (the gaps between readings are all the
  dropout rule sees; a log that stops midway and never comes back had none);
- a log more than 5 % of whose readings are spikes is not one sensor reading one place (two
  sensors answering on one column): noted and refused for the thermal model; so is a log
  that jumps more than 5 K between readings at most 10 s apart (units or sensors changed);
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

from avard.core.io.screen.accel import screen_accel
from avard.core.io.screen.notes import Screened, ScreenLog
from avard.core.io.screen.stream import screen_blocks, screen_record
from avard.core.io.screen.temperature import screen_temperature, stuck_runs

__all__ = ["ScreenLog", "Screened", "screen_accel", "screen_blocks", "screen_record",
           "screen_temperature", "stuck_runs"]

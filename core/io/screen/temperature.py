"""One DS18B20 channel's readings judged: read errors, power-on 85 °C values, spikes, dropouts and
stuck runs, and a channel's readings tracked across blocks."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

#: The DS18B20's range (°C) and its error value.
DS18B20_MIN_C, DS18B20_MAX_C, DS18B20_ERROR_C = -55.0, 125.0, -127.0
#: The power-on-reset value.
POWER_ON_C = 85.0
#: A jump (K) a room or a plate cannot make and undo between two readings.
JUMP_C = 0.5
#: A hole in a temperature log longer than this (s) and this many reading intervals.
DROPOUT_S, DROPOUT_READINGS = 10.0, 8.0
#: A glitch: up to this many readings in a row away from neighbours that agree (a spike is
#: one; a room or a plate does not move 0.5 K and back within a few readings)
GLITCH_READINGS = 3
#: The stuck rule: longer than this (s) and this factor times the channel's 95th-percentile run.
STUCK_MIN_S, STUCK_FACTOR = 1800.0, 10.0
#: The DS18B20's resolution (K): its readings (9–12 bits) are multiples of this.
DS18B20_STEP_C = 0.0625
#: A log is off the DS18B20's grid when fewer than this share of its readings lie on it.
OFF_GRID_SHARE = 0.5
#: Temperature channels that are no DS18B20 (avard's own ADXL355 die temperature, on its own
#: ~0.11 K step): the DS18B20 grid's units rule does not judge them.
NOT_DS18B20 = frozenset({"chip"})


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
    x = v[g]
    seen: set[int] = set()
    for width in range(1, GLITCH_READINGS + 1):
        if len(g) < width + 2:
            break
        # ``width`` readings in a row, each more than JUMP_C from both the reading before
        # them and the one after, which agree (a glitch of two readings had been kept,
        # and refused a whole log once a rule judged its level)
        left, right = x[:-width - 1], x[width + 1:]
        far = np.ones(len(left), dtype=bool)
        for j in range(1, width + 1):
            mid = x[j:len(x) - width - 1 + j]
            far &= (np.abs(mid - left) > JUMP_C) & (np.abs(mid - right) > JUMP_C)
        for s0 in np.flatnonzero(far & (np.abs(left - right) < 0.5 * JUMP_C)):
            for i in g[s0 + 1:s0 + 1 + width]:
                if int(i) not in seen:
                    seen.add(int(i))
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

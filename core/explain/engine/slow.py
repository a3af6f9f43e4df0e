"""The slow view: block means of every axis and temperature channel, kept on analyze's
first pass."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from typing import Any

import numpy as np
from avard.core.io.screen.stream import ScreenedSource
from numpy.typing import NDArray

#: Target length of one slow-view block (s); the block is the next power of two in samples.
BLOCK_S = 1.0
#: Most block means kept per channel (longer records get longer blocks).
MAX_POINTS = 1 << 18
MISFIT_SIGMA = 3.0
#: Fewest slow-view points for the time-domain causes.
MIN_SLOW_POINTS = 256

StageFn = Callable[[str], None]


# --------------------------------------------------------------------------------------------
# the slow view: block means of the axes and temperatures, collected while analyze streams


def block_size(rate_hz: float, n_samples: int | None) -> int:
    """Samples per slow-view block: a power of two (so its τ grid is analyze's octave grid),
    at least ``BLOCK_S`` long and at most ``MAX_POINTS`` blocks for a known length."""
    want = max(1.0, rate_hz * BLOCK_S, (n_samples or 0) / MAX_POINTS)
    return 1 << math.ceil(math.log2(want))


def _after(carry: NDArray[np.float64], x: NDArray[np.float64]) -> NDArray[np.float64]:
    """``x`` after the rows ``carry`` left from the last block (``x`` itself when none)."""
    return np.concatenate([carry, x]) if len(carry) else x


def slow_block_means(a: NDArray[np.float64], b: int) -> NDArray[np.float64]:
    """The means of consecutive ``b``-row blocks of ``a`` (nb·b, C):
    ``a.reshape(nb, b, C).mean(axis=1)`` to the bit. Over that middle axis numpy adds the
    block's rows one after the other, each a C-long inner loop; with C ≥ 2 the same
    additions in the same order are done here as b adds of whole (nb, C) row slices, which
    costs about half as much on every block explain reads. One channel (its blocks
    contiguous, which numpy sums pairwise), rows not laid out one after the other (numpy's
    order follows the strides) and blocks longer than their count (b slices of few rows)
    keep numpy's mean (``tests/core/test_explain_slow_view.py`` holds the two
    equal)."""
    nb = len(a) // b
    v = a.reshape(nb, b, a.shape[1])
    if a.shape[1] < 2 or b > nb or not a.flags.c_contiguous:
        return np.asarray(v.mean(axis=1), dtype=np.float64)
    s = np.zeros((nb, a.shape[1]))  # numpy's sum starts from 0 too (a block of −0.0: +0.0)
    for i in range(b):
        s += v[:, i, :]
    return np.asarray(s / b, dtype=np.float64)


def _reading_means(t: NDArray[np.float64], b: int
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(means, times): the mean of the finite readings in each block of ``b`` rows of ``t``
    (n, k), and the mean row of those readings in the block, as a fraction of a block from
    the block's centre (the acceleration's block mean is at the centre); NaN where a block
    holds none. A DS18B20 reads every 0.75 s, so nearly every value is NaN: the few readings
    are summed into their blocks by ``bincount``, in row order as a sum over the block adds
    them (the zeros a masked sum adds between them change no bit), instead of five passes
    over every value.

    The times are what :meth:`SlowView.finish` places each mean at: a 10 Hz record read
    every 8 rows holds its readings at rows 0 and 8 of a 16-row block, 0.35 s before the
    acceleration's centre, and a mean taken as the block's own value read the temperature
    0.35 s early (a +0.35 s bias on every lag)."""
    nb, k = len(t) // b, t.shape[1]
    r, c = np.nonzero(np.isfinite(t))
    where = (r // b) * k + c
    s = np.bincount(where, weights=t[r, c], minlength=nb * k).reshape(nb, k)
    cnt = np.bincount(where, minlength=nb * k).reshape(nb, k)
    rows = np.bincount(where, weights=(r % b).astype(float), minlength=nb * k).reshape(nb, k)
    with np.errstate(invalid="ignore", divide="ignore"):
        return (np.where(cnt > 0, s / cnt, np.nan),
                np.where(cnt > 0, (rows / cnt - 0.5 * (b - 1)) / b, np.nan))


class SlowView:
    """Block means (``b`` samples each) of C axes and k temperature channels; a temperature
    block without a reading (DS18B20 every 0.75 s) is NaN until ``finish`` interpolates it."""

    def __init__(self, b: int, n_axes: int, n_temps: int) -> None:
        self.b = int(b)
        self._acc: list[NDArray[np.float64]] = []
        self._tmp: list[NDArray[np.float64]] = []
        #: per block, where its readings' mean sits (fraction of a block from its centre)
        self._when: list[NDArray[np.float64]] = []
        self._carry_a = np.zeros((0, n_axes))
        self._carry_t = np.zeros((0, n_temps))
        self.n_temps = n_temps

    def update(self, accel: NDArray, temp: NDArray | None) -> None:
        # the carry is empty when the blocks are whole multiples of b (the usual case): then
        # the block itself, not a copy of it
        a = _after(self._carry_a, np.asarray(accel, dtype=float))
        nb = len(a) // self.b
        self._acc.append(slow_block_means(a[:nb * self.b], self.b))
        self._carry_a = a[nb * self.b:].copy()  # not a view of a block its reader may reuse
        if self.n_temps:
            t = (np.full((len(accel), self.n_temps), np.nan) if temp is None
                 else np.asarray(temp, dtype=float).reshape(len(accel), -1))
            t = _after(self._carry_t, t)
            means, when = _reading_means(t[:nb * self.b], self.b)
            self._tmp.append(means)
            self._when.append(when)
            self._carry_t = t[nb * self.b:].copy()

    def finish(self, holes: Sequence[Sequence[tuple[float, float]]] = (),
               rate_b: float = 1.0
               ) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
        """(axes (M, C), temperatures (M, k) with gaps interpolated, or None). ``holes``: per
        temperature channel, (start, end) s where the screen says the log tells nothing of the
        temperature (a stuck run: its readings were read before the rule could know), made
        gaps before the interpolation; ``rate_b`` blocks per second."""
        acc = np.concatenate(self._acc) if self._acc else np.zeros((0, self._carry_a.shape[1]))
        if not self.n_temps or not self._tmp:
            return acc, None
        tmp = np.concatenate(self._tmp)
        idx = np.arange(len(tmp))
        # each block's readings' mean at the time of its readings, interpolated onto the
        # block centres the acceleration's means sit at (``_reading_means``)
        at = idx[:, None] + np.concatenate(self._when)
        for j, spans in enumerate(holes):
            for t0, t1 in spans:
                tmp[max(0, math.floor(t0 * rate_b)):math.ceil(t1 * rate_b) + 1, j] = np.nan
        for j in range(tmp.shape[1]):
            ok = np.isfinite(tmp[:, j])
            if np.count_nonzero(ok) < 2:
                tmp[:, j] = np.nan
            else:
                tmp[:, j] = np.interp(idx, at[ok, j], tmp[ok, j])
        return acc, tmp


class _SlowTap:
    """The slow view fed by analyze's first pass (``analysis.engine.FirstPassTap``), or by
    ``explain_stream``'s blocks; ``complete`` once it has seen the whole record."""

    def __init__(self, rate_hz: float, n_samples: int | None, n_axes: int,
                 n_temps: int) -> None:
        self.slow = SlowView(block_size(float(rate_hz), n_samples), n_axes, n_temps)
        self.complete = False

    def update(self, accel: NDArray[np.float64], temp: NDArray[np.float64] | None) -> None:
        a = np.asarray(accel, dtype=float).reshape(len(accel), -1)
        if self.slow.n_temps and temp is not None and np.asarray(temp).size:
            self.slow.update(a, temp)
        else:
            self.slow.update(a, None)

    def end(self) -> None:
        self.complete = True


#: The held-out record: its description, its screened blocks (read when the held-out
#: measure asks) and the screen they come through (its log complete once they are read).
Held = tuple[dict[str, Any], Iterable[Any], ScreenedSource]

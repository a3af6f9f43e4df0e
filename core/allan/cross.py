"""Streaming Allan moments of two co-located sensors: what the live separation of each
sensor's own noise from the common input (core/analysis/separate.py) is computed from.

Two sensors a and b bolted to one plate see the same input; the Allan covariance of their
aligned outputs is the common part and the Allan variance of their difference a − b has
none of it (separate.py, eqs. 1 and 2). :class:`CrossAllan` keeps, for one pair and every
axis, the streaming partially overlapping Allan sums (:class:`~avard.core.allan.streaming.
StreamingAllan`, SP 1065 eq. 12 with the cascade's stride, and its covariance form for two
series) of the three channels a, b and a − b: so, at every octave τ,

    σ²_A(a),  σ²_A(b),  Cov_A(a, b),  σ²_A(a − b)

each with the noise identification (Lag1Ladder) and the Greenhall EDF of its own series —
exactly what the estimator needs (:class:`PairMoments`). The difference is a channel of its
own, not w·cov·w of the other two: its noise type, and so its EDF, is its own.

The state is the cascade's (O(C² · S · octaves) numbers with C = 3 per axis, whatever the
duration): kilobytes per pair, measured in tests/core/test_cross.py. Like the cascade it is
mergeable and checkpointable (``state``/``from_state``), and a gap in either sensor is a
gap for the pair: :meth:`CrossAllan.feed` takes each sensor's sample indices and ends the
segment wherever either index does not continue, so no difference straddles a loss.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from avard.core.allan.deviations import AllanResult
from avard.core.allan.streaming import StreamingAllan
from avard.core.errors import DataError, FormatError
from numpy.typing import ArrayLike, NDArray

__all__ = ["CrossAllan", "PairMoments"]

STATE_KIND = "cross_allan"
STATE_VERSION = 1


@dataclass(frozen=True)
class PairMoments:
    """The Allan moments of two aligned series a and b at K τ, in (input unit)² (m²/s⁴ for
    acceleration): ``var_a``, ``var_b`` their Allan variances, ``cov`` their Allan
    covariance, ``var_d`` the Allan variance of a − b; ``edf_*`` the EDF of each (of the
    noise identified on that series); ``n`` the second differences summed at each τ;
    ``n_samples`` the aligned samples the sums cover (all segments)."""

    tau: NDArray[np.float64]
    m: NDArray[np.int64]
    n: NDArray[np.int64]
    var_a: NDArray[np.float64]
    var_b: NDArray[np.float64]
    cov: NDArray[np.float64]
    var_d: NDArray[np.float64]
    edf_a: NDArray[np.float64]
    edf_b: NDArray[np.float64]
    edf_d: NDArray[np.float64]
    n_samples: int

    @classmethod
    def from_result(cls, res: AllanResult, a: int, b: int, d: int,
                    n_samples: int) -> PairMoments:
        """The moments of channels ``a``, ``b`` and their difference ``d`` (a channel holding
        a − b) of a multi-channel result with its covariance: the one reading of an Allan
        result for the separation, by the batch path and the streaming one alike."""
        if res.cov is None or res.var.ndim != 2:
            raise DataError("the separation needs a multi-channel Allan result with its "
                            "covariance")
        return cls(res.tau, res.m, res.n, res.var[:, a], res.var[:, b], res.cov[:, a, b],
                   res.var[:, d], res.edf[:, a], res.edf[:, b], res.edf[:, d],
                   int(n_samples))

    def at(self, ms: NDArray[np.int64]) -> PairMoments:
        """The moments at the averaging factors ``ms`` (each one of ``m``)."""
        k = np.searchsorted(self.m, ms)
        if np.any(k >= len(self.m)) or np.any(self.m[np.minimum(k, len(self.m) - 1)] != ms):
            raise DataError("PairMoments.at: an averaging factor these moments do not have")
        return PairMoments(self.tau[k], self.m[k], self.n[k], self.var_a[k], self.var_b[k],
                           self.cov[k], self.var_d[k], self.edf_a[k], self.edf_b[k],
                           self.edf_d[k], self.n_samples)


class CrossAllan:
    """Streaming Allan moments of one sensor pair (a, b) on ``axes``, at octave τ.

    Feed aligned samples (n, A) of both sensors, in SI, with :meth:`update` (and
    :meth:`gap` at a loss), or with their sample indices through :meth:`feed`, which finds
    the losses itself. :meth:`moments` gives one :class:`PairMoments` per axis.
    """

    def __init__(self, rate_hz: float, *, axes: Sequence[str] = ("x", "y", "z"),
                 sensors: tuple[str, str] = ("a", "b"), overlap: int = 8,
                 max_octaves: int = 40) -> None:
        if len(axes) < 1 or len(set(axes)) != len(axes):
            raise DataError(f"axes {list(axes)}: give one or more distinct axis names")
        if len(sensors) != 2 or sensors[0] == sensors[1]:
            raise DataError(f"a pair is two distinct sensors, not {list(sensors)}")
        self.axes = tuple(axes)
        self.sensors = (str(sensors[0]), str(sensors[1]))
        a, b = self.sensors
        names = [f"{who}.{ax}" for ax in self.axes for who in (a, b, f"{a}-{b}")]
        self._acc = StreamingAllan(3 * len(self.axes), rate_hz, overlap=overlap,
                                   max_octaves=max_octaves, names=names)
        # each sensor's index of the last sample fed through ``feed`` (None: a new segment)
        self._last: tuple[int, int] | None = None
        self.n_segments = 0        # segments that received samples (a gap starts the next)
        self._open = False

    @property
    def rate_hz(self) -> float:
        return self._acc.rate_hz

    @property
    def last_fed(self) -> tuple[int, int] | None:
        """Each sensor's index of the last row :meth:`feed` added (None after a gap): a
        replay continues after it."""
        return self._last

    @property
    def n_samples(self) -> int:
        """Aligned sample pairs accumulated (all segments)."""
        return self._acc.n_samples

    def _stack(self, a: ArrayLike, b: ArrayLike) -> NDArray[np.float64]:
        ya = np.asarray(a, dtype=np.float64)
        yb = np.asarray(b, dtype=np.float64)
        ya = ya[:, None] if ya.ndim == 1 else ya
        yb = yb[:, None] if yb.ndim == 1 else yb
        k = len(self.axes)
        if ya.shape != yb.shape or ya.ndim != 2 or ya.shape[1] != k:
            raise DataError(f"a pair's blocks must be aligned: the same samples and {k} axes "
                            f"(shapes {ya.shape} and {yb.shape})")
        out = np.empty((ya.shape[0], 3 * k))
        out[:, 0::3] = ya
        out[:, 1::3] = yb
        out[:, 2::3] = ya - yb
        return out

    def update(self, a: ArrayLike, b: ArrayLike) -> None:
        """Add aligned samples of a and b, each (n, A) (or (n,) for one axis) in SI;
        they continue the current segment."""
        block = self._stack(a, b)
        if len(block) and not self._open:
            self.n_segments += 1
            self._open = True
        self._acc.update(block)

    def gap(self) -> None:
        """End the segment: no later difference reaches back across this point."""
        self._acc.gap()
        self._last = None
        self._open = False

    def feed(self, index_a: ArrayLike, index_b: ArrayLike, a: ArrayLike,
             b: ArrayLike) -> int:
        """Add rows whose sensor indices are ``index_a``/``index_b`` (n,) (−1 where that
        sensor has no sample): rows missing in either sensor are left out, and the segment
        ends wherever either sensor's index does not continue by exactly one (a loss, or a
        slip of the alignment), here or from the previous call. Returns the rows added."""
        ia = np.asarray(index_a, dtype=np.int64)
        ib = np.asarray(index_b, dtype=np.int64)
        ya = np.asarray(a, dtype=np.float64)
        yb = np.asarray(b, dtype=np.float64)
        if not (ia.shape == ib.shape and ia.ndim == 1 and len(ya) == len(yb) == len(ia)):
            raise DataError("feed: one index per row of each sensor's block "
                            f"({ia.shape}, {ib.shape}, {len(ya)} and {len(yb)} rows)")
        ok = np.flatnonzero((ia >= 0) & (ib >= 0))
        if not len(ok):
            return 0
        ia, ib = ia[ok], ib[ok]
        brk = np.flatnonzero((np.diff(ia) != 1) | (np.diff(ib) != 1)) + 1
        edges = [0, *brk.tolist(), len(ok)]
        for s, e in itertools.pairwise(edges):
            if self._last is None or (int(ia[s]), int(ib[s])) != (self._last[0] + 1,
                                                                   self._last[1] + 1):
                self.gap()
            rows = ok[s:e]
            self.update(ya[rows], yb[rows])
            self._last = (int(ia[e - 1]), int(ib[e - 1]))
        return len(ok)

    def merge(self, other: CrossAllan) -> None:
        """Add another accumulator's sums (other segments of the same pair and axes)."""
        if not isinstance(other, CrossAllan) or other.axes != self.axes \
                or other.sensors != self.sensors:
            raise DataError("merge takes a CrossAllan of the same sensors and axes")
        self._acc.merge(other._acc)
        self.n_segments += other.n_segments

    def moments(self, ci: float = 0.683) -> tuple[PairMoments, ...]:
        """One :class:`PairMoments` per axis, at every octave τ with a difference so far."""
        try:
            res = self._acc.result(ci=ci)
        except DataError:
            raise DataError(f"no Allan moments yet for {self.sensors[0]}–{self.sensors[1]}: "
                            f"{self.n_samples} aligned samples is too few; feed more") from None
        return tuple(PairMoments.from_result(res, 3 * c, 3 * c + 1, 3 * c + 2,
                                             self.n_samples) for c in range(len(self.axes)))

    def state(self) -> dict:
        """Everything needed to continue exactly (msgpack-able): the cascade's state and the
        last fed indices."""
        return {"kind": STATE_KIND, "v": STATE_VERSION, "axes": list(self.axes),
                "sensors": list(self.sensors), "last": None if self._last is None
                else list(self._last), "segments": self.n_segments, "open": self._open,
                "allan": self._acc.state()}

    @classmethod
    def from_state(cls, state: dict) -> CrossAllan:
        """Restore from :meth:`state` exactly."""
        try:
            if state.get("kind") != STATE_KIND or state.get("v") != STATE_VERSION:
                raise FormatError(f"not a version-{STATE_VERSION} CrossAllan state "
                                  f"(kind={state.get('kind')!r}, v={state.get('v')!r})")
            allan = StreamingAllan.from_state(state["allan"])
            sensors = tuple(str(s) for s in state["sensors"])
            self = cls(allan.rate_hz, axes=[str(a) for a in state["axes"]],
                       sensors=(sensors[0], sensors[1]), overlap=allan.overlap,
                       max_octaves=allan.max_octaves)
            if allan.n_channels != 3 * len(self.axes):
                raise FormatError(f"a CrossAllan state of {len(self.axes)} axes holds "
                                  f"{allan.n_channels} channels, not {3 * len(self.axes)}")
            self._acc = allan
            last = state["last"]
            self._last = None if last is None else (int(last[0]), int(last[1]))
            self.n_segments = int(state["segments"])
            self._open = bool(state["open"])
        except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
            raise FormatError(f"CrossAllan state is incomplete or malformed: {exc}; start a "
                              "new accumulator") from exc
        return self

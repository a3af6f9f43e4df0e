"""Where the sensors of a rig stand against each other in time: per sensor, the sample taken at
the same instant as a reference sensor's sample, from each sensor's own fitted time base
(daemon/hw/timebase.py). Published and recorded as the ``alignment`` event of every sensor
(its detail is :meth:`Alignment.to_dict`), and the seam a cross-sensor stage reads
(docs/architecture.md, "Several sensors").

The ADXL355's own crystal sets each sensor's rate (±ppm apart), so without a shared sample
clock the offsets drift; ``sync = "external"`` in the config says the SYNC/CLK pins share one,
which this module records as a fact (``sync``) beside the fitted offsets: the offsets are
fitted either way, so a wiring that does not do what the config says shows as a drift.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any, Protocol

#: How far a time base may date a drain's newest set from its true time, in samples (the set
#: is seen within one sample period of being made; daemon/service/acquisition.py).
DATING_U_SAMPLES = 0.5


class AlignedLane(Protocol):
    """What alignment needs of a lane: its name, its next sample index and its time base."""

    sensor_name: str

    def next_index(self) -> int: ...

    def time_of(self, index: float) -> float: ...

    def rate(self) -> tuple[float, float, float]: ...   # odr_hz, odr_u_hz, jitter_s


@dataclass(frozen=True)
class SensorAlignment:
    """One sensor against the reference: its sample ``index_offset`` (a float) after the
    reference's sample ``at_index`` was taken at the same instant (± ``offset_u_samples``,
    the two time bases' scatter), and its fitted rate."""

    name: str
    odr_hz: float
    odr_u_hz: float
    index_offset: float
    offset_u_samples: float
    offset_s: float           # index_offset in seconds at this sensor's rate


@dataclass(frozen=True)
class Alignment:
    """The rig's sensors against ``reference`` (the first sensor) at its sample ``at_index``
    (CLOCK_MONOTONIC ``t_mono``)."""

    reference: str
    at_index: int
    t_mono: float
    sync: str                 # "external" (SYNC/CLK wired to a common clock) or "none"
    sensors: tuple[SensorAlignment, ...]

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["sensors"] = [asdict(s) for s in self.sensors]
        return out

    def of(self, name: str) -> SensorAlignment:
        return next(s for s in self.sensors if s.name == name)


def align(lanes: Sequence[AlignedLane], sync: str) -> Alignment | None:
    """The alignment of ``lanes`` against the first; None until every time base has a fit
    (a sensor that never produced a sample cannot be placed)."""
    ref = lanes[0]
    at = ref.next_index() - 1
    try:
        t = ref.time_of(at)
        _r_odr, _r_u, r_jitter = ref.rate()
    except (ValueError, ZeroDivisionError):
        return None
    out = []
    for lane in lanes:
        try:
            last = lane.next_index() - 1
            odr, odr_u, jitter = lane.rate()
            j = last + (t - lane.time_of(last)) * odr
        except (ValueError, ZeroDivisionError):
            return None
        offset = j - at
        # the drains' scatter, and each time base's dating of a drain's newest set (within a
        # sample period: half a sample each way), which does not average out when the drains
        # keep one phase (a virtual clock, an INT1 pin); 0 for the reference against itself
        dating = 0.0 if lane is ref else 2 * DATING_U_SAMPLES ** 2
        u = ((jitter ** 2 + r_jitter ** 2) * odr ** 2 + dating) ** 0.5
        out.append(SensorAlignment(lane.sensor_name, odr, odr_u, offset, u, offset / odr))
    return Alignment(ref.sensor_name, at, t, sync, tuple(out))

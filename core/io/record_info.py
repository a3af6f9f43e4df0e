"""The description of a record (``RecordInfo``, its format, a recording's runs, losses, gaps and
duplicates) and the ``RecordSource`` protocol every command reads a record through."""

from __future__ import annotations

import enum
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from avard.core.errors import DataError
from avard.core.io.rates import format_rate
from numpy.typing import NDArray

#: Samples per block a source yields by default.
BLOCK = 1 << 16

#: (accel block (n, C) m/s², temperature block (n, k) °C or None, True where a segment ends:
#: no Allan difference or spectrum segment spans what follows)
RecordBlock = tuple[NDArray[np.float64], NDArray[np.float64] | None, bool]


class RecordFormat(enum.Enum):
    """What a record was read from."""

    NPZ = "npz"
    CSV = "csv"
    RECORDING = "recording"      # the service's recording (segment files)
    STREAM = "stream"            # blocks from anywhere (the simulator, a test)


@dataclass(frozen=True)
class RunSummary:
    """One run of a recording: its rate (Hz) with its standard uncertainty, its samples and
    what damage or deletion cost it. ``rate_fitted`` False: the run ended before the
    service's fit of the output rate was ready, so its header carries the nominal ODR
    (``nominal_hz``) and no uncertainty."""

    run: str
    rate_hz: float
    rate_u_hz: float
    first_index: int
    n_samples: int
    samples_lost: int
    samples_duplicated: int
    rate_fitted: bool = True
    nominal_hz: float | None = None

    def to_dict(self) -> dict[str, object]:
        return {"run": self.run, "rate_hz": self.rate_hz, "rate_u_hz": self.rate_u_hz,
                "rate_fitted": self.rate_fitted, "nominal_hz": self.nominal_hz,
                "first_index": self.first_index, "n_samples": self.n_samples,
                "samples_lost": self.samples_lost,
                "samples_duplicated": self.samples_duplicated}

    def rate_text(self) -> str:
        return (format_rate(self.rate_hz, self.rate_u_hz) if self.rate_fitted
                else f"{self.rate_hz:g} Hz (nominal, not fitted yet)")


@dataclass(frozen=True)
class Loss:
    """Samples ``[i0, i0 + n)`` of run ``run`` the recording lacks without a gap record saying
    why: damage (``cause``), or a missing, empty or replaced segment; ``where`` names the
    files around them."""

    run: str
    i0: int
    n: int
    cause: str
    where: str

    def to_dict(self) -> dict[str, object]:
        return {"run": self.run, "i0": self.i0, "n": self.n, "cause": self.cause,
                "where": self.where}


@dataclass(frozen=True)
class Duplicate:
    """Samples ``[i0, i0 + n)`` read again in ``where`` (counted once)."""

    run: str
    i0: int
    n: int
    where: str

    def to_dict(self) -> dict[str, object]:
        return {"run": self.run, "i0": self.i0, "n": self.n, "where": self.where}


@dataclass(frozen=True)
class Gap:
    """A gap record: samples ``[i0, i0 + n)`` the service knew it missed, and why."""

    run: str
    i0: int
    n: int
    reason: str

    def to_dict(self) -> dict[str, object]:
        return {"run": self.run, "i0": self.i0, "n": self.n, "reason": self.reason}


@dataclass(frozen=True)
class RecordingSummary:
    """What a recording holds beyond its samples: the runs read (in order), every loss,
    duplicate and gap record, the segments the accumulators saw (split at every gap record,
    run change and index jump), the files, and the frames the reader skipped."""

    runs: tuple[RunSummary, ...]
    losses: tuple[Loss, ...]
    duplicates: tuple[Duplicate, ...]
    gaps: tuple[Gap, ...]
    n_segments: int
    files: tuple[str, ...]
    problems: tuple[str, ...]
    dropped_bytes: int

    @property
    def samples_lost(self) -> int:
        return sum(x.n for x in self.losses)

    @property
    def samples_duplicated(self) -> int:
        return sum(x.n for x in self.duplicates)

    def to_dict(self) -> dict[str, object]:
        """The ``recording`` part of analyze's JSON."""
        return {"segments": self.n_segments, "gap_records": len(self.gaps),
                "samples_lost": self.samples_lost,
                "losses": [x.to_dict() for x in self.losses],
                "samples_duplicated": self.samples_duplicated,
                "duplicates": [x.to_dict() for x in self.duplicates],
                "runs": [r.to_dict() for r in self.runs],
                "gaps": [g.to_dict() for g in self.gaps],
                "problems": list(self.problems), "dropped_bytes": self.dropped_bytes}


@dataclass(frozen=True)
class RecordInfo:
    """A record's description, known before its samples are read. ``rate_hz`` in Hz with its
    standard uncertainty ``rate_u_hz`` (0: unknown); ``n_samples`` None when unknown (a CSV);
    ``lsb_mps2`` the quantisation step in m/s² when the record says it; ``filter_corner_hz``
    the sensor's own low-pass corner (the ADXL355's ODR/4) when the record says it is one,
    so every path that fits the record models the same filter."""

    source: str
    format: RecordFormat
    rate_hz: float
    names: tuple[str, ...]
    temperature_names: tuple[str, ...] = ()
    n_samples: int | None = None
    rate_u_hz: float = 0.0
    lsb_mps2: float | None = None
    sensor_name: str | None = None
    sensor_model: str | None = None
    filter_corner_hz: float | None = None
    has_gyro: bool = False
    recording: RecordingSummary | None = None

    def as_meta(self) -> dict[str, Any]:
        """The description as the plain dictionary older code reads (explain's internals,
        ``Analysis.meta``): new code reads the fields."""
        meta: dict[str, Any] = {
            "format": self.format.value, "source": self.source, "rate_hz": self.rate_hz,
            "rate_u_hz": self.rate_u_hz, "names": list(self.names),
            "temperature_names": list(self.temperature_names), "n_samples": self.n_samples,
            "lsb_mps2": self.lsb_mps2, "sensor": self.sensor_name,
            "sensor_model": self.sensor_model, "has_gyro": self.has_gyro,
            "units": {"accel": "m/s^2", "temperature": "degC", "rate": "Hz"}}
        if self.recording is not None:
            meta["n_segments"] = self.recording.n_segments
        return meta


class RecordSource(Protocol):
    """A record: its description and its blocks, readable as often as a consumer needs
    (``rereadable`` False: a one-shot stream, read once)."""

    @property
    def info(self) -> RecordInfo: ...

    @property
    def rereadable(self) -> bool: ...

    def blocks(self, block: int = BLOCK, *, columns: Sequence[int] | None = None,
               temperature: bool = True, verify: bool = True) -> Iterator[RecordBlock]: ...


def _check_block(block: int) -> None:
    if block < 1:
        raise DataError(f"block size {block} must be >= 1 sample")


def _check_columns(columns: Sequence[int] | None, info: RecordInfo) -> None:
    n = len(info.names)
    if columns is not None and any(not 0 <= int(c) < n for c in columns):
        raise DataError(f"{info.source}: accel columns {list(columns)} asked for, the record "
                        f"has {n} (0..{n - 1})")

"""The one record source of every command: a typed description and a re-iterable block stream.

``open_record(path)`` gives a :class:`RecordSource` for an ``.npz``, a ``.csv`` or an avard
recording (a directory of segment files, or one ``.avr`` segment) alike:

* ``source.info`` is a frozen :class:`RecordInfo`: where it came from, its format (an enum,
  never a string to compare), the sensor, the rate with its standard uncertainty, the
  channels, the sample count, the LSB, the sensor's own low-pass corner when known, and for a
  recording the summary of its runs, losses, gaps and duplicates (:class:`RecordingSummary`).
* ``source.blocks(...)`` streams (accel (n, C) m/s², temperature (n, k) °C or None, True where
  a segment ends) and may be called again: a consumer may read the record (or some of its
  channels) once more. Memory stays at one block whatever the record's length; a recording
  is walked frame by frame (``recording.walk``), never loaded whole.

A recording is scanned once when it is opened (no samples kept): every run's rate, where the
sample index jumps without a gap record (a missing, emptied or replaced segment: a loss, in
samples, with the files it lies between), and what was read twice. Runs whose fitted rates do
not agree by the one rule of :mod:`avard.core.io.rates` are refused, naming them, unless
``runs=`` picks compatible ones: they are never averaged. One WARNING line per run says what
was lost or duplicated; the detail is in ``info.recording`` (and analyze's JSON).

The types live in :mod:`avard.core.io.record_info`, the recording reader in
:mod:`avard.core.io.recording_source`; this module is where every command opens a record.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path

import numpy as np
from avard.core.errors import DataError
from avard.core.io.record_info import (
    BLOCK,
    Duplicate,
    Gap,
    Loss,
    RecordBlock,
    RecordFormat,
    RecordInfo,
    RecordingSummary,
    RecordSource,
    RunSummary,
    _check_block,
    _check_columns,
)
from avard.core.io.recording_source import RecordingSource

__all__ = ["BLOCK", "Duplicate", "Gap", "Loss", "RecordBlock", "RecordFormat", "RecordInfo",
           "RecordSource", "RecordingSource", "RecordingSummary", "RunSummary", "StreamSource",
           "open_record"]

log = logging.getLogger(__name__)

# ---------------------------------------------------------------------------------------------
# blocks from anywhere


class StreamSource:
    """Blocks from anywhere (the simulator, a test) with their description: read once."""

    rereadable = False

    def __init__(self, info: RecordInfo, blocks: Iterable[RecordBlock]) -> None:
        self._info = info
        self._blocks: Iterable[RecordBlock] | None = blocks

    @property
    def info(self) -> RecordInfo:
        return self._info

    def blocks(self, block: int = BLOCK, *, columns: Sequence[int] | None = None,
               temperature: bool = True, verify: bool = True) -> Iterator[RecordBlock]:
        """The blocks as given (``block`` does not re-cut them); a second call is refused."""
        if self._blocks is None:
            raise DataError(f"{self._info.source}: a stream can be read once only")
        _check_columns(columns, self._info)
        blocks, self._blocks = self._blocks, None
        cols = None if columns is None else list(columns)
        for a, t, end in blocks:
            yield (a if cols is None else a[:, cols]), (t if temperature else None), end


# ---------------------------------------------------------------------------------------------
# .npz and .csv: the file readers of readers.py


class FileSource:
    """An ``.npz`` or ``.csv`` file, streamed by :func:`avard.core.io.readers.iter_blocks`
    (one segment: a file has no gaps)."""

    rereadable = True

    def __init__(self, path: Path, rate_hz: float | None) -> None:
        from avard.core.io.readers import record_info

        self.path, self._rate = path, rate_hz
        meta = record_info(path, rate_hz=rate_hz)
        fmt = RecordFormat(meta["format"])
        odr = meta.get("odr_nominal_hz")
        rate = float(meta["rate_hz"])
        lsb = meta.get("lsb_mps2")
        preset = meta.get("preset")
        # avard's simulator writes odr_nominal_hz: its records are an ADXL355's, filter and all
        adxl = odr is not None
        self._info = RecordInfo(
            source=str(path), format=fmt, rate_hz=rate, names=tuple(meta["names"]),
            temperature_names=tuple(meta["temperature_names"]),
            n_samples=None if meta["n_samples"] is None else int(meta["n_samples"]),
            lsb_mps2=float(lsb) if isinstance(lsb, int | float | np.floating) and lsb > 0
            else None,
            # the file's own 'sensor' field (avard fleet --by sensor), else the preset's name
            sensor_name=(str(meta["sensor"]) if meta.get("sensor") is not None
                         else str(preset) if preset is not None else None),
            sensor_model="ADXL355" if adxl else None,
            filter_corner_hz=rate / 4.0 if adxl else None,
            has_gyro=bool(meta.get("has_gyro")))

    @property
    def info(self) -> RecordInfo:
        return self._info

    def blocks(self, block: int = BLOCK, *, columns: Sequence[int] | None = None,
               temperature: bool = True, verify: bool = True) -> Iterator[RecordBlock]:
        from avard.core.io.readers import iter_blocks

        _check_block(block)
        _check_columns(columns, self._info)
        _meta, it = iter_blocks(self.path, block, rate_hz=self._rate, columns=columns,
                                temperature=temperature, verify=verify)
        for a, t in it:
            yield a, t, False


# ---------------------------------------------------------------------------------------------


def rig_sensors(path: str | Path) -> tuple[str, ...]:
    """The sensors of a rig's recording (``avard run`` with several ``[[sensor]]``: one
    recording directory per sensor, ``DIR/NAME``), in name order; () for anything else."""
    p = Path(path)
    if not p.is_dir():
        return ()
    return tuple(sorted(d.name for d in p.iterdir() if _readable_recording(d)))


def _readable_recording(d: Path) -> bool:
    """A subdirectory holding segment files; one that cannot be read (lost+found at a
    mount's root, root-only) is no sensor's recording, not an error of the one beside it."""
    try:
        return d.is_dir() and _holds_segments(d)
    except OSError:
        return False


def rig_of(path: str | Path) -> tuple[str, ...]:
    """The sensors when ``path`` is a rig's recording and not itself a recording; () else."""
    names = rig_sensors(path)
    return () if not names or _holds_segments(Path(path)) else names


def _holds_segments(d: Path) -> bool:
    from avard.core.io.recording import SEGMENT_SUFFIX

    return any(f.suffix == SEGMENT_SUFFIX for f in d.iterdir())


def sensor_path(path: str | Path, sensor: str | None) -> Path:
    """``path`` itself, or the recording of ``sensor`` in a rig's recording. A rig's recording
    without a sensor named, or a name it does not hold, is refused (DataError, one line naming
    the sensors it holds). A directory that holds segment files itself (a one-sensor
    recording, perhaps beside a rig's later one) is that recording unless ``sensor`` names
    one of its subdirectories."""
    p = Path(path)
    if sensor is None and p.is_dir() and _holds_segments(p):
        beside = rig_sensors(p)      # today's one-sensor layout, a rig's recording beside it
        if beside:
            log.warning("%s holds a one-sensor recording (read here) and a rig's sensors "
                        "beside it (%s): pick one of those with --sensor NAME", p,
                        ", ".join(beside))
        return p
    names = rig_sensors(p)
    if sensor is not None and sensor in names:
        return p / sensor
    if not names or _holds_segments(p):
        return p
    if sensor is None:
        raise DataError(f"{p}: a rig's recording of {len(names)} sensors "
                        f"({', '.join(names)}); pick one with --sensor NAME")
    if sensor not in names:
        raise DataError(f"{p}: no sensor {sensor!r} in this rig's recording; its sensors are "
                        f"{', '.join(names)}")
    return p / sensor


def open_record(path: str | Path, *, rate_hz: float | None = None,
                runs: Sequence[str] | None = None, sensor: str | None = None) -> RecordSource:
    """The record at ``path``: an ``.npz``, a ``.csv`` (or ``.txt``), or an avard recording
    (a directory of segment files, or one ``.avr`` segment). ``rate_hz`` overrides the
    record's rate (Hz); ``runs`` keeps only these runs of a recording; ``sensor`` picks one
    sensor of a rig's recording (:func:`sensor_path`), or checks that a single record is
    that sensor's."""
    from avard.core.io.readers import record_kind

    p, kind = record_kind(sensor_path(path, sensor))
    source: RecordSource
    if kind == "recording":
        source = RecordingSource(p, rate_hz, runs)
        _ = source.info   # scanned now: a bad recording is said before any analysis starts
    elif runs is not None:
        raise DataError(f"{p}: --run picks runs of a recording; this is a single {kind} file")
    else:
        source = FileSource(p, rate_hz)
    if sensor is not None and source.info.sensor_name != sensor:
        raise DataError(f"{p}: no sensor {sensor!r} here; this record's sensor is "
                        f"{source.info.sensor_name or 'not named'}")
    return source

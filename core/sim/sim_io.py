"""Simulated records to disk as the .npz of issue 4, streamed so memory does not grow.

Keys written (``np.load(path)`` reads them without pickles):

* ``accel`` (N, 3) float64, m/s²: the 20-bit counts × LSB, what the sensor reports;
* ``rate_hz``: the real output data rate (Hz; nominal ODR × (1 + clock error));
* ``axes``: axis names; ``temperature_c`` (N, 2) °C: DS18B20 plate and ambient readings on the
  sample grid, NaN between readings; ``temperature_names``;
* ``lsb_mps2``, ``odr_nominal_hz``, ``seed``, ``preset``, ``sim_config`` (JSON of every
  parameter), ``source`` — so a record says how it was made.

An .npz is a zip of .npy members. ``accel`` is written into the zip chunk by chunk; the
temperatures go to a temporary .npy beside the output first (a zip member must be written in
one go) and are then copied in. The file appears under its name only when complete.
"""

from __future__ import annotations

import os
import secrets
import shutil
import tempfile
import zipfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import numpy as np
from avard.core.errors import DataError, OutputError, describe_os_error
from avard.core.sim.presets import SimConfig
from avard.core.sim.simulate import SensorSimulator, n_samples
from avard.core.sim.thermal import DS18B20_STEP_C, ds18b20_schedule
from numpy.typing import NDArray


def record_meta(config: SimConfig, seed: int | None) -> dict[str, object]:
    """The small members of a simulated record."""
    return {
        "rate_hz": np.float64(config.rate_hz),
        "axes": np.array(config.axes),
        "temperature_names": np.array(config.temperature_names),
        "lsb_mps2": np.float64(config.lsb_mps2),
        "odr_nominal_hz": np.float64(config.odr_hz),
        "seed": np.int64(-1 if seed is None else seed),
        "preset": np.array(config.preset),
        "sim_config": np.array(config.to_json()),
        "source": np.array(f"avard simulate (preset {config.preset}, seed {seed})"),
    }


def iter_record_blocks(
    config: SimConfig, n_total: int, seed: int | None, *, chunk: int = 1 << 17
) -> Iterator[tuple[int, NDArray[np.float64], NDArray[np.float64]]]:
    """Yield (index0, accel (n, 3) m/s² = counts × LSB, DS18B20 temperatures (n, 2) aligned)."""
    sim = SensorSimulator(config, seed)
    offsets = np.asarray(config.ds18b20_offset_c)
    done = 0
    while done < n_total:
        c = sim.next(min(chunk, n_total - done))
        # the DS18B20s need the temperatures at their conversion times only
        idx = ds18b20_schedule(c.index0, len(c), config.rate_hz, config.ds18b20_conversion_s)
        temp: NDArray[np.float64] = np.full((len(c), 2), np.nan, dtype=np.float64)
        vals = c.temperatures_at(idx - c.index0)[:, :2] + offsets
        temp[idx - c.index0] = np.round(vals / DS18B20_STEP_C) * DS18B20_STEP_C
        yield c.index0, np.asarray(c.counts * config.lsb_mps2, dtype=np.float64), temp
        done += len(c)


#: Bytes per sample of the written record: accel (3 × float64) and temperature_c (2 × float64).
_BYTES_PER_SAMPLE = 8 * (3 + 2)
#: Zip and .npy headers and the small members: a generous bound, they are a few kB.
_FIXED_BYTES = 1 << 16


@dataclass(frozen=True)
class NpzSize:
    """Disk space of a simulated record, in bytes: the finished file, and the most in use
    while it is written (the temperatures sit in a temporary .npy until they are copied in)."""

    n_samples: int
    final_bytes: int
    peak_bytes: int


def npz_size(config: SimConfig, hours: float) -> NpzSize:
    """What :func:`write_npz` will put on disk for ``hours`` of ``config``; a DataError when
    that is not a whole, countable number of samples."""
    if not (0 < hours * 3600.0 * config.rate_hz < 1e18):   # 1e18 samples: 40 EB
        raise DataError(f"{hours:g} h at {config.rate_hz:g} Hz is not a record that can be "
                        "written; ask for between one sample and a few years (--hours)")
    n = n_samples(config, hours)
    if n < 1:
        raise DataError(f"{hours:g} h at {config.rate_hz:g} Hz is less than one sample; ask "
                        "for a longer record (--hours)")
    final = n * _BYTES_PER_SAMPLE + _FIXED_BYTES
    return NpzSize(n, final, final + n * 8 * 2)


def draw_seed() -> int:
    """A fresh seed for a record asked for without one, so that the record can still say
    how to make it again (32 bits: short enough to type back, and SeedSequence-ready)."""
    return secrets.randbits(32)


def _npy_header(fp: IO[bytes], shape: tuple[int, ...], dtype: np.dtype) -> None:
    header = {"descr": np.lib.format.dtype_to_descr(dtype), "fortran_order": False,
              "shape": shape}
    np.lib.format.write_array_header_2_0(fp, header)


def write_npz(
    path: str | os.PathLike, config: SimConfig, hours: float, seed: int | None, *,
    chunk: int = 1 << 17, progress: Callable[[int, int], None] | None = None,
) -> int:
    """Simulate ``hours`` of ``config`` into ``path`` (.npz) in bounded memory. Returns the
    number of samples written. ``progress(done, total)`` is called after every chunk."""
    n_total = n_samples(config, hours)
    if n_total < 1:
        raise DataError(f"{hours} h at {config.rate_hz:g} Hz is less than one sample; "
                        "ask for a longer record (--hours)")
    out = Path(path)
    if out.suffix != ".npz":
        raise DataError(f"output {out} must end in .npz")
    if not out.parent.exists():
        raise DataError(f"output folder {out.parent} does not exist; create it first")
    tmp_zip = tmp_temp = ""
    try:
        # both inside the try: a second mkstemp that fails must not leave the first behind
        fd, tmp_zip = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".part", dir=out.parent)
        os.close(fd)
        fd, tmp_temp = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".temp.npy",
                                        dir=out.parent)
        os.close(fd)
        with zipfile.ZipFile(tmp_zip, "w", compression=zipfile.ZIP_STORED,
                             allowZip64=True) as zf, open(tmp_temp, "wb") as tf:
            _npy_header(tf, (n_total, 2), np.dtype("<f8"))
            with zf.open("accel.npy", "w", force_zip64=True) as af:
                _npy_header(af, (n_total, 3), np.dtype("<f8"))
                for i0, accel, temp in iter_record_blocks(config, n_total, seed, chunk=chunk):
                    af.write(np.ascontiguousarray(accel, dtype="<f8").tobytes())
                    tf.write(np.ascontiguousarray(temp, dtype="<f8").tobytes())
                    if progress is not None:
                        progress(i0 + len(accel), n_total)
            tf.close()
            with zf.open("temperature_c.npy", "w", force_zip64=True) as zt, \
                    open(tmp_temp, "rb") as src:
                shutil.copyfileobj(src, zt, 1 << 20)
            for key, value in record_meta(config, seed).items():
                with zf.open(f"{key}.npy", "w") as member:
                    np.lib.format.write_array(member, np.asarray(value), allow_pickle=False)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp_zip, 0o666 & ~umask)    # mkstemp makes 0600; a record is an ordinary file
        os.replace(tmp_zip, out)
    except OSError as exc:  # a full disk, a folder removed under us: one line, the path named
        raise OutputError(f"writing {out}: {describe_os_error(exc)}") from exc
    finally:
        # also reached on Ctrl-C and (through avard.daemon.service.stop_signals) SIGTERM and SIGHUP
        for p in (tmp_zip, tmp_temp):
            if p and os.path.exists(p):
                os.unlink(p)
    return n_total

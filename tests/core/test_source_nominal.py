"""A recording's runs are compared by the nominal ODR their headers state, read by the one
reader of it (``feed.nominal_of``): the source read ``nominal_odr_hz`` by hand, and took a
value no avard writes (NaN, 0, negative) as a rate, so a single run whose header said NaN
was refused as incompatible with itself, and a run saying 0 beside one at 125 Hz refused."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from avard.core.errors import DataError
from avard.core.io import frames
from avard.core.io.readers import load_record
from avard.core.io.recording import frame
from avard.core.io.source import open_record


def _read(data: Path) -> tuple[float, int]:
    """(rate, samples) by the record source (avard analyze's) and by the loader, which must
    agree on what they accept."""
    info = open_record(data).info
    rec = load_record(data)
    assert (info.rate_hz, info.n_samples) == (rec.rate_hz, len(rec.accel))
    return info.rate_hz, info.n_samples


def _refused(data: Path) -> None:
    with pytest.raises(DataError, match="rates"):
        _ = open_record(data).info
    with pytest.raises(DataError, match="rates"):
        load_record(data)


def _run(data: Path, run: str, i0: int, nominal: object, rate: float = 125.0) -> None:
    """One segment of a run whose rate fit was not ready (its header gives the nominal ODR
    only), continuing the index at ``i0``."""
    head = frames.header_record(run, rate_hz=rate, t_mono=0.0, t_real=1.7e9, i0=i0,
                                scale_m_s2_per_count=3.9e-5,
                                timebase={"odr_hz": rate, "odr_u_hz": 0.0},
                                nominal_odr_hz=nominal)
    counts = np.random.default_rng(i0).integers(-50, 50, (2000, 3)).astype(np.int32)
    raw = frames.raw_record(run, 1, i0, counts, 0.0, 1.7e9, rate_hz=rate)
    data.mkdir(exist_ok=True)
    (data / f"{run}_00000000_x.avr").write_bytes(
        b"".join(frame(frames.encode(r)) for r in (head, raw)))


@pytest.mark.parametrize("nominal", [125.0, 125, None])
def test_runs_at_one_stated_rate_are_one_record(tmp_path, nominal) -> None:
    data = tmp_path / "rec"
    _run(data, "0001-a", 0, nominal)
    _run(data, "0002-b", 2000, nominal)
    assert _read(data) == (125.0, 4000)


def test_runs_at_two_stated_rates_are_refused(tmp_path) -> None:
    data = tmp_path / "rec"
    _run(data, "0001-a", 0, 125.0)
    _run(data, "0002-b", 2000, 250.0, rate=250.0)
    _refused(data)


@pytest.mark.parametrize("bogus", [math.nan, 0.0, -125.0])
def test_a_stated_rate_no_avard_writes_counts_as_not_stated(tmp_path, bogus) -> None:
    """As for a recording of a version that wrote none: the run's own rate stands."""
    data = tmp_path / "rec"
    _run(data, "0001-a", 0, bogus)
    assert _read(data) == (125.0, 2000)
    _run(data, "0002-b", 2000, 125.0)
    assert _read(data) == (125.0, 4000)
    _run(data, "0003-c", 4000, 250.0, rate=250.0)          # another rate is still refused
    _refused(data)

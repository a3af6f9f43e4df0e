"""A recording's temperature records are decoded in bulk (``core/io/tempscan.py``) from the
byte ranges the scan skipped: the service's layout by array operations, every other layout
by the general decode, frame by frame. The tables are the walk's, reading for reading, on a
recording whose temperature records take every layout the bulk decoder must recognise or
hand on: the service's at every integer width of the sequence number and the index, a failed
read, several readings in one record, another key order, a float32, an integer reading, a
name that is no UTF-8, a second run, a record of a run the recording has no header of, and
two records at one index (the later wins)."""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any

import msgpack
import numpy as np
import pytest
from avard.core.io import frames, rawscan
from avard.core.io import recording_source as source_mod
from avard.core.io.recording import frame
from avard.core.io.source import RecordingSource, open_record

from tests.core.test_record_source_temperature import assert_same_tables

RATE = 100.0
SCALE = 1e-6
NAMES = ["chip", "28-00000000plate", "28-0000000ambient"]


def _temp(run: str, seq: int, i0: int, names: list[str], values: list[Any]) -> bytes:
    return frames.encode(frames.temp_record(run, seq, i0, names, values, i0 / RATE,
                                            1.7e9 + i0 / RATE))


def _odd(run: str, seq: int, i0: int, style: str, rng: np.random.Generator) -> bytes:
    """A temperature record the service would not write, but a reader must take."""
    v = float(20 + rng.normal())
    if style == "two":          # two readings in one record
        return _temp(run, seq, i0, NAMES[1:], [v, v + 1])
    if style == "order":        # the keys in another order
        return msgpack.packb({"kind": "temp", "v": 1, "i0": i0, "run": run, "seq": seq,
                              "t_mono": 0.0, "t_real": 0.0, "names": [NAMES[1]],
                              "values_c": [v], "source": "ds18b20"})
    if style == "float32":
        return msgpack.packb({"kind": "temp", "v": 1, "run": run, "seq": seq, "i0": i0,
                              "t_mono": 0.0, "t_real": 0.0, "names": [NAMES[2]],
                              "values_c": [v], "source": "ds18b20"}, use_single_float=True)
    if style == "int":          # a whole-degree reading packed as an integer
        return msgpack.packb({"kind": "temp", "v": 1, "run": run, "seq": seq, "i0": i0,
                              "t_mono": 0.0, "t_real": 0.0, "names": [NAMES[0]],
                              "values_c": [21], "source": "adxl355"})
    assert style == "latin1"    # a name that is no UTF-8: refused by both reads
    good = _temp(run, seq, i0, ["28-0000000ambienX"], [v])
    return good.replace(b"28-0000000ambienX", b"28-0000000ambien\xff")


def _write(d: Path, rng: np.random.Generator) -> Counter[str]:
    """Two runs (and records of a third, headerless one) over three segment files; returns
    how many records of each odd style were written."""
    d.mkdir()
    styles = ["two", "order", "float32", "int", "latin1"]
    written: Counter[str] = Counter()
    seq = [0]

    def nxt(i0: int) -> int:
        seq[0] += 1 if i0 < 70_000 else 50_000     # every width of a sequence number
        return seq[0]

    for k, (run, first) in enumerate((("r1", 0), ("r1", 150_000), ("r2", 0))):
        out = [frames.encode(frames.header_record(
            run, rate_hz=RATE, t_mono=0.0, t_real=0.0, seq=nxt(0), scale_m_s2_per_count=SCALE,
            temperature_channels=NAMES))]
        # the indices cross every width (fixint, uint 8/16/32) and the sequence numbers too
        for i0 in range(first, first + 30_000 if k != 2 else first + 4_000, 50):
            counts = rng.integers(-1000, 1000, (50, 3)).astype(np.int32)
            out.append(frames.encode(frames.raw_record(run, nxt(i0), i0, counts, i0 / RATE,
                                                       i0 / RATE)))
            for j, name in enumerate(NAMES):
                r = rng.random()
                if r < 0.05:
                    style = styles[int(rng.integers(len(styles)))]
                    written[style] += 1
                    out.append(_odd(run, nxt(i0), i0 + j, style, rng))
                elif r < 0.1:
                    out.append(_temp(run, nxt(i0), i0 + j, [name], [None]))   # a failed read
                elif r < 0.8:
                    value = float(np.round(20 + rng.normal(), 4))
                    out.append(_temp(run, nxt(i0), i0 + j, [name], [value]))
                    if r < 0.12:     # read again at the same index: the later one wins
                        out.append(_temp(run, nxt(i0), i0 + j, [name], [value + 0.5]))
            if i0 % 5000 == 0:
                out.append(_temp("r9", nxt(i0), i0, [NAMES[0]], [99.0]))   # no header: dropped
        (d / f"{run}_{k:04d}_x.avr").write_bytes(b"".join(frame(p) for p in out))
    return written


@pytest.mark.skipif(not rawscan.available(), reason="the scan notes the places in its C loop")
@pytest.mark.parametrize("runs", [None, ("r1",)])
def test_bulk_decoded_tables_are_the_walks(tmp_path, monkeypatch, runs) -> None:
    written = _write(tmp_path / "rec", np.random.default_rng(5))
    assert all(written[s] > 10 for s in ("two", "order", "float32", "int", "latin1"))
    general = Counter[str]()
    one_by_one = source_mod._temp_record

    def counted(payload: bytes, *a: Any) -> Any:
        general["frames"] += 1
        return one_by_one(payload, *a)

    monkeypatch.setattr(source_mod, "_temp_record", counted)
    src = open_record(tmp_path / "rec", runs=runs)
    assert isinstance(src, RecordingSource)
    assert src._places is not None and src._places.ok
    bulk = src._temperature_tables()
    # the service's layout is read in bulk: only the odd records went one by one
    odd = sum(written.values())
    assert 0 < general["frames"] <= odd
    src._temps, src._places = None, None
    assert_same_tables(bulk, src._temperature_tables(), 100)
    assert 99.0 not in np.concatenate([v for _i, v in bulk])

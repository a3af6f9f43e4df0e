"""``avard explain`` reads a record as ``avard analyze`` does, no more: analyze's first pass
reads every column and the temperatures through the one input screen and feeds explain's
slow view (``analysis.engine.FirstPassTap``); explain used to read the record a second time
for the slow view when analyze took it in several passes, screening it again.

The explanation is the one the two-read path gives (analyze of the record, then a read for
the slow view: ``explain_stream(..., base=analyze(...))``), JSON for JSON, on a recording
whose temperatures drive an axis and on its .npz twin, with analyze reading the record in
one pass and in one pass per channel."""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from avard.core.analysis import engine as analysis_engine
from avard.core.analysis.engine import analyze
from avard.core.explain.engine import explain_file, explain_stream
from avard.core.explain.options import ExplainOptions
from avard.core.io.source import RecordingSource, RecordSource, open_record

from tests.core.test_record_source_temperature import SCALE, _as_recording, _npz
from tests.support.adversary_gen import make_record as adversary_record

OPTIONS = ExplainOptions()


@pytest.fixture(scope="module")
def coupled(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The adversary generator's two-path thermal record (2 h, an axis driven through the
    plate and the room, two DS18B20 logs) as a recording and as an .npz of its samples."""
    tmp = tmp_path_factory.mktemp("coupled")
    adversary_record("twopath", 11, tmp / "gen.npz", hours=2.0)
    with np.load(tmp / "gen.npz") as z:
        rate = float(z["rate_hz"])
        counts = np.rint(np.asarray(z["accel"], dtype=float) / SCALE)
        temps = np.asarray(z["temperature_c"], dtype=float).reshape(len(counts), -1)
        names = [str(x) for x in z["temperature_names"]]
    return (_as_recording(counts, temps, names, rate, tmp / "rec"),
            _npz(counts, temps, names, rate, tmp / "same.npz"))


def _json(ex: Any) -> str:
    """The explanation as ``avard explain --json`` writes it (NaN as null), less the source
    (the path differs between twins)."""
    d = ex.to_dict()
    d.pop("source")

    def clean(v: Any) -> Any:
        if isinstance(v, float) and not math.isfinite(v):
            return None
        if isinstance(v, dict):
            return {k: clean(x) for k, x in v.items()}
        if isinstance(v, list | tuple):
            return [clean(x) for x in v]
        if isinstance(v, np.ndarray):
            return clean(v.tolist())
        if isinstance(v, np.generic):
            return clean(v.item())
        return v

    return json.dumps(clean(d), sort_keys=True)


def _two_reads(path: Path) -> str:
    """The explanation by the path explain took before: analyze of the record, then one more
    read of it (screened again) for the slow view."""
    base = analyze(open_record(path), OPTIONS)
    return _json(explain_stream(open_record(path), OPTIONS, base=base))


@pytest.fixture(params=["one pass", "a pass per channel"])
def passes(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    """analyze reading every channel in one pass (the records here are short), or, with the
    OADEV histories' budget cut to one channel's, one channel per pass (as a 60 h record)."""
    if request.param == "a pass per channel":
        monkeypatch.setattr(analysis_engine, "PASS_BUDGET_BYTES", 1)
    return str(request.param)


@pytest.mark.parametrize("twin", ["recording", "npz"])
def test_explain_from_analyzes_first_pass_equals_the_two_read_path(coupled, passes,
                                                                  twin) -> None:
    rec, npz = coupled
    path = rec if twin == "recording" else npz
    one = explain_file(open_record(path), OPTIONS)
    assert one.screen is not None and one.screen.done
    assert one.temperature_unused == {}   # both logs drive the thermal model
    assert any(ch.thermal is not None for ch in one.channels.values())
    assert _json(one) == _two_reads(path)


class _Counted:
    """A record source that counts its reads: (columns, with temperatures) per read."""

    def __init__(self, source: RecordSource) -> None:
        self.source = source
        self.reads: Counter[tuple[tuple[int, ...] | None, bool]] = Counter()

    @property
    def info(self) -> Any:
        return self.source.info

    @property
    def rereadable(self) -> bool:
        return bool(self.source.rereadable)

    def blocks(self, block: int = 1 << 16, *, columns: Sequence[int] | None = None,
               temperature: bool = True, verify: bool = True) -> Iterator[Any]:
        self.reads[(None if columns is None else tuple(columns), temperature)] += 1
        return self.source.blocks(block, columns=columns, temperature=temperature,
                                  verify=verify)


def test_explain_reads_the_record_as_often_as_analyze(coupled, passes, monkeypatch) -> None:
    """Every read explain makes of a recording is one analyze makes of it (the first with
    every column and the temperatures, for the screen and the slow view), and the
    temperature records are decoded once."""
    rec, _npz_path = coupled
    decoded = Counter[str]()
    placed = RecordingSource._placed_readings

    def counted_placed(self: RecordingSource, places: Any, keep: Any) -> Any:
        decoded["tables"] += 1
        return placed(self, places, keep)

    monkeypatch.setattr(RecordingSource, "_placed_readings", counted_placed)
    by_analyze = _Counted(open_record(rec))
    analyze(by_analyze, OPTIONS)
    by_explain = _Counted(open_record(rec))
    explain_file(by_explain, OPTIONS)
    n_passes = 1 if passes == "one pass" else 3
    assert by_explain.reads[(None, True)] == 1      # the screen's and the slow view's read
    assert sum(by_explain.reads.values()) == sum(by_analyze.reads.values())
    assert sum(n for (_c, t), n in by_explain.reads.items() if t) == 1
    assert sum(n for (c, _t), n in by_analyze.reads.items() if c is None) == 1
    assert len(by_analyze.reads) >= (1 if n_passes == 1 else 2)
    assert decoded["tables"] == 1                   # explain's; analyze reads none


def test_after_a_parallel_analysis_the_slow_view_is_read_as_before(coupled, monkeypatch
                                                                    ) -> None:
    """Worker processes read an .npz's chunks, so analyze's pass feeds no slow view: explain
    then reads it once more, as the two-read path did, and explains alike."""
    from dataclasses import replace

    from avard.core.explain.engine import slow

    _rec, npz = coupled
    options = replace(OPTIONS, workers=2)
    fed = Counter[str]()
    end = slow._SlowTap.end

    def counted_end(self: Any) -> None:
        fed["end"] += 1
        end(self)

    monkeypatch.setattr(slow._SlowTap, "end", counted_end)
    one = explain_file(open_record(npz), options)
    assert fed["end"] == 0          # the parallel pass fed no slow view
    base = analyze(open_record(npz), options)
    assert _json(one) == _json(explain_stream(open_record(npz), options, base=base))

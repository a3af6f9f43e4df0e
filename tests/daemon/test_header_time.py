"""A header's (i0, t_mono) is a point of the raw blocks' time line (issue 26, item 11): the
docs say t_mono is the time of sample i0, and the header once carried the clock at the moment
it was built, up to a drain period and a batch later (139 ms off at 125 Hz)."""

from __future__ import annotations

from pathlib import Path

from avard.core.io.recording import RecordingReader
from avard.daemon.compose import simulated_service
from avard.daemon.config import load_config


def test_every_header_dates_its_i0_on_the_raw_time_line(tmp_path: Path) -> None:
    cfg = load_config(None, **{
        "recording.data_dir": str(tmp_path / "rec"), "publish.enabled": False,
        "recording.segment_s": 10.0, "sensor.poll_hz": 2.0})
    svc, _sims, _emu = simulated_service(cfg, "quiet-lab", seed=2, speed=None)
    svc.run(45.0)
    recs = list(RecordingReader(tmp_path / "rec"))
    raws = [r for r in recs if r["kind"] == "raw"]
    headers = [r for r in recs if r["kind"] == "header"]
    assert len(headers) >= 4
    checked = 0
    for h in headers:
        # the raw block holding sample i0 (or starting there), and its time for i0
        blk = [r for r in raws if r["i0"] <= h["i0"] < r["i0"] + r["n"]]
        if not blk:
            continue
        r = blk[0]
        rate = float(r.get("rate_hz", h["rate_hz"]))
        expected = r["t_mono"] + (h["i0"] - r["i0"]) / rate
        assert abs(h["t_mono"] - expected) < 0.5 / rate, (h["i0"], h["t_mono"], expected)
        assert abs((h["t_real"] - h["t_mono"]) - (r["t_real"] - r["t_mono"])) < 1e-6
        checked += 1
    assert checked >= 3

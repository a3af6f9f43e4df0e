"""One recording directory holds one output data rate.

The accumulators' τ are sample counts: samples at another ODR fed into them would be averaged
as if they were at the first rate, with no error and a wrong curve. A service configured at
another rate than the recording in its data directory stops at start with one line (exit
status 2 through ``avard run``), and a directory that already mixes rates (made by hand or by
an older version) is refused by the offline replay and by the service's restore, which then
starts afresh (logged), never feeding the other rate's samples.
"""

from __future__ import annotations

import logging
import subprocess
import sys
from pathlib import Path

import pytest
from avard.core.errors import ConfigError, DataError
from avard.core.io import frames
from avard.core.io.readers import load_record
from avard.core.io.recording import RecordingReader, frame, replay_allan, scan_frames
from avard.daemon.compose import simulated_service
from avard.daemon.config import load_config
from avard.daemon.service.checkpoint import STATE_FILE
from avard.daemon.service.supervisor import Service


def _config(data: Path, odr: float, **over: object):
    settings: dict[str, object] = {
        "recording.data_dir": str(data), "publish.enabled": False, "sensor.poll_hz": 2.0,
        "sensor.odr_hz": odr, "allan.checkpoint_interval_s": 4.0,
        "allan.snapshot_interval_s": 4.0}
    settings.update(over)
    return load_config(None, **settings)


def _record(data: Path, odr: float, seconds: float, seed: int, **over: object) -> None:
    svc, _sims, _emu = simulated_service(_config(data, odr, **over), "quiet-lab", seed=seed)
    svc.run(seconds)


def _headers(data: Path) -> dict[str, float]:
    return {r["run"]: float(r["nominal_odr_hz"]) for r in RecordingReader(data)
            if r["kind"] == "header"}


def test_a_service_at_another_rate_than_its_recording_stops_at_start(tmp_path):
    data = tmp_path / "rec"
    _record(data, 125.0, 6.0, seed=1)
    before = sorted(p.name for p in data.iterdir())
    svc, _sims, _emu = simulated_service(_config(data, 250.0), "quiet-lab", seed=2)
    with pytest.raises(ConfigError, match=r"125 Hz.*250 Hz.*one output data rate"):
        svc.start()
    svc.stop()
    # nothing written: no second run in the recording, no file added or removed
    assert set(_headers(data).values()) == {125.0}
    assert sorted(p.name for p in data.iterdir()) == before
    # the same rate still continues the recording (the check did not keep the lock)
    _record(data, 125.0, 3.0, seed=3)
    assert len(_headers(data)) == 2 and set(_headers(data).values()) == {125.0}


def test_avard_run_at_another_rate_says_so_in_one_line_with_exit_status_2(tmp_path):
    data = tmp_path / "rec"
    _record(data, 125.0, 4.0, seed=4)
    cfg = tmp_path / "avard.toml"
    cfg.write_text(f'[recording]\ndata_dir = "{data}"\n[publish]\nenabled = false\n'
                   '[sensor]\nodr_hz = 250.0\n')
    out = subprocess.run([sys.executable, "-m", "avard.daemon.cli", "run", "--config", str(cfg),
                          "--simulate", "quiet-lab", "--speed", "0", "--duration", "2"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2, out.stderr
    assert "Traceback" not in out.stderr
    lines = [ln for ln in out.stderr.splitlines() if "one output data rate" in ln]
    assert len(lines) == 1 and "125 Hz" in lines[0] and "250 Hz" in lines[0]


def _mixed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, **over: object) -> Path:
    """A directory holding a 125 Hz run and then a 250 Hz run, as an older version (which
    did not check the rate at start) left it."""
    data = tmp_path / "rec"
    _record(data, 125.0, 6.0, seed=5, **over)
    with monkeypatch.context() as m:
        m.setattr(Service, "_check_recorded_rate", lambda self: None)
        _record(data, 250.0, 6.0, seed=6, **over)
    assert sorted(set(_headers(data).values())) == [125.0, 250.0]
    return data


def test_the_offline_replay_refuses_a_directory_that_mixes_rates(tmp_path, monkeypatch):
    data = _mixed(tmp_path, monkeypatch)
    with pytest.raises(DataError, match=r"250 Hz.*125 Hz.*one output data rate"):
        replay_allan(data)


def test_a_restore_over_mixed_rates_starts_afresh_and_never_feeds_the_other_rate(
        tmp_path, monkeypatch, caplog):
    # no checkpoint anywhere: the restore replays the whole recording into new accumulators
    data = _mixed(tmp_path, monkeypatch)
    (data / STATE_FILE).unlink()
    for seg in data.glob("*.avr"):                # as runs killed before any checkpoint
        kept = [frame(f.payload) for f in scan_frames(seg.read_bytes())
                if frames.decode(f.payload)["kind"] != "checkpoint"]
        seg.write_bytes(b"".join(kept))
    caplog.set_level(logging.ERROR)
    svc, _sims, _emu = simulated_service(
        _config(data, 250.0, **{"allan.checkpoint_interval_s": 3600.0}), "quiet-lab", seed=7)
    svc.run(3.0)
    said = [r.getMessage() for r in caplog.records if "one output data rate" in r.getMessage()]
    assert len(said) == 1 and "starting afresh" in said[0]
    # the accumulators hold this run's samples only (none of the 125 Hz run's, nor the
    # earlier 250 Hz run's, which the refused replay did not reach)
    assert float(svc.allan.rate_hz) == 250.0
    assert int(svc.allan.n_samples) <= int(svc.final_status["samples"])


def test_loading_a_directory_that_mixes_rates_refuses_it_rather_than_average_the_rates(
        tmp_path, monkeypatch):
    # (the pair separation loads whole recordings this way; a mean of 125 and 250 Hz was
    # its rate)
    data = _mixed(tmp_path, monkeypatch)
    with pytest.raises(DataError, match=r"different output data rates.*125 Hz.*250 Hz"):
        load_record(data)


def test_the_one_rate_rule_names_the_newest_run_at_another_rate(tmp_path):
    """``rate_conflict`` is the rule both the service and ``avard record --out`` apply (each
    says what to do in its own words): the newest header's run when its nominal ODR is not
    the one asked, else None (no stated rate on either side is no conflict)."""
    from avard.daemon.service.recorder import rate_conflict

    data = tmp_path / "rec"
    assert rate_conflict(data, 125.0) is None                 # no directory yet
    _record(data, 125.0, 3.0, seed=5)
    run = next(iter(_headers(data)))
    assert rate_conflict(data, 125.0) is None
    assert rate_conflict(data, None) is None
    assert rate_conflict(data, 250.0) == (run, 125.0)

"""The service and its files, adversarially (daemon23g): what a simulated service leaves behind,
and a segment changed behind the recorder's back while it writes into it.

Each case runs the simulated service on its virtual clock (as fast as it can) and acts from
the reader's tick at a chosen simulated time, so what happens depends on the data clock only.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest
from avard.core.io.recording import RecordingReader
from avard.daemon.compose import simulated_service
from avard.daemon.config import load_config
from avard.daemon.hw.simulation import W1_DIR
from avard.daemon.service.supervisor import Service


def _config(data: Path, **over: object):
    settings: dict[str, object] = {
        "recording.data_dir": str(data), "publish.enabled": False, "sensor.poll_hz": 2.0,
        "allan.checkpoint_interval_s": 4.0, "allan.snapshot_interval_s": 4.0}
    settings.update(over)
    return load_config(None, **settings)


# -- the simulated 1-Wire tree ------------------------------------------------------------------


def test_the_simulated_one_wire_tree_lives_in_the_recording_directory_never_in_tmp(
        tmp_path, monkeypatch):
    """The tree was a TemporaryDirectory in /tmp: removed by a finalizer that a killed
    process never runs, so every killed service or test left an ``avard-sim-w1-*`` folder.
    It now lives in the recording directory the service owns; a killed run's folder is
    replaced at the next start and removed at a clean stop."""
    data = tmp_path / "rec"
    data.mkdir()
    cfg = _config(data)
    tmp = tmp_path / "tmp"                       # the process's temporary directory
    tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    stale = data / W1_DIR / "devices" / "28-00000000dead"
    stale.mkdir(parents=True)                    # what a killed run left
    (stale / "w1_slave").write_text("junk\n")
    seen: list[set[str]] = []

    def look(t_mono: float) -> None:
        if not seen and (data / W1_DIR / "devices").is_dir() and \
                not (data / W1_DIR / "devices" / stale.name).exists():
            seen.append({p.name for p in (data / W1_DIR / "devices").iterdir()})
            seen.append({p.name for p in tmp.iterdir()})

    svc, sims, _emu = simulated_service(cfg, "quiet-lab", seed=1, after_tick=look)
    svc.run(6.0)
    # while it ran (as a SIGKILL would find it): the sensors' folders in the recording
    # directory, the stale one gone, nothing in the temporary directory
    assert seen, "the 1-Wire tree was never made in the recording directory"
    assert {f"28-{sid}" for sid in sims.ids} <= seen[0]
    assert seen[1] == set()
    # the simulated DS18B20s were read through it
    read = {n for r in RecordingReader(data) if r["kind"] == "temp"
            for n, v in zip(r["names"], r["values_c"], strict=True) if v is not None}
    assert set(sims.names) <= read
    # a clean stop removes it
    assert not (data / W1_DIR).exists()
    assert list(tmp.iterdir()) == []


def _run(data: Path, seconds: float, seed: int, **over: object) -> Service:
    svc, _sims, _emu = simulated_service(_config(data, **over), "quiet-lab", seed=seed)
    svc.run(seconds)
    return svc

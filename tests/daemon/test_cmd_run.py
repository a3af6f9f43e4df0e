"""`avard run` as a real process: SIGKILL and restart, SIGTERM, SIGHUP, argument checks."""

from __future__ import annotations

import itertools
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from avard.core.allan.streaming import StreamingAllan
from avard.core.io import frames
from avard.core.io.recording import RecordingReader, replay_allan, scan_frames
from avard.daemon.cli import main

CONFIG = """
[allan]
snapshot_interval_s = 5.0
checkpoint_interval_s = 20.0
[recording]
segment_s = 60.0
fsync_interval_s = 0.5
[publish]
enabled = false
[sensor]
poll_hz = 1.0
"""


def _start(tmp: Path, *extra: str) -> subprocess.Popen:
    cfg = tmp / "avard.toml"
    cfg.write_text(CONFIG)
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen(
        [sys.executable, "-m", "avard.daemon.cli", "-v", "run", "--config", str(cfg),
         "--simulate", "quiet-lab", "--data-dir", str(tmp / "rec"), *extra],
        stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, env=env, text=True)


def _timeout_stop_s() -> float:
    unit = Path(__file__).parents[2] / "systemd" / "avard.service"
    line = next(ln for ln in unit.read_text().splitlines() if ln.startswith("TimeoutStopSec="))
    return float(line.split("=", 1)[1].rstrip("s"))


def _wait_for(pred, timeout: float = 60.0) -> None:  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + timeout
    while not pred():
        if time.monotonic() > deadline:
            raise AssertionError("timed out")
        time.sleep(0.05)


def _recorded_samples(data_dir: Path) -> int:
    return sum(r["n"] for r in RecordingReader(data_dir) if r["kind"] == "raw")


def _state(path: Path) -> dict:
    fr = next(scan_frames(path.read_bytes()))
    return frames.decode(fr.payload)


def test_killed_process_restarts_with_gap_and_restored_accumulators(tmp_path: Path) -> None:
    ckpt = tmp_path / "rec" / "allan-state.ckpt"
    p1 = _start(tmp_path, "--speed", "0")
    try:
        _wait_for(lambda: ckpt.exists() and _state(ckpt)["n_samples"] > 40 * 125)
        # more data recorded after the checkpoint: the crash window (a count, not a sleep)
        n_ckpt = _state(ckpt)["n_samples"]
        _wait_for(lambda: _recorded_samples(tmp_path / "rec") > n_ckpt + 125)
    finally:
        p1.send_signal(signal.SIGKILL)
        p1.communicate(timeout=10)
    run1 = _state(ckpt)["run"]
    p2 = _start(tmp_path, "--speed", "0", "--duration", "30")
    _, err = p2.communicate(timeout=120)
    assert p2.returncode == 0, err
    assert "restored the Allan accumulators" in err
    recs = list(RecordingReader(tmp_path / "rec"))
    runs = list(dict.fromkeys(r["run"] for r in recs))
    assert runs[0] == run1 and len(runs) == 2
    gap = next(r for r in recs if r["kind"] == "gap" and r["reason"] == "restart")
    last1 = max(r["i0"] + r["n"] for r in recs if r["kind"] == "raw" and r["run"] == run1)
    first2 = min(r["i0"] for r in recs if r["kind"] == "raw" and r["run"] == runs[1])
    assert gap["i0"] == last1 and gap["i0"] + gap["n"] == first2
    start = next(r for r in recs if r["kind"] == "event" and r["name"] == "start"
                 and r["run"] == runs[1])
    assert start["detail"]["restored"]["run"] == run1
    # The accumulators after the restart hold both runs: exactly what an offline replay of
    # the whole recording gives (the crash window was replayed from the recording).
    final = StreamingAllan.from_state(_state(ckpt)["state"]).snapshot()
    offline = replay_allan(tmp_path / "rec").snapshot()
    assert final.n_samples == offline.n_samples
    np.testing.assert_allclose(final.avar, offline.avar, rtol=1e-12, atol=0)


def test_sigterm_flushes_and_sighup_reopens(tmp_path: Path) -> None:
    p = _start(tmp_path, "--speed", "20")
    try:
        # samples on disk before each signal (counts, not sleeps)
        _wait_for(lambda: any((tmp_path / "rec").glob("*.avr")))
        _wait_for(lambda: _recorded_samples(tmp_path / "rec") > 0)
        p.send_signal(signal.SIGHUP)
        _wait_for(lambda: len(list((tmp_path / "rec").glob("*.avr"))) >= 2)
        n_reopen = _recorded_samples(tmp_path / "rec")
        _wait_for(lambda: _recorded_samples(tmp_path / "rec") > n_reopen)
        p.send_signal(signal.SIGTERM)
        # The promise is systemd's: stopped before TimeoutStopSec= (else it is SIGKILLed).
        # TimeoutExpired fails the test; no wall-time figure tighter than that contract.
        _, err = p.communicate(timeout=_timeout_stop_s())
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 0, err
    reader = RecordingReader(tmp_path / "rec")
    recs = list(reader)
    assert reader.problems == []                   # closed cleanly: no truncated tail
    assert recs[-1]["kind"] in ("checkpoint", "avar", "raw", "event")
    assert any(r["kind"] == "checkpoint" for r in recs)
    raw = [r for r in recs if r["kind"] == "raw"]
    assert all(b["i0"] == a["i0"] + a["n"] for a, b in itertools.pairwise(raw))


def test_argument_and_config_errors_exit_2(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["run", "--speed", "10"]) == 2
    assert "--speed needs --simulate" in capsys.readouterr().err
    assert main(["run", "--simulate", "nonesuch", "--data-dir", str(tmp_path)]) == 2
    assert "unknown preset" in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    bad.write_text("[recording]\nfsync_interval_s = -1\n")
    assert main(["run", "--config", str(bad), "--simulate", "quiet-lab"]) == 2
    assert "recording.fsync_interval_s = -1" in capsys.readouterr().err


def test_hardware_code_path_over_an_emulated_spi_bus(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """The non-simulated path of `avard run` (system clock, the reader process, no
    backpressure), with only the part on /dev/spidev replaced by the register-level emulator
    on the real clock (in the reader process: drain_process.open_emulated)."""
    import argparse

    from avard.daemon.commands import run as run_cmd
    from avard.daemon.config import load_config
    from avard.daemon.config_types import Config
    from avard.daemon.hw import rig

    monkeypatch.setattr(rig, "HARDWARE_OPENER", "avard.daemon.hw.drain_process:open_emulated")
    cfg = load_config(None, **{"recording.data_dir": str(tmp_path / "rec"),
                               "publish.enabled": False, "temperature.ds18b20": False})
    args = argparse.Namespace(simulate=None, speed=None, seed=None)
    svc = run_cmd.build(args, Config.from_dict(cfg))
    assert svc.run(1.5) == 0
    st = svc.final_status
    assert st["overruns"] == 0 and 120 < st["samples"] < 260
    recs = list(RecordingReader(tmp_path / "rec"))
    assert recs[0]["sensor"]["device"] == "ADXL355"
    assert recs[0]["config"] == cfg   # the typed Config leaves the stored config unchanged
    counts = np.concatenate([r["counts"] for r in recs if r["kind"] == "raw"])
    # counter_source: consecutive counts, so nothing was lost or repeated on the way.
    assert np.all(np.diff(counts[:, 0]) == 1)


_LEAN = r"""
import os, sys
from avard.daemon.cli import build_parser
build_parser("run")                       # what `avard run` imports before it runs
from avard.daemon import blas_threads
from avard.daemon.config import load_config
from avard.daemon.config_types import as_config
from avard.daemon.hw.emulator import EmulatedAdxl355, FakeSpiDev, VirtualClock, counter_source
from avard.daemon.hw.adxl355 import Adxl355
from avard.daemon.compose import compose
from avard.daemon.hw.rig import Rig, RigSpec, SensorSpec
from avard.daemon.hw.transport import SpiBus
clock = VirtualClock()
dev = Adxl355(SpiBus(FakeSpiDev(EmulatedAdxl355(counter_source(), clock))), clock=clock)
dev.probe(); dev.reset(); dev.configure(range_g=2, odr_hz=125.0); dev.start()
cfg = load_config(None, **{"recording.data_dir": sys.argv[1], "publish.enabled": False,
                           "allan.snapshot_interval_s": 1.0})
config = as_config(cfg)
rig = Rig(RigSpec((SensorSpec.from_config(config.sensor),)), dev, clock, {})
svc = compose(config, rig)
svc.run(30.0)
heavy = sorted(m for m in sys.modules if m.split(".")[0] in ("scipy", "matplotlib"))
print(blas_threads.LOADED_BEFORE_NUMPY, os.environ["OPENBLAS_NUM_THREADS"], heavy,
      svc.final_status["allan_samples"])
"""


def test_the_service_path_loads_no_scipy_and_one_blas_thread(tmp_path: Path) -> None:
    """`avard run` on hardware (here the emulator fed by a counter, without the simulator):
    BLAS held to one thread before numpy loads, and neither scipy nor
    matplotlib imported through a run with snapshots (their intervals included)."""
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    out = subprocess.run([sys.executable, "-c", _LEAN, str(tmp_path)], capture_output=True,
                         text=True, env=env, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    before, threads, heavy, n = out.stdout.split(maxsplit=3)
    assert (before, threads, heavy) == ("True", "1", "[]")
    assert int(n) > 3000


_LEAN_SIMULATE = r"""
import sys
from avard.daemon.cli import main
sys.argv = ["avard", "run", "--config", sys.argv[1], "--simulate", "quiet-lab", "--speed", "0",
            "--duration", "40", "--data-dir", sys.argv[2], "--seed", "3"]
rc = main()
heavy = sorted(m for m in sys.modules if m.split(".")[0] in ("scipy", "matplotlib"))
print(rc, heavy)
"""


def test_the_simulated_rig_loads_no_scipy(tmp_path: Path) -> None:
    """`avard run --simulate` (issue #13: RSS ≤ 80 MB): the simulator's filters are numpy
    (core/sim/linear_filter.py), so neither scipy nor matplotlib is imported through a run
    of the whole simulated rig with snapshots."""
    cfg = tmp_path / "avard.toml"
    cfg.write_text("[publish]\nenabled = false\n[allan]\nsnapshot_interval_s = 1.0\n")
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    out = subprocess.run([sys.executable, "-c", _LEAN_SIMULATE, str(cfg), str(tmp_path / "d")],
                         capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split(maxsplit=1) == ["0", "[]\n"], out.stdout + out.stderr[-2000:]

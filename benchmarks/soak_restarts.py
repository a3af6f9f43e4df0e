"""The soak's restart classes (#26): early stops, restarts in quick succession, a damaged,
emptied or deleted checkpoint, and a wall-clock step with retention.

Each class is a sequence of service runs (in this process, over the emulator, preset
quiet-lab at 125 Hz, virtual clock) on one recording directory. After every run the soak
checks what the service promises, from the files alone:

- the accumulators of ``allan-state.ckpt`` equal the offline Allan variance of the recording
  (same sample count, AVAR to 1e-12): nothing counted twice, no history thrown away;
- the ``restart`` gaps tile the holes between runs (no two overlap);
- no ``invariant_violated`` event was recorded;
- a forward step of CLOCK_REALTIME with ``retention_days`` set deletes no segment.

``python -m benchmarks soak`` runs these after the long soak (``--restart-cycles``);
``tests/daemon/test_soak_restarts.py`` runs one cycle in CI.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

DAY_S = 86400.0


@dataclass
class RestartCampaign:
    """What the restart classes did and whether every check held."""

    runs: int = 0
    faults: dict[str, int] = field(default_factory=dict)
    recorded: int = 0                   # raw samples in the recording at the end
    accumulators: int = 0               # samples in the final accumulators
    restart_gaps: int = 0
    segments_deleted: int = 0
    checks: dict[str, bool] = field(default_factory=dict)
    failures: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return all(self.checks.values())

    def check(self, name: str, ok: bool, detail: str = "") -> None:
        self.checks[name] = self.checks.get(name, True) and ok
        if not ok:
            self.failures.append(f"{name}: {detail}")


def _config(data: Path, **extra: Any) -> Any:
    from avard.daemon.config import load_config

    keys = {"recording.data_dir": str(data), "publish.enabled": False, "sensor.poll_hz": 2.0,
            "allan.checkpoint_interval_s": 4.0, "allan.snapshot_interval_s": 4.0}
    keys.update(extra)
    return load_config(None, **keys)


def _service(data: Path, seed: int, *, after_tick: Callable[[float], None] | None = None,
             **extra: Any) -> Any:
    from avard.daemon.compose import simulated_service

    svc, _sims, _emu = simulated_service(_config(data, **extra), "quiet-lab", seed=seed,
                                         after_tick=after_tick)
    return svc


def _silent_stop(data: Path, seed: int) -> Any:
    """A sensor that produces nothing, stopped (SIGTERM) before its first sample."""
    from avard.daemon.hw.adxl355 import Drain

    svc = _service(data, seed)

    def nothing() -> Drain:
        return Drain(np.zeros((0, 3), np.int32), False, svc.clock.monotonic(),
                     svc.clock.realtime(), 0)

    svc.sensor.drain = nothing
    svc.run(None, before_acquisition=svc.stop_requested.set)
    return svc


class _Campaign:
    def __init__(self, data: Path, seed: int) -> None:
        self.data = data
        self.seed = seed
        self.res = RestartCampaign()

    def run(self, seconds: float, fault: str | None = None, **extra: Any) -> Any:
        self.seed += 1
        if fault:
            self.res.faults[fault] = self.res.faults.get(fault, 0) + 1
        svc = _service(self.data, self.seed, **extra)
        svc.run(seconds)
        self.res.runs += 1
        self.verify(fault or "run")
        return svc

    def silent(self) -> None:
        self.seed += 1
        self.res.faults["silent_sensor_stop"] = self.res.faults.get("silent_sensor_stop",
                                                                    0) + 1
        _silent_stop(self.data, self.seed)
        self.res.runs += 1
        self.verify("silent_sensor_stop")

    def verify(self, after: str) -> None:
        from avard.core.allan.streaming import StreamingAllan
        from avard.core.io import frames
        from avard.core.io.recording import RecordingReader, replay_allan, scan_frames
        from avard.daemon.service.checkpoint import STATE_FILE

        ckpt = frames.decode(next(scan_frames((self.data / STATE_FILE).read_bytes())).payload)
        mine = StreamingAllan.from_state(ckpt["state"]).snapshot()
        offline = replay_allan(self.data).snapshot()
        same_n = mine.n_samples == offline.n_samples
        a, b = np.asarray(mine.avar), np.asarray(offline.avar)
        same = same_n and a.shape == b.shape and bool(np.all(
            np.abs(a - b) <= 1e-12 * np.abs(b) + 0.0))
        self.res.check("accumulators = offline Allan of the recording", same,
                       f"after {after}: {mine.n_samples} vs {offline.n_samples} samples")
        recs = list(RecordingReader(self.data))
        gaps = sorted((r["i0"], r["n"]) for r in recs
                      if r["kind"] == "gap" and r["reason"] == "restart")
        tiled = all(a0 + n0 <= a1 for (a0, n0), (a1, _n1) in itertools.pairwise(gaps))
        self.res.check("restart gaps do not overlap", tiled, f"after {after}: {gaps}")
        bad = [r for r in recs if r["kind"] == "event" and r["name"] == "invariant_violated"]
        self.res.check("no invariant_violated event", not bad, f"after {after}: {bad[:1]}")
        self.res.recorded = sum(r["n"] for r in recs if r["kind"] == "raw")
        self.res.accumulators = int(mine.n_samples)
        self.res.restart_gaps = len(gaps)


def _damage_state(data: Path, how: str) -> None:
    from avard.daemon.service.checkpoint import STATE_FILE

    path = data / STATE_FILE
    if how == "deleted":
        path.unlink()
    elif how == "emptied":
        path.write_bytes(b"")
    else:
        raw = bytearray(path.read_bytes())
        raw[len(raw) // 2] ^= 0x10
        path.write_bytes(bytes(raw))


def run_restart_campaign(out: Path, *, seed: int = 1, cycles: int = 1) -> RestartCampaign:
    """``cycles`` rounds of every restart class on one recording in ``out``."""
    c = _Campaign(out / "restarts", seed)
    c.run(9.0)
    for _ in range(cycles):
        # early stops: --duration 0.05, a silent sensor stopped by SIGTERM
        c.run(0.05, "early_stop")
        c.silent()
        c.run(6.0)
        # restarts in quick succession
        for _k in range(3):
            c.run(0.05, "quick_restart")
        c.run(5.0)
        # the checkpoint file damaged, emptied, deleted
        for how in ("damaged", "emptied", "deleted"):
            _damage_state(c.data, how)
            c.res.faults[f"checkpoint_{how}"] = c.res.faults.get(f"checkpoint_{how}", 0) + 1
            c.run(5.0)
        _clock_step_with_retention(c)
    return c.res


def _clock_step_with_retention(c: _Campaign) -> None:
    """CLOCK_REALTIME stepped forward two days 12 s into a run with retention_days = 1 and a
    segment every 10 s (a Pi without an RTC corrected by NTP): no segment may go."""
    before = len(list(c.data.glob("*.avr")))
    stepped: list[float] = []
    holder: dict[str, Any] = {}

    def step(t: float) -> None:
        svc = holder.get("svc")
        if svc is not None and not stepped and t - svc.t_start > 12.0:
            svc.clock.step_realtime(2 * DAY_S)
            stepped.append(t)

    c.seed += 1
    svc = _service(c.data, c.seed, after_tick=step, **{
        "recording.retention_days": 1.0, "recording.segment_s": 10.0})
    holder["svc"] = svc
    svc.run(40.0)
    c.res.runs += 1
    c.res.faults["clock_step_retention"] = c.res.faults.get("clock_step_retention", 0) + 1
    deleted = list(svc.recorder.deleted) if svc.recorder is not None else []
    c.res.segments_deleted += len(deleted)
    after = len(list(c.data.glob("*.avr")))
    c.res.check("a wall-clock step deletes no segment",
                bool(stepped) and not deleted and after > before,
                f"stepped={stepped} deleted={deleted}")
    c.verify("clock_step_retention")


def format_campaign(res: RestartCampaign) -> str:
    lines = [f"restart classes: {res.runs} runs, faults "
             + ", ".join(f"{k} {v}" for k, v in sorted(res.faults.items())),
             f"  recorded {res.recorded} samples; final accumulators {res.accumulators}; "
             f"{res.restart_gaps} restart gaps; {res.segments_deleted} segments deleted"]
    lines += [f"[{'ok' if v else 'FAIL'}] {k}" for k, v in res.checks.items()]
    lines += [f"  {f}" for f in res.failures[:5]]
    return "\n".join(lines)

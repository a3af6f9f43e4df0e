"""Soak: the whole service for many simulated hours, faults on a schedule, a remote subscriber.

``python -m benchmarks soak [--hours 60] [--fault-every-h 2] [--out DIR] [--disk-full]``
``python -m benchmarks soak --campaign``: the classes of soak_service_faults.py instead.

The service (reader, ring, Allan accumulators, recorder, publisher, request socket) runs in
this process over the register-level emulator fed by the simulator (preset quiet-lab,
125 Hz), its virtual clock as fast as the CPU allows. A separate process, ``avard record``,
subscribes over loopback TCP and archives the stream: the remote subscriber. Faults are
injected on a schedule (bus EIO, EIO bursts, an unplugged sensor that comes back without
power, a stalled reader that overruns the FIFO, a DS18B20 drop-out, CLOCK_REALTIME steps,
optionally a full disk). At the end it prints:

- samples produced by the emulator, recorded, published, received by the subscriber, each as
  a ratio of the produced count, and the samples the gap records account for;
- gaps recorded vs faults injected, by kind;
- RSS of the service process after warm-up, peak and final (growth must stay under 5 MB), and
  CPU seconds per simulated hour against real time;
- the Allan deviation from the stream (the service's last published snapshot, as the
  subscriber received it), from the recording (offline replay) and from the subscriber's copy
  (offline replay), at a few τ, with the largest relative difference (equal: < 1e-9).

Then the restart classes (benchmarks/soak_restarts.py, ``--restart-cycles``): early stops,
restarts in quick succession, the checkpoint file damaged, emptied and deleted, and a
CLOCK_REALTIME step with retention, each checked against the recording.

Exit status 0 when every check holds. tests/daemon/test_soak_short.py runs 2 simulated hours.
"""

from __future__ import annotations

import argparse
import itertools
import logging
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

RATE = 125.0
MAX_RSS_GROWTH = 5 * 2**20
#: One fault per slot of the schedule, cycling through this list (name, loses samples?).
FAULTS = [("eio", False), ("eio_burst", True), ("unplug", True), ("stall", True),
          ("ds18b20", False), ("clock_step", False)]


def _rss_bytes() -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    return 0


def _cpu_s() -> float:
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime


@dataclass
class SoakResult:
    """Everything a soak measured; ``checks`` maps each promise to whether it held."""

    hours: float
    produced: int = 0
    #: sets the part's time line had due while it made none (a stall, standby after a power
    #: cycle): a gap is sized by time, so it accounts for them too (emulator.missed_total)
    missed: int = 0
    recorded: int = 0
    published: int = 0
    received: int = 0
    gap_samples_recorded: int = 0
    disk_full_gap_samples: int = 0
    gaps_recorded: dict[str, int] = field(default_factory=dict)
    gaps_received: dict[str, int] = field(default_factory=dict)
    events_recorded: dict[str, int] = field(default_factory=dict)
    faults: dict[str, int] = field(default_factory=dict)
    lossy_faults: int = 0
    rss_warm: int = 0
    rss_peak: int = 0
    rss_final: int = 0
    rss_trace: list[tuple[float, int]] = field(default_factory=list)
    cpu_s: float = 0.0
    wall_s: float = 0.0
    sim_s: float = 0.0
    adev: dict[str, np.ndarray] = field(default_factory=dict)
    tau: np.ndarray | None = None
    allan_rel_diff: dict[str, float] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)
    checks: dict[str, bool] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return all(self.checks.values())


class _Schedule:
    """Faults due at virtual times; run from the reader thread before each drain."""

    def __init__(self, every_s: float, end_s: float, disk: Any | None) -> None:
        self.actions: list[tuple[float, str, Any]] = []
        kinds = list(FAULTS) + ([("disk_full", True)] if disk is not None else [])
        t = every_s
        for name, _lossy in itertools.cycle(kinds):
            if t >= end_s - 60:
                break
            self.actions.append((t, name, None))
            t += every_s
        self.disk = disk
        self.injected: list[tuple[float, str]] = []
        self._pos = 0
        self._later: list[tuple[float, Any]] = []

    def run(self, ctx: dict[str, Any], t: float) -> None:
        while self._later and self._later[0][0] <= t:
            _, undo = self._later.pop(0)
            undo()
        while self._pos < len(self.actions) and self.actions[self._pos][0] <= t:
            _, name, _ = self.actions[self._pos]
            self._pos += 1
            self.injected.append((t, name))
            self._start(ctx, t, name)

    def _after(self, t: float, fn: Any) -> None:
        self._later.append((t, fn))
        self._later.sort(key=lambda x: x[0])

    def _start(self, ctx: dict[str, Any], t: float, name: str) -> None:
        emu, clock, sims = ctx["emu"], ctx["clock"], ctx["sims"]
        if name == "eio":
            emu.faults.fail_next(1)
        elif name == "eio_burst":
            emu.faults.fail_next(12)
        elif name == "unplug":
            emu.faults.unplug(0xFF)

            def back() -> None:
                emu.power_cycle()
                emu.faults.replug()
            self._after(t + 3.0, back)
        elif name == "stall":
            clock.advance(2.0)
        elif name == "ds18b20":
            sims.fail.add(sims.names[0])
            self._after(t + 30.0, sims.fail.clear)
        elif name == "clock_step":
            clock.step_realtime(-2.5 if len(self.injected) % 2 else 1.25)
        elif name == "disk_full":
            self.disk.full = True

            def space() -> None:
                self.disk.full = False
            self._after(t + 120.0, space)


def run_soak(hours: float, out: Path, *, fault_every_h: float = 2.0, disk_full: bool = False,
             seed: int = 1, log_level: int = logging.WARNING) -> SoakResult:
    """Run the soak for ``hours`` simulated hours with data under ``out``; return the result."""
    from avard.core.io.recording import RecordingReader, replay_allan
    from avard.daemon.compose import simulated_service
    from avard.daemon.config import load_config
    from avard.daemon.net.publisher import Publisher
    from avard.daemon.service.recorder import FileOps, Recorder
    from avard.daemon.service.supervisor import Service, ServiceHooks

    logging.getLogger("avard").setLevel(log_level)
    res = SoakResult(hours=hours)
    end_s = hours * 3600.0
    service_dir, archive_dir = out / "service", out / "subscriber"
    cfg = load_config(None, **{
        "recording.data_dir": str(service_dir),
        "publish.endpoint": "tcp://127.0.0.1:0", "publish.request_endpoint": "tcp://127.0.0.1:0",
        "publish.hwm": 1_000_000, "sensor.poll_hz": 12.0,
        "allan.snapshot_interval_s": 600.0, "allan.checkpoint_interval_s": 1800.0,
        "publish.status_interval_s": 60.0, "service.status_log_interval_s": 3600.0,
    })

    class Disk(FileOps):
        full = False

        def write(self, f: Any, data: bytes) -> None:
            if self.full:
                import errno
                raise OSError(errno.ENOSPC, "No space left on device (soak)")
            super().write(f, data)

        def free_bytes(self, directory: Path) -> int:
            return 0 if self.full else super().free_bytes(directory)

    disk = Disk() if disk_full else None
    schedule = _Schedule(fault_every_h * 3600.0, end_s, disk)
    published = [0]

    class CountingPublisher(Publisher):
        def publish(self, topic: str | None, record: Any) -> int:
            if record.get("kind") == "raw":
                published[0] += int(record["n"])
            return super().publish(topic, record)

    def publisher_factory(svc: Service) -> Publisher:
        p = svc.cfg["publish"]
        return CountingPublisher(p["endpoint"], svc.run_id, hwm=p["hwm"])

    def recorder_factory(svc: Service) -> Recorder:
        r = svc.cfg["recording"]
        return Recorder(svc.data_dir, svc.run_id, svc.header, segment_s=r["segment_s"],
                        fsync_interval_s=r["fsync_interval_s"], retry_s=5.0,
                        clock=svc.clock.monotonic, wall=svc.clock.monotonic,
                        realtime=svc.clock.realtime, fileops=disk or FileOps())

    svc, sims, emu = simulated_service(cfg, "quiet-lab", seed=seed, speed=None,
                                       hooks=ServiceHooks(publisher=publisher_factory,
                                                          recorder=recorder_factory))
    dev, clock = svc.sensor, svc.clock
    ctx = {"svc": svc, "emu": emu, "clock": clock, "sims": sims}
    drain = dev.drain

    def scheduled_drain(*args: Any, **kwargs: Any) -> Any:
        schedule.run(ctx, clock.monotonic() - svc.t_start)
        return drain(*args, **kwargs)

    dev.drain = scheduled_drain  # type: ignore[method-assign]

    box: dict[str, Any] = {}
    stop_monitor = threading.Event()

    def start_subscriber() -> None:
        # The remote subscriber: another process, over loopback TCP, archiving the stream.
        box["sub"] = subprocess.Popen(
            [sys.executable, "-m", "avard.daemon.cli", "record", svc.publisher.endpoint,
             "--request", svc.request_server.endpoint, "--out", str(archive_dir),
             "--wait", "600"],
            stdout=subprocess.DEVNULL, stderr=open(out / "subscriber.log", "w"))
        deadline = time.monotonic() + 60
        while svc.publisher.stats()["peers"] < 1 and time.monotonic() < deadline:
            time.sleep(0.02)
        time.sleep(1.0)  # its subscription reaches the PUB socket
        box["cpu0"], box["wall0"] = _cpu_s(), time.monotonic()
        box["monitor"].start()

    def monitor() -> None:
        while not stop_monitor.wait(0.25):
            res.rss_trace.append((clock.monotonic() - svc.t_start, _rss_bytes()))

    box["monitor"] = threading.Thread(target=monitor, daemon=True)
    svc.run(end_s, before_acquisition=start_subscriber)
    res.cpu_s = _cpu_s() - box["cpu0"]
    res.wall_s = time.monotonic() - box["wall0"]
    stop_monitor.set()
    box["monitor"].join(2)
    res.rss_final = _rss_bytes()
    res.sim_s = svc.final_status["sim_time_s"]
    sub = box["sub"]
    time.sleep(2.0)  # the last messages reach the subscriber
    sub.send_signal(signal.SIGTERM)
    try:
        sub.wait(timeout=60)
    except subprocess.TimeoutExpired:
        sub.kill()
        res.problems.append("the subscriber did not stop within 60 s of SIGTERM")

    # -- counts -------------------------------------------------------------------------------
    res.produced = int(emu.produced_total)
    res.missed = int(emu.missed_total)
    res.published = published[0]
    # (streamed, one record at a time: 60 hours of records do not fit in memory as a list)
    rec_reader = RecordingReader(service_dir)
    for r in rec_reader:
        if r["kind"] == "raw":
            res.recorded += r["n"]
        elif r["kind"] == "gap":
            res.gaps_recorded[r["reason"]] = res.gaps_recorded.get(r["reason"], 0) + 1
            res.gap_samples_recorded += r["n"]
            if r["reason"] == "disk_full":
                res.disk_full_gap_samples += r["n"]
        elif r["kind"] == "event":
            res.events_recorded[r["name"]] = res.events_recorded.get(r["name"], 0) + 1
    sub_reader = RecordingReader(archive_dir)
    stream = None
    for r in sub_reader:
        if r["kind"] == "raw":
            res.received += r["n"]
        elif r["kind"] == "gap":
            res.gaps_received[r["reason"]] = res.gaps_received.get(r["reason"], 0) + 1
        elif r["kind"] == "avar":
            stream = r
    for _, name in schedule.injected:
        res.faults[name] = res.faults.get(name, 0) + 1
    lossy = {n for n, lossy in [*FAULTS, ("disk_full", True)] if lossy}
    res.lossy_faults = sum(v for k, v in res.faults.items() if k in lossy)
    res.problems += [str(p) for p in rec_reader.problems + sub_reader.problems]

    # -- memory: flat after warm-up (the first tenth of the run, at least 5 % of samples) ----
    trace = res.rss_trace
    if trace:
        warm_t = 0.1 * end_s
        after = [rss for t, rss in trace if t >= warm_t] or [trace[-1][1]]
        res.rss_warm = after[0]
        res.rss_peak = max(rss for _, rss in trace)
        growth = max(after) - res.rss_warm
    else:
        growth = 0

    # -- Allan: stream vs recording vs the subscriber's copy --------------------------------
    if stream is None:
        raise RuntimeError(f"the subscriber archived no Allan snapshot; see {out}/subscriber.log")
    avar_stream = np.asarray(stream["snapshot"]["avar"], dtype=float)
    tau = np.asarray(stream["snapshot"]["tau"], dtype=float)
    avar_rec = replay_allan(service_dir).snapshot().avar
    avar_sub = replay_allan(archive_dir).snapshot().avar
    res.tau = tau
    for name, a in (("stream", avar_stream), ("recording", avar_rec), ("subscriber", avar_sub)):
        res.adev[name] = np.sqrt(a[:, 0])
    scale = np.where(avar_stream == 0, 1.0, np.abs(avar_stream))
    for name, a in (("recording", avar_rec), ("subscriber", avar_sub)):
        same = a.shape == avar_stream.shape
        res.allan_rel_diff[name] = (float(np.max(np.abs(a - avar_stream) / scale)) if same
                                    else float("inf"))

    # -- the promises -------------------------------------------------------------------------
    unaccounted = res.produced + res.missed - res.recorded - res.gap_samples_recorded
    res.checks = {
        "every published sample received": res.received == res.published,
        "lost samples (and the time line's sets the part did not make) accounted for by gap "
        "records (±1 per fault, FIFO at stop)":
            abs(unaccounted) <= 2 * len(schedule.injected) + 64,
        "a lossy fault never passes without a gap record":
            sum(v for k, v in res.gaps_recorded.items() if k != "restart")
            >= res.lossy_faults,
        "subscriber lost nothing in transport": "subscriber_loss" not in res.gaps_received,
        "segments read back without corrupt frames":
            all("truncated" in p for p in res.problems),
        "RSS growth after warm-up < 5 MB": growth < MAX_RSS_GROWTH,
        "Allan: subscriber's copy = stream (1e-9)": res.allan_rel_diff["subscriber"] < 1e-9,
        "clock steps recorded": res.events_recorded.get("clock_step", 0)
            == res.faults.get("clock_step", 0),
    }
    if disk is None:
        res.checks["every published sample recorded"] = res.recorded == res.published
        res.checks["Allan: recording = stream (1e-9)"] = res.allan_rel_diff["recording"] < 1e-9
    else:
        # The recording lacks exactly the disk-full interval, and says so; its Allan result
        # then differs from the stream's (fewer samples), which is why it is not compared.
        res.checks["samples missing from the recording = its disk_full gaps"] = (
            res.published - res.recorded == res.disk_full_gap_samples > 0)
    return res


def format_result(res: SoakResult) -> str:
    """The soak's table, in SI units."""
    mb = 2**20
    p = max(res.produced, 1)
    lines = [
        f"soak: {res.hours:g} simulated hours at {RATE:g} Hz (quiet-lab), "
        f"{res.sim_s / 3600:.2f} h run, wall {res.wall_s:.0f} s "
        f"({res.sim_s / max(res.wall_s, 1e-9):.0f}× real time)",
        "",
        f"{'samples':<34}{'count':>14}{'ratio to produced':>20}",
        f"{'produced by the emulator':<34}{res.produced:>14}{1.0:>20.6f}",
        f"{'recorded by the service':<34}{res.recorded:>14}{res.recorded / p:>20.6f}",
        f"{'published':<34}{res.published:>14}{res.published / p:>20.6f}",
        f"{'received by the subscriber':<34}{res.received:>14}{res.received / p:>20.6f}",
        f"{'due, not made (stalled, reset)':<34}{res.missed:>14}{res.missed / p:>20.6f}",
        f"{'in gap records (lost to faults)':<34}{res.gap_samples_recorded:>14}"
        f"{res.gap_samples_recorded / p:>20.6f}",
        "",
        f"faults injected: {sum(res.faults.values())} "
        + ", ".join(f"{k} {v}" for k, v in sorted(res.faults.items()))
        + f" ({res.lossy_faults} lose samples)",
        "gaps recorded:   " + (", ".join(f"{k} {v}" for k, v in sorted(res.gaps_recorded.items()))
                               or "none"),
        "gaps received:   " + (", ".join(f"{k} {v}" for k, v in sorted(res.gaps_received.items()))
                               or "none"),
        "events recorded: " + ", ".join(f"{k} {v}" for k, v in sorted(res.events_recorded.items())),
        "",
        f"{'service process':<34}{'value':>14}{'ratio':>20}",
        f"{'RSS after warm-up (MB)':<34}{res.rss_warm / mb:>14.1f}{1.0:>20.3f}",
        f"{'RSS peak (MB)':<34}{res.rss_peak / mb:>14.1f}"
        f"{res.rss_peak / max(res.rss_warm, 1):>20.3f}",
        f"{'RSS final (MB)':<34}{res.rss_final / mb:>14.1f}"
        f"{res.rss_final / max(res.rss_warm, 1):>20.3f}",
        f"{'CPU (s)':<34}{res.cpu_s:>14.1f}{res.cpu_s / max(res.wall_s, 1e-9):>20.3f}"
        "  (CPU s per wall s)",
        f"{'CPU per simulated hour (s)':<34}{res.cpu_s / max(res.sim_s / 3600, 1e-9):>14.2f}"
        f"{res.cpu_s / max(res.sim_s, 1e-9):>20.5f}  (CPU s per simulated s)",
        "",
        "Allan deviation of x (m/s²): stream (last published snapshot) vs recording vs "
        "subscriber's copy",
        f"{'tau (s)':>12}{'stream':>16}{'recording':>16}{'subscriber':>16}",
    ]
    if res.tau is not None:
        for k in range(0, len(res.tau), max(1, len(res.tau) // 8)):
            lines.append(f"{res.tau[k]:>12.4g}" + "".join(
                f"{res.adev[s][k]:>16.6e}" for s in ("stream", "recording", "subscriber")))
    lines.append("max relative AVAR difference to the stream: " + ", ".join(
        f"{k} {v:.2e}" for k, v in res.allan_rel_diff.items()))
    if res.problems:
        lines.append(f"reader problems ({len(res.problems)}): " + "; ".join(res.problems[:5]))
    lines.append("")
    lines += [f"[{'ok' if v else 'FAIL'}] {k}" for k, v in res.checks.items()]
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks soak", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=60.0, help="simulated hours (default 60)")
    ap.add_argument("--fault-every-h", type=float, default=2.0,
                    help="simulated hours between faults (default 2)")
    ap.add_argument("--disk-full", action="store_true",
                    help="also fill the disk for 120 s in the schedule (the recording then "
                         "lacks those samples and its Allan result differs from the stream)")
    ap.add_argument("--out", type=Path, default=None, help="keep the data here (default: a "
                    "temporary directory, removed at the end)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--restart-cycles", type=int, default=1,
                    help="rounds of the restart classes after the soak (early stops, quick "
                         "restarts, checkpoint damage, clock step with retention: "
                         "benchmarks/soak_restarts.py); 0 skips them")
    ap.add_argument("--campaign", action="store_true",
                    help="run the campaign classes against the process and the request side "
                         "instead (soak_service_faults.py: fd exhaustion, SIGHUP bursts, "
                         "request floods, stalled subscribers)")
    args = ap.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="avard-soak-"))
    out.mkdir(parents=True, exist_ok=True)
    if args.campaign:
        from benchmarks.soak_service_faults import run_campaign

        try:
            results = run_campaign(out)
            print("\n\n".join(r.format() for r in results))
        finally:
            if args.out is None:
                shutil.rmtree(out, ignore_errors=True)
        return 0 if all(r.ok for r in results) else 1
    try:
        res = run_soak(args.hours, out, fault_every_h=args.fault_every_h,
                       disk_full=args.disk_full, seed=args.seed)
        print(format_result(res))
        restarts_ok = True
        if args.restart_cycles > 0:
            from benchmarks.soak_restarts import format_campaign, run_restart_campaign

            camp = run_restart_campaign(out, seed=args.seed, cycles=args.restart_cycles)
            print(format_campaign(camp))
            restarts_ok = camp.ok
    finally:
        if args.out is None:
            shutil.rmtree(out, ignore_errors=True)
    return 0 if res.ok and restarts_ok else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

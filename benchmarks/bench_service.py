"""CPU cost of the whole service per simulated second, at 125 Hz and 4 kHz in real time.

``python -m benchmarks service [--seconds S] [--rates 125,4000] [--clients] [--watch]``

For each ODR the service runs on the emulated ADXL355 (preset quiet-lab) at ``--speed 1`` for
``--seconds`` (default 10; the report uses 60): reader thread draining at the default poll rate,
streaming Allan accumulators over 3 axes + 3 temperature channels, recording into a temporary
directory, publishing on loopback with a real subscriber counting every sample. Measured:

- CPU seconds of the service per simulated second: the process (all threads,
  ``time.process_time``) minus the bench's own subscriber thread (a client; shown apart);
- overruns (must be 0) and samples lost anywhere (subscriber index continuity);
- sample-to-subscriber latency p50/p99: from when a raw block's last sample was due (sample
  time mapped to wall time through the run's start) to when the subscriber decoded it.

- peak RSS (VmHWM) of `avard run` as its own process, twice: ``--simulate quiet-lab`` (the
  simulator needs scipy.signal, ~55 MB of it) and the hardware path, where the emulated
  ADXL355 is fed by a numpy counter instead of the simulator (what `avard run` loads on a Pi:
  no scipy, no matplotlib).

Reference, measured in the same run at the same rate and drain period: the drain loop alone
(driver over emulator over simulator, no ring consumers, no disk, no sockets). The ratio says
what the service adds on top of reading the (emulated) sensor; on a Pi the emulator and the
simulator are replaced by spidev, so the service's own share is the difference.
"""

from __future__ import annotations

import argparse
import logging
import os
import subprocess
import sys
import tempfile
import threading
import time
from typing import Any

import numpy as np
from avard.daemon.compose import simulated_service
from avard.daemon.config import effective_poll_hz, load_config
from avard.daemon.hw.simulation import build_simulated
from avard.daemon.hw.timebase import TimeBase
from avard.daemon.net.subscriber import Subscriber
from avard.daemon.service.acquisition import Acquisition
from avard.daemon.service.ring import Ring


def _cfg(odr: float, data_dir: str) -> dict:
    return load_config(None, **{
        "sensor.odr_hz": odr, "recording.data_dir": data_dir,
        "publish.endpoint": "tcp://127.0.0.1:0", "publish.request_endpoint": "tcp://127.0.0.1:0",
        "publish.hwm": 1_000_000, "service.status_log_interval_s": 3600.0})


def _thread_cpu_s(tid: int) -> float:
    """CPU seconds of one thread of this process: the scheduler's run time in ns from
    /proc (exact; the user + system ticks of /proc/…/stat are sampled every 10 ms and miss
    threads that run in short bursts)."""
    with open(f"/proc/self/task/{tid}/schedstat") as f:
        return int(f.read().split()[0]) * 1e-9


_CLIENT = r"""
import sys, time, zmq, msgpack
endpoint, mode, seconds = sys.argv[1], sys.argv[2], float(sys.argv[3])
ctx = zmq.Context()
s = ctx.socket(zmq.DEALER); s.setsockopt(zmq.LINGER, 0); s.connect(endpoint)
reqs = [msgpack.packb({"op": op, "args": a, "id": i}) for i, (op, a) in enumerate(
    [("status", {}), ("snapshot", {}), ("recent", {"seconds": 1.0}), ("nosuch", {})])]
reqs.append(b"\xc1garbage")
end, n = time.monotonic() + seconds, 0
big = msgpack.packb({"op": "recent", "args": {"seconds": 5.0}, "id": 1})
if mode == "noread":   # asks for the biggest replies and never reads one
    s.setsockopt(zmq.RCVHWM, 1); s.setsockopt(zmq.RCVBUF, 4096)
if mode == "poll":     # a client polling the snapshot (and its fit) every 5 s
    snap = msgpack.packb({"op": "snapshot", "args": {}, "id": 1})
    while time.monotonic() < end:
        s.send_multipart([b"", snap]); n += 1
        if s.poll(10000):
            s.recv_multipart()
        time.sleep(min(5.0, max(0.0, end - time.monotonic())))
    print(n / seconds); sys.exit(0)
while time.monotonic() < end:
    try:               # as fast as the socket takes them (never blocks past the end)
        s.send_multipart([b"", big if mode == "noread" else reqs[n % len(reqs)]], zmq.NOBLOCK)
        n += 1
    except zmq.Again:
        time.sleep(0.001)
    while mode != "noread" and s.poll(0):
        s.recv_multipart()
print(n / seconds)
"""


def _tids() -> set[int]:
    return {int(t) for t in os.listdir("/proc/self/task")}


def _threads_cpu_s(exclude: set[int]) -> dict[str, float]:
    """CPU seconds of the live threads of this process but ``exclude``, by Python thread
    name (threads Python did not start, libzmq's I/O threads, as "libzmq")."""
    names = {t.native_id: t.name for t in threading.enumerate()}
    out: dict[str, float] = {}
    for tid in _tids() - exclude:
        try:
            cpu = _thread_cpu_s(tid)
        except FileNotFoundError:   # ended meanwhile
            continue
        name = names.get(tid, "libzmq").removeprefix("avard-")
        out[name] = out.get(name, 0.0) + cpu
    return out


def _cpu_of(tids: set[int]) -> float:
    total = 0.0
    for tid in tids:
        try:
            total += _thread_cpu_s(tid)
        except FileNotFoundError:
            pass
    return total


def _vm_rss_mb() -> float:
    return int(open("/proc/self/status").read().split("VmRSS:")[1].split()[0]) / 1024


def _service_run(odr: float, seconds: float, client: str | None = None) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="avard-bench-") as d:
        cfg = _cfg(odr, d)
        svc, _sims, _emu = simulated_service(cfg, "quiet-lab", seed=1, speed=1.0)
        clock = svc.clock
        lat: list[float] = []
        got = {"samples": 0, "next": None, "ok": True}
        stop = threading.Event()
        origin: dict[str, float] = {}

        def listen(sub: Subscriber) -> None:
            while not stop.is_set() or sub._sub.poll(200):
                msg = sub.recv(timeout_s=0.2)
                if msg is None or msg.topic != "raw":
                    continue
                now = time.monotonic()
                r = msg.record
                if got["next"] is not None and r["i0"] != got["next"]:
                    got["ok"] = False
                got["next"] = r["i0"] + r["n"]
                got["samples"] += r["n"]
                t_last = r["t_mono"] + (r["n"] - 1) / r.get("rate_hz", odr)
                lat.append(now - (origin["wall"] + (t_last - origin["virt"])))

        rss = {"max": 0.0}

        def watch_rss() -> None:
            while not stop.is_set():
                rss["max"] = max(rss["max"], _vm_rss_mb())
                stop.wait(0.25)

        def per_thread() -> None:   # just before the service stops its threads
            stop.wait(seconds / 2)
            # the second half alone: steady state, after one-time costs (imports, the first
            # fit's filter terms)
            origin["cpu_half"] = time.process_time()
            origin["sub_cpu_half"] = _cpu_of(origin["bench_tids"])  # type: ignore[arg-type]
            origin["wall_half"] = time.monotonic()
            stop.wait(seconds / 2 - 0.5)
            # ends here, before the stop (the last snapshot and checkpoint, the joins)
            sub_half = _cpu_of(origin["bench_tids"]) - origin["sub_cpu_half"]  # type: ignore[arg-type]
            origin["steady"] = ((time.process_time() - origin["cpu_half"] - sub_half)
                                / (time.monotonic() - origin["wall_half"]))
            after = _threads_cpu_s(origin["bench_tids"])  # type: ignore[arg-type]
            t0: dict[str, float] = origin["threads"]  # type: ignore[assignment]
            wall = time.monotonic() - origin["wall"]
            origin["per_thread"] = {  # type: ignore[assignment]
                k: (v - t0.get(k, 0.0)) / wall for k, v in after.items()}

        def before() -> None:
            # Everything the bench starts (the subscriber, its libzmq threads, its helper
            # threads) is a client or a probe, not the service: their CPU is taken out.
            tids0 = _tids()
            sub = Subscriber(svc.publisher.endpoint).connect(join=False)
            th = threading.Thread(target=listen, args=(sub,), daemon=True)
            th.start()
            threading.Thread(target=watch_rss, daemon=True).start()
            threading.Thread(target=per_thread, daemon=True).start()
            origin["bench_tids"] = _tids() - tids0  # type: ignore[assignment]
            origin["th"] = th  # type: ignore[assignment]
            origin["sub"] = sub  # type: ignore[assignment]
            deadline = time.monotonic() + 5
            while svc.publisher.stats()["peers"] < 1 and time.monotonic() < deadline:
                time.sleep(0.01)
            time.sleep(0.2)
            origin["wall"] = time.monotonic()
            origin["virt"] = clock.monotonic()
            origin["cpu"] = time.process_time()
            origin["sub_cpu"] = _cpu_of(origin["bench_tids"])  # type: ignore[arg-type]
            origin["threads"] = _threads_cpu_s(origin["bench_tids"])  # type: ignore[arg-type,assignment]
            origin["rss0"] = _vm_rss_mb()
            if client == "avard-watch":   # the real `avard watch`, in its own process
                origin["client"] = subprocess.Popen(  # type: ignore[assignment]
                    _avard_watch_args(svc.publisher.endpoint, svc.request_server.endpoint),
                    stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
            elif client is not None:   # a hostile request client, in its own process
                origin["client"] = subprocess.Popen(  # type: ignore[assignment]
                    [sys.executable, "-c", _CLIENT, svc.request_server.endpoint, client,
                     str(seconds)], stdout=subprocess.PIPE, text=True)

        svc.run(seconds, before_acquisition=before)
        drain_max = svc.acq.max_drain_interval_s if svc.acq else float("nan")
        req_rate = float("nan")
        if client == "avard-watch":
            proc = origin["client"]
            proc.terminate()  # type: ignore[attr-defined]
            _out, err = proc.communicate(timeout=60)  # type: ignore[attr-defined]
            if "Traceback" in (err or ""):
                raise RuntimeError(f"avard watch failed: {err[-2000:]}")
        elif client is not None:
            out, _ = origin["client"].communicate(timeout=60)  # type: ignore[attr-defined]
            req_rate = float(out.split()[-1])
        # The bench's subscriber is a client, not the service: its threads' CPU is taken out.
        sub_cpu = _cpu_of(origin["bench_tids"]) - origin["sub_cpu"]  # type: ignore[arg-type]
        cpu = time.process_time() - origin["cpu"] - sub_cpu
        wall = time.monotonic() - origin["wall"]
        steady = origin.get("steady", float("nan"))
        stop.set()
        origin["th"].join(5)  # type: ignore[attr-defined]
        origin["sub"].close()  # type: ignore[attr-defined]
        st = svc.final_status
        lat_ms = np.array(lat) * 1e3 if lat else np.array([np.nan])
        return {"drain_max_s": drain_max, "rss_growth": rss["max"] - origin["rss0"],
                "req_rate": req_rate, "answered": svc.request_server.answered
                if svc.request_server else 0,
                "cpu": cpu, "sub_cpu": sub_cpu, "wall": wall, "sim": st["sim_time_s"],
                "steady_cpu_per_s": steady, "rss_max": rss["max"],
                "samples": st["samples"],
                "overruns": st["overruns"], "received": got["samples"], "continuous": got["ok"],
                "p50": float(np.percentile(lat_ms, 50)), "p99": float(np.percentile(lat_ms, 99)),
                "poll": effective_poll_hz(cfg),
                "threads": origin.get("per_thread", {})}


def _avard_watch_args(endpoint: str, request_endpoint: str) -> list[str]:
    """`avard watch` as a user runs it (every topic, one snapshot request at join, its
    own fits), redrawing every 2 s into a pipe."""
    return [sys.executable, "-c", "import sys; from avard.daemon.cli import main; "
            "sys.exit(main())", "watch", endpoint, "--request", request_endpoint,
            "--interval", "2"]


def _drain_only(odr: float, seconds: float) -> dict[str, Any]:
    """Reference: the reader's drain loop over the emulator alone, same poll period."""
    cfg = _cfg(odr, tempfile.gettempdir())
    dev, clock, _sims, _emu = build_simulated(cfg, "quiet-lab", seed=1)
    acq = Acquisition(dev, Ring(int(odr * 30)), TimeBase(odr), clock,
                      poll_hz=float(cfg["sensor"]["poll_hz"]), speed=1.0)
    cpu0 = time.process_time()
    t0 = clock.monotonic()
    acq.start()
    time.sleep(seconds)
    acq.stop()
    return {"cpu": time.process_time() - cpu0, "sim": clock.monotonic() - t0,
            "overruns": acq.overruns, "samples": acq.samples}


_RSS_HARDWARE_PATH = r"""
import sys
from avard.daemon import blas_threads
from avard.daemon.hw.adxl355 import Adxl355
from avard.daemon.config import load_config
from avard.daemon.config_types import as_config
from avard.daemon.hw.emulator import EmulatedAdxl355, FakeSpiDev, VirtualClock, counter_source
from avard.daemon.compose import compose
from avard.daemon.hw.rig import ClockSpec, Rig, RigSpec, SensorSpec
from avard.daemon.hw.transport import SpiBus
odr, seconds, data_dir = float(sys.argv[1]), float(sys.argv[2]), sys.argv[3]
watch = sys.argv[4:]   # a command (with {pub} and {req}) started once the sockets are bound
clock = VirtualClock(speed=1.0)
dev = Adxl355(SpiBus(FakeSpiDev(EmulatedAdxl355(counter_source(), clock))), clock=clock)
dev.probe(); dev.reset(); dev.configure(range_g=2, odr_hz=odr); dev.start()
cfg = load_config(None, **{"sensor.odr_hz": odr, "recording.data_dir": data_dir,
    "publish.endpoint": "tcp://127.0.0.1:0", "publish.request_endpoint": "tcp://127.0.0.1:0"})
config = as_config(cfg)
spec = RigSpec((SensorSpec.from_config(config.sensor),), ClockSpec(speed=1.0))
svc = compose(config, Rig(spec, dev, clock, {}))
procs = []
def client():
    import subprocess, time
    args = [a.format(pub=svc.publisher.endpoint, req=svc.request_server.endpoint) for a in watch]
    procs.append(subprocess.Popen(args, stdout=subprocess.DEVNULL))
    time.sleep(1.0)    # connected before the first drain
svc.run(seconds, before_acquisition=client if watch else None)
for p in procs:
    p.terminate(); p.wait(30)
heavy = sorted({m.split(".")[0] for m in sys.modules} & {"scipy", "matplotlib"})
print(open("/proc/self/status").read().split("VmHWM:")[1].split()[0], ",".join(heavy) or "-")
"""


def _rss_mb(odr: float, seconds: float, simulate: bool,
            watch: bool = False) -> tuple[float, str]:
    """Peak RSS (MB) of the service as its own process, and the heavy modules it loaded;
    ``watch``: with a real `avard watch` attached (hardware path only)."""
    with tempfile.TemporaryDirectory(prefix="avard-bench-rss-") as d:
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        if simulate:
            cfg = os.path.join(d, "avard.toml")
            with open(cfg, "w") as f:
                f.write(f"[sensor]\nodr_hz = {odr}\n[publish]\nendpoint = 'tcp://127.0.0.1:0'"
                        "\nrequest_endpoint = 'tcp://127.0.0.1:0'\n")
            code = ("import sys, runpy\nsys.argv = ['avard'] + sys.argv[1:]\n"
                    "from avard.daemon.cli import main\nrc = main()\n"
                    "heavy = sorted({m.split('.')[0] for m in sys.modules} & "
                    "{'scipy', 'matplotlib'})\n"
                    "print(open('/proc/self/status').read().split('VmHWM:')[1].split()[0], "
                    "','.join(heavy) or '-')")
            args = [sys.executable, "-c", code, "run", "--config", cfg, "--simulate",
                    "quiet-lab", "--duration", str(seconds), "--data-dir", d]
        else:
            args = [sys.executable, "-c", _RSS_HARDWARE_PATH, str(odr), str(seconds), d]
            if watch:
                args += _avard_watch_args("{pub}", "{req}")
        out = subprocess.run(args, capture_output=True, text=True, env=env, timeout=600)
        if out.returncode != 0:
            raise RuntimeError(out.stderr[-2000:])
        kb, heavy = out.stdout.split()[-2:]
        return int(kb) / 1024, heavy


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks service", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seconds", type=float, default=10.0, help="real seconds per rate")
    p.add_argument("--rates", default="125,4000", help="ODRs in Hz, comma separated")
    p.add_argument("--clients", action="store_true",
                   help="also run each rate under a request flood and a never-reading client")
    p.add_argument("--watch", action="store_true",
                   help="only: the service at 125 Hz with no client, with the real "
                        "`avard watch` attached, and with a client polling `snapshot` every "
                        "5 s, against the drain loop alone; steady-state CPU (second half), "
                        "CPU per thread, and RSS of `avard run` with `avard watch`")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    if args.watch:
        return _watch_table(args.seconds)
    rows = []
    for odr in (float(r) for r in args.rates.split(",")):
        ref = _drain_only(odr, args.seconds)
        res = _service_run(odr, args.seconds)
        res["rss_sim"], res["heavy_sim"] = _rss_mb(odr, min(args.seconds, 10.0), True)
        res["rss_hw"], res["heavy_hw"] = _rss_mb(odr, min(args.seconds, 10.0), False)
        rows.append((odr, res, ref))
    print(f"service at --speed 1 for {args.seconds:g} s per rate (emulated ADXL355, quiet-lab); "
          "CPU = CPU s of the service (all its threads, emulator and simulator included) per "
          "simulated s; sub = the bench's subscriber (its threads and libzmq's), taken out")
    hdr = (f"{'ODR Hz':>7} {'drain Hz':>8} {'sim s':>6} {'samples':>8} {'overruns':>8} "
           f"{'recv ok':>7} {'CPU/sim s':>9} {'sub':>6} {'ref CPU/s':>9} {'ratio':>6} "
           f"{'lat p50 ms':>10} {'p99 ms':>7} {'RSS sim MB':>10} {'RSS hw MB':>9}")
    print(hdr)
    print("-" * len(hdr))
    for odr, r, ref in rows:
        cps = r["cpu"] / r["sim"]
        ref_cps = ref["cpu"] / ref["sim"]
        ok = "yes" if r["continuous"] and r["received"] == r["samples"] else "NO"
        print(f"{odr:7g} {r['poll']:8.1f} {r['sim']:6.1f} {r['samples']:8d} {r['overruns']:8d} "
              f"{ok:>7} {cps:9.3f} {r['sub_cpu'] / r['sim']:6.3f} {ref_cps:9.3f} "
              f"{cps / ref_cps:6.2f} {r['p50']:10.1f} "
              f"{r['p99']:7.1f} {r['rss_sim']:10.1f} {r['rss_hw']:9.1f}")
    print("ref = drain loop alone (driver + emulator + simulator) at the same drain period; "
          "ratio = service / ref")
    for odr, r, _ref in rows:
        parts = sorted(r["threads"].items(), key=lambda kv: -kv[1])
        print(f"{odr:g} Hz CPU-s/s by thread (MainThread = supervisor): "
              + ", ".join(f"{k} {v:.4f}" for k, v in parts))
    print("RSS = peak resident memory of `avard run` as its own process: sim = --simulate "
          f"(loads {rows[0][1]['heavy_sim']}), hw = the hardware path, emulator fed by a "
          f"counter (loads {rows[0][1]['heavy_hw']} of scipy/matplotlib)")
    if args.clients:
        _client_table(rows, args.seconds)
    bad = any(r["overruns"] for odr, r, _ in rows if odr >= 4000)
    return 1 if bad else 0


def _client_table(rows: list[tuple[float, dict[str, Any], dict[str, Any]]],
                  seconds: float) -> None:
    """The same service with a hostile request client in another process: a flood of
    requests (status, snapshot, recent, unknown op, garbage) read as fast as it can, and a
    client asking for the largest `recent` replies and never reading one."""
    print()
    print("request clients (another process) against the same service; FIFO time = 32/ODR")
    hdr = (f"{'ODR Hz':>7} {'client':>8} {'req/s sent':>10} {'answered':>8} {'overruns':>8} "
           f"{'max drain gap / FIFO time':>25} {'CPU/sim s':>9} {'RSS growth MB':>13}")
    print(hdr)
    print("-" * len(hdr))
    for odr, quiet, _ref in rows:
        for client in (None, "flood", "noread"):
            r = quiet if client is None else _service_run(odr, seconds, client)
            fifo_s = 32.0 / odr
            print(f"{odr:7g} {client or 'none':>8} {r['req_rate']:10.0f} {r['answered']:8d} "
                  f"{r['overruns']:8d} {r['drain_max_s'] / fifo_s:25.2f} "
                  f"{r['cpu'] / r['sim']:9.3f} {r['rss_growth']:13.1f}")


def _watch_table(seconds: float) -> int:
    """The cost of one watching client at 125 Hz: the real `avard watch` in its own process
    (it subscribes to every topic, asks one snapshot at join and fits the streamed ones
    itself), and a client polling `snapshot` every 5 s (the service fits for it), against
    the service with no client and the drain loop alone (the emulated sensor: on a Pi spidev
    replaces it), all in the same run."""
    per_fit = _fit_cost_per_snapshot()
    print("one snapshot's fit (3 axes) at a fitted rate that moves by 3 ppm from one snapshot "
          "to the next, CPU-s: " + ", ".join(f"{c:.3f}" for c in per_fit)
          + " (the first computes the filter terms of this corner)")
    ref = _drain_only(125.0, seconds)
    ref_cps = ref["cpu"] / ref["sim"]
    rows = [(name, _service_run(125.0, seconds, client)) for name, client in
            (("none", None), ("avard watch", "avard-watch"), ("poll 5 s", "poll"))]
    rss_s = min(seconds, 30.0)
    rss_hw, _heavy = _rss_mb(125.0, rss_s, False)
    rss_watch, _heavy = _rss_mb(125.0, rss_s, False, watch=True)
    print(f"service at 125 Hz, --speed 1, {seconds:g} s per row, quiet-lab; CPU-s of the "
          "service process (every thread, the emulated sensor's included; the bench's own "
          "subscriber taken out) per s; steady = over the second half (after the first "
          f"fit); ref = the drain loop alone (emulator + simulator + driver), "
          f"{ref_cps:.4f} CPU-s/s in the same run; machine shared and loaded")
    hdr = (f"{'client':>12} {'CPU/sim s':>9} {'steady CPU/s':>12} {'steady - ref':>12} "
           f"{'fit thread CPU/s':>16} {'RSS max MB (in-process)':>23}")
    print(hdr)
    print("-" * len(hdr))
    for name, r in rows:
        fit = r["threads"].get("fit", 0.0)
        print(f"{name:>12} {r['cpu'] / r['sim']:9.4f} {r['steady_cpu_per_s']:12.4f} "
              f"{r['steady_cpu_per_s'] - ref_cps:12.4f} {fit:16.4f} {r['rss_max']:23.1f}")
    for name, r in rows:
        parts = sorted(r["threads"].items(), key=lambda kv: -kv[1])
        print(f"{name}: CPU-s/s by thread (MainThread = supervisor): "
              + ", ".join(f"{k} {v:.4f}" for k, v in parts))
    print(f"peak RSS of `avard run` on the hardware path (own process, {rss_s:g} s): "
          f"{rss_hw:.1f} MB with no client, {rss_watch:.1f} MB with `avard watch` attached")
    return 0


def _fit_cost_per_snapshot(n: int = 5) -> list[float]:
    """CPU-s of :func:`fit_snapshot` for ``n`` snapshots of one 10-minute white + random-walk
    record whose fitted rate moves by 3 ppm each time (what a running service's does)."""
    from avard.core.allan.streaming import AllanSnapshot, StreamingAllan
    from avard.daemon.service.snapshots import fit_snapshot

    rng = np.random.default_rng(1)
    a = StreamingAllan(3, 125.0, names=["x", "y", "z"])
    x = rng.standard_normal((125 * 600, 3)) * 1e-3
    a.update(x + np.cumsum(rng.standard_normal((125 * 600, 3)), axis=0) * 1e-7)
    snap = a.snapshot().to_dict()
    out = []
    for k in range(n):
        t0 = time.process_time()
        fit_snapshot(AllanSnapshot.from_dict(dict(snap, rate_hz=125.0 * (1 + 3e-6 * k))))
        out.append(time.process_time() - t0)
    return out

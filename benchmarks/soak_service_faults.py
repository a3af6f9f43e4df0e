"""The soak's campaign classes against the request side and the process (issue 26): each runs
``avard run --simulate quiet-lab`` as its own process, attacks it, and reports RSS and open
fds over time and whether the recording, the checkpoints and a well-behaved client kept going.

- :func:`fd_exhaustion`: 1 010 idle TCP connections to each socket (the campaign filled the
  default fd table of 1 024 with them and checkpoints and rotation stopped);
- :func:`sighup_burst`: two processes sending SIGHUP as fast as they can for a few seconds,
  then SIGTERM (a crash or a deadlock before);
- :func:`request_flood`: 600 connections sending 1 MB requests (RSS went to 1 GB before);
- :func:`stalled_subscribers`: 50 subscribers that never read at a fast simulated pace.

Run by ``python -m benchmarks soak --campaign``. Each returns a :class:`CampaignResult`.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

CONFIG = """
[allan]
snapshot_interval_s = 2.0
checkpoint_interval_s = 3.0
[recording]
segment_s = 10.0
[publish]
endpoint = "tcp://127.0.0.1:{pub}"
request_endpoint = "tcp://127.0.0.1:{req}"
[sensor]
poll_hz = 4.0
"""


@dataclass
class CampaignResult:
    name: str
    faults: str
    samples: list[tuple[float, float, int]] = field(default_factory=list)  # (s, RSS MB, fds)
    checks: dict[str, bool] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return all(self.checks.values())

    def format(self) -> str:
        lines = [f"== {self.name}: {self.faults}"]
        if self.samples:
            rss = [s[1] for s in self.samples]
            fds = [s[2] for s in self.samples]
            lines.append("   t (s)  RSS (MB)  fds")
            step = max(1, len(self.samples) // 8)
            lines += [f"   {t:5.1f}  {r:8.1f}  {f:4d}" for t, r, f in self.samples[::step]]
            lines.append(f"   RSS max {max(rss):.1f} MB, fds max {max(fds)}")
        lines += [f"   {n}" for n in self.notes]
        lines += [f"   [{'ok' if v else 'FAIL'}] {k}" for k, v in self.checks.items()]
        return "\n".join(lines)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _proc_rss_mb(pid: int) -> float:
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return float("nan")


def _proc_fds(pid: int) -> int:
    try:
        return len(os.listdir(f"/proc/{pid}/fd"))
    except OSError:
        return -1


class Service:
    """`avard run --simulate quiet-lab` in its own process, on two free loopback ports."""

    def __init__(self, tmp: Path, speed: float = 5.0) -> None:
        self.pub, self.req = _free_port(), _free_port()
        cfg = tmp / "avard.toml"
        cfg.write_text(CONFIG.format(pub=self.pub, req=self.req))
        self.data = tmp / "rec"
        self.log = tmp / "service.log"
        with open(self.log, "w") as err:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "avard.daemon.cli", "-v", "run", "--config", str(cfg),
                 "--simulate", "quiet-lab", "--speed", str(speed), "--seed", "1",
                 "--data-dir", str(self.data)],
                stdout=subprocess.DEVNULL, stderr=err,
                env=dict(os.environ, PYTHONUNBUFFERED="1"))
        self.t0 = time.monotonic()
        self.samples: list[tuple[float, float, int]] = []

    def wait_ready(self, timeout: float = 60.0) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and self.proc.poll() is None:
            if "samples flow; ready" in self.log.read_text():
                return True
            time.sleep(0.1)
        return False

    def sample(self) -> None:
        self.samples.append((time.monotonic() - self.t0, _proc_rss_mb(self.proc.pid),
                             _proc_fds(self.proc.pid)))

    def watch(self, seconds: float, every: float = 0.5) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end and self.proc.poll() is None:
            self.sample()
            time.sleep(every)

    def stop(self, timeout: float = 30.0) -> int | None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            return self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
            return None

    def segments(self) -> list[Path]:
        return sorted(self.data.glob("*.avr")) if self.data.exists() else []

    def checkpoint_mtime(self) -> float:
        p = self.data / "allan-state.ckpt"
        return p.stat().st_mtime if p.exists() else 0.0

    def ask_status(self, timeout_s: float = 10.0) -> bool:
        """A well-behaved client still gets a `status` reply."""
        import zmq
        from avard.core.io import frames

        ctx = zmq.Context()
        s = ctx.socket(zmq.DEALER)
        s.setsockopt(zmq.LINGER, 0)
        try:
            s.connect(f"tcp://127.0.0.1:{self.req}")
            for k in range(int(timeout_s / 0.5)):
                s.send(frames.encode_request("status", {}, id=k))
                if s.poll(500):
                    rep = frames.unpack_bounded(s.recv(), max_bytes=1 << 22, what="reply")
                    if rep.get("error") is None:
                        return True
            return False
        finally:
            s.close()
            ctx.term()


_HOLDER = r"""
import resource, socket, sys, time
port, n, secs = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
resource.setrlimit(resource.RLIMIT_NOFILE, (min(hard, 4 * n + 64), hard))
held = []
for _ in range(n):
    try:
        held.append(socket.create_connection(("127.0.0.1", port), timeout=2))
    except OSError:
        pass
print(len(held), flush=True)
time.sleep(secs)
"""


def _campaign(res: CampaignResult, tmp: Path, attack: Callable[[Service], None], *,
              speed: float = 5.0) -> CampaignResult:
    """Start the service, let it settle, ``attack`` it (which adds its checks), stop it with
    SIGTERM: it must exit 0."""
    svc = Service(tmp, speed=speed)
    rc: int | None = None
    try:
        if not svc.wait_ready():
            res.checks["service became ready"] = False
            return res
        svc.watch(2.0)
        attack(svc)
    finally:
        rc = svc.stop()
        res.samples = svc.samples
    res.checks["stopped cleanly on SIGTERM (0)"] = rc == 0
    return res


def fd_exhaustion(tmp: Path, n: int = 1010, hold_s: float = 20.0) -> CampaignResult:
    res = CampaignResult("fd exhaustion", f"{n} idle TCP connections to each socket")

    def attack(svc: Service) -> None:
        segs0, ck0 = len(svc.segments()), svc.checkpoint_mtime()
        holders = [subprocess.Popen([sys.executable, "-c", _HOLDER, str(port), str(n),
                                     str(hold_s)], stdout=subprocess.PIPE, text=True)
                   for port in (svc.req, svc.pub)]
        svc.watch(hold_s * 0.8)
        res.checks["a client still gets a status reply"] = svc.ask_status()
        for h in holders:
            out, _ = h.communicate(timeout=hold_s + 60)
            res.notes.append(f"holder connected {out.strip()} of {n}")
        svc.watch(1.0)
        res.checks["segments kept rotating"] = len(svc.segments()) > segs0
        res.checks["checkpoints kept being written"] = svc.checkpoint_mtime() > ck0
        res.checks["fds stayed bounded (< 700)"] = max(s[2] for s in svc.samples) < 700

    return _campaign(res, tmp, attack)


_HUPPER = ("import os, signal, sys, time\n"
           "pid, end = int(sys.argv[1]), time.monotonic() + float(sys.argv[2])\n"
           "while time.monotonic() < end:\n"
           "    for _ in range(200):\n"
           "        os.kill(pid, signal.SIGHUP)\n")


def sighup_burst(tmp: Path, seconds: float = 5.0) -> CampaignResult:
    res = CampaignResult("SIGHUP burst", f"2 senders, SIGHUP as fast as kill(2) for {seconds} s")

    def attack(svc: Service) -> None:
        senders = [subprocess.Popen([sys.executable, "-c", _HUPPER, str(svc.proc.pid),
                                     str(seconds)]) for _ in range(2)]
        svc.watch(seconds)
        for s in senders:
            s.wait(60)
        svc.watch(2.0)
        res.checks["alive after the burst"] = svc.proc.poll() is None
        res.checks["a client still gets a status reply"] = svc.ask_status()

    _campaign(res, tmp, attack)
    text = (tmp / "service.log").read_text()
    res.checks["no traceback"] = "Traceback" not in text
    res.notes.append(f"reloads logged: {text.count('SIGHUP: reopening')}")
    return res


_FLOODER = r"""
import resource, sys, time, zmq
port, n, size, secs = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
resource.setrlimit(resource.RLIMIT_NOFILE, (min(hard, 4 * n + 256), hard))
ctx = zmq.Context(io_threads=2)
ctx.setsockopt(zmq.MAX_SOCKETS, n + 64)
socks = []
blob = b"\x81\xa2op\xc4" + b"\x00" * size
for _ in range(n):
    s = ctx.socket(zmq.DEALER)
    s.setsockopt(zmq.LINGER, 0)
    s.setsockopt(zmq.SNDHWM, 4)
    s.connect("tcp://127.0.0.1:%d" % port)
    socks.append(s)
end = time.monotonic() + secs
sent = 0
while time.monotonic() < end:
    for s in socks:
        try:
            s.send(blob, zmq.NOBLOCK)
            sent += 1
        except zmq.Again:
            pass
    time.sleep(0.05)
print(sent, flush=True)
"""


def request_flood(tmp: Path, n: int = 600, size: int = 1 << 20,
                  seconds: float = 20.0) -> CampaignResult:
    res = CampaignResult("request flood", f"{n} connections sending {size >> 20} MB requests "
                         f"for {seconds:g} s")

    def attack(svc: Service) -> None:
        rss0 = svc.samples[-1][1]
        fl = subprocess.Popen([sys.executable, "-c", _FLOODER, str(svc.req), str(n), str(size),
                               str(seconds)], stdout=subprocess.PIPE, text=True)
        svc.watch(seconds * 0.8)
        res.checks["a client still gets a status reply"] = svc.ask_status()
        out, _ = fl.communicate(timeout=seconds + 60)
        res.notes.append(f"requests sent: {out.strip()}")
        peak = max(s[1] for s in svc.samples)
        res.notes.append(f"RSS before {rss0:.1f} MB, peak {peak:.1f} MB")
        res.checks["RSS grew by < 150 MB"] = peak - rss0 < 150

    return _campaign(res, tmp, attack)


_STALLED = r"""
import sys, time, zmq
port, n, secs = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
ctx = zmq.Context()
subs = []
for _ in range(n):
    s = ctx.socket(zmq.SUB)
    s.setsockopt(zmq.LINGER, 0)
    s.setsockopt(zmq.RCVHWM, 1)
    s.setsockopt(zmq.RCVBUF, 4096)
    s.setsockopt(zmq.SUBSCRIBE, b"")
    s.connect("tcp://127.0.0.1:%d" % port)
    subs.append(s)
time.sleep(secs)      # never reads
"""


def stalled_subscribers(tmp: Path, n: int = 50, seconds: float = 30.0) -> CampaignResult:
    res = CampaignResult("stalled subscribers", f"{n} subscribers that never read, {seconds:g} s"
                         " at --speed 20")

    def attack(svc: Service) -> None:
        rss0 = svc.samples[-1][1]
        st = subprocess.Popen([sys.executable, "-c", _STALLED, str(svc.pub), str(n),
                               str(seconds)])
        svc.watch(seconds)
        st.wait(60)
        res.checks["a client still gets a status reply"] = svc.ask_status()
        peak = max(s[1] for s in svc.samples)
        res.notes.append(f"RSS before {rss0:.1f} MB, peak {peak:.1f} MB")

    return _campaign(res, tmp, attack, speed=20.0)


CAMPAIGN = (fd_exhaustion, sighup_burst, request_flood, stalled_subscribers)


def run_campaign(tmp: Path) -> list[CampaignResult]:
    out = []
    for fn in CAMPAIGN:
        d = tmp / fn.__name__
        d.mkdir(parents=True, exist_ok=True)
        out.append(fn(d))
    return out

"""Load on ``avard web``: 20 viewers for a minute, against the same server with none.

``python -m benchmarks web [--viewers 20] [--seconds 60] [--speed 1]``

Starts ``avard run --simulate quiet-lab`` (real time by default: 125 Hz, one raw block per
drain) and ``avard web`` as processes on free loopback ports (the rig of the browser test,
``tests/daemon/web_rig.py``). Three phases of ``--seconds`` each, in the same run:

1. reference: the web server subscribed, nobody viewing;
2. load: ``--viewers`` clients each load the page once (a late viewer gets the whole run)
   and then hold its server-sent-event stream open, reading every update; ``/metrics`` is
   scraped every 5 s as Prometheus would;
3. reference again (the CPU ratio is against the mean of 1 and 3: the process warms up and
   the machine's load drifts).

The viewers are plain ``http.client`` connections in threads (written from the SSE format,
not with the server's library). For each phase it prints the web process's CPU (s per s of
wall time) and resident memory (now and peak), the updates and bytes the viewers received,
and the service's side: FIFO overruns, samples lost, messages the PUB socket dropped and
messages/samples the web server's subscriber lost. The load phase must leave all of those
unchanged (0), and every viewer must get an update at least every 10 s (the service sends
status every 5 s); exit status 1 otherwise.
"""

from __future__ import annotations

import argparse
import http.client
import os
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from avard.daemon.net.subscriber import Subscriber

from tests.daemon.web_rig import WebRig

CLK_TCK = os.sysconf("SC_CLK_TCK")


def proc_cpu_s(pid: int) -> float:
    """User + system CPU seconds of a process (from /proc/PID/stat)."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


def proc_rss(pid: int) -> tuple[int, int]:
    """(VmRSS, VmHWM) in bytes."""
    out = {}
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith(("VmRSS:", "VmHWM:")):
                out[line.split(":")[0]] = int(line.split()[1]) * 1024
    return out.get("VmRSS", 0), out.get("VmHWM", 0)


@dataclass
class Viewer:
    """One browser's worth of load: the page once, then the event stream."""

    port: int
    stop: threading.Event
    updates: int = 0
    bytes: int = 0
    page_bytes: int = 0
    error: str = ""
    thread: threading.Thread | None = None

    def start(self) -> None:
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        try:
            conn = http.client.HTTPConnection("127.0.0.1", self.port, timeout=30)
            conn.request("GET", "/")
            self.page_bytes = len(conn.getresponse().read())
            conn.request("GET", "/events")
            resp = conn.getresponse()
            if resp.status != 200:
                self.error = f"/events: HTTP {resp.status}"
                return
            while not self.stop.is_set():
                line = resp.fp.readline()
                if not line:
                    self.error = "stream closed by the server"
                    return
                self.bytes += len(line)
                if line.startswith(b"event: update"):
                    self.updates += 1
            conn.close()
        except OSError as exc:
            self.error = f"{type(exc).__name__}: {exc}"


@dataclass
class Phase:
    name: str
    seconds: float
    cpu_s: float = 0.0
    rss: int = 0
    peak_rss: int = 0
    updates: list[int] = field(default_factory=list)
    stream_bytes: int = 0
    page_bytes: int = 0
    errors: list[str] = field(default_factory=list)
    service: dict[str, Any] = field(default_factory=dict)   # deltas over the phase
    web_loss: dict[str, int] = field(default_factory=dict)


def service_counts(sub: Subscriber) -> dict[str, int]:
    st = sub.request("status")
    return {"overruns": int(st.get("overruns", 0)),
            "lost_samples_estimate": int(st.get("lost_samples_estimate", 0)),
            "publish_dropped": int(st.get("publish_dropped", 0)),
            "consumers_lost": int(sum(st.get("consumers_lost", {}).values()))}


def run_phase(rig: WebRig, sub: Subscriber, name: str, seconds: float, viewers: int) -> Phase:
    assert rig.web is not None
    pid = rig.web.pid
    ph = Phase(name, seconds)
    svc0, web0 = service_counts(sub), rig.state()
    cpu0 = proc_cpu_s(pid)
    stop = threading.Event()
    vs = [Viewer(rig.http, stop) for _ in range(viewers)]
    for v in vs:
        v.start()
    t0 = time.monotonic()
    next_scrape = t0
    while (now := time.monotonic()) < t0 + seconds:
        if viewers and now >= next_scrape:
            rig.get("/metrics")
            next_scrape = now + 5.0
        time.sleep(0.5)
    wall = time.monotonic() - t0
    ph.cpu_s = (proc_cpu_s(pid) - cpu0) / wall
    ph.rss, ph.peak_rss = proc_rss(pid)
    stop.set()
    for v in vs:
        assert v.thread is not None
        v.thread.join(20)
    ph.updates = [v.updates for v in vs]
    ph.stream_bytes = sum(v.bytes for v in vs)
    ph.page_bytes = max((v.page_bytes for v in vs), default=0)
    ph.errors = [v.error for v in vs if v.error and v.error != "stream closed by the server"]
    svc1, web1 = service_counts(sub), rig.state()
    ph.service = {k: svc1[k] - svc0[k] for k in svc0}
    ph.web_loss = {k: int(web1[k]) - int(web0[k]) for k in ("messages_lost", "samples_lost")}
    return ph


def format_table(phases: list[Phase]) -> str:
    refs = [p for p in phases if p.name.startswith("reference")]
    ref_cpu = sum(p.cpu_s for p in refs) / len(refs)
    lines = ["| phase | web CPU [s/s] | vs mean reference | RSS / peak [MB] | updates per viewer "
             "(min–max) | SSE bytes | overruns | samples lost (service) | PUB dropped | "
             "ring consumers lost | web messages / samples lost |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for ph in phases:
        ratio = ph.cpu_s / ref_cpu if ref_cpu > 0 else float("nan")
        ups = f"{min(ph.updates)}–{max(ph.updates)}" if ph.updates else "–"
        lines.append(
            f"| {ph.name} | {ph.cpu_s:.3f} | {ratio:.2f} × | {ph.rss / 2**20:.1f} / "
            f"{ph.peak_rss / 2**20:.1f} | {ups} | {ph.stream_bytes} | "
            f"{ph.service['overruns']} | {ph.service['lost_samples_estimate']} | "
            f"{ph.service['publish_dropped']} | {ph.service['consumers_lost']} | "
            f"{ph.web_loss['messages_lost']} / {ph.web_loss['samples_lost']} |")
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks web", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--viewers", type=int, default=20)
    ap.add_argument("--seconds", type=float, default=60.0, help="per phase (default 60)")
    ap.add_argument("--speed", type=float, default=1.0,
                    help="simulated time per real second (default 1: real time)")
    ap.add_argument("--warmup", type=float, default=45.0,
                    help="seconds before measuring (imports, first snapshots and fits; "
                         "default 45)")
    ap.add_argument("--fit-interval", type=float, default=10.0, metavar="S",
                    help="avard web --fit-interval (default 10: every snapshot, so both "
                         "phases fit equally often)")
    ap.add_argument("--no-fit", action="store_true",
                    help="avard web --no-fit: what the viewers cost, without the fits")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="avard-bench-web-") as tmp:
        web_args = ("--no-fit",) if args.no_fit else ("--fit-interval", str(args.fit_interval))
        rig = WebRig(Path(tmp), speed=args.speed, web_args=web_args)
        sub = Subscriber(f"tcp://127.0.0.1:{rig.pub}",
                         request_endpoint=f"tcp://127.0.0.1:{rig.req}", request_timeout_s=15)
        try:
            rig.start_service()
            rig.start_web()
            time.sleep(args.warmup)
            # reference before and after the load: the web process warms up (imports, the
            # fit's caches) and the machine's load drifts; the ratio is against their mean
            phases = [run_phase(rig, sub, "reference: 0 viewers", args.seconds, 0),
                      run_phase(rig, sub, f"load: {args.viewers} viewers", args.seconds,
                                args.viewers),
                      run_phase(rig, sub, "reference again: 0 viewers", args.seconds, 0)]
        finally:
            sub.close()
            rig.close()
    print(f"avard web under load: {args.seconds:g} s per phase, service at {args.speed:g}× "
          f"real time (quiet-lab, 125 Hz), web {' '.join(web_args)}; CPU in s per s of wall "
          "time (1.0 = one core)")
    print(format_table(phases))
    load = phases[1]
    print(f"page size {load.page_bytes} bytes; viewer errors: {load.errors or 'none'}")
    bad = [k for k, v in {**load.service, **load.web_loss}.items() if v] + \
        (["viewer errors"] if load.errors else []) + \
        (["a viewer missed updates"] if not load.updates
         or min(load.updates) < max(2, args.seconds / 10) else [])
    if bad:
        print(f"FAIL: {', '.join(bad)}")
        return 1
    print("OK: no overrun, no loss, every viewer updated at least every 10 s")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

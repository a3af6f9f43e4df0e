"""A burst of SIGHUPs (issue 26, item 6): `avard run` as a real process keeps feeding the
watchdog, reloads, and still stops cleanly on the SIGTERM that follows.

The old handlers called ``Event.set()`` from a Python signal handler: a handler that fired
while the main thread held that event's lock deadlocked (SIGTERM ignored, WATCHDOG=1 no longer
sent), and handlers nested inside each other until RecursionError.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from avard.daemon.service.signal_latch import SignalLatch

from tests.daemon.test_faults_sigkill import NotifySocket

CONFIG = """
[recording]
segment_s = 60.0
[publish]
enabled = false
[sensor]
poll_hz = 4.0
"""


def test_a_burst_of_sighups_then_sigterm_stops_the_service_cleanly(tmp_path: Path) -> None:
    cfg = tmp_path / "avard.toml"
    cfg.write_text(CONFIG)
    notify = NotifySocket(tmp_path / "notify.sock")
    env = dict(os.environ, NOTIFY_SOCKET=notify.path, WATCHDOG_USEC="200000",
               PYTHONUNBUFFERED="1")
    env.pop("WATCHDOG_PID", None)
    log = tmp_path / "stderr.log"
    with open(log, "w") as err:
        p = subprocess.Popen(
            [sys.executable, "-m", "avard.daemon.cli", "-v", "run", "--config", str(cfg),
             "--simulate", "quiet-lab", "--speed", "5", "--seed", "3",
             "--data-dir", str(tmp_path / "rec")],
            stdout=subprocess.DEVNULL, stderr=err, env=env)
    try:
        assert notify.wait_ready(), "no READY=1"
        # Two processes sending SIGHUP as fast as kill(2) goes for a few seconds: handlers
        # fire inside handlers and inside the main loop's own lock-holding calls.
        burst = ("import os, signal, sys, time\n"
                 "pid, end = int(sys.argv[1]), time.monotonic() + float(sys.argv[2])\n"
                 "while time.monotonic() < end:\n"
                 "    for _ in range(200):\n"
                 "        os.kill(pid, signal.SIGHUP)\n")
        senders = [subprocess.Popen([sys.executable, "-c", burst, str(p.pid), "4"])
                   for _ in range(2)]
        for s in senders:
            s.wait(60)
        notify.drain()
        # alive and still feeding the watchdog after the burst
        deadline = time.monotonic() + 30
        fed = False
        while not fed and time.monotonic() < deadline and p.poll() is None:
            fed = any(m.get("WATCHDOG") == "1" for m in notify.drain())
        assert p.poll() is None, log.read_text()[-2000:]
        assert fed, "the watchdog was no longer fed after the SIGHUP burst"
        p.send_signal(signal.SIGTERM)
        try:
            rc = p.wait(30)
        except subprocess.TimeoutExpired:
            raise AssertionError("SIGTERM ignored after a SIGHUP burst (deadlock)") from None
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
        notify.close()
    text = log.read_text()
    assert rc == 0, text[-2000:]
    assert "RecursionError" not in text and "Traceback" not in text
    assert "SIGHUP: reopening" in text


def test_the_latch_coalesces_repeats_and_keeps_sigterm() -> None:
    latch = SignalLatch()
    old = {s: signal.getsignal(s) for s in (signal.SIGHUP, signal.SIGUSR1)}
    try:
        latch.install((signal.SIGHUP, signal.SIGUSR1))
        for _ in range(500):
            os.kill(os.getpid(), signal.SIGHUP)
        os.kill(os.getpid(), signal.SIGUSR1)
        assert latch.wait(5.0) == sorted([signal.SIGHUP, signal.SIGUSR1])
        assert latch.wait(0.0) == []
    finally:
        latch.close()
    assert {s: signal.getsignal(s) for s in old} == old

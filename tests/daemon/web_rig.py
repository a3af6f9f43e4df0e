"""A simulated service and ``avard web`` as real processes on loopback ports (for the web
browser test and the web load benchmark)."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


def free_ports(n: int) -> list[int]:
    """``n`` distinct free TCP ports on 127.0.0.1 (bound and released)."""
    socks = []
    for _ in range(n):
        s = socket.socket()
        s.bind(("127.0.0.1", 0))
        socks.append(s)
    ports = [s.getsockname()[1] for s in socks]
    for s in socks:
        s.close()
    return ports


def avard(*args: str) -> list[str]:
    return [sys.executable, "-m", "avard.daemon.cli", *args]


class PortTaken(Exception):
    """Another process took the port between asking for a free one and binding it."""


@dataclass
class WebRig:
    """``avard run --simulate quiet-lab`` + ``avard web`` on free loopback ports."""

    tmp: Path
    speed: float = 20.0
    web_args: tuple[str, ...] = ()
    extra_config: str = ""          # more TOML sections for the service
    pub: int = 0
    req: int = 0
    http: int = 0
    service: subprocess.Popen[bytes] | None = None
    web: subprocess.Popen[bytes] | None = None
    logs: list[Path] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.pub, self.req, self.http = free_ports(3)
        self.config = self.tmp / "svc.toml"
        self._write_config()

    def _write_config(self) -> None:
        # snapshots every 10 s and status every 2 s of simulated time
        self.config.write_text(
            f'[publish]\nendpoint = "tcp://127.0.0.1:{self.pub}"\n'
            f'request_endpoint = "tcp://127.0.0.1:{self.req}"\nstatus_interval_s = 2.0\n'
            "[allan]\nsnapshot_interval_s = 10.0\ncheckpoint_interval_s = 20.0\n"
            + self.extra_config)

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.http}/"

    def _log(self, name: str) -> Any:
        path = self.tmp / f"{name}-{len(self.logs)}.log"
        self.logs.append(path)
        return path.open("wb")

    def start_service(self, tries: int = 3) -> None:
        """Start the service; if its ports were taken meanwhile (it exits at once), on new
        ones (only before ``avard web`` is started: it follows the ports it was given)."""
        for _ in range(tries):
            self._start_service()
            # running once it says samples flow (its sockets are bound before), not after a
            # guessed 1.5 s: a loaded machine takes longer than that just to import
            log = self.logs[-1]
            deadline = time.monotonic() + 120  # a bound on a hang only
            while self.service.poll() is None:  # type: ignore[union-attr]
                if "samples flow" in log.read_text(errors="replace"):
                    return
                if time.monotonic() > deadline:
                    raise RuntimeError(f"avard run never became ready: {self.read_logs()}")
                time.sleep(0.05)
            if self.web is not None:
                break
            self.pub, self.req = free_ports(2)
            self._write_config()
        raise RuntimeError(f"avard run exited: {self.read_logs()}")

    def _start_service(self) -> None:
        self.service = subprocess.Popen(
            avard("run", "--simulate", "quiet-lab", "--speed", str(self.speed), "--seed", "3",
                  "--config", str(self.config), "--data-dir", str(self.tmp / "data")),
            stdout=subprocess.DEVNULL, stderr=self._log("service"),
            env={**os.environ, "PYTHONUNBUFFERED": "1"})

    def stop_service(self) -> None:
        if self.service is not None and self.service.poll() is None:
            self.service.send_signal(signal.SIGTERM)
            self.service.wait(30)
        self.service = None

    def start_web(self, tries: int = 3) -> None:
        """Start ``avard web``; a port taken meanwhile by another test (the free ports are
        only free when asked) is replaced by a new one."""
        for _ in range(tries - 1):
            try:
                return self._start_web()
            except PortTaken:
                (self.http,) = free_ports(1)
        return self._start_web()

    def _start_web(self) -> None:
        self.web = subprocess.Popen(
            avard("web", f"tcp://127.0.0.1:{self.pub}", "--request",
                  f"tcp://127.0.0.1:{self.req}", "--listen", f"127.0.0.1:{self.http}",
                  *self.web_args),
            stdout=subprocess.DEVNULL, stderr=self._log("web"))
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            if self.web.poll() is not None:
                if "cannot serve there" in self.logs[-1].read_text(errors="replace"):
                    raise PortTaken(self.http)
                raise RuntimeError(f"avard web exited: {self.read_logs()}")
            try:
                self.state()
                return
            except OSError:
                time.sleep(0.2)
        raise RuntimeError(f"avard web did not answer: {self.read_logs()}")

    def state(self) -> dict[str, Any]:
        with urllib.request.urlopen(self.url + "state.json", timeout=30) as r:
            return json.loads(r.read())

    def get(self, path: str) -> tuple[int, dict[str, str], bytes]:
        with urllib.request.urlopen(self.url + path.lstrip("/"), timeout=30) as r:
            return r.status, dict(r.headers), r.read()

    def read_logs(self) -> str:
        return "\n".join(f"--- {p.name}\n{p.read_text(errors='replace')[-3000:]}"
                         for p in self.logs if p.exists())

    def close(self) -> None:
        self.stop_service()
        if self.web is not None and self.web.poll() is None:
            self.web.send_signal(signal.SIGTERM)
            try:
                self.web.wait(15)
            except subprocess.TimeoutExpired:
                self.web.kill()
                self.web.wait(5)

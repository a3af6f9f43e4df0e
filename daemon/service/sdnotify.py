"""systemd's notify protocol (sd_notify(3)) without libsystemd.

The service tells systemd that it is ready (``READY=1``, Type=notify), that it is still alive
(``WATCHDOG=1``, only while samples advance, WatchdogSec=), what it is doing (``STATUS=``) and
that it is stopping or reloading. Messages are newline-separated ``KEY=value`` assignments sent
as one datagram to the AF_UNIX socket named by ``$NOTIFY_SOCKET``; a leading ``@`` names a
socket in the Linux abstract namespace (the ``@`` becomes a NUL byte).

Outside systemd (``$NOTIFY_SOCKET`` unset) every call is a no-op. A notification is never worth
crashing acquisition for: every send error is logged once and swallowed, and the public methods
never raise.
"""

from __future__ import annotations

import logging
import os
import socket
import threading
import time
from collections.abc import Mapping

log = logging.getLogger(__name__)

# systemd caps a notification datagram far above this; STATUS= text is for one human line.
_MAX_STATUS_CHARS = 1024


def _socket_address(raw: str) -> str | bytes | None:
    """Turn ``$NOTIFY_SOCKET`` into an address ``socket.sendto`` accepts, or None if unusable."""
    if not raw:
        return None
    if raw.startswith("@"):
        # Abstract namespace: the kernel wants a leading NUL instead of '@' (unix(7)).
        return b"\0" + raw[1:].encode()
    if raw.startswith("/"):
        return raw
    # systemd ≥ 254 also allows vsock:CID:PORT; the service never runs inside a VM guest of a
    # systemd host, so anything that is not a path or abstract name is ignored, loudly.
    log.warning("NOTIFY_SOCKET=%r is neither a path nor an abstract name; not notifying", raw)
    return None


def _watchdog_usec(environ: Mapping[str, str]) -> int | None:
    """WATCHDOG_USEC if it is meant for this process (WATCHDOG_PID absent or equal to ours)."""
    raw = environ.get("WATCHDOG_USEC")
    if not raw:
        return None
    pid = environ.get("WATCHDOG_PID")
    if pid and pid.strip() != str(os.getpid()):
        return None  # set for a parent (e.g. a shell wrapper); not ours to feed
    try:
        usec = int(raw)
    except ValueError:
        log.warning("WATCHDOG_USEC=%r is not an integer; watchdog disabled", raw)
        return None
    return usec if usec > 0 else None


class Notifier:
    """Sends sd_notify messages; a silent no-op when not started by systemd.

    ``Notifier()`` reads the environment once. Thread-safe: one socket, one lock. Pass
    ``environ`` to test without touching ``os.environ``.
    """

    def __init__(self, environ: Mapping[str, str] | None = None) -> None:
        env = os.environ if environ is None else environ
        self._address = _socket_address(env.get("NOTIFY_SOCKET", ""))
        self._watchdog_usec = _watchdog_usec(env)
        self._sock: socket.socket | None = None
        self._lock = threading.Lock()
        self._failed_once = False
        self.sent = 0  # datagrams delivered, for STATUS/tests

    @property
    def enabled(self) -> bool:
        """True when a notify socket is configured (the service runs under systemd)."""
        return self._address is not None

    def watchdog_interval_s(self) -> float | None:
        """Seconds between WATCHDOG=1 pings: half of WatchdogSec as sd_watchdog_enabled(3)
        advises, or None when systemd runs no watchdog for this process."""
        if self._watchdog_usec is None:
            return None
        return self._watchdog_usec / 2e6

    def notify(self, fields: Mapping[str, str | int]) -> bool:
        """Send ``KEY=value`` lines as one datagram. True when sent, False otherwise; never
        raises (a full or vanished notify socket must not stop acquisition)."""
        if self._address is None:
            return False
        lines = []
        for key, value in fields.items():
            text = str(value).replace("\n", " ")  # a newline would start a new assignment
            lines.append(f"{key}={text}")
        payload = ("\n".join(lines) + "\n").encode("utf-8", "replace")
        with self._lock:
            try:
                if self._sock is None:
                    kind = socket.SOCK_DGRAM | socket.SOCK_CLOEXEC
                    self._sock = socket.socket(socket.AF_UNIX, kind)
                    # A stuck systemd must not block the reader thread: drop the message instead.
                    self._sock.setblocking(False)
                self._sock.sendto(payload, self._address)
            except OSError as exc:
                if not self._failed_once:
                    log.warning("sd_notify to %r failed (%s); continuing without it",
                                self._address, exc)
                    self._failed_once = True
                return False
            except Exception:  # documented: never raise into the service
                log.exception("unexpected error in sd_notify; continuing")
                return False
        self.sent += 1
        return True

    def ready(self, status: str | None = None) -> bool:
        """READY=1: samples flow (Type=notify start-up is complete)."""
        fields: dict[str, str | int] = {"READY": 1}
        if status:
            fields["STATUS"] = status[:_MAX_STATUS_CHARS]
        return self.notify(fields)

    def watchdog(self) -> bool:
        """WATCHDOG=1: call only while samples advance, so a stalled reader gets restarted."""
        return self.notify({"WATCHDOG": 1})

    def status(self, text: str) -> bool:
        """STATUS=<one line> shown by ``systemctl status`` (rate, samples, gaps, disk...)."""
        return self.notify({"STATUS": text[:_MAX_STATUS_CHARS]})

    def stopping(self) -> bool:
        """STOPPING=1: SIGTERM received, flushing and closing."""
        return self.notify({"STOPPING": 1})

    def reloading(self) -> bool:
        """RELOADING=1 (with MONOTONIC_USEC, which Type=notify-reload in systemd ≥ 253 wants):
        SIGHUP received, reopening recording files. Send ``ready()`` again when done."""
        usec = time.clock_gettime_ns(time.CLOCK_MONOTONIC) // 1000
        return self.notify({"RELOADING": 1, "MONOTONIC_USEC": usec})

    def close(self) -> None:
        """Close the socket (idempotent); later calls reopen it."""
        with self._lock:
            if self._sock is not None:
                self._sock.close()
                self._sock = None

    def __enter__(self) -> Notifier:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

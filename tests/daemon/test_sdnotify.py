"""sd_notify over a real AF_UNIX datagram socket: paths, abstract names, no-op, never raising."""

from __future__ import annotations

import os
import socket
import threading
import uuid

import pytest
from avard.daemon.service.sdnotify import Notifier


def _recv_fields(sock: socket.socket) -> dict[str, str]:
    data = sock.recv(4096).decode()
    assert data.endswith("\n")
    return dict(line.split("=", 1) for line in data.splitlines())


@pytest.fixture
def path_socket(tmp_path):
    path = tmp_path / "notify.sock"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(path))
    sock.settimeout(2.0)
    yield sock, str(path)
    sock.close()


@pytest.fixture
def abstract_socket():
    name = f"avard-test-{uuid.uuid4().hex}"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(b"\0" + name.encode())
    sock.settimeout(2.0)
    yield sock, "@" + name
    sock.close()


def test_every_message_arrives_on_a_path_socket(path_socket):
    sock, path = path_socket
    n = Notifier({"NOTIFY_SOCKET": path})
    assert n.enabled
    assert n.ready("rate 125.000 Hz")
    assert _recv_fields(sock) == {"READY": "1", "STATUS": "rate 125.000 Hz"}
    assert n.watchdog()
    assert _recv_fields(sock) == {"WATCHDOG": "1"}
    assert n.status("samples 12 gaps 0")
    assert _recv_fields(sock) == {"STATUS": "samples 12 gaps 0"}
    assert n.reloading()
    fields = _recv_fields(sock)
    assert fields["RELOADING"] == "1" and int(fields["MONOTONIC_USEC"]) > 0
    assert n.stopping()
    assert _recv_fields(sock) == {"STOPPING": "1"}
    assert n.sent == 5
    n.close()


def test_abstract_namespace_at_sign_is_a_nul(abstract_socket):
    sock, name = abstract_socket
    with Notifier({"NOTIFY_SOCKET": name}) as n:
        assert n.watchdog()
        assert _recv_fields(sock) == {"WATCHDOG": "1"}


def test_newline_in_status_cannot_inject_an_assignment(path_socket):
    sock, path = path_socket
    n = Notifier({"NOTIFY_SOCKET": path})
    n.status("disk full\nREADY=1")
    fields = _recv_fields(sock)
    assert fields == {"STATUS": "disk full READY=1"}
    n.close()


def test_unset_socket_is_a_silent_no_op():
    n = Notifier({})
    assert not n.enabled
    assert n.ready() is False and n.watchdog() is False and n.status("x") is False
    assert n.stopping() is False and n.reloading() is False
    assert n.watchdog_interval_s() is None


def test_default_reads_os_environ(monkeypatch, path_socket):
    sock, path = path_socket
    monkeypatch.setenv("NOTIFY_SOCKET", path)
    n = Notifier()
    assert n.ready()
    assert _recv_fields(sock)["READY"] == "1"
    n.close()


def test_vanished_socket_never_raises_and_warns_once(tmp_path, caplog):
    n = Notifier({"NOTIFY_SOCKET": str(tmp_path / "gone.sock")})
    assert n.enabled
    for _ in range(3):
        assert n.watchdog() is False
    warnings = [r for r in caplog.records if "sd_notify" in r.getMessage()]
    assert len(warnings) == 1
    assert n.sent == 0


def test_socket_that_comes_back_is_used_again(tmp_path):
    path = tmp_path / "later.sock"
    n = Notifier({"NOTIFY_SOCKET": str(path)})
    assert n.status("early") is False
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(path))
    sock.settimeout(2.0)
    try:
        assert n.status("late")
        assert _recv_fields(sock) == {"STATUS": "late"}
    finally:
        sock.close()
        n.close()


def test_full_socket_drops_instead_of_blocking(path_socket):
    # Nobody reads: the receive queue fills. The reader thread must never block on systemd.
    _sock, path = path_socket
    n = Notifier({"NOTIFY_SOCKET": path})
    results = [n.status("x" * 1000) for _ in range(2000)]
    assert results[0] is True
    assert False in results  # queue full → dropped, returned False, no exception, no hang
    n.close()


def test_unusable_address_is_ignored(caplog):
    n = Notifier({"NOTIFY_SOCKET": "vsock:2:1234"})
    assert not n.enabled and n.ready() is False
    assert "neither a path" in caplog.text


@pytest.mark.parametrize(
    ("env", "expected"),
    [
        ({"WATCHDOG_USEC": "20000000"}, 10.0),
        ({"WATCHDOG_USEC": "20000000", "WATCHDOG_PID": str(os.getpid())}, 10.0),
        ({"WATCHDOG_USEC": "20000000", "WATCHDOG_PID": "1"}, None),  # meant for another process
        ({"WATCHDOG_USEC": "0"}, None),
        ({"WATCHDOG_USEC": "soon"}, None),
        ({}, None),
    ],
)
def test_watchdog_interval_is_half_of_watchdog_sec(env, expected):
    assert Notifier(env).watchdog_interval_s() == expected


def test_concurrent_senders_each_deliver_whole_datagrams(path_socket):
    # The kernel queues only ~10 datagrams; a reader drains while 4 threads send. Every send
    # reported as delivered arrives whole (no interleaving); drops are allowed and reported.
    sock, path = path_socket
    n = Notifier({"NOTIFY_SOCKET": path})
    per_thread = 50
    got: list[str] = []
    done = threading.Event()

    def receive() -> None:
        sock.settimeout(0.2)
        while True:
            try:
                got.append(_recv_fields(sock)["STATUS"])
            except TimeoutError:
                if done.is_set():
                    return

    def send(k: int) -> None:
        for i in range(per_thread):
            n.status(f"thread {k} msg {i}")

    receiver = threading.Thread(target=receive)
    receiver.start()
    threads = [threading.Thread(target=send, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    done.set()
    receiver.join()
    sent_all = {f"thread {k} msg {i}" for k in range(4) for i in range(per_thread)}
    assert len(got) == n.sent > 0
    assert set(got) <= sent_all and len(set(got)) == len(got)
    n.close()


def test_service_feeds_the_watchdog_only_while_samples_advance(tmp_path, path_socket):
    # The whole service with a Notifier on a real socket: WATCHDOG=1 stops while the sensor
    # produces nothing (so systemd's WatchdogSec= restarts a stuck service) and comes back
    # with the samples; READY=1 once samples flow; STOPPING=1 at the end.
    from .test_faults_bus import run_rig

    sock, path = path_socket
    sock.settimeout(0.05)
    received: list[dict[str, str]] = []
    stamped: list[tuple[float, dict[str, str]]] = []
    box: dict = {}

    class StampedNotifier(Notifier):
        """Each message stamped with the service's (virtual) time when it is sent, not when a
        thread of this test gets round to reading it: the times below are exact on a loaded
        machine."""

        def notify(self, fields):  # type: ignore[no-untyped-def]
            clock = box.get("clock")
            t = clock.monotonic() - box["t0"] if clock else -1.0
            sent = super().notify(fields)
            if sent:  # (a datagram the full socket refused is not expected below)
                stamped.append((t, {k: str(v) for k, v in fields.items()}))
            return sent

    def collect() -> None:  # until STOPPING=1, the last message the service sends
        while not received or received[-1].get("STOPPING") != "1":
            try:
                received.append(_recv_fields(sock))
            except TimeoutError:
                continue

    def inject(ctx: dict, t: float) -> None:
        box.setdefault("clock", ctx["clock"])
        box.setdefault("t0", ctx["svc"].t_start)
        if t > 6 and ctx["once"]("stop"):
            ctx["emu"].stop_producing()
        if t > 14 and ctx["once"]("resume"):
            ctx["emu"].resume_producing()

    reader = threading.Thread(target=collect, daemon=True)
    reader.start()
    notifier = StampedNotifier({"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "200000"})
    try:
        rig = run_rig(tmp_path, 22.0, inject=inject, speed=10.0, notifier=notifier)
    finally:
        reader.join(120)  # a bound on a hang only: it returns at STOPPING=1
        notifier.close()
    assert not reader.is_alive(), "STOPPING=1 never arrived"
    # what was sent is what arrived, in order
    assert received == [f for _, f in stamped]
    got = stamped
    pings = [t for t, f in got if f.get("WATCHDOG") == "1"]
    assert any(f.get("READY") == "1" for _, f in got)
    assert any(f.get("STOPPING") == "1" for _, f in got)
    # Pings before the stall, none while it lasted (after the 2 s stall detection), again after.
    assert any(t < 6 for t in pings)
    assert not any(8.5 < t < 14 for t in pings), pings
    assert any(t > 15 for t in pings)
    events = [r["name"] for r in rig.kinds("event")]
    assert "stalled" in events and "resumed" in events


@pytest.mark.parametrize("state, words", [("writing", "disk writing"), ("disk_full", "disk full"),
                                          ("write_error", "disk write error"), ("off", "disk off")])
def test_the_status_line_says_the_recorders_state_in_words(state, words):
    """STATUS= reads "disk full", not the status map's "disk disk_full"."""
    from avard.daemon.service.supervisor import disk_words

    assert disk_words(state) == words

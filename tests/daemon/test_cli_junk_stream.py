"""A stream of messages avard cannot read (another program on the port, another version): the
clients end with one line saying so, not "nothing received" (which sent the user looking for
a service that was not running), and log a bounded number of lines, not one per message.
The real CLI in a subprocess, against junk published from this process."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from collections.abc import Iterator

import pytest

zmq = pytest.importorskip("zmq")


@pytest.fixture
def junk() -> Iterator[str]:
    """A PUB socket sending junk on the topics a service uses (undecodable payloads, a record
    without a format version, a message of one part) until the test ends."""
    ctx = zmq.Context()
    pub = ctx.socket(zmq.PUB)
    port = pub.bind_to_random_port("tcp://127.0.0.1")
    stop = threading.Event()

    def send() -> None:
        while not stop.wait(0.01):
            pub.send_multipart([b"raw", os.urandom(50)])
            pub.send_multipart([b"avar", b"\x81\xa4kind\xa4avar"])
            pub.send(b"x")

    t = threading.Thread(target=send, daemon=True)
    t.start()
    try:
        yield f"tcp://127.0.0.1:{port}"
    finally:
        stop.set()
        t.join(5)
        pub.close(linger=0)
        ctx.term()


@pytest.mark.parametrize("command", ["record", "watch"])
def test_a_stream_of_junk_is_named_in_one_line(junk, tmp_path, command) -> None:
    args = (["record", junk, "--out", str(tmp_path / "out"), "--wait", "2"]
            if command == "record" else ["watch", junk, "--once", "--wait", "2"])
    r = subprocess.run([sys.executable, "-m", "avard.daemon.cli", *args, "--timeout", "0.3"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr
    errors = [ln for ln in r.stderr.splitlines() if ln.startswith(f"avard {command}: error:")]
    assert len(errors) == 1, r.stderr
    assert "nothing readable" in errors[0] and "cannot read" in errors[0] \
        and "this version" in errors[0], errors[0]
    # hundreds of junk messages came: the log names the first and then counts by decades
    n = int(errors[0].split("within 2 s: ")[1].split()[0])
    logged = [ln for ln in r.stderr.splitlines() if "undecodable" in ln]
    assert n >= 10 and 1 <= len(logged) <= 1 + len(str(n)) - 1, (n, logged)
    if command == "record":
        assert not list((tmp_path / "out").glob("*.avr"))      # nothing archived

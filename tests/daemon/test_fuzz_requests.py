"""The request socket under hostile peers, over real loopback TCP (hypothesis fuzzing).

The server is the service's own RequestServer with the service's own handlers (snapshot,
status, recent, header of a Service that has its ring, accumulators and time base). A DEALER
peer sends random bytes, arbitrary msgpack, valid requests with hostile arguments, deep
nesting, huge declared lengths, multi-frame and empty messages: every one gets an error or a
valid reply, in order, and the server never stops answering. Messages above the hard cap are
dropped by libzmq before they are buffered (the peer is disconnected); the next peer is
served. The server's memory does not grow with what it was sent.
"""

from __future__ import annotations

import math
from typing import Any

import msgpack
import pytest
import zmq
from avard.core.io import frames
from avard.daemon.compose import compose
from avard.daemon.config_types import as_config
from avard.daemon.hw.simulation import build_simulated
from avard.daemon.net.publisher import RequestServer
from hypothesis import given
from hypothesis import strategies as st

from tests.support.rigs import rig_from_parts

from .test_faults_bus import rig_config
from .test_faults_subscriber import _rss_bytes
from .test_fuzz_frames import (
    deep_nesting,
    fuzz_settings,
    huge_declared_lengths,
    make_counter,
    msgpack_values,
    save_counts,
)

REPLY_TIMEOUT_MS = 3000


@pytest.fixture(scope="module")
def counter(request):
    c = make_counter(request)
    yield c
    save_counts(request, c)


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    cfg = rig_config(tmp_path_factory.mktemp("req") / "rec")
    dev, clock, sims, _emu = build_simulated(cfg, "quiet-lab", seed=5)
    svc = compose(as_config(cfg), rig_from_parts(as_config(cfg), dev, clock,
                                                 simulate="quiet-lab", sims=sims))
    # Some samples in the ring, so that "recent" has something to return.
    import numpy as np

    n = 500
    svc.ring.push(np.zeros((n, 3), np.int32), np.arange(n, dtype=np.int64),
                  np.arange(n, dtype=np.float64) / 125.0)
    srv = RequestServer("tcp://127.0.0.1:0", svc.handlers()).start()
    yield srv
    srv.stop()


@pytest.fixture(scope="module")
def peer(server):
    ctx = zmq.Context()
    sock = ctx.socket(zmq.DEALER)
    sock.setsockopt(zmq.LINGER, 0)
    sock.connect(server.endpoint)
    yield sock
    sock.close()
    ctx.term()


def _ask(sock: zmq.Socket, parts: list[bytes]) -> dict[str, Any]:
    sock.send_multipart(parts)
    assert sock.poll(REPLY_TIMEOUT_MS), "no reply: the server stopped answering"
    reply = sock.recv_multipart()
    # A message starting with an empty frame looks like a REQ envelope: the server answers
    # with the same empty delimiter in front of the reply.
    assert len(reply) == 1 or (len(reply) == 2 and reply[0] == b"" and parts[0] == b"")
    return frames.decode_reply(reply[-1])


def _check(rep: dict[str, Any]) -> None:
    if rep["ok"]:
        assert isinstance(rep["result"], dict)
    else:
        assert len(rep["error"]) >= 10 and "internal error" not in rep["error"], rep["error"]


_args = st.dictionaries(st.text(max_size=8), msgpack_values, max_size=4)
_hostile_seconds = st.one_of(
    st.floats(), st.integers(-(2**63), 2**64 - 1), st.text(max_size=5), st.none(),
    st.lists(st.integers(), max_size=3), st.sampled_from([math.nan, math.inf, -1, 1e308, 0]),
)


@st.composite
def requests(draw) -> bytes:
    """Requests that parse, with real and unknown ops and hostile arguments."""
    op = draw(st.one_of(st.sampled_from(["snapshot", "status", "recent", "header"]),
                        st.text(max_size=12)))
    args = draw(_args)
    if op == "recent" and draw(st.booleans()):
        args["seconds"] = draw(_hostile_seconds)
    req = {"op": op, "args": args, "id": draw(st.integers(-(2**63), 2**63 - 1))}
    for key in draw(st.lists(st.sampled_from(["op", "args", "id"]), max_size=2)):
        req[key] = draw(msgpack_values)  # and sometimes a field of the wrong type
    return msgpack.packb(req, use_bin_type=True)


@fuzz_settings(200)
@given(payload=st.one_of(
    requests(), st.binary(max_size=512),
    msgpack_values.map(lambda v: msgpack.packb(v, use_bin_type=True)),
    huge_declared_lengths(), deep_nesting().filter(lambda b: len(b) < 60_000),
))
def test_every_single_frame_request_gets_a_reply(counter, peer, payload):
    counter.tick("request socket")
    _check(_ask(peer, [payload]))


@fuzz_settings(60)
@given(parts=st.lists(st.binary(max_size=64), min_size=0, max_size=5).filter(
    lambda p: len(p) != 1 and p[:2] != [b"", frames.encode_request("status")]))
def test_multi_frame_and_empty_messages_get_an_error(counter, peer, parts):
    counter.tick("request socket")
    rep = _ask(peer, parts or [b""])
    # (b"", payload) is a REQ envelope around one frame: then the payload itself is judged
    assert rep["ok"] is False and ("frame" in rep["error"] or parts[:1] == [b""])


def test_valid_requests_are_answered(counter, peer):
    counter.tick("request socket", 3)
    for op in ("status", "header"):
        assert _ask(peer, [frames.encode_request(op, id=7)])["ok"] is True
    rep = _ask(peer, [frames.encode_request("recent", {"seconds": 2.0}, id=8)])
    assert rep["ok"] is True and rep["id"] == 8 and rep["result"]["n"] == 250


def test_oversized_requests(counter, server, peer):
    counter.tick("request socket", 2)
    # Over the request limit, under the hard cap: an error reply naming the limit.
    big = frames.encode_request("status", {"pad": b"x" * (server.max_request_bytes + 1)})
    rep = _ask(peer, [big])
    assert rep["ok"] is False and "limit" in rep["error"]
    # Over the hard cap: libzmq drops the peer before buffering it; the server lives on.
    ctx = zmq.Context()
    hostile = ctx.socket(zmq.DEALER)
    hostile.setsockopt(zmq.LINGER, 0)
    hostile.connect(server.endpoint)
    hostile.send_multipart([b"\x00" * (server.hard_cap_bytes + 1)])
    assert not hostile.poll(500)
    hostile.close()
    ctx.term()
    assert _ask(peer, [frames.encode_request("status")])["ok"] is True


def test_server_memory_does_not_grow_with_hostile_traffic(counter, server, peer):
    junk = [b"\xdd\xff\xff\xff\xff", b"\x91" * 50_000, b"\xc1" * 1000,
            frames.encode_request("recent", {"seconds": 1e308}),
            frames.encode_request("nosuchop", {"x": "y" * 60_000})]
    for _ in range(50):  # warm-up: allocator pools reach their size
        for j in junk:
            _ask(peer, [j])
    rss0 = _rss_bytes()
    for _ in range(200):
        for j in junk:
            _ask(peer, [j])
    counter.tick("request socket", 250 * len(junk))
    assert _rss_bytes() - rss0 < 4 * 2**20
    assert server.errors >= 250 * len(junk)

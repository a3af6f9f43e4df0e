"""The request side: the latest published snapshot, fits off the request thread, error
replies that name the request, and bounded memory for peers that never read."""

from __future__ import annotations

import threading
from typing import Any

import msgpack
import numpy as np
import pytest
import zmq
from avard.core.io import frames as F
from avard.daemon.net.publisher import REPLY_HWM, RequestServer
from avard.daemon.service.snapshots import FIT_LEASE_RECORDS, SnapshotBoard

LOCAL = "tcp://127.0.0.1:*"


def _rec(i_end: int) -> dict[str, Any]:
    return {"kind": "avar", "i_end": i_end, "snapshot": {"m": [1]}, "fit": None}


class BlockingFit:
    """A fit that waits for the test to release it (a 2-second fit on a Pi, without timing)."""

    def __init__(self) -> None:
        self.release = threading.Event()
        self.started = threading.Event()
        self.seen: list[int] = []

    def __call__(self, rec: dict[str, Any]) -> dict[str, Any]:
        self.seen.append(rec["i_end"])
        self.started.set()
        assert self.release.wait(10)
        return {"x": {"fitted_i_end": rec["i_end"]}}


def test_board_answers_the_latest_record_and_only_its_own_fit() -> None:
    fit = BlockingFit()
    board = SnapshotBoard(fit)
    try:
        assert board.reply() is None                   # nothing published yet
        board.publish(_rec(100))
        assert fit.started.wait(5)                     # asked once: the fit thread runs
        rep = board.reply()
        assert rep is not None and rep["i_end"] == 100 and rep["fit_pending"]
        board.publish(_rec(200))                       # while record 100 is being fitted
        rep = board.reply()
        assert rep is not None and rep["i_end"] == 200 and rep["fit"] is None
        fit.release.set()
        assert board.wait_fitted(5)
        rep = board.reply()
        assert rep is not None and rep["i_end"] == 200 and not rep["fit_pending"]
        assert rep["fit"] == {"x": {"fitted_i_end": 200}}     # never 100's fit on 200
    finally:
        fit.release.set()
        board.stop()


def test_no_fit_and_no_thread_until_a_client_asks() -> None:
    fit = BlockingFit()
    board = SnapshotBoard(fit)
    board.publish(_rec(1))
    board.publish(_rec(2))
    assert not fit.started.wait(0.2) and fit.seen == []
    board.stop()


def test_one_request_leases_a_few_fits_not_the_rest_of_the_run() -> None:
    """#26 item 9: one `snapshot` request (what `avard watch` sends at join) made the service
    fit every later snapshot for the rest of the run. It now fits the record current at the
    request and the next FIT_LEASE_RECORDS, then nothing until a client asks again."""
    fit = BlockingFit()
    fit.release.set()
    board = SnapshotBoard(fit)
    try:
        board.publish(_rec(0))
        assert board.reply() is not None               # the one request
        assert board.wait_fitted(10)
        for k in range(1, 3 * FIT_LEASE_RECORDS):
            board.publish(_rec(k))
            if k <= FIT_LEASE_RECORDS:
                assert board.wait_fitted(10)
            else:                                      # past the lease: nothing to fit
                assert not board.fit_due()
        assert fit.seen == list(range(FIT_LEASE_RECORDS + 1))
        last = 3 * FIT_LEASE_RECORDS - 1
        rep = board.reply()                            # a client asks again: its record
        assert rep is not None and rep["i_end"] == last and rep["fit_pending"]
        assert board.wait_fitted(10)
        assert fit.seen == [*range(FIT_LEASE_RECORDS + 1), last]
        assert board.fits == FIT_LEASE_RECORDS + 2
    finally:
        board.stop()


def _dealer(ctx: zmq.Context, endpoint: str) -> zmq.Socket:
    s = ctx.socket(zmq.DEALER)
    s.setsockopt(zmq.LINGER, 0)
    s.connect(endpoint)
    return s


def _reply(s: zmq.Socket) -> dict[str, Any]:
    assert s.poll(5000), "no reply"
    return F.decode_reply(s.recv_multipart()[-1])


def test_status_is_answered_while_a_snapshot_fit_runs() -> None:
    fit = BlockingFit()
    board = SnapshotBoard(fit)
    board.publish(_rec(7))

    def snapshot(_a: dict) -> dict:
        rep = board.reply()
        assert rep is not None
        return rep

    srv = RequestServer(LOCAL, {"snapshot": snapshot,
                                "status": lambda _a: {"samples": 1}}).start()
    ctx = zmq.Context()
    try:
        a, b = _dealer(ctx, srv.endpoint), _dealer(ctx, srv.endpoint)
        a.send_multipart([b"", F.encode_request("snapshot", id=1)])
        first = _reply(a)
        assert first["ok"] and first["result"]["fit_pending"]
        assert fit.started.wait(5)                 # the fit is running and blocked
        b.send_multipart([b"", F.encode_request("status", id=2)])
        rep = _reply(b)                            # answered while the fit still blocks
        assert rep["ok"] and rep["id"] == 2 and not fit.release.is_set()
        fit.release.set()
        assert board.wait_fitted(5)
        a.send_multipart([b"", F.encode_request("snapshot", id=3)])
        rep = _reply(a)
        assert rep["result"]["fit"] == {"x": {"fitted_i_end": 7}}
    finally:
        fit.release.set()
        srv.stop()
        board.stop()
        ctx.destroy(linger=0)


@pytest.mark.parametrize(("request_map", "op", "rid"), [
    ({"op": "nosuch", "id": 42}, "nosuch", 42),                    # unknown op
    ({"op": "status", "args": [1], "id": 43}, "status", 43),       # args not a map
    ({"op": "status", "id": "x"}, "status", 0),                    # id not an int
    ({"op": 5, "id": 44}, "?", 44),                                # op not a string
])
def test_error_replies_echo_the_op_and_id_they_could_read(
        request_map: dict, op: str, rid: int) -> None:
    srv = RequestServer(LOCAL, {"status": lambda _a: {}})
    reply = F.decode_reply(srv.handle(msgpack.packb(request_map)))
    assert not reply["ok"] and reply["op"] == op and reply["id"] == rid


def test_a_peer_that_never_reads_gets_its_replies_refused_not_queued() -> None:
    """Per peer at most REPLY_HWM replies wait in the service (plus what the kernel's socket
    buffers take); the rest are refused and counted."""
    big = np.zeros((40000, 3), dtype=np.int32)            # ~480 kB per reply
    srv = RequestServer(LOCAL, {"recent": lambda _a: {"counts": F.pack_array(big)}},
                        max_requests_per_s=1e4).start()
    ctx = zmq.Context()
    try:
        s = _dealer(ctx, srv.endpoint)
        s.setsockopt(zmq.RCVBUF, 4096)
        s.setsockopt(zmq.RCVHWM, 1)
        n = 200
        for i in range(n):
            s.send_multipart([b"", F.encode_request("recent", id=i)])
        deadline = threading.Event()
        for _ in range(100):
            if srv.answered >= n:
                break
            deadline.wait(0.05)
        assert srv.answered == n
        # 200 × 480 kB = 96 MB were asked for; what was accepted is bounded.
        accepted = n - srv.refused_replies
        assert accepted * 480e3 < 40e6
        assert srv.refused_replies > n / 2
        assert REPLY_HWM <= 4
    finally:
        srv.stop()
        ctx.destroy(linger=0)


def test_replies_are_bounded_in_total_by_the_number_of_peers_answered() -> None:
    """Beyond max_peers clients asking within the window, a new one gets a short 'busy' error
    (naming its op and id) instead of a reply: what can queue for peers that never read is
    bounded by max_peers × REPLY_HWM × the largest reply."""
    srv = RequestServer(LOCAL, {"status": lambda _a: {"ok": 1}}, max_peers=3).start()
    ctx = zmq.Context()
    try:
        socks = [_dealer(ctx, srv.endpoint) for _ in range(5)]
        replies = []
        for i, s in enumerate(socks):
            s.send_multipart([b"", F.encode_request("status", id=100 + i)])
            replies.append(_reply(s))
        assert [r["ok"] for r in replies] == [True, True, True, False, False]
        assert replies[3]["op"] == "status" and replies[3]["id"] == 103
        assert "busy" in replies[3]["error"] and srv.refused_peers == 2
        socks[0].send_multipart([b"", F.encode_request("status", id=7)])
        assert _reply(socks[0])["ok"]                  # the admitted ones go on being answered
    finally:
        srv.stop()
        ctx.destroy(linger=0)

"""Options of the network clients that can never work are refused before anything starts:
one line naming the option and what to give, exit status 2, nothing created. Each of these
was taken: a negative ``--interval`` redrew ``avard watch`` at every message, ``--target 0``
asked for an interval no record reaches, ``--segment 0`` had ``avard record`` start a file
per record, a negative ``--duration`` ended it at once with exit status 1 and nothing on
stderr, ``--timeout 0`` waited 0 s for every reply."""

from __future__ import annotations

import pytest
from avard.daemon.cli import main

#: nothing listens here, and nothing is asked of it: the options are refused first
ENDPOINT = "tcp://127.0.0.1:1"


@pytest.mark.parametrize("args, named", [
    (["watch", ENDPOINT, "--interval", "-1"], "--interval -1"),
    (["watch", ENDPOINT, "--interval", "0"], "--interval 0"),
    (["watch", ENDPOINT, "--interval", "nan"], "--interval nan"),
    (["watch", ENDPOINT, "--once", "--wait", "-2"], "--wait -2"),
    (["watch", ENDPOINT, "--count", "0"], "--count 0"),
    (["watch", ENDPOINT, "--target", "0"], "--target 0"),
    (["watch", ENDPOINT, "--timeout", "0"], "--timeout 0"),
    (["record", ENDPOINT, "--out", "{out}", "--segment", "0"], "--segment 0"),
    (["record", ENDPOINT, "--out", "{out}", "--fsync", "-1"], "--fsync -1"),
    (["record", ENDPOINT, "--out", "{out}", "--duration", "-1"], "--duration -1"),
    (["record", ENDPOINT, "--out", "{out}", "--wait", "0"], "--wait 0"),
    (["record", ENDPOINT, "--out", "{out}", "--timeout", "inf"], "--timeout inf"),
])
def test_an_option_that_can_never_work_is_refused_in_one_line(tmp_path, capsys, monkeypatch,
                                                               args, named) -> None:
    from avard.daemon.commands import record
    from avard.daemon.net.subscriber import Subscriber

    def started(*_a: object, **_k: object) -> None:
        pytest.fail("the command started before refusing the option")

    # a command that took the option would go on and wait on the endpoint: fail at once
    monkeypatch.setattr(Subscriber, "connect", started)
    monkeypatch.setattr(record, "check_stream_sensor", started)
    out = tmp_path / "archive"
    assert main([a.format(out=out) for a in args]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert err.startswith(f"avard {args[0]}: error: {named}: give "), err
    assert not out.exists()                      # nothing made before the refusal


def test_the_limits_themselves_are_taken(tmp_path) -> None:
    """``--fsync 0`` (every record) stays allowed; refused values are the impossible ones."""
    from avard.daemon.commands._options import check_seconds

    check_seconds(0.0, "--fsync", zero=True)
    check_seconds(None, "--duration")
    check_seconds(1e-3, "--interval")

"""journald levels: `<N>` syslog priority prefixes when stderr is the journal stream."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from avard.daemon.service.logfmt import priority_of


def test_priorities_follow_syslog() -> None:
    assert [priority_of(x) for x in (50, 40, 30, 20, 10, 25, 5)] == [2, 3, 4, 6, 7, 6, 7]


_LOG = ("import logging, sys; from avard.daemon.cli import setup_logging; setup_logging(1);"
        "log = logging.getLogger('avard.test'); log.error('bad'); log.warning('odd');"
        "log.info('fine'); log.debug('detail')\n"
        "try:\n    1/0\nexcept ZeroDivisionError:\n    log.exception('boom')")


def _run(tmp_path: Path, journal: bool, other_stream: str | None = None) -> list[str]:
    err = tmp_path / "stderr.txt"
    with open(err, "w") as f:
        st = os.fstat(f.fileno())
        env = dict(os.environ)
        env.pop("JOURNAL_STREAM", None)
        if journal:       # what systemd sets when stderr is the journal stream
            env["JOURNAL_STREAM"] = f"{st.st_dev}:{st.st_ino}"
        elif other_stream is not None:
            env["JOURNAL_STREAM"] = other_stream
        subprocess.run([sys.executable, "-c", _LOG], stderr=f, env=env, check=True)
    return err.read_text().splitlines()


def test_journal_stream_gets_priority_prefixes_on_every_line(tmp_path: Path) -> None:
    lines = _run(tmp_path, journal=True)
    assert lines[:4] == ["<3>avard.test: bad", "<4>avard.test: odd", "<6>avard.test: fine",
                         "<7>avard.test: detail"]
    trace = lines[4:]
    assert trace[0] == "<3>avard.test: boom" and len(trace) > 3
    assert all(line.startswith("<3>") for line in trace)     # the traceback too


@pytest.mark.parametrize("journal_stream", [None, "1:2"])
def test_terminal_gets_plain_levels(tmp_path: Path, journal_stream: str | None) -> None:
    """Without JOURNAL_STREAM, or when it names another stream (a child whose stderr was
    redirected), no prefixes."""
    lines = _run(tmp_path, journal=False, other_stream=journal_stream)
    assert lines[:2] == ["ERROR avard.test: bad", "WARNING avard.test: odd"]

"""The CLI's logging does not outlive the stderr it was set up on.

``setup_logging`` bound its handler to the ``sys.stderr`` of the moment and replaced every
handler of the root logger: after an in-process ``main()`` under a test's capture, the root
logger wrote to that (closed) capture, and every later test's log line became a 'Logging
error' in its own stderr. The handler now writes to the ``sys.stderr`` of the moment, a
second call replaces only its own handler, and tests/conftest.py puts the root logger back
after every test, whatever configured it.
"""

from __future__ import annotations

import io
import logging
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from avard.daemon.cli import setup_logging

ROOT = Path(__file__).resolve().parents[2]


def test_the_cli_handler_writes_to_the_stderr_of_the_moment(monkeypatch) -> None:
    old = io.StringIO()
    monkeypatch.setattr(sys, "stderr", old)
    setup_logging(0, narrates=False)
    old.close()                                    # as pytest closes a test's capture
    now = io.StringIO()
    monkeypatch.setattr(sys, "stderr", now)
    logging.getLogger("avard.test").warning("after the first stream closed")
    assert now.getvalue() == "WARNING avard.test: after the first stream closed\n"


def test_a_second_setup_replaces_only_its_own_handler(monkeypatch) -> None:
    err = io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    other = logging.StreamHandler(io.StringIO())
    logging.getLogger().addHandler(other)
    setup_logging(0, narrates=False)
    setup_logging(1, narrates=False)
    assert other in logging.getLogger().handlers
    logging.getLogger("avard.test").info("once")
    assert err.getvalue() == "INFO avard.test: once\n"           # one handler of ours
    assert other.stream.getvalue() == "once\n"                   # and the other one kept


_LEAKS = '''
import logging, sys
from avard.daemon.cli import main


def test_1_main_in_process(capsys, tmp_path):
    assert main(["keys", "--out", str(tmp_path / "keys")]) == 0


def test_2_a_handler_left_on_this_tests_capture(capsys):
    logging.getLogger().addHandler(logging.StreamHandler(sys.stderr))


def test_3_logs_and_reads_its_stderr(capsys):
    logging.getLogger("avard.later").warning("a later test logs")
    err = capsys.readouterr().err
    assert "Logging error" not in err, err
'''


@pytest.mark.parametrize("conftest", [True, False])
def test_what_one_test_leaves_on_the_root_logger_never_reaches_the_next(tmp_path,
                                                                         conftest) -> None:
    """Three tests in one process, in order: the first runs ``main()`` in-process, the
    second leaves a handler on its captured stderr as any code could; the third logs.
    With the suite's conftest, the third sees no 'Logging error'; without it, the handler
    the second left does write one (which shows the case is real: the CLI's own handler no
    longer leaks, the hand-made one does)."""
    (tmp_path / "test_leaks.py").write_text(_LEAKS)
    (tmp_path / "pytest.ini").write_text("[pytest]\n")      # not the repository's settings
    if conftest:
        shutil.copy(ROOT / "tests" / "conftest.py", tmp_path / "conftest.py")
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                        "-p", "no:xdist", "--rootdir", str(tmp_path),
                        str(tmp_path / "test_leaks.py")],
                       capture_output=True, text=True, timeout=120, cwd=tmp_path)
    if conftest:
        assert r.returncode == 0 and "3 passed" in r.stdout, r.stdout + r.stderr
    else:
        assert r.returncode == 1 and "1 failed, 2 passed" in r.stdout, r.stdout + r.stderr
        assert "test_3_logs_and_reads_its_stderr" in r.stdout and "Logging error" in r.stdout

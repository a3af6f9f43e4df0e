"""A FIFO (or another special file) given as the data: one line, exit status 2, no hang
(adv27). ``open()`` of a FIFO blocks until a writer comes, so ``avard analyze x.npz`` on a
named pipe waited forever instead of saying what is wrong; the config loader already
refused special files, the data readers did not. A FIFO named like a segment inside a
recording directory was already skipped (segment_files keeps regular files only); a single
segment given by its path was not.

The commands run as subprocesses with a generous timeout: the timeout only ends a hang, the
assertion is on the exit status and the message, never on how long it took."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest


@pytest.mark.parametrize(("command", "name"), [("analyze", "data.npz"), ("analyze", "seg.avr"),
                                               ("explain", "data.csv")])
def test_a_fifo_as_the_data_is_refused_with_one_line(tmp_path: Path, command: str,
                                                      name: str) -> None:
    fifo = tmp_path / name
    os.mkfifo(fifo)
    try:
        out = subprocess.run([sys.executable, "-m", "avard.daemon.cli", command, str(fifo)],
                             capture_output=True, text=True, timeout=60, cwd=tmp_path)
    except subprocess.TimeoutExpired:
        pytest.fail(f"avard {command} {name} (a FIFO) never returned: open() waits for a writer")
    err = [ln for ln in out.stderr.splitlines() if ln.strip()]
    assert out.returncode == 2, out.stderr
    assert "Traceback" not in out.stderr
    assert len(err) == 1 and str(fifo) in err[0] and "not a regular file" in err[0], err

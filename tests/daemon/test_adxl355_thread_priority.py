"""Raising the reader thread to SCHED_FIFO: only that thread, and a clear refusal."""

from __future__ import annotations

import logging
import os
import threading

import pytest
from avard.daemon.hw import thread_priority as TP


def test_raises_only_the_calling_thread_or_says_why_not(caplog):
    result = {}

    def worker():
        with caplog.at_level(logging.INFO):
            result["ok"] = TP.raise_thread_priority(5)
        result["policy"] = TP.current_policy()

    t = threading.Thread(target=worker)
    t.start()
    t.join()
    if result["ok"]:
        assert result["policy"] == "SCHED_FIFO"
    else:
        assert result["policy"] == "SCHED_OTHER" and "CAP_SYS_NICE" in caplog.text
    assert TP.current_policy() == "SCHED_OTHER"  # the main thread is untouched


def test_refusal_is_logged_not_raised(monkeypatch, caplog):
    def deny(*_args):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", deny)
    with caplog.at_level(logging.WARNING):
        assert TP.raise_thread_priority() is False
    assert "RestrictRealtime=no" in caplog.text
    with pytest.raises(ValueError):
        TP.raise_thread_priority(0)

"""`avard run` under the unit's own seccomp lines: a unit edit that would abort libzmq fails here.

Issue #17: the unit passed `systemd-analyze verify` and the offline security rating, yet under a
real systemd libzmq aborted 0.6 s after every start, because SystemCallFilter= refused
sched_setscheduler and RestrictAddressFamilies= refused AF_NETLINK. Here the unit's
SystemCallFilter=, SystemCallErrorNumber=, RestrictAddressFamilies=, RestrictRealtime= and
MemoryDenyWriteExecute= are applied with libseccomp to `avard run --simulate quiet-lab
--duration 5`, as systemd would apply them, in seconds and without systemd. The two lines of
the unit before the fix are kept as cases: each must make the same run abort, the way it did
under systemd, which is what shows this check can catch the mistake.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from .sandbox import missing_tools, spec_from_unit, syscall_filter, wrap
from .unit_file import UNIT, Unit, parse_unit, scratch_config

VENV_AVARD = Path(sys.executable).with_name("avard")

# The unit's lines before issue #17, kept so that the check is shown to catch them.
OLD_SYSCALL_FILTER = [
    "@system-service",
    "~@privileged @resources @mount @swap @reboot @raw-io @module @obsolete @cpu-emulation "
    "@debug @clock",
]
OLD_FAMILIES = ["AF_UNIX AF_INET AF_INET6"]


@pytest.fixture(scope="module")
def tools() -> None:
    reason = missing_tools()
    if reason is None:
        return
    if os.environ.get("CI") == "true":
        pytest.fail(f"CI must run the seccomp check: {reason}")
    pytest.skip(reason)


@pytest.fixture(scope="module")
def unit() -> Unit:
    return parse_unit(UNIT.read_text())


def _run_sandboxed(unit: Unit, tmp_path: Path) -> subprocess.CompletedProcess[str]:
    spec_path = tmp_path / "seccomp.json"
    spec_path.write_text(json.dumps(spec_from_unit(unit)))
    argv = [str(VENV_AVARD), "run", "--config", str(scratch_config(tmp_path)),
            "--simulate", "quiet-lab", "--duration", "5"]
    return subprocess.run(wrap(spec_path, argv), cwd=tmp_path, capture_output=True, text=True,
                          timeout=120, env=dict(os.environ, PYTHONDONTWRITEBYTECODE="1"))


def _with(unit: Unit, **service: list[str]) -> Unit:
    changed = {section: dict(keys) for section, keys in unit.items()}
    changed["Service"].update(service)
    return changed


def test_the_filter_is_the_units_own(tools, unit):
    # The expansion is systemd's: the shipped filter allows the call libzmq needs, refuses the
    # rest of @resources, and the old filter refused it (what broke the start).
    allow_list, allowed = syscall_filter(unit["Service"]["SystemCallFilter"])
    assert allow_list and "sched_setscheduler" in allowed
    assert {"setpriority", "sched_setaffinity", "setrlimit", "reboot", "mount"}.isdisjoint(allowed)
    _, old_allowed = syscall_filter(OLD_SYSCALL_FILTER)
    assert allowed - old_allowed == {"sched_setscheduler"}


def test_avard_runs_under_the_shipped_units_seccomp_lines(tools, unit, tmp_path):
    proc = _run_sandboxed(unit, tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert list((tmp_path / "data").glob("*.avr")), "no recording written"


def test_the_old_syscall_filter_aborts_libzmq(tools, unit, tmp_path):
    proc = _run_sandboxed(_with(unit, SystemCallFilter=OLD_SYSCALL_FILTER), tmp_path)
    assert proc.returncode == -signal.SIGABRT, proc.stderr[-3000:]
    assert re.search(r"Operation not permitted \(.*thread\.cpp:\d+\)", proc.stderr), proc.stderr


def test_the_old_address_families_abort_libzmq(tools, unit, tmp_path):
    proc = _run_sandboxed(_with(unit, RestrictAddressFamilies=OLD_FAMILIES), tmp_path)
    assert proc.returncode == -signal.SIGABRT, proc.stderr[-3000:]
    assert re.search(r"Address family not supported by protocol \(.*ip_resolver\.cpp:\d+\)",
                     proc.stderr), proc.stderr

"""A unit's seccomp settings as seccomp_exec.py applies them, expanded by systemd's own tables.

The @sets (@system-service, @resources, ...) are expanded with `systemd-analyze syscall-filter`,
so the lists are the ones the installed systemd would load, never a copy kept in the tests.
"""

from __future__ import annotations

import ctypes.util
import errno
import functools
import shutil
import subprocess
import sys
from pathlib import Path

from .unit_file import Unit

SECCOMP_EXEC = Path(__file__).with_name("seccomp_exec.py")


def missing_tools() -> str | None:
    """Why the unit's sandbox cannot be applied here, or None when it can."""
    if shutil.which("systemd-analyze") is None:
        return "systemd-analyze not installed (apt-get install systemd)"
    if ctypes.util.find_library("seccomp") is None:
        return "libseccomp.so.2 not found (apt-get install libseccomp2)"
    return None


@functools.cache
def expand(name: str) -> frozenset[str]:
    """System calls named by `name`: a single call, or an @set expanded recursively."""
    if not name.startswith("@"):
        return frozenset({name})
    proc = subprocess.run(
        ["systemd-analyze", "syscall-filter", "--no-pager", name],
        capture_output=True, text=True, check=True,
    )
    lines = proc.stdout.splitlines()
    assert lines and lines[0].strip() == name, f"unexpected syscall-filter output:\n{proc.stdout}"
    calls: set[str] = set()
    for line in lines[1:]:
        entry = line.strip()
        if entry and not entry.startswith("#"):
            calls |= expand(entry)
    return frozenset(calls)


def syscall_filter(lines: list[str]) -> tuple[bool, frozenset[str]]:
    """(allow_list, names) from SystemCallFilter= lines, applied in order as systemd does.

    The first line decides: without '~' it is an allow list (systemd then adds @default, the
    calls every program needs) and later '~' lines remove from it, later plain lines add back;
    with '~' it is a deny list and the roles swap (systemd.exec(5), SystemCallFilter=)."""
    allow_list = not lines[0].startswith("~")
    names: set[str] = set(expand("@default")) if allow_list else set()
    for line in lines:
        invert = line.startswith("~")
        for item in line.lstrip("~").split():
            if invert == allow_list:
                names -= expand(item)
            else:
                names |= expand(item)
    return allow_list, frozenset(names)


def spec_from_unit(unit: Unit) -> dict[str, object]:
    """What seccomp_exec.py installs for the unit's [Service] section."""
    svc = unit["Service"]
    spec: dict[str, object] = {}
    if svc.get("SystemCallFilter"):
        allow_list, names = syscall_filter(svc["SystemCallFilter"])
        code_name = svc.get("SystemCallErrorNumber", [""])[-1]
        spec["syscalls"] = {
            "allow_list": allow_list,
            "names": sorted(names),
            "errno": getattr(errno, code_name) if code_name else None,
        }
    if svc.get("RestrictAddressFamilies"):
        families = svc["RestrictAddressFamilies"][-1]
        assert not families.startswith("~"), "only allow lists of families are handled"
        spec["families_allowed"] = families.split()
    spec["restrict_realtime"] = svc.get("RestrictRealtime", ["no"])[-1] == "yes"
    spec["memory_deny_write_execute"] = svc.get("MemoryDenyWriteExecute", ["no"])[-1] == "yes"
    return spec


def wrap(spec_path: Path, argv: list[str]) -> list[str]:
    """argv run under the sandbox described by the JSON file at spec_path."""
    return [sys.executable, str(SECCOMP_EXEC), str(spec_path), *argv]

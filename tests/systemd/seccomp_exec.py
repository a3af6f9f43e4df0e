"""Apply a systemd unit's seccomp settings to this process, then exec a command under them.

    python seccomp_exec.py SPEC.json COMMAND [ARG...]

SPEC (written by tests/systemd/sandbox.py from the unit's own lines) holds what systemd would
install before exec: the system-call allow list with its errno (SystemCallFilter=,
SystemCallErrorNumber=), the allowed socket families (RestrictAddressFamilies=),
RestrictRealtime= and MemoryDenyWriteExecute=. Each becomes its own seccomp filter, stacked
as systemd stacks them; the kernel applies the most restrictive answer of all of them.

libseccomp is used through ctypes (libseccomp.so.2, which systemd itself links against), so
the check needs no Python package beyond the standard library. Standalone on purpose: it runs
as a separate interpreter and must not import the package under test.
"""

from __future__ import annotations

import ctypes
import errno
import json
import os
import socket
import sys

SCMP_ACT_ALLOW = 0x7FFF0000
SCMP_ACT_KILL_PROCESS = 0x80000000
SCMP_CMP_EQ = 4
SCMP_CMP_GE = 5
SCMP_CMP_GT = 6
NR_SCMP_ERROR = -1
AF_MAX = 46  # include/linux/socket.h (Linux 6.x): families at or above it do not exist
SCHED_FIFO, SCHED_RR, SCHED_IDLE = 1, 2, 5
PR_SET_MDWE, PR_MDWE_REFUSE_EXEC_GAIN = 65, 1


def act_errno(number: int) -> int:
    """SCMP_ACT_ERRNO(x) from seccomp.h: fail the call with errno x."""
    return 0x00050000 | (number & 0x0000FFFF)


class ArgCmp(ctypes.Structure):
    """struct scmp_arg_cmp (seccomp.h): one comparison on one system-call argument."""

    _fields_ = [("arg", ctypes.c_uint), ("op", ctypes.c_int),
                ("datum_a", ctypes.c_uint64), ("datum_b", ctypes.c_uint64)]


class SeccompError(OSError):
    """A libseccomp call failed (it returns -errno)."""


class Filter:
    """One seccomp filter: a default action and rules, loaded into the kernel by load()."""

    def __init__(self, lib: ctypes.CDLL, default_action: int) -> None:
        self._lib = lib
        self.default_action = default_action
        self._ctx = lib.seccomp_init(ctypes.c_uint32(default_action))
        if not self._ctx:
            raise SeccompError(errno.ENOMEM, "seccomp_init failed")

    def rule(self, action: int, syscall: str, *cmps: tuple[int, int, int]) -> bool:
        """Add `action` for `syscall` when every (arg, op, value) holds; False if the name is
        unknown to this architecture's libseccomp (systemd skips those the same way)."""
        number = self._lib.seccomp_syscall_resolve_name(syscall.encode())
        if number == NR_SCMP_ERROR:
            return False
        array = (ArgCmp * max(1, len(cmps)))(*[ArgCmp(a, op, v, 0) for a, op, v in cmps])
        rc = self._lib.seccomp_rule_add_array(self._ctx, ctypes.c_uint32(action), number,
                                              len(cmps), array)
        # A pseudo-number (negative) is a call this architecture does not have: nothing to do.
        if rc < 0 and number >= 0:
            raise SeccompError(-rc, f"seccomp_rule_add({syscall}): {os.strerror(-rc)}")
        return rc == 0

    def load(self) -> None:
        rc = self._lib.seccomp_load(self._ctx)
        if rc < 0:
            raise SeccompError(-rc, f"seccomp_load: {os.strerror(-rc)}")


def load_libseccomp() -> ctypes.CDLL:
    lib = ctypes.CDLL("libseccomp.so.2", use_errno=True)
    lib.seccomp_init.restype = ctypes.c_void_p
    lib.seccomp_init.argtypes = [ctypes.c_uint32]
    lib.seccomp_syscall_resolve_name.restype = ctypes.c_int
    lib.seccomp_syscall_resolve_name.argtypes = [ctypes.c_char_p]
    lib.seccomp_rule_add_array.restype = ctypes.c_int
    lib.seccomp_rule_add_array.argtypes = [ctypes.c_void_p, ctypes.c_uint32, ctypes.c_int,
                                           ctypes.c_uint, ctypes.POINTER(ArgCmp)]
    lib.seccomp_load.restype = ctypes.c_int
    lib.seccomp_load.argtypes = [ctypes.c_void_p]
    return lib


def apply(spec: dict[str, object]) -> None:
    """Install every filter of `spec` on this process (and, through exec, its successor)."""
    if spec.get("memory_deny_write_execute"):
        # The kernel's own W^X rule (Linux ≥ 6.3) does what systemd's mmap/mprotect filter does.
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(PR_SET_MDWE, PR_MDWE_REFUSE_EXEC_GAIN, 0, 0, 0) != 0:
            code = ctypes.get_errno()
            if code != errno.EINVAL:
                raise OSError(code, "prctl(PR_SET_MDWE)")
            # Linux < 6.3: the system-call filters still apply; say what is not checked.
            print("seccomp_exec: no PR_SET_MDWE in this kernel, W^X not enforced",
                  file=sys.stderr)
    lib = load_libseccomp()
    filters: list[Filter] = []

    calls = spec.get("syscalls")
    if isinstance(calls, dict):
        # SystemCallFilter=: an allow list (everything else refused) or a deny list; refused
        # calls fail with SystemCallErrorNumber=, or kill the process when it is not set.
        code = calls.get("errno")
        refuse = act_errno(int(code)) if isinstance(code, int) else SCMP_ACT_KILL_PROCESS
        allow_list = bool(calls["allow_list"])
        flt = Filter(lib, refuse if allow_list else SCMP_ACT_ALLOW)
        for name in calls["names"]:
            flt.rule(SCMP_ACT_ALLOW if allow_list else refuse, str(name))
        filters.append(flt)

    families = spec.get("families_allowed")
    if isinstance(families, list):
        # RestrictAddressFamilies= as an allow list: socket() of any other family fails with
        # EAFNOSUPPORT, which is what an application sees under systemd.
        allowed = {int(getattr(socket, str(name))) for name in families}
        net = Filter(lib, SCMP_ACT_ALLOW)
        refuse = act_errno(errno.EAFNOSUPPORT)
        for family in range(AF_MAX):
            if family not in allowed:
                net.rule(refuse, "socket", (0, SCMP_CMP_EQ, family))
        net.rule(refuse, "socket", (0, SCMP_CMP_GE, AF_MAX))
        filters.append(net)

    if spec.get("restrict_realtime"):
        # RestrictRealtime=yes: no SCHED_FIFO, SCHED_RR, nor any policy above SCHED_IDLE
        # (SCHED_DEADLINE, or a policy with SCHED_RESET_ON_FORK or'ed in).
        rt = Filter(lib, SCMP_ACT_ALLOW)
        for cmp in ((1, SCMP_CMP_EQ, SCHED_FIFO), (1, SCMP_CMP_EQ, SCHED_RR),
                    (1, SCMP_CMP_GT, SCHED_IDLE)):
            rt.rule(act_errno(errno.EPERM), "sched_setscheduler", cmp)
        filters.append(rt)

    # The system-call list goes in last: it may refuse seccomp() itself, as it does under
    # systemd, which also loads that filter after the others.
    for flt in reversed(filters):
        flt.load()


def main(argv: list[str]) -> None:
    if len(argv) < 3:
        sys.exit("usage: seccomp_exec.py SPEC.json COMMAND [ARG...]")
    with open(argv[1], encoding="utf-8") as fh:
        spec = json.load(fh)
    apply(spec)
    os.execv(argv[2], argv[2:])


if __name__ == "__main__":
    main(sys.argv)

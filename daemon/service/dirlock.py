"""One service per recording directory: an exclusive ``flock`` on ``.avard.lock`` in it.

Two services recording into one directory (a manual ``avard run`` beside the unit, with the
unit's config) both took the same run sequence number, both continued the sample index from
the same end of the recording, wrote the same indices twice with different samples and
replaced each other's state file: the recording then held two streams under one index, and
on hardware the second one's start-up reset the first one's sensor. The second process now
stops before it opens the sensor, with one line naming the process that records there, and
exit status 2.

The lock belongs to the open file, so the kernel drops it when the process ends however it
ends (SIGKILL, a power cut): a stale lock file never keeps a restart out. It is held from
before the rig is opened (``avard run``) until the service has stopped; within one process
it is counted (the command and the service it starts both hold it).
"""

from __future__ import annotations

import errno
import fcntl
import logging
import os
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from avard.core.errors import ConfigError

LOCK_FILE = ".avard.lock"

log = logging.getLogger(__name__)

_guard = threading.Lock()
#: directory → [fd, holders in this process, times its lock file was locked again]
_held: dict[Path, list[int]] = {}


def _key(directory: Path) -> Path:
    return Path(os.path.realpath(directory))


#: What a refused process is told to do, by the option that named the directory.
SERVICE_ADVICE = ("stop it (systemctl stop avard) or give this one another data directory "
                  "(--data-dir)")


def hold(directory: str | Path, *, what: str = "recording.data_dir =",
         advice: str = SERVICE_ADVICE) -> Path:
    """Lock ``directory`` (made if missing) for this process, or raise ConfigError naming
    the process that holds it (``what``: the setting that named the directory, ``advice``:
    what to do). Returns the key to :func:`release` it with."""
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    key = _key(d)
    with _guard:
        if key in _held:
            # held by this process already (``avard run`` holds it from before the rig is
            # opened, the service again at its start): the directory may have been removed
            # and made again in between, while nothing was written, and another process
            # may have locked the new one; the second hold checks, as the recorder does
            lost = _recheck(key, d)
            if lost is not None:
                raise ConfigError(f"{what} {str(d)!r}: {lost}; {advice}")
            _held[key][1] += 1
            return key
        path = key / LOCK_FILE
        try:
            fd, writable = _open(path)
        except OSError as exc:
            if exc.errno in (errno.ENOSPC, errno.EDQUOT):
                # a full disk at the very first start: the service records nothing until
                # space returns anyway, and it must start to say so (and be restarted);
                # exit status 2 would keep systemd from ever restarting it
                log.warning("cannot create %s in %s (%s); running without the one-service "
                            "lock", LOCK_FILE, d, exc.strerror)
                _held[key] = [-1, 1, 0]
                return key
            raise ConfigError(f"{what} {str(d)!r}: cannot open its lock file "
                              f"{LOCK_FILE} ({exc.strerror})") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            other = _holder(fd)
            os.close(fd)
            if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise ConfigError(f"{what} {str(d)!r}: cannot lock it "
                                  f"({exc.strerror})") from None
            raise ConfigError(
                f"{what} {str(d)!r}: another avard process"
                f"{f' (pid {other})' if other else ''} is recording there; {advice}") from None
        _note_pid(fd, writable, d)
        _held[key] = [fd, 1, 0]
        return key


def recheck(directory: str | Path) -> str | None:
    """Whether this process still holds ``directory``'s lock: None when it does (or holds
    none there), else why not, for the recorder to pause on.

    The lock is on an open file, not on a name: with the directory removed (``rm -r``) and
    made again (the recorder does, to go on recording), this process still held the old,
    deleted file, and a second service took a lock on the new one: two services in one
    directory. The recorder calls this whenever it opens a segment: the file at the lock's
    name is not the one held, so it is locked again; if another process has locked it
    meanwhile, that one records there now and this one must not write beside it."""
    key = _key(Path(directory))
    with _guard:
        return _recheck(key, directory)


def _recheck(key: Path, directory: str | Path) -> str | None:
    """:func:`recheck` with ``_guard`` held."""
    entry = _held.get(key)
    if entry is None or entry[0] < 0:
        return None
    path = key / LOCK_FILE
    try:
        held, now = os.fstat(entry[0]), os.stat(path, follow_symlinks=False)
        if (held.st_dev, held.st_ino) == (now.st_dev, now.st_ino):
            return None
    except FileNotFoundError:
        pass
    except OSError as exc:
        return f"cannot check the lock file {path} ({exc.strerror})"
    try:
        fd, writable = _open(path)
    except OSError as exc:
        return f"cannot open the lock file {path} again ({exc.strerror})"
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as exc:
        other = _holder(fd)
        os.close(fd)
        return (f"{LOCK_FILE} in {str(directory)!r} was replaced (the directory removed "
                f"and made again?) and another avard process"
                f"{f' (pid {other})' if other else ''} has locked it ({exc.strerror}): "
                "it records there now; this one does not write beside it")
    _note_pid(fd, writable, directory)
    os.close(entry[0])
    entry[0] = fd
    entry[2] += 1
    log.warning("%s in %s was gone or replaced (the directory removed?); locked it again",
                LOCK_FILE, directory)
    return None


def generation(directory: str | Path) -> int:
    """How many times this process has locked ``directory``'s lock file again (:func:`recheck`
    found it gone or replaced): a writer that opened a file there under an earlier count
    holds it in a directory that is no longer the one at the path (moved away, removed)."""
    key = _key(Path(directory))
    with _guard:
        entry = _held.get(key)
        return entry[2] if entry is not None else 0


def release(key: Path) -> None:
    """Drop one hold of :func:`hold`; the last one unlocks (the file stays: removing it
    could race with another process that just opened it)."""
    with _guard:
        entry = _held.get(key)
        if entry is None:
            return
        entry[1] -= 1
        if entry[1] == 0:
            del _held[key]
            if entry[0] >= 0:
                os.close(entry[0])


@contextmanager
def held(directory: str | Path, **how: str) -> Iterator[Path]:
    key = hold(directory, **how)
    try:
        yield key
    finally:
        release(key)


def _open(path: Path) -> tuple[int, bool]:
    """The lock file opened (made if missing), and whether it could be opened for writing.

    A lock file this user may not write (left root-owned 0644 by a manual ``sudo avard
    run``) made the unit (User=avard) exit 2, which RestartPreventExitStatus keeps down for
    good. flock needs only an open file: read-only will do, only the pid note for a refused
    process is not written then (it names the holder from /proc/locks, :func:`_holder`)."""
    try:
        return os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC | os.O_NOFOLLOW, 0o644), True
    except PermissionError:
        return os.open(path, os.O_RDONLY | os.O_CLOEXEC | os.O_NOFOLLOW), False


def _note_pid(fd: int, writable: bool, directory: str | Path) -> None:
    if not writable:
        log.warning("%s in %s is not writable by this user (left by a run as another "
                    "user?): locked read-only, without this process's pid in it",
                    LOCK_FILE, directory)
        return
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
    except OSError:
        pass                # the pid is only for the message of a refused process


def _holder(fd: int) -> int | None:
    """The pid holding the lock on ``fd``'s file: the kernel's (/proc/locks) first, since
    a holder that could only open the file read-only wrote none and the note may be an
    older process's; else the pid the holder wrote into the file."""
    try:
        st = os.fstat(fd)
        where = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}"
        with open("/proc/locks") as f:
            for line in f:
                parts = line.split()
                if len(parts) >= 6 and parts[1] == "FLOCK" and parts[5] == where \
                        and parts[4].isdigit():
                    return int(parts[4])
    except OSError:
        pass
    try:
        text = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
        return int(text) if text.isdigit() else None
    except OSError:
        return None

"""The one exception root of avard, and its specific subclasses.

Every error a user can cause (bad data, a bad config, a missing sensor, a corrupt file) is an
``AvardError`` whose message names what is wrong and what to do about it. The command line turns
it into a one-line message and a non-zero exit; the service logs it.
"""


class AvardError(Exception):
    """Root of every error avard raises on purpose."""

    #: The command line's exit status for it: 2, "you must fix something" (the unit's
    #: RestartPreventExitStatus=2 keeps such a service down instead of looping).
    exit_status = 2


class ServiceFault(AvardError):
    """A part of the running service failed on its own (a worker thread died): nothing the
    user must fix, so the exit status is 70 (EX_SOFTWARE), which systemd's Restart=on-failure
    restarts; the restart is a recorded gap."""

    exit_status = 70


class DataError(AvardError, ValueError):
    """Input arrays or measured-data files that cannot be used (shape, NaN, rate, too short)."""


class FormatError(AvardError):
    """A recording, frame or message that does not decode (corrupt, truncated, wrong version)."""


class ConfigError(AvardError):
    """A configuration key that is unknown, of the wrong type or out of range."""


class FitError(AvardError):
    """A noise-model fit that cannot be made from the data given."""


class HardwareError(AvardError):
    """A bus or device problem: no device, wrong device, bus errors."""


class SensorMissingError(HardwareError):
    """A sensor that was expected and is not there."""


class BusError(HardwareError):
    """A transfer on the SPI or I2C bus failed (OSError from the kernel, e.g. EIO)."""

    def __init__(self, message: str, errno: int | None = None) -> None:
        super().__init__(message)
        self.errno = errno


class DeviceStalledError(HardwareError):
    """The device answers on the bus but has stopped producing samples."""


class NetworkError(AvardError):
    """A ZeroMQ peer that does not answer, refuses us, or answers with an error."""


class OutputError(AvardError):
    """An output path that cannot be written (missing folder, no permission, unknown suffix,
    no space), found before the work that would fill it starts."""


def describe_os_error(exc: OSError) -> str:
    """One line for an ``OSError`` from the file system: the file it concerns, what happened
    and what to do. Used by the command line for every ``OSError`` no command turned into an
    ``AvardError`` itself, so that none ends in a traceback."""
    import errno

    name = "" if exc.filename is None else f"{exc.filename}: "
    if exc.filename2 is not None:
        name = f"{exc.filename} → {exc.filename2}: "
    what = exc.strerror or str(exc)
    advice = {
        errno.EACCES: "run as a user allowed to use it (for the service's recordings: a "
                      "member of group avard, or sudo), or choose another path",
        errno.EPERM: "run as a user allowed to use it, or choose another path",
        errno.ENOENT: "check the path; a folder to write into must exist first",
        errno.ENOTDIR: "a part of the path is a file, not a folder; check the path",
        errno.EISDIR: "give a file name, not a folder",
        errno.ENOSPC: "free some space on that disk, or write somewhere else",
        errno.EDQUOT: "your disk quota is used up; free some space or write somewhere else",
        errno.EROFS: "that file system is mounted read-only; write somewhere else",
        errno.EEXIST: "remove it or choose another name",
        errno.ENAMETOOLONG: "use a shorter path",
        errno.EMFILE: "too many open files; raise the limit (ulimit -n) and try again",
        errno.EIO: "the storage reported an input/output error; check the disk (dmesg)",
        errno.ECONNREFUSED: "nothing listens there; check the address and that the service runs",
        errno.EHOSTUNREACH: "the host cannot be reached; check the address and the network",
        errno.ENETUNREACH: "the network cannot be reached; check the address and the network",
        errno.ETIMEDOUT: "no answer in time; check the address and the network",
    }.get(exc.errno if exc.errno is not None else -1,
          "check the path and its permissions")
    return f"{name}{what}; {advice}"

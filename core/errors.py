"""The one exception root of avard, and its specific subclasses.

Every error a user can cause (bad data, a bad config, a missing sensor, a corrupt file) is an
``AvardError`` whose message names what is wrong and what to do about it. The command line turns
it into a one-line message and a non-zero exit; the service logs it.
"""


class AvardError(Exception):
    """Root of every error avard raises on purpose."""


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

"""avard.daemon: drivers, the emulator, the acquisition service and the ``avard`` command line.

Importing this package never touches hardware: buses are opened only when a device is.
"""

__version__ = "0.1.0"

"""The acquisition service behind ``avard run``, as a pipeline of parts that each own one
thing and are handed what they need:

- ``supervisor.py``  :class:`Service`: builds the parts, start/stop order, sd_notify, signals,
  watchdog, duration;
- ``stage.py``       a ring consumer thread woken by work (the base of the three stages);
- ``allan_stage.py`` streaming Allan accumulators, snapshots and checkpoints (outbound marks);
- ``recorder_stage.py`` the segment files;
- ``publisher_stage.py`` the PUB socket and the request handlers;
- ``header.py``      the run's header record, shared by recorder, publisher and requests;
- ``checkpoint.py``  the state file and the restore at start-up.

The reader thread is daemon/acquisition.py, the ring daemon/ring.py, the fits of snapshots
daemon/snapshots.py. The wire format is docs/wire-format.md, the design docs/service.md.
"""

from .checkpoint import STATE_FILE
from .supervisor import Service

__all__ = ["STATE_FILE", "Service"]

"""The acquisition service behind ``avard run``, as a pipeline of parts that each own one
thing and are handed what they need:

- ``supervisor.py``  :class:`Service`: builds the parts, start/stop order, sd_notify, signals,
  watchdog, duration;
- ``stage.py``       a ring consumer thread woken by work (the base of the three stages);
- ``allan_stage.py`` streaming Allan accumulators, snapshots and checkpoints (outbound marks);
- ``recorder_stage.py`` the segment files;
- ``publisher_stage.py`` the PUB socket and the request handlers;
- ``header.py``      the run's header record, shared by recorder, publisher and requests;
- ``checkpoint.py``  the state file and the restore at start-up;
- ``acquisition.py`` the reader thread (FIFO drain into the ring), paced by hw/pacing.py;
- ``ring.py``        the sample ring the stages block on;
- ``recorder.py``    the crash-safe segment writer (also used by ``avard record``);
- ``snapshots.py``   the one snapshot fit (service, ``avard watch``, ``avard web``);
- ``sdnotify.py``, ``stop_signals.py``, ``logfmt.py``: systemd and process plumbing
  (``daemon/blas_threads.py`` stays outside: it must run before anything imports numpy).

The service is handed a built rig (daemon/hw/rig.py) by the composition root,
daemon/compose.py. The wire format is docs/wire-format.md, the design docs/service.md. This
package imports nothing itself: ``avard`` loads ``logfmt`` and ``stop_signals`` before numpy
is imported.
"""

"""``avard web``: a live, read-only browser view of a running service.

A separate process (never inside the hardened service) that subscribes over ZeroMQ with the
same :class:`avard.daemon.net.subscriber.Subscriber` as ``avard watch``, keeps the run's history
(:mod:`.state`), draws it as SVG on the server (:mod:`.render`), and serves the page, its
server-sent-event updates and ``/metrics`` (:mod:`.app`, :mod:`.metrics`). Needs the ``web``
extra (aiohttp).
"""

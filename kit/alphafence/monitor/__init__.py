"""The in-flight companion: samples from the vehicle in, events and actions out.

The engine (``engine``, ``engine_reroute``: no I/O; what it reads of its surroundings is in
:mod:`alphafence.awareness`), what it may do (``options``), its events (``events``) and the
vehicle's own fence as a layer (``onboard``); on the vehicle link: ``feeds`` (one async
generator per stream), ``commands`` (actions and alerts), ``reroute`` and ``reroute_flight``
(re-routes planned and flown), ``rolling`` (the onboard fence re-uploaded in flight),
``eventlog`` and ``tlog`` (the logs), ``observe`` (the public hook for observers),
``runner`` (the :class:`~alphafence.monitor.runner.Monitor` wiring them together) and ``run``.
"""

"""The companion monitor: full-resolution fences checked against telemetry, breaches
predicted before they happen.

The pure parts, tested and replayed without a vehicle: ``fenceset`` (the fence index),
``applicability`` (ED-269 time windows), ``predict`` (stopping distance, closest approach),
``state`` (alert levels with hysteresis), ``traffic`` (other aircraft), ``options``,
``events`` (every event built one way), ``onboard`` (the fence the vehicle itself holds, as a
layer of its own) and ``engine`` (samples in, events out); ``reroute`` plans re-routes. The async parts on a MAVSDK connection: ``feeds`` (one generator per
stream), ``commands`` (actions and alerts to the vehicle), ``reroute_flight`` (flying a
re-route), ``eventlog`` (the JSON-lines log), ``observe`` (the public hook for observers) and
``runner`` (the :class:`~alphafence.monitor.runner.Monitor` wiring them together).
"""

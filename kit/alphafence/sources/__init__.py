"""Live sources of zones: an OGC API - Features collection asked over HTTP (``ogc``), its
answers read as zones (``answers``), and a PostGIS table written for such a service to serve
(``postgis``). A source's answer is never trusted to remove what is in force: that is the
monitor's rule (:mod:`alphafence.monitor.live_zones`)."""

"""Flights and missions looked at away from the vehicle: a flight log checked against the
fences (``check-flight``), a mission's legs at their altitudes (``check-mission``), recorded
traces replayed through the engine (at once, or in real time for the live map), and the
demo's recorded SITL flight."""

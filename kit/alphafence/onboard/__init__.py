"""Compiling fences into a vehicle's fence storage."""

HOME_CLEARANCE_M = 25.0  # no compiled keep-out item comes nearer home (or the vehicle) than this

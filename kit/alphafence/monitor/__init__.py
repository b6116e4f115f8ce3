"""The companion monitor: full-resolution fences checked against telemetry, breaches
predicted before they happen. This package holds the pure parts (fence index, prediction,
state machine, traffic); the async MAVSDK controller builds on them."""

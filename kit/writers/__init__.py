"""Fence outputs: GeoJSON (lon, lat), QGroundControl .plan and ArduPilot fence waypoints
(lat, lon). Coordinate order is converted in kit.coords only."""

"""The kit's fence files, written and read back: fence GeoJSON and its sequences, GeoParquet,
QGroundControl plans, WPL ``.waypoints`` and ArduPilot's legacy fence text; any of them (and
KML or OpenAir zones) read as fences; every write all or nothing."""

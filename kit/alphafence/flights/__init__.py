"""Missions and flight logs: missions read as the positions they fly through and as the items
an upload sends, flown as ArduPilot flies them; DataFlash (``.BIN``) and telemetry (``.tlog``)
logs read as tracks."""

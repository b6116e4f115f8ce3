"""ArduPilot / MAVProxy fence files in the QGC WPL 110 text format (lat, lon order).

Each line: seq, current, frame, command, param1..4, lat, lon, alt, autocontinue, tab separated.
Fence items use frame 0 (MAV_FRAME_GLOBAL), as ArduPilot reports them.
"""

from __future__ import annotations

HEADER = "QGC WPL 110"
FRAME_GLOBAL = 0


def waypoints_text(items) -> str:
    lines = [HEADER]
    for seq, it in enumerate(items):
        fields = [
            str(seq),
            "0",
            str(FRAME_GLOBAL),
            str(it.command),
            f"{it.param1:.6f}",
            "0.000000",
            "0.000000",
            "0.000000",
            f"{it.lat:.8f}",
            f"{it.lon:.8f}",
            "0.000000",
            "1",
        ]
        lines.append("\t".join(fields))
    return "\n".join(lines) + "\n"

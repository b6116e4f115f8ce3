"""The live map in a real browser (Debian's headless Chromium): during `alphafence demo --replay
--map-server`, the vehicle's marker moves and the IMMINENT event the replay raises appears."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.browser

pytest.importorskip("aiohttp", reason="needs aiohttp (the map extra)")

ROOT = Path(__file__).resolve().parents[1]
ALPHAFENCE = Path(sys.executable).parent / "alphafence"
DEADLINE_S = 120.0
STATE = (
    "var l = window.afLive; if (!l || !l.vehicle) return null;"
    "var p = l.marker.getLatLng();"
    "return {lat: p.lat, lng: p.lng, positions: l.positions, connected: l.connected,"
    " fences: l.fences, onboard: l.onboard,"
    " levels: l.events.filter(function (e) { return e.event === 'level'; })"
    ".map(function (e) { return e.level; }),"
    " shown: Array.from(document.querySelectorAll('.af-event')).map(e => e.innerText)};"
)


def _wait(what, probe):
    """Poll ``probe()`` until it returns something true; fail naming ``what`` at the deadline."""
    end = time.monotonic() + DEADLINE_S
    while True:
        got = probe()
        if got:
            return got
        assert time.monotonic() < end, f"never: {what}"
        time.sleep(0.05)


def test_the_live_map_shows_the_replayed_vehicle_moving_and_the_imminent_event(
    local_browser, tmp_path
):
    demo = subprocess.Popen(
        [str(ALPHAFENCE), "demo", "--replay", "--map-server", "127.0.0.1:0", "-o", "out"],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    lines = []
    reader = threading.Thread(target=lambda: lines.extend(demo.stdout), daemon=True)
    reader.start()
    try:
        url = _wait(
            "the map's URL printed",
            lambda: (
                demo.poll() is None
                and next(
                    (m.group(1) for m in map(re.compile(r"live map: (\S+)").search, lines) if m),
                    None,
                )
            ),
        )
        assert url.startswith("http://127.0.0.1:") and "token" not in url
        local_browser.get(url)
        first = _wait("the vehicle on the map", lambda: local_browser.execute_script(STATE))
        assert first["connected"] and first["fences"] > 0 and first["onboard"] > 0
        imminent = _wait(
            "the IMMINENT event",
            lambda: (s := local_browser.execute_script(STATE)) and "IMMINENT" in s["levels"] and s,
        )
        # the marker moved with the replayed positions, and the event is listed on the page
        assert (imminent["lat"], imminent["lng"]) != (first["lat"], first["lng"])
        assert imminent["positions"] > first["positions"]
        assert any("IMMINENT" in text for text in imminent["shown"])
        shots = os.environ.get("ALPHAFENCE_SHOTS")  # the docs' picture: run with it set
        picture = ROOT / "docs" / "live-map.png" if shots else tmp_path / "live-map.png"
        local_browser.save_screenshot(str(picture))
        assert picture.stat().st_size > 10_000
        _wait("the replay's end", lambda: any("the map stays up" in line for line in lines))
    finally:
        demo.send_signal(signal.SIGINT)
        code = demo.wait(timeout=60)
        reader.join(timeout=10)
    assert code == 0, "".join(lines)
    # the replayed flight was written as without the map
    assert (tmp_path / "out" / "events.jsonl").is_file()
    assert '"level": "IMMINENT"' in (tmp_path / "out" / "events.jsonl").read_text()

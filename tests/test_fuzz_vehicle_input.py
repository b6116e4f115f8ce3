"""What comes from the vehicle is input too: a faulty autopilot, a corrupted link or a hostile
transmitter must yield clean one-line errors (or be ignored), never a crash or a hang.

- Fence downloads from a scripted vehicle (tests/fake_vehicle.py) that claims absurd counts and
  sends items out of range, of other mission types, with bad vertex counts and NaN radii.
- hypothesis over the same decoding (``from_raw``), the signed link's frame parser, the
  monitor's ADS-B and GLOBAL_POSITION_INT parsers, and the engine's telemetry input.

`make test` runs a small sample; `make fuzz` many more (ALPHAFENCE_FUZZ_EXAMPLES)."""

from __future__ import annotations

import asyncio
import json
import math
import os
from types import SimpleNamespace

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as mav

from alphafence.awareness.fenceset import FenceSet
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.fencefiles.qgc_plan import group_polygons
from alphafence.mavlink.items import POLYGON_EXCLUSION
from alphafence.monitor.engine import Engine, MonitorOptions, Sample
from alphafence.monitor.feeds import parse_adsb, parse_global_position
from alphafence.vehicle.bridge import VehicleLink, signature_matches
from alphafence.vehicle.fence_transfer import FenceTransferError, download_fence, from_raw
from alphafence.vehicle.link import open_vehicle
from tests.fake_vehicle import FakeVehicle, Faults
from tests.test_upload_faults import NEW

N = int(os.environ.get("ALPHAFENCE_FUZZ_EXAMPLES", "60"))
FUZZ = settings(max_examples=N, deadline=None, suppress_health_check=list(HealthCheck))
KEY = bytes(range(7, 39))
INT32 = st.integers(-(2**31), 2**31 - 1)
ANY_FLOAT = st.floats(allow_nan=True, allow_infinity=True, width=32)


def one_line(exc) -> str:
    text = str(exc)
    assert text and "\n" not in text and len(text) < 600, text
    return text


# -- hostile downloads, end to end through each link ---------------------------------------------


@pytest.mark.parametrize(
    "faults, says",
    [
        # MAVSDK asks for every item and times out; the pymavlink link refuses the count
        (Faults(claim_count=65535), ("download failed", "sent 65535 fence items (over 8191")),
        (Faults(item_fields={1: {"x": 1_000_000_000}}), "item 1: position 100.0000000"),
        (Faults(item_fields={0: {"command": 16}}), "item 0: command 16 is not a fence item"),
        (Faults(item_fields={2: {"param1": 0.0}}), "item 2: polygon vertex count 0"),
        (
            Faults(item_fields={3: {"param1": 9.0}}),
            "item 3: a polygon of 8 vertices starting at item 0 is broken by",
        ),
        (Faults(item_fields={8: {"param1": math.nan}}), "item 8: parameter 1 is nan"),
        (Faults(item_fields={8: {"param1": -5.0}}), "item 8: circle radius -5"),
        (Faults(item_fields={4: {"mission_type": 0}}), ""),  # MAVSDK or the kit refuses it
    ],
)
async def test_hostile_download_is_a_clean_error(faults, says, link):
    async with FakeVehicle(fence=NEW, faults=faults) as fake:
        async with open_vehicle(fake.url, 10) as vehicle:
            # MAVSDK's own timeouts end it (no hang: the deadline only stops one)
            with pytest.raises(FenceTransferError) as err:
                await asyncio.wait_for(download_fence(vehicle), 60.0)
    says = (says,) if isinstance(says, str) else says
    assert any(s in one_line(err.value) for s in says), err.value


async def test_cli_download_writes_nothing_from_a_hostile_vehicle(tmp_path, capsys):
    from alphafence.cli import main

    out = tmp_path / "onboard.plan"
    faults = Faults(item_fields={2: {"param1": 0.0}})  # would loop forever grouping polygons
    async with FakeVehicle(fence=NEW, faults=faults) as fake:
        code = await asyncio.to_thread(main, ["download", "--connect", fake.url, "-o", str(out)])
    assert code == 3
    assert "polygon vertex count 0" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


# -- the decoding of downloaded items -------------------------------------------------------

raw_items = st.lists(
    st.builds(
        SimpleNamespace,
        seq=st.integers(0, 100),
        command=st.one_of(st.sampled_from([5000, 5001, 5002, 5003, 5004]), st.integers(0, 65535)),
        mission_type=st.one_of(st.just(1), st.integers(0, 255)),
        frame=st.integers(0, 255),
        param1=st.one_of(ANY_FLOAT, st.integers(0, 300).map(float)),
        x=INT32,
        y=INT32,
    ),
    max_size=30,
)


@FUZZ
@given(raw_items)
def test_from_raw_accepts_only_valid_fences(raw):
    try:
        items = from_raw(raw)
    except FenceTransferError as exc:
        one_line(exc)
        return
    for it in items:
        assert -90 <= it.lat <= 90 and -180 <= it.lon <= 180 and math.isfinite(it.param1)
    polygons, _ = group_polygons(items)  # terminates, and every polygon is whole
    for _command, vertices in polygons:
        assert len(vertices) >= 3


@FUZZ
@given(st.integers(0, 30), st.integers(0, 29), st.integers(3, 8))
def test_from_raw_keeps_every_valid_polygon(n_circles, where, n):
    good = [SimpleNamespace(command=POLYGON_EXCLUSION, mission_type=1, param1=float(n),
                            x=351234567 + i, y=144567890 + i) for i in range(n)]  # fmt: skip
    circles = [
        SimpleNamespace(command=5004, mission_type=1, param1=10.0 + i, x=0, y=i)
        for i in range(n_circles)
    ]
    where = min(where, len(circles))
    items = from_raw(circles[:where] + good + circles[where:])
    assert len(items) == n + n_circles
    assert [it.lat for it in items[where : where + n]] == [g.x / 1e7 for g in good]


# -- the signed link's parser ---------------------------------------------------------------


def _frames(key, count, timestamp=10**12):
    sender = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    sender.signing.secret_key, sender.signing.sign_outgoing = key, True
    sender.signing.timestamp = timestamp
    return [sender.heartbeat_encode(2, 3, 0, 0, 4).pack(sender) for _ in range(count)]


@FUZZ
@given(
    st.lists(
        st.one_of(
            st.binary(max_size=300),
            st.tuples(
                st.sampled_from(_frames(KEY, 3) + _frames(bytes(32 * [1]), 2)),
                st.integers(0, 40),
                st.integers(0, 255),
            ).map(
                lambda t: t[0][: t[1] % len(t[0])] + bytes([t[2]]) + t[0][t[1] % len(t[0]) + 1 :]
            ),
            st.sampled_from(_frames(KEY, 3)),
        ),  # fmt: skip
        max_size=12,
    ),
    st.booleans(),
)
def test_signed_link_parser_never_raises_and_passes_only_signed(chunks, verify):
    got = []
    link = VehicleLink("udpout://127.0.0.1:9", KEY, got.append, verify=verify)
    for chunk in chunks:
        link._received(chunk, ("127.0.0.1", 1))
    if verify:
        for msg in got:
            buf = bytes(msg.get_msgbuf())
            assert signature_matches(buf, KEY) or msg.get_msgId() in (109, 166)
    assert link.stats.received == len(got)


@FUZZ
@given(
    st.lists(st.sampled_from(["ours", "theirs", "unsigned"]), max_size=20),
    st.lists(st.integers(1, 200), max_size=6),
)
def test_signed_link_counts_every_whole_frame_where_it_belongs(kinds, cuts):
    """Whole frames, ours in order (each stamp newer), another key's and unsigned ones,
    in any order and cut into chunks anywhere: each is counted once, as what it is."""
    from alphafence.vehicle.keys import signing_timestamp

    ours = iter(_frames(KEY, 20, signing_timestamp() + 1000))
    theirs = iter(_frames(bytes(32 * [1]), 20, signing_timestamp() + 1000))
    sender = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    frames = [
        next(ours) if k == "ours" else next(theirs) if k == "theirs"
        else sender.heartbeat_encode(2, 3, 0, 0, 4).pack(sender)
        for k in kinds
    ]  # fmt: skip
    data = b"".join(frames)
    got = []
    link = VehicleLink("udpout://127.0.0.1:9", KEY, got.append, verify=True)
    at = 0
    for cut in cuts + [len(data)]:
        link._received(data[at : at + cut], ("127.0.0.1", 1))
        at += cut
    link._received(data[at:], ("127.0.0.1", 1))
    s = link.stats
    assert (s.received, s.bad_signature, s.unsigned, s.garbage) == (
        kinds.count("ours"), kinds.count("theirs"), kinds.count("unsigned"), 0,
    )  # fmt: skip
    assert len(got) == s.received


# -- the monitor's traffic parsers and engine ------------------------------------------------

json_numbers = st.one_of(
    st.integers(-(10**30), 10**30),
    ANY_FLOAT,
    st.floats(allow_nan=True),
    st.none(),
    st.text(max_size=4),
)
KEYS = ["lat", "lon", "altitude", "hor_velocity", "heading", "ver_velocity", "callsign",
        "ICAO_address", "alt", "vx", "vy", "vz"]  # fmt: skip
VALID = {
    "lat": 359000000, "lon": 145000000, "altitude": 120000, "hor_velocity": 1500,
    "heading": 9000, "ver_velocity": -50, "callsign": "AB123", "ICAO_address": 4660,
    "alt": 120000, "vx": 300, "vy": -200, "vz": 10,
}  # fmt: skip
# a valid message with some fields replaced or dropped (so the arithmetic is reached), or any
adsb_fields = st.one_of(
    st.tuples(
        st.dictionaries(st.sampled_from(KEYS), json_numbers, max_size=4),
        st.sets(st.sampled_from(KEYS), max_size=2),
    ).map(lambda t: {k: v for k, v in {**VALID, **t[0]}.items() if k not in t[1]}),
    st.dictionaries(st.sampled_from(KEYS), json_numbers, max_size=12),
)


@FUZZ
@given(adsb_fields, st.integers(-5, 300))
def test_traffic_parsers_return_a_clean_report_or_none(fields, system_id):
    text = json.dumps(fields)  # NaN/Infinity as Python's json writes them
    for report in (parse_adsb(text), parse_global_position(system_id, text)):
        if report is None:
            continue
        assert -90 <= report["lat"] <= 90 and -180 <= report["lon"] <= 180
        for k in ("alt_amsl_m", "ve", "vn", "vu"):
            assert math.isfinite(report[k]), (k, report)


def _engine():
    import shapely

    from alphafence.geo.frame import LocalFrame

    frame = LocalFrame(14.5, 35.9)
    square = shapely.box(14.50, 35.90, 14.51, 35.91)
    return Engine(FenceSet([FenceRecord("sq", "keep_out", square)], frame=frame), MonitorOptions())


samples = st.builds(
    Sample,
    t=st.floats(0, 1e6),
    lat=st.one_of(ANY_FLOAT, st.floats(35.8, 36.0)),
    lon=st.one_of(ANY_FLOAT, st.floats(14.4, 14.6)),
    alt_m=ANY_FLOAT,
    vn=ANY_FLOAT,
    ve=ANY_FLOAT,
    mode=st.one_of(st.none(), st.sampled_from(["BRAKE", "GUIDED", "POSHOLD", "RTL"])),
    armed=st.one_of(st.none(), st.booleans()),
    alt_amsl_m=st.one_of(st.none(), ANY_FLOAT),
    vd=ANY_FLOAT,
    gps_fix=st.one_of(st.none(), st.integers(-1, 10)),
)


@FUZZ
@given(st.lists(samples, max_size=15), st.lists(adsb_fields, max_size=4))
def test_engine_takes_any_telemetry(seq, traffic):
    engine = _engine()
    for i, fields in enumerate(traffic):
        report = parse_adsb(json.dumps(fields))
        if report is not None:
            engine.aircraft(t=float(i), **report)
    for s in seq:
        for event in engine.step(s) + engine.tick(s.t + 0.5):
            json.dumps(event, allow_nan=False)  # every event is loggable strict JSON

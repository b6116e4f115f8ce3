"""alphafence check-flight: flight logs written as pymavlink and ArduPilot write them, checked
against fences, the verdicts and numbers checked independently (another metric frame, shapely,
pymavlink's own DataFlash reader)."""

import json
import struct
from datetime import datetime, timezone

import numpy as np
import pytest
import shapely

from alphafence.cli import main
from alphafence.errors import InputError
from alphafence.flights.flight_log import CHUNK, FlightLog
from alphafence.geo.frame import LocalFrame
from tests.helpers import VerifyFrame

pytest.importorskip("pymavlink")

LON0, LAT0 = 14.45, 35.88
FRAME = LocalFrame(LON0, LAT0)
VERIFY = VerifyFrame(LON0 + 0.01, LAT0 - 0.01)  # transverse Mercator, another origin
WEDNESDAY = datetime(2024, 11, 27, 10, 0, tzinfo=timezone.utc).timestamp()
SATURDAY = datetime(2024, 11, 30, 10, 0, tzinfo=timezone.utc).timestamp()
HOME_AMSL = 100.0
PNG = b"\x89PNG\r\n\x1a\n"
WALL = shapely.box(-40, 200, 40, 260)  # metres east/north of the origin
WEEKENDS = [{"permanent": "NO", "schedule": [{"day": ["SAT", "SUN"]}]}]


# -- logs, written the way the ground station and the autopilot write them -----------------
def track(points, speed=8.0, rate=4.0, t0=WEDNESDAY, alt=50.0):
    """Positions along straight legs through ``points`` (metres), ``rate`` per second."""
    pts = np.asarray(points, dtype=float)
    legs = np.hypot(*np.diff(pts, axis=0).T)
    along = np.arange(0.0, legs.sum(), speed / rate)
    x = np.interp(along, np.r_[0, np.cumsum(legs)], pts[:, 0])
    y = np.interp(along, np.r_[0, np.cumsum(legs)], pts[:, 1])
    lon, lat = FRAME.to_wgs84(x, y)
    t = t0 + along / speed
    rel = np.broadcast_to(np.asarray(alt, dtype=float), t.shape).copy()
    return dict(t=t, lat=np.asarray(lat), lon=np.asarray(lon), rel=rel, amsl=rel + HOME_AMSL)


def write_tlog(path, tr, sysid=1):
    """A MAVProxy-style tlog: 8-byte big-endian UNIX microseconds, then a MAVLink 2 packet;
    a HEARTBEAT and an ATTITUDE between positions, as a real log interleaves them."""
    from pymavlink.dialects.v20 import ardupilotmega as m

    mav = m.MAVLink(None, srcSystem=sysid, srcComponent=1)
    out = []
    for i, t in enumerate(tr["t"]):
        us = int(round(t * 1e6))
        boot = 60_000 + int(round((t - tr["t"][0]) * 1000))
        pos = m.MAVLink_global_position_int_message(
            boot,
            int(round(tr["lat"][i] * 1e7)),
            int(round(tr["lon"][i] * 1e7)),
            int(round(tr["amsl"][i] * 1000)),
            int(round(tr["rel"][i] * 1000)),
            0,
            0,
            0,
            0,
        )
        hb = m.MAVLink_heartbeat_message(2, 3, 209, 4, 4, 3)
        att = m.MAVLink_attitude_message(boot, 0.01, 0.02, 1.0, 0.0, 0.0, 0.0)
        for k, msg in enumerate((pos, hb, att)):
            out.append(struct.pack(">Q", us + 1000 * k) + msg.pack(mav))
    path.write_bytes(b"".join(out))
    return path


FMT = struct.Struct("<BB4s16s64s")
# ArduPilot's own declarations (libraries/AP_GPS and AP_AHRS LogStructure.h)
GPS_FMT = (
    "GPS",
    "QBBIHBcLLeffffB",
    "TimeUS,I,Status,GMS,GWk,NSats,HDop,Lat,Lng,Alt,Spd,GCrs,VZ,Yaw,U",
)
POS_FMT = ("POS", "QLLfff", "TimeUS,Lat,Lng,Alt,RelHomeAlt,RelOriginAlt")
STRUCT = {"Q": "Q", "B": "B", "I": "I", "H": "H", "c": "h", "L": "i", "e": "i", "f": "f"}
STRUCT.update(n="4s", N="16s", Z="64s")


def _fmt(ftype, name, fmt, cols):
    length = 3 + struct.calcsize("<" + "".join(STRUCT[c] for c in fmt))
    return b"\xa3\x95\x80" + FMT.pack(ftype, length, name.encode(), fmt.encode(), cols.encode())


def write_bin(path, tr, pos=True, leap=18, gps_time=True):
    """A DataFlash log: FMT for FMT, GPS, POS and an IMU-like message, then messages in the
    order ArduPilot writes them (GPS with GPS week and milliseconds, POS, IMU)."""
    boot = tr["t"][0] - 40.0
    out = [
        _fmt(0x80, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns"),
        _fmt(130, *GPS_FMT),
        _fmt(131, "IMU", "Qff", "TimeUS,GyrX,GyrY"),
    ]
    if pos:
        out.append(_fmt(132, *POS_FMT))
    for i, t in enumerate(tr["t"]):
        us = int(round((t - boot) * 1e6))
        gps = t + leap - 315964800
        week, ms = int(gps // 604800), int(round((gps % 604800) * 1000))
        week, ms = (week, ms) if gps_time else (0, 0)  # a GPS that has not got the time
        lat, lon = int(round(tr["lat"][i] * 1e7)), int(round(tr["lon"][i] * 1e7))
        amsl = tr["amsl"][i]
        gps_fields = (
            us,
            0,
            3,
            ms,
            week,
            14,
            80,
            lat,
            lon,
            int(round(amsl * 100)),
            8.0,
            0.0,
            0.0,
            0.0,
            1,
        )
        out.append(b"\xa3\x95\x82" + struct.pack("<QBBIHBhiiiffffB", *gps_fields))
        if pos:
            out.append(
                b"\xa3\x95\x84"
                + struct.pack("<Qiifff", us + 150, lat, lon, amsl, tr["rel"][i], tr["rel"][i])
            )
        out.append(b"\xa3\x95\x83" + struct.pack("<Qff", us + 300, 0.01, 0.02))
    path.write_bytes(b"".join(out))
    return path


def feature(site_id, kind, geom_local, **props):
    return {
        "type": "Feature",
        "properties": {"site_id": site_id, "kind": kind, "name": site_id.split("/")[0], **props},
        "geometry": shapely.geometry.mapping(FRAME.geom_to_wgs84(geom_local)),
    }


def fence_file(tmp_path, *features):
    path = tmp_path / "fences.geojson"
    path.write_text(json.dumps({"type": "FeatureCollection", "features": list(features)}))
    return path


@pytest.fixture
def fences(tmp_path):
    return fence_file(
        tmp_path,
        feature("prison/1", "keep_out", WALL),
        feature("prison/1", "warning", WALL.buffer(30)),
    )


def run(argv, capsys):
    code = main(["check-flight", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def as_json(argv, capsys):
    code, out, err = run([*argv, "--json"], capsys)
    assert err == "", err
    return code, json.loads(out)


def first_inside(tr, geom_local):
    """The first position inside ``geom_local``, found in the verifying frame."""
    poly = VERIFY.local(FRAME.geom_to_wgs84(geom_local))
    x, y = VERIFY.xy(tr["lon"], tr["lat"])
    inside = shapely.contains_xy(poly, x, y)
    return int(np.argmax(inside)) if inside.any() else None


# -- verdicts -----------------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["tlog", "bin"])
def test_a_flight_through_a_keep_out_fence_exits_1_naming_it_and_when(
    fences, tmp_path, capsys, kind
):
    tr = track([(0, 1), (0, 500)])  # positions every 2 m, none on the wall's edges
    log = (write_tlog if kind == "tlog" else write_bin)(tmp_path / f"f.{kind}", tr)
    png = tmp_path / "f.png"
    code, out, err = run([log, "--fences", fences, "--figure", png], capsys)
    assert code == 1 and err == ""
    k = first_inside(tr, WALL)
    entry = datetime.fromtimestamp(tr["t"][k], timezone.utc)
    assert "ENTERED keep-out fence prison/1" in out
    assert entry.strftime("%H:%M:%S.%f")[:12] in out  # the first position inside
    assert png.read_bytes().startswith(PNG)
    code, doc = as_json([log, "--fences", fences], capsys)
    assert code == 1 and doc["entered"] is True
    (hit,) = [i for i in doc["incursions"] if i["kind"] == "keep_out"]
    assert hit["fence"] == "prison/1" and hit["in_t"] == pytest.approx(tr["t"][k], abs=1e-3)
    assert hit["in"] == entry.isoformat(timespec="milliseconds")
    out_k = k + int(np.argmin(first_inside_mask(tr, WALL)[k:]))
    assert hit["out_t"] == pytest.approx(tr["t"][out_k], abs=1e-3)
    assert hit["positions"] == out_k - k and not hit["between_positions"]
    assert hit["depth_m"] == pytest.approx(29.0, abs=0.01)  # 60 m deep, positions at odd metres
    # the warning layer around it is a warning, not a verdict
    assert [i["kind"] for i in doc["incursions"]] == ["warning", "keep_out"]
    assert [a["level"] for a in doc["alerts"]][-1] == "BREACH"


def first_inside_mask(tr, geom_local):
    poly = VERIFY.local(FRAME.geom_to_wgs84(geom_local))
    return shapely.contains_xy(poly, *VERIFY.xy(tr["lon"], tr["lat"]))


@pytest.mark.parametrize("kind", ["tlog", "bin"])
def test_a_flight_past_it_exits_0_with_its_closest_approach(fences, tmp_path, capsys, kind):
    # a diagonal leg and a turn east of the wall: the closest point is not at a sample
    tr = track([(150, -100), (75, 230), (260, 600)], rate=2.0)
    log = (write_tlog if kind == "tlog" else write_bin)(tmp_path / f"f.{kind}", tr)
    code, out, _ = run([log, "--fences", fences], capsys)
    assert code == 0 and "no fence entered" in out
    code, doc = as_json([log, "--fences", fences], capsys)
    assert code == 0 and doc["entered"] is False and doc["incursions"] == []
    # an independent distance: the track as one line, in a transverse Mercator frame
    line = shapely.LineString(np.column_stack(VERIFY.xy(tr["lon"], tr["lat"])))
    expect = shapely.distance(line, VERIFY.local(FRAME.geom_to_wgs84(WALL)))
    (row,) = [f for f in doc["fences"] if f["kind"] == "keep_out"]
    assert row["closest"]["distance_m"] == pytest.approx(expect, abs=1.0)
    assert abs(row["closest"]["distance_m"] - expect) < 0.05  # in fact to centimetres
    assert f"{row['closest']['distance_m']:.1f}" in out  # the table says the same number
    # where: the track's point nearest the wall (east of its north-east corner)
    x, y = FRAME.to_local(row["closest"]["lon"], row["closest"]["lat"])
    assert float(x) > 40 and 200 < float(y) < 262


@pytest.mark.parametrize("when, code", [(WEDNESDAY, 0), (SATURDAY, 1)])
def test_a_fence_in_force_on_weekends_only_counts_at_the_weekend(tmp_path, capsys, when, code):
    fences = fence_file(
        tmp_path, feature("concert/1", "keep_out", WALL, zone={"applicability": WEEKENDS})
    )
    log = write_tlog(tmp_path / "f.tlog", track([(0, 0), (0, 500)], t0=when))
    got, doc = as_json([log, "--fences", fences], capsys)
    assert got == code and doc["entered"] is bool(code)
    (row,) = doc["fences"]
    assert row["in_force"] == ("no" if code == 0 else "yes")
    assert row["closest"]["in_force"] is bool(code)
    _, out, _ = run([log, "--fences", fences], capsys)
    assert ("no fence entered" in out) is (code == 0)


def test_altitude_limits_follow_their_reference(tmp_path, capsys):
    # a zone up to 200 m: AMSL, home at 100 m AMSL, flown at 120 m above home (220 m AMSL): over it
    def zone(ref):
        props = dict(alt_min_m=0, alt_max_m=200)
        props["zone"] = {"lower_reference": ref, "upper_reference": ref}
        return fence_file(tmp_path, feature("zone/1", "keep_out", WALL, **props))

    log = write_tlog(tmp_path / "f.tlog", track([(0, 0), (0, 500)], alt=120.0))
    code, doc = as_json([log, "--fences", zone("AMSL")], capsys)
    assert code == 0 and doc["fences"][0]["closest"]["vertical_m"] == pytest.approx(20.0, abs=0.01)
    code, doc = as_json([log, "--fences", zone("AGL")], capsys)  # 120 m above ground: inside
    assert code == 1 and doc["incursions"][0]["alt_m"] == pytest.approx(120.0, abs=0.01)
    assert any("AGL limits compared with the height above home" in n for n in doc["notes"])
    low = write_tlog(tmp_path / "g.tlog", track([(0, 0), (0, 500)], alt=90.0))  # 190 m AMSL
    assert as_json([low, "--fences", zone("AMSL")], capsys)[0] == 1


def test_a_fence_crossed_between_two_positions_is_an_incursion(tmp_path, capsys):
    thin = shapely.box(-40, 200, 40, 210)  # 10 m deep; positions every 25 m
    fences = fence_file(tmp_path, feature("mast/1", "keep_out", thin))
    tr = track([(0, 12.5), (0, 500)], speed=25.0, rate=1.0)
    assert first_inside(tr, thin) is None  # no position is inside
    code, doc = as_json([write_tlog(tmp_path / "f.tlog", tr), "--fences", fences], capsys)
    assert code == 1
    (hit,) = doc["incursions"]
    assert hit["between_positions"] and hit["positions"] == 0
    x, y = FRAME.to_local(hit["lon"], hit["lat"])
    assert 200 <= float(y) <= 210 and abs(float(x)) < 0.01
    assert hit["in_t"] == pytest.approx(tr["t"][0] + (205 - 12.5) / 25.0, abs=0.01)


def test_leaving_a_keep_in_fence_exits_1(tmp_path, capsys):
    field = shapely.box(-100, -100, 100, 300)
    fences = fence_file(tmp_path, feature("field/1", "keep_in", field))
    inside = write_tlog(tmp_path / "in.tlog", track([(0, 0), (0, 250)]))
    assert run([inside, "--fences", fences], capsys)[0] == 0
    out = write_tlog(tmp_path / "out.tlog", track([(0, 0), (0, 400)]))
    code, doc = as_json([out, "--fences", fences], capsys)
    assert code == 1 and doc["incursions"][0]["kind"] == "keep_in"
    assert doc["incursions"][0]["out_t"] is None  # the log ends outside
    assert doc["incursions"][0]["depth_m"] == pytest.approx(100.0, abs=2.0)
    assert "LEFT keep-in fence field/1" in run([out, "--fences", fences], capsys)[1]


def test_json_holds_the_tables_numbers(fences, tmp_path, capsys):
    tr = track([(0, 0), (0, 500), (200, 500)])
    log = write_tlog(tmp_path / "f.tlog", tr)
    _, out, _ = run([log, "--fences", fences], capsys)
    _, doc = as_json([log, "--fences", fences], capsys)
    assert doc["log"]["positions"] == len(tr["t"]) and doc["log"]["kind"] == "tlog"
    assert doc["log"]["start_t"] == pytest.approx(tr["t"][0], abs=1e-6)
    assert f"{len(tr['t'])} positions" in out
    for inc in doc["incursions"]:
        assert inc["in"][11:23] in out and f"{inc['depth_m']:.1f}" in out
    for row in doc["fences"]:
        assert f"{row['closest']['distance_m']:.1f}" in out and row["closest"]["time"][11:23] in out


# -- bad logs -----------------------------------------------------------------------------
def _tlog_bytes(tmp_path):
    return write_tlog(tmp_path / "whole.tlog", track([(0, 0), (0, 100)])).read_bytes()


@pytest.mark.parametrize(
    "name, data, said",
    [
        ("garbage.tlog", bytes(range(256)) * 20, "not a telemetry log"),
        ("empty.tlog", b"", "empty file"),
        ("cut.tlog", "head:30", "not a telemetry log"),  # cut inside the first packet
        ("noise.BIN", b"\x00\x01" * 500, "not a DataFlash log"),
        ("cut.BIN", b"\xa3\x95\x80" + b"\x00" * 40, "not a DataFlash log"),
        ("text.log", b"FMT, 128, 89, FMT, BBnNZ, Type,Length,Name,Format,Columns\n", "text"),
        ("nofix.BIN", "nofix", "no POS or GPS message with a position"),
    ],
)
def test_a_bad_log_is_one_line_exit_2_and_nothing_written(
    fences, tmp_path, capsys, name, data, said
):
    if data == "head:30":
        data = _tlog_bytes(tmp_path)[:30]
    elif data == "nofix":
        tr = track([(0, 0), (0, 100)])
        tr["lat"][:] = 0.0
        tr["lon"][:] = 0.0
        data = write_bin(tmp_path / "x.BIN", tr).read_bytes()
    log = tmp_path / name
    log.write_bytes(data)
    png = tmp_path / "f.png"
    code, out, err = run([log, "--fences", fences, "--figure", png, "--json"], capsys)
    assert code == 2 and out == ""
    (line,) = err.strip().splitlines()
    assert line.startswith(f"alphafence check-flight: error: {log}: ") and said in line, line
    assert not png.exists() and not list(tmp_path.glob(".f.png*"))


def test_a_log_cut_mid_message_is_checked_up_to_there(fences, tmp_path, capsys):
    tr = track([(0, 0), (0, 500)])
    whole = write_tlog(tmp_path / "w.tlog", tr).read_bytes()
    cut = tmp_path / "cut.tlog"
    cut.write_bytes(whole[: len(whole) // 2 + 7])
    code, doc = as_json([cut, "--fences", fences], capsys)
    assert doc["log"]["truncated"] is True and 0 < doc["log"]["positions"] < len(tr["t"])
    assert any("ends within a message" in n for n in doc["notes"])
    binary = write_bin(tmp_path / "w.BIN", tr).read_bytes()
    cut = tmp_path / "cut.BIN"
    cut.write_bytes(binary[: len(binary) - 20])
    code, doc = as_json([cut, "--fences", fences], capsys)
    assert code == 1 and doc["log"]["truncated"] is True


def test_bad_fences_are_one_line_too(tmp_path, capsys):
    log = write_tlog(tmp_path / "f.tlog", track([(0, 0), (0, 100)]))
    empty = tmp_path / "none.geojson"
    empty.write_text('{"type": "FeatureCollection", "features": []}')
    code, out, err = run([log, "--fences", empty], capsys)
    assert code == 2 and out == "" and "holds no fences" in err


# -- the readers --------------------------------------------------------------------------
def test_the_dataflash_reader_reads_what_pymavlinks_dfreader_reads(tmp_path):
    from pymavlink import DFReader

    tr = track([(0, 0), (300, 400), (-200, 900)], rate=10.0)
    for pos in (True, False):
        path = write_bin(tmp_path / f"f{pos}.BIN", tr, pos=pos)
        log = FlightLog(path, chunk=100)
        chunks = list(log.chunks())
        assert max(len(c) for c in chunks) == 100 and log.info.source == ("POS" if pos else "GPS")
        got = {
            k: np.concatenate([getattr(c, k) for c in chunks])
            for k in ("t", "lat", "lon", "alt_amsl")
        }
        ref = DFReader.DFReader_binary(str(path))
        rows = []
        while (m := ref.recv_match(type=log.info.source)) is not None:
            rows.append((m._timestamp, m.Lat, m.Lng, m.Alt))
        rows = np.array(rows)
        assert len(rows) == len(got["t"]) == len(tr["t"])
        np.testing.assert_allclose(got["t"], rows[:, 0], atol=1e-6)  # UTC from GPS time
        # 1e-12 degrees (0.1 um): pymavlink 2.4.20 scales the 1e-7 integers by another route
        np.testing.assert_allclose(got["lat"], rows[:, 1], rtol=0, atol=1e-12)
        np.testing.assert_allclose(got["lon"], rows[:, 2], rtol=0, atol=1e-12)
        np.testing.assert_allclose(got["alt_amsl"], rows[:, 3], atol=1e-4)


def test_the_tlog_reader_keeps_one_vehicle_and_its_times(tmp_path):
    tr = track([(0, 0), (0, 300)])
    a, b = write_tlog(tmp_path / "a.tlog", tr), write_tlog(tmp_path / "b.tlog", tr, sysid=7)
    both = tmp_path / "both.tlog"
    both.write_bytes(a.read_bytes() + b.read_bytes())  # another system's positions after
    log = FlightLog(both)
    t = np.concatenate([c.t for c in log.chunks()])
    assert log.info.sysid == 1 and len(t) == len(tr["t"])
    np.testing.assert_allclose(t, tr["t"], atol=1e-6)
    assert any("other systems (7)" in n for n in log.info.notes)
    log = FlightLog(both, sysid=7)
    assert sum(len(c) for c in log.chunks()) == len(tr["t"]) and log.info.sysid == 7
    assert len(next(FlightLog(a, chunk=CHUNK).chunks())) == min(CHUNK, len(tr["t"]))


def test_a_missing_log_is_an_input_error(tmp_path):
    with pytest.raises(InputError, match="cannot read"):
        FlightLog(tmp_path / "none.tlog")


# -- a real flight: ArduPilot SITL, its own DataFlash log and a ground station's tlog ------
SQUARE = shapely.box(-20, 130, 20, 170)  # metres east/north of SITL's home: on the way north
GOAL_NORTH = 300.0


def _fly_through(sitl, tlog, timeout=90.0):
    """Fly SITL's copter (pymavlink, GUIDED) from home to 300 m north at 30 m, through SQUARE
    (not uploaded: nothing stops it), and land; every message received is written to ``tlog``
    as a ground station writes it."""
    import time

    from pymavlink import mavutil

    frame = LocalFrame(sitl.home.lon, sitl.home.lat)
    deadline = time.monotonic() + timeout
    conn = mavutil.mavlink_connection(sitl.pymavlink_url, source_system=250)
    out = open(tlog, "wb")  # as MAVProxy writes its tlog: arrival time, then the packet

    def record(_, m):
        if m.get_type() != "BAD_DATA":
            out.write(struct.pack(">Q", int(time.time() * 1e6)) + m.get_msgbuf())

    conn.message_hooks.append(record)

    def wait(what, ok, kind="GLOBAL_POSITION_INT"):
        while time.monotonic() < deadline:
            m = conn.recv_match(type=kind, blocking=True, timeout=1.0)
            if m is not None and ok(m):
                return m
        raise AssertionError(f"SITL: no {what} within {timeout:g} s")

    try:
        conn.wait_heartbeat(timeout=10)
        sys_, comp = conn.target_system, conn.target_component
        conn.mav.command_long_send(sys_, comp, 511, 0, 33, 100_000, 0, 0, 0, 0, 0)  # 10 Hz
        conn.set_mode("GUIDED")
        wait("GUIDED", lambda m: m.custom_mode == 4, "HEARTBEAT")
        while not conn.motors_armed() and time.monotonic() < deadline:
            conn.arducopter_arm()
            wait("heartbeat", lambda m: True, "HEARTBEAT")
        conn.mav.command_long_send(sys_, comp, 22, 0, 0, 0, 0, 0, 0, 0, 30.0)  # NAV_TAKEOFF
        wait("climb to 27 m", lambda m: m.relative_alt > 27_000)
        lon, lat = frame.to_wgs84(0.0, GOAL_NORTH)
        conn.mav.set_position_target_global_int_send(
            0,
            sys_,
            comp,
            6,
            0b110111111000,
            int(lat * 1e7),
            int(lon * 1e7),
            30.0,
            0,
            0,
            0,
            0,
            0,
            0,
            0,
            0,
        )  # fmt: skip  (MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, position only)

        def north(m):
            return float(frame.to_local(m.lon * 1e-7, m.lat * 1e-7)[1])

        wait("arrival 300 m north", lambda m: north(m) > GOAL_NORTH - 5)
        conn.set_mode("LAND")
        wait("landed and disarmed", lambda m: not (m.base_mode & 128), "HEARTBEAT")
    finally:
        conn.close()
        out.close()
    return frame


@pytest.mark.sitl
@pytest.mark.parametrize("sitl", [{"home": "egham", "speedup": 5}], indirect=True)
async def test_a_sitl_flight_through_a_zone_is_caught_in_both_its_logs(sitl, tmp_path, capsys):
    import asyncio

    from pymavlink import DFReader

    tlog = tmp_path / "flight.tlog"
    frame = await asyncio.to_thread(_fly_through, sitl, tlog)
    fences = tmp_path / "fences.geojson"
    g = frame.geom_to_wgs84(SQUARE)
    feat = {"type": "Feature", "properties": {"site_id": "square", "kind": "keep_out"}}
    feat["geometry"] = shapely.geometry.mapping(g)
    fences.write_text(json.dumps({"type": "FeatureCollection", "features": [feat]}))
    (binary,) = sorted((sitl.workdir / "logs").glob("*.BIN"))[-1:]  # ArduPilot's own log
    entries = {}
    for log in (tlog, binary):
        code, doc = as_json([log, "--fences", fences], capsys)
        assert code == 1 and doc["log"]["clock"] == "utc", doc["log"]
        (hit,) = doc["incursions"]
        assert hit["fence"] == "square" and hit["positions"] > 10
        x, y = (float(v) for v in frame.to_local(hit["lon"], hit["lat"]))
        assert abs(x) < 5 and 130 <= y < 134, (log, x, y)  # the square's south edge, flying north
        assert hit["alt_m"] == pytest.approx(30, abs=3)
        entries[log.suffix] = hit
    # the streamed DataFlash reader reads the real log as pymavlink's DFReader does: whole, and
    # cut mid-message as a log still being written is. Both read the same copy, since SITL is
    # still running and may append to its log between two reads.
    data = binary.read_bytes()
    for size in (len(data), len(data) * 2 // 3 + 5):
        snapshot = tmp_path / f"snapshot-{size}.BIN"
        snapshot.write_bytes(data[:size])
        log = FlightLog(snapshot)
        got = [np.column_stack([c.t, c.lat, c.lon, c.alt_amsl]) for c in log.chunks()]
        got = np.concatenate(got)
        ref, rows = DFReader.DFReader_binary(str(snapshot)), []
        while (m := ref.recv_match(type="POS")) is not None:
            if m.Lat != 0 or m.Lng != 0:
                rows.append((m._timestamp, m.Lat, m.Lng, m.Alt))
        rows = np.array(rows)
        assert log.info.source == "POS" and len(got) == len(rows) > 100, size
        np.testing.assert_allclose(got[:, 0], rows[:, 0], atol=1e-6)
        np.testing.assert_allclose(got[:, 1:3], rows[:, 1:3], rtol=0, atol=1e-12)  # as above
        np.testing.assert_allclose(got[:, 3], rows[:, 3], atol=1e-3)


def test_it_needs_pymavlink_alone_and_says_so_without_it(fences, tmp_path):
    from tests.test_imports import NO_EXTRAS, _run

    log = write_tlog(tmp_path / "f.tlog", track([(0, 1), (0, 500)]))
    png = tmp_path / "f.png"
    code, modules, err = _run(["check-flight", str(log), "--fences", str(fences)], NO_EXTRAS)
    assert code == 1, err  # entered: the check ran with no extra but pymavlink
    assert "pymavlink" in modules and not {"scipy", "matplotlib", "osmium"} & modules
    argv = ["check-flight", str(log), "--fences", str(fences), "--figure", str(png)]
    code, _, err = _run(argv, NO_EXTRAS + ",pymavlink")
    (line,) = err.strip().splitlines()
    assert code == 2 and not png.exists()
    assert f"reading {log} needs pymavlink" in line and "f.png needs matplotlib" in line, line


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_incursions_are_what_each_position_says(tmp_path, seed):
    """Random walks among fences of every kind: the incursions (after the walk's shortcuts far
    from the fences) are the runs of positions each full check finds inside (keep-in: outside)."""
    from alphafence.awareness.fenceset import FenceSet
    from alphafence.review.postflight import check_flight, load_fences

    rng = np.random.default_rng(seed)
    path = fence_file(
        tmp_path,
        feature("a/1", "keep_out", shapely.box(-50, 100, 50, 160)),
        feature("a/1", "warning", shapely.box(-80, 70, 80, 190)),
        feature("b/2", "keep_out", shapely.Point(200, -50).buffer(40), alt_min_m=20, alt_max_m=60),
        feature("c/3", "keep_in", shapely.box(-300, -300, 300, 300)),
    )
    steps = np.zeros((3000, 2))  # a walk drawn to each fence in turn, and out of the keep-in
    goals = np.array([(0, 130), (200, -50), (330, 0)])
    for i in range(1, len(steps)):
        pull = steps[i - 1] - goals[(i // 300) % 3]
        steps[i] = steps[i - 1] + rng.normal(0, 6, 2) - 0.03 * pull
    lon, lat = FRAME.to_wgs84(steps[:, 0], steps[:, 1])
    t = WEDNESDAY + np.arange(len(steps)) * 0.5
    rel = np.clip(40 + rng.normal(0, 2, len(t)).cumsum(), 0, 120)
    tr = dict(t=t, lat=np.asarray(lat), lon=np.asarray(lon), rel=rel, amsl=rel + HOME_AMSL)
    rep = check_flight(FlightLog(write_tlog(tmp_path / "w.tlog", tr)), load_fences(path))
    fs = FenceSet(load_fences(path).records)
    runs = {}
    for i in range(len(t)):
        lo, la = tr["lon"][i], tr["lat"][i]
        x, y = fs.frame.to_local(round(lo, 7), round(la, 7))
        c = fs.check(float(x), float(y), round(rel[i], 3))
        for k in c.inside_keep_out + c.inside_warning + c.outside_keep_in:
            runs.setdefault(k, []).append(i)
    expect = sorted((k, len(v)) for k, v in runs.items())
    got = {}
    for inc in rep.incursions:
        if not inc.between_samples:
            got[inc.fence] = got.get(inc.fence, 0) + inc.samples
    assert sorted(got.items()) == expect
    assert {k for k, _ in expect} >= {0, 1, 2, 3}, expect  # the walk met every fence


def test_without_a_wall_clock_time_windows_count_as_in_force(tmp_path, capsys):
    fences = fence_file(
        tmp_path, feature("concert/1", "keep_out", WALL, zone={"applicability": WEEKENDS})
    )
    tr = track([(0, 1), (0, 500)])  # a Wednesday, but the log cannot say so
    log = write_bin(tmp_path / "f.BIN", tr, gps_time=False)
    code, doc = as_json([log, "--fences", fences], capsys)
    assert code == 1 and doc["log"]["clock"] == "boot" and doc["log"]["start"] is None
    assert doc["log"]["start_t"] == pytest.approx(40.0, abs=0.01)  # seconds since boot
    assert any("no GPS time" in n for n in doc["notes"])
    assert any("time windows counted as in force" in n for n in doc["notes"])
    _, out, _ = run([log, "--fences", fences], capsys)
    assert "T+" in out

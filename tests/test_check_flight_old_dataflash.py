"""DataFlash logs written before 2015 (ArduCopter 3.1, ArduPlane 2.7x and their time): no
``TimeUS`` and no ``POS``; positions are ``GPS`` messages whose ``TimeMS`` and ``Week`` are GPS
time and whose ``T`` is milliseconds since boot (or, earlier still, no ``T`` at all). The logs
are written as ArduPilot's ``libraries/DataFlash/LogStructure.h`` of 2013-2014 declares them, and
read against the truth they were written from and against pymavlink's own ``DFReader``."""

import struct
from datetime import datetime, timezone

import numpy as np
import pytest

from alphafence.flights.flight_log import FlightLog
from tests.test_check_flight import WALL, as_json, feature, fence_file, first_inside, run, track

pytest.importorskip("pymavlink")

# a Wednesday of 2014: GPS time was 16 s ahead of UTC from mid-2012 to mid-2015
WEDNESDAY_2014 = datetime(2014, 6, 11, 10, 0, tzinfo=timezone.utc).timestamp()
LEAP_2014 = 16
FMT = struct.Struct("<BB4s16s64s")
# (name, DataFlash format, columns, struct layout): LOG_BASE_STRUCTURES of 2013-2014, and the
# GPS of 2012-2013 before it gained T
GPS_2014 = (
    "GPS",
    "BIHBcLLeeEefI",
    "Status,TimeMS,Week,NSats,HDop,Lat,Lng,RelAlt,Alt,Spd,GCrs,VZ,T",
    "<BIHBhiiiiIifI",
)
GPS_2013 = ("GPS", "BIHBcLLeeEe", "Status,TimeMS,Week,NSats,HDop,Lat,Lng,RelAlt,Alt,Spd,GCrs")
GPS_2013 += ("<BIHBhiiiiIi",)
IMU_2014 = ("IMU", "Iffffff", "TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ", "<Iffffff")


def _fmt(ftype, name, fmt, cols, layout):
    length = 3 + struct.calcsize(layout)
    return b"\xa3\x95\x80" + FMT.pack(ftype, length, name.encode(), fmt.encode(), cols.encode())


def write_old_bin(path, tr, gps=GPS_2014):
    """A pre-2015 DataFlash log of the track ``tr``: FMT, GPS and IMU declared; GPS records
    without a fix first (no GPS time, then a 2-D fix, then a 3-D fix still at 0,0), then one GPS
    and one IMU record per position, times as the autopilot's millisecond clock gives them."""
    boot = tr["t"][0] - 40.0
    has_t = gps[2].endswith(",T")
    out = [
        _fmt(0x80, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns", "<BB4s16s64s"),
        _fmt(130, *gps),
        _fmt(131, *IMU_2014),
    ]
    layout = struct.Struct(gps[3])

    def record(t, status, lat, lon, rel, amsl, gps_time=True):
        ms_boot = int(round((t - boot) * 1000))
        g = t + LEAP_2014 - 315964800
        week, ms = (int(g // 604800), int(round((g % 604800) * 1000))) if gps_time else (0, 0)
        lat, lon = int(round(lat * 1e7)), int(round(lon * 1e7))
        fields = (status, ms, week, 9, 180, lat, lon, round(rel * 100), round(amsl * 100), 800, 0)
        fields += (0.0, ms_boot) if has_t else ()
        out.append(b"\xa3\x95\x82" + layout.pack(*fields))
        out.append(b"\xa3\x95\x83" + struct.pack("<Iffffff", ms_boot + 3, 0, 0, 0, 0, 0, -9.8))

    t0, lat0, lon0 = tr["t"][0], tr["lat"][0], tr["lon"][0]
    record(t0 - 3.0, 1, 0.0, 0.0, 0.0, 0.0, gps_time=False)  # no fix, no GPS time yet
    record(t0 - 2.0, 2, lat0 + 0.01, lon0, 0.0, 90.0)  # a 2-D fix: not a position
    record(t0 - 1.0, 3, 0.0, 0.0, 0.0, 0.0)  # a 3-D fix at 0,0: not a position
    for i, t in enumerate(tr["t"]):
        record(t, 3, tr["lat"][i], tr["lon"][i], tr["rel"][i], tr["amsl"][i])
    path.write_bytes(b"".join(out))
    return path


def _read(path):
    log = FlightLog(path, chunk=50)
    chunks = list(log.chunks())
    got = {k: np.concatenate([getattr(c, k) for c in chunks]) for k in ("t", "lat", "lon")}
    got.update(rel=np.concatenate([c.alt_rel for c in chunks]))
    got.update(amsl=np.concatenate([c.alt_amsl for c in chunks]))
    return log, got


@pytest.mark.parametrize("gps", [GPS_2014, GPS_2013], ids=["T-since-boot", "no-T"])
def test_a_pre_2015_log_is_read_as_its_gps_fixes(tmp_path, gps):
    tr = track([(0, 0), (300, 400), (-200, 900)], rate=5.0, t0=WEDNESDAY_2014)
    log, got = _read(write_old_bin(tmp_path / "old.BIN", tr, gps=gps))
    assert log.info.source == "GPS" and log.info.clock == "utc"
    assert log.info.positions == len(tr["t"])  # not the 2-D fix, not the fix at 0,0
    np.testing.assert_allclose(got["t"], tr["t"], rtol=0, atol=2e-3)  # UTC, to the millisecond
    for k in ("lat", "lon"):
        np.testing.assert_allclose(got[k], tr[k], rtol=0, atol=1e-7)
    for k in ("rel", "amsl"):  # centimetres in the log
        np.testing.assert_allclose(got[k], tr[k], rtol=0, atol=0.006)


def test_a_pre_2015_log_reads_as_pymavlinks_dfreader_reads_it(tmp_path):
    from pymavlink import DFReader

    tr = track([(0, 0), (300, 400)], rate=10.0, t0=WEDNESDAY_2014)
    path = write_old_bin(tmp_path / "old.BIN", tr)
    _, got = _read(path)
    ref, rows = DFReader.DFReader_binary(str(path)), []
    while (m := ref.recv_match(type="GPS")) is not None:
        if m.Status >= 3 and (m.Lat, m.Lng) != (0, 0):
            rows.append((m._timestamp, m.Lat, m.Lng, m.RelAlt, m.Alt))
    rows = np.array(rows)
    assert len(rows) == len(got["t"]) == len(tr["t"])
    # DFReader times a GPS by its T on a clock set from the first GPS time: the same intervals
    # (its UTC assumes today's 18 leap seconds, not the 16 of 2014)
    np.testing.assert_allclose(np.diff(got["t"]), np.diff(rows[:, 0]), rtol=0, atol=1e-6)
    for k, col in (("lat", 1), ("lon", 2), ("rel", 3), ("amsl", 4)):
        np.testing.assert_allclose(got[k], rows[:, col], rtol=0, atol=1e-9)


def test_check_flight_finds_a_pre_2015_flight_in_a_fence(tmp_path, capsys):
    fences = fence_file(tmp_path, feature("prison/1", "keep_out", WALL))
    tr = track([(0, 1), (0, 500)], t0=WEDNESDAY_2014)
    log = write_old_bin(tmp_path / "old.BIN", tr)
    code, out, err = run([log, "--fences", fences], capsys)
    assert code == 1 and err == "" and "ENTERED keep-out fence prison/1" in out
    k = first_inside(tr, WALL)
    entry = datetime.fromtimestamp(tr["t"][k], timezone.utc)
    assert entry.strftime("%H:%M:%S.%f")[:12] in out
    code, doc = as_json([log, "--fences", fences], capsys)
    assert code == 1 and doc["log"]["kind"] == "dataflash" and doc["log"]["clock"] == "utc"
    assert doc["log"]["positions"] == len(tr["t"])
    (hit,) = doc["incursions"]
    assert hit["fence"] == "prison/1" and hit["in_t"] == pytest.approx(tr["t"][k], abs=2e-3)
    assert hit["in"].startswith("2014-06-11T")

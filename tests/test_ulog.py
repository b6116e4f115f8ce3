"""check-flight on PX4's flight logs (ULog, ``.ulg``): the track is the estimator's position,
heights above the home in force, velocities from the local position, UTC from the GPS."""

from datetime import datetime, timezone

import numpy as np
import pytest

from alphafence.errors import InputError
from alphafence.flights.flight_log import FlightLog
from tests.test_check_flight import HOME_AMSL, WALL, feature, fence_file, first_inside, run, track
from tests.ulog_writer import GLOBAL, GPS, HOME, LOCAL, ulog_bytes

pytest.importorskip("pyulog")
BOOT_UTC = datetime(2024, 11, 27, 9, 58, tzinfo=timezone.utc).timestamp()


def write_ulog(path, tr, utc=True, home=True, bad=()):
    """``tr`` (tests/test_check_flight.py's track) as PX4 logs it: times since boot, home set
    before the first position, a GPS sample giving UTC; the positions at ``bad`` not valid."""
    boot_us = np.rint((tr["t"] - BOOT_UTC) * 1e6).astype(np.int64)
    rows = [(int(t), float(la), float(lo), float(a), k not in bad)
            for k, (t, la, lo, a) in enumerate(zip(boot_us, tr["lat"], tr["lon"], tr["amsl"]))]  # fmt: skip
    topics = {"vehicle_global_position": (GLOBAL, rows)}
    # the local position at half the rate, 8 m/s north (the track's speed)
    topics["vehicle_local_position"] = (LOCAL, [(int(t), 8.0, 0.0) for t in boot_us[::2]])
    if home:
        t0 = int(boot_us[0]) - 500_000
        topics["home_position"] = (
            HOME,
            [(t0, float(tr["lat"][0]), float(tr["lon"][0]), HOME_AMSL)],
        )
    if utc:
        t = int(boot_us[0]) + 100_000
        topics["vehicle_gps_position"] = (GPS, [(t, int(round(BOOT_UTC * 1e6)) + t)])
    path.write_bytes(ulog_bytes(topics))
    return path


def test_a_ulog_is_read_as_px4_logged_it(tmp_path):
    tr = track([(0, 1), (0, 300)])
    log = FlightLog(write_ulog(tmp_path / "f.ulg", tr, bad=(3,)))
    chunks = list(log.chunks())
    t, lat, rel, vn = (
        np.concatenate([getattr(c, k) for c in chunks]) for k in ("t", "lat", "alt_rel", "vn")
    )
    keep = np.ones(len(tr["t"]), bool)
    keep[3] = False  # lat_lon_valid false: dropped
    assert log.info.kind == "ulog" and log.info.clock == "utc"
    assert log.info.source == "vehicle_global_position"
    assert log.info.positions == keep.sum() and log.info.skipped == 1
    assert t == pytest.approx(tr["t"][keep], abs=1e-6)  # UTC, from the GPS sample's offset
    assert lat == pytest.approx(tr["lat"][keep], abs=1e-12)
    assert rel == pytest.approx(tr["rel"][keep], abs=1e-3)  # alt less home's
    inside = np.isfinite(vn)
    assert inside.sum() >= len(vn) - 2 and vn[inside] == pytest.approx(8.0)


def test_without_utc_or_home_the_times_are_since_boot_and_heights_unknown(tmp_path):
    tr = track([(0, 1), (0, 100)])
    log = FlightLog(write_ulog(tmp_path / "f.ulg", tr, utc=False, home=False))
    (chunk,) = list(log.chunks())
    assert log.info.clock == "boot"
    assert chunk.t[0] == pytest.approx(tr["t"][0] - BOOT_UTC, abs=1e-6)
    assert np.isnan(chunk.alt_rel).all()
    notes = " ".join(log.info.notes)
    assert "no GPS time" in notes and "before PX4 set home" in notes


def test_check_flight_finds_the_incursion_in_a_ulog(tmp_path, capsys):
    tr = track([(0, 1), (0, 500)])
    fences = fence_file(tmp_path, feature("prison/1", "keep_out", WALL))
    code, out, err = run([write_ulog(tmp_path / "f.ulg", tr), "--fences", fences], capsys)
    assert code == 1 and err == "", err
    k = first_inside(tr, WALL)
    entry = datetime.fromtimestamp(tr["t"][k], timezone.utc)
    assert "ENTERED keep-out fence prison/1" in out
    assert entry.strftime("%H:%M:%S.%f")[:12] in out
    assert "vehicle_global_position" in out


@pytest.mark.parametrize(
    "content, says",
    [
        (b"ULog\x01\x12\x35\x01" + b"\x00" * 8 + b"\xff\xff\x46garbage", "vehicle_global_position"),
        (b"ULog\x01\x12\x35\x01", "not a readable ULog"),
    ],
)
def test_a_ulog_without_positions_or_cut_short_is_one_line(tmp_path, capsys, content, says):
    path = tmp_path / "bad.ulg"
    path.write_bytes(content)
    with pytest.raises(InputError) as err:
        list(FlightLog(path).chunks())
    assert str(err.value).startswith(str(path)) and "\n" not in str(err.value)
    assert says in str(err.value)
    fences = fence_file(tmp_path, feature("prison/1", "keep_out", WALL))
    code, out, err_text = run([path, "--fences", fences], capsys)
    assert code == 2 and len(err_text.strip().splitlines()) == 1

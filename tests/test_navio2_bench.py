"""`make navio2-test`'s bench phase judges its measurements: armhf (emulated) beside x86, a
missing compiled piece, a monitor that fell behind, a CPU per position far above x86's."""

from tests.navio2.bench import MAX_EMULATED_RATIO, verdict

NATIVE = {"fastcrc": True, "numpy": True, "shapely": True, "pyproj": True}


def rows(per_us, rate=50.0, native=NATIVE):
    return [
        {"link": "pymavlink", "hz": 50.0, "share": per_us * rate / 1e6, "rate": rate,
         "per_position_s": per_us / 1e6, "machine": "x", "native": dict(native)},
        {"link": "floor", "hz": 50.0, "share": 0.01, "rate": 80.0, "machine": "x",
         "native": dict(native)},
    ]  # fmt: skip


def test_figures_within_bounds_pass_and_are_labelled_emulated():
    got, failed = verdict({"x86": rows(300.0), "armhf": rows(300.0 * 12)})
    assert failed == []
    monitor = got[0]
    assert "emulated" in monitor["name"] and monitor["ratio"] == "12.0x" and monitor["ok"]
    assert monitor["peer_value"] == 300.0 and monitor["unit"] == "us/position"


def test_a_missing_wheel_a_slow_fallback_or_a_monitor_behind_fails():
    slow = verdict({"x86": rows(300.0), "armhf": rows(300.0 * (MAX_EMULATED_RATIO + 5))})[1]
    assert any("x86's" in f for f in slow)
    no_crc = verdict(
        {"x86": rows(300.0), "armhf": rows(3000.0, native=dict(NATIVE, fastcrc=False))}
    )[1]
    assert no_crc == ["the armhf install lacks fastcrc (x86 has it)"]
    behind = verdict({"x86": rows(300.0), "armhf": rows(3000.0, rate=20.0)})[1]
    assert behind == ["armhf 50 Hz: 20.0 checks/s"]

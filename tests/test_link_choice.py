"""Which vehicle link the kit takes (alphafence.vehicle.link.choose_link), and what it says when
the one asked for, or any, is missing."""

import pytest

from alphafence.cli import main
from alphafence.vehicle import link as link_module
from alphafence.vehicle.link import LINKS, NoLinkError, choose_link
from tests.test_imports import _free_udp_port, _run


def _only(monkeypatch, *installed):
    monkeypatch.setattr(link_module, "_installed", lambda kind: kind in installed)
    monkeypatch.delenv("ALPHAFENCE_LINK", raising=False)


def test_auto_prefers_pymavlink_then_mavsdk(monkeypatch):
    _only(monkeypatch, "pymavlink", "mavsdk")
    assert choose_link() == link_module.PREFERRED[0]
    _only(monkeypatch, "mavsdk")
    assert choose_link("auto") == "mavsdk"
    _only(monkeypatch, "pymavlink")  # a Navio2: no MAVSDK 4 wheel for armv7
    assert choose_link(None) == "pymavlink"


def test_the_environment_chooses_when_the_caller_does_not(monkeypatch):
    _only(monkeypatch, "pymavlink", "mavsdk")
    monkeypatch.setenv("ALPHAFENCE_LINK", "MAVSDK")
    assert choose_link() == "mavsdk"
    assert choose_link("pymavlink") == "pymavlink"  # the caller's word wins


@pytest.mark.parametrize(
    "installed, asked, said",
    [
        ((), "auto", "no vehicle link is installed: pip install pymavlink"),
        (("pymavlink",), "mavsdk", "none for 32-bit ARM"),
        (("mavsdk",), "pymavlink", "the pymavlink vehicle link is not installed"),
        (("mavsdk", "pymavlink"), "grpc", "unknown vehicle link 'grpc'"),
    ],
)
def test_a_missing_link_is_one_line_naming_what_to_install(monkeypatch, installed, asked, said):
    _only(monkeypatch, *installed)
    with pytest.raises(NoLinkError) as err:
        choose_link(asked)
    assert said in str(err.value) and "\n" not in str(err.value)
    assert err.value.exit_code == 3


def test_links_are_the_cli_choices():
    from alphafence.cli import parser

    args = parser().parse_args(
        ["download", "--connect", "udpin://:1", "-o", "x", "--link", "pymavlink"]
    )
    assert args.link == "pymavlink" and set(LINKS) == {"auto", "pymavlink", "mavsdk"}


def test_monitor_with_no_link_installed_says_so_in_one_line(tmp_path):
    from alphafence.cli.demo import scene_path

    fences = tmp_path / "f.geojson"
    assert main(["build", str(scene_path()), "-o", str(fences)]) == 0
    url = f"udpin://127.0.0.1:{_free_udp_port()}"
    argv = ["monitor", "--fences", str(fences), "--allow-unsigned", "--connect", url]
    code, modules, err = _run([*argv, "--timeout", "1"], "mavsdk,pymavlink")
    assert code == 3, err
    lines = err.strip().splitlines()
    assert lines[-1].startswith("alphafence monitor: error: no vehicle link is installed"), err
    assert "Traceback" not in err


def test_monitor_of_an_empty_fence_file_is_one_line(tmp_path, capsys):
    fences = tmp_path / "f.geojson"
    fences.write_text('{"type": "FeatureCollection", "features": []}')
    argv = ["monitor", "--fences", str(fences), "--allow-unsigned", "--connect", "udpin://:1"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]  # after the unverified warning
    assert err == f"alphafence monitor: error: {fences}: holds no fences: nothing to monitor"

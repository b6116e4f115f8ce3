"""The connection forms operators type (alphafence.vehicle.endpoints), and ``--connect`` on the
command line: every form read to the endpoint it means, the baud defaults, the forms that are
refused (one line naming the value and the accepted forms), and host/port/baud round trips."""

from __future__ import annotations

import doctest

import pytest
from hypothesis import given
from hypothesis import strategies as st

from alphafence.cli import main, parser
from alphafence.vehicle import endpoints
from alphafence.vehicle.endpoints import (
    FORMS,
    RADIO_BAUD,
    USB_BAUD,
    Endpoint,
    EndpointError,
    default_baud,
    parse_endpoint,
)


def serial(device, baud, flow=False):
    return Endpoint("serial", device=device, baud=baud, flow_control=flow)


def net(kind, host, port):
    return Endpoint(kind, host=host, port=port)


FORMS_READ = [
    # USB flight controllers: 115200 unless given
    ("/dev/ttyACM0", serial("/dev/ttyACM0", USB_BAUD)),
    ("/dev/ttyACM1,921600", serial("/dev/ttyACM1", 921600)),
    ("/dev/serial/by-id/usb-ArduPilot_Pixhawk1_1E0037-if00",
     serial("/dev/serial/by-id/usb-ArduPilot_Pixhawk1_1E0037-if00", USB_BAUD)),
    ("/dev/serial/by-id/usb-Hex_ProfiCNC_CubeOrange_2E00-if00",
     serial("/dev/serial/by-id/usb-Hex_ProfiCNC_CubeOrange_2E00-if00", USB_BAUD)),
    # radios and UARTs: 57600 unless given
    ("/dev/ttyUSB0", serial("/dev/ttyUSB0", RADIO_BAUD)),
    ("/dev/ttyUSB0,57600", serial("/dev/ttyUSB0", 57600)),
    ("/dev/ttyUSB0:115200", serial("/dev/ttyUSB0", 115200)),
    ("/dev/serial/by-id/usb-FTDI_FT231X_USB_UART_DN05-if00-port0",
     serial("/dev/serial/by-id/usb-FTDI_FT231X_USB_UART_DN05-if00-port0", RADIO_BAUD)),
    ("/dev/ttyAMA0", serial("/dev/ttyAMA0", RADIO_BAUD)),
    ("/dev/serial0", serial("/dev/serial0", RADIO_BAUD)),
    ("serial:///dev/ttyUSB0:57600", serial("/dev/ttyUSB0", 57600)),
    ("serial:///dev/ttyACM0", serial("/dev/ttyACM0", USB_BAUD)),
    ("serial:/dev/ttyS1:38400", serial("/dev/ttyS1", 38400)),
    ("serial_flowcontrol:///dev/ttyAMA0:921600", serial("/dev/ttyAMA0", 921600, True)),
    ("COM3", serial("COM3", RADIO_BAUD)),
    ("COM3,115200", serial("COM3", 115200)),
    ("serial://COM12:57600", serial("COM12", 57600)),
    ("  /dev/ttyACM0 ", serial("/dev/ttyACM0", USB_BAUD)),
    # a device by a relative path (a pseudo-terminal pair's link made here)
    ("./gcs,57600", serial("./gcs", 57600)),
    ("../walk/gcs", serial("../walk/gcs", RADIO_BAUD)),
    # UDP: listen
    ("udpin:0.0.0.0:14550", net("udpin", "0.0.0.0", 14550)),
    ("udpin://0.0.0.0:14550", net("udpin", "0.0.0.0", 14550)),
    ("udpin://:14550", net("udpin", "0.0.0.0", 14550)),
    ("udpin:14550", net("udpin", "0.0.0.0", 14550)),
    ("udp://:14540", net("udpin", "0.0.0.0", 14540)),
    ("udp://127.0.0.1:14550", net("udpin", "127.0.0.1", 14550)),
    ("udp:127.0.0.1:14550", net("udpin", "127.0.0.1", 14550)),
    ("127.0.0.1:14550", net("udpin", "127.0.0.1", 14550)),
    ("UDPIN://[::1]:14550", net("udpin", "::1", 14550)),
    # UDP: send
    ("udpout:192.168.4.1:14550", net("udpout", "192.168.4.1", 14550)),
    ("udpout://navio.local:14550/", net("udpout", "navio.local", 14550)),
    ("udpbcast:192.168.1.255:14550", net("udpbcast", "192.168.1.255", 14550)),
    # TCP
    ("tcp:navio.local:5760", net("tcpout", "navio.local", 5760)),
    ("tcp://127.0.0.1:5760", net("tcpout", "127.0.0.1", 5760)),
    ("tcpout://127.0.0.1:5760", net("tcpout", "127.0.0.1", 5760)),
    ("tcpin:0.0.0.0:5760", net("tcpin", "0.0.0.0", 5760)),
    ("tcpin://:5760", net("tcpin", "0.0.0.0", 5760)),
]  # fmt: skip


@pytest.mark.parametrize("text, expected", FORMS_READ)
def test_every_form_reads_as_what_it_means(text, expected):
    got = parse_endpoint(text)
    assert got == expected
    assert parse_endpoint(str(got)) == got  # the canonical form reads back the same


REFUSED = [
    ("", "empty"),
    ("   ", "empty"),
    ("ttyACM0", "not a serial port, UDP or TCP connection"),
    ("navio.local", "not a serial port, UDP or TCP connection"),
    ("http://x:80", "unknown scheme 'http'"),
    ("udpout://:14550", "udpout needs the vehicle's address"),
    ("udpout:0.0.0.0:14550", "udpout needs the vehicle's address"),
    ("tcp://:5760", "tcp needs the vehicle's address"),
    ("tcp:navio.local", "tcp needs HOST:PORT"),
    ("udpin://0.0.0.0:0", "port 0 is outside 1..65535"),
    ("udpin://0.0.0.0:65536", "port 65536 is outside 1..65535"),
    ("udpin:bad_host!:14550", "needs HOST:PORT"),
    ("udpout:-bad-.local:14550", "is not a host name or address"),
    ("/dev/ttyUSB0,12", "baud rate 12 is outside 50..12000000"),
    ("serial://ttyUSB0:57600", "a serial port is a /dev/... path (or ./NAME) or COMn"),
    ("serial:///dev/:57600", "a serial port is a device, not a directory"),
]


@pytest.mark.parametrize("text, says", REFUSED)
def test_bad_forms_are_one_line_naming_the_value_and_the_forms(text, says):
    with pytest.raises(EndpointError) as err:
        parse_endpoint(text)
    line = str(err.value)
    assert "\n" not in line
    assert line.startswith(f"connection {text!r}: ")
    assert says in line and line.endswith(f"(accepted: {FORMS})")


def test_baud_defaults():
    assert default_baud("/dev/ttyACM0") == USB_BAUD == 115200
    assert default_baud("/dev/ttyUSB3") == RADIO_BAUD == 57600
    assert default_baud("COM7") == RADIO_BAUD


def test_a_link_to_a_usb_port_takes_the_usb_baud(tmp_path):
    link = tmp_path / "pixhawk"
    link.symlink_to("/dev/ttyACM0")
    assert default_baud(str(link)) == USB_BAUD
    radio = tmp_path / "radio"
    radio.symlink_to("/dev/ttyUSB0")
    assert default_baud(str(radio)) == RADIO_BAUD


def test_mavsdk_urls():
    assert parse_endpoint("/dev/ttyUSB0").mavsdk_url == "serial:///dev/ttyUSB0:57600"
    assert parse_endpoint("udp://:14540").mavsdk_url == "udpin://0.0.0.0:14540"
    assert parse_endpoint("tcp:h:5760").mavsdk_url == "tcpout://h:5760"
    assert parse_endpoint("tcpin::5760").mavsdk_url == "tcpin://0.0.0.0:5760"
    assert parse_endpoint("udpbcast:10.0.0.255:14550").mavsdk_url is None  # the kit's bridge


def test_docstring_examples_run():
    result = doctest.testmod(endpoints, optionflags=doctest.ELLIPSIS)
    assert result.attempted >= 8 and result.failed == 0


# -- round trips ------------------------------------------------------------------------------

LABEL = st.from_regex(r"[a-z0-9]([a-z0-9-]{0,10}[a-z0-9])?", fullmatch=True)
HOSTNAME = st.lists(LABEL, min_size=1, max_size=4).map(".".join)
IPV4 = st.tuples(*[st.integers(0, 255)] * 4).map(lambda t: ".".join(map(str, t)))
IPV6 = st.ip_addresses(v=6).map(str)
HOST = st.one_of(HOSTNAME, IPV4, IPV6).filter(lambda h: h not in ("0.0.0.0", "::"))
PORT = st.integers(1, 65535)
BAUD = st.integers(50, 12_000_000)
DEVICE = st.one_of(
    st.from_regex(r"/dev/tty(ACM|USB|AMA|S)[0-9]{1,2}", fullmatch=True),
    st.from_regex(r"COM[1-9][0-9]?", fullmatch=True),
)


def _written(host):
    return f"[{host}]" if ":" in host else host


@given(kind=st.sampled_from(["udpin", "udpout", "udpbcast", "tcpout", "tcpin"]), host=HOST,
       port=PORT, slashes=st.booleans())  # fmt: skip
def test_host_and_port_round_trip(kind, host, port, slashes):
    text = f"{kind}:{'//' if slashes else ''}{_written(host)}:{port}"
    ep = parse_endpoint(text)
    assert (ep.kind, ep.host, ep.port) == (kind, host, port)
    assert parse_endpoint(str(ep)) == ep


@given(device=DEVICE, baud=BAUD, form=st.sampled_from(["{d},{b}", "{d}:{b}", "serial://{d}:{b}"]))
def test_device_and_baud_round_trip(device, baud, form):
    ep = parse_endpoint(form.format(d=device, b=baud))
    assert (ep.kind, ep.device, ep.baud) == ("serial", device, baud)
    assert parse_endpoint(str(ep)) == ep


@given(port=st.one_of(st.just(0), st.integers(65536, 10**6)))
def test_ports_out_of_range_are_refused(port):
    with pytest.raises(EndpointError, match=f"port {port} is outside 1..65535"):
        parse_endpoint(f"udpout:10.0.0.1:{port}")


# -- the command line -------------------------------------------------------------------------


@pytest.mark.parametrize("verb", ["upload", "download", "monitor", "signing setup"])
def test_connect_help_lists_the_forms_and_baud_defaults(verb, capsys):
    with pytest.raises(SystemExit):
        main([*verb.split(), "--help"])
    text = " ".join(capsys.readouterr().out.split())
    for form in ("/dev/ttyACM0", "COM3", "/dev/ttyUSB0,115200", "udpin:0.0.0.0:14550",
                 "udp://:14540", "udpout:HOST:PORT", "tcp:HOST:5760", "tcpin:0.0.0.0:5760",
                 "115200 baud unless given", "57600 unless given",
                 "Example: --connect /dev/ttyACM0"):  # fmt: skip
        assert form in text, (verb, form)


@pytest.mark.parametrize("verb", ["upload", "download", "monitor"])
def test_a_bad_connection_is_one_line_at_parse_time(verb, capsys, tmp_path):
    fences = tmp_path / "f.geojson"
    rest = {"upload": [str(fences)], "download": ["-o", "x.plan"], "monitor": ["--fences", "f"]}
    code = main([verb, *rest[verb], "--connect", "udpout://:14550"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1
    assert err.startswith(
        f"alphafence {verb}: error: --connect 'udpout://:14550': udpout needs the vehicle's"
    )


def test_the_parser_keeps_the_connection_as_typed():
    args = parser().parse_args(["download", "--connect", "/dev/ttyUSB0,57600", "-o", "x.plan"])
    assert args.connect == "/dev/ttyUSB0,57600"

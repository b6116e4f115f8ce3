"""Vehicle connections as operators write them, read into one typed :class:`Endpoint`.

Every vehicle link of the kit reads ``--connect`` here, so the forms of pymavlink and MAVProxy,
of MAVSDK and of a bare device name all mean the same thing everywhere:

====================================================  =======================================
written                                               means
====================================================  =======================================
``/dev/ttyACM0``, ``/dev/ttyUSB0,57600``, ``COM3``    a serial port (``,BAUD`` or ``:BAUD``)
``serial:///dev/ttyUSB0:57600``, ``serial:COM3``      the same (``serial_flowcontrol://``: RTS/CTS)
``udpin:0.0.0.0:14550``, ``udpin://:14550``           listen on UDP; the vehicle sends to us
``udp://:14540``, ``udp:HOST:PORT``, ``HOST:PORT``    the same (MAVSDK's, pymavlink's reading)
``udpout:HOST:PORT``, ``udpout://HOST:PORT``          send to the vehicle on UDP
``udpbcast:192.168.1.255:14550``                      broadcast until the vehicle answers
``tcp:HOST:5760``, ``tcpout://HOST:5760``             connect to the vehicle over TCP
``tcpin:0.0.0.0:5760``, ``tcpin://:5760``             listen on TCP and accept the vehicle
====================================================  =======================================

Without a baud rate, a USB flight controller (``/dev/ttyACM*``, a ``/dev/serial/by-id`` name
of a USB CDC device) gets 115200 and anything else (a telemetry radio on ``/dev/ttyUSB*``,
``/dev/ttyAMA*``, ``/dev/serial0``, ``COMn``) 57600, SiK radios' default. Ports are 1..65535.

Examples
--------
>>> parse_endpoint("/dev/ttyACM0")
Endpoint(kind='serial', host='', port=0, device='/dev/ttyACM0', baud=115200, flow_control=False)
>>> str(parse_endpoint("/dev/ttyUSB0"))
'serial:///dev/ttyUSB0:57600'
>>> str(parse_endpoint("udp://:14540"))
'udpin://0.0.0.0:14540'
>>> str(parse_endpoint("tcp:navio.local:5760"))
'tcpout://navio.local:5760'
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass

from alphafence.errors import InputError

KINDS = ("serial", "udpin", "udpout", "udpbcast", "tcpout", "tcpin")
USB_BAUD = 115200  # USB CDC: the rate is not used on the wire; ArduPilot's SERIAL0 default
RADIO_BAUD = 57600  # SiK telemetry radios and ArduPilot's TELEM default
MIN_BAUD, MAX_BAUD = 50, 12_000_000
FORMS = (
    "/dev/ttyACM0, /dev/ttyUSB0,57600, COM3[,BAUD], serial:///dev/ttyUSB0:57600, "
    "udpin:HOST:PORT, udp://:14540, udpout:HOST:PORT, udpbcast:BCAST:PORT, tcp:HOST:PORT, "
    "tcpin:HOST:PORT"
)
HELP = (
    "the vehicle: a serial port, USB (/dev/ttyACM0: 115200 baud unless given) or a telemetry "
    "radio (/dev/ttyUSB0, /dev/ttyAMA0, /dev/serial0, COM3: 57600 unless given; "
    "/dev/ttyUSB0,115200 or serial:///dev/ttyUSB0:115200 to set it); UDP: udpin:0.0.0.0:14550 "
    "or udp://:14540 (listen for the vehicle), udpout:HOST:PORT (send to it), "
    "udpbcast:BCAST:PORT; TCP: tcp:HOST:5760 (connect), tcpin:0.0.0.0:5760 (listen)"
)
# scheme -> kind; pymavlink's and MAVSDK's "udp" and MAVProxy's bare HOST:PORT both listen
SCHEMES = {
    "serial": "serial",
    "serial_flowcontrol": "serial",
    "udpin": "udpin",
    "udp": "udpin",
    "udpout": "udpout",
    "udpbcast": "udpbcast",
    "tcp": "tcpout",
    "tcpout": "tcpout",
    "tcpin": "tcpin",
}
LISTEN_ANY = ("", "0.0.0.0", "::")
PATHS = ("/", "./", "../", "~/")  # a serial device by its path (a pty pair's link: ./gcs)
_SCHEME = re.compile(r"([A-Za-z_]+):(?://)?(.*)", re.S)
_HOST_PORT = re.compile(r"(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9._-]*):(\d+)/?")
_HOSTNAME = re.compile(r"(?!-)[A-Za-z0-9-]{1,63}(?<!-)(\.(?!-)[A-Za-z0-9-]{1,63}(?<!-))*\.?")
_COM = re.compile(r"(?:\\\\\.\\)?COM\d{1,3}", re.I)
_DEVICE_BAUD = re.compile(r"(.+?)(?:[,:](\d+))?")


class EndpointError(InputError):
    """A connection that is none of the accepted forms (one line, naming it and the forms)."""

    def __init__(self, text: str, why: str):
        super().__init__(f"connection {text!r}", f"{why} (accepted: {FORMS})")


@dataclass(frozen=True)
class Endpoint:
    """Where the vehicle is and how to reach it.

    Attributes
    ----------
    kind : str
        One of :data:`KINDS`.
    host, port : str, int
        For UDP and TCP: the address to listen on (``udpin``, ``tcpin``) or to reach.
    device, baud : str, int
        For ``serial``: the port and its speed.
    flow_control : bool
        For ``serial``: RTS/CTS hardware flow control.
    """

    kind: str
    host: str = ""
    port: int = 0
    device: str = ""
    baud: int = 0
    flow_control: bool = False

    @property
    def listens(self) -> bool:
        """Whether the kit waits for the vehicle (``udpin``, ``tcpin``)."""
        return self.kind in ("udpin", "tcpin")

    @property
    def address(self) -> tuple[str, int]:
        """``(host, port)`` for a socket."""
        return self.host, self.port

    def __str__(self) -> str:
        """The canonical form (MAVSDK's URL, ``udpbcast://`` aside).

        Examples
        --------
        >>> str(parse_endpoint("COM3,115200"))
        'serial://COM3:115200'
        """
        if self.kind == "serial":
            scheme = "serial_flowcontrol" if self.flow_control else "serial"
            return f"{scheme}://{self.device}:{self.baud}"
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{self.kind}://{host}:{self.port}"

    @property
    def mavsdk_url(self) -> str | None:
        """The URL MAVSDK opens itself, or None where it has no such connection
        (``udpbcast``: the kit's bridge carries it)."""
        return None if self.kind == "udpbcast" else str(self)


def default_baud(device: str) -> int:
    """The baud rate of a serial port given without one.

    Parameters
    ----------
    device : str
        The port's name.

    Returns
    -------
    int
        :data:`USB_BAUD` for a USB flight controller (``/dev/ttyACM*``, a ``/dev/serial/by-id``
        name of a USB CDC device, or a link to a ``/dev/ttyACM*``), else :data:`RADIO_BAUD`.

    Examples
    --------
    >>> default_baud("/dev/ttyACM1"), default_baud("/dev/ttyUSB0"), default_baud("COM3")
    (115200, 57600, 57600)
    >>> default_baud("/dev/serial/by-id/usb-ArduPilot_CubeOrange_2E0039-if00")
    115200
    >>> default_baud("/dev/serial/by-id/usb-FTDI_FT231X_USB_UART_DN05-if00-port0")
    57600
    """
    name = os.path.basename(device)
    if name.startswith("ttyACM") or "ArduPilot" in name:
        return USB_BAUD
    if device.startswith("/dev/serial/by-id/usb-"):
        # USB-to-UART bridges (radios, FTDI cables) end in -portN; USB CDC devices do not
        return RADIO_BAUD if re.search(r"-port\d+$", name) else USB_BAUD
    if device.startswith("/") and os.path.islink(device):  # a udev rule's name: its device's
        target = os.path.basename(os.path.realpath(device))
        return USB_BAUD if target.startswith("ttyACM") else RADIO_BAUD
    return RADIO_BAUD


def parse_endpoint(text: str | Endpoint) -> Endpoint:
    """Read a connection as an operator writes it (the forms in this module's table).

    Parameters
    ----------
    text : str or Endpoint
        The connection (an Endpoint is returned as it is).

    Returns
    -------
    Endpoint

    Raises
    ------
    EndpointError
        One line naming the value, what is wrong and the accepted forms.

    Examples
    --------
    >>> parse_endpoint("udpin:0.0.0.0:14550")
    Endpoint(kind='udpin', host='0.0.0.0', port=14550, device='', baud=0, flow_control=False)
    >>> parse_endpoint("serial:///dev/ttyUSB0:115200").baud
    115200
    >>> try:
    ...     parse_endpoint("udpout://:14550")
    ... except EndpointError as exc:
    ...     print(exc)
    connection 'udpout://:14550': udpout needs the vehicle's address (accepted: ...)
    """
    if isinstance(text, Endpoint):
        return text
    raw = str(text)
    value = raw.strip()
    if not value:
        raise EndpointError(raw, "empty")
    if value.startswith(PATHS) or _COM.fullmatch(value.split(",")[0].split(":")[0]):
        return _serial(raw, value, flow_control=False)
    m = _SCHEME.fullmatch(value)
    if m is not None and m.group(1).lower() in SCHEMES:
        scheme, rest = m.group(1).lower(), m.group(2)
        kind = SCHEMES[scheme]
        if kind == "serial":
            return _serial(raw, rest, flow_control=scheme == "serial_flowcontrol")
        return _network(raw, kind, rest, scheme)
    if _HOST_PORT.fullmatch(value) and not value.startswith(":"):
        return _network(raw, "udpin", value, "udpin")  # MAVProxy's HOST:PORT: listen
    if m is not None and "://" in value:
        raise EndpointError(raw, f"unknown scheme {m.group(1)[:20]!r}")
    raise EndpointError(raw, "not a serial port, UDP or TCP connection")


def _serial(raw: str, rest: str, flow_control: bool) -> Endpoint:
    device, baud = _DEVICE_BAUD.fullmatch(rest).groups()
    if not (device.startswith(PATHS) or _COM.fullmatch(device)):
        raise EndpointError(raw, "a serial port is a /dev/... path (or ./NAME) or COMn")
    if device.startswith("~/"):
        device = os.path.expanduser(device)
    if device.endswith("/"):
        raise EndpointError(raw, "a serial port is a device, not a directory")
    if baud is None:
        return Endpoint(
            "serial", device=device, baud=default_baud(device), flow_control=flow_control
        )
    if not MIN_BAUD <= int(baud) <= MAX_BAUD:
        raise EndpointError(raw, f"baud rate {int(baud)} is outside {MIN_BAUD}..{MAX_BAUD}")
    return Endpoint("serial", device=device, baud=int(baud), flow_control=flow_control)


def _network(raw: str, kind: str, rest: str, scheme: str) -> Endpoint:
    if kind in ("udpin", "tcpin") and rest.rstrip("/").isdigit():
        rest = ":" + rest.rstrip("/")  # udpin:14550, tcpin://5760: every interface
    m = _HOST_PORT.fullmatch(rest)
    if m is None:
        raise EndpointError(raw, f"{scheme} needs HOST:PORT")
    host, port = m.group(1), int(m.group(2))
    bracketed = host.startswith("[")
    host = host.strip("[]")
    if not bracketed and host and not _HOSTNAME.fullmatch(host):
        raise EndpointError(raw, f"{host[:40]!r} is not a host name or address")
    if not 0 < port < 65536:
        raise EndpointError(raw, f"port {port} is outside 1..65535")
    if kind in ("udpin", "tcpin"):
        host = host or "0.0.0.0"
    elif host in LISTEN_ANY:
        raise EndpointError(raw, f"{scheme} needs the vehicle's address")
    return Endpoint(kind, host=host, port=port)

"""MAVLink addresses: one parser for every form preland takes, and the forms its libraries want.

preland writes a MAVLink address as a runtime URL (`mavlink+udp://:14550`, `mavlink+udpout://HOST:PORT`,
`mavlink+tcp://HOST:PORT`, `mavlink+serial:///dev/ttyAMA0?baud=921600`). The forms that MAVSDK, ArduPilot
and pymavlink write are taken too, so a user can paste what those tools print: `udp://:14550`,
`udpout://HOST:PORT`, `tcp://HOST:PORT`, `serial:///dev/ttyAMA0:921600` (MAVSDK), and `udp:HOST:PORT`,
`udpin:HOST:PORT`, `udpout:HOST:PORT`, `udpclient:HOST:PORT` (pymavlink, ArduPilot's --serialN).
"""

from __future__ import annotations

from dataclasses import dataclass
from urllib.parse import parse_qsl

from ..errors import PrelandError

PREFIX = "mavlink+"
# udp: listen; udpout: send first; tcp: connect to a server; tcpin: be the server; serial: a device.
KINDS = ("udp", "udpout", "tcp", "tcpin", "serial")
DEFAULT_BAUD = 57600  # ArduPilot's SERIALn_BAUD default for telemetry ports
_ALIASES = {"udp": "udp", "udpin": "udp", "udpout": "udpout", "udpclient": "udpout", "tcp": "tcp",
            "tcpout": "tcp", "tcpin": "tcpin", "serial": "serial"}
FORMS = ("mavlink+udp://[HOST]:PORT", "mavlink+udpout://HOST:PORT", "mavlink+tcp://HOST:PORT",
         "mavlink+tcpin://[HOST]:PORT", "mavlink+serial:///dev/DEVICE?baud=N")


class EndpointError(PrelandError):
    """A MAVLink address that cannot be read."""


@dataclass(frozen=True, kw_only=True)
class Endpoint:
    """A MAVLink link: `kind` (udp: listen on host:port; udpout: send to host:port first; tcp: connect to a
    server at host:port; tcpin: serve TCP on host:port; serial: `device` at `baud`)."""

    kind: str
    host: str = ""
    port: int = 0
    device: str = ""
    baud: int = DEFAULT_BAUD

    @property
    def url(self) -> str:
        """preland's own form of it."""
        if self.kind == "serial":
            return f"{PREFIX}serial://{self.device}?baud={self.baud}"
        return f"{PREFIX}{self.kind}://{self.host}:{self.port}"

    def mavsdk_url(self) -> str:
        """As MAVSDK's `add_any_connection` takes it, in MAVSDK 3's spelling (`udpin://`, `tcpout://`: its
        `udp://` and `tcp://` are deprecated); a listening address without a host listens on every one."""
        if self.kind == "serial":
            return f"serial://{self.device}:{self.baud}"
        scheme = {"udp": "udpin", "udpout": "udpout", "tcp": "tcpout", "tcpin": "tcpin"}[self.kind]
        host = self.host or ("0.0.0.0" if self.kind in ("udp", "tcpin") else "")
        return f"{scheme}://{host}:{self.port}"

    def pymavlink_address(self) -> str:
        """As pymavlink's `mavutil.mavlink_connection` takes it (UDP only: what a served face listens on)."""
        if self.kind not in ("udp", "udpout"):
            raise EndpointError(f"{self.url}: only UDP addresses can be served")
        return f"{'udpin' if self.kind == 'udp' else 'udpout'}:{self.host or '0.0.0.0'}:{self.port}"

    def host_port(self) -> tuple[str, int]:
        if self.kind == "serial":
            raise EndpointError(f"{self.url}: a serial device has no host and port")
        return self.host or "127.0.0.1", self.port


def _problem(text: str) -> EndpointError:
    return EndpointError(f"{text!r}: not a MAVLink address (expected one of: {', '.join(FORMS)})")


def parse_endpoint(text: str) -> Endpoint:
    """Read any of the forms in the module's docstring; EndpointError naming the forms otherwise."""
    body = text.strip()
    if body.startswith(PREFIX):
        body = body[len(PREFIX):]
        if "://" not in body:
            raise _problem(text)
    if "://" in body:
        scheme, _, rest = body.partition("://")
    else:  # pymavlink and ArduPilot: KIND:HOST:PORT
        scheme, _, rest = body.partition(":")
    kind = _ALIASES.get(scheme.lower())
    if kind is None:
        raise _problem(text)
    if kind == "serial":
        return _serial(text, rest)
    rest, _, query = rest.partition("?")
    if query:
        raise EndpointError(f"{text!r}: a {kind} address takes no options (got ?{query})")
    host, sep, port = rest.rpartition(":")
    if not sep or not port.isdigit() or not 0 < int(port) < 65536:
        raise EndpointError(f"{text!r}: needs a port from 1 to 65535 ({kind}://HOST:PORT)")
    if kind in ("udpout", "tcp") and not host:
        raise EndpointError(f"{text!r}: a {kind} address needs the host to send to ({kind}://HOST:PORT)")
    return Endpoint(kind=kind, host=host, port=int(port))


def _serial(text: str, rest: str) -> Endpoint:
    path, _, query = rest.partition("?")
    baud = DEFAULT_BAUD
    if query:
        options = dict(parse_qsl(query, keep_blank_values=True))
        unknown = sorted(set(options) - {"baud"})
        if unknown:
            raise EndpointError(f"{text!r}: unknown option {unknown[0]!r} (a serial address takes baud)")
        baud_text = options["baud"]
    else:  # MAVSDK's serial:///dev/ttyAMA0:921600
        path, sep, baud_text = path.rpartition(":") if ":" in path else (path, "", "")
        baud_text = baud_text if sep else str(DEFAULT_BAUD)
    if not baud_text.isdigit() or int(baud_text) <= 0:
        raise EndpointError(f"{text!r}: baud must be a positive whole number, got {baud_text!r}")
    if not path.startswith("/"):
        raise EndpointError(f"{text!r}: needs a device path (serial:///dev/ttyAMA0?baud=921600)")
    return Endpoint(kind="serial", device=path, baud=int(baud_text))

"""PRELAND_FAULT_INJECTION (dialect `preland.xml`): the thesis' fault command as a MAVLink 2 message.

The message layout and its CRC extra come from the dialect XML through
pymavlink's own parser (`pymavlink.generator.mavparse`), so the wire format is
MAVLink's, byte for byte. A running companion listens for it on a UDP port
(`--fault-listen`); `preland fault send` sends it there.
"""

from __future__ import annotations

import asyncio
import socket
import struct
from collections.abc import Callable
from functools import lru_cache
from pathlib import Path

from pymavlink.generator import mavcrc, mavparse

from ..errors import PrelandError
from ..sensing.faults import FaultCommand, FaultSyntaxError

DIALECT = Path(__file__).with_name("preland.xml")
MAGIC_V2 = 0xFD
_TYPES = {"uint8_t": "B", "uint16_t": "H", "float": "f"}


class FaultMessageError(PrelandError):
    """A fault command cannot be sent or parsed."""


@lru_cache(maxsize=1)
def _definition():
    xml = mavparse.MAVXML(str(DIALECT), wire_protocol_version=mavparse.PROTOCOL_2_0)
    (message,) = [m for m in xml.message if m.name == "PRELAND_FAULT_INJECTION"]
    layout = "<" + "".join(_TYPES[field.type] for field in message.ordered_fields)
    return message.id, message.crc_extra, [f.name for f in message.ordered_fields], layout


def encode(command: FaultCommand, *, system_id: int = 255, component_id: int = 190, target_system: int = 0,
           target_component: int = 0, sequence: int = 0) -> bytes:
    """One MAVLink 2 frame carrying `command`."""
    message_id, crc_extra, names, layout = _definition()
    values = {"target_system": target_system, "target_component": target_component, "target": int(command.target),
              "r_drop": float(command.r_drop), "p_keep": command.p_keep, "p_drop": command.p_drop}
    payload = struct.pack(layout, *(values[name] for name in names))
    header = struct.pack("<BBBBBBBHB", MAGIC_V2, len(payload), 0, 0, sequence & 0xFF, system_id, component_id,
                         message_id & 0xFFFF, message_id >> 16)
    crc = mavcrc.x25crc(header[1:] + payload)
    crc.accumulate(struct.pack("B", crc_extra))
    return header + payload + struct.pack("<H", crc.crc)


def decode(frame: bytes) -> FaultCommand | None:
    """The command in a MAVLink 2 frame, or None when the frame is another message or corrupt."""
    message_id, crc_extra, names, layout = _definition()
    if len(frame) < 12 or frame[0] != MAGIC_V2:
        return None
    length = frame[1]
    if len(frame) < 10 + length + 2:
        return None
    frame_id = frame[7] | (frame[8] << 8) | (frame[9] << 16)
    if frame_id != message_id:
        return None
    crc = mavcrc.x25crc(frame[1:10 + length])
    crc.accumulate(struct.pack("B", crc_extra))
    if struct.unpack("<H", frame[10 + length:12 + length])[0] != crc.crc:
        return None
    # MAVLink 2 trims trailing zero bytes from payloads.
    payload = frame[10:10 + length].ljust(struct.calcsize(layout), b"\0")
    values = dict(zip(names, struct.unpack(layout, payload)))
    try:
        return FaultCommand(target=values["target"], r_drop=values["r_drop"], p_keep=values["p_keep"],
                            p_drop=values["p_drop"])
    except (FaultSyntaxError, ValueError):
        return None


def _address(url: str) -> tuple[str, int]:
    """`udp:HOST:PORT`, `udpout://HOST:PORT` or `udp://HOST:PORT` -> (host, port)."""
    rest = url.split("://", 1)[1] if "://" in url else url.partition(":")[2]
    host, _, port = rest.rpartition(":")
    if not port.isdigit():
        raise FaultMessageError(f"{url!r}: expected udp://HOST:PORT")
    return host or "127.0.0.1", int(port)


def send(command: FaultCommand, *, url: str) -> None:
    """Send the command to a companion listening at `url`."""
    host, port = _address(url)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.sendto(encode(command), (host, port))


class _Receiver(asyncio.DatagramProtocol):
    def __init__(self, on_command: Callable[[FaultCommand], None]) -> None:
        self.on_command = on_command

    def datagram_received(self, data: bytes, addr) -> None:
        command = decode(data)
        if command is not None:
            self.on_command(command)


async def listen(url: str, on_command: Callable[[FaultCommand], None]) -> asyncio.DatagramTransport:
    """Start listening for fault commands at `url`; close the returned transport to stop."""
    host, port = _address(url)
    try:
        transport, _ = await asyncio.get_running_loop().create_datagram_endpoint(
            lambda: _Receiver(on_command), local_addr=(host, port))
    except OSError as error:
        raise FaultMessageError(f"--fault-listen {url}: {error.strerror or error}") from None
    return transport

"""preland's MAVLink dialect (`preland.xml`): its messages framed and read as MAVLink 2, byte for byte.

The layouts and CRC extras come from the XML through pymavlink's own parser
(`pymavlink.generator.mavparse`); neither MAVSDK nor pymavlink's compiled
dialects know these messages, so they are framed here and sent or read as
plain bytes (or, through MAVSDK, after `xml_text()` is loaded).
"""

from __future__ import annotations

import struct
from functools import lru_cache
from pathlib import Path

from pymavlink.generator import mavcrc, mavparse

DIALECT = Path(__file__).with_name("preland.xml")
MAGIC_V2 = 0xFD
_TYPES = {"uint8_t": "B", "uint16_t": "H", "uint32_t": "I", "float": "f"}


@lru_cache(maxsize=1)
def _messages() -> dict:
    xml = mavparse.MAVXML(str(DIALECT), wire_protocol_version=mavparse.PROTOCOL_2_0)
    return {m.name: m for m in xml.message}


@lru_cache(maxsize=8)
def definition(name: str) -> tuple[int, int, list[str], str]:
    """(message id, CRC extra, field names in wire order, struct layout) of message `name`."""
    message = _messages()[name]
    layout = "<" + "".join(_TYPES[field.type] for field in message.ordered_fields)
    return message.id, message.crc_extra, [f.name for f in message.ordered_fields], layout


def message_id(name: str) -> int:
    return definition(name)[0]


def xml_text() -> str:
    """The dialect's XML, as MAVSDK's MavlinkDirect.load_custom_xml takes it."""
    return DIALECT.read_text()


def encode_frame(name: str, values: dict, *, system_id: int, component_id: int, sequence: int = 0) -> bytes:
    """One MAVLink 2 frame of message `name` with `values` (every field)."""
    msg_id, crc_extra, names, layout = definition(name)
    payload = struct.pack(layout, *(values[field] for field in names))
    header = struct.pack("<BBBBBBBHB", MAGIC_V2, len(payload), 0, 0, sequence & 0xFF, system_id, component_id,
                         msg_id & 0xFFFF, msg_id >> 16)
    crc = mavcrc.x25crc(header[1:] + payload)
    crc.accumulate(struct.pack("B", crc_extra))
    return header + payload + struct.pack("<H", crc.crc)


def decode_frame(name: str, frame: bytes) -> dict | None:
    """The fields of a MAVLink 2 frame of message `name`, or None when it is another message or corrupt."""
    msg_id, crc_extra, names, layout = definition(name)
    if len(frame) < 12 or frame[0] != MAGIC_V2:
        return None
    length = frame[1]
    if len(frame) < 10 + length + 2:
        return None
    if frame[7] | (frame[8] << 8) | (frame[9] << 16) != msg_id:
        return None
    crc = mavcrc.x25crc(frame[1:10 + length])
    crc.accumulate(struct.pack("B", crc_extra))
    if struct.unpack("<H", frame[10 + length:12 + length])[0] != crc.crc:
        return None
    # MAVLink 2 trims trailing zero bytes from payloads.
    payload = frame[10:10 + length].ljust(struct.calcsize(layout), b"\0")
    return dict(zip(names, struct.unpack(layout, payload)))

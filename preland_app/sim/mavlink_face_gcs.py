"""What a ground station asks of the MAVLink face beyond flying: the mission protocol and MAVLink FTP, answered
as ArduCopter 4.6 answers a vehicle with no stored mission, and as a vehicle without FTP files.

Mission (GCS_Common.cpp, MissionItemProtocol*.cpp): item 0 of the MISSION list is always home, so a vehicle
with no mission counts 1; FENCE and RALLY hold nothing (count 0); any other mission type is UNSUPPORTED.
MISSION_REQUEST_INT answers MISSION_ITEM_INT; the old MISSION_REQUEST answers MISSION_ITEM (float degrees)
and warns once, as ArduPilot does. Uploads are refused with MISSION_ACK UNSUPPORTED (the embedded autopilot
has no AUTO mode to fly them); an empty upload and MISSION_CLEAR_ALL are accepted, there being nothing to keep.

FTP (GCS_FTP.cpp's reply layout): every request gets its reply at once, so a ground station's parameter
download over FTP (MAVProxy's @PARAM/param.pck) falls back to PARAM_REQUEST_LIST instead of timing out:
session resets are ACKed, file operations are NAKed FileNotFound (reads) or Fail (writes), reads and writes in a
session NAKed InvalidSession, and unknown opcodes UnknownCommand.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from ..geo import GeoPoint

# MAVLink FTP opcodes and error codes (the FILE_TRANSFER_PROTOCOL payload's own protocol).
FTP_ACK = 128
FTP_NAK = 129
FTP_ERR_FAIL = 1
FTP_ERR_INVALID_SESSION = 4
FTP_ERR_UNKNOWN_COMMAND = 7
FTP_ERR_FILE_NOT_FOUND = 10
_FTP_ACKED = {0, 1, 2}  # None, TerminateSession, ResetSessions
_FTP_NAK_ERROR = {
    3: FTP_ERR_FILE_NOT_FOUND,  # ListDirectory
    4: FTP_ERR_FILE_NOT_FOUND,  # OpenFileRO
    5: FTP_ERR_INVALID_SESSION,  # ReadFile
    6: FTP_ERR_FAIL,  # CreateFile
    7: FTP_ERR_INVALID_SESSION,  # WriteFile
    8: FTP_ERR_FILE_NOT_FOUND,  # RemoveFile
    9: FTP_ERR_FAIL,  # CreateDirectory
    10: FTP_ERR_FILE_NOT_FOUND,  # RemoveDirectory
    11: FTP_ERR_FAIL,  # OpenFileWO
    12: FTP_ERR_FILE_NOT_FOUND,  # TruncateFile
    13: FTP_ERR_FILE_NOT_FOUND,  # Rename
    14: FTP_ERR_FILE_NOT_FOUND,  # CalcFileCRC32
    15: FTP_ERR_INVALID_SESSION,  # BurstReadFile
}
_FTP_HEADER = struct.Struct("<HBBBBBBI")  # seq, session, opcode, size, req_opcode, burst_complete, padding, offset
FTP_PAYLOAD_LEN = 251

_MISSION = mavlink2.MAV_MISSION_TYPE_MISSION
_EMPTY_TYPES = (mavlink2.MAV_MISSION_TYPE_FENCE, mavlink2.MAV_MISSION_TYPE_RALLY)


def ftp_reply(request: bytes | list[int]) -> bytes:
    """The 251-byte reply to one FTP request payload, as ArduPilot lays it out: seq + 1, the same session,
    the request's opcode as req_opcode, ACK or NAK with its one-byte error code."""
    raw = bytes(request)[:FTP_PAYLOAD_LEN].ljust(FTP_PAYLOAD_LEN, b"\0")
    seq, session, opcode, *_ = _FTP_HEADER.unpack_from(raw)
    if opcode in _FTP_ACKED:
        header, data = _FTP_HEADER.pack((seq + 1) & 0xFFFF, session, FTP_ACK, 0, opcode, 0, 0, 0), b""
    else:
        error = _FTP_NAK_ERROR.get(opcode, FTP_ERR_UNKNOWN_COMMAND)
        header, data = _FTP_HEADER.pack((seq + 1) & 0xFFFF, session, FTP_NAK, 1, opcode, 0, 0, 0), bytes([error])
    return (header + data).ljust(FTP_PAYLOAD_LEN, b"\0")


class GroundStationServices:
    """Mission and FTP handlers of `MavlinkFace` (mixed in): they reply on the channel being served through
    `self.mav`, warn through `self._say` and read home from `self.home_location()`."""

    _mission_request_warned = False
    # Provided by MavlinkFace, the only class this is mixed into.
    mav: Any
    home_location: Callable[[], GeoPoint]
    _say: Callable[..., None]

    def _mission_ack(self, message, result: int) -> None:
        self.mav.mission_ack_send(message.get_srcSystem(), message.get_srcComponent(), result,
                                  message.mission_type)

    def _mission_count(self, message, mission_type: int) -> None:
        count = 1 if mission_type == _MISSION else 0
        self.mav.mission_count_send(message.get_srcSystem(), message.get_srcComponent(), count, mission_type)

    @staticmethod
    def _known_type(mission_type: int) -> bool:
        return mission_type == _MISSION or mission_type in _EMPTY_TYPES

    def _on_mission_request_list(self, message) -> None:
        if not self._known_type(message.mission_type):
            self._mission_ack(message, mavlink2.MAV_MISSION_UNSUPPORTED)
            return
        self._mission_count(message, message.mission_type)

    def _home_item_or_refusal(self, message) -> GeoPoint | None:
        """Home for a request of MISSION item 0; otherwise the refusal ArduPilot sends, and None."""
        if not self._known_type(message.mission_type):
            self._mission_ack(message, mavlink2.MAV_MISSION_UNSUPPORTED)
            return None
        if message.mission_type != _MISSION:
            self._mission_ack(message, mavlink2.MAV_MISSION_INVALID_SEQUENCE)
            return None
        if message.seq != 0:
            # ArduPilot tells the ground station the real size before refusing.
            self._mission_count(message, _MISSION)
            self._mission_ack(message, mavlink2.MAV_MISSION_ERROR)
            return None
        return self.home_location()

    def _on_mission_request_int(self, message) -> None:
        home = self._home_item_or_refusal(message)
        if home is None:
            return
        self.mav.mission_item_int_send(message.get_srcSystem(), message.get_srcComponent(), 0,
                                       mavlink2.MAV_FRAME_GLOBAL, mavlink2.MAV_CMD_NAV_WAYPOINT, 0, 1,
                                       0.0, 0.0, 0.0, 0.0, int(round(home.latitude_deg * 1e7)),
                                       int(round(home.longitude_deg * 1e7)), float(home.altitude_amsl_m), _MISSION)

    def _on_mission_request(self, message) -> None:
        home = self._home_item_or_refusal(message)
        if home is None:
            return
        if not self._mission_request_warned:
            self._mission_request_warned = True
            self._say("got MISSION_REQUEST; use MISSION_REQUEST_INT!")
        self.mav.mission_item_send(message.get_srcSystem(), message.get_srcComponent(), 0,
                                   mavlink2.MAV_FRAME_GLOBAL, mavlink2.MAV_CMD_NAV_WAYPOINT, 0, 1,
                                   0.0, 0.0, 0.0, 0.0, home.latitude_deg, home.longitude_deg,
                                   float(home.altitude_amsl_m), _MISSION)

    def _on_mission_clear_all(self, message) -> None:
        known = self._known_type(message.mission_type)
        self._mission_ack(message, mavlink2.MAV_MISSION_ACCEPTED if known else mavlink2.MAV_MISSION_UNSUPPORTED)

    def _on_mission_count(self, message) -> None:
        """An upload: refused (nothing here could fly it), except an empty one, which stores nothing."""
        if self._known_type(message.mission_type) and message.count == 0:
            self._mission_ack(message, mavlink2.MAV_MISSION_ACCEPTED)
        else:
            self._mission_ack(message, mavlink2.MAV_MISSION_UNSUPPORTED)

    def _on_file_transfer_protocol(self, message) -> None:
        self.mav.file_transfer_protocol_send(0, message.get_srcSystem(), message.get_srcComponent(),
                                             list(ftp_reply(message.payload)))

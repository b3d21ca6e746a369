"""PRELAND_FAULT_INJECTION (dialect `preland.xml`): the thesis' fault command as a MAVLink 2 message.

Framed by `preland_app.mavlink.dialect`, so the wire format is MAVLink's, byte
for byte. A running companion listens for it on a UDP port
(`--fault-listen`); `preland fault send` sends it there. The thesis' command has
no acknowledgement; the dialect adds PRELAND_FAULT_ACK, which the companion
sends back, so a sender knows whether anyone took the command.
"""

from __future__ import annotations

import asyncio
import socket
from collections.abc import Callable

from ..errors import PrelandError
from .dialect import decode_frame, encode_frame
from .endpoint import EndpointError, parse_endpoint
from ..sensing.faults import FaultCommand, FaultSyntaxError


class FaultMessageError(PrelandError):
    """A fault command cannot be sent or parsed."""


ACK_APPLIED = 0
ACK_IGNORED = 1
ACK_TIMEOUT_S = 1.0  # wall seconds a sender waits for PRELAND_FAULT_ACK


def encode(command: FaultCommand, *, system_id: int = 255, component_id: int = 190, target_system: int = 0,
           target_component: int = 0, sequence: int = 0) -> bytes:
    """One MAVLink 2 frame carrying `command`."""
    values = {"target_system": target_system, "target_component": target_component, "target": int(command.target),
              "r_drop": float(command.r_drop), "p_keep": command.p_keep, "p_drop": command.p_drop}
    return encode_frame("PRELAND_FAULT_INJECTION", values, system_id=system_id, component_id=component_id,
                        sequence=sequence)


def encode_ack(*, target: int, result: int, system_id: int = 1, component_id: int = 191) -> bytes:
    """One MAVLink 2 frame carrying PRELAND_FAULT_ACK."""
    return encode_frame("PRELAND_FAULT_ACK", {"target_system": 0, "target_component": 0, "target": target,
                                              "result": result}, system_id=system_id, component_id=component_id)


def decode_ack(frame: bytes) -> dict[str, int] | None:
    """The fields of a PRELAND_FAULT_ACK frame, or None when the frame is another message or corrupt."""
    return decode_frame("PRELAND_FAULT_ACK", frame)


def decode(frame: bytes) -> FaultCommand | None:
    """The command in a MAVLink 2 frame, or None when the frame is another message or corrupt."""
    values = decode_frame("PRELAND_FAULT_INJECTION", frame)
    if values is None:
        return None
    try:
        return FaultCommand(target=values["target"], r_drop=values["r_drop"], p_keep=values["p_keep"],
                            p_drop=values["p_drop"])
    except (FaultSyntaxError, ValueError):
        return None


def _address(url: str) -> tuple[str, int]:
    """Any UDP form `parse_endpoint` reads (`udp://HOST:PORT`, `udp:HOST:PORT`, `mavlink+udp://...`) ->
    (host, port)."""
    try:
        endpoint = parse_endpoint(url)
    except EndpointError:
        raise FaultMessageError(f"{url!r}: expected udp://HOST:PORT") from None
    if endpoint.kind not in ("udp", "udpout"):
        raise FaultMessageError(f"{url!r}: expected udp://HOST:PORT (the fault command travels over UDP)")
    return endpoint.host_port()


def send(command: FaultCommand, *, url: str, ack_timeout_s: float | None = ACK_TIMEOUT_S) -> int | None:
    """Send the command to a companion listening at `url` and wait up to `ack_timeout_s` wall seconds for
    its PRELAND_FAULT_ACK. Returns the ack's result (ACK_APPLIED, ACK_IGNORED), or None when not waiting
    (`ack_timeout_s=None`). Raises FaultMessageError when no acknowledgement comes."""
    host, port = _address(url)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        try:
            sock.connect((host, port))  # connected: an ICMP "port unreachable" surfaces as an error
            sock.send(encode(command))
        except OSError as error:
            raise FaultMessageError(f"{url}: {error.strerror or error}") from None
        if ack_timeout_s is None:
            return None
        sock.settimeout(ack_timeout_s)
        try:
            while True:
                ack = decode_ack(sock.recv(512))
                if ack is not None and ack["target"] == int(command.target):
                    return int(ack["result"])
        except ConnectionRefusedError:
            raise FaultMessageError(f"{url}: nothing listens there (is a companion flying with "
                                    "--fault-listen at this address?)") from None
        except (TimeoutError, socket.timeout):
            raise FaultMessageError(f"{url}: no acknowledgement within {ack_timeout_s:g} s (is a companion "
                                    "flying with --fault-listen at this address?)") from None


class _Receiver(asyncio.DatagramProtocol):
    def __init__(self, on_command: Callable[[FaultCommand], bool | None]) -> None:
        self.on_command = on_command
        self.transport: asyncio.DatagramTransport | None = None

    def connection_made(self, transport) -> None:
        self.transport = transport

    def datagram_received(self, data: bytes, addr) -> None:
        command = decode(data)
        if command is not None:
            applied = self.on_command(command)
            if self.transport is not None:
                self.transport.sendto(encode_ack(target=int(command.target),
                                                 result=ACK_IGNORED if applied is False else ACK_APPLIED), addr)


async def listen(url: str, on_command: Callable[[FaultCommand], bool | None]) -> asyncio.DatagramTransport:
    """Start listening for fault commands at `url` and acknowledge each one to its sender (`on_command`
    returns False when the command was ignored); close the returned transport to stop."""
    host, port = _address(url)
    try:
        transport, _ = await asyncio.get_running_loop().create_datagram_endpoint(
            lambda: _Receiver(on_command), local_addr=(host, port))
    except OSError as error:
        raise FaultMessageError(f"--fault-listen {url}: {error.strerror or error}") from None
    return transport

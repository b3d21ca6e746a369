"""A UDP relay between SITL's first serial port and MAVSDK that counts the MAVLink frames passed each way.

In lock-step (`vehicle.lockstep_clock`) the companion must have taken in, before it acts at a vehicle time,
everything SITL sent up to that time, and SITL must have, before its next step, what the companion sent.
MAVSDK receives and sends on threads of its own, where neither can be seen; the relay, between the two
sockets, sees both. A frame is counted under its message name, a COMMAND_LONG under
`COMMAND_LONG:<command>` (MAVSDK sends commands of its own too). SITL sends to `sitl_port`; the relay
passes what comes to MAVSDK's port, and MAVSDK's answers (to the relay's address) back to SITL.

A message MAVSDK also sends on a wall-clock timer of its own (its HEARTBEAT each wall second) reaches SITL at
whatever vehicle time this machine's speed gives. Once `gate(key)` is called, the relay passes a frame of
`key` from MAVSDK only as `allow(key)` admits one (the companion sends its own at vehicle times) and drops
the others.
"""

from __future__ import annotations

import collections
import select
import socket
import struct
import threading
from collections.abc import Callable

from ..mavlink.dialect import MAGIC_V2

_POLL_WALL_S = 0.2  # how often the relay's thread looks whether it is to stop (wall s)
_COMMAND_LONG = 76
_COMMAND_OFFSET = 28  # of `command` (uint16) in COMMAND_LONG's payload, after its seven floats


def _names() -> dict[int, str]:
    from pymavlink.dialects.v20 import ardupilotmega

    return {message_id: cls.msgname for message_id, cls in ardupilotmega.mavlink_map.items()}


def frame_keys(data: bytes, names: dict[int, str]) -> list[str]:
    """The keys of the MAVLink 1 and 2 frames in one datagram, in order (a message id without a name: `#id`)."""
    return [key for key, _, _ in frame_spans(data, names)]


def frame_spans(data: bytes, names: dict[int, str]) -> list[tuple[str, int, int]]:
    """(key, start, end) of each MAVLink 1 and 2 frame in one datagram, in order (see `frame_keys`)."""
    spans, index = [], 0
    while index + 8 <= len(data):
        magic, length = data[index], data[index + 1]
        if magic == MAGIC_V2:  # MAVLink 2: incompat, compat, seq, sysid, compid, 3-byte id; 13 more bytes if signed
            message_id = data[index + 7] | data[index + 8] << 8 | data[index + 9] << 16
            payload, end = index + 10, index + 12 + length + (13 if data[index + 2] & 1 else 0)
        elif magic == 0xFE:  # MAVLink 1: seq, sysid, compid, 1-byte id
            message_id, payload, end = data[index + 5], index + 6, index + 8 + length
        else:
            index += 1
            continue
        key = names.get(message_id, f"#{message_id}")
        if message_id == _COMMAND_LONG:
            body = data[payload:payload + length].ljust(_COMMAND_OFFSET + 2, b"\0")  # MAVLink 2 trims zeros
            key = f"COMMAND_LONG:{struct.unpack_from('<H', body, _COMMAND_OFFSET)[0]}"
        spans.append((key, index, end))
        index = end
    return spans


class MavlinkRelay:
    """Relays SITL <-> MAVSDK (`mavsdk_port`, where MAVSDK listens) on a thread of its own; `from_sitl` and
    `to_sitl` count the frames passed on, by key (see the module)."""

    def __init__(self, *, mavsdk_port: int) -> None:
        self.mavsdk_port = mavsdk_port
        self._names = _names()
        self._sitl = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sitl.bind(("127.0.0.1", 0))
        self.sitl_port = self._sitl.getsockname()[1]
        self._mavsdk = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._mavsdk.bind(("127.0.0.1", 0))
        self._sitl_address: tuple[str, int] | None = None
        self.from_sitl: collections.Counter[str] = collections.Counter()
        self.to_sitl: collections.Counter[str] = collections.Counter()
        self.held_back: collections.Counter[str] = collections.Counter()  # MAVSDK's frames of gated keys dropped
        self._allowed: dict[str, int] = {}  # gated key -> frames of it still admitted
        self._lock = threading.Lock()
        self._passing = False  # a datagram is read and not yet counted and passed on
        self.on_pass: Callable[[], None] | None = None  # called (from the relay's thread) after each datagram
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="preland-sitl-relay", daemon=True)

    def start(self) -> MavlinkRelay:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=2 * _POLL_WALL_S)
        self._sitl.close()
        self._mavsdk.close()

    def gate(self, key: str) -> int:
        """From now on, pass MAVSDK's frames of `key` to SITL only as `allow` admits them; returns how many
        were passed before."""
        with self._lock:
            self._allowed.setdefault(key, 0)
            return self.to_sitl[key]

    def allow(self, key: str) -> None:
        """Admit the next frame of gated `key` from MAVSDK (nothing for a key not gated)."""
        with self._lock:
            if key in self._allowed:
                self._allowed[key] += 1

    def _to_sitl(self, data: bytes) -> None:
        """Pass MAVSDK's `data` on without the frames of gated keys not admitted, and count what passed (under
        the lock, so `gate` counts a frame being passed as it is gated)."""
        with self._lock:
            spans = frame_spans(data, self._names)
            kept = []
            for key, start, end in spans:
                if key in self._allowed:
                    if not self._allowed[key]:
                        self.held_back[key] += 1
                        continue
                    self._allowed[key] -= 1
                kept.append((key, data[start:end]))
            if len(kept) < len(spans):
                if not kept:
                    return
                data = b"".join(frame for _, frame in kept)
            self._sitl.sendto(data, self._sitl_address)  # (bytes in no frame pass as they came)
            self.to_sitl.update(key for key, _ in kept)  # counted once SITL's socket has it

    def idle(self) -> bool:
        """Nothing from SITL is waiting in the relay's socket or being passed on."""
        if self._passing:
            return False
        try:
            readable, _, _ = select.select([self._sitl], [], [], 0)
        except (OSError, ValueError):  # closed: stopped
            return True
        return not readable

    def _run(self) -> None:
        sockets = [self._sitl, self._mavsdk]
        while not self._stop.is_set():
            try:
                readable, _, _ = select.select(sockets, [], [], _POLL_WALL_S)
            except (OSError, ValueError):
                return
            for sock in readable:
                self._passing = True
                try:
                    data, address = sock.recvfrom(65536)
                    if sock is self._sitl:
                        self._sitl_address = address
                        self._mavsdk.sendto(data, ("127.0.0.1", self.mavsdk_port))
                        self.from_sitl.update(frame_keys(data, self._names))  # counted once MAVSDK's socket has it
                    elif self._sitl_address is not None:
                        self._to_sitl(data)
                except OSError:
                    pass  # a closed socket (stopping), or a peer not there yet: UDP drops it as the link would
                finally:
                    self._passing = False
                    if self.on_pass is not None:
                        self.on_pass()

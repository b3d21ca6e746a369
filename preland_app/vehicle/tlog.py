"""MAVLink telemetry logs (.tlog) as MAVProxy and pymavlink's tools read them: each record is an 8-byte
big-endian timestamp in microseconds followed by one MAVLink packet.

The MAVLink backend sees messages as MAVSDK decodes them (name and fields);
they are packed again with pymavlink under their sender's system and component
ids. Messages pymavlink cannot pack (unknown to its dialect) are counted and left out.
"""

from __future__ import annotations

import struct
import time
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2


class TlogWriter:
    """Appends decoded MAVLink messages to a .tlog file."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = self.path.open("wb")
        self._encoders: dict[tuple[int, int], mavlink2.MAVLink] = {}
        self.written = 0
        self.skipped = 0

    def _encoder(self, system_id: int, component_id: int) -> mavlink2.MAVLink:
        key = (system_id, component_id)
        if key not in self._encoders:
            self._encoders[key] = mavlink2.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        return self._encoders[key]

    def write(self, *, name: str, fields: dict[str, Any], system_id: int, component_id: int,
              wall_time_s: float | None = None) -> bool:
        cls = getattr(mavlink2, f"MAVLink_{name.lower()}_message", None)
        if cls is None:
            self.skipped += 1
            return False
        try:
            arguments = []
            for field_name in cls.fieldnames:
                value = fields.get(field_name, 0)
                if isinstance(value, str):
                    value = value.encode("utf-8")
                arguments.append(value)
            packet = cls(*arguments).pack(self._encoder(system_id, component_id))
        except (TypeError, ValueError, struct.error):
            self.skipped += 1
            return False
        stamp_us = int((wall_time_s if wall_time_s is not None else time.time()) * 1e6)
        self._file.write(struct.pack(">Q", stamp_us) + packet)
        self.written += 1
        return True

    def close(self) -> None:
        self._file.close()

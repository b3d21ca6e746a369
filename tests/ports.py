"""Free local UDP ports for the tests' servers (served vehicles, fault listeners, a tutorial's vehicle).

Chosen below the system's ephemeral range, and free when chosen. A port from inside that range would be free
only until the server binds it: meanwhile any program's socket bound to port 0 (a companion's MAVSDK, a JSON
bridge) may be given it, and a companion would then read, or a server hold, another test's datagrams. Below
the range only another explicit choice can take it, which the server's own bind then refuses aloud.
"""

from __future__ import annotations

import random
import socket
from pathlib import Path

# Below the well-known ports the tests and ArduPilot use (5760, 9002, 14550) are avoided too.
LOWEST_PORT = 20000
_RANGE_FILE = Path("/proc/sys/net/ipv4/ip_local_port_range")
_CHOICE = random.SystemRandom()  # xdist workers started together must not draw the same sequence


def _ephemeral_low() -> int:
    try:
        return int(_RANGE_FILE.read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return 32768  # Linux's default, and what other systems' ranges lie above


def free_udp_port() -> int:
    """A 127.0.0.1 UDP port nobody holds now, outside the ephemeral range (inside it where that range leaves
    no room below it)."""
    high = _ephemeral_low() - 1
    for _ in range(200):
        port = _CHOICE.randint(LOWEST_PORT, high) if high > LOWEST_PORT + 1000 else 0
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            try:
                probe.bind(("127.0.0.1", port))
            except OSError:
                continue
            return probe.getsockname()[1]
    raise RuntimeError(f"no free UDP port from {LOWEST_PORT} to {high} in 200 tries")

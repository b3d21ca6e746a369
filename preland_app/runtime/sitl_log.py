"""What a SITL trial's dataflash log (`SitlOptions.log_dir`) tells about ArduCopter's own estimate.

SITL logs its physics' truth (SIM) beside ArduCopter's estimate (ATT) at the same instants, so the
estimate's error is their difference, whatever the physics (SITL's own, or preland's over the JSON bridge).
"""

from __future__ import annotations

import math
from pathlib import Path

AIRBORNE_M = 1.0
"""Instants count as airborne when the truth is more than this above its first logged altitude (m)."""


def attitude_estimate_errors_deg(log: Path) -> list[float]:
    """ArduCopter's roll and pitch estimate errors (ATT - SIM, degrees), two per logged instant while
    airborne."""
    from pymavlink import mavutil

    reader = mavutil.mavlink_connection(str(log))
    att = None
    ground_m = None
    errors: list[float] = []
    while (message := reader.recv_match(type=["ATT", "SIM"])) is not None:
        if message.get_type() == "ATT":
            att = message
            continue
        ground_m = message.Alt if ground_m is None else ground_m
        if att is not None and att.TimeUS == message.TimeUS and message.Alt - ground_m > AIRBORNE_M:
            errors += [att.Roll - message.Roll, att.Pitch - message.Pitch]
    return errors


def rms(values: list[float]) -> float:
    """The root mean square of `values` (nan for none)."""
    return math.sqrt(sum(v * v for v in values) / len(values)) if values else float("nan")

"""What a SITL trial's dataflash log (`SitlOptions.log_dir`) tells about ArduCopter's own estimate.

SITL logs its physics' truth (SIM, SIM2) beside ArduCopter's estimate (ATT, XKF1), so the estimate's error is
their difference, whatever the physics (SITL's own, or preland's over the JSON bridge).
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


HIGH_PASS_S = 4.0
"""The window (s) of the centred moving average `horizontal_estimate_errors` takes off the position error."""


def horizontal_estimate_errors(log: Path, *, core: int = 0) -> tuple[list[float], list[float]]:
    """ArduCopter's horizontal velocity and position estimate errors while airborne, from EKF3 core `core`
    (XKF1) against the truth logged just before it (SIM2): (velocity errors in m/s, north and east of each
    instant; position errors in m, likewise). The position error is high-passed (less its centred
    HIGH_PASS_S moving average), which takes off what moves slowly: the offset between the EKF's origin and
    SITL's home, and the GPS error SITL is given (its glitch offsets), so what is left is how far the
    estimate strays from its GPS."""
    from pymavlink import mavutil

    reader = mavutil.mavlink_connection(str(log))
    truth = None
    ground_m = None
    velocity: list[float] = []
    rows: list[tuple[float, float, float]] = []
    while (message := reader.recv_match(type=["XKF1", "SIM2"])) is not None:
        if message.get_type() == "SIM2":
            truth = message
            ground_m = message.PD if ground_m is None else ground_m
            continue
        if truth is None or message.C != core or ground_m - truth.PD <= AIRBORNE_M:
            continue
        velocity += [message.VN - truth.VN, message.VE - truth.VE]
        rows.append((message.TimeUS * 1e-6, message.PN - truth.PN, message.PE - truth.PE))
    return velocity, high_passed(rows)


def high_passed(rows: list[tuple[float, float, float]]) -> list[float]:
    """(time s, north, east) rows less their centred HIGH_PASS_S moving average, north and east of each row,
    leaving out rows too near either end of the rows for a centred average."""
    out: list[float] = []
    half_s = HIGH_PASS_S / 2
    start = 0
    for time_s, north, east in rows:
        while rows[start][0] < time_s - half_s:
            start += 1
        if rows[start][0] > time_s - half_s + 0.5:
            continue
        stop = start
        while stop < len(rows) and rows[stop][0] <= time_s + half_s:
            stop += 1
        if rows[stop - 1][0] < time_s + half_s - 0.5:
            continue
        window = rows[start:stop]
        out += [north - sum(r[1] for r in window) / len(window), east - sum(r[2] for r in window) / len(window)]
    return out


def rms(values: list[float]) -> float:
    """The root mean square of `values` (nan for none)."""
    return math.sqrt(sum(v * v for v in values) / len(values)) if values else float("nan")

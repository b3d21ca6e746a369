"""Value types the Vehicle protocol speaks: modes, states, telemetry, landing targets.

Units and frames are in every field name. These types are plain frozen
dataclasses so that every backend (embedded simulator, MAVLink, fake) builds
the same values.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass


class FlightMode(enum.Enum):
    """ArduCopter flight modes preland uses, valued by ArduCopter's custom_mode number."""

    STABILIZE = 0
    GUIDED = 4
    LOITER = 5
    RTL = 6
    LAND = 9
    POSHOLD = 16

    @classmethod
    def parse(cls, text: str) -> "FlightMode":
        try:
            return cls[text.strip().upper()]
        except KeyError:
            names = ", ".join(m.name for m in cls)
            raise ValueError(f"unknown flight mode {text!r} (expected one of {names})") from None


class LandedState(enum.Enum):
    """Like MAVLink's MAV_LANDED_STATE."""

    UNDEFINED = 0
    ON_GROUND = 1
    IN_AIR = 2
    TAKING_OFF = 3
    LANDING = 4


@dataclass(frozen=True, slots=True)
class PositionNed:
    """A position in metres, NED, relative to home."""

    north_m: float
    east_m: float
    down_m: float

    def horizontal_distance_m(self, other: "PositionNed") -> float:
        return math.hypot(self.north_m - other.north_m, self.east_m - other.east_m)


@dataclass(frozen=True, slots=True)
class VelocityNed:
    """A velocity in m/s, NED."""

    north_m_s: float
    east_m_s: float
    down_m_s: float

    @property
    def horizontal_m_s(self) -> float:
        return math.hypot(self.north_m_s, self.east_m_s)


@dataclass(frozen=True, slots=True)
class GlobalPosition:
    """WGS-84 position: degrees; altitude AMSL and relative to home, in m."""

    latitude_deg: float
    longitude_deg: float
    altitude_amsl_m: float
    altitude_rel_m: float


@dataclass(frozen=True, slots=True)
class Attitude:
    """Euler angles in degrees (body FRD relative to NED)."""

    roll_deg: float
    pitch_deg: float
    yaw_deg: float


@dataclass(frozen=True, slots=True)
class Battery:
    voltage_v: float
    remaining_pct: float


@dataclass(frozen=True, slots=True, kw_only=True)
class Telemetry:
    """One snapshot of what the autopilot reports. Everything here is *estimated*.

    `time_s` is the vehicle clock; `position_ned_m` is relative to home;
    `height_above_ground_m` comes from the rangefinder when it is in range and
    otherwise from the barometric altitude above home (as ArduCopter does).
    """

    time_s: float
    armed: bool
    mode: FlightMode
    landed_state: LandedState
    position_ok: bool
    position_ned_m: PositionNed
    velocity_ned_m_s: VelocityNed
    global_position: GlobalPosition
    home: GlobalPosition
    attitude: Attitude
    height_above_ground_m: float
    rangefinder_valid: bool
    battery: Battery

    @property
    def altitude_rel_m(self) -> float:
        return -self.position_ned_m.down_m


class LandingTargetFrame(enum.Enum):
    """MAV_FRAME values ArduPilot accepts in LANDING_TARGET."""

    BODY_FRD = 12
    LOCAL_FRD = 20


@dataclass(frozen=True, slots=True, kw_only=True)
class LandingTarget:
    """The content of a MAVLink LANDING_TARGET message.

    `angle_x_rad` / `angle_y_rad`: angles of the target off the downward
    camera axis in radians, as ArduPilot reads them: the unit direction to the
    target in body FRD is proportional to (-tan(angle_y), tan(angle_x), 1), so
    angle_x > 0 means the target is to the right and angle_y > 0 means it is
    behind. `distance_m` is the range to the target in m, or None when the
    sensor measures none (IR-LOCK).
    `timestamp_s` is the capture time on the vehicle clock.
    """

    timestamp_s: float
    angle_x_rad: float
    angle_y_rad: float
    distance_m: float | None = None
    size_x_rad: float = 0.0
    size_y_rad: float = 0.0
    target_num: int = 0
    frame: LandingTargetFrame = LandingTargetFrame.BODY_FRD
    position_valid: bool = False
    position_frd_m: tuple[float, float, float] | None = None

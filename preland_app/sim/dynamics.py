"""Multirotor motion: a point mass tilted by a lagged attitude, with drag, wind and ground contact.

The autopilot's inner loops (attitude and climb-rate controllers, motor mixing)
are folded into first-order responses: the lean angles follow their demand with
time constant `attitude_tau_s`; the vertical acceleration follows the autopilot's
demand (its z velocity loop, PSC_VELZ_P) with the thrust lag `thrust_tau_s`.
Horizontal acceleration comes from the thrust tilt
(g tan(lean)) and linear drag of the air-relative velocity. The docs' "The error model" (explanation)
says what this leaves out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from .spec import AirframeSpec

GRAVITY_M_S2 = 9.80665


@dataclass(slots=True, kw_only=True)
class Touchdown:
    """One ground contact. Position NED in m from the simulation origin (true)."""

    time_s: float
    north_m: float
    east_m: float
    vertical_speed_m_s: float
    tilt_deg: float
    crashed: bool


@dataclass(slots=True)
class BodyState:
    """True state. Position NED in m from the simulation origin; velocity NED in m/s;
    attitude roll/pitch/yaw in rad (body FRD relative to NED)."""

    north_m: float = 0.0
    east_m: float = 0.0
    down_m: float = 0.0
    velocity_north_m_s: float = 0.0
    velocity_east_m_s: float = 0.0
    velocity_down_m_s: float = 0.0
    roll_rad: float = 0.0
    pitch_rad: float = 0.0
    yaw_rad: float = 0.0
    accel_up_m_s2: float = 0.0
    on_ground: bool = True
    touchdowns: list[Touchdown] = field(default_factory=list)


@dataclass(slots=True)
class ActuatorDemand:
    """What the autopilot asks of the airframe: lean angles (rad), yaw (rad), the climb rate it wants
    (m/s, up) and the vertical acceleration its velocity loop asks for to get there (m/s/s, up)."""

    roll_rad: float = 0.0
    pitch_rad: float = 0.0
    yaw_rad: float = 0.0
    climb_rate_m_s: float = 0.0
    climb_accel_m_s2: float = 0.0
    motors_armed: bool = False


class MultirotorDynamics:
    """Integrates `BodyState` forward (semi-implicit Euler)."""

    def __init__(self, *, airframe: AirframeSpec, state: BodyState | None = None) -> None:
        self.airframe = airframe
        self.state = state or BodyState()
        self._yaw_rate_max_rad_s = math.radians(airframe.yaw_rate_max_deg_s)

    def step(self, *, dt_s: float, time_s: float, demand: ActuatorDemand,
             wind_ned_m_s: tuple[float, float, float]) -> None:
        s = self.state
        airframe = self.airframe
        if s.on_ground:
            if not (demand.motors_armed and demand.climb_rate_m_s > 0.05):
                # Resting on the ground: the airframe is level and does not slide.
                s.velocity_north_m_s = s.velocity_east_m_s = s.velocity_down_m_s = 0.0
                s.roll_rad = s.pitch_rad = 0.0
                s.accel_up_m_s2 = 0.0
                s.down_m = 0.0
                return
            s.on_ground = False

        if demand.motors_armed:
            att_gain = min(1.0, dt_s / airframe.attitude_tau_s)
            s.roll_rad += (demand.roll_rad - s.roll_rad) * att_gain
            s.pitch_rad += (demand.pitch_rad - s.pitch_rad) * att_gain
            yaw_error = (demand.yaw_rad - s.yaw_rad + math.pi) % (2.0 * math.pi) - math.pi
            max_step = self._yaw_rate_max_rad_s * dt_s
            s.yaw_rad += max(-max_step, min(max_step, yaw_error))
            # Thrust tilt -> horizontal acceleration in the body frame, rotated to NED.
            tan_pitch = math.tan(s.pitch_rad)
            accel_forward = -GRAVITY_M_S2 * tan_pitch
            accel_right = GRAVITY_M_S2 * math.tan(s.roll_rad) / max(math.cos(s.pitch_rad), 0.2)
            cy, sy = math.cos(s.yaw_rad), math.sin(s.yaw_rad)
            accel_north = accel_forward * cy - accel_right * sy
            accel_east = accel_forward * sy + accel_right * cy
            thrust_gain = min(1.0, dt_s / airframe.thrust_tau_s)
            s.accel_up_m_s2 += (demand.climb_accel_m_s2 - s.accel_up_m_s2) * thrust_gain
            climb_rate = -s.velocity_down_m_s + s.accel_up_m_s2 * dt_s
            # Vertical gusts push the vehicle until the climb-rate loop catches up.
            climb_rate += (-wind_ned_m_s[2] - climb_rate) * airframe.drag_per_s * dt_s * 0.5
            s.velocity_down_m_s = -climb_rate
        else:
            # Motors off: it falls.
            accel_north = accel_east = 0.0
            s.velocity_down_m_s += GRAVITY_M_S2 * dt_s

        drag = airframe.drag_per_s
        accel_north += drag * (wind_ned_m_s[0] - s.velocity_north_m_s)
        accel_east += drag * (wind_ned_m_s[1] - s.velocity_east_m_s)
        s.velocity_north_m_s += accel_north * dt_s
        s.velocity_east_m_s += accel_east * dt_s
        s.north_m += s.velocity_north_m_s * dt_s
        s.east_m += s.velocity_east_m_s * dt_s
        s.down_m += s.velocity_down_m_s * dt_s

        if s.down_m >= 0.0:
            self._touch_down(time_s)

    def _touch_down(self, time_s: float) -> None:
        s = self.state
        tilt_deg = math.degrees(math.acos(max(-1.0, min(1.0, math.cos(s.roll_rad) * math.cos(s.pitch_rad)))))
        vertical_speed = s.velocity_down_m_s
        crashed = vertical_speed > self.airframe.crash_speed_m_s or tilt_deg > 60.0
        s.touchdowns.append(
            Touchdown(time_s=time_s, north_m=s.north_m, east_m=s.east_m,
                      vertical_speed_m_s=vertical_speed, tilt_deg=tilt_deg, crashed=crashed)
        )
        s.down_m = 0.0
        s.on_ground = True
        s.velocity_north_m_s = s.velocity_east_m_s = s.velocity_down_m_s = 0.0
        s.accel_up_m_s2 = 0.0
        s.roll_rad = s.pitch_rad = 0.0

"""An ArduCopter-like autopilot: flight modes, arming, take-off, position control, landing.

It controls on the *estimated* state (`NavEstimate`), never the truth. Modes and
their behaviour follow ArduCopter 4.x:

* GUIDED: take-off, position targets (WPNAV_SPEED / WPNAV_ACCEL), velocity
  targets that time out after GUID_TIMEOUT, hold;
* LOITER, POSHOLD: hold the stopping point (no pilot sticks here, so POSHOLD's braking and
  stick mixing reduce to LOITER's hold);
* LAND: hold the stopping point horizontally (4.6: the held target of a running position controller, else
  where the vehicle is); descend as mode_land.cpp does
  (sqrt-shaped approach to LAND_ALT_LOW at up to LAND_SPEED_HIGH or
  WPNAV_SPEED_DN, then LAND_SPEED); disarm on land detection;
* RTL: climb to RTL_ALT, return home, loiter RTL_LOIT_TIME, land (or, with
  RTL_ALT_FINAL > 0, descend to it and hold there, as mode_rtl.cpp does).

Positions inside are NED in metres from the simulation origin, in the
estimate's frame; commands relative to home are converted on entry.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from ..errors import CommandDenied
from ..vehicle.types import FlightMode, LandedState, LandingTarget
from .shaping import AltitudeShaper, PositionShaper
from .control import HorizontalController, VerticalController, sqrt_controller, stopping_distance_m
from .dynamics import GRAVITY_M_S2, ActuatorDemand
from .navigation import NavEstimate
from .params import ParameterTable
from .precland import PrecisionLandingEstimator
from .precland_retry import Action, LandingRetry
from .spec import Firmware

LAND_DETECTOR_TRIGGER_S = 1.0  # ArduCopter LAND_DETECTOR_TRIGGER_SEC
LAND_DETECTOR_MAYBE_TRIGGER_S = 0.2  # LAND_DETECTOR_MAYBE_TRIGGER_SEC
LAND_RANGEFINDER_MIN_ALT_M = 2.0  # LAND_RANGEFINDER_MIN_ALT_CM
ARMING_DELAY_S = 2.0  # ArduCopter config.h ARMING_DELAY_SEC: motors spin this long after arming
# mode_land.cpp's precision-landing slow-down near the ground.
PRECLAND_SLOWDOWN_MIN_HEIGHT_M = 0.35
PRECLAND_SLOWDOWN_MAX_HEIGHT_M = 2.0
PRECLAND_ACCEPTABLE_ERROR_M = 0.15
PRECLAND_MIN_DESCENT_SPEED_M_S = 0.10
PLND_TYPE_COMPANION = 1
TAKEOFF_COMPLETE_MARGIN_M = 0.1
LOITER_VEL_CORRECTION_MAX_M_S = 2.0  # AC_Loiter.cpp LOITER_VEL_CORRECTION_MAX
# PLND_OPTIONS bits (AC_PrecLand.h).
PLND_OPTION_MOVING_TARGET = 1
PLND_OPTION_PRECLAND_AFTER_REPOSITION = 2
PLND_OPTION_FAST_DESCEND = 4
_ARMABLE_MODES = (FlightMode.GUIDED, FlightMode.LOITER, FlightMode.POSHOLD, FlightMode.STABILIZE)
_POSITION_MODES = (FlightMode.GUIDED, FlightMode.LOITER, FlightMode.POSHOLD, FlightMode.RTL, FlightMode.LAND)


class GuidedTarget(enum.Enum):
    NONE = "none"
    TAKEOFF = "takeoff"
    POSITION = "position"
    VELOCITY = "velocity"


class RtlStage(enum.Enum):
    CLIMB = "climb"
    RETURN = "return"
    LOITER = "loiter"
    FINAL_DESCENT = "final_descent"
    FINAL = "final"


@dataclass(frozen=True, slots=True)
class StatusText:
    """A STATUSTEXT-like message from the autopilot (vehicle time in s)."""

    time_s: float
    text: str


class Autopilot:
    """The flight-control logic. One instance per simulated vehicle."""

    def __init__(self, *, params: ParameterTable, initial_yaw_rad: float = 0.0,
                 firmware: Firmware = Firmware.COPTER_4_0) -> None:
        """`firmware`: the ArduCopter release whose precision landing this follows (`sim.spec.Firmware`)."""
        self.params = params
        self.firmware = firmware
        self.mode = FlightMode.STABILIZE
        self.armed = False
        self.land_complete = True
        self.home_set = False
        self.home_north_m = 0.0
        self.home_east_m = 0.0
        self.home_down_m = 0.0
        self.messages: list[StatusText] = []
        self.landing_targets_received = 0
        self.precland = PrecisionLandingEstimator(params, firmware=firmware)
        # copter-4.6: the position controller's kinematic target (AC_PosControl 4.1+); None when not running
        self._shaper: PositionShaper | None = None
        self.retry = LandingRetry(params)
        self._precland_active = False
        self._retry_hold: tuple[float, float, float] | None = None
        self._retry_messages_seen = 0
        self.nav: NavEstimate | None = None
        self.yaw_rad = initial_yaw_rad
        self.roll_rad = 0.0
        self.pitch_rad = 0.0
        self.yaw_target_rad = initial_yaw_rad
        self._xy = HorizontalController()
        self._z = VerticalController()
        self._guided = GuidedTarget.NONE
        self._target_north_m = 0.0
        self._target_east_m = 0.0
        self._target_down_m = 0.0
        self._velocity_target = (0.0, 0.0, 0.0)
        self._velocity_target_time_s = 0.0
        self._yaw_rate_rad_s = 0.0
        self._rtl_stage = RtlStage.CLIMB
        self._rtl_stage_time_s = 0.0
        self._rtl_alt_m = 0.0
        self._land_detector_s = 0.0
        self._landed_since_s = 0.0
        self._armed_at_s = 0.0
        self._takeoff_at_s = 0.0
        self._climb_shaper: AltitudeShaper | None = None  # copter-4.6's take-off target
        self._now_s = 0.0
        self.last_climb_demand_m_s = 0.0
        # What the control loop derives from the parameters, recomputed when the table changes
        # (`_derive_from_params`).
        self._params_version = -1
        self._precland_enabled = False
        self._angle_max_rad = 0.0
        self._loiter_accel_m_s2 = 0.0
        self._derive_from_params()

    # ------------------------------------------------------------------ helpers

    def _say(self, text: str) -> None:
        self.messages.append(StatusText(self._now_s, text))

    def _nav(self, operation: str) -> NavEstimate:
        if self.nav is None:
            raise CommandDenied(operation=operation, reason="autopilot not started")
        return self.nav

    def altitude_above_home_m(self) -> float:
        return -(self.nav.down_m - self.home_down_m) if self.nav else 0.0

    def rangefinder_alt_ok(self) -> bool:
        return self.nav is not None and self.nav.rangefinder_m is not None

    def height_above_ground_m(self) -> float:
        """Rangefinder height when in range, else altitude above home (as ArduCopter's get_alt_above_ground_cm)."""
        if self.nav is not None and self.nav.rangefinder_m is not None:
            return self.nav.rangefinder_m
        return self.altitude_above_home_m()

    def _stopping_point(self) -> tuple[float, float]:
        nav = self._nav("stopping point")
        speed = math.hypot(nav.velocity_north_m_s, nav.velocity_east_m_s)
        if speed < 1e-3:
            return nav.north_m, nav.east_m
        distance = stopping_distance_m(speed, self.params.value("PSC_POSXY_P"), self.params.m_s("WPNAV_ACCEL"))
        return (nav.north_m + nav.velocity_north_m_s / speed * distance,
                nav.east_m + nav.velocity_east_m_s / speed * distance)

    def _hold_here(self) -> None:
        north, east = self._stopping_point()
        self._target_north_m, self._target_east_m = north, east
        self._target_down_m = self._nav("hold").down_m

    # ------------------------------------------------------------------ commands

    def arm(self) -> None:
        nav = self._nav("arm")
        if self.armed:
            return
        if self.params.value("ARMING_CHECK") != 0 and not nav.position_ok:
            raise CommandDenied(operation="arm", reason="PreArm: Need Position Estimate")
        if self.mode not in _ARMABLE_MODES:
            raise CommandDenied(operation="arm", reason=f"Mode not armable: {self.mode.name}")
        self.armed = True
        self.land_complete = True
        self._landed_since_s = self._now_s
        self._armed_at_s = self._now_s
        # ArduCopter sets home where it arms.
        self.home_north_m, self.home_east_m, self.home_down_m = nav.north_m, nav.east_m, nav.down_m
        self.home_set = True
        self._guided = GuidedTarget.NONE
        self._say("Arming motors")

    def disarm(self, *, force: bool = False, reason: str = "") -> None:
        if not self.armed:
            return
        if not force and not self.land_complete:
            raise CommandDenied(operation="disarm", reason="vehicle is flying (use LAND)")
        self.armed = False
        self._guided = GuidedTarget.NONE
        self._say("Disarming motors" + (f": {reason}" if reason else ""))

    def set_mode(self, mode: FlightMode) -> None:
        nav = self._nav("set_mode")
        if mode in _POSITION_MODES and not nav.position_ok:
            raise CommandDenied(operation="set_mode", reason=f"{mode.name} requires a position estimate")
        if mode is FlightMode.RTL and not self.home_set:
            raise CommandDenied(operation="set_mode", reason="RTL requires home")
        previous = self.mode
        # ArduCopter 4.6's LAND (mode_land.cpp) leaves a running xy position controller as it is: from GUIDED
        # at a position, LOITER or POSHOLD it holds the target it had. 3.6/4.0's LAND holds the stopping point.
        keeps_xy_target = (self.firmware is Firmware.COPTER_4_6 and mode is FlightMode.LAND
                           and self._holds_xy_target())
        if not keeps_xy_target:
            self._shaper = None
        self.mode = mode
        if not keeps_xy_target:
            self._xy.reset(velocity_north_m_s=nav.velocity_north_m_s, velocity_east_m_s=nav.velocity_east_m_s)
        self._z.reset(-nav.velocity_down_m_s)
        if mode is FlightMode.GUIDED:
            self._guided = GuidedTarget.NONE
            self._hold_here()
        elif mode in (FlightMode.LOITER, FlightMode.POSHOLD, FlightMode.LAND):
            if keeps_xy_target:
                self._target_down_m = nav.down_m
            elif mode is FlightMode.LAND and self.firmware is Firmware.COPTER_4_6:
                # init_xy_controller: the target starts where the vehicle is, its velocity shaped to zero
                self._target_north_m, self._target_east_m, self._target_down_m = nav.north_m, nav.east_m, nav.down_m
            else:
                self._hold_here()
            self._precland_active = False
            self.retry.reset()
            self._retry_hold = None
        elif mode is FlightMode.RTL:
            self._rtl_stage = RtlStage.CLIMB
            self._rtl_stage_time_s = self._now_s
            self._rtl_alt_m = max(self.params.m_s("RTL_ALT") if self.params.value("RTL_ALT") > 0 else 0.0,
                                  self.altitude_above_home_m())
        if previous is not mode:
            self._say(f"Mode {mode.name}")

    def _holds_xy_target(self) -> bool:
        """Whether the xy position controller is running on a held target: GUIDED at a position (or taking
        off), LOITER, POSHOLD."""
        if self.mode is FlightMode.GUIDED:
            return self._guided in (GuidedTarget.POSITION, GuidedTarget.TAKEOFF)
        return self.mode in (FlightMode.LOITER, FlightMode.POSHOLD)

    def _require_guided(self, operation: str) -> NavEstimate:
        nav = self._nav(operation)
        if self.mode is not FlightMode.GUIDED:
            raise CommandDenied(operation=operation, reason=f"requires GUIDED mode (mode is {self.mode.name})")
        return nav

    def takeoff(self, *, altitude_rel_m: float) -> None:
        nav = self._require_guided("takeoff")
        if not self.armed:
            raise CommandDenied(operation="takeoff", reason="vehicle is not armed")
        if not self.land_complete:
            raise CommandDenied(operation="takeoff", reason="vehicle is already flying")
        if altitude_rel_m <= 0:
            raise CommandDenied(operation="takeoff", reason="altitude must be > 0 m")
        self._guided = GuidedTarget.TAKEOFF
        self._takeoff_at_s = self._now_s
        self._climb_shaper = None
        self._target_north_m, self._target_east_m = nav.north_m, nav.east_m
        self._target_down_m = self.home_down_m - altitude_rel_m
        self._xy.reset()
        self._z.reset()
        self._say(f"Takeoff to {altitude_rel_m:.1f} m")

    def goto(self, *, north_m: float, east_m: float, down_m: float, yaw_rad: float | None) -> None:
        """Position target, NED relative to home."""
        self._require_guided("goto")
        self._guided = GuidedTarget.POSITION
        self._target_north_m = self.home_north_m + north_m
        self._target_east_m = self.home_east_m + east_m
        self._target_down_m = self.home_down_m + down_m
        if yaw_rad is not None:
            self.yaw_target_rad = yaw_rad

    def set_velocity(self, *, north_m_s: float, east_m_s: float, down_m_s: float, yaw_rad: float | None,
                     yaw_rate_rad_s: float = 0.0) -> None:
        self._require_guided("set_velocity")
        self._guided = GuidedTarget.VELOCITY
        self._velocity_target = (north_m_s, east_m_s, down_m_s)
        self._velocity_target_time_s = self._now_s
        self._yaw_rate_rad_s = yaw_rate_rad_s
        if yaw_rad is not None:
            self.yaw_target_rad = yaw_rad

    def hold(self) -> None:
        self._require_guided("hold")
        self._guided = GuidedTarget.POSITION
        self._hold_here()

    def precland_enabled(self) -> bool:
        self._derive_from_params()
        return self._precland_enabled

    def _derive_from_params(self) -> None:
        """Bring what the control loop derives from the parameters up to date (a no-op until one is set)."""
        if self._params_version == self.params.version:
            return
        value = self.params.value
        self._precland_enabled = value("PLND_ENABLED") == 1 and value("PLND_TYPE") == PLND_TYPE_COMPANION
        self._angle_max_rad = math.radians(value("ANGLE_MAX") / 100.0)
        # AC_Loiter's correction acceleration: LOIT_ACC_MAX, at most what ANGLE_MAX allows
        # (AC_Loiter::sanity_check_params).
        self._loiter_accel_m_s2 = min(self.params.m_s("LOIT_ACC_MAX"), GRAVITY_M_S2 * math.tan(self._angle_max_rad))
        self._params_version = self.params.version

    def receive_landing_target(self, target: LandingTarget) -> None:
        """LANDING_TARGET from a companion: fused by the precision-landing estimator when PLND is enabled
        with a companion source (PLND_TYPE=1); ignored otherwise, as ArduCopter does."""
        self.landing_targets_received += 1
        if self.precland_enabled():
            self.precland.handle(self._now_s, target)

    # ------------------------------------------------------------------ state

    def landed_state(self) -> LandedState:
        if not self.armed or self.land_complete:
            return LandedState.ON_GROUND
        if self.mode is FlightMode.GUIDED and self._guided is GuidedTarget.TAKEOFF:
            return LandedState.TAKING_OFF
        if self.mode is FlightMode.LAND or (self.mode is FlightMode.RTL and self._rtl_stage is RtlStage.FINAL):
            return LandedState.LANDING
        return LandedState.IN_AIR

    # ------------------------------------------------------------------ control loop

    def step(self, *, dt_s: float, now_s: float, nav: NavEstimate, yaw_rad: float,
             touching_ground: bool, roll_rad: float = 0.0, pitch_rad: float = 0.0) -> ActuatorDemand:
        """Run one control cycle on the estimate; returns the actuator demand."""
        self._derive_from_params()
        precland_enabled = self._precland_enabled
        if precland_enabled:  # only precision landing reads the gyro
            # The gyro's rate (rad/s) from the attitude's change over the step: small angles, so Euler rates will do.
            yaw_change_rad = math.remainder(yaw_rad - self.yaw_rad, 2 * math.pi)
            gyro_rad_s = math.sqrt((roll_rad - self.roll_rad) ** 2 + (pitch_rad - self.pitch_rad) ** 2
                                   + yaw_change_rad ** 2) / dt_s if dt_s > 0 else 0.0
        self._now_s = now_s
        self.nav = nav
        self.yaw_rad = yaw_rad
        self.roll_rad = roll_rad
        self.pitch_rad = pitch_rad
        if precland_enabled:
            self.precland.predict(dt_s=dt_s, delta_velocity_ned_m_s=(nav.delta_velocity_north_m_s,
                                                                     nav.delta_velocity_east_m_s))
            self.precland.record_pose(now_s, north_m=nav.north_m, east_m=nav.east_m,
                                      height_m=self.height_above_ground_m(),
                                      roll_rad=self.roll_rad + nav.roll_error_rad,
                                      pitch_rad=self.pitch_rad + nav.pitch_error_rad,
                                      yaw_rad=yaw_rad + nav.heading_error_rad, gyro_rad_s=gyro_rad_s,
                                      velocity_ne_m_s=(nav.velocity_north_m_s, nav.velocity_east_m_s))
            self.precland.update(now_s)
        if not self.armed:
            self.last_climb_demand_m_s = 0.0
            return ActuatorDemand(motors_armed=False, yaw_rad=yaw_rad)

        if self.land_complete:
            demand = self._ground_idle(dt_s, nav, yaw_rad)
        elif self.mode is FlightMode.GUIDED:
            demand = self._run_guided(dt_s, nav)
        elif self.mode is FlightMode.LAND:
            demand = self._run_land(dt_s, nav, self._target_north_m, self._target_east_m)
        elif self.mode is FlightMode.RTL:
            demand = self._run_rtl(dt_s, nav)
        else:  # LOITER, POSHOLD, and STABILIZE with no pilot: hold position and altitude
            demand = self._fly_to(dt_s, nav, self._target_north_m, self._target_east_m, self._target_down_m,
                                  speed_max_m_s=self.params.m_s("LOIT_SPEED"), loiter=True)
        self.last_climb_demand_m_s = demand.climb_rate_m_s
        self._update_land_detector(dt_s, touching_ground, demand)
        return demand

    def _ground_idle(self, dt_s: float, nav: NavEstimate, yaw_rad: float) -> ActuatorDemand:
        """Landed and armed: motors at idle until a take-off; auto-disarm after DISARM_DELAY."""
        if self.mode is FlightMode.LAND or (self.mode is FlightMode.RTL):
            self.disarm(reason="landed")
            return ActuatorDemand(motors_armed=False, yaw_rad=yaw_rad)
        if self.firmware is Firmware.COPTER_4_6 and self._now_s - self._armed_at_s < ARMING_DELAY_S:
            # motors.cpp: the motor interlock stays off during the arming delay
            self._xy.reset()
            self._z.reset()
            return ActuatorDemand(motors_armed=False, yaw_rad=yaw_rad)
        taking_off = self.mode is FlightMode.GUIDED and self._guided is GuidedTarget.TAKEOFF
        if taking_off and self._now_s >= self._liftoff_s():
            self.land_complete = False
            self._say("Taking off")
            return self._run_guided(dt_s, nav)
        delay_s = self.params.value("DISARM_DELAY")
        if delay_s > 0 and self._now_s - self._landed_since_s >= delay_s:
            self.disarm(reason="auto-disarm")
            return ActuatorDemand(motors_armed=False, yaw_rad=yaw_rad)
        self._xy.reset()
        self._z.reset()
        return ActuatorDemand(motors_armed=True, yaw_rad=yaw_rad, climb_rate_m_s=-0.5)

    def _liftoff_s(self) -> float:
        """When a commanded take-off leaves the ground, s. `copter-4.6` (takeoff.cpp _AutoTakeoff::run): after the
        arming delay the motors spool up (MOT_SPOOL_TIME), then the throttle ramps at 1 / TKOFF_SLEW_TIME a
        second until the vehicle climbs, at about the hover throttle (MOT_THST_HOVER). 3.6/4.0: at once."""
        if self.firmware is not Firmware.COPTER_4_6:
            return self._takeoff_at_s
        p = self.params
        start_s = max(self._takeoff_at_s, self._armed_at_s + ARMING_DELAY_S)
        return start_s + p.value("MOT_SPOOL_TIME") + p.value("MOT_THST_HOVER") * p.value("TKOFF_SLEW_TIME")

    def _update_land_detector(self, dt_s: float, touching_ground: bool, demand: ActuatorDemand) -> None:
        # Motors at their lower limit happens when the ground pushes back against a descent demand.
        at_lower_limit = touching_ground and demand.climb_rate_m_s <= 0.0
        rangefinder_check = not self.rangefinder_alt_ok() or self.height_above_ground_m() < LAND_RANGEFINDER_MIN_ALT_M
        if at_lower_limit and rangefinder_check:
            self._land_detector_s += dt_s
            if self._land_detector_s >= LAND_DETECTOR_TRIGGER_S and not self.land_complete:
                self.land_complete = True
                self._landed_since_s = self._now_s
                self._say("Land complete")
        else:
            self._land_detector_s = 0.0

    def _fly_to(self, dt_s: float, nav: NavEstimate, north_m: float | None, east_m: float | None,
                down_m: float | None, *, speed_max_m_s: float, climb_rate_m_s: float | None = None,
                velocity_ff: tuple[float, float] = (0.0, 0.0),
                accel_ff: tuple[float, float] | None = None,
                velocity_feedback: tuple[float, float] | None = None,
                loiter: bool = False) -> ActuatorDemand:
        """One position-control step. `loiter`: the position controller as AC_Loiter sets it up (LOITER,
        POSHOLD, LAND): corrections at LOIT_ACC_MAX and at most LOITER_VEL_CORRECTION_MAX; otherwise as
        AC_WPNav does (WPNAV_ACCEL)."""
        value, m_s = self.params.value, self.params.m_s
        if loiter:
            accel_max_m_s2 = self._loiter_accel_m_s2
            speed_max_m_s = min(speed_max_m_s, LOITER_VEL_CORRECTION_MAX_M_S)
        else:
            accel_max_m_s2 = m_s("WPNAV_ACCEL")
        velocity_north, velocity_east = velocity_feedback or (nav.velocity_north_m_s, nav.velocity_east_m_s)
        roll, pitch = self._xy.update(
            dt_s=dt_s,
            yaw_rad=self.yaw_rad,
            est_north_m=nav.north_m,
            est_east_m=nav.east_m,
            est_velocity_north_m_s=velocity_north,
            est_velocity_east_m_s=velocity_east,
            target_north_m=north_m,
            target_east_m=east_m,
            velocity_ff_north_m_s=velocity_ff[0],
            velocity_ff_east_m_s=velocity_ff[1],
            accel_ff_ne_m_s2=accel_ff,
            speed_max_m_s=speed_max_m_s,
            accel_max_m_s2=accel_max_m_s2,
            pos_p=value("PSC_POSXY_P"),
            vel_p=value("PSC_VELXY_P"),
            vel_i=value("PSC_VELXY_I"),
            vel_imax_m_s2=m_s("PSC_VELXY_IMAX"),
            angle_max_rad=self._angle_max_rad,
        )
        accel_z = m_s("WPNAV_ACCEL_Z")
        if climb_rate_m_s is None:
            climb_rate_m_s = self._z.climb_for_altitude(
                target_alt_m=-(down_m if down_m is not None else nav.down_m),
                est_alt_m=-nav.down_m,
                pos_p=value("PSC_POSZ_P"),
                accel_max_m_s2=accel_z,
                speed_up_m_s=m_s("WPNAV_SPEED_UP"),
                speed_down_m_s=m_s("WPNAV_SPEED_DN"),
            )
        climb = self._z.shape(dt_s=dt_s, climb_rate_m_s=climb_rate_m_s, accel_max_m_s2=accel_z)
        climb_accel = self._z.accel_for_climb(dt_s=dt_s, est_climb_rate_m_s=-nav.velocity_down_m_s,
                                              vel_p=value("PSC_VELZ_P"))
        return ActuatorDemand(roll_rad=roll, pitch_rad=pitch, yaw_rad=self.yaw_target_rad,
                              climb_rate_m_s=climb, climb_accel_m_s2=climb_accel, motors_armed=True)

    def _run_guided(self, dt_s: float, nav: NavEstimate) -> ActuatorDemand:
        p = self.params
        if self._guided is GuidedTarget.TAKEOFF:
            climb_rate_m_s, complete = (self._shaped_takeoff_climb_rate(dt_s, nav)
                                        if self.firmware is Firmware.COPTER_4_6 else
                                        (self._takeoff_climb_rate(nav),
                                         -nav.down_m >= -self._target_down_m - TAKEOFF_COMPLETE_MARGIN_M))
            if complete:
                self._guided = GuidedTarget.POSITION
                self._climb_shaper = None
                self._say("Takeoff complete")
            return self._fly_to(dt_s, nav, self._target_north_m, self._target_east_m, self._target_down_m,
                                speed_max_m_s=p.m_s("WPNAV_SPEED"), climb_rate_m_s=climb_rate_m_s)
        if self._guided is GuidedTarget.VELOCITY:
            self._shaper = None  # a later position target starts the path from the vehicle's state
            if self._now_s - self._velocity_target_time_s > p.value("GUID_TIMEOUT"):
                # ArduCopter stops the vehicle when velocity commands stop arriving.
                self._velocity_target = (0.0, 0.0, 0.0)
            vn, ve, vd = self._velocity_target
            self.yaw_target_rad += self._yaw_rate_rad_s * dt_s
            return self._fly_to(dt_s, nav, None, None, None, speed_max_m_s=p.m_s("LOIT_SPEED"),
                                climb_rate_m_s=max(-p.m_s("WPNAV_SPEED_DN"), min(p.m_s("WPNAV_SPEED_UP"), -vd)),
                                velocity_ff=(vn, ve))
        if self.firmware is Firmware.COPTER_4_6:
            # 4.1+: the target moves along a jerk-limited path to the position (input_pos_xyz), followed
            # with its velocity as feed-forward
            shaper = self._running_shaper(nav)
            shaper.to_position((self._target_north_m, self._target_east_m), dt_s=dt_s,
                               speed_max_m_s=p.m_s("WPNAV_SPEED"), accel_max_m_s2=p.m_s("WPNAV_ACCEL"),
                               jerk_max_m_s3=p.value("PSC_JERK_XY"))
            north_m, east_m = shaper.position_ne_m
            return self._fly_to(dt_s, nav, north_m, east_m, self._target_down_m, speed_max_m_s=p.m_s("WPNAV_SPEED"),
                                velocity_ff=(shaper.velocity_ne_m_s[0], shaper.velocity_ne_m_s[1]),
                                accel_ff=(shaper.accel_ne_m_s2[0], shaper.accel_ne_m_s2[1]))
        return self._fly_to(dt_s, nav, self._target_north_m, self._target_east_m, self._target_down_m,
                            speed_max_m_s=p.m_s("WPNAV_SPEED"))

    def _running_shaper(self, nav: NavEstimate) -> PositionShaper:
        """The position controller's kinematic target, started from the vehicle's state (init_xy_controller)."""
        if self._shaper is None:
            self._shaper = PositionShaper(position_ne_m=(nav.north_m, nav.east_m),
                                          velocity_ne_m_s=(nav.velocity_north_m_s, nav.velocity_east_m_s))
        return self._shaper

    def _takeoff_climb_rate(self, nav: NavEstimate) -> float:
        p = self.params
        return self._z.climb_for_altitude(
            target_alt_m=-self._target_down_m, est_alt_m=-nav.down_m, pos_p=p.value("PSC_POSZ_P"),
            accel_max_m_s2=p.m_s("WPNAV_ACCEL_Z"), speed_up_m_s=p.m_s("WPNAV_SPEED_UP"),
            speed_down_m_s=p.m_s("WPNAV_SPEED_DN"))

    def _shaped_takeoff_climb_rate(self, dt_s: float, nav: NavEstimate) -> tuple[float, bool]:
        """4.1+'s take-off (_AutoTakeoff::run): the altitude target moves along a jerk-limited path from where
        the vehicle left the ground (input_pos_vel_accel_z), followed with its climb rate as feed-forward.
        Returns the climb-rate demand (m/s up) and whether the take-off is complete: the target within the
        stopping distance of a tenth of the climb speed, and climbing slower than that."""
        p = self.params
        speed_up_m_s, accel_m_s2 = p.m_s("WPNAV_SPEED_UP"), p.m_s("WPNAV_ACCEL_Z")
        if self._climb_shaper is None:
            # the lift-off is declared when the measured climb acceleration reaches half WPNAV_ACCEL_Z, and
            # init_z_controller starts the target with it
            self._climb_shaper = AltitudeShaper(altitude_m=-nav.down_m, climb_rate_m_s=-nav.velocity_down_m_s,
                                                accel_up_m_s2=0.5 * accel_m_s2)
        shaper = self._climb_shaper
        target_m = -self._target_down_m
        shaper.to_altitude(target_m, dt_s=dt_s, speed_up_m_s=speed_up_m_s, speed_down_m_s=p.m_s("WPNAV_SPEED_DN"),
                           accel_max_m_s2=accel_m_s2, jerk_max_m_s3=p.value("PSC_JERK_Z"))
        correction = sqrt_controller(shaper.altitude_m - (-nav.down_m), p.value("PSC_POSZ_P"), accel_m_s2)
        slow_m_s = 0.1 * speed_up_m_s
        complete = shaper.altitude_m >= target_m - 0.5 * slow_m_s ** 2 / accel_m_s2 and shaper.climb_rate_m_s < slow_m_s
        return shaper.climb_rate_m_s + correction, complete

    def land_descent_rate_m_s(self) -> float:
        """mode_land.cpp's land_run_vertical_control, as a (negative) climb rate in m/s."""
        p = self.params
        land_speed = abs(p.m_s("LAND_SPEED"))
        max_descent = p.m_s("LAND_SPEED_HIGH") if p.value("LAND_SPEED_HIGH") > 0 else p.m_s("WPNAV_SPEED_DN")
        max_descent = max(max_descent, land_speed)  # never faster than allowed, never slower than LAND_SPEED
        alt_low_m = max(p.m_s("LAND_ALT_LOW"), 1.0)
        rate = sqrt_controller(alt_low_m - self.height_above_ground_m(), p.value("PSC_POSZ_P"),
                               p.m_s("WPNAV_ACCEL_Z"))
        return max(-max_descent, min(-land_speed, rate))

    def _run_land(self, dt_s: float, nav: NavEstimate, north_m: float, east_m: float) -> ActuatorDemand:
        climb_rate = self.land_descent_rate_m_s()
        if self.precland_enabled():
            target = self.precland.target_position_m(self._now_s, vehicle_north_m=nav.north_m,
                                                     vehicle_east_m=nav.east_m)
            if target is not None:
                self.retry.note_target(vehicle_ned_m=(nav.north_m, nav.east_m, nav.down_m), target_ne_m=target)
            directive = self.retry.update(now_s=self._now_s, target_found=target is not None,
                                          vehicle_ned_m=(nav.north_m, nav.east_m, nav.down_m),
                                          height_m=self.height_above_ground_m(),
                                          rangefinder_valid=self.rangefinder_alt_ok(), home_down_m=self.home_down_m)
            for text in self.retry.messages[self._retry_messages_seen:]:
                self._say(text)
            self._retry_messages_seen = len(self.retry.messages)
            if directive.action in (Action.GOTO, Action.HOLD):
                self._shaper = None  # the retry flies its own targets from here on
            if directive.action is Action.GOTO:
                self._retry_hold = None
                self._precland_active = False
                return self._fly_to(dt_s, nav, directive.north_m, directive.east_m, directive.down_m,
                                    speed_max_m_s=self.params.m_s("WPNAV_SPEED"))
            if directive.action is Action.HOLD:
                self._precland_active = False
                if self._retry_hold is None:
                    stop_n, stop_e = self._stopping_point()
                    self._retry_hold = (stop_n, stop_e, nav.down_m)
                return self._fly_to(dt_s, nav, *self._retry_hold, speed_max_m_s=self.params.m_s("LOIT_SPEED"),
                                    loiter=True)
            self._retry_hold = None
            if target is not None:
                if not self._precland_active:
                    self._say("PrecLand: target acquired")
                self._precland_active = True
                self._shaper = None
                north_m, east_m = target
                self._target_north_m, self._target_east_m = target
                climb_rate = self._precland_descent_rate_m_s(nav, target, climb_rate)
                # ArduCopter 3.6/4.0 (the thesis' autopilot) feeds the xy velocity loop with the
                # estimator's target-relative velocity instead of the EKF's (override_vehicle_velocity_xy);
                # 4.1 and later leave it on the EKF's (input_pos_vel_accel_xy).
                relative_velocity = self.precland.relative_velocity_m_s(self._now_s)
                feedback = None
                if relative_velocity is not None and self.firmware is Firmware.COPTER_4_0:
                    feedback = (-relative_velocity[0], -relative_velocity[1])
                # PLND_OPTIONS bit 0 (moving target): the target's estimated ground velocity is the
                # velocity feed-forward (AC_PrecLand::get_target_velocity_cms); otherwise it is zero.
                target_velocity = (0.0, 0.0)
                if self._plnd_option(PLND_OPTION_MOVING_TARGET) and relative_velocity is not None:
                    target_velocity = (relative_velocity[0] + nav.velocity_north_m_s,
                                       relative_velocity[1] + nav.velocity_east_m_s)
                return self._fly_to(dt_s, nav, north_m, east_m, None, speed_max_m_s=self.params.m_s("LOIT_SPEED"),
                                    climb_rate_m_s=climb_rate, velocity_feedback=feedback,
                                    velocity_ff=target_velocity, loiter=True)
            if self._precland_active:
                # Target lost: hold where we are and keep descending (PLND_STRICT=0 behaviour).
                self._precland_active = False
                self._say("PrecLand: target lost")
                north_m, east_m = self._stopping_point()
                self._target_north_m, self._target_east_m = north_m, east_m
        if self._shaper is not None:
            # 4.6's LAND from a running position controller: its target stops along its path
            # (input_vel_accel_xy with zero velocity), at LAND's WPNAV_ACCEL
            p = self.params
            self._shaper.to_stop(dt_s=dt_s, accel_max_m_s2=p.m_s("WPNAV_ACCEL"), jerk_max_m_s3=p.value("PSC_JERK_XY"))
            north_m, east_m = self._shaper.position_ne_m
            return self._fly_to(dt_s, nav, north_m, east_m, None, speed_max_m_s=p.m_s("LOIT_SPEED"),
                                climb_rate_m_s=climb_rate, loiter=True,
                                velocity_ff=(self._shaper.velocity_ne_m_s[0], self._shaper.velocity_ne_m_s[1]),
                                accel_ff=(self._shaper.accel_ne_m_s2[0], self._shaper.accel_ne_m_s2[1]))
        return self._fly_to(dt_s, nav, north_m, east_m, None, speed_max_m_s=self.params.m_s("LOIT_SPEED"),
                            climb_rate_m_s=climb_rate, loiter=True)

    def _plnd_option(self, bit: int) -> bool:
        return int(self.params.value("PLND_OPTIONS")) & bit != 0

    def _precland_descent_rate_m_s(self, nav: NavEstimate, target: tuple[float, float], climb_rate: float) -> float:
        """mode_land.cpp with a target: no descent while farther than PLND_XY_DIST_MAX; between 0.35 and
        2 m above the target, descend slower the larger the horizontal error, unless PLND_OPTIONS bit 2."""
        error_m = math.hypot(target[0] - nav.north_m, target[1] - nav.east_m)
        xy_dist_max_m = self.params.value("PLND_XY_DIST_MAX")
        if xy_dist_max_m > 0 and error_m > xy_dist_max_m:
            return 0.0
        height_m = self.precland.last_measured_height_m
        if self._plnd_option(PLND_OPTION_FAST_DESCEND):
            # PLND_OPTIONS bit 2: keep LAND_SPEED in the final descent (no slow-down near the target).
            return climb_rate
        if height_m is not None and PRECLAND_SLOWDOWN_MIN_HEIGHT_M < height_m < PRECLAND_SLOWDOWN_MAX_HEIGHT_M:
            max_descent = abs(self.params.m_s("LAND_SPEED")) * 0.5
            slowdown = max(0.0, error_m * max_descent / PRECLAND_ACCEPTABLE_ERROR_M)
            return min(-PRECLAND_MIN_DESCENT_SPEED_M_S, -max_descent + slowdown)
        return climb_rate

    def _run_rtl(self, dt_s: float, nav: NavEstimate) -> ActuatorDemand:
        p = self.params
        home_n, home_e = self.home_north_m, self.home_east_m
        target_down = self.home_down_m - self._rtl_alt_m
        speed = p.m_s("RTL_SPEED") if p.value("RTL_SPEED") > 0 else p.m_s("WPNAV_SPEED")
        stage = self._rtl_stage
        if stage is RtlStage.CLIMB:
            if -nav.down_m >= -target_down - 0.3:
                self._next_rtl_stage(RtlStage.RETURN)
            return self._fly_to(dt_s, nav, self._target_north_m, self._target_east_m, target_down,
                                speed_max_m_s=speed)
        if stage is RtlStage.RETURN:
            if math.hypot(nav.north_m - home_n, nav.east_m - home_e) < 0.5:
                self._next_rtl_stage(RtlStage.LOITER)
            return self._fly_to(dt_s, nav, home_n, home_e, target_down, speed_max_m_s=speed)
        if stage is RtlStage.LOITER:
            if self._now_s - self._rtl_stage_time_s >= p.value("RTL_LOIT_TIME") / 1000.0:
                # mode_rtl.cpp: with RTL_ALT_FINAL > 0, descend to it and stay there instead of landing.
                self._next_rtl_stage(RtlStage.FINAL_DESCENT if p.value("RTL_ALT_FINAL") > 0 else RtlStage.FINAL)
            return self._fly_to(dt_s, nav, home_n, home_e, target_down, speed_max_m_s=speed)
        if stage is RtlStage.FINAL_DESCENT:
            return self._fly_to(dt_s, nav, home_n, home_e, self.home_down_m - p.m_s("RTL_ALT_FINAL"),
                                speed_max_m_s=speed, loiter=True)
        return self._run_land(dt_s, nav, home_n, home_e)

    def _next_rtl_stage(self, stage: RtlStage) -> None:
        self._rtl_stage = stage
        self._rtl_stage_time_s = self._now_s
        if stage is RtlStage.FINAL:
            self._say("RTL: landing")
        elif stage is RtlStage.FINAL_DESCENT:
            self._say("RTL: descending to RTL_ALT_FINAL")

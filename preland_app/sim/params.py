"""The simulated autopilot's parameters, by ArduPilot name and in ArduPilot units.

Defaults, ranges (the @Range documentation; ArduPilot itself does not enforce them) and storage types are
ArduCopter 4.6's (checked against the 4.6.2 source tree: ArduCopter/Parameters.cpp, AC_WPNav, AC_Loiter,
AC_PosControl, AC_PrecLand, AP_RangeFinder_Params, AP_Arming, AP_MultiCopter.h) unless noted. The simulator
reads them in SI units through the helpers on `ParameterTable`; users and missions read and write them by
name exactly as they would on a real ArduCopter, and an integer parameter keeps only what ArduPilot's
AP_Param::set_float would keep.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from dataclasses import KW_ONLY, dataclass

import numpy as np

from .spec import Firmware


class ParamKind(enum.Enum):
    """ArduPilot's storage type of a parameter, valued by its MAV_PARAM_TYPE on the wire."""

    INT8 = 2  # AP_Int8 (and AP_Enum): MAV_PARAM_TYPE_INT8
    INT16 = 4  # AP_Int16: MAV_PARAM_TYPE_INT16
    INT32 = 6  # AP_Int32: MAV_PARAM_TYPE_INT32
    REAL32 = 9  # AP_Float: MAV_PARAM_TYPE_REAL32

    @property
    def mav_param_type(self) -> int:
        return self.value

    @property
    def is_integer(self) -> bool:
        return self is not ParamKind.REAL32

    @property
    def limits(self) -> tuple[float, float]:
        """What the storage type can hold."""
        bits = {ParamKind.INT8: 8, ParamKind.INT16: 16, ParamKind.INT32: 32}.get(self)
        if bits is None:
            return -3.4028234663852886e38, 3.4028234663852886e38
        return -(2 ** (bits - 1)), 2 ** (bits - 1) - 1

    def rounded(self, value: float) -> float:
        """An integer type's rounding in AP_Param::set_float: add 0.01 away from zero in float32, then
        truncate, so 2.995 keeps 3 but 2.5 keeps 2. A float stays as is."""
        if not self.is_integer:
            return float(value)
        value32 = np.float32(value)
        nudged = value32 + (np.float32(-0.01) if value32 < 0 else np.float32(0.01))
        return float(math.trunc(float(nudged)))

    def stored(self, value: float) -> float:
        """`value` as ArduPilot stores it (AP_Param::set_float): rounded, then clamped to what the type holds."""
        low, high = self.limits
        return float(min(max(self.rounded(value), low), high))


INT8, INT16, INT32, REAL32 = ParamKind.INT8, ParamKind.INT16, ParamKind.INT32, ParamKind.REAL32


@dataclass(frozen=True, slots=True)
class ParamInfo:
    """One parameter: default, units, meaning, documented range; `kind` is ArduPilot's storage type,
    `ardupilot` False marks a parameter of preland's embedded autopilot only, never served over MAVLink, and
    `firmware` one that the embedded autopilot uses only as that firmware."""

    default: float
    units: str
    description: str
    minimum: float | None = None
    maximum: float | None = None
    _: KW_ONLY
    kind: ParamKind
    ardupilot: bool = True
    firmware: Firmware | None = None


ARDUCOPTER_PARAMS: dict[str, ParamInfo] = {
    # Navigation speeds and accelerations (AC_WPNav.h, AC_Loiter.h: AP_Float; AC_PosControl's gains are
    # AC_P_1D/AC_P_2D/AC_PID_2D/AC_PID_Basic members, all AP_Float).
    "WPNAV_SPEED": ParamInfo(1000, "cm/s", "horizontal waypoint speed", 10, 2000, kind=REAL32),
    "WPNAV_SPEED_UP": ParamInfo(250, "cm/s", "climb speed", 10, 1000, kind=REAL32),
    "WPNAV_SPEED_DN": ParamInfo(150, "cm/s", "descent speed", 10, 500, kind=REAL32),
    "WPNAV_ACCEL": ParamInfo(250, "cm/s/s", "horizontal waypoint acceleration", 50, 500, kind=REAL32),
    "WPNAV_ACCEL_Z": ParamInfo(100, "cm/s/s", "vertical acceleration", 50, 500, kind=REAL32),
    "LOIT_SPEED": ParamInfo(1250, "cm/s", "loiter maximum horizontal speed", 20, 3500, kind=REAL32),
    "LOIT_ACC_MAX": ParamInfo(500, "cm/s/s", "loiter maximum correction acceleration", 100, 981, kind=REAL32),
    "ANGLE_MAX": ParamInfo(3000, "cdeg", "maximum lean angle", 1000, 8000, kind=INT16),  # AP_MultiCopter.h
    "PSC_POSXY_P": ParamInfo(1.0, "1/s", "horizontal position P gain", 0.5, 2.0, kind=REAL32),
    "PSC_VELXY_P": ParamInfo(2.0, "1/s", "horizontal velocity P gain", 0.1, 6.0, kind=REAL32),
    "PSC_VELXY_I": ParamInfo(1.0, "1/s/s", "horizontal velocity I gain", 0.02, 1.0, kind=REAL32),
    "PSC_VELXY_IMAX": ParamInfo(1000, "cm/s/s", "horizontal velocity I limit", 0, 4500, kind=REAL32),
    # AC_PosControl.cpp (4.1+): the jerk of the position target's path; `copter-4.6` shapes with it
    "PSC_JERK_XY": ParamInfo(5.0, "m/s/s/s", "horizontal jerk limit of the position target's path", 1.0, 20.0,
                             kind=REAL32, firmware=Firmware.COPTER_4_6),
    "PSC_JERK_Z": ParamInfo(5.0, "m/s/s/s", "vertical jerk limit of the position target's path", 5.0, 50.0,
                            kind=REAL32, firmware=Firmware.COPTER_4_6),
    "PSC_POSZ_P": ParamInfo(1.0, "1/s", "vertical position P gain", 1.0, 3.0, kind=REAL32),
    "PSC_VELZ_P": ParamInfo(5.0, "1/s", "vertical velocity P gain", 1.0, 8.0, kind=REAL32),
    # Take-off of `copter-4.6` (AP_MotorsMulticopter.h defaults; ArduCopter/Parameters.cpp TKOFF_SLEW_TIME): the
    # motors spool up, then the throttle ramps until the vehicle leaves the ground at about the hover throttle.
    "MOT_SPOOL_TIME": ParamInfo(0.5, "s", "motor spool-up time", 0.05, 2.0, kind=REAL32, firmware=Firmware.COPTER_4_6),
    "MOT_THST_HOVER": ParamInfo(0.35, "", "hover throttle", 0.125, 0.6875, kind=REAL32, firmware=Firmware.COPTER_4_6),
    "TKOFF_SLEW_TIME": ParamInfo(2.0, "s", "take-off throttle slew time (0 to full throttle)", 0.25, 5.0,
                                 kind=REAL32, firmware=Firmware.COPTER_4_6),
    # Landing (mode_land.cpp; ArduCopter/Parameters.h).
    "LAND_SPEED": ParamInfo(50, "cm/s", "descent speed for the final stage of landing", 30, 200, kind=INT16),
    "LAND_SPEED_HIGH": ParamInfo(0, "cm/s", "descent speed above LAND_ALT_LOW (0: WPNAV_SPEED_DN)", 0, 500,
                                 kind=INT16),
    "LAND_ALT_LOW": ParamInfo(1000, "cm", "altitude below which LAND_SPEED applies", 100, 10000, kind=INT16),
    "DISARM_DELAY": ParamInfo(10, "s", "auto-disarm delay when landed", 0, 127, kind=INT8),
    # Return to launch (ArduCopter/Parameters.h).
    "RTL_ALT": ParamInfo(1500, "cm", "RTL return altitude (0: current)", 30, 300000, kind=INT32),
    "RTL_ALT_FINAL": ParamInfo(0, "cm", "RTL final altitude (0: land)", 0, 1000, kind=INT16),
    "RTL_SPEED": ParamInfo(0, "cm/s", "RTL horizontal speed (0: WPNAV_SPEED)", 0, 2000, kind=INT16),
    "RTL_LOIT_TIME": ParamInfo(5000, "ms", "RTL loiter time above home before descent", 0, 60000, kind=INT32),
    # Guided mode.
    "GUID_TIMEOUT": ParamInfo(3, "s", "guided velocity command timeout", 0.1, 5, kind=REAL32),
    # Rangefinder (only the range; the sensor model is the simulator's). ArduCopter 4.6 still has the
    # centimetre AP_Int16 RNGFND1_MIN_CM/MAX_CM (AP_RangeFinder_Params.h of 4.6.2 and 4.6.3); the metre
    # RNGFND1_MIN/MAX came after 4.6. ArduPilot's default maximum is 700 cm; 10 m is the modelled sensor.
    "RNGFND1_MAX_CM": ParamInfo(1000, "cm", "rangefinder maximum distance", 20, 32767, kind=INT16),
    "RNGFND1_MIN_CM": ParamInfo(20, "cm", "rangefinder minimum distance", 0, 1000, kind=INT16),
    # Precision landing (AC_PrecLand.h: AP_Int8, AP_Enum (an AP_Int8), AP_Int16, AP_Float). Used by the
    # precision land modes.
    "PLND_ENABLED": ParamInfo(0, "", "precision landing enabled", 0, 1, kind=INT8),
    "PLND_TYPE": ParamInfo(0, "", "precision landing source (1: companion, 2: IRLock, 3: SITL Gazebo, 4: SITL)",
                           0, 4, kind=INT8),
    "PLND_EST_TYPE": ParamInfo(1, "", "target estimator (0: raw sensor, 1: Kalman filter)", 0, 1, kind=INT8),
    "PLND_ACC_P_NSE": ParamInfo(2.5, "m/s/s", "Kalman filter accelerometer noise", 0.5, 5, kind=REAL32),
    "PLND_LAG": ParamInfo(0.02, "s", "sensor lag", 0.02, 0.25, kind=REAL32),
    "PLND_XY_DIST_MAX": ParamInfo(2.5, "m", "max horizontal distance to start the final descent", 0, 10,
                                  kind=REAL32),
    "PLND_STRICT": ParamInfo(1, "", "target lost: 0 land vertically, 1 retry, 2 hover", 0, 2, kind=INT8),
    "PLND_RET_MAX": ParamInfo(4, "", "maximum landing retries", 0, 10, kind=INT8),
    "PLND_TIMEOUT": ParamInfo(4, "s", "time without target before retry/failsafe", 0, 20, kind=REAL32),
    "PLND_RET_BEHAVE": ParamInfo(0, "", "retry: 0 go to where the target was last seen, 1 go towards the "
                                 "target's approximate position", 0, 1, kind=INT8),
    "PLND_ALT_MIN": ParamInfo(0.75, "m", "below this the target is not required", 0, 5, kind=REAL32),
    "PLND_ALT_MAX": ParamInfo(8, "m", "above this retries climb no further", 0, 50, kind=REAL32),
    "PLND_OPTIONS": ParamInfo(0, "", "precision landing options bitmask (1: moving target, 2: precision landing "
                              "after manual reposition, 4: keep descent speed in the final descent)", 0, 7, kind=INT16),
    # AC_PrecLand's CAM_POS (an AP_Vector3f: three AP_Float on the wire).
    "PLND_CAM_POS_X": ParamInfo(0, "m", "sensor position forward of the vehicle's centre", -5, 5, kind=REAL32),
    "PLND_CAM_POS_Y": ParamInfo(0, "m", "sensor position right of the vehicle's centre", -5, 5, kind=REAL32),
    "PLND_CAM_POS_Z": ParamInfo(0, "m", "sensor position below the vehicle's centre", -5, 5, kind=REAL32),
    # preland's embedded autopilot only (ArduPilot has no such parameters): never served over MAVLink.
    "PRL_LOST_HOLD": ParamInfo(0, "", "target lost: 0 keep descending for PLND_TIMEOUT (ArduPilot), 1 hold (thesis)",
                               0, 1, kind=INT8, ardupilot=False),
    "PRL_RET_ALT": ParamInfo(0, "m", "thesis default retry height above home (0: ArduPilot's retry)", 0, 100,
                             kind=REAL32, ardupilot=False),
    "PRL_FS_HOLD": ParamInfo(7, "s", "hover before the blind descent once retries are spent (ArduPilot: 7)", 0, 60,
                             kind=REAL32, ardupilot=False),
    # Arming (AP_Arming.h: AP_Int32 bitmask, bits 0..19).
    "ARMING_CHECK": ParamInfo(1, "", "arming checks bitmask (0: none)", 0, 1048575, kind=INT32),
}

# What a MAVLink client sees, in ArduPilot's order of no importance (sorted names): the ArduPilot parameters.
ARDUPILOT_PARAM_NAMES: tuple[str, ...] = tuple(sorted(name for name, info in ARDUCOPTER_PARAMS.items()
                                                      if info.ardupilot))


class ParameterTable:
    """A mutable table of autopilot parameters, validated against `ARDUCOPTER_PARAMS`."""

    def __init__(self, overrides: dict[str, float] | None = None) -> None:
        self._values: dict[str, float] = {name: float(info.default) for name, info in ARDUCOPTER_PARAMS.items()}
        # `value(name)`: the stored value, straight from the dict (the autopilot reads a dozen a physics step).
        self.value: Callable[[str], float] = self._values.__getitem__
        # `m_s(name)`: a cm/s (or cm/s/s, cm) parameter in m/s (m/s/s, m), kept in step with `_values` by `set`
        # (the simulator reads ~90k a trial).
        self._si_values: dict[str, float] = {name: value / 100.0 for name, value in self._values.items()}
        self.m_s: Callable[[str], float] = self._si_values.__getitem__
        # Counts `set` calls, so that readers may cache what they derive from the table until it changes.
        self.version = 0
        for name, value in (overrides or {}).items():
            self.set(name, value)

    def names(self) -> list[str]:
        return sorted(self._values)

    def __contains__(self, name: str) -> bool:
        return name in self._values

    def get(self, name: str) -> float:
        try:
            return self._values[name]
        except KeyError:
            raise KeyError(f"unknown parameter {name!r}") from None

    def set(self, name: str, value: float) -> None:
        info = ARDUCOPTER_PARAMS.get(name)
        if info is None:
            raise KeyError(f"unknown parameter {name!r}")
        value = float(value)
        if not math.isfinite(value):
            raise ValueError(f"{name}={value}: not a number")
        # The documented range is checked on the rounded value before the type's clamp, so an integer
        # parameter given 300 is refused rather than kept as the 127 an AP_Int8 would hold.
        rounded = info.kind.rounded(value)
        if (info.minimum is not None and rounded < info.minimum) or (
            info.maximum is not None and rounded > info.maximum
        ):
            raise ValueError(f"{name}={value:g} is outside {info.minimum:g}..{info.maximum:g} {info.units}")
        self._values[name] = stored = info.kind.stored(value)
        self._si_values[name] = stored / 100.0
        self.version += 1


"""The simulated autopilot's parameters, by ArduPilot name and in ArduPilot units.

Defaults are ArduCopter 4.x defaults unless noted. The simulator reads them in
SI units through the helpers on `ParameterTable`; users and missions read and
write them by name exactly as they would on a real ArduCopter.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class ParamInfo:
    default: float
    units: str
    description: str
    minimum: float | None = None
    maximum: float | None = None


ARDUCOPTER_PARAMS: dict[str, ParamInfo] = {
    # Navigation speeds and accelerations (AC_WPNav / AC_PosControl).
    "WPNAV_SPEED": ParamInfo(1000, "cm/s", "horizontal waypoint speed", 20, 2000),
    "WPNAV_SPEED_UP": ParamInfo(250, "cm/s", "climb speed", 10, 1000),
    "WPNAV_SPEED_DN": ParamInfo(150, "cm/s", "descent speed", 10, 500),
    "WPNAV_ACCEL": ParamInfo(250, "cm/s/s", "horizontal waypoint acceleration", 50, 500),
    "WPNAV_ACCEL_Z": ParamInfo(100, "cm/s/s", "vertical acceleration", 50, 500),
    "LOIT_SPEED": ParamInfo(1250, "cm/s", "loiter maximum horizontal speed", 20, 3500),
    "LOIT_ACC_MAX": ParamInfo(500, "cm/s/s", "loiter maximum correction acceleration", 100, 981),
    "ANGLE_MAX": ParamInfo(3000, "cdeg", "maximum lean angle", 1000, 8000),
    "PSC_POSXY_P": ParamInfo(1.0, "1/s", "horizontal position P gain", 0.5, 2.0),
    "PSC_VELXY_P": ParamInfo(2.0, "1/s", "horizontal velocity P gain", 0.1, 6.0),
    "PSC_VELXY_I": ParamInfo(1.0, "1/s/s", "horizontal velocity I gain", 0.02, 1.0),
    "PSC_VELXY_IMAX": ParamInfo(1000, "cm/s/s", "horizontal velocity I limit", 0, 4500),
    "PSC_POSZ_P": ParamInfo(1.0, "1/s", "vertical position P gain", 1.0, 3.0),
    "PSC_VELZ_P": ParamInfo(5.0, "1/s", "vertical velocity P gain", 1.0, 8.0),
    # Landing (mode_land.cpp).
    "LAND_SPEED": ParamInfo(50, "cm/s", "descent speed for the final stage of landing", 30, 200),
    "LAND_SPEED_HIGH": ParamInfo(0, "cm/s", "descent speed above LAND_ALT_LOW (0: WPNAV_SPEED_DN)", 0, 500),
    "LAND_ALT_LOW": ParamInfo(1000, "cm", "altitude below which LAND_SPEED applies", 100, 10000),
    "DISARM_DELAY": ParamInfo(10, "s", "auto-disarm delay when landed", 0, 127),
    # Return to launch.
    "RTL_ALT": ParamInfo(1500, "cm", "RTL return altitude (0: current)", 200, 300000),
    "RTL_ALT_FINAL": ParamInfo(0, "cm", "RTL final altitude (0: land)", 0, 1000),
    "RTL_SPEED": ParamInfo(0, "cm/s", "RTL horizontal speed (0: WPNAV_SPEED)", 0, 2000),
    "RTL_LOIT_TIME": ParamInfo(5000, "ms", "RTL loiter time above home before descent", 0, 60000),
    # Guided mode.
    "GUID_TIMEOUT": ParamInfo(3, "s", "guided velocity command timeout", 0.1, 5),
    # Rangefinder (only the range; the sensor model is the simulator's).
    "RNGFND1_MAX_CM": ParamInfo(1000, "cm", "rangefinder maximum distance", 20, 70000),
    "RNGFND1_MIN_CM": ParamInfo(20, "cm", "rangefinder minimum distance", 0, 1000),
    # Precision landing (AC_PrecLand). Used by the precision land modes.
    "PLND_ENABLED": ParamInfo(0, "", "precision landing enabled", 0, 1),
    "PLND_TYPE": ParamInfo(0, "", "precision landing source (1: companion, 2: IRLock, 4: SITL IRLock)", 0, 6),
    "PLND_EST_TYPE": ParamInfo(1, "", "target estimator (0: raw sensor, 1: Kalman filter)", 0, 1),
    "PLND_ACC_P_NSE": ParamInfo(2.5, "m/s/s", "Kalman filter accelerometer noise", 0.5, 5),
    "PLND_LAG": ParamInfo(0.02, "s", "sensor lag", 0.02, 0.25),
    "PLND_XY_DIST_MAX": ParamInfo(2.5, "m", "max horizontal distance to start the final descent", 0, 10),
    "PLND_STRICT": ParamInfo(1, "", "target lost: 0 land vertically, 1 retry, 2 hover", 0, 2),
    "PLND_RET_MAX": ParamInfo(4, "", "maximum landing retries", 0, 10),
    "PLND_TIMEOUT": ParamInfo(4, "s", "time without target before retry/failsafe", 0, 20),
    "PLND_RET_BEHAVE": ParamInfo(0, "", "retry: 0 go to last known position, 1 go up only", 0, 1),
    "PLND_ALT_MIN": ParamInfo(0.75, "m", "below this the target is not required", 0, 5),
    "PLND_ALT_MAX": ParamInfo(8, "m", "above this retries climb no further", 0, 50),
    "PLND_OPTIONS": ParamInfo(0, "", "precision landing options bitmask", 0, 7),
    # preland's embedded autopilot only (ArduPilot has no such parameters): the thesis' cautious
    # landing as options of the retry state machine (see sim/precland_retry.py).
    "PRL_LOST_HOLD": ParamInfo(0, "", "target lost: 0 keep descending for PLND_TIMEOUT (ArduPilot), 1 hold (thesis)",
                               0, 1),
    "PRL_RET_ALT": ParamInfo(0, "m", "thesis default retry height above home (0: ArduPilot's retry)", 0, 100),
    "PRL_FS_HOLD": ParamInfo(7, "s", "hover before the blind descent once retries are spent (ArduPilot: 7)", 0, 60),
    # Arming.
    "ARMING_CHECK": ParamInfo(1, "", "arming checks bitmask (0: none)", 0, 1048575),
}


class ParameterTable:
    """A mutable table of autopilot parameters, validated against `ARDUCOPTER_PARAMS`."""

    def __init__(self, overrides: dict[str, float] | None = None) -> None:
        self._values: dict[str, float] = {name: float(info.default) for name, info in ARDUCOPTER_PARAMS.items()}
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
        if (info.minimum is not None and value < info.minimum) or (
            info.maximum is not None and value > info.maximum
        ):
            raise ValueError(f"{name}={value:g} is outside {info.minimum:g}..{info.maximum:g} {info.units}")
        self._values[name] = value

    # SI helpers for the simulator.
    def m_s(self, name: str) -> float:
        """A cm/s (or cm/s/s, cm) parameter in m/s (m/s/s, m)."""
        return self._values[name] / 100.0

    def value(self, name: str) -> float:
        return self._values[name]

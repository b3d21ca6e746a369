"""The simulator's calibratable parameters: the only ones `preland sim calibrate` may fit.

Each is a number of the simulated world, named by its dotted path into a
mission's `environment:` section (`navigation.gps_drift_sigma_m`) or, from
`sensors.`, into its `sensors:` section (`sensors.irlock.noise_sigma_deg`),
with the range a fit may search (plausible values for a small multirotor and
its sensors) and where its default comes from. The default itself is read
from the spec dataclasses, so it cannot disagree with what a mission gets.

A user's package adds parameters with `register_calibratable`, or declares
them under the entry-point group `preland.calibratable` (each entry point a
`CalibratableParameter` or a list of them).
"""

from __future__ import annotations

import dataclasses
import importlib.metadata
import math
from dataclasses import dataclass
from typing import Any

from ..errors import PrelandError

ENTRY_POINT_GROUP = "preland.calibratable"
SENSORS_PREFIX = "sensors."


class CalibratableError(PrelandError):
    """A parameter is not calibratable, or a declaration is wrong."""


@dataclass(frozen=True, kw_only=True)
class CalibratableParameter:
    """One calibratable number: `name` (dotted path, see the module), the range a fit searches
    (`low`..`high`, in the field's own unit), `source`: where the default comes from (or that it has none)."""

    name: str
    low: float
    high: float
    source: str
    unit: str = ""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.low) and math.isfinite(self.high) and self.low < self.high):
            raise CalibratableError(f"{self.name}: range must be finite with low < high, got {self.low}..{self.high}")

    def default(self) -> float:
        """The value a mission gets when nothing overrides it."""
        return float(spec_default(self.name))

    def contains(self, value: float) -> bool:
        return self.low <= value <= self.high


def section_and_path(name: str) -> tuple[str, list[str]]:
    """Which mission section (`environment` or `sensors`) and the key path inside it."""
    if name.startswith(SENSORS_PREFIX):
        return "sensors", name[len(SENSORS_PREFIX):].split(".")
    return "environment", name.split(".")


def section_default(section: str, parts: list[str], *, name: str | None = None) -> Any:
    """The default of the field at key path `parts` in a mission's `section` (environment or sensors), as a
    mission gets it when nothing overrides it; CalibratableError (naming `name`) when there is no such field."""
    from ..sensing.spec import SensorsSpec
    from .spec import EnvironmentSpec

    value: Any = {"environment": EnvironmentSpec, "sensors": SensorsSpec}[section]()
    for part in parts:
        if not dataclasses.is_dataclass(value) or part not in {f.name for f in dataclasses.fields(value)}:
            raise CalibratableError(f"{name or '.'.join(parts)}: no such field in the mission's {section} section")
        value = getattr(value, part)
    return value


def spec_default(name: str) -> Any:
    """The default of the spec field at dotted path `name`; CalibratableError when there is no such number."""
    section, parts = section_and_path(name)
    value = section_default(section, parts, name=name)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise CalibratableError(f"{name}: not a number (only numbers can be calibrated)")
    return value


_BUILT_IN = (
    CalibratableParameter(
        name="navigation.gps_drift_sigma_m", low=0.2, high=2.5, unit="m",
        source="fitted by hand to GPS-only landings (thesis Table 3 normal mode, paper 0.51 to 1.44 m); "
               "u-blox M8 CEP 2.5 m bounds it"),
    CalibratableParameter(
        name="navigation.position_noise_sigma_m", low=0.0, high=0.3, unit="m",
        source="none: an order of magnitude for a GPS+EKF's fast position noise"),
    CalibratableParameter(
        name="navigation.attitude_noise_sigma_deg", low=0.0, high=2.0, unit="deg",
        source="none: an order of magnitude for vibration and EKF attitude error"),
    CalibratableParameter(
        name="navigation.attitude_noise_tau_s", low=0.1, high=5.0, unit="s",
        source="none: an order of magnitude"),
    CalibratableParameter(
        name="navigation.imu_accel_noise_m_s2", low=0.0, high=0.5, unit="m/s^2",
        source="none: an order of magnitude for a multirotor's vibrating accelerometers"),
    CalibratableParameter(
        name="wind.speed_m_s", low=0.0, high=8.0, unit="m/s",
        source="campaign files (thesis: 'practically ideal weather' for Table 3, 'regular wind gusts' for 4 and 5)"),
    CalibratableParameter(
        name="wind.turbulence_w20_m_s", low=0.0, high=10.0, unit="m/s",
        source="none: the form is MIL-F-8785C's, whose light turbulence is W20 = 15 kt (7.7 m/s); "
               "the 2 m/s default and the campaign files' values have no source"),
    CalibratableParameter(
        # Bounded by half the rotors' induced velocity in hover (momentum theory: 5.7 m/s for a 2.5 kg
        # hexacopter on 10-inch propellers), the speed of the wash that recirculates.
        name="ground_effect.sigma_m_s", low=0.0, high=3.0, unit="m/s",
        source="none: 0 (off); recirculating rotor wash below ground_effect.height_m (docs: error sources)"),
    CalibratableParameter(
        name="airframe.drag_per_s", low=0.1, high=1.0, unit="1/s",
        source="none: a linear drag typical of a 1.5 kg quadcopter"),
    CalibratableParameter(
        name="airframe.attitude_tau_s", low=0.05, high=0.5, unit="s",
        source="none: ArduCopter's attitude loop on a mid-size frame"),
    CalibratableParameter(
        name="sensors.irlock.noise_sigma_deg", low=0.0, high=1.5, unit="deg",
        source="none: a fraction of a Pixy pixel (0.19 deg at 320 px over 60 deg)"),
    CalibratableParameter(
        name="sensors.camera.noise_sigma", low=0.0, high=15.0, unit="grey levels",
        source="none: a Raspberry Pi camera v2 in daylight"),
    CalibratableParameter(
        name="sensors.camera.blur_px", low=0.0, high=3.0, unit="px",
        source="none: 0 (a sharp image)"),
    CalibratableParameter(
        name="sensors.marker.processing_latency_s", low=0.0, high=0.3, unit="s",
        source="thesis: about 50 ms per frame on its Raspberry Pi"),
)

_REGISTRY: dict[str, CalibratableParameter] = {}
_entry_points_loaded = False


def register_calibratable(parameter: CalibratableParameter) -> None:
    """Declare `parameter` calibratable (replacing one of that name). Its name must be a number field of the
    mission's environment or sensors, and its default within its range."""
    default = float(spec_default(parameter.name))
    if not parameter.contains(default):
        raise CalibratableError(f"{parameter.name}: its default {default:g} is outside the declared range "
                                f"{parameter.low:g}..{parameter.high:g}")
    _REGISTRY[parameter.name] = parameter


def _load_entry_points() -> None:
    global _entry_points_loaded
    if _entry_points_loaded:
        return
    _entry_points_loaded = True
    for entry_point in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        try:
            declared = entry_point.load()
        except Exception as error:  # a broken plugin must not break the built-in parameters
            raise CalibratableError(f"entry point {entry_point.name!r} ({entry_point.value}): cannot be loaded "
                                    f"({type(error).__name__}: {error})") from None
        for parameter in declared if isinstance(declared, (list, tuple)) else [declared]:
            if not isinstance(parameter, CalibratableParameter):
                raise CalibratableError(f"entry point {entry_point.name!r}: expected CalibratableParameter(s), "
                                        f"got {type(parameter).__name__}")
            register_calibratable(parameter)


def calibratable_parameters() -> dict[str, CalibratableParameter]:
    """Every declared parameter by name: the built-in ones and those packages register."""
    _load_entry_points()
    return dict(_REGISTRY)


def find_calibratable(name: str) -> CalibratableParameter:
    """The declared parameter `name`; CalibratableError (one line, naming the known ones) when undeclared."""
    parameters = calibratable_parameters()
    if name not in parameters:
        raise CalibratableError(f"{name!r} is not a calibratable parameter (declared: {', '.join(sorted(parameters))})")
    return parameters[name]


for _parameter in _BUILT_IN:
    register_calibratable(_parameter)

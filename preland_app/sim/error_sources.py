"""The modelled error sources: which mission fields set each one, where its magnitude comes from, and how to
switch it off.

One table serves the error budget (`benchmarks/error_budget.py` flies each source switched off in turn) and
the docs' error-source reference, so the two cannot disagree. Defaults are read from the spec dataclasses
(`EnvironmentSpec`, `SensorsSpec`), never written here.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from ..errors import PrelandError
from .calibratable import CalibratableError, section_default

_SECTIONS = ("environment", "sensors")


@dataclass(frozen=True, kw_only=True)
class ErrorSource:
    """One error source. `off`: mission field (dotted path from the mission's root, `environment.` or
    `sensors.`) -> the value that switches it off; `magnitude_from`: where the default's size comes from
    ("calibratable" where no source gives it)."""

    name: str
    off: dict[str, Any]
    magnitude_from: str

    def defaults(self) -> dict[str, Any]:
        """Each field's default, as a mission gets it when nothing overrides it."""
        return {path: field_default(path) for path in self.off}


ERROR_SOURCES: tuple[ErrorSource, ...] = (
    ErrorSource(name="GPS drift + noise",
                off={"environment.navigation.gps_drift_sigma_m": 0.0,
                     "environment.navigation.position_noise_sigma_m": 0.0},
                magnitude_from="fitted by hand to the thesis' normal landings (Table 3); the paper's GPS-only "
                               "landings (0.51 to 1.44 m) are the check on data it was not fitted to"),
    ErrorSource(name="baro drift + noise",
                off={"environment.navigation.baro_drift_sigma_m": 0.0,
                     "environment.navigation.baro_noise_sigma_m": 0.0},
                magnitude_from="unsourced: calibratable"),
    ErrorSource(name="velocity noise", off={"environment.navigation.velocity_noise_sigma_m_s": 0.0},
                magnitude_from="unsourced: calibratable"),
    ErrorSource(name="rangefinder noise", off={"environment.navigation.rangefinder_noise_sigma_m": 0.0},
                magnitude_from="unsourced: calibratable"),
    ErrorSource(name="attitude error", off={"environment.navigation.attitude_noise_sigma_deg": 0.0},
                magnitude_from="unsourced: calibratable (it drives the blind descent below 3 m)"),
    ErrorSource(name="IMU accel noise", off={"environment.navigation.imu_accel_noise_m_s2": 0.0},
                magnitude_from="unsourced: calibratable"),
    ErrorSource(name="heading error", off={"environment.navigation.heading_error_sigma_deg": 0.0},
                magnitude_from="HMC5883L datasheet: 1 to 2 deg heading accuracy (midpoint); time constant "
                               "unsourced"),
    ErrorSource(name="steady wind", off={"environment.wind.speed_m_s": 0.0},
                magnitude_from="the thesis gives no speeds ('practically ideal weather' for Table 3, 'regular "
                               "wind gusts' for Tables 4 and 5): calibratable"),
    ErrorSource(name="gusts (Dryden)", off={"environment.wind.turbulence_w20_m_s": 0.0},
                magnitude_from="MIL-F-8785C's form and scales; the W20 magnitude is unsourced: calibratable"),
    ErrorSource(name="IR-LOCK angle noise", off={"sensors.irlock.noise_sigma_deg": 0.0},
                magnitude_from="unsourced: calibratable"),
    ErrorSource(name="IR-LOCK pixel grid", off={"sensors.irlock.quantize": False},
                magnitude_from="Pixy's 320 x 200 block output (Charmed Labs); the irlock drivers' 60 x 35 deg "
                               "pixel-to-angle scale"),
    ErrorSource(name="IR-LOCK frame age", off={"sensors.irlock.latency_s": 0.0},
                magnitude_from="Pixy: a frame every 20 ms at 50 Hz; a reading describes the last finished frame"),
    ErrorSource(name="camera image noise", off={"sensors.camera.noise_sigma": 0.0},
                magnitude_from="unsourced: calibratable"),
    ErrorSource(name="companion processing", off={"sensors.marker.processing_latency_s": 0.0},
                magnitude_from="thesis: about 50 ms per frame on its Raspberry Pi"),
    ErrorSource(name="sensor mounting offset",
                off={"sensors.irlock.mount_offset_frd_m": (0.0, 0.0, 0.0),
                     "sensors.camera.mount_offset_frd_m": (0.0, 0.0, 0.0)},
                magnitude_from="thesis Fig. 14b (side by side at the frame's centre) and the boards' widths "
                               "(Pixy 53 mm, camera 25 mm): 12.5 mm left and 27 mm right"),
    ErrorSource(name="rotor wash near the ground", off={"environment.ground_effect.sigma_m_s": 0.0},
                magnitude_from="reach: four rotor radii of 10-inch propellers (Cheeseman and Bennett); size "
                               "unsourced, off by default, calibratable"),
)


class ErrorSourceError(PrelandError):
    """A source names a field the mission does not have."""


def _split(path: str) -> tuple[str, list[str]]:
    section, *parts = path.split(".")
    if section not in _SECTIONS or not parts:
        raise ErrorSourceError(f"{path}: must start with one of: {', '.join(_SECTIONS)}")
    return section, parts


def field_default(path: str) -> Any:
    """The default of the mission field at dotted `path` (e.g. `environment.wind.speed_m_s`)."""
    section, parts = _split(path)
    try:
        return section_default(section, parts, name=path)
    except CalibratableError as error:
        raise ErrorSourceError(str(error)) from None


def _replaced(spec: Any, parts: list[str], value: Any) -> Any:
    if not parts:
        return value
    head, *rest = parts
    return dataclasses.replace(spec, **{head: _replaced(getattr(spec, head), rest, value)})


def switched_off(mission: Any, *sources: ErrorSource) -> Any:
    """`mission` (a MissionSpec) with each of `sources` switched off."""
    for source in sources:
        for path, value in source.off.items():
            section, parts = _split(path)
            mission = dataclasses.replace(mission, **{section: _replaced(getattr(mission, section), parts, value)})
    return mission


def find_error_source(name: str) -> ErrorSource:
    for source in ERROR_SOURCES:
        if source.name == name:
            return source
    raise ErrorSourceError(f"no error source {name!r} (known: {', '.join(s.name for s in ERROR_SOURCES)})")

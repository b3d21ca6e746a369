"""Mission specs: YAML files in missions/, loaded into validated frozen dataclasses.

A mission says where the pad is relative to the start, how high to take off,
which path to fly (waypoints relative to the position recorded after
take-off), how to land, and the timeouts of each step. Optional sections
override the simulated environment and autopilot parameters.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace
from pathlib import Path

from ..errors import SpecError, require
from ..landing.registry import LAND_MODES, land_mode_names
from ..sim.params import ARDUCOPTER_PARAMS
from ..sensing.pad import PAD_PRESETS, PadSpec, load_pad
from ..sensing.spec import SensorsSpec
from ..sim.spec import EnvironmentSpec
from .loader import build, read_yaml_mapping

_MAX_ALTITUDE_M = 120.0  # the usual legal ceiling for small drones


@dataclass(frozen=True)
class PadPlacementSpec:
    """Which landing pad (`preset`: thesis, paper, or a pad YAML file relative to the mission), where its
    centre is in m NED (north, east) from the vehicle's start position, and its yaw in degrees."""

    preset: str = "thesis"
    offset_from_start_ned_m: tuple[float, float] = (2.0, 0.0)
    yaw_deg: float = 0.0

    def __post_init__(self) -> None:
        require(all(math.isfinite(v) for v in self.offset_from_start_ned_m), "offset_from_start_ned_m",
                "must be finite numbers")
        require(self.preset in PAD_PRESETS or self.preset.endswith((".yaml", ".yml")), "preset",
                f"unknown pad preset {self.preset!r} (expected one of: {', '.join(PAD_PRESETS)}, or a .yaml file)")


@dataclass(frozen=True)
class TakeoffSpec:
    """Take-off altitude above home in m, optionally per land mode (thesis: 6 m for marker)."""

    altitude_rel_m: float
    altitude_by_land_mode_rel_m: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        require(0.0 < self.altitude_rel_m <= _MAX_ALTITUDE_M, "altitude_rel_m",
                f"must be > 0 and <= {_MAX_ALTITUDE_M:g} m, got {self.altitude_rel_m:g}")
        for mode, altitude in self.altitude_by_land_mode_rel_m.items():
            require(mode in LAND_MODES, f"altitude_by_land_mode_rel_m.{mode}",
                    f"unknown land mode (expected one of: {', '.join(land_mode_names())})")
            require(0.0 < altitude <= _MAX_ALTITUDE_M, f"altitude_by_land_mode_rel_m.{mode}",
                    f"must be > 0 and <= {_MAX_ALTITUDE_M:g} m, got {altitude:g}")

    def altitude_for(self, land_mode: str) -> float:
        return self.altitude_by_land_mode_rel_m.get(land_mode, self.altitude_rel_m)


@dataclass(frozen=True)
class PathSpec:
    """Waypoints in m (north, east) relative to the position recorded after take-off, flown at take-off altitude.

    A waypoint counts as reached when the vehicle's *estimated* position is
    within `acceptance_radius_m` of it and its estimated horizontal speed is at
    most `settle_speed_m_s` (it has arrived, not just passed by).
    """

    waypoints_rel_ned_m: tuple[tuple[float, float], ...]
    acceptance_radius_m: float = 0.2
    settle_speed_m_s: float = 0.25

    def __post_init__(self) -> None:
        require(len(self.waypoints_rel_ned_m) > 0, "waypoints_rel_ned_m", "needs at least one waypoint")
        for i, (north, east) in enumerate(self.waypoints_rel_ned_m):
            require(math.isfinite(north) and math.isfinite(east) and math.hypot(north, east) <= 1000.0,
                    f"waypoints_rel_ned_m[{i}]", "must be finite and within 1000 m")
        require(0.05 <= self.acceptance_radius_m <= 10.0, "acceptance_radius_m", "must be within 0.05..10 m")
        require(0.05 <= self.settle_speed_m_s <= 20.0, "settle_speed_m_s", "must be within 0.05..20 m/s")


@dataclass(frozen=True)
class LandSpec:
    """How to land: the land mode's name (see `preland fly --help` for the list)."""

    mode: str = "normal"

    def __post_init__(self) -> None:
        require(self.mode in LAND_MODES, "mode",
                f"unknown land mode {self.mode!r} (expected one of: {', '.join(land_mode_names())})")


@dataclass(frozen=True)
class TimeoutsSpec:
    """Per-step timeouts in vehicle seconds."""

    position_fix_s: float = 120.0
    arm_s: float = 20.0
    takeoff_s: float = 60.0
    waypoint_s: float = 60.0
    land_s: float = 240.0

    def __post_init__(self) -> None:
        for name in ("position_fix_s", "arm_s", "takeoff_s", "waypoint_s", "land_s"):
            require(getattr(self, name) > 0, name, "must be > 0 s")


@dataclass(frozen=True)
class MissionSpec:
    """A whole mission. `params` are autopilot parameters (ArduPilot names and units) set before arming."""

    name: str
    takeoff: TakeoffSpec
    path: PathSpec
    land: LandSpec = field(default_factory=LandSpec)
    description: str = ""
    pad: PadPlacementSpec = field(default_factory=PadPlacementSpec)
    timeouts: TimeoutsSpec = field(default_factory=TimeoutsSpec)
    environment: EnvironmentSpec = field(default_factory=EnvironmentSpec)
    sensors: SensorsSpec = field(default_factory=SensorsSpec)
    params: dict[str, float] = field(default_factory=dict)
    initial_yaw_deg: float = 0.0
    source_path: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        require(bool(re.fullmatch(r"[A-Za-z0-9_.-]+", self.name)), "name",
                "must be a non-empty word (letters, digits, _ . -)")
        for name in self.params:
            require(name in ARDUCOPTER_PARAMS, f"params.{name}", "unknown autopilot parameter")

    def takeoff_altitude_rel_m(self, land_mode: str | None = None) -> float:
        return self.takeoff.altitude_for(land_mode or self.land.mode)

    @property
    def base_dir(self) -> Path:
        """Where relative paths in the mission (pad file, camera calibration) are resolved from."""
        return Path(self.source_path).parent if self.source_path else Path.cwd()

    def pad_spec(self) -> PadSpec:
        preset = self.pad.preset
        if preset in PAD_PRESETS:
            return PAD_PRESETS[preset]
        path = Path(preset)
        return load_pad(str(path if path.is_absolute() else self.base_dir / path))

    def with_land_mode(self, land_mode: str) -> "MissionSpec":
        """This mission with another land mode (validated)."""
        return replace(self, land=LandSpec(mode=land_mode))


def load_mission(path: str | Path) -> MissionSpec:
    """Load and validate a mission YAML file. Raises SpecError naming file and field."""
    path_text = str(path)
    data = read_yaml_mapping(path)
    if "source_path" in data:
        raise SpecError(path=path_text, field="source_path", problem="unknown key")
    spec = replace(build(MissionSpec, data, path=path_text), source_path=path_text)
    # Resolve referenced files now, so a bad pad or calibration file is reported at load time.
    try:
        spec.pad_spec()
    except SpecError as error:
        raise SpecError(path=path_text, field="pad.preset", problem=str(error)) from None
    if spec.sensors.camera.calibration is not None:
        try:
            spec.sensors.camera.model(relative_to=spec.base_dir)
        except SpecError as error:
            raise SpecError(path=path_text, field="sensors.camera.calibration", problem=str(error)) from None
    return spec

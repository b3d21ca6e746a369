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
from typing import TYPE_CHECKING, Any

from ..errors import SpecError, SpecValueError, require
from ..field.preflight import PreflightSpec
from ..landing.base import LandStrategy
from ..landing.cautious import CautiousSpec
from ..landing.paper import PaperSpec
from ..landing.plugins import LandModeError, precision_sensor_of
from ..landing.precision import PrecisionLanding
from ..landing.registry import LAND_MODES, PRECISION_SENSORS, create_land_strategy, find_land_mode, is_land_mode_name, \
    land_mode_names
from ..sensing.faults import SENSORS as FAULT_SENSORS
from ..sensing.faults import FaultKind, FaultSpec, FaultSyntaxError
from ..sim.params import ARDUCOPTER_PARAMS
from ..sensing.pad import PAD_PRESETS, PadSpec, load_pad
from ..sensing.spec import SensorsSpec
from ..sim.spec import EnvironmentSpec
from .loader import build, read_yaml_mapping

if TYPE_CHECKING:
    from ..sim.profile import ProfileSpec

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
    """Take-off altitude above home in m, optionally per land mode or precision sensor
    (thesis: 6 m for the marker, which it cannot detect reliably from higher up)."""

    altitude_rel_m: float
    altitude_by_land_mode_rel_m: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        require(0.0 < self.altitude_rel_m <= _MAX_ALTITUDE_M, "altitude_rel_m",
                f"must be > 0 and <= {_MAX_ALTITUDE_M:g} m, got {self.altitude_rel_m:g}")
        for mode, altitude in self.altitude_by_land_mode_rel_m.items():
            require(mode in PRECISION_SENSORS or is_land_mode_name(mode), f"altitude_by_land_mode_rel_m.{mode}",
                    f"unknown land mode or sensor (expected one of: {', '.join(land_mode_names())}, "
                    "or an import path package.module:ClassName)")
            require(0.0 < altitude <= _MAX_ALTITUDE_M, f"altitude_by_land_mode_rel_m.{mode}",
                    f"must be > 0 and <= {_MAX_ALTITUDE_M:g} m, got {altitude:g}")

    def altitude_for(self, land_mode: str, sensor: str | None = None) -> float:
        """The altitude for a land mode, else for its sensor, else the default."""
        by = self.altitude_by_land_mode_rel_m
        if land_mode in by:
            return by[land_mode]
        if sensor is not None and sensor in by:
            return by[sensor]
        return self.altitude_rel_m


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


# Fields added after 0.1 leave a spec's hash as it was while they keep their default, so stored campaigns
# still resume (campaign/spec.py: spec_hash).
HASH_WHEN_SET = {"hash": "when-set"}
# Where a value came from, not what it is: never hashed (a profile's values are, through the sections it fills).
HASH_NEVER = {"hash": "never"}
# What the JSON Schema (config/schema.py) says beyond the types: the keys these mappings take.
FAULTS_SCHEMA = {"schema": {"propertyNames": {"enum": list(FAULT_SENSORS)}}}
PARAMS_SCHEMA = {"schema": {"propertyNames": {"enum": sorted(ARDUCOPTER_PARAMS)}}}


@dataclass(frozen=True)
class LandSpec:
    """How to land. `mode`: a land mode by name (`preland modes`: normal, irlock, marker, fused, cautious,
    paper_static, paper_adaptive, or an installed plugin's name) or by import path
    (`package.module:ClassName`); `params`: a plugin's keyword options, checked against its class when the
    file loads; `sensor`: the precision sensor of the cautious mode (irlock, marker or fused; default
    marker); `faults`: per sensor (irlock, marker), in the fault syntax (`random:0.75`,
    `below:3:first-attempt`...); `cautious`: the retry parameters; `paper`: the paper algorithms'
    parameters; `normal_scored_from`: what a `normal` landing is scored against, `takeoff` (the thesis)
    or `pad` (the paper, whose GPS landing aims at the marker)."""

    mode: str = field(default="normal", metadata={"schema": {"examples": list(LAND_MODES)}})
    sensor: str | None = None
    faults: dict[str, str] = field(default_factory=dict, metadata=FAULTS_SCHEMA)
    cautious: CautiousSpec = field(default_factory=CautiousSpec)
    paper: PaperSpec = field(default_factory=PaperSpec)
    normal_scored_from: str = "takeoff"
    params: dict[str, Any] = field(default_factory=dict, metadata=HASH_WHEN_SET)

    def __post_init__(self) -> None:
        try:
            builtin = find_land_mode(self.mode).builtin
        except LandModeError as error:
            raise SpecValueError("mode", str(error)) from None
        if self.sensor is not None:
            require(self.mode == "cautious", "sensor", "only the cautious mode takes a sensor (the others are one)")
            require(self.sensor in PRECISION_SENSORS, "sensor",
                    f"unknown sensor {self.sensor!r} (expected one of: {', '.join(PRECISION_SENSORS)})")
        require(self.normal_scored_from in ("takeoff", "pad"), "normal_scored_from", "must be takeoff or pad")
        for sensor, text in self.faults.items():
            require(sensor in FAULT_SENSORS, f"faults.{sensor}",
                    f"unknown sensor (expected one of: {', '.join(FAULT_SENSORS)})")
            try:
                FaultSpec.parse(text)
            except FaultSyntaxError as error:
                raise SpecValueError(f"faults.{sensor}", str(error)) from None
        # Make the strategy once now: a plugin that cannot be imported, or refuses its options, is reported
        # when the file loads. What it uses decides its sensor and which faults apply.
        strategy = self._make_strategy()
        sensor = precision_sensor_of(strategy)
        used = {None: (), "irlock": ("irlock",), "marker": ("marker",), "fused": ("irlock", "marker")}[sensor]
        for sensor_name, text in self.faults.items():
            require(sensor_name in used, f"faults.{sensor_name}",
                    f"land mode {self.mode!r} does not use the {sensor_name} sensor")
            # A marker's detections carry no time of their own; only the precision modes send them with one.
            stalestamp = any(part.kind is FaultKind.STALESTAMP for part in FaultSpec.parse(text).parts())
            require(sensor_name != "marker" or not stalestamp or isinstance(strategy, PrecisionLanding),
                    f"faults.{sensor_name}",
                    f"land mode {self.mode!r} reads the marker's detections, which carry no time for stalestamp "
                    "to make old (the precision modes send them with one)")
        object.__setattr__(self, "_precision_sensor", sensor)
        object.__setattr__(self, "_builtin", builtin)

    @property
    def precision_sensor(self) -> str | None:
        """The sensor this landing uses: irlock, marker, fused, or None (GPS only)."""
        return self._precision_sensor

    def fault_specs(self) -> dict[str, FaultSpec]:
        return {sensor: FaultSpec.parse(text) for sensor, text in self.faults.items()}

    def sensor_faults(self) -> dict[str, FaultSpec]:
        """The faults the sensor suite applies to the readings it delivers: a plugin's (the built-in modes
        apply their own, so none for them)."""
        return {} if self._builtin else self.fault_specs()

    def _make_strategy(self) -> LandStrategy:
        try:
            return create_land_strategy(self.mode, sensor=self.sensor, faults=self.fault_specs(),
                                        cautious=self.cautious if self.mode == "cautious" else None,
                                        paper=self.paper, normal_reference=self.normal_scored_from,
                                        params=self.params)
        except LandModeError as error:
            raise SpecValueError("mode", str(error)) from None

    def strategy(self) -> LandStrategy:
        """A fresh strategy for one trial."""
        return self._make_strategy()


@dataclass(frozen=True)
class TimeoutsSpec:
    """Per-step timeouts in vehicle seconds."""

    position_fix_s: float = 120.0
    arm_s: float = 60.0  # ArduPilot refuses arming until its EKF is ready (about 40 s after boot in SITL)
    takeoff_s: float = 60.0
    waypoint_s: float = 60.0
    land_s: float = 240.0

    def __post_init__(self) -> None:
        for name in ("position_fix_s", "arm_s", "takeoff_s", "waypoint_s", "land_s"):
            require(getattr(self, name) > 0, name, "must be > 0 s")


@dataclass(frozen=True)
class GeofenceSpec:
    """A cylinder around home: leaving it (`max_distance_m` horizontally or `max_height_m` up) switches the
    vehicle to `action` (LAND or RTL) and ends the mission."""

    max_distance_m: float = 50.0
    max_height_m: float = 30.0
    action: str = "RTL"

    def __post_init__(self) -> None:
        require(self.max_distance_m > 0, "max_distance_m", "must be > 0 m")
        require(self.max_height_m > 0, "max_height_m", "must be > 0 m")
        require(self.action in ("LAND", "RTL"), "action", "must be LAND or RTL")


@dataclass(frozen=True)
class MissionSpec:
    """A whole mission. `params` are autopilot parameters (ArduPilot names and units) set before arming.
    `sim_profile`: a simulation profile file (relative to the mission) whose overrides the mission's own
    `environment:` and `sensors:` apply on top of."""

    name: str
    takeoff: TakeoffSpec
    path: PathSpec
    land: LandSpec = field(default_factory=LandSpec)
    description: str = ""
    pad: PadPlacementSpec = field(default_factory=PadPlacementSpec)
    timeouts: TimeoutsSpec = field(default_factory=TimeoutsSpec)
    environment: EnvironmentSpec = field(default_factory=EnvironmentSpec)
    sensors: SensorsSpec = field(default_factory=SensorsSpec)
    geofence: GeofenceSpec | None = None
    preflight: PreflightSpec = field(default_factory=PreflightSpec)
    params: dict[str, float] = field(default_factory=dict, metadata=PARAMS_SCHEMA)
    initial_yaw_deg: float = 0.0
    sim_profile: str | None = field(default=None, metadata=HASH_NEVER)
    source_path: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        require(bool(re.fullmatch(r"[A-Za-z0-9_.-]+", self.name)), "name",
                "must be a non-empty word (letters, digits, _ . -)")
        for name in self.params:
            require(name in ARDUCOPTER_PARAMS, f"params.{name}", "unknown autopilot parameter")
            firmware = ARDUCOPTER_PARAMS[name].firmware  # the one firmware whose model uses it, if only one
            mission_firmware = self.environment.autopilot.firmware
            require(firmware in (None, mission_firmware), f"params.{name}",
                    f"used only with `environment.autopilot.firmware: {firmware and firmware.value}`; this "
                    f"mission's is {mission_firmware.value}")
        options = self.params.get("PLND_OPTIONS")
        # Bit 1 changes what happens after a pilot repositions the vehicle with the sticks; no mission has
        # a pilot on the sticks, so the bit could only be carried and never act.
        require(options is None or int(options) & 2 == 0, "params.PLND_OPTIONS",
                "bit 1 (precision landing after manual reposition) needs a pilot's sticks, which preland's "
                "missions never use; bits 0 (moving target) and 2 (fast final descent) are supported")

    def takeoff_altitude_rel_m(self) -> float:
        return self.takeoff.altitude_for(self.land.mode, self.land.precision_sensor)

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

    def with_land(self, *, mode: str | None = None, sensor: str | None = None,
                  faults: dict[str, str] | None = None, params: dict[str, Any] | None = None) -> "MissionSpec":
        """This mission with another land mode, sensor, faults or plugin options (validated like the file's).
        Another mode drops the mission's `land.params` (they were the other mode's) unless `params` is given."""
        land = self.land
        new_mode = mode or land.mode
        new_sensor = sensor if sensor is not None else (land.sensor if new_mode == "cautious" else None)
        new_params = params if params is not None else (dict(land.params) if new_mode == land.mode else {})
        return replace(self, land=replace(land, mode=new_mode, sensor=new_sensor, params=new_params,
                                          faults=faults if faults is not None else dict(land.faults)))


def load_mission(path: str | Path, *, profile: "ProfileSpec | None" = None) -> MissionSpec:
    """Load and validate a mission YAML file. Raises SpecError naming file and field. `profile` takes the
    place of the profile the mission names (a campaign's, or a candidate during calibration)."""
    from ..sim.profile import load_profile, resolve_profile_path
    from .loader import deep_merge

    path_text = str(path)
    data = read_yaml_mapping(path)
    if "source_path" in data:
        raise SpecError(path=path_text, field="source_path", problem="unknown key")
    if profile is None and data.get("sim_profile") is not None:
        if not isinstance(data["sim_profile"], str):
            raise SpecError(path=path_text, field="sim_profile", problem=f"expected a string, got {data['sim_profile']!r}")
        profile_path = resolve_profile_path(data["sim_profile"], relative_to=Path(path).parent)
        try:
            profile = load_profile(profile_path)
        except SpecError as error:
            raise SpecError(path=path_text, field="sim_profile", problem=str(error)) from None
    if profile is not None:
        for section in ("environment", "sensors"):
            own = data.get(section, {})
            if isinstance(own, dict):  # anything else is reported by the loader as the mission's mistake
                data[section] = deep_merge(getattr(profile, section), own)
        data["sim_profile"] = profile.source_path or profile.name
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

"""Campaign specs: a mission, scenarios (land mode, sensor, faults, initial height, environment), trials.

YAML files in campaigns/, loaded into frozen dataclasses and validated at load
time; every error names the file and the field. Scenario overrides are applied
to the mission at load time too, so a bad override is reported before any trial
runs.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from ..config.loader import build, deep_merge, load_spec_file, to_plain
from ..runtime.base import RuntimeUrlError, split_url
from ..config.mission import FAULTS_SCHEMA, HASH_NEVER, HASH_WHEN_SET, PARAMS_SCHEMA, MissionSpec, load_mission
from ..errors import SpecError, SpecValueError, require
from .field_spec import FieldSpec
from ..sim.spec import EnvironmentSpec


@dataclass(frozen=True)
class ReferenceSpec:
    """Published figures for a scenario: mean, min and max landing error in cm, mean landing time in s, and
    optionally the published trials (a CSV like the thesis' field trials, filtered by `source_table`)."""

    avg_error_cm: float | None = None
    max_error_cm: float | None = None
    min_error_cm: float | None = field(default=None, metadata=HASH_WHEN_SET)
    avg_landing_time_s: float | None = None
    source: str = ""
    trials_csv: str | None = None
    source_table: int | None = None

    def __post_init__(self) -> None:
        for name in ("avg_error_cm", "max_error_cm", "min_error_cm", "avg_landing_time_s"):
            value = getattr(self, name)
            require(value is None or value >= 0, name, "must be >= 0")
        require((self.trials_csv is None) == (self.source_table is None), "source_table",
                "give trials_csv and source_table together")


@dataclass(frozen=True)
class ScenarioSpec:
    """One scenario: a label, how it lands (`land`: a land mode by name or import path; `land_params`: a
    plugin's keyword options), what fails, from how high, in which environment."""

    label: str
    land: str
    land_params: dict[str, Any] = field(default_factory=dict, metadata=HASH_WHEN_SET)
    sensor: str | None = None
    faults: dict[str, str] = field(default_factory=dict, metadata=FAULTS_SCHEMA)
    initial_height_m: float | None = None
    environment: dict[str, Any] = field(default_factory=dict, metadata={"schema_partial": EnvironmentSpec})
    params: dict[str, float] = field(default_factory=dict, metadata=PARAMS_SCHEMA)
    trials: int | None = None
    reference: ReferenceSpec | None = None

    def __post_init__(self) -> None:
        require(bool(self.label.strip()), "label", "must not be empty")
        require(self.trials is None or self.trials > 0, "trials", f"must be > 0, got {self.trials}")
        require(self.initial_height_m is None or 0 < self.initial_height_m <= 120, "initial_height_m",
                "must be > 0 and <= 120 m")


@dataclass(frozen=True)
class CampaignSpec:
    """A campaign. `mission` is a mission file relative to the campaign file; `pad` overrides its pad preset;
    `sim_profile`: a simulation profile file (relative to the campaign) taking the place of the mission's.
    `runtime`: where the trials fly, a runtime URL (`sim:`, the default; `sitl:PATH`; `mavlink+udp://...`);
    `preland campaign run --runtime` overrides it. `field`: how the campaign flies on one vehicle (between
    trials, battery swaps, the pad's surveyed position; `campaign.field_spec`), read by field campaigns only."""

    name: str
    mission: str
    scenarios: tuple[ScenarioSpec, ...]
    trials: int = 10
    base_seed: int = 0
    description: str = ""
    pad: str | None = None
    sim_profile: str | None = field(default=None, metadata=HASH_NEVER)
    runtime: str | None = field(default=None, metadata=HASH_NEVER)
    source_path: str = field(default="", compare=False)
    # Last: below it, `field` in this class body would name this attribute, not dataclasses.field.
    field: FieldSpec = dataclasses.field(default_factory=FieldSpec, metadata=HASH_NEVER)

    def __post_init__(self) -> None:
        require(bool(re.fullmatch(r"[A-Za-z0-9_.-]+", self.name)), "name",
                "must be a non-empty word (letters, digits, _ . -)")
        if self.runtime is not None:
            try:
                split_url(self.runtime)
            except RuntimeUrlError as error:
                require(False, "runtime", str(error))
        require(self.trials > 0, "trials", f"must be > 0, got {self.trials}")
        require(len(self.scenarios) > 0, "scenarios", "needs at least one scenario")
        labels = [s.label for s in self.scenarios]
        for index, label in enumerate(labels):
            require(labels.index(label) == index, f"scenarios[{index}].label", f"duplicate label {label!r}")

    @property
    def base_dir(self) -> Path:
        return Path(self.source_path).parent if self.source_path else Path.cwd()

    def trials_for(self, scenario: ScenarioSpec) -> int:
        return scenario.trials if scenario.trials is not None else self.trials


@dataclass(frozen=True, kw_only=True)
class ResolvedScenario:
    """A scenario applied to the mission: what each of its trials flies."""

    index: int
    spec: ScenarioSpec
    mission: MissionSpec
    trials: int
    takeoff_altitude_rel_m: float
    spec_hash: str


def _hashed(value: Any, spec_field: dataclasses.Field) -> bool:
    """Whether a field enters a spec's plain form: not `source_path`, and not a field added after 0.1 while
    it keeps its default (HASH_WHEN_SET), so that stores made before it still resume."""
    if spec_field.name == "source_path" or spec_field.metadata.get("hash") == "never":
        return False
    if spec_field.metadata.get("hash") == "when-set":
        default = (spec_field.default_factory() if spec_field.default_factory is not dataclasses.MISSING
                   else spec_field.default)
        return getattr(value, spec_field.name) != default
    return True


def spec_hash(value: Any) -> str:
    """A short stable hash of a spec's content."""
    text = json.dumps(to_plain(value, keep=_hashed), sort_keys=True, default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]


def resolve_scenarios(campaign: CampaignSpec, *, mission: MissionSpec | None = None) -> list[ResolvedScenario]:
    """Apply each scenario to the mission; raises SpecError naming the campaign file and field."""
    path = campaign.source_path
    if mission is None:
        mission = load_campaign_mission(campaign)
    if campaign.pad is not None:
        mission = replace(mission, pad=replace(mission.pad, preset=campaign.pad))
    resolved = []
    for index, scenario in enumerate(campaign.scenarios):
        where = f"scenarios[{index}]"
        try:
            flown = mission.with_land(mode=scenario.land, sensor=scenario.sensor, faults=dict(scenario.faults),
                                      params=dict(scenario.land_params) if scenario.land_params else None)
        except SpecValueError as error:
            field_name = "land" if error.field == "mode" else error.field
            if field_name == "params" or field_name.startswith("params."):
                field_name = "land_" + field_name
            raise SpecError(path=path, field=f"{where}.{field_name}", problem=error.problem) from None
        if scenario.environment:
            merged = deep_merge(to_plain(flown.environment, keep=_hashed), scenario.environment)
            environment = build(EnvironmentSpec, merged, path=path, field=f"{where}.environment")
            flown = replace(flown, environment=environment)
        if scenario.params:
            try:
                flown = replace(flown, params={**flown.params, **scenario.params})
            except SpecValueError as error:
                raise SpecError(path=path, field=f"{where}.{error.field}", problem=error.problem) from None
        altitude = scenario.initial_height_m or flown.takeoff_altitude_rel_m()
        resolved.append(ResolvedScenario(index=index, spec=scenario, mission=flown,
                                         trials=campaign.trials_for(scenario), takeoff_altitude_rel_m=altitude,
                                         spec_hash=spec_hash({"mission": flown, "altitude": altitude})))
    return resolved


def load_campaign_mission(campaign: CampaignSpec) -> MissionSpec:
    mission_path = Path(campaign.mission)
    if not mission_path.is_absolute():
        mission_path = campaign.base_dir / mission_path
    if not mission_path.exists():
        raise SpecError(path=campaign.source_path, field="mission", problem=f"unknown mission: {mission_path} not found")
    profile = None
    if campaign.sim_profile is not None:
        from ..sim.profile import load_profile, resolve_profile_path

        try:
            profile = load_profile(resolve_profile_path(campaign.sim_profile, relative_to=campaign.base_dir))
        except SpecError as error:
            raise SpecError(path=campaign.source_path, field="sim_profile", problem=str(error)) from None
    return load_mission(mission_path, profile=profile)


def load_campaign(path: str | Path) -> CampaignSpec:
    """Load and validate a campaign file, scenarios applied to the mission included."""
    campaign = load_spec_file(CampaignSpec, path)
    resolve_scenarios(campaign)
    return campaign

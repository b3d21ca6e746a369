"""Simulation profiles: overrides of the simulated world, with where they came from.

A profile YAML holds `environment:` and `sensors:` overrides (the mission
sections of those names, any subset) and, when it was fitted, its
`provenance`: the field data and campaign it was fitted on, the fitted
parameters with their values, the scenarios held out, the scores per scenario,
the date, preland's version and the optimizer's budget and seed. Missions and
campaigns name one with `sim_profile: FILE` (relative to their own file); a
mission's and a scenario's own `environment:` and `sensors:` overrides apply on
top of it.

Checked when it loads: unknown keys and wrong types (as a mission's sections),
calibratable parameters outside their declared range (`calibratable.py`), and
fitted parameters that are not declared calibratable or disagree with the
overrides. Every error names the file and the field.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from ..config.loader import build, deep_merge, load_spec_file, to_plain
from ..errors import SpecError, require
from ..sensing.spec import SensorsSpec
from .calibratable import CalibratableError, calibratable_parameters, find_calibratable, section_and_path
from .spec import EnvironmentSpec

ROLES = ("fitted", "held_out")


@dataclass(frozen=True, kw_only=True)
class ScenarioScore:
    """How a scenario's simulated landings compare with its field trials under the profile.

    `role`: fitted or held_out; `wasserstein_cm`: Wasserstein-1 distance between the simulated and field
    landing errors; `time_wasserstein_s`: the same for landing times; means and the field's min..max in cm;
    `inside`: whether the simulated mean lies within the field's min..max; `trials`/`field_trials`: how many
    simulated (landed) and field trials were compared."""

    label: str
    role: str
    wasserstein_cm: float
    sim_mean_cm: float
    field_mean_cm: float
    field_min_cm: float
    field_max_cm: float
    inside: bool
    trials: int
    field_trials: int
    time_wasserstein_s: float | None = None
    sim_time_mean_s: float | None = None
    field_time_mean_s: float | None = None

    def __post_init__(self) -> None:
        require(self.role in ROLES, "role", f"must be one of: {', '.join(ROLES)}")
        require(self.wasserstein_cm >= 0, "wasserstein_cm", "must be >= 0")


@dataclass(frozen=True, kw_only=True)
class OptimizerRecord:
    """How the fit searched: `method`, the evaluation `budget` and those used, the `seed`, simulated
    trials per scenario and evaluation, and the objective's landing-time weight; the best values'
    `objective` on the fit's own seeds and, flown again with the campaign's base seed replaced by each of
    `fresh_base_seeds`, on other seeds (`fresh_seed_objectives`)."""

    method: str
    budget: int
    evaluations: int
    seed: int
    trials_per_scenario: int
    time_weight: float = 0.0
    objective: float | None = None
    wall_time_s: float | None = None
    fresh_base_seeds: tuple[int, ...] = ()
    fresh_seed_objectives: tuple[float, ...] = ()


@dataclass(frozen=True, kw_only=True)
class Provenance:
    """Where a fitted profile came from."""

    data: str
    campaign: str
    fitted: dict[str, float]
    held_out: tuple[str, ...] = ()
    scores: tuple[ScenarioScore, ...] = ()
    created: str = ""
    preland_version: str = ""
    optimizer: OptimizerRecord | None = None
    start: dict[str, float] = field(default_factory=dict)

    def score_of(self, label: str) -> ScenarioScore | None:
        return next((s for s in self.scores if s.label == label), None)


@dataclass(frozen=True)
class ProfileSpec:
    """A simulation profile: `environment` and `sensors` overrides (any subset of a mission's sections of those
    names), and the provenance of a fitted one."""

    name: str
    description: str = ""
    environment: dict[str, Any] = field(default_factory=dict, metadata={"schema_partial": EnvironmentSpec})
    sensors: dict[str, Any] = field(default_factory=dict, metadata={"schema_partial": SensorsSpec})
    provenance: Provenance | None = None
    source_path: str = field(default="", compare=False)

    def value_of(self, name: str) -> float | None:
        """The override of calibratable parameter `name`, None when the profile leaves it."""
        section, parts = section_and_path(name)
        value: Any = getattr(self, section)
        for part in parts:
            if not isinstance(value, dict) or part not in value:
                return None
            value = value[part]
        return value


def overrides_of(values: dict[str, float]) -> dict[str, dict[str, Any]]:
    """Calibratable parameter values as `environment:` and `sensors:` override mappings."""
    sections: dict[str, dict[str, Any]] = {"environment": {}, "sensors": {}}
    for name, value in values.items():
        section, parts = section_and_path(name)
        node = sections[section]
        for part in parts[:-1]:
            node = node.setdefault(part, {})
        node[parts[-1]] = float(value)
    return sections


def _walk(mapping: dict[str, Any], prefix: str = ""):
    for key, value in mapping.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            yield from _walk(value, name + ".")
        else:
            yield name, value


def validate_profile(profile: ProfileSpec) -> ProfileSpec:
    """Check the overrides against the mission's sections and the calibratable ranges; SpecError naming the
    file and field."""
    path = profile.source_path or profile.name
    build(EnvironmentSpec, profile.environment, path=path, field="environment")
    build(SensorsSpec, profile.sensors, path=path, field="sensors")
    declared = calibratable_parameters()
    for section, prefix in (("environment", ""), ("sensors", "sensors.")):
        for name, value in _walk(getattr(profile, section)):
            parameter = declared.get(prefix + name)
            if parameter is not None and not isinstance(value, bool) and isinstance(value, (int, float)) \
                    and not parameter.contains(float(value)):
                raise SpecError(path=path, field=f"{section}.{name}",
                                problem=f"{value:g} is outside the calibratable range "
                                        f"{parameter.low:g}..{parameter.high:g}")
    if profile.provenance is not None:
        for name, value in profile.provenance.fitted.items():
            try:
                find_calibratable(name)
            except CalibratableError as error:
                raise SpecError(path=path, field=f"provenance.fitted.{name}", problem=str(error)) from None
            if profile.value_of(name) != value:
                raise SpecError(path=path, field=f"provenance.fitted.{name}",
                                problem=f"fitted value {value:g} is not the profile's override "
                                        f"({profile.value_of(name)})")
    return profile


def load_profile(path: str | Path) -> ProfileSpec:
    """Load and validate a profile YAML file. Raises SpecError naming file and field."""
    return validate_profile(load_spec_file(ProfileSpec, path))


def resolve_profile_path(name: str, *, relative_to: Path) -> Path:
    path = Path(name)
    return path if path.is_absolute() else relative_to / path


def _written(value: Any, spec_field: dataclasses.Field) -> bool:
    return spec_field.name != "source_path" and getattr(value, spec_field.name) is not None


def profile_yaml(profile: ProfileSpec) -> str:
    """The profile as YAML text (loadable by `load_profile`)."""
    header = ("# yaml-language-server: $schema=../schemas/profile.schema.json\n"
              "# A simulation profile (docs: reference/profile.md): overrides of the simulated world,\n"
              "# and, for a fitted one, the data it was fitted on and how it scores.\n")
    return header + yaml.safe_dump(to_plain(profile, keep=_written, float_digits=6), sort_keys=False,
                                   allow_unicode=True, width=110)


def write_profile(profile: ProfileSpec, path: Path) -> None:
    validate_profile(profile)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(profile_yaml(profile), encoding="utf-8")

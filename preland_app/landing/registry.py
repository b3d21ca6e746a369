"""The land modes preland knows, by the name missions, campaigns and the CLI use: one lookup.

A name is found, in this order, among the built-in modes, the modes installed
packages register under the entry-point group `preland.land_modes`, and import
paths (`package.module:ClassName`). The built-in modes are entry points like a
plugin's (declared here rather than in preland's installed metadata, so they
work from a source tree), and their factories are loaded by import path the
same way.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from importlib.metadata import EntryPoint
from typing import Any

from ..errors import SpecValueError
from ..sensing.faults import FaultSpec
from .base import LandStrategy
from .cautious import CautiousSpec
from .paper import PaperSpec
from .plugins import (
    ENTRY_POINT_GROUP,
    LandModeError,
    entry_point_origin,
    installed_entry_points,
    is_import_path,
    load_object,
    make_strategy,
    precision_sensor_of,
)
from .precision import SENSORS

BUILT_IN: tuple[EntryPoint, ...] = tuple(
    EntryPoint(name=name, value=f"preland_app.landing.builtin:{name}", group=ENTRY_POINT_GROUP)
    for name in ("normal", "irlock", "marker", "fused", "cautious", "paper_static", "paper_adaptive"))
LAND_MODES = tuple(entry_point.name for entry_point in BUILT_IN)
PRECISION_SENSORS = SENSORS
BUILT_IN_OPTIONS = "land.sensor, land.faults, land.cautious, land.paper, land.normal_scored_from"


@dataclass(frozen=True, kw_only=True)
class LandMode:
    """A land mode found by name. `target`: the import path of its factory; `origin`: built-in, the
    installed distribution that registers it, or import path."""

    name: str
    target: str
    origin: str
    builtin: bool = False

    @property
    def label(self) -> str:
        """How errors name it."""
        if self.builtin or is_import_path(self.name):
            return self.name
        return f"{self.name} ({self.target})"

    def factory(self) -> Any:
        """The class (or function) that makes the strategy; raises LandModeError when it cannot be loaded."""
        return load_object(self.target)


def land_mode_names() -> list[str]:
    """Every short name: the built-in modes, then the installed plugins' entry points."""
    return [*LAND_MODES, *(name for name in installed_entry_points() if name not in LAND_MODES)]


def find_land_mode(name: str) -> LandMode:
    """The land mode `name` names (nothing is imported yet); raises LandModeError for an unknown name."""
    builtin = next((entry_point for entry_point in BUILT_IN if entry_point.name == name), None)
    if builtin is not None:
        return LandMode(name=name, target=builtin.value, origin="built-in", builtin=True)
    if is_import_path(name):
        return LandMode(name=name, target=name, origin="import path")
    entry_point = installed_entry_points().get(name)
    if entry_point is not None:
        return LandMode(name=name, target=entry_point.value, origin=entry_point_origin(entry_point))
    raise LandModeError(f"unknown land mode {name!r} (expected one of: {', '.join(land_mode_names())}, "
                        "or an import path package.module:ClassName)")


def is_land_mode_name(name: str) -> bool:
    """True for a built-in or installed mode's name and any import path (imported only when flown)."""
    try:
        find_land_mode(name)
    except LandModeError:
        return False
    return True


def create_land_strategy(mode: str, *, sensor: str | None = None, faults: dict[str, FaultSpec] | None = None,
                         cautious: CautiousSpec | None = None, paper: PaperSpec | None = None,
                         normal_reference: str = "takeoff", params: dict[str, Any] | None = None) -> LandStrategy:
    """A fresh strategy for land mode `mode`. Built-in modes take the mission's land fields; a plugin takes
    `params` as keyword arguments. Raises LandModeError (cannot find or load it) or SpecValueError at
    `params...` (options it does not take, or refuses)."""
    found = find_land_mode(mode)
    factory = found.factory()
    if found.builtin:
        if params:
            raise SpecValueError("params", f"the built-in land mode {mode!r} takes no params "
                                           f"(its options are {BUILT_IN_OPTIONS})")
        from .builtin import BuiltInOptions

        return factory(BuiltInOptions(sensor=sensor, faults=dict(faults or {}), cautious=cautious, paper=paper,
                                      normal_scored_from=normal_reference))
    return make_strategy(factory, params or {}, describe=found.label)


@dataclass(frozen=True, kw_only=True)
class LandModeRow:
    """One line of `preland modes`. `scored_from` and `sensor` are None where they depend on options."""

    name: str
    origin: str
    scored_from: str | None
    sensor: str | None
    description: str


def _first_line(obj: Any) -> str:
    doc = inspect.getdoc(obj) or ""
    return doc.strip().splitlines()[0] if doc.strip() else ""


def catalog() -> list[LandModeRow]:
    """Every land mode found by short name: built-in ones, then installed plugins (one that cannot be
    loaded is listed with the reason)."""
    rows = []
    for name in land_mode_names():
        found = find_land_mode(name)
        try:
            factory = found.factory()
        except LandModeError as error:
            rows.append(LandModeRow(name=name, origin=found.origin, scored_from=None, sensor=None,
                                    description=f"cannot be loaded: {error}"))
            continue
        try:
            strategy = create_land_strategy(name)
            scored_from, sensor = strategy.scoring_reference.value, precision_sensor_of(strategy) or "GPS"
        except Exception:  # needs options to be made: its scoring depends on them
            scored_from = sensor = None
        rows.append(LandModeRow(name=name, origin=found.origin, scored_from=scored_from, sensor=sensor,
                                description=_first_line(factory)))
    return rows

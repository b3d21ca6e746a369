"""The built-in land modes, each a factory the registry finds by import path, as it finds a plugin's class.

A plugin takes its options as keyword arguments (`land.params`); the built-in
modes take theirs from the mission's own `land` fields (sensor, faults,
cautious, paper, normal_scored_from), gathered in `BuiltInOptions`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..sensing.faults import FaultSpec
from .base import LandStrategy, ScoringReference
from .cautious import CautiousSpec
from .normal import NormalLanding
from .paper import PaperLanding, PaperSpec
from .precision import PrecisionLanding

DEFAULT_CAUTIOUS_SENSOR = "marker"  # the thesis' cautious trials (Table 5) use the marker


@dataclass(frozen=True, kw_only=True)
class BuiltInOptions:
    """A mission's `land` fields that the built-in modes read."""

    sensor: str | None = None
    faults: dict[str, FaultSpec] = field(default_factory=dict)
    cautious: CautiousSpec | None = None
    paper: PaperSpec | None = None
    normal_scored_from: str = "takeoff"


def normal(options: BuiltInOptions) -> LandStrategy:
    """the autopilot's LAND on GPS alone"""
    return NormalLanding(scoring_reference=ScoringReference(options.normal_scored_from))


def irlock(options: BuiltInOptions) -> LandStrategy:
    """LAND with precision landing on the IR-LOCK (angles only, height from the rangefinder)"""
    return PrecisionLanding("irlock", faults=options.faults)


def marker(options: BuiltInOptions) -> LandStrategy:
    """LAND with precision landing on ArUco marker detections (angles and distance)"""
    return PrecisionLanding("marker", faults=options.faults)


def fused(options: BuiltInOptions) -> LandStrategy:
    """LAND with precision landing on the fused IR-LOCK + marker sensor"""
    return PrecisionLanding("fused", faults=options.faults)


def cautious(options: BuiltInOptions) -> LandStrategy:
    """precision landing that retries when the target is lost (--sensor irlock|marker|fused)"""
    return PrecisionLanding(options.sensor or DEFAULT_CAUTIOUS_SENSOR, faults=options.faults,
                            cautious=options.cautious or CautiousSpec())


def paper_static(options: BuiltInOptions) -> LandStrategy:
    """the paper's Algorithm 1: companion-side GUIDED descent onto the highest marker id"""
    return PaperLanding(adaptive=False, spec=options.paper, marker_fault=options.faults.get("marker"))


def paper_adaptive(options: BuiltInOptions) -> LandStrategy:
    """the paper's Algorithm 2: activation levels, recovery climbs, altitude-scaled speeds"""
    return PaperLanding(adaptive=True, spec=options.paper, marker_fault=options.faults.get("marker"))

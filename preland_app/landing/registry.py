"""The land modes preland knows, by the name missions and the CLI use."""

from __future__ import annotations

from ..sensing.faults import FaultSpec
from .base import LandStrategy, ScoringReference
from .cautious import CautiousSpec
from .normal import NormalLanding
from .paper import PaperLanding, PaperSpec
from .precision import SENSORS, PrecisionLanding

LAND_MODES = ("normal", "irlock", "marker", "fused", "cautious", "paper_static", "paper_adaptive")
PRECISION_SENSORS = SENSORS
DEFAULT_CAUTIOUS_SENSOR = "marker"  # the thesis' cautious trials (Table 5) use the marker

MODE_DESCRIPTIONS = {
    "normal": "the autopilot's LAND on GPS alone",
    "irlock": "LAND with precision landing on the IR-LOCK (angles only, height from the rangefinder)",
    "marker": "LAND with precision landing on ArUco marker detections (angles and distance)",
    "fused": "LAND with precision landing on the fused IR-LOCK + marker sensor",
    "cautious": "precision landing that retries when the target is lost (--sensor irlock|marker|fused)",
    "paper_static": "the paper's Algorithm 1: companion-side GUIDED descent onto the highest marker id",
    "paper_adaptive": "the paper's Algorithm 2: activation levels, recovery climbs, altitude-scaled speeds",
}


def land_mode_names() -> list[str]:
    return list(LAND_MODES)


def sensor_for(mode: str, sensor: str | None) -> str | None:
    """The precision sensor a land mode uses (None for normal)."""
    if mode == "normal":
        return None
    if mode.startswith("paper_"):
        return "marker"
    if mode == "cautious":
        return sensor or DEFAULT_CAUTIOUS_SENSOR
    return mode


def create_land_strategy(mode: str, *, sensor: str | None = None, faults: dict[str, FaultSpec] | None = None,
                         cautious: CautiousSpec | None = None, paper: PaperSpec | None = None,
                         normal_reference: str = "takeoff") -> LandStrategy:
    """A fresh strategy for land mode `mode`; raises KeyError naming the known modes."""
    if mode not in LAND_MODES:
        raise KeyError(f"unknown land mode {mode!r} (expected one of: {', '.join(LAND_MODES)})")
    if mode == "normal":
        return NormalLanding(scoring_reference=ScoringReference(normal_reference))
    if mode in ("paper_static", "paper_adaptive"):
        return PaperLanding(adaptive=mode == "paper_adaptive", spec=paper, marker_fault=(faults or {}).get("marker"))
    if mode == "cautious":
        return PrecisionLanding(sensor_for(mode, sensor), faults=faults, cautious=cautious or CautiousSpec())
    return PrecisionLanding(mode, faults=faults)

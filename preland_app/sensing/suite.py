"""What sensors a land mode gets from the runtime. No ground truth is reachable from here."""

from __future__ import annotations

from dataclasses import dataclass

from .camera import FrameSource
from .marker import MarkerDetector
from .sources import IrLockSource
from .spec import SensorsSpec


@dataclass
class SensorSuite:
    """The companion's sensors for one trial. `camera` and `irlock` are None where the vehicle has none."""

    spec: SensorsSpec
    camera: FrameSource | None = None
    marker_detector: MarkerDetector | None = None
    irlock: IrLockSource | None = None

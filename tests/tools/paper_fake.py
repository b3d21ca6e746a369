"""A fake vehicle hovering at 12 m over the paper pad, with a camera rendering from the fake's own state:
for paper-landing tests that use nothing but the Vehicle protocol and frames."""

from __future__ import annotations

import numpy as np

from preland_app.clock import LoopClock, wait_until
from preland_app.events import EventLog
from preland_app.landing.base import LandingContext
from preland_app.sensing.camera import RPI_CAMERA_V2_640X480
from preland_app.sensing.marker import TrackingMarkerDetector
from preland_app.sensing.pad import PAPER_PAD
from preland_app.sensing.sources import VirtualFrameSource
from preland_app.sensing.spec import SensorsSpec
from preland_app.sensing.suite import SensorSuite
from preland_app.sensing.virtual_camera import CameraPose, VirtualCamera
from preland_app.vehicle.fake import FakeVehicle
from preland_app.vehicle.types import FlightMode


async def paper_context_over_fake(*, pad_at_ned_m: tuple[float, float],
                                  timeout_s: float) -> tuple[FakeVehicle, LandingContext]:
    """The fake, taken off to 12 m, and a landing context whose camera sees the paper pad at `pad_at_ned_m`."""
    clock = LoopClock()
    vehicle = FakeVehicle(clock=clock, speed_m_s=2.0, climb_rate_m_s=3.0, descent_rate_m_s=0.5)
    await vehicle.connect()
    await vehicle.set_mode(FlightMode.GUIDED)
    await vehicle.arm()
    await vehicle.takeoff(altitude_rel_m=12.0)

    async def up():
        return (await vehicle.telemetry()).altitude_rel_m >= 11.99

    await wait_until(up, clock=clock, timeout_s=30, operation="climb")
    renderer = VirtualCamera(camera=RPI_CAMERA_V2_640X480, pad=PAPER_PAD, pad_origin_ned_m=pad_at_ned_m,
                             rng=np.random.default_rng(0))
    source = VirtualFrameSource(
        renderer=renderer, clock=clock,
        pose=lambda: CameraPose(vehicle.north_m, vehicle.east_m, vehicle.down_m, 0.0, 0.0, 0.0))
    sensors = SensorSuite(spec=SensorsSpec(), camera=source,
                          marker_detector=TrackingMarkerDetector(pad=PAPER_PAD, camera=RPI_CAMERA_V2_640X480))
    context = LandingContext(vehicle=vehicle, clock=clock, events=EventLog(clock), rng=np.random.default_rng(1),
                             timeout_s=timeout_s, sensors=sensors)
    return vehicle, context

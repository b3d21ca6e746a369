"""The companion's simulated sensors, assembled once for every runtime that has ground truth: the virtual
camera with the marker detector, and the IR-LOCK model, each seeing the world through a pose function."""

from __future__ import annotations

import math
from collections.abc import Callable

from ..config.mission import MissionSpec
from ..sensing.irlock import IrLockModel
from ..sensing.marker import TrackingMarkerDetector, detector_parameters
from ..sensing.sources import IrLockSource, VirtualFrameSource
from ..sensing.suite import SensorSuite
from ..sensing.virtual_camera import CameraPose, VirtualCamera
from ..sim.noise import child_rng


def build_sensor_suite(*, mission: MissionSpec, seed: int, true_pose: Callable[[], CameraPose], clock,
                       camera: bool, irlock: bool, pose_time_s: Callable[[], float] | None = None) -> SensorSuite:
    """The companion's simulated sensors: they see the world through `true_pose` (NED from the start
    position, from the embedded simulator or from SITL's SIM_STATE); what they give is images and readings.
    `pose_time_s`: the vehicle time (s) of the pose `true_pose` gives, which stamps the readings; None when
    the pose is always the clock's present (the embedded simulator)."""
    spec = mission.sensors
    suite = SensorSuite(spec=spec)
    if not (camera or irlock):
        return suite
    pad = mission.pad_spec()
    pad_origin = mission.pad.offset_from_start_ned_m

    if camera:
        model = spec.camera.model(relative_to=mission.base_dir)
        renderer = VirtualCamera(camera=model, pad=pad, pad_origin_ned_m=pad_origin, pad_yaw_deg=mission.pad.yaw_deg,
                                 rng=child_rng(seed, "camera"), effects=spec.camera.effects())
        suite.camera = VirtualFrameSource(renderer=renderer, pose=true_pose, clock=clock, pose_time_s=pose_time_s)
        suite.marker_detector = TrackingMarkerDetector(pad=pad, camera=model,
                                                       parameters=detector_parameters(spec.marker.detector))
    if irlock and pad.beacon_m is not None:
        yaw = math.radians(mission.pad.yaw_deg)
        bn, be = pad.beacon_m
        beacon = (pad_origin[0] + bn * math.cos(yaw) - be * math.sin(yaw),
                  pad_origin[1] + bn * math.sin(yaw) + be * math.cos(yaw))
        model_ir = IrLockModel(spec=spec.irlock, beacon_ned_m=beacon, rng=child_rng(seed, "irlock"))
        suite.irlock = IrLockSource(model=model_ir, pose=true_pose, clock=clock, pose_time_s=pose_time_s)
    return suite

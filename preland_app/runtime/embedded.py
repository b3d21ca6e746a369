"""Run one trial on the embedded simulator, in virtual time, and score it from the simulator's truth."""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ..clock import LoopClock, run_virtual
from ..config.mission import MissionSpec
from ..events import EventLog
from ..landing.base import ScoringReference
from ..mission import MissionReport, MissionRunner
from ..outcome import Outcome, TrialOutcome, outcome_for_error, score_touchdown
from ..sim.noise import child_rng
from ..sim.simulator import Simulator
from ..vehicle.sim_backend import SimVehicle
from ..sensing.irlock import IrLockModel
from ..sensing.marker import TrackingMarkerDetector, detector_parameters
from ..sensing.sources import IrLockSource, VirtualFrameSource
from ..sensing.suite import SensorSuite
from ..sensing.virtual_camera import CameraPose, VirtualCamera
from .recorder import TrajectoryRecorder



@dataclass(frozen=True, kw_only=True)
class TrialRequest:
    """One trial: a mission, a seed, and optional overrides of its land mode (a name or an import path),
    the plugin's options (`land_params`), sensor, faults (sensor -> fault syntax) and take-off altitude."""

    mission: MissionSpec
    seed: int
    land_mode: str | None = None
    sensor: str | None = None
    faults: dict[str, str] | None = None
    takeoff_altitude_rel_m: float | None = None
    record_trajectory: bool = True
    land_params: dict[str, Any] | None = None

    def resolved_mission(self) -> MissionSpec:
        if self.land_mode is None and self.sensor is None and self.faults is None and self.land_params is None:
            return self.mission
        return self.mission.with_land(mode=self.land_mode, sensor=self.sensor, faults=self.faults,
                                      params=self.land_params)


def run_trial(request: TrialRequest) -> TrialOutcome:
    """Fly one trial on the embedded simulator (blocking; runs its own virtual-time loop)."""
    return run_virtual(fly_embedded(request))


async def fly_embedded(request: TrialRequest) -> TrialOutcome:
    mission = request.resolved_mission()
    strategy = mission.land.strategy()
    clock = LoopClock()
    simulator = Simulator(seed=request.seed, environment=mission.environment,
                          initial_yaw_deg=mission.initial_yaw_deg)
    vehicle = SimVehicle(simulator=simulator, clock=clock)
    events = EventLog(clock)
    def true_pose() -> CameraPose:
        pose = simulator.true_pose()
        return CameraPose(pose.north_m, pose.east_m, pose.down_m, pose.roll_rad, pose.pitch_rad, pose.yaw_rad)

    sensors = build_sensor_suite(mission=mission, seed=request.seed, true_pose=true_pose, clock=clock,
                                 camera=strategy.uses_marker, irlock=strategy.uses_irlock)
    runner = MissionRunner(spec=mission, vehicle=vehicle, strategy=strategy, events=events,
                           rng=child_rng(request.seed, "landing"), sensors=sensors,
                           takeoff_altitude_rel_m=request.takeoff_altitude_rel_m)

    def truth() -> tuple[float, float, float]:
        pose = simulator.true_pose()
        return pose.north_m, pose.east_m, -pose.down_m

    recorder = TrajectoryRecorder(vehicle=vehicle, clock=clock, truth=truth)
    outcome, message = Outcome.LANDED, Outcome.LANDED.description
    await vehicle.connect()
    recording = asyncio.ensure_future(recorder.run()) if request.record_trajectory else None
    try:
        await runner.run()
    except Exception as error:  # every failure is recorded as this trial's outcome
        outcome, message = outcome_for_error(error)
    finally:
        if recording is not None:
            recording.cancel()
            await asyncio.gather(recording, return_exceptions=True)
        await vehicle.close()
    return _score(request=request, mission=mission, simulator=simulator, report=runner.report, events=events,
                  outcome=outcome, message=message, scoring=strategy.scoring_reference,
                  takeoff_altitude_rel_m=runner.takeoff_altitude_rel_m,
                  trajectory=recorder.array() if request.record_trajectory else None)


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


def _score(*, request: TrialRequest, mission: MissionSpec, simulator: Simulator, report: MissionReport,
           events: EventLog, outcome: Outcome, message: str, scoring: ScoringReference,
           takeoff_altitude_rel_m: float, trajectory) -> TrialOutcome:
    touchdowns = simulator.touchdowns()
    crash = next((t for t in touchdowns if t.crashed), None)
    if crash is not None:
        outcome = Outcome.CRASHED
        message = (f"touched down at {crash.vertical_speed_m_s:.1f} m/s vertical speed, "
                   f"{crash.tilt_deg:.0f} deg tilt")
    reference = mission.pad.offset_from_start_ned_m if scoring is ScoringReference.PAD else (0.0, 0.0)
    final = touchdowns[-1] if touchdowns and simulator.true_pose().on_ground else None
    score = None
    if final is not None and outcome in (Outcome.LANDED, Outcome.CRASHED):
        score = score_touchdown(touchdown_ned_m=(final.north_m, final.east_m), reference_ned_m=reference)
    landing_time_s = None
    if final is not None and report.handover_time_s is not None:
        landing_time_s = final.time_s - report.handover_time_s
    armed = events.first("armed")
    flight_time_s = None
    if armed is not None and report.disarmed_time_s is not None:
        flight_time_s = report.disarmed_time_s - armed.time_s
    details = dict(report.landing.details) if report.landing else {}
    details["wind_from_deg"] = round(simulator.wind.direction_from_deg, 1)
    return TrialOutcome(
        outcome=outcome,
        message=message,
        seed=request.seed,
        mission=mission.name,
        land_mode=mission.land.mode,
        takeoff_altitude_rel_m=takeoff_altitude_rel_m,
        scoring_reference=scoring.value,
        landing_error_cm=score.landing_error_cm if score else None,
        offset_north_cm=score.offset_north_cm if score else None,
        offset_east_cm=score.offset_east_cm if score else None,
        landing_time_s=landing_time_s,
        flight_time_s=flight_time_s,
        touchdown_speed_m_s=final.vertical_speed_m_s if final is not None else None,
        details=details,
        events=tuple(events.events),
        trajectory=trajectory,
    )

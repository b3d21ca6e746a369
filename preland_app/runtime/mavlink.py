"""Run one trial over MAVLink: ArduPilot SITL, a real drone, or `preland sim serve`.

The mission, land mode and sensors are the embedded runtime's; only the
vehicle differs (`MavlinkVehicle`) and the clock is the autopilot's. Where the
vehicle reports ground truth (SIM_STATE, from SITL or the simulator's MAVLink
face), the virtual camera and the IR-LOCK model see the world through it and
the landing is scored from it; without truth (a real drone) the outcome has no
landing error: the operator measures it.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, TypeVar

from ..errors import PrelandError
from ..events import EventLog
from ..geo import GeoPoint, LocalTangentPlane
from ..field.preflight import PreflightFailed, run_preflight
from ..landing.base import ScoringReference
from ..landing.precision import PrecisionLanding
from ..sensing.logging import LoggingDetector, RecordingFrameSource
from ..sensing.marker import TrackingMarkerDetector, detector_parameters
from ..mavlink.endpoint import Endpoint, parse_endpoint
from ..mavlink.fault_message import listen
from ..sensing.faults import FaultCommand
from ..mission import MissionRunner
from ..outcome import Outcome, TrialOutcome, outcome_for_error, reference_ned_m, score_trial
from ..sensing.virtual_camera import CameraPose
from ..sim.noise import child_rng
from ..vehicle.mavlink_backend import MavlinkVehicle
from .base import TrialRequest, build_options
from .sensors import build_sensor_suite
from .recorder import TrajectoryRecorder

ON_GROUND_M = 0.05
T = TypeVar("T")


class SimStateTruth:
    """Ground truth from SIM_STATE: NED in m from where the vehicle stood when the trial started."""

    def __init__(self, vehicle: MavlinkVehicle) -> None:
        self.vehicle = vehicle
        self._plane: LocalTangentPlane | None = None

    @staticmethod
    def _point(state: dict) -> GeoPoint:
        # The float lat/lon fields are float32 (about 0.4 m steps); the int extensions carry 1e-7 degrees.
        if state.get("lat_int") or state.get("lon_int"):
            return GeoPoint(state["lat_int"] / 1e7, state["lon_int"] / 1e7, state["alt"])
        return GeoPoint(state["lat"], state["lon"], state["alt"])

    def start(self) -> None:
        self._plane = LocalTangentPlane(self._point(self.vehicle.sim_state()))

    def pose(self) -> CameraPose:
        state = self.vehicle.sim_state()
        north, east, down = self._plane.to_ned(self._point(state))
        return CameraPose(north, east, down, state["roll"], state["pitch"], state["yaw"])

    def time_s(self) -> float:
        """The vehicle time (s) of the newest SIM_STATE: the vehicle clock's reading when it was read."""
        return self.vehicle.sim_state_time_s()

    def ned(self) -> tuple[float, float, float]:
        pose = self.pose()
        return pose.north_m, pose.east_m, -pose.down_m


async def fly_mavlink(request: TrialRequest, *, url: str, truth: bool = True, link_timeout_s: float = 5.0,
                      tlog_path: str | None = None, fault_listen: str | None = None, preflight: bool = False,
                      camera_source: str | None = None, frame_source=None, detection_log: str | None = None,
                      video_path: str | None = None, paced: bool = False, lockstep=None, sensor_truth=None,
                      companions: Sequence[Callable[[MavlinkVehicle], Awaitable[None]]] = (),
                      before_link: Callable[[], None] | None = None) -> TrialOutcome:
    """Fly one trial over MAVLink (on an ordinary asyncio loop: the autopilot keeps time).
    `tlog_path`: write every MAVLink message received to this telemetry log. `fault_listen`: a UDP address
    where PRELAND_FAULT_INJECTION commands change the land mode's faults while it flies. `preflight`: run
    the preflight checks first and refuse take-off when one fails. `camera_source` (a capture device or a
    video file) or `frame_source` (any FrameSource) replaces the virtual camera. `detection_log` (CSV) and
    `video_path` keep every detection and every frame the companion saw. `companions`: coroutines run beside
    the trial from the start (a SITL watchdog, a GPS-error driver); one that raises ends the trial with that
    error. `paced`: the vehicle is preland's simulator, flown in lock-step (PRELAND_PACE): every sensor reading
    at its vehicle time however slow this machine is. `lockstep` (a `LockstepClock`): the vehicle is SITL on
    a physics in this process that owns time, and this is its clock; `sensor_truth` (with `pose()` and
    `time_s()`): where the simulated sensors see the world from, instead of SIM_STATE (that physics' own
    state, exact at each reading's time), and with `ned()` what the trajectory and the score read too.
    `before_link`: called just before the link binds its port (whoever kept the port for it lets it go)."""
    mission = request.resolved_mission()
    strategy = mission.land.strategy()
    vehicle = MavlinkVehicle(url=url, want_truth=truth, link_timeout_s=link_timeout_s, tlog_path=tlog_path,
                             paced=paced, lockstep=lockstep, before_link=before_link)
    clock = vehicle.clock
    events = EventLog(clock)
    side_tasks = [asyncio.ensure_future(companion(vehicle)) for companion in companions]
    try:
        await _race(vehicle.connect(), side_tasks)
        # In lock-step, the companion's HEARTBEAT from here on, none of MAVSDK's: one that reached SITL after the
        # mission's start, at a wall time of MAVSDK's, could put a request's answer a loop later. Closed at the
        # connection, not at the start: one MAVSDK sent just before the start could still reach SITL after it.
        vehicle.keep_heartbeat_in_vehicle_time()
        if truth:
            await _race(vehicle.wait_for_truth(), side_tasks)
    except BaseException:
        await _stop(side_tasks)
        await vehicle.close()
        raise
    connected_s = None
    if lockstep is not None:
        connected_s = await lockstep.start_at()
        await vehicle.restart_streams()  # on a schedule from the mission's start, the same in every trial
    truth_source = None
    if truth:
        truth_source = SimStateTruth(vehicle)
        truth_source.start()
    real_camera = frame_source or (_open_camera(camera_source, mission, clock) if camera_source else None)
    seen_from = sensor_truth or truth_source
    sensors = build_sensor_suite(mission=mission, seed=request.seed,
                                 true_pose=seen_from.pose if seen_from else _no_truth, clock=clock,
                                 pose_time_s=seen_from.time_s if seen_from else None,
                                 camera=strategy.uses_marker and real_camera is None, irlock=strategy.uses_irlock)
    if real_camera is not None:
        sensors.camera = real_camera
        sensors.marker_detector = TrackingMarkerDetector(
            pad=mission.pad_spec(), camera=real_camera.camera,
            parameters=detector_parameters(mission.sensors.marker.detector))
    kept = []
    if sensors.camera is not None and video_path:
        sensors.camera = RecordingFrameSource(source=sensors.camera, path=video_path)
        kept.append(sensors.camera)
    if sensors.marker_detector is not None and detection_log:
        sensors.marker_detector = LoggingDetector(detector=sensors.marker_detector, path=detection_log, clock=clock)
        kept.append(sensors.marker_detector)
    if preflight:
        try:
            passed = await run_preflight(vehicle=vehicle, clock=clock, spec=mission.preflight,
                                         precision=isinstance(strategy, PrecisionLanding), sensors=sensors)
        except PreflightFailed as error:
            await _stop(side_tasks)
            for keeper in kept:
                keeper.close()
            await vehicle.close()
            return TrialOutcome(outcome=Outcome.ABORTED, message=str(error), seed=request.seed, mission=mission.name,
                                land_mode=mission.land.mode, takeoff_altitude_rel_m=mission.takeoff_altitude_rel_m(),
                                scoring_reference=strategy.scoring_reference.value,
                                details={"preflight_failures": error.failures, "runtime": "mavlink"})
        for line in passed:
            events.add("preflight", line)
    runner = MissionRunner(spec=mission, vehicle=vehicle, strategy=strategy, events=events,
                           rng=child_rng(request.seed, "landing"), sensors=sensors,
                           takeoff_altitude_rel_m=request.takeoff_altitude_rel_m)
    # A physics in this process that renders the sensors (`sensor_truth` with `ned`) is the truth it is scored by.
    recorded_truth = getattr(sensor_truth, "ned", None) or (truth_source.ned if truth_source else None)
    recorder = TrajectoryRecorder(vehicle=vehicle, clock=clock, truth=recorded_truth)
    recording = asyncio.ensure_future(recorder.run())
    listener = None
    if fault_listen is not None:
        def on_fault_command(fault_command: FaultCommand) -> bool:
            apply = getattr(strategy, "apply_fault_command", None)
            if apply is None:
                events.add("fault_command", f"ignored: land mode {strategy.name!r} takes no faults")
                return False
            apply(fault_command)
            events.add("fault_command", f"faults now {', '.join(f'{k} {v}' for k, v in fault_command.faults().items())}",
                       target=int(fault_command.target), r_drop=fault_command.r_drop, p_keep=fault_command.p_keep,
                       p_drop=fault_command.p_drop)
            return True

        listener = await listen(fault_listen, on_fault_command)
    outcome, message = Outcome.LANDED, Outcome.LANDED.description
    try:
        await _race(runner.run(), side_tasks)
    except Exception as error:  # every failure is recorded as this trial's outcome
        outcome, message = outcome_for_error(error)
    finally:
        await _stop(side_tasks)
        recording.cancel()
        await asyncio.gather(recording, return_exceptions=True)
        if listener is not None:
            listener.close()
        for keeper in kept:
            keeper.close()
        final_state = await _final_state(vehicle)
        await vehicle.close()
    trajectory = recorder.array()
    command = events.first("land_handover")
    final = touchdown = None
    if recorded_truth is not None and outcome is Outcome.LANDED and len(trajectory):
        final = trajectory[-1]  # where it came to rest; the first row on the ground after the hand-over times it
        on_ground = [row for row in trajectory if command is not None and row[0] >= command.time_s
                     and row[6] <= ON_GROUND_M]
        touchdown = on_ground[0] if on_ground else None
    armed = events.first("armed")
    scored = score_trial(
        touchdown_ned_m=(final[4], final[5]) if final is not None else None,
        touchdown_s=float(touchdown[0]) if touchdown is not None else None, scored=final is not None,
        reference_ned_m=reference_ned_m(pad_offset_ned_m=mission.pad.offset_from_start_ned_m,
                                        scored_from_pad=strategy.scoring_reference is ScoringReference.PAD),
        handover_s=command.time_s if command is not None else None,
        armed_s=armed.time_s if armed is not None else None, disarmed_s=runner.report.disarmed_time_s)
    score, landing_time_s, flight_time_s = scored.score, scored.landing_time_s, scored.flight_time_s
    details = dict(runner.report.landing.details) if runner.report.landing else {}
    details["runtime"] = "mavlink"
    details.update(final_state)
    details["clock_rate"] = round(clock.rate, 2)
    if paced:
        details["paced_grants"] = clock.grants
    if lockstep is not None:
        details["lockstep_wakes"] = lockstep.wakes
        details["lockstep_settles"] = lockstep.settles
        details["lockstep_settle_wall_s"] = round(lockstep.settle_wall_s, 2)
        details["lockstep_unsettled"] = lockstep.unsettled
        details["lockstep_connected_s"] = round(connected_s, 3)
    # Sensor ticks that gave nothing because no SIM_STATE had come since the last reading.
    waits = [getattr(source, "ticks_without_new_truth", None) for source in (sensors.camera, sensors.irlock)]
    if any(count is not None for count in waits):
        details["ticks_without_new_truth"] = sum(count or 0 for count in waits)
    if vehicle.tlog is not None:
        details["tlog"] = str(vehicle.tlog.path)
        details["tlog_messages"] = vehicle.tlog.written
    return TrialOutcome(
        outcome=outcome, message=message, seed=request.seed, mission=mission.name, land_mode=mission.land.mode,
        takeoff_altitude_rel_m=runner.takeoff_altitude_rel_m, scoring_reference=strategy.scoring_reference.value,
        landing_error_cm=score.landing_error_cm if score else None,
        offset_north_cm=score.offset_north_cm if score else None,
        offset_east_cm=score.offset_east_cm if score else None,
        landing_time_s=landing_time_s, flight_time_s=flight_time_s, details=details, events=tuple(events.events),
        trajectory=trajectory)


async def _final_state(vehicle: MavlinkVehicle) -> dict[str, Any]:
    """Where the vehicle ended the trial and its battery, as it last reported them (for a field campaign: the
    touchdown by RTK, the battery swap); nothing from a vehicle that no longer answers, and no position from
    one that never reported it (0, 0 until GLOBAL_POSITION_INT arrives)."""
    try:
        telemetry = await vehicle.telemetry()
    except PrelandError:
        return {}
    state = {"battery_remaining_pct": telemetry.battery.remaining_pct,
             "battery_voltage_v": round(telemetry.battery.voltage_v, 2)}
    position = telemetry.global_position
    if position.latitude_deg != 0.0 or position.longitude_deg != 0.0:
        state.update(final_latitude_deg=position.latitude_deg, final_longitude_deg=position.longitude_deg)
    return state


def _failed(task: asyncio.Future) -> bool:
    return task.done() and not task.cancelled() and task.exception() is not None


async def _race(work: Awaitable[T], side_tasks: list[asyncio.Future]) -> T:
    """Await `work`; a side task that fails first cancels it and raises its error instead."""
    main = asyncio.ensure_future(work)
    try:
        while True:
            failed = [task for task in side_tasks if _failed(task)]
            if failed:
                main.cancel()
                await asyncio.gather(main, return_exceptions=True)
                raise failed[0].exception()
            if main.done():
                return main.result()
            running = [task for task in side_tasks if not task.done()]
            await asyncio.wait([main, *running], return_when=asyncio.FIRST_COMPLETED)
    except BaseException:
        if not main.done():
            main.cancel()
            await asyncio.gather(main, return_exceptions=True)
        raise


async def _stop(tasks: list[asyncio.Future]) -> None:
    for task in tasks:
        task.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)


def _open_camera(source: str, mission, clock):
    from pathlib import Path

    from ..sensing.capture import CaptureDeviceSource, VideoFileSource

    camera = mission.sensors.camera.model(relative_to=mission.base_dir)
    if Path(source).is_file():
        return VideoFileSource(path=source, clock=clock, camera=camera, realtime=True)
    return CaptureDeviceSource(source=source, clock=clock, camera=camera)


def _no_truth() -> CameraPose:
    raise PrelandError("this runtime has no ground truth: simulated sensors cannot be used (use a real camera)")


@dataclass(frozen=True, kw_only=True)
class MavlinkOptions:
    """How to fly a vehicle over MAVLink. `truth`: the vehicle reports ground truth (SIM_STATE: `sim serve`,
    SITL; False for a real drone, whose landings the operator measures); `preflight`: run the preflight
    checks before take-off and refuse it when one fails; `camera_source`: a capture device or video file
    instead of the virtual camera; `detection_log` (CSV), `video_path`: keep every detection and frame;
    `tlog_dir`: keep one MAVLink telemetry log per trial there; `fault_listen`: a UDP address for the
    thesis' fault command during the flight; `link_timeout_s`: vehicle seconds without a HEARTBEAT before
    the link counts as lost; `paced`: the vehicle is preland's simulator (`preland sim serve`), flown in
    lock-step with the companion (PRELAND_PACE), so every camera frame and IR-LOCK reading is made at its
    vehicle time however loaded the machine is (refused at connect by anything else)."""

    truth: bool = True
    preflight: bool = True
    camera_source: str | None = None
    detection_log: str | None = None
    video_path: str | None = None
    tlog_dir: str | None = None
    fault_listen: str | None = None
    link_timeout_s: float = 5.0
    paced: bool = False


@dataclass(frozen=True)
class MavlinkRuntime:
    """A vehicle over MAVLink (`mavlink+udp://`, `+udpout://`, `+tcp://`, `+serial://`): `preland sim serve`,
    a SITL already running, or a drone. One vehicle: its trials fly one after another."""

    scheme: ClassVar[str] = "mavlink"
    name: ClassVar[str] = "mavlink"
    simulated_world: ClassVar[bool] = False
    max_workers: ClassVar[int | None] = 1
    cluster_resource: ClassVar[str | None] = None
    flies_a_vehicle: ClassVar[bool] = True  # a campaign on it is a field campaign (`preland_app.field.campaign`)
    endpoint: Endpoint
    options: MavlinkOptions = field(default_factory=MavlinkOptions)

    @property
    def url(self) -> str:
        return self.endpoint.url

    @property
    def source(self) -> str:
        """`sim` where the vehicle reports ground truth (a simulated one), else `field`."""
        return "sim" if self.options.truth else "field"

    @classmethod
    def from_url(cls, *, target: str, query: dict[str, str], options: dict[str, Any]) -> "MavlinkRuntime":
        return cls(endpoint=parse_endpoint(target), options=build_options(MavlinkOptions, options,
                                                                          runtime="mavlink+"))

    def fly(self, request: TrialRequest, *, tlog_name: str | None = None) -> TrialOutcome:
        o = self.options
        tlog_path = None
        if o.tlog_dir is not None:
            tlog_path = str(Path(o.tlog_dir) / (tlog_name or f"{request.mission.name}_seed{request.seed}.tlog"))
        return run_mavlink_trial(request, url=self.endpoint.url, truth=o.truth, link_timeout_s=o.link_timeout_s,
                                 tlog_path=tlog_path, fault_listen=o.fault_listen, preflight=o.preflight,
                                 camera_source=o.camera_source, detection_log=o.detection_log,
                                 video_path=o.video_path, paced=o.paced)

    def on_this_machine(self) -> "MavlinkRuntime":
        return self


def run_mavlink_trial(request: TrialRequest, *, url: str, **options) -> TrialOutcome:
    return asyncio.run(fly_mavlink(request, url=url, **options))



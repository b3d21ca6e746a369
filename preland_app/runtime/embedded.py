"""Run one trial on the embedded simulator, in virtual time, and score it from the simulator's truth."""

from __future__ import annotations

import asyncio
from dataclasses import dataclass
from typing import Any, ClassVar

from ..clock import LoopClock, run_virtual
from ..config.mission import MissionSpec
from ..events import EventLog
from ..landing.base import ScoringReference
from ..mission import MissionReport, MissionRunner
from ..outcome import Outcome, TrialOutcome, outcome_for_error, reference_ned_m, score_trial
from ..sim.noise import child_rng
from ..sim.simulator import Simulator
from ..vehicle.sim_backend import SimVehicle
from ..sensing.virtual_camera import CameraPose
from .base import RuntimeUrlError, TrialRequest, no_options
from .sensors import build_sensor_suite
from .recorder import TrajectoryRecorder



@dataclass(frozen=True)
class EmbeddedRuntime:
    """The embedded simulator (`sim:`): virtual time, ground truth, the same outcome for the same seed."""

    scheme: ClassVar[str] = "sim"
    name: ClassVar[str] = "embedded"
    source: ClassVar[str] = "sim"
    simulated_world: ClassVar[bool] = True
    max_workers: ClassVar[int | None] = None
    cluster_resource: ClassVar[str | None] = None
    url: ClassVar[str] = "sim:"

    @classmethod
    def from_url(cls, *, target: str, query: dict[str, str], options: dict[str, Any]) -> "EmbeddedRuntime":
        if target or query:
            raise RuntimeUrlError(f"sim:{target}{'?' if query else ''}: the embedded simulator takes no path or "
                                  "options (write sim:)")
        no_options({**options}, runtime="sim:")
        return cls()

    def fly(self, request: TrialRequest, *, tlog_name: str | None = None) -> TrialOutcome:
        return run_trial(request)

    def on_this_machine(self) -> "EmbeddedRuntime":
        return self


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


def _score(*, request: TrialRequest, mission: MissionSpec, simulator: Simulator, report: MissionReport,
           events: EventLog, outcome: Outcome, message: str, scoring: ScoringReference,
           takeoff_altitude_rel_m: float, trajectory) -> TrialOutcome:
    touchdowns = simulator.touchdowns()
    crash = next((t for t in touchdowns if t.crashed), None)
    if crash is not None:
        outcome = Outcome.CRASHED
        message = (f"touched down at {crash.vertical_speed_m_s:.1f} m/s vertical speed, "
                   f"{crash.tilt_deg:.0f} deg tilt")
    final = touchdowns[-1] if touchdowns and simulator.true_pose().on_ground else None
    armed = events.first("armed")
    scored = score_trial(
        touchdown_ned_m=(final.north_m, final.east_m) if final is not None else None,
        touchdown_s=final.time_s if final is not None else None,
        scored=outcome in (Outcome.LANDED, Outcome.CRASHED),
        reference_ned_m=reference_ned_m(pad_offset_ned_m=mission.pad.offset_from_start_ned_m,
                                        scored_from_pad=scoring is ScoringReference.PAD),
        handover_s=report.handover_time_s, armed_s=armed.time_s if armed is not None else None,
        disarmed_s=report.disarmed_time_s)
    score, landing_time_s, flight_time_s = scored.score, scored.landing_time_s, scored.flight_time_s
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

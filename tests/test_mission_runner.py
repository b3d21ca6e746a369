"""The mission runner's steps, timeouts and watcher, against the in-package fake vehicle."""

import asyncio
from dataclasses import replace

import numpy as np

from preland_app.clock import LoopClock, run_virtual
from preland_app.errors import CommandDenied, LinkLost, MissionAborted, WaitTimeout
from preland_app.events import EventLog
from preland_app.landing.normal import NormalLanding
from preland_app.mission import MissionRunner
from preland_app.vehicle.fake import FakeVehicle


def run_with_fake(mission, during=None, **fake_options):
    async def main():
        clock = LoopClock()
        vehicle = FakeVehicle(clock=clock, **fake_options)
        await vehicle.connect()
        events = EventLog(clock)
        runner = MissionRunner(spec=mission, vehicle=vehicle, strategy=NormalLanding(), events=events,
                               rng=np.random.default_rng(0))
        side = asyncio.ensure_future(during(vehicle, clock)) if during else None
        try:
            report = await runner.run()
            return report, vehicle, events, None
        except Exception as error:  # the test inspects it
            return runner.report, vehicle, events, error
        finally:
            if side:
                side.cancel()

    return run_virtual(main())


def test_mission_flies_steps_in_order(thesis_mission):
    mission = replace(thesis_mission, params={"LAND_SPEED": 40.0})
    report, vehicle, events, error = run_with_fake(mission)
    assert error is None and report.completed
    ops = [op for op in vehicle.operations() if op not in ("get_param",)]
    assert ops[:5] == ["connect", "set_param", "set_mode", "arm", "takeoff"]
    assert ops[5:9] == ["goto_ned"] * 4 and ops[9] == "set_mode"
    assert vehicle.params["LAND_SPEED"] == 40.0
    gotos = [c.arguments for c in vehicle.calls if c.operation == "goto_ned"]
    assert [(g["north_m"], g["east_m"], g["down_m"]) for g in gotos] == [
        (-2.0, 0.0, -10.0), (-2.0, 2.0, -10.0), (0.0, 2.0, -10.0), (0.0, 0.0, -10.0)]
    assert [e.kind for e in events.events] == ["params", "armed", "takeoff", "recorded", "waypoint", "waypoint",
                                               "waypoint", "waypoint", "land_handover", "land_command", "disarmed"]
    assert report.handover_time_s == events.first("land_handover").time_s < report.disarmed_time_s


def test_arm_is_retried_while_refused(thesis_mission):
    report, vehicle, _, error = run_with_fake(thesis_mission, deny={"arm": "PreArm: Gyros inconsistent"},
                                              deny_count={"arm": 2})
    assert error is None and report.completed
    assert vehicle.operations().count("arm") == 3


def test_arm_refused_for_good_ends_with_the_autopilots_reason(thesis_mission):
    mission = replace(thesis_mission, timeouts=replace(thesis_mission.timeouts, arm_s=5.0))
    _, vehicle, _, error = run_with_fake(mission, deny={"arm": "PreArm: Compass not calibrated"})
    assert isinstance(error, CommandDenied) and "Compass not calibrated" in str(error)
    assert 5 <= vehicle.operations().count("arm") <= 7


def test_slow_takeoff_times_out_with_a_typed_error(thesis_mission):
    mission = replace(thesis_mission, timeouts=replace(thesis_mission.timeouts, takeoff_s=5.0))
    report, _, _, error = run_with_fake(mission, climb_rate_m_s=0.1)
    assert isinstance(error, WaitTimeout)
    assert error.operation == "take-off" and error.timeout_s == 5.0
    assert "altitude" in str(error)
    assert report.recorded_position_ned_m is None


def test_disarm_in_flight_aborts_the_mission(thesis_mission):
    async def cut_motors(vehicle, clock):
        await clock.sleep(6.0)  # after take-off, before the landing
        vehicle.armed = False

    report, _, events, error = run_with_fake(thesis_mission, during=cut_motors)
    assert isinstance(error, MissionAborted)
    assert events.events[-1].kind == "aborted"
    assert not report.completed


def test_lost_link_surfaces_as_a_vehicle_error(thesis_mission):
    _, _, _, error = run_with_fake(thesis_mission, fail_after_s=6.0)
    assert isinstance(error, LinkLost)
    assert error.operation in {"telemetry", "goto_ned", "takeoff"}


def test_no_position_fix_times_out(thesis_mission):
    mission = replace(thesis_mission, timeouts=replace(thesis_mission.timeouts, position_fix_s=10.0))
    _, vehicle, _, error = run_with_fake(mission, position_ok_after_s=1e9)
    assert isinstance(error, WaitTimeout) and error.operation == "wait for position"
    assert "arm" not in vehicle.operations()

"""Field operations: preflight checks, pilot takeover and the geofence."""

import asyncio
import json
import socket
from dataclasses import replace

import numpy as np
import pytest

from preland_app.config.mission import GeofenceSpec
from preland_app.field.preflight import PreflightSpec
from preland_app.outcome import Outcome
from preland_app.runtime.embedded import TrialRequest, run_trial
from preland_app.runtime.mavlink import fly_mavlink
from preland_app.sensing.camera import RPI_CAMERA_V2_640X480, Frame
from preland_app.sim.spec import NavigationSpec
from preland_app.vehicle.types import FlightMode

from .conftest import SHORT_MISSION
from .test_mavlink_runtime import PATIENCE_S, ServedSimulator
from .waiting import until, until_async


class BlankCamera:
    """A camera that sees no pad, at `rate_hz` frames per vehicle second."""

    camera = RPI_CAMERA_V2_640X480

    def __init__(self, clock_getter, rate_hz: float) -> None:
        self._clock_getter = clock_getter
        self.rate_hz = rate_hz

    async def next_frame(self):
        clock = self._clock_getter()
        await clock.sleep(1.0 / self.rate_hz)
        return Frame(np.full((480, 640), 120, np.uint8), capture_time_s=clock.now_s())


def _preflight(mission, *, seed=1, mode="normal", prepare=None, frame_source=None):
    served = ServedSimulator(mission, seed=seed, speedup=8.0)
    if prepare is not None:
        prepare(served.simulator)
    try:
        outcome = asyncio.run(fly_mavlink(TrialRequest(mission=mission, seed=seed, land_mode=mode), url=served.url,
                                          preflight=True, frame_source=frame_source))
        armed = served.simulator.autopilot.armed
    finally:
        served.stop()
    return outcome, armed


def test_no_gps_fix_refuses_take_off(thesis_mission):
    environment = replace(thesis_mission.environment,
                          navigation=NavigationSpec(gps_fix_delay_s=1e6))
    outcome, armed = _preflight(replace(thesis_mission, environment=environment,
                                        preflight=PreflightSpec(gps_wait_s=2.0)))
    assert outcome.outcome is Outcome.ABORTED and not armed
    assert outcome.details["preflight_failures"] == ["GPS: no 3D fix / position estimate not healthy yet"]


def test_low_battery_refuses_take_off(thesis_mission):
    def drain(simulator):
        simulator.battery_used_mah = 0.8 * simulator.environment.airframe.battery_capacity_mah

    outcome, armed = _preflight(thesis_mission, prepare=drain)
    assert not armed
    (failure,) = [f for f in outcome.details["preflight_failures"] if f.startswith("battery")]
    assert failure.endswith("% is below 30 %") and 15 <= int(failure.split()[1]) <= 20


def test_precision_mode_without_plnd_refuses_take_off(thesis_mission):
    outcome, armed = _preflight(thesis_mission, mode="irlock")
    assert not armed
    failures = outcome.details["preflight_failures"]
    assert any(f.startswith("PLND_ENABLED is 0") for f in failures)
    assert any(f.startswith("PLND_TYPE is 0") and "reboot" in f for f in failures)


def test_slow_camera_and_missing_pad_refuse_take_off(thesis_mission):
    mission = replace(thesis_mission, params={"PLND_ENABLED": 1, "PLND_TYPE": 1},
                      preflight=PreflightSpec(require_pad_visible=True))
    holder = {}

    def prepare(simulator):
        simulator.params.set("PLND_ENABLED", 1)
        simulator.params.set("PLND_TYPE", 1)

    slow = BlankCamera(lambda: holder["clock"], rate_hz=5.0)

    async def run():
        from preland_app.runtime import mavlink as runtime

        original = runtime.MavlinkVehicle

        class Capturing(original):
            def __init__(self, **kwargs):
                super().__init__(**kwargs)
                holder["clock"] = self.clock

        runtime.MavlinkVehicle = Capturing
        try:
            served = ServedSimulator(mission, seed=1, speedup=4.0)
            prepare(served.simulator)
            try:
                return await fly_mavlink(TrialRequest(mission=mission, seed=1, land_mode="marker"), url=served.url,
                                         preflight=True, frame_source=slow), served.simulator.autopilot.armed
            finally:
                served.stop()
        finally:
            runtime.MavlinkVehicle = original

    outcome, armed = asyncio.run(run())
    assert not armed
    failures = outcome.details["preflight_failures"]
    assert any(f.startswith("camera: ") and "expected 30" in f for f in failures)
    assert "pad: not in view of the camera" in failures
    assert not any(f.startswith("PLND") for f in failures)


def test_a_pilot_mode_change_stops_the_mission_within_a_vehicle_second(thesis_mission):
    served = ServedSimulator(thesis_mission, seed=3, speedup=4.0)

    async def main():
        trial = asyncio.ensure_future(fly_mavlink(TrialRequest(mission=thesis_mission, seed=3), url=served.url))
        await until_async(lambda: served.simulator.autopilot.landed_state().name == "IN_AIR" or trial.done(),
                          timeout_s=PATIENCE_S, what="the vehicle to take off")
        take_off_s = served.simulator.time_s
        await until_async(lambda: served.simulator.time_s > take_off_s + 2.0 or trial.done(), timeout_s=PATIENCE_S,
                          what="two vehicle seconds of flight")
        changed = asyncio.get_running_loop().create_future()

        def pilot():
            served.simulator.autopilot.set_mode(FlightMode.LOITER)  # the pilot flips the mode switch
            changed.get_loop().call_soon_threadsafe(changed.set_result, served.simulator.time_s)

        served.loop.call_soon_threadsafe(pilot)
        changed_at = await asyncio.wait_for(changed, timeout=PATIENCE_S)
        outcome = await asyncio.wait_for(trial, timeout=PATIENCE_S)
        return outcome, changed_at, served.simulator.time_s, served.simulator.autopilot.mode

    try:
        outcome, changed_at, ended_at, mode_after = asyncio.run(main())
    finally:
        served.stop()
    assert outcome.outcome is Outcome.PILOT_TAKEOVER and "LOITER" in outcome.message
    assert ended_at - changed_at <= 1.0  # within a vehicle second
    assert mode_after is FlightMode.LOITER  # preland did not switch it back


def test_leaving_the_geofence_lands_and_ends_the_mission(thesis_mission):
    mission = replace(thesis_mission, geofence=GeofenceSpec(max_distance_m=1.5, max_height_m=30.0, action="LAND"))
    outcome = run_trial(TrialRequest(mission=mission, seed=2, record_trajectory=False))
    assert outcome.outcome is Outcome.ABORTED and outcome.message.startswith("geofence:")
    event = next(e for e in outcome.events if e.kind == "geofence")
    assert event.data["action"] == "LAND"
    assert [e.kind for e in outcome.events].count("waypoint") == 0


def test_a_high_fence_does_not_trigger(thesis_mission):
    mission = replace(thesis_mission, geofence=GeofenceSpec(max_distance_m=20.0, max_height_m=15.0))
    assert run_trial(TrialRequest(mission=mission, seed=2, record_trajectory=False)).outcome is Outcome.LANDED




def test_a_field_style_flight_keeps_its_logs_and_records_the_measured_result(short_mission, tmp_path):
    """fly --connect with the detection log, the video and the end-of-flight prompt, against the simulator's face."""
    from typer.testing import CliRunner

    from preland_app.campaign.store import ResultsStore
    from preland_app.cli import app

    mission_path = tmp_path / "mission.yaml"
    text = SHORT_MISSION.read_text()
    mission_path.write_text(text.replace("  mode: normal", "  mode: marker").replace(
        "pad:\n", "params:\n  PLND_ENABLED: 1\n  PLND_TYPE: 1\npad:\n").replace(
        "preset: thesis", "preset: thesis"))
    # In lock-step: the camera renders, detects and records each frame at its vehicle time, so the preflight's
    # frame-rate check (80 % of the camera's rate) holds however loaded the machine is.
    served = ServedSimulator(short_mission, seed=2, paced=True)
    served.simulator.params.set("PLND_ENABLED", 1)
    served.simulator.params.set("PLND_TYPE", 1)
    db, log, video = tmp_path / "field.db", tmp_path / "detections.csv", tmp_path / "flight.mkv"
    try:
        result = CliRunner().invoke(app, [
            "fly", str(mission_path), "--connect", served.url, "--detections-log", str(log), "--record-video",
            str(video), "--record-to", str(db), "--campaign", "field_day", "--scenario", "Marker / none", "--new",
            "--paced", "--json"], input="7.5\n5\n-5.5\n")
    finally:
        served.stop()
    assert result.exit_code == 0, result.output
    assert "recorded field trial 0 of field_day / Marker / none: 7.5 cm" in result.output, result.output
    rows = log.read_text().splitlines()
    assert rows[0].startswith("time_s,markers,chosen_id") and len(rows) > 100
    assert video.stat().st_size > 100_000
    with ResultsStore(db) as store:
        (trial,) = store.trials("field_day")
        assert trial["source"] == "field" and trial["landing_error_cm"] == 7.5 and trial["offset_east_cm"] == -5.5
        assert trial["land_mode"] == "marker"


class _OneMessage:
    """MAVSDK's MavlinkDirect stream, delivering one message and ending."""

    def __init__(self, name: str, fields: dict) -> None:
        from types import SimpleNamespace

        self.message = SimpleNamespace(message_name=name, fields_json=json.dumps(fields), system_id=1,
                                       component_id=1)

    async def subscribe_message(self, name: str):
        yield self.message


class _SteppedClock:
    """Vehicle time that moves only when the test moves it."""

    def __init__(self) -> None:
        self.time_s = 100.0
        self.newest_s = None  # no stamped message read

    def now_s(self) -> float:
        return self.time_s

    def observe(self, vehicle_s: float) -> None:
        pass


def test_a_heartbeat_sent_before_a_mode_change_but_read_after_its_ack_is_no_takeover(monkeypatch):
    """MAVSDK delivers HEARTBEAT and COMMAND_ACK on separate streams, so HEARTBEATs sent before an accepted
    change can arrive after its ACK (seen at 20x as a false "pilot takeover: mode STABILIZE"). They do not
    count; a mode the vehicle really keeps, or a change after the confirmation, does."""
    from preland_app.field.takeover import GuardedVehicle, PilotTakeover
    from preland_app.vehicle.commanded_state import COMMANDED_STATE_GRACE_S
    from preland_app.vehicle.mavlink_backend import MavlinkVehicle

    vehicle = MavlinkVehicle(url="udp://:14550")
    clock = _SteppedClock()
    vehicle._clock = clock

    async def accepted(*params, operation, check=True):
        return None

    monkeypatch.setattr(vehicle, "_command", accepted)
    monkeypatch.setattr(vehicle, "_check_link", lambda operation: None)

    def heartbeat(mode: FlightMode, armed: bool, after_s: float = 0.1):
        """One HEARTBEAT through the backend's own receive path, `after_s` vehicle seconds on."""
        clock.time_s += after_s
        vehicle._direct = _OneMessage("HEARTBEAT", {"custom_mode": mode.value, "base_mode": 128 if armed else 0})
        asyncio.run(vehicle._listen())
        telemetry = asyncio.run(vehicle.telemetry())
        guarded.check(telemetry)
        return telemetry

    guarded = GuardedVehicle(vehicle)
    heartbeat(FlightMode.STABILIZE, False)
    asyncio.run(guarded.set_mode(FlightMode.GUIDED))
    asyncio.run(guarded.arm())
    stale = [heartbeat(FlightMode.STABILIZE, False) for _ in range(10)]  # a vehicle second of late ones
    assert {(t.mode, t.armed) for t in stale} == {(FlightMode.GUIDED, True)}
    confirmed = heartbeat(FlightMode.GUIDED, True)
    assert (confirmed.mode, confirmed.armed) == (FlightMode.GUIDED, True)
    # After the confirmation, another mode is the pilot's at once: PilotTakeover after GuardedVehicle.CONFIRM_S.
    assert heartbeat(FlightMode.LOITER, True).mode is FlightMode.LOITER
    with pytest.raises(PilotTakeover, match="mode LOITER, preland had set GUIDED"):
        heartbeat(FlightMode.LOITER, True, after_s=GuardedVehicle.CONFIRM_S)

    # A change the vehicle never shows is believed for COMMANDED_STATE_GRACE_S only.
    vehicle._commanded_mode = vehicle._commanded_armed = None
    guarded = GuardedVehicle(vehicle)
    heartbeat(FlightMode.STABILIZE, False)
    asyncio.run(guarded.set_mode(FlightMode.GUIDED))
    assert heartbeat(FlightMode.STABILIZE, False, after_s=COMMANDED_STATE_GRACE_S - 0.2).mode is FlightMode.GUIDED
    assert heartbeat(FlightMode.STABILIZE, False, after_s=0.2).mode is FlightMode.STABILIZE
    with pytest.raises(PilotTakeover, match="mode STABILIZE, preland had set GUIDED"):
        heartbeat(FlightMode.STABILIZE, False, after_s=GuardedVehicle.CONFIRM_S)

    # Read late (a backlog on a loaded machine): the clock has run past the grace, but by the stamps read
    # before them the HEARTBEATs were sent before the change: no takeover, until the stamps move on.
    vehicle._commanded_mode = vehicle._commanded_armed = None
    guarded = GuardedVehicle(vehicle)
    clock.newest_s = clock.time_s
    heartbeat(FlightMode.STABILIZE, False)
    asyncio.run(guarded.set_mode(FlightMode.GUIDED))
    late = heartbeat(FlightMode.STABILIZE, False, after_s=COMMANDED_STATE_GRACE_S + 0.5)  # no newer stamp
    assert late.mode is FlightMode.GUIDED
    clock.newest_s = clock.time_s  # the backlog read: the vehicle's stamps are past the grace
    assert heartbeat(FlightMode.STABILIZE, False).mode is FlightMode.STABILIZE
    with pytest.raises(PilotTakeover, match="mode STABILIZE, preland had set GUIDED"):
        heartbeat(FlightMode.STABILIZE, False, after_s=GuardedVehicle.CONFIRM_S)


def test_a_heartbeat_read_after_its_commands_ack_on_the_message_stream_is_believed_however_late(monkeypatch):
    """The message stream carries each COMMAND_ACK in the order the vehicle sent it: HEARTBEATs read before a
    change's ACK there are of the old state however far the clock has run (a backlog of many vehicle seconds
    at 20x), and the first one read after it tells the truth, so a real takeover is seen at once."""
    from preland_app.field.takeover import GuardedVehicle, PilotTakeover
    from preland_app.vehicle.commanded_state import COMMANDED_STATE_GRACE_S, COMMANDED_STATE_LIMIT_S
    from preland_app.vehicle.mavlink_backend import MAV_CMD_DO_SET_MODE, MavlinkVehicle

    vehicle = MavlinkVehicle(url="udp://:14550")
    clock = _SteppedClock()
    vehicle._clock = clock
    returned: dict[int, int] = {}

    async def accepted(command, *params, operation, check=True):
        returned[command] = returned.get(command, 0) + 1
        return returned[command]

    monkeypatch.setattr(vehicle, "_command", accepted)
    monkeypatch.setattr(vehicle, "_check_link", lambda operation: None)

    def read(name: str, fields: dict, after_s: float = 0.1):
        clock.time_s += after_s
        vehicle._direct = _OneMessage(name, fields)
        asyncio.run(vehicle._listen())

    def heartbeat(mode: FlightMode, after_s: float = 0.1):
        read("HEARTBEAT", {"custom_mode": mode.value, "base_mode": 128}, after_s)
        telemetry = asyncio.run(vehicle.telemetry())
        guarded.check(telemetry)
        return telemetry

    def ack(command: int = MAV_CMD_DO_SET_MODE):
        read("COMMAND_ACK", {"command": command, "result": 0}, after_s=0.0)

    guarded = GuardedVehicle(vehicle)
    asyncio.run(guarded.set_mode(FlightMode.GUIDED))
    ack()  # the stream shows ACKs
    assert heartbeat(FlightMode.GUIDED).mode is FlightMode.GUIDED
    asyncio.run(guarded.set_mode(FlightMode.LAND))
    # Its ACK returned, the stream still reads the backlog: well past the time grace, no takeover.
    stale = [heartbeat(FlightMode.GUIDED, after_s=1.0) for _ in range(int(COMMANDED_STATE_GRACE_S) + 3)]
    assert {t.mode for t in stale} == {FlightMode.LAND}
    ack()
    # The next HEARTBEAT was sent after the change: the vehicle is not in LAND, and that is the pilot's.
    assert heartbeat(FlightMode.LOITER).mode is FlightMode.LOITER
    with pytest.raises(PilotTakeover, match="mode LOITER, preland had set LAND"):
        heartbeat(FlightMode.LOITER, after_s=GuardedVehicle.CONFIRM_S)

    # An ACK the stream never shows is waited for COMMANDED_STATE_LIMIT_S at most.
    vehicle._commanded_mode = None
    guarded = GuardedVehicle(vehicle)
    heartbeat(FlightMode.LOITER)
    asyncio.run(guarded.set_mode(FlightMode.GUIDED))
    assert heartbeat(FlightMode.LOITER, after_s=COMMANDED_STATE_LIMIT_S - 0.2).mode is FlightMode.GUIDED
    assert heartbeat(FlightMode.LOITER, after_s=0.2).mode is FlightMode.LOITER


def _vehicle_at_a_frozen_wall_time(monkeypatch, *, rate: float):
    """A MavlinkVehicle on a _SteppedClock at `rate` vehicle s per wall s, with wall time frozen at `now`:
    (vehicle, clock, now)."""
    import time

    from preland_app.vehicle.mavlink_backend import MavlinkVehicle

    vehicle = MavlinkVehicle(url="udp://:14550", link_timeout_s=5.0)
    clock = _SteppedClock()
    clock.rate = rate
    vehicle._clock = clock
    vehicle._direct = _OneMessage("HEARTBEAT", {})
    now = time.monotonic()
    monkeypatch.setattr("preland_app.vehicle.link_watch.time.monotonic", lambda: now)
    return vehicle, clock, now


def test_a_mode_change_waiting_for_its_ack_is_no_takeover_while_a_third_mode_is():
    """Until the vehicle acknowledges a mode change, the mode before it is still preland's: at 10x a LAND
    whose COMMAND_ACK took longer than CONFIRM_S (25 wall ms) was read as "pilot takeover: mode GUIDED,
    preland had set LAND". A mode that is neither is the pilot's, in flight or not; a refused change was
    never preland's."""
    from types import SimpleNamespace

    from preland_app.errors import CommandDenied
    from preland_app.field.takeover import GuardedVehicle, PilotTakeover

    class Vehicle:
        def __init__(self) -> None:
            self.acked = asyncio.Event()
            self.refuse = False

        async def set_mode(self, mode: FlightMode) -> None:
            await self.acked.wait()
            if self.refuse:
                raise CommandDenied(operation="set_mode", reason="MAV_RESULT 2")

    def seen(mode: FlightMode, time_s: float) -> SimpleNamespace:
        return SimpleNamespace(mode=mode, time_s=time_s)

    async def landing_unacknowledged():
        """GUIDED acknowledged, then LAND sent with its ACK not yet in: (vehicle, guarded, the LAND call)."""
        vehicle = Vehicle()
        guarded = GuardedVehicle(vehicle)
        vehicle.acked.set()
        await guarded.set_mode(FlightMode.GUIDED)
        vehicle.acked.clear()
        landing = asyncio.ensure_future(guarded.set_mode(FlightMode.LAND))
        await asyncio.sleep(0)  # the change is sent, its ACK not yet in
        return vehicle, guarded, landing

    async def fly() -> list[str]:
        vehicle, guarded, landing = await landing_unacknowledged()
        said = []
        for step in range(20):  # 2 vehicle s of GUIDED, then of LAND, before the ACK
            guarded.check(seen(FlightMode.GUIDED if step < 10 else FlightMode.LAND, 10.0 + 0.1 * step))
        vehicle.acked.set()
        await landing
        guarded.check(seen(FlightMode.LAND, 12.0))
        said.append(f"landing: {guarded.commanded_modes[-1].name}")
        # After the ACK, the mode before it is no longer preland's.
        guarded.check(seen(FlightMode.GUIDED, 12.1))
        with pytest.raises(PilotTakeover, match="mode GUIDED, preland had set LAND"):
            guarded.check(seen(FlightMode.GUIDED, 12.1 + GuardedVehicle.CONFIRM_S))

        # In flight, a third mode is the pilot's.
        vehicle, guarded, landing = await landing_unacknowledged()
        guarded.check(seen(FlightMode.LOITER, 20.0))
        with pytest.raises(PilotTakeover, match="mode LOITER, preland had set GUIDED"):
            guarded.check(seen(FlightMode.LOITER, 20.0 + GuardedVehicle.CONFIRM_S))
        vehicle.acked.set()
        with pytest.raises(PilotTakeover):
            await landing  # nothing more is sent once the pilot has taken over
        said.append("third mode: taken over")

        # A refused change leaves the mode before it preland's.
        vehicle = Vehicle()
        guarded = GuardedVehicle(vehicle)
        vehicle.acked.set()
        await guarded.set_mode(FlightMode.GUIDED)
        vehicle.refuse = True
        with pytest.raises(CommandDenied):
            await guarded.set_mode(FlightMode.LAND)
        for step in range(10):
            guarded.check(seen(FlightMode.GUIDED, 30.0 + 0.1 * step))
        said.append(f"refused: {guarded.commanded_modes}")
        return said

    assert asyncio.run(fly()) == ["landing: LAND", "third mode: taken over", "refused: [<FlightMode.GUIDED: 4>]"]


def test_a_stall_shorter_than_three_wall_seconds_is_not_a_lost_link(monkeypatch):
    """At 40x, 5 vehicle s of heartbeat silence is 0.125 wall s: a stall of either process that long (or up to
    LINK_LOST_MIN_WALL_S, MAVSDK's own heartbeat timeout) is no lost link; a silence of more than
    LINK_LOST_MIN_WALL_S (and 5 vehicle s) is."""
    from preland_app.errors import LinkLost
    from preland_app.vehicle.link_watch import LINK_LOST_MIN_WALL_S

    assert LINK_LOST_MIN_WALL_S == 3.0
    vehicle, clock, now = _vehicle_at_a_frozen_wall_time(monkeypatch, rate=40.0)
    vehicle._link.last_heartbeat_wall = now - 2.9  # 116 vehicle s at 40x, 2.9 wall s: a stall
    vehicle._check_link("telemetry")
    vehicle._link.last_heartbeat_wall = now - 3.1
    with pytest.raises(LinkLost, match="telemetry.*no heartbeat for 124.0 vehicle s at 40x, nothing heard for 3.1 wall s"):
        vehicle._check_link("telemetry")
    # Up to 5/3x the vehicle seconds alone decide: 3.6 wall s is 5.4 vehicle s at 1.5x, lost.
    vehicle._link.last_heartbeat_wall = now - 3.6
    clock.rate = 1.5
    with pytest.raises(LinkLost, match="no heartbeat for 5.4 vehicle s at 1.5x, nothing heard for 3.6 wall s"):
        vehicle._check_link("telemetry")
    clock.rate = 1.0  # at 1x, 3.6 s of silence is within 5
    vehicle._check_link("telemetry")
    vehicle._link.last_heartbeat_wall = now - 5.1
    with pytest.raises(LinkLost, match="no heartbeat for 5.1 vehicle s at 1x, nothing heard for 5.1 wall s"):
        vehicle._check_link("telemetry")


def test_a_check_run_after_the_tick_that_ends_a_stall_does_not_count_the_stall_as_quiet(monkeypatch):
    """The machine stalls for 3.3 wall s, this process and a served vehicle on it alike, so the vehicle sent
    nothing meanwhile. After it the event loop may run the tick before a check that fell due in the stall
    (their timers' order): quiet is reckoned from the stall's end (a CI run stored a field tutorial's trial as
    "nothing heard for 3.3 wall s"). A vehicle that stays quiet for LINK_LOST_MIN_WALL_S after it is lost."""
    from preland_app.errors import LinkLost

    vehicle, clock, now = _vehicle_at_a_frozen_wall_time(monkeypatch, rate=3.0)
    vehicle._link.loop_ran(now - 3.3)  # the last tick before the stall
    vehicle._link.last_heartbeat_wall = vehicle._link.last_message_wall = now - 3.3
    vehicle._link.loop_ran(now)  # the first one after it
    vehicle._check_link("telemetry")
    for tick in range(1, 32):  # ticking every 0.1 s from then on; the vehicle says nothing
        vehicle._link.loop_ran(now + 0.1 * tick)
    monkeypatch.setattr("preland_app.vehicle.link_watch.time.monotonic", lambda: now + 2.9)
    vehicle._check_link("telemetry")
    monkeypatch.setattr("preland_app.vehicle.link_watch.time.monotonic", lambda: now + 3.1)
    with pytest.raises(LinkLost, match="no heartbeat for 19.2 vehicle s at 3x, nothing heard for 3.1 wall s"):
        vehicle._check_link("telemetry")


def test_a_stall_of_preland_itself_is_no_lost_link_until_it_has_read_what_came_meanwhile(thesis_mission):
    """The companion's own event loop blocked for longer than LINK_LOST_MIN_WALL_S (a loaded machine): the
    vehicle's messages of meanwhile are waiting unread, so the link is not judged until they are read.
    (A CI run on a loaded machine stored a stand-in SITL trial as "set_param: no heartbeat for 9.3 vehicle s".)
    A vehicle that really goes quiet is still lost."""
    import time

    from preland_app.errors import LinkLost
    from preland_app.vehicle.link_watch import LINK_LOST_MIN_WALL_S
    from preland_app.vehicle.mavlink_backend import MavlinkVehicle

    served = ServedSimulator(thesis_mission, seed=1, speedup=10.0)

    async def stall_then_go_quiet() -> list[str]:
        vehicle = MavlinkVehicle(url=served.url, link_timeout_s=5.0)
        said = []
        try:
            await vehicle.connect()
            await until_async(lambda: vehicle._link.loop_ran_wall is not None and vehicle._clock.settled,
                              timeout_s=PATIENCE_S, what="the link's clock to settle")
            # The stall: this thread (the event loop's) blocks, reading nothing, until by the old rule the link
            # would be lost (more than 5 vehicle s flown and LINK_LOST_MIN_WALL_S passed since the last HEARTBEAT).
            stalled_at_s = served.simulator.time_s
            until(lambda: served.simulator.time_s - stalled_at_s > vehicle.link_timeout_s + 1.0
                  and time.monotonic() - vehicle._link.last_heartbeat_wall > LINK_LOST_MIN_WALL_S + 0.2,
                  timeout_s=PATIENCE_S, what="the vehicle to fly on through the stall")
            vehicle._check_link("telemetry")
            said.append("stalled: no verdict")
            await until_async(lambda: time.monotonic() - vehicle._link.last_heartbeat_wall < 1.0, timeout_s=PATIENCE_S,
                              what="the HEARTBEATs of the stall to be read")
            vehicle._check_link("telemetry")
            said.append("read: linked")
            served.stop()  # the vehicle goes quiet for good
            lost: list[LinkLost] = []

            def judged_lost() -> bool:
                try:
                    vehicle._check_link("telemetry")
                except LinkLost as error:
                    lost.append(error)
                return bool(lost)

            await until_async(judged_lost, timeout_s=PATIENCE_S, what="the quiet link to be judged lost")
            said.append(f"quiet: {lost[0].operation}")
        finally:
            await vehicle.close()
        return said

    try:
        assert asyncio.run(stall_then_go_quiet()) == ["stalled: no verdict", "read: linked", "quiet: telemetry"]
    finally:
        served.stop()


class _Messages:
    """What MAVSDK's message stream gives the backend: these (name, fields) messages of the vehicle, in order."""

    def __init__(self, messages) -> None:
        from types import SimpleNamespace

        self.messages = [SimpleNamespace(message_name=name, fields_json=json.dumps(fields), system_id=1,
                                         component_id=1) for name, fields in messages]

    async def subscribe_message(self, name: str):
        for message in self.messages:
            yield message


def _read(vehicle, *messages) -> None:
    """The messages through the backend's own receive path."""
    vehicle._direct = _Messages(messages)
    asyncio.run(vehicle._listen())


def _attitudes(first_ms: int, last_ms: int) -> list:
    """ATTITUDE at 10 Hz, stamped `first_ms` to `last_ms` (time_boot_ms)."""
    return [("ATTITUDE", {"time_boot_ms": ms}) for ms in range(first_ms, last_ms + 1, 100)]


def _stamped_vehicle(monkeypatch):
    vehicle, clock, now = _vehicle_at_a_frozen_wall_time(monkeypatch, rate=8.0)
    clock.observe = lambda vehicle_s: setattr(clock, "newest_s", vehicle_s)  # the newest stamp read
    return vehicle


def test_a_vehicle_that_talks_without_heartbeats_has_lost_its_link_by_its_own_stamps(monkeypatch):
    """Heartbeats stop while stamped messages keep coming: lost after 5 vehicle s by the vehicle's stamps, at
    a wall time that has not moved (within the 3 wall s that a wholly quiet link is given)."""
    from preland_app.errors import LinkLost

    vehicle = _stamped_vehicle(monkeypatch)
    _read(vehicle, ("ATTITUDE", {"time_boot_ms": 100_000}), ("HEARTBEAT", {}), *_attitudes(100_100, 104_900))
    vehicle._check_link("telemetry")  # the vehicle has counted 4.9 s since its last heartbeat: not yet
    _read(vehicle, *_attitudes(105_000, 105_200))
    with pytest.raises(LinkLost, match="telemetry.*no heartbeat for 5.2 vehicle s by the stamps of its other messages"):
        vehicle._check_link("telemetry")


def test_vehicle_time_whose_messages_were_lost_counts_as_no_talk_without_heartbeats(monkeypatch):
    """A starved process's UDP receive buffer overflows: what the vehicle sent meanwhile is lost, its heartbeats
    with the rest, and the stamps read jump (here 8.4 vehicle s: 0.84 wall s at 10x). That is no vehicle heard
    talking without heartbeats; one heard doing so after the gap still loses its link after 5 s of it."""
    from preland_app.errors import LinkLost

    vehicle = _stamped_vehicle(monkeypatch)
    _read(vehicle, ("ATTITUDE", {"time_boot_ms": 100_000}), ("HEARTBEAT", {}), *_attitudes(100_100, 100_500))
    _read(vehicle, *_attitudes(108_900, 109_000))  # the first messages after the gap, before a heartbeat
    vehicle._check_link("telemetry")
    _read(vehicle, ("HEARTBEAT", {}), *_attitudes(109_100, 113_900))
    vehicle._check_link("telemetry")  # 4.9 s heard since that heartbeat
    _read(vehicle, *_attitudes(114_000, 114_200))
    with pytest.raises(LinkLost, match="telemetry.*no heartbeat for 5.2 vehicle s by the stamps of its other messages"):
        vehicle._check_link("telemetry")
    # Steps of up to HEARD_STEP_MAX_S (1 s) are heard time: a slow stream, a few messages lost.
    vehicle = _stamped_vehicle(monkeypatch)
    _read(vehicle, ("ATTITUDE", {"time_boot_ms": 100_000}), ("HEARTBEAT", {}),
          *[("ATTITUDE", {"time_boot_ms": 100_000 + 1000 * k}) for k in range(1, 6)])
    vehicle._check_link("telemetry")  # five 1 s steps: 5.0 s, not more
    _read(vehicle, ("ATTITUDE", {"time_boot_ms": 105_200}))
    with pytest.raises(LinkLost, match="no heartbeat for 5.2 vehicle s"):
        vehicle._check_link("telemetry")


class _CountedSdk:
    """What close() needs of MAVSDK's instance: a synchronous destroy, counted."""

    def __init__(self) -> None:
        self.destroyed = 0

    def destroy(self) -> None:
        self.destroyed += 1


def test_closing_destroys_mavsdk_even_when_it_fails_or_is_cancelled():
    """MAVSDK is destroyed by close() itself, never left to the garbage collector: when closing works, when a
    step of it fails, and when it is cancelled while a task will not end."""
    from preland_app.vehicle.mavlink_backend import MavlinkVehicle

    async def close_with(trouble: str) -> _CountedSdk:
        vehicle = MavlinkVehicle(url="udp://:14550")
        sdk = vehicle._sdk = _CountedSdk()
        if trouble == "a failing log":
            class _Log:
                def close(self):
                    raise OSError("disk full")

            vehicle.tlog = _Log()
            with pytest.raises(OSError, match="disk full"):
                await vehicle.close()
        elif trouble == "a task that will not end":
            async def stubborn() -> None:
                try:
                    await asyncio.Event().wait()
                except asyncio.CancelledError:
                    await asyncio.Event().wait()  # ignores the cancel: close() waits here until cancelled

            vehicle._tasks.append(asyncio.ensure_future(stubborn()))
            await asyncio.sleep(0)
            with pytest.raises(TimeoutError):
                await asyncio.wait_for(vehicle.close(), timeout=0.2)
        else:
            await vehicle.close()
        assert vehicle._sdk is None and not vehicle.connected
        return sdk

    for trouble in ("nothing", "a failing log", "a task that will not end"):
        assert asyncio.run(close_with(trouble)).destroyed == 1, trouble


def test_a_connect_that_fails_destroys_mavsdk_itself(monkeypatch):
    """No autopilot answers: connect() raises LinkLost naming the wait, and the MAVSDK instance it made is
    already destroyed (a real MAVSDK: its own register of live instances no longer holds it), so nothing is
    left for the garbage collector to destroy in whatever thread it runs."""
    import mavsdk.asyncio.mavsdk as mavsdk_asyncio
    from mavsdk import mavsdk as mavsdk_core

    from preland_app.errors import LinkLost
    from preland_app.vehicle.mavlink_backend import MavlinkVehicle

    made = []

    class Recorded(mavsdk_asyncio.Mavsdk):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            made.append(self)

    monkeypatch.setattr(mavsdk_asyncio, "Mavsdk", Recorded)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as silent:  # bound, never answers
        silent.bind(("127.0.0.1", 0))
        vehicle = MavlinkVehicle(url=f"udpout://127.0.0.1:{silent.getsockname()[1]}", connect_timeout_s=0.5)

        async def connect() -> None:
            with pytest.raises(LinkLost, match="no autopilot on .* within 0.5 s"):
                await vehicle.connect()

        asyncio.run(connect())
    (sdk,) = made
    assert vehicle._sdk is None and not vehicle.connected
    assert sdk._mavsdk._handle is None and sdk._mavsdk not in mavsdk_core._live_instances


def test_the_vehicle_rate_is_not_bent_by_a_backlog_read_after_a_stall(monkeypatch):
    """At 10x: messages every 10 wall ms, then 3.2 wall s with nothing read (the companion's loop stalled),
    then the 32 vehicle s sent meanwhile read within 20 wall ms, then fresh ones again. The rate stays
    10x throughout (measured across the backlog it read 0.02x, then 60x)."""
    import time

    from preland_app.vehicle.vehicle_time_clock import VehicleTimeClock

    wall = [1000.0]
    monkeypatch.setattr("preland_app.vehicle.vehicle_time_clock.time.monotonic", lambda: wall[0])
    clock = VehicleTimeClock()
    vehicle_s, rates = 50.0, []

    def read(at_wall_s: float, at_vehicle_s: float) -> None:
        wall[0] = at_wall_s
        clock.observe(at_vehicle_s)
        rates.append(clock.rate)

    for i in range(400):  # 4 wall s at 10x
        read(1000.0 + 0.01 * i, vehicle_s + 0.1 * i)
    assert clock.rate == pytest.approx(10.0) and clock.settled
    stalled_wall_s, stalled_vehicle_s = 1004.0, vehicle_s + 40.0
    rates.clear()
    for i in range(320):  # the backlog: sent over 3.2 wall s, read in 20 ms after the stall
        read(stalled_wall_s + 3.2 + 0.02 * i / 320, stalled_vehicle_s + 0.1 * i)
    for i in range(500):  # fresh again, 5 wall s
        read(stalled_wall_s + 3.22 + 0.01 * i, stalled_vehicle_s + 32.0 + 0.1 * i)
    assert min(rates) == pytest.approx(10.0, rel=0.05) and max(rates) == pytest.approx(10.0, rel=0.05)
    assert clock.now_s() == pytest.approx(stalled_vehicle_s + 32.0 + 49.9)
    assert time.monotonic() == wall[0]

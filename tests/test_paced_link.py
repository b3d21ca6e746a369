"""Paced flight when the companion's own side of the link fails: a grant MAVSDK refuses to send is sent
again, and a task that reads or writes the link and stops ends the trial at once, named."""

import asyncio

from mavsdk.plugins.mavlink_direct import MavlinkDirectError, MavlinkDirectResult

from preland_app.outcome import Outcome
from preland_app.runtime.embedded import TrialRequest
from preland_app.runtime.mavlink import fly_mavlink
from preland_app.vehicle import mavlink_backend, paced_clock
from preland_app.vehicle.mavlink_backend import MavlinkVehicle

from .test_mavlink_runtime import PATIENCE_S, ServedSimulator


def pace(vehicle, flight) -> None:
    """Run `flight()` (sleeps on the vehicle's paced clock) with the vehicle's grant sender running, from the
    clock's start at 1 s; the sender is stopped after it."""

    async def main():
        vehicle._background(vehicle._pace_sender(), "pace")
        vehicle.clock.start(1.0)
        try:
            await asyncio.wait_for(flight(), timeout=PATIENCE_S)
        finally:
            vehicle._closed = True
            for task in vehicle._tasks:
                task.cancel()

    asyncio.run(main())


def test_a_grant_mavsdk_refuses_is_sent_again():
    vehicle = MavlinkVehicle(url="udpout://127.0.0.1:9", paced=True)
    clock = vehicle.clock
    tries: list[int] = []

    async def send_now(name, fields, *, targeted=True):
        tries.append(fields["time_boot_ms"])
        if len(tries) <= 2:  # MAVSDK's link is down for the first two sends
            raise MavlinkDirectError(MavlinkDirectResult.CONNECTION_ERROR, "send_message()", None)
        asyncio.get_running_loop().call_soon(clock.held, fields["time_boot_ms"] / 1000)

    vehicle._send_now = send_now
    pace(vehicle, lambda: clock.sleep(0.5))
    # The start's grant, then the sleep's (the newest wanted is what goes), refused; sent again
    # PACE_RESEND_WALL_S later, then answered.
    assert tries == [1000, 1500, 1500]
    assert clock.now_s() == 1.5 and vehicle._failure is None


def test_an_answer_to_an_earlier_grant_does_not_stop_a_lost_grant_being_sent_again():
    # The simulator's answer to one grant crosses the next grant, which is lost on the way (a full socket
    # buffer on a loaded machine). The answer says nothing about the later grant: it must be sent again.
    vehicle = MavlinkVehicle(url="udpout://127.0.0.1:9", paced=True)
    clock = vehicle.clock
    clock.answer_timeout_wall_s = 10.0
    received, held_back = [], []

    async def send_now(name, fields, *, targeted=True):
        time_ms = fields["time_boot_ms"]
        if time_ms == 2000 and -2000 not in received:
            received.append(-2000)  # lost
            asyncio.get_running_loop().call_soon(clock.held, held_back.pop() / 1000)  # the crossing answer
            return
        received.append(time_ms)
        if time_ms == 1500:
            held_back.append(time_ms)  # answered only once the next grant has left
        else:
            asyncio.get_running_loop().call_soon(clock.held, time_ms / 1000)

    vehicle._send_now = send_now

    async def flight():
        first = asyncio.ensure_future(clock.sleep(0.5))
        await asyncio.sleep(0.05)
        first.cancel()  # a wait that gave up: the earliest deadline is now the next sleeper's
        await clock.sleep(1.0)

    pace(vehicle, flight)
    assert received == [1000, 1500, -2000, 2000]
    assert clock.now_s() == 2.0


def test_a_listener_that_stops_ends_the_paced_trial_at_once_as_link_lost(short_mission, monkeypatch):
    served = ServedSimulator(short_mission, seed=4, paced=True)
    confirms = mavlink_backend.MavlinkVehicle._heartbeat_confirms
    heartbeats = []

    def failing_confirms(self, fields):
        heartbeats.append(fields)
        if len(heartbeats) == 8:
            raise RuntimeError("a message the listener cannot take")
        confirms(self, fields)

    monkeypatch.setattr(mavlink_backend.MavlinkVehicle, "_heartbeat_confirms", failing_confirms)
    # With the wall bound out of reach, only the listener's stop can end the trial in time.
    monkeypatch.setattr(paced_clock, "PACE_ANSWER_WALL_S", 10 * PATIENCE_S)
    try:
        outcome = asyncio.run(asyncio.wait_for(
            fly_mavlink(TrialRequest(mission=short_mission, seed=4, land_mode="irlock"), url=served.url,
                        paced=True), timeout=PATIENCE_S))
    finally:
        served.stop()
    assert len(heartbeats) == 8
    assert outcome.outcome is Outcome.LINK_LOST
    assert "mavlink-listen stopped: RuntimeError: a message the listener cannot take" in outcome.message

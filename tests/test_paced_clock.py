"""PacedClock: time passes only as the simulator answers the companion's grants, granted only when every
task waits; checked against a stand-in simulator that holds where it is told (no MAVLink)."""

import asyncio

import pytest

from preland_app.clock import join
from preland_app.errors import LinkLost
from preland_app.vehicle.paced_clock import PacedClock

DT_S = 0.01


class Simulator:
    """Steps in DT_S to each grant, then answers where it holds (as the MAVLink face does)."""

    def __init__(self) -> None:
        self.time_s = 1.0  # running for a second when the companion starts pacing it
        self.grants: list[int] = []
        self.clock = PacedClock(grant=self.grant)

    def grant(self, time_ms: int) -> None:
        self.grants.append(time_ms)
        if time_ms == 0:
            return
        while self.time_s < time_ms / 1000 - 1e-9:
            self.time_s = round(self.time_s + DT_S, 6)
        asyncio.get_running_loop().call_soon(self.clock.held, self.time_s)


def run(main):
    return asyncio.run(asyncio.wait_for(main(), timeout=30))


def test_sleepers_wake_at_their_deadlines_in_order():
    sim = Simulator()
    woken = []

    async def sleeper(name, duration_s):
        await sim.clock.sleep(duration_s)
        woken.append((name, sim.clock.now_s()))

    async def main():
        sim.clock.start(1.0)
        await asyncio.sleep(0)  # the simulator's first answer: it holds where it is
        await asyncio.gather(sleeper("b", 0.5), sleeper("a", 0.25), sleeper("c", 0.505))

    run(main)
    assert woken == [("a", 1.25), ("b", 1.5), ("c", 1.51)]  # c: the first step at or after its deadline
    assert sim.grants == [1000, 1250, 1500, 1505]  # each the earliest deadline; never past one


def test_no_time_is_granted_while_a_sensor_task_works_or_an_exchange_is_under_way():
    sim = Simulator()
    seen = {}

    async def sensor():
        join(sim.clock)
        await sim.clock.sleep(0.1)
        seen["reading_s"] = sim.clock.now_s()
        await asyncio.sleep(0.05)  # detecting a frame in wall time: the vehicle must wait
        seen["after_work_s"] = sim.clock.now_s()
        await sim.clock.sleep(0.1)

    async def mission():
        await sim.clock.sleep(0.15)  # would run the vehicle on while the sensor works
        seen["mission_s"] = sim.clock.now_s()
        with sim.clock.holding():
            await asyncio.sleep(0.05)  # a command and its COMMAND_ACK
            seen["held_s"] = sim.clock.now_s()

    async def main():
        sim.clock.start(1.0)
        await asyncio.sleep(0)
        await asyncio.gather(sensor(), mission())

    run(main)
    assert seen["reading_s"] == 1.1 and seen["after_work_s"] == 1.1
    assert seen["mission_s"] == 1.15 and seen["held_s"] == 1.15
    assert max(sim.grants) == 1200


def test_a_simulator_that_stops_answering_is_a_lost_link_after_the_wall_bound():
    clock = PacedClock(grant=lambda time_ms: None, answer_timeout_wall_s=0.2)

    async def main():
        clock.start(1.0)
        await clock.sleep(0.1)

    with pytest.raises(LinkLost, match="did not answer PRELAND_PACE"):
        run(main)


def test_release_lets_the_simulator_go_and_sleeps_no_longer_wait():
    sim = Simulator()

    async def main():
        sim.clock.start(1.0)
        await sim.clock.sleep(0.02)
        sim.clock.release()
        await sim.clock.sleep(100.0)  # not paced any more: returns at once

    run(main)
    assert sim.grants[-1] == 0 and sim.clock.now_s() == 1.02


def test_a_sensor_task_that_waits_for_something_else_is_named_when_time_cannot_pass():
    from preland_app.errors import WaitTimeout

    sim = Simulator()
    sim.clock.answer_timeout_wall_s = 0.2
    never = asyncio.Event()

    async def reader():
        join(sim.clock)
        await sim.clock.sleep(0.1)
        await never.wait()  # joined, then waiting for something that is not the clock: time stands still

    async def main():
        sim.clock.start(1.0)
        task = asyncio.ensure_future(reader())
        task.set_name("camera-reader")
        try:
            await sim.clock.sleep(1.0)
        finally:
            task.cancel()

    with pytest.raises(WaitTimeout, match="camera-reader hold the vehicle's time"):
        run(main)


def test_a_failed_link_ends_every_sleep_at_once_naming_it():
    sim = Simulator()
    sim.clock.answer_timeout_wall_s = 600.0  # the wall bound must not be what ends the sleeps
    ended = []

    async def sleeper(duration_s):
        try:
            await sim.clock.sleep(duration_s)
        except LinkLost as error:
            ended.append(str(error))

    async def main():
        sim.clock.start(1.0)
        await asyncio.sleep(0)
        sim.grant = lambda time_ms: None  # the simulator stops answering: both sleepers stay asleep
        sim.clock._grant = sim.grant
        sleepers = [asyncio.ensure_future(sleeper(d)) for d in (0.5, 2.0)]
        await asyncio.sleep(0)
        sim.clock.fail(operation="mavlink-listen", reason="mavlink-listen stopped: RuntimeError: boom")
        await asyncio.gather(*sleepers)
        await sleeper(0.1)  # and a sleep begun afterwards

    run(main)
    assert ended == ["mavlink-listen: mavlink-listen stopped: RuntimeError: boom"] * 3


def test_an_unanswered_grant_is_reported_with_what_the_sender_knows():
    clock = PacedClock(grant=lambda time_ms: None, answer_timeout_wall_s=0.2,
                       explain=lambda: "that grant sent 3 times")

    async def main():
        clock.start(1.0)
        await clock.sleep(0.1)

    with pytest.raises(LinkLost, match=r"held at 1000 ms, granted 1100 ms; that grant sent 3 times"):
        run(main)


def test_an_answer_far_past_every_grant_is_another_vehicles_and_ends_the_link():
    # A vehicle still sending to a port its companion closed reaches the companion the system gave that port
    # next; this companion's grants then reach it too, and it answers from its own time (here 171 s).
    sim = Simulator()
    sim.clock.answer_timeout_wall_s = 600.0
    outcome = {}

    async def main():
        sim.clock.start(1.0)
        await asyncio.sleep(0)  # the own simulator's first answer
        await sim.clock.sleep(0.25)
        outcome["before"] = sim.clock.now_s()
        sim.clock.held(1.25)  # a second answer at the time already held: the same vehicle, no harm
        asyncio.get_running_loop().call_soon(sim.clock.held, 171.0)
        try:
            await sim.clock.sleep(0.25)
        except LinkLost as error:
            outcome["error"] = str(error)
        outcome["after"] = sim.clock.now_s()

    run(main)
    assert outcome["before"] == 1.25 and outcome["after"] == 1.25  # the other vehicle's time never counted
    assert outcome["error"] == ("paced clock: an answer holding at 171.000 s, past the 1250 ms granted and the "
                                "1.250 s held: another vehicle answers on this companion's port")


def test_a_first_answer_past_the_grant_is_where_a_free_running_simulator_holds():
    sim = Simulator()
    sim.time_s = 40.0  # a simulator that ran free for 40 s before this companion paced it

    async def main():
        sim.clock.held(0.5)  # an answer read before this companion started pacing (to whoever paced before)
        sim.clock.start(1.0)
        await asyncio.sleep(0)
        await sim.clock.sleep(0.5)

    run(main)
    assert sim.clock.now_s() == 40.5 and sim.grants == [1000, 40500]

"""Lock-step SITL on preland's physics, without SITL: a thread plays SITL on the bridge (a servo packet,
the answer, the next), the companion's clock is a `LockstepClock` on the bridge's gate."""

import asyncio
import collections
import math
import threading
import types

from preland_app.sim.json_bridge import JsonBridge
from preland_app.sim.multirotor import QuadXFrame, QuadXMultirotor
from preland_app.sim.sensor_smoothing import SensorSmoothing
from preland_app.sim.sitl_json import build_servo_packet
from preland_app.sim.step_gate import StepGate
from preland_app.vehicle.lockstep_clock import LockstepClock

from .waiting import until, until_async

FRAME_RATE_HZ = 1200  # ArduCopter SITL's physics rate


def _play_sitl(bridge: JsonBridge, stop: threading.Event) -> threading.Thread:
    pwm = [round(QuadXFrame().hover_pwm_us()) - 50] * 4 + [0] * 12

    def run() -> None:
        frame = 0
        while not stop.is_set():
            bridge.handle(build_servo_packet(frame_rate_hz=FRAME_RATE_HZ, frame_count=frame, pwm_us=pwm))
            frame += 1

    thread = threading.Thread(target=run, name="sitl-stand-in", daemon=True)
    thread.start()
    return thread


def test_a_reading_shows_the_physics_at_its_tick_and_the_physics_waits_while_it_is_made():
    bridge = JsonBridge(model=QuadXMultirotor(frame=QuadXFrame()), port=0)
    stop = threading.Event()
    period_s = 1.0 / 15.0  # the camera's frame period
    seen: list[tuple[int, float, float]] = []

    async def camera(clock: LockstepClock) -> None:
        clock.join()
        for _ in range(30):
            tick = math.floor(clock.now_s() / period_s) + 1  # the next frame's tick
            await clock.sleep(tick * period_s - clock.now_s())
            at_wake_s = bridge.latest_state.time_s
            # A detection that lasts until the physics thread stands at the hold, however loaded the
            # machine: the physics must not move meanwhile.
            await asyncio.get_running_loop().run_in_executor(
                None, lambda: until(lambda: bridge.gate.waiting, timeout_s=30, what="the physics at the hold"))
            seen.append((tick, at_wake_s, bridge.latest_state.time_s))

    async def mission(clock: LockstepClock) -> None:
        end_s = clock.now_s() + 2.0
        while clock.now_s() < end_s:  # another task's waits only add deadlines
            await clock.sleep(0.1)

    async def main() -> None:
        clock = LockstepClock(gate=bridge.gate, stall_wall_s=30.0)
        await asyncio.wait_for(asyncio.gather(camera(clock), mission(clock)), timeout=60)

    player = _play_sitl(bridge, stop)
    try:
        asyncio.run(main())
    finally:
        stop.set()
        bridge.gate.hold_at(None)
        player.join(5)
        bridge.stop()
    step_s = 1.0 / FRAME_RATE_HZ
    assert len(seen) == 30
    for tick, at_wake_s, after_detection_s in seen:
        assert tick * period_s <= at_wake_s < tick * period_s + step_s + 1e-9, (tick, at_wake_s)
        assert after_detection_s == at_wake_s  # held while the frame was processed
    assert bridge.counters.holds >= 30


def test_a_task_that_joins_holds_the_physics_before_it_reads_the_time():
    """The physics runs free until a sensor task joins; from the join on it must stand still, before the
    task picks its first reading's time from the clock (else a loaded machine makes that reading late)."""
    gate = StepGate()
    gate.stepped(0.1325)  # where a free-running physics happens to be

    async def sensor() -> tuple[float | None, float]:
        clock = LockstepClock(gate=gate, stall_wall_s=30.0)
        clock.join()
        return gate.hold_at_s, clock.now_s()

    hold_s, now_s = asyncio.run(sensor())
    assert hold_s == now_s == 0.1325
    assert gate.held()


def test_smoothed_sensors_tell_a_levelling_touchdown_as_a_rotation():
    """The ground levels a tilted vehicle in one step; SITL is told a gyro rate that turns it there
    within a few time constants, not a jump its gyro never saw."""
    from dataclasses import replace

    state = QuadXMultirotor(frame=QuadXFrame()).state
    smoothing = SensorSmoothing()
    tilted = math.radians(6.0)
    smoothing.smoothed(replace(state, quaternion_wxyz=(math.cos(tilted / 2), math.sin(tilted / 2), 0.0, 0.0)))
    roll_rates = []
    for k in range(1, 600):  # then the ground holds it level for half a second
        told = smoothing.smoothed(replace(state, time_s=k * 0.001))
        roll_rates.append(told.gyro_frd_rad_s[0])
    assert min(roll_rates) < -0.5  # told it rolls back towards level
    assert abs(roll_rates[-1]) < 0.01  # and has stopped there
    assert abs(told.velocity_ned_m_s[2]) < 0.01


def _run_on_played_bridge(main_factory, *, bridge: JsonBridge | None = None, player=_play_sitl) -> JsonBridge:
    """Run `main_factory(bridge)` while `player(bridge, stop)` plays SITL on the bridge."""
    bridge = bridge or JsonBridge(model=QuadXMultirotor(frame=QuadXFrame()), port=0)
    # Held from its first step, as a trial's physics is by the time its mission sleeps: a deadline taken while
    # the physics runs free may be passed mid-step before the clock holds it, and without `activity` a wake
    # does not wait for the physics to stand, so what a task reads at its wake could still move by a step.
    bridge.gate.hold_at(0.0)
    stop = threading.Event()
    thread = player(bridge, stop)
    try:
        asyncio.run(asyncio.wait_for(main_factory(bridge), timeout=60))
    finally:
        stop.set()
        bridge.gate.hold_at(None)
        thread.join(5)
        bridge.stop()
    return bridge


def test_a_message_sent_holds_the_physics_until_mavsdk_has_had_time_to_send_it(monkeypatch):
    """MAVSDK sends from a thread of its own: a message handed to it while the physics stands at a wake must
    be in SITL's socket before SITL's next step, so the physics waits DELIVERY_WALL_S, even for a task that
    reads no sensor and while another task's deadline lies ahead."""
    import preland_app.vehicle.lockstep_clock as lockstep_clock

    monkeypatch.setattr(lockstep_clock, "DELIVERY_WALL_S", 0.3)  # long enough to see the physics stand
    seen: dict[str, object] = {}

    async def main(bridge: JsonBridge) -> None:
        clock = LockstepClock(gate=bridge.gate, stall_wall_s=30.0)

        async def mission() -> None:
            await clock.sleep(1.0)  # a deadline ahead, that the physics would otherwise run to

        async def sender() -> None:
            await clock.sleep(0.05)
            seen["woken_s"] = bridge.latest_state.time_s
            await clock.sent()
            seen["sent_s"] = bridge.latest_state.time_s

        await asyncio.gather(mission(), sender())

    _run_on_played_bridge(main)
    assert seen["sent_s"] == seen["woken_s"]  # over 0.3 wall s, with the physics free to run 0.95 vehicle s


def test_an_exchange_whose_request_reaches_sitl_late_runs_time_once_it_has(monkeypatch):
    """The relay passes a request on to SITL from its own thread and tells no one: while the request is not
    in SITL's socket the physics stands, and once it is, time runs for the answer, however late that was
    (a loaded machine: after EXCHANGE_DELIVERY_WALL_S, here 0), with nothing else here happening meanwhile."""
    import preland_app.vehicle.lockstep_clock as lockstep_clock

    monkeypatch.setattr(lockstep_clock, "EXCHANGE_DELIVERY_WALL_S", 0.0)
    monkeypatch.setattr(lockstep_clock, "RELAYED_MAX_WALL_S", 60.0)  # only the relay's count lets time run
    monkeypatch.setattr(lockstep_clock, "LOOK_WALL_S", 60.0)  # and the clock sees it when the relay tells it
    relay = types.SimpleNamespace(to_sitl=collections.Counter(), on_pass=None)
    seen: dict[str, float] = {}

    def relay_passes(key: str) -> None:  # as the relay's thread does: count, then tell
        relay.to_sitl.update([key])
        relay.on_pass()

    async def main(bridge: JsonBridge) -> None:
        clock = LockstepClock(gate=bridge.gate, stall_wall_s=30.0, relay=relay)
        loop = asyncio.get_running_loop()

        async def mission() -> None:
            await clock.sleep(5.0)

        async def commander() -> None:
            await clock.sleep(0.1)
            with clock.exchanging(answered=lambda: False, sends="COMMAND_LONG"):
                seen["asked_s"] = clock.now_s()
                await loop.run_in_executor(None, lambda: until(lambda: bridge.gate.waiting, timeout_s=30,
                                                               what="the physics at the hold"))
                seen["held_s"] = clock.now_s()
                await loop.run_in_executor(None, relay_passes, "COMMAND_LONG")
                await until_async(lambda: clock.now_s() >= seen["asked_s"] + 0.05, timeout_s=20,
                                  what="time to run once the request is in SITL's socket")

        await asyncio.gather(mission(), commander())

    _run_on_played_bridge(main)
    assert seen["held_s"] == seen["asked_s"]


def test_a_physics_this_clock_holds_for_too_long_is_not_called_a_silent_sitl(monkeypatch):
    """SITL's packet is in and this clock holds it (a request never relayed): the stall names the hold, not a
    SITL that sent nothing."""
    import preland_app.vehicle.lockstep_clock as lockstep_clock
    from preland_app.errors import WaitTimeout

    monkeypatch.setattr(lockstep_clock, "EXCHANGE_DELIVERY_WALL_S", 0.0)
    monkeypatch.setattr(lockstep_clock, "RELAYED_MAX_WALL_S", 60.0)
    relay = types.SimpleNamespace(to_sitl=collections.Counter(), on_pass=None)
    raised: list[BaseException] = []

    async def main(bridge: JsonBridge) -> None:
        clock = LockstepClock(gate=bridge.gate, stall_wall_s=1.0, relay=relay)

        async def mission() -> None:
            try:
                await clock.sleep(5.0)
            except WaitTimeout as error:
                raised.append(error)

        async def commander() -> None:
            await clock.sleep(0.1)
            with clock.exchanging(answered=lambda: False, sends="COMMAND_LONG"):
                await until_async(lambda: raised, timeout_s=30, what="the mission's sleep to end")

        await asyncio.gather(mission(), commander())

    _run_on_played_bridge(main)
    assert "with SITL's packet in, held by this clock (0 messages being sent, 1 exchanges" in str(raised[0])


def test_an_exchange_runs_time_until_its_answer_is_read_then_holds_until_it_ends(monkeypatch):
    """SITL answers only as time passes, so an exchange steps time on; once the answer is read off the link
    the physics stands until the waiting task has it, however long that takes in wall time."""
    import preland_app.vehicle.lockstep_clock as lockstep_clock

    monkeypatch.setattr(lockstep_clock, "EXCHANGE_DELIVERY_WALL_S", 0.0)
    seen: dict[str, float] = {}

    async def main(bridge: JsonBridge) -> None:
        clock = LockstepClock(gate=bridge.gate, stall_wall_s=30.0)
        answered = False

        async def mission() -> None:
            await clock.sleep(5.0)

        async def commander() -> None:
            nonlocal answered
            await clock.sleep(0.1)
            with clock.exchanging(answered=lambda: answered):
                start_s = clock.now_s()
                await until_async(lambda: clock.now_s() >= start_s + 0.05, timeout_s=30,
                                  what="time to run in the exchange while no answer has come")
                answered = True
                clock._apply()  # the hold, as the clock's next look (a wake after the answer's step) sets it
                # At that hold: the physics may still wait at the one before, which the hold just moved from.
                await asyncio.get_running_loop().run_in_executor(
                    None, lambda: until(lambda: bridge.gate.waiting and bridge.gate.held(), timeout_s=30,
                                        what="the physics at the hold"))
                seen["answered_s"] = clock.now_s()
                await asyncio.sleep(0.2)  # the answer on its way to the task, in wall time
                seen["before_end_s"] = clock.now_s()
            await clock.sleep(0.01)
            seen["after_end_s"] = clock.now_s()

        await asyncio.gather(mission(), commander())

    _run_on_played_bridge(main)
    assert seen["answered_s"] >= 0.15
    assert seen["before_end_s"] == seen["answered_s"]
    assert seen["after_end_s"] > seen["answered_s"]


def test_the_receive_queue_of_a_udp_socket_is_read_from_the_kernel():
    import socket

    from preland_app.vehicle.lockstep_clock import udp_receive_queue

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as bound, \
            socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
        bound.bind(("127.0.0.1", 0))
        port = bound.getsockname()[1]
        assert udp_receive_queue(port) == 0
        sender.sendto(b"x" * 100, ("127.0.0.1", port))
        until(lambda: udp_receive_queue(port) > 0, timeout_s=10, what="the datagram in the socket's queue")
        bound.recv(1000)
        assert udp_receive_queue(port) == 0
    assert udp_receive_queue(port, table="/nonexistent") == 0


def test_a_wake_takes_in_what_sitl_sent_in_the_loop_of_its_step_however_slow_that_loop(monkeypatch):
    """SITL runs its loop after each answer (sending its messages) and only then asks for the next step:
    a task woken at a deadline must see everything the loop of that step sent, however long the loop takes.
    The SITL played here sends a step's messages only once the companion's wake has gone on without them
    (its settle ended) or waits for SITL. The wake learns that the physics waits from the gate, not by
    looking again later (the look is put off beyond the test's bound)."""
    import preland_app.vehicle.lockstep_clock as lockstep_clock

    monkeypatch.setattr(lockstep_clock, "LOOK_WALL_S", 60.0)
    monkeypatch.setattr(lockstep_clock, "SITL_LOOP_MAX_WALL_S", 60.0)
    bridge = JsonBridge(model=QuadXMultirotor(frame=QuadXFrame()), port=0)
    clock = LockstepClock(gate=bridge.gate, stall_wall_s=30.0)
    sent = [0]  # the steps whose loop has sent its messages
    clock.activity = lambda: sent[0]
    pwm = [round(QuadXFrame().hover_pwm_us()) - 50] * 4 + [0] * 12

    def slow_sitl(bridge: JsonBridge, stop: threading.Event) -> threading.Thread:
        def run() -> None:
            frame = 0
            while not stop.is_set():
                settles = clock.settles
                bridge.handle(build_servo_packet(frame_rate_hz=FRAME_RATE_HZ, frame_count=frame, pwm_us=pwm))
                if bridge.gate.held():  # a wake is due at this step: its loop's messages come late
                    until(lambda: stop.is_set() or clock.settles > settles or clock.waiting_for_sitl,
                          timeout_s=30, what="the wake to go on or to wait for SITL")
                sent[0] = bridge.counters.steps
                frame += 1

        thread = threading.Thread(target=run, name="slow-sitl", daemon=True)
        thread.start()
        return thread

    seen: list[tuple[int, int]] = []

    async def main(bridge: JsonBridge) -> None:
        for _ in range(20):
            await clock.sleep(0.01)
            seen.append((sent[0], bridge.counters.steps))

    _run_on_played_bridge(main, bridge=bridge, player=slow_sitl)
    assert len(seen) == 20
    assert all(messages == steps for messages, steps in seen), seen
    assert clock.unsettled == 0  # each wake saw SITL's loop end, none went on at its bound


def test_an_answer_read_mid_step_ends_the_step_where_it_was_to_and_the_task_goes_on_once_sitl_stands_there(
        monkeypatch):
    """A request that reaches SITL while SITL runs its loop is read a loop earlier than one that reaches it
    while SITL waits for the physics: so an exchange's task goes on only once the physics stands at the end
    of the step under way (not wherever this machine read the answer) with SITL's next packet in."""
    import preland_app.vehicle.lockstep_clock as lockstep_clock

    monkeypatch.setattr(lockstep_clock, "EXCHANGE_DELIVERY_WALL_S", 0.0)
    slow, permits = threading.Event(), threading.Semaphore(0)
    frame_s = 1.0 / FRAME_RATE_HZ
    pwm = [round(QuadXFrame().hover_pwm_us()) - 50] * 4 + [0] * 12

    def player(bridge: JsonBridge, stop: threading.Event) -> threading.Thread:
        def run() -> None:  # free-running SITL until `slow`, then one servo packet per permit
            frame = 0
            while not stop.is_set():
                if slow.is_set() and not permits.acquire(timeout=0.05):
                    continue
                bridge.handle(build_servo_packet(frame_rate_hz=FRAME_RATE_HZ, frame_count=frame, pwm_us=pwm))
                frame += 1

        thread = threading.Thread(target=run, name="sitl-stand-in", daemon=True)
        thread.start()
        return thread

    seen: dict[str, object] = {}

    async def main(bridge: JsonBridge) -> None:
        clock = LockstepClock(gate=bridge.gate, stall_wall_s=30.0)
        answer_in = False

        async def mission() -> None:
            await clock.sleep(0.5)

        async def commander() -> None:
            nonlocal answer_in
            await clock.sleep(0.1)
            slow.set()
            permits.release()  # the packet the physics stands at: taken in once it is let go
            with clock.exchanging(answered=lambda: answer_in):
                start_s = clock.now_s()
                await until_async(lambda: bridge.gate.hold_at_s is not None and bridge.gate.hold_at_s > start_s,
                                  timeout_s=30, what="the exchange's step to be let go")
                step_end_s = bridge.gate.hold_at_s
                # The packet the physics stood at and the one permitted above: two frames of the step's three
                # at most, so the looks below are mid-step however late this task sees the first.
                await until_async(lambda: clock.now_s() > start_s, timeout_s=30, what="one frame of the step")
                clock._apply()  # a look mid-step (another task's sleep, a delivery) keeps the step's end
                seen["hold_mid_step_s"] = bridge.gate.hold_at_s
                seen["mid_step_s"] = clock.now_s()
                answer_in = True  # read off the link in the middle of the step
                clock._apply()  # the hold, as the clock's next look sets it
                seen["hold_after_answer_s"] = bridge.gate.hold_at_s
                went_on = asyncio.ensure_future(clock.answered(lambda: answer_in))
                seen["went_on_mid_step"] = went_on.done()
                for _ in range(10):  # SITL asks for more steps than the step has
                    permits.release()
                await asyncio.wait_for(went_on, timeout=30)
                seen["went_on_at_s"] = clock.now_s()
                seen["sitl_waiting"] = bridge.gate.waiting
                seen["start_s"], seen["step_end_s"] = start_s, step_end_s
            slow.clear()  # SITL runs free again: the mission's sleep ends

        await asyncio.gather(mission(), commander())

    bridge = _run_on_played_bridge(main, player=player)
    assert seen["step_end_s"] == seen["start_s"] + lockstep_clock.EXCHANGE_STEP_S
    assert seen["start_s"] < seen["mid_step_s"] < seen["step_end_s"]
    assert seen["hold_mid_step_s"] == seen["step_end_s"]
    assert seen["hold_after_answer_s"] == seen["step_end_s"]  # not the mid-step time the answer was read at
    assert seen["went_on_mid_step"] is False
    assert seen["step_end_s"] <= seen["went_on_at_s"] < seen["step_end_s"] + frame_s + 1e-9
    assert seen["sitl_waiting"] is True
    assert bridge.counters.steps > 0

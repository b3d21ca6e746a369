"""Lock-step SITL on preland's physics, without SITL: a thread plays SITL on the bridge (a servo packet,
the answer, the next), the companion's clock is a `LockstepClock` on the bridge's gate."""

import asyncio
import math
import threading

from preland_app.sim.json_bridge import JsonBridge
from preland_app.sim.multirotor import QuadXFrame, QuadXMultirotor
from preland_app.sim.sensor_smoothing import SensorSmoothing
from preland_app.sim.sitl_json import build_servo_packet
from preland_app.sim.step_gate import StepGate
from preland_app.vehicle.lockstep_clock import LockstepClock

from .waiting import until

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

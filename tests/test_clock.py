import asyncio
import pytest

from preland_app.clock import LoopClock, run_virtual, wait_until
from preland_app.errors import WaitTimeout


def test_virtual_time_advances_deterministically():
    order = []

    async def main():
        clock = LoopClock()

        async def ticker(name, period_s, count):
            for _ in range(count):
                await clock.sleep(period_s)
                order.append((round(clock.now_s(), 6), name))

        await asyncio.gather(ticker("fast", 0.5, 4), ticker("slow", 1.0, 2))
        return clock.now_s()

    end_s = run_virtual(main())
    first_order = list(order)
    order.clear()
    assert run_virtual(main()) == end_s == pytest.approx(2.0)
    assert order == first_order  # deterministic
    assert sorted(order) == [(0.5, "fast"), (1.0, "fast"), (1.0, "slow"), (1.5, "fast"), (2.0, "fast"), (2.0, "slow")]


def test_asyncio_timeouts_are_virtual_too():
    async def main():
        clock = LoopClock()
        with pytest.raises(TimeoutError):
            await asyncio.wait_for(asyncio.sleep(3600), timeout=30)
        return clock.now_s()

    assert run_virtual(main()) == pytest.approx(30.0)


def test_wait_until_returns_when_true_and_raises_typed_timeout():
    async def main():
        clock = LoopClock()

        async def after_five():
            return clock.now_s() >= 5.0

        reached = await wait_until(after_five, clock=clock, timeout_s=10, operation="five", poll_period_s=0.5)

        async def never():
            return False

        async def describe():
            return "still waiting"

        with pytest.raises(WaitTimeout) as info:
            await wait_until(never, clock=clock, timeout_s=3, operation="never", describe=describe)
        return reached, info.value, clock.now_s()

    reached, error, end_s = run_virtual(main())
    assert reached == pytest.approx(5.0)
    assert error.operation == "never" and error.timeout_s == 3
    assert "still waiting" in str(error)
    assert end_s == pytest.approx(8.0, abs=0.2)


def _ticks_with_neighbours(step_alone: bool) -> list[tuple[float, str]]:
    """A 10 ms stepper beside a 33 ms and a 50 ms sleeper, the stepper skipping ahead alone when asked."""
    order: list[tuple[float, str]] = []

    async def main():
        clock = LoopClock()

        async def stepper():
            for _ in range(60):
                await clock.sleep(0.01)
                order.append((clock.now_s(), "step"))
                while step_alone and len(order) < 200 and clock.skip_alone(0.01):
                    order.append((clock.now_s(), "step"))

        async def sleeper(name, period_s):
            while True:
                await clock.sleep(period_s)
                order.append((clock.now_s(), name))

        others = [asyncio.ensure_future(sleeper("camera", 1 / 30)), asyncio.ensure_future(sleeper("poll", 0.05))]
        await stepper()
        for task in others:
            task.cancel()

    run_virtual(main())
    return order


def test_skipping_ahead_alone_gives_the_same_times_and_order_as_sleeping():
    slept = _ticks_with_neighbours(step_alone=False)
    skipped = _ticks_with_neighbours(step_alone=True)
    steps = [t for t, name in skipped if name == "step"]
    # Exactly the same instants (to the bit) and interleaving, for as long as both ran.
    common = min(len(slept), len(skipped))
    assert skipped[:common] == slept[:common]
    assert len(steps) > 60  # it did skip ahead, several steps between the other timers
    assert all(b > a for a, b in zip(steps, steps[1:]))


def test_skip_alone_refuses_when_another_timer_or_callback_is_due():
    async def main():
        clock = LoopClock()
        loop = asyncio.get_running_loop()
        results = {}
        loop.call_later(0.015, lambda: None)
        results["timer at 15 ms, skip 10 ms"] = clock.skip_alone(0.01)
        results["now"] = clock.now_s()
        results["timer at 15 ms, skip 20 ms"] = clock.skip_alone(0.01)
        loop.call_soon(lambda: None)
        results["callback ready"] = clock.skip_alone(0.001)
        await asyncio.sleep(0)
        return results

    results = run_virtual(main())
    assert results == {"timer at 15 ms, skip 10 ms": True, "now": pytest.approx(0.01),
                       "timer at 15 ms, skip 20 ms": False, "callback ready": False}


def test_skip_alone_is_false_on_an_ordinary_loop():
    async def main():
        clock = LoopClock()
        before = clock.now_s()
        return clock.skip_alone(5.0), clock.now_s() - before

    skipped, elapsed_s = asyncio.run(main())
    assert skipped is False and elapsed_s < 1.0


def test_a_thread_posting_to_a_busy_virtual_loop_is_heard():
    """With callbacks always ready the loop polls I/O only every few passes, but it does poll."""
    import threading

    async def main():
        loop = asyncio.get_running_loop()
        heard = loop.create_future()
        threading.Thread(target=lambda: loop.call_soon_threadsafe(heard.set_result, "posted")).start()
        passes = 0
        while not heard.done() and passes < 100_000:
            await asyncio.sleep(0)  # busy: never lets virtual time advance
            passes += 1
        return heard.result() if heard.done() else None, passes

    message, passes = run_virtual(main())
    assert message == "posted" and passes < 100_000


def test_a_trial_is_the_same_whether_the_simulator_skips_ahead_or_sleeps(monkeypatch, thesis_mission):
    import numpy as np

    from preland_app.runtime.embedded import TrialRequest, run_trial

    request = TrialRequest(mission=thesis_mission, seed=3, land_mode="irlock", faults={"irlock": "random:0.75"})
    skipping = run_trial(request)
    monkeypatch.setattr(LoopClock, "skip_alone", lambda self, duration_s: False)
    sleeping = run_trial(request)
    assert skipping.landing_error_cm == sleeping.landing_error_cm
    assert skipping.flight_time_s == sleeping.flight_time_s
    assert np.array_equal(skipping.trajectory, sleeping.trajectory)
    assert [(e.kind, e.time_s) for e in skipping.events] == [(e.kind, e.time_s) for e in sleeping.events]

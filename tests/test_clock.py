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

"""Time for mission, landing and sensing logic: a Clock, and a virtual-time event loop.

Mission logic reads time and sleeps only through a `Clock`. Which clock depends
on the runtime:

* embedded simulator: `LoopClock` on a `VirtualTimeEventLoop`. The loop's time is
  virtual and jumps straight to the next timer whenever every task is waiting,
  so the simulation runs as fast as the CPU allows and every `asyncio` timer
  (sleeps, timeouts) is in simulated seconds;
* field: `LoopClock` on an ordinary event loop (wall time);
* ArduPilot SITL: a clock that follows the autopilot's own time, behind the same
  protocol.
"""

from __future__ import annotations

import asyncio
import selectors
from collections.abc import Awaitable, Callable, Coroutine
from typing import Any, Protocol, TypeVar, runtime_checkable

from .errors import WaitTimeout

T = TypeVar("T")


@runtime_checkable
class Clock(Protocol):
    """A source of time in seconds and a way to sleep on it."""

    def now_s(self) -> float:
        """Seconds since an arbitrary epoch of this clock (monotonic)."""
        ...

    async def sleep(self, duration_s: float) -> None:
        """Sleep `duration_s` seconds of this clock's time."""
        ...


class LoopClock:
    """A clock that reads the running asyncio loop's time.

    On a `VirtualTimeEventLoop` this is simulated time; on an ordinary loop it is
    the wall clock. `now_s()` counts from the moment the clock was created.
    """

    def __init__(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._epoch = self._loop.time()
        # Looked up once: the simulator asks at nearly every physics step.
        self._skip_alone = getattr(self._loop, "skip_alone", None)

    def now_s(self) -> float:
        return self._loop.time() - self._epoch

    async def sleep(self, duration_s: float) -> None:
        await asyncio.sleep(max(0.0, duration_s))

    def skip_alone(self, duration_s: float) -> bool:
        """Advance time by `duration_s` at once, without yielding, when nothing else would run before then
        (see `VirtualTimeEventLoop.skip_alone`); False, with time unchanged, on any other loop or when
        something would. A task that sleeps in fixed steps runs the same with or without it."""
        return self._skip_alone is not None and self._skip_alone(duration_s)


class _VirtualSelector(selectors.DefaultSelector):
    """A selector whose blocking waits advance virtual time instead of blocking."""

    # With callbacks ready (timeout 0), I/O is polled only every this many passes: the poll is a system
    # call, and in virtual time nothing is late for waiting a few callbacks.
    _POLL_EVERY_READY_PASSES = 32

    def __init__(self) -> None:
        super().__init__()
        self.virtual_now_s = 0.0
        self._ready_passes = 0

    def select(self, timeout: float | None = None):  # noqa: D401 - selector API
        if timeout is not None and timeout <= 0:
            self._ready_passes += 1
            if self._ready_passes < self._POLL_EVERY_READY_PASSES:
                return []
        self._ready_passes = 0
        # Real I/O (the loop's self-pipe, threads posting callbacks) is still
        # polled, without waiting; only the idle wait becomes a jump in time.
        events = super().select(0)
        if events:
            return events
        if timeout is None:
            # Nothing scheduled at all: only I/O or another thread can wake us.
            return super().select(None)
        if timeout > 0:
            self.virtual_now_s += timeout
        return []


class VirtualTimeEventLoop(asyncio.SelectorEventLoop):
    """An asyncio loop whose clock is virtual, starting at 0 s.

    Whenever no callback is ready, time advances to the next scheduled timer at
    once, so simulated seconds cost only the CPU the tasks use. Task ordering is
    that of asyncio (FIFO, timers by deadline), hence deterministic.
    """

    def __init__(self) -> None:
        self._virtual_selector = _VirtualSelector()
        super().__init__(self._virtual_selector)

    def time(self) -> float:
        return self._virtual_selector.virtual_now_s

    def skip_alone(self, delay_s: float) -> bool:
        """Advance virtual time by `delay_s` now, for the running callback, when the loop would otherwise
        do exactly that and then resume only it: no other callback ready, no other timer due by then
        (asyncio's own rule: due when earlier than the new time plus the clock's resolution). The time
        reached is computed as `asyncio.sleep(delay_s)` would reach it, to the last bit, so a task that
        steps with this instead of sleeping runs identically, minus the loop's bookkeeping. False, with
        time unchanged, otherwise."""
        if self._ready or self._stopping or delay_s <= 0:
            return False
        selector = self._virtual_selector
        now_s = selector.virtual_now_s
        # call_later(delay) schedules at now + delay; _run_once then waits (when - now); select adds it.
        timeout_s = (now_s + delay_s) - now_s
        new_now_s = now_s + timeout_s if timeout_s > 0 else now_s
        scheduled = self._scheduled
        if scheduled:
            head = scheduled[0]
            if head._cancelled or head._when < new_now_s + self._clock_resolution:
                return False
        selector.virtual_now_s = new_now_s
        return True


def run_virtual(main: Coroutine[Any, Any, T]) -> T:
    """Run a coroutine to completion on a fresh `VirtualTimeEventLoop`."""
    with asyncio.Runner(loop_factory=VirtualTimeEventLoop) as runner:
        return runner.run(main)


def join(clock: Clock) -> None:
    """The running task reads sensors on `clock`: on a clock in lock-step with a simulator
    (`vehicle.paced_clock.PacedClock`) time stands still while the task is not sleeping on it, until the
    task ends, so the vehicle waits for its readings; on any other clock, nothing. A task that goes on to
    wait for other tasks should read its sensors in a task of its own."""
    joining = getattr(clock, "join", None)
    if joining is not None:
        joining()


async def wait_until(
    predicate: Callable[[], Awaitable[bool]],
    *,
    clock: Clock,
    timeout_s: float,
    operation: str,
    poll_period_s: float = 0.1,
    describe: Callable[[], Awaitable[str]] | None = None,
) -> float:
    """Poll `predicate` every `poll_period_s` (clock seconds) until it is true.

    Returns the clock time at which it became true. Raises `WaitTimeout` naming
    `operation` (and the last state, if `describe` is given) after `timeout_s`.
    """
    deadline_s = clock.now_s() + timeout_s
    while True:
        if await predicate():
            return clock.now_s()
        if clock.now_s() >= deadline_s:
            last_state = await describe() if describe is not None else ""
            raise WaitTimeout(operation=operation, timeout_s=timeout_s, last_state=last_state)
        await clock.sleep(poll_period_s)

"""Run a callback once the event loop's callbacks already ready have run: the lock-step clocks decide
how far the vehicle may go only after the tasks just woken have gone back to sleep, so the decision
sees all their new deadlines."""

from __future__ import annotations

import asyncio
from collections.abc import Callable

# A callback waits at most this many passes of the event loop for the callbacks ready before it.
MAX_DEFERRALS = 64


class AfterReady:
    """`schedule()` calls `callback` once, after the ready callbacks (at most MAX_DEFERRALS passes);
    more calls before it runs change nothing."""

    def __init__(self, callback: Callable[[], None]) -> None:
        self._callback = callback
        self._scheduled = False
        self._deferrals = 0
        self._loop: asyncio.AbstractEventLoop | None = None

    def schedule(self, loop: asyncio.AbstractEventLoop | None = None) -> None:
        if not self._scheduled:
            self._scheduled = True
            self._loop = loop or asyncio.get_running_loop()
            self._loop.call_soon(self._run)

    def _run(self) -> None:
        if getattr(self._loop, "_ready", None) and self._deferrals < MAX_DEFERRALS:
            self._deferrals += 1  # other callbacks first: a task just woken or created may sleep sooner
            self._loop.call_soon(self._run)
            return
        self._scheduled = False
        self._deferrals = 0
        self._callback()

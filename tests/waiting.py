"""Bounded, named waits for tests that watch something running beside them (a served simulator, a
process): each gives up after its timeout and fails naming what it waited for, however loaded the
machine is (the bounds are wall seconds far above what an idle machine needs)."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable

POLL_S = 0.01


def until(predicate: Callable[[], bool], *, timeout_s: float, what: str, poll_s: float = POLL_S) -> None:
    """Return once `predicate()` is true; fail after `timeout_s` wall seconds naming `what`."""
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"waited {timeout_s:g} s for {what}")
        time.sleep(poll_s)


async def until_async(predicate: Callable[[], bool], *, timeout_s: float, what: str,
                      poll_s: float = POLL_S) -> None:
    """`until` for a coroutine: the event loop keeps running while it waits."""
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"waited {timeout_s:g} s for {what}")
        await asyncio.sleep(poll_s)

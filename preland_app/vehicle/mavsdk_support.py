"""MAVSDK as preland uses it: its connection URLs, its log lines, its calls on threads that never hold up a
trial's end, and the one setting its Python package does not wrap."""

from __future__ import annotations

import concurrent.futures
import threading
from typing import Any

from ..mavlink.endpoint import parse_endpoint


def set_command_resend_wall_s(sdk: Any, wall_s: float) -> None:
    """MAVSDK's wait for an answer before it resends (`Mavsdk::set_timeout_s`), which its Python package
    does not wrap: set through its C library."""
    import ctypes

    inner = sdk._mavsdk
    setter = inner._lib.mavsdk_set_timeout_s
    setter.argtypes, setter.restype = [ctypes.c_void_p, ctypes.c_double], None
    setter(inner._handle, wall_s)


def quiet_mavsdk_logs() -> None:
    """Keep MAVSDK's own log lines to warnings and errors (its debug output would drown the CLI's)."""
    from mavsdk.logging import LogLevel, log_subscribe

    def handler(level: LogLevel, message: str, file: str | None, line: int) -> bool:
        # True suppresses MAVSDK's default printing. "Sending message failed" comes with every new TCP link
        # to ArduPilot (a heartbeat sent before the socket is up); a link that really fails is preland's to
        # report (LinkLost), in one line.
        return level < LogLevel.WARN or message.startswith("Sending message failed")

    log_subscribe(handler)


class DaemonCallExecutor(concurrent.futures.ThreadPoolExecutor):
    """Runs each call on a daemon thread of its own, and never waits for one at shutdown.

    MAVSDK's asyncio plugins run every call with `loop.run_in_executor(None, ...)`, and some calls can
    block for good: a command that got MAV_RESULT_IN_PROGRESS waits for a final COMMAND_ACK that an
    autopilot which has gone (SITL stopped, a link lost) never sends. preland bounds its own waits for
    such calls; with the loop's default ThreadPoolExecutor, `asyncio.run` would still join the blocked
    thread when the trial ends, and the trial (a campaign worker) would hang there for ever. (A
    ThreadPoolExecutor only because asyncio accepts no other kind as a loop's default; its pool is unused.)
    The calls not yet returned are kept (`running`): MAVSDK must not be destroyed under one that is sending,
    which crashes the process."""

    def __init__(self) -> None:
        super().__init__(max_workers=1)
        self.running: set[concurrent.futures.Future] = set()

    def submit(self, fn, /, *args, **kwargs) -> concurrent.futures.Future:
        future: concurrent.futures.Future = concurrent.futures.Future()
        self.running.add(future)
        future.add_done_callback(self.running.discard)

        def call() -> None:
            if not future.set_running_or_notify_cancel():
                return
            try:
                future.set_result(fn(*args, **kwargs))
            except BaseException as error:  # handed to the awaiting coroutine
                future.set_exception(error)

        threading.Thread(target=call, name="preland-mavsdk-call", daemon=True).start()
        return future

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        """Nothing to join: a call still blocked stays behind on its daemon thread."""


def mavsdk_connection_url(url: str) -> str:
    """`url` (any form `parse_endpoint` reads) as MAVSDK takes it: `tcp://host:port` (a vehicle or SITL
    serving TCP, as ArduPilot's documentation writes it) is MAVSDK's `tcpout://host:port`; MAVSDK 3
    deprecates the bare `tcp://`."""
    return parse_endpoint(url).mavsdk_url()

"""When a companion's MAVLink link to a free-running vehicle counts as lost: what was heard, and when.

A vehicle that still sends stamped messages counts its own silence: the vehicle seconds its stamps move on
by, heard step by step, since its last HEARTBEAT. One that sends nothing at all is judged by wall time at the
vehicle clock's measured rate, and only after LINK_LOST_MIN_WALL_S of total quiet, counted from the end of
any stall of this process. (In lock-step and paced, time passes only with the companion's leave: the backend
judges those by the vehicle's own clock.)
"""

from __future__ import annotations

import asyncio
import time

from ..errors import LinkLost

# A vehicle that sends nothing at all (no stamped message either) has its silence reckoned from wall time,
# so at 8x the 5 vehicle s of link_timeout_s would be 0.6 wall s, and a stall of either process (a loaded
# machine, a garbage collection) would read as a lost link. Such a link is lost only after this much wall time
# of quiet too: MAVSDK's own heartbeat timeout (SystemImpl::_HEARTBEAT_TIMEOUT_S), after which it reports the
# system disconnected. Up to 5/3x the 5 vehicle s alone decide; a SITL that has stopped is found within 3 wall s.
LINK_LOST_MIN_WALL_S = 3.0
# Stamped messages come at 10 Hz (mavlink_backend.STREAMS_HZ): stamps read further apart than this mean the
# messages between were lost (a starved process's UDP receive buffer overflows, heartbeats and all), and that
# vehicle time is not time the vehicle was heard talking without heartbeats.
HEARD_STEP_MAX_S = 1.0
# preland's own event loop has stalled (a loaded machine, a long synchronous step) when its tick has not run for
# this long: what the vehicle sent meanwhile waits unread, so the silence seen is not yet the vehicle's.
LOOP_STALL_WALL_S = 0.5
LOOP_TICK_WALL_S = 0.1


class LinkWatch:
    """What a companion has heard of its vehicle (monotonic wall s; vehicle s by the vehicle's stamps)."""

    def __init__(self) -> None:
        self.last_heartbeat_wall: float | None = None
        self.last_message_wall: float | None = None  # any message of the vehicle's
        self.loop_ran_wall: float | None = None  # when this process's event loop last ran `tick`
        self.resumed_wall = 0.0  # when `tick` last ran after a stall of this process
        self.talked_s = 0.0  # vehicle s heard in stamped messages since the last heartbeat
        self._stamp_high_s: float | None = None  # the newest stamp read

    def heard(self, *, heartbeat: bool) -> None:
        """A message of the vehicle's was read now (a HEARTBEAT, or another)."""
        self.last_message_wall = time.monotonic()
        if heartbeat:
            self.last_heartbeat_wall = self.last_message_wall
            self.talked_s = 0.0

    def heard_stamp(self, stamp_s: float) -> None:
        """A message stamped `stamp_s` (time_boot_ms, in s) was read: count the vehicle seconds it moves the
        stream on by, when heard step by step (HEARD_STEP_MAX_S)."""
        high_s = self._stamp_high_s
        if high_s is not None and high_s < stamp_s <= high_s + HEARD_STEP_MAX_S:
            self.talked_s += stamp_s - high_s
        if high_s is None or stamp_s > high_s or stamp_s < high_s - 1.0:  # newer, or the autopilot rebooted
            self._stamp_high_s = stamp_s

    async def tick(self) -> None:
        """Note, every LOOP_TICK_WALL_S, that this process's event loop runs."""
        while True:
            self.loop_ran(time.monotonic())
            await asyncio.sleep(LOOP_TICK_WALL_S)

    def loop_ran(self, now_wall_s: float) -> None:
        # After a stall the tick may run before a check that was due in it, and before the messages sent
        # meanwhile are read: quiet is reckoned from the stall's end, not from before it.
        if self.loop_ran_wall is not None and now_wall_s - self.loop_ran_wall > LOOP_STALL_WALL_S:
            self.resumed_wall = now_wall_s
        self.loop_ran_wall = now_wall_s

    def check(self, operation: str, *, link_timeout_s: float, rate: float) -> None:
        """Raise LinkLost, naming `operation` and the evidence, when the link is lost: more than
        `link_timeout_s` vehicle s without a HEARTBEAT, at `rate` vehicle s per wall s. Nothing before the
        first HEARTBEAT."""
        if self.last_heartbeat_wall is None:
            return
        if self.talked_s > link_timeout_s:
            raise LinkLost(operation=operation, reason=f"no heartbeat for {self.talked_s:.1f} vehicle s by the "
                                                      "stamps of its other messages")
        now_wall_s = time.monotonic()
        if self.loop_ran_wall is not None and now_wall_s - self.loop_ran_wall > LOOP_STALL_WALL_S:
            return  # this process stalled: the vehicle's messages of meanwhile are not read yet
        silent_vehicle_s = (now_wall_s - self.last_heartbeat_wall) * rate
        quiet_wall_s = now_wall_s - max(self.last_heartbeat_wall, self.last_message_wall or 0.0, self.resumed_wall)
        if silent_vehicle_s > link_timeout_s and quiet_wall_s > LINK_LOST_MIN_WALL_S:
            raise LinkLost(operation=operation, reason=f"no heartbeat for {silent_vehicle_s:.1f} vehicle s at "
                                                      f"{rate:.2g}x, nothing heard for {quiet_wall_s:.1f} wall s")

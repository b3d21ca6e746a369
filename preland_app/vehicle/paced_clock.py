"""The vehicle clock in lock-step with preland's simulator (PRELAND_PACE): time passes only when the
companion lets it.

Over MAVLink the autopilot keeps time and the companion follows it
(`VehicleTimeClock`). Against `preland sim serve` the two can instead run in
lock-step: every sleep on this clock is a deadline; the simulator is granted
the earliest deadline of all sleepers, steps to it without waiting for its own
clock, says where it holds, and holds. Time here is the time the simulator
last said it holds at, never extrapolated, so a sleeper wakes with the vehicle
exactly at its deadline (to within one physics step) and the SIM_STATE the
simulator sent there is the truth of that moment.

Time is granted only when the companion is idle, as the embedded simulator's
virtual time jumps only when every task waits: tasks that read sensors join
the clock (`join`), and while such a task is not sleeping on it (it is
detecting a frame, sending a LANDING_TARGET), no new time is granted; nor
while an exchange with the vehicle is under way (`holding`: a command and its
COMMAND_ACK, a parameter read), nor while other callbacks are ready to run.
So the vehicle waits for a reading or a command however long it takes in wall
time. Other tasks (the mission's waits) only add their deadlines.
"""

from __future__ import annotations

import asyncio
import contextlib
import heapq
import itertools
import math
import time
from collections.abc import Callable

from ..errors import LinkLost, WaitTimeout
from .after_ready import AfterReady

# Wall seconds without the simulator answering a grant (a held time) before the link counts as lost: far
# more than a loaded machine's stall, far less than a test's patience.
PACE_ANSWER_WALL_S = 20.0
# A deadline is reached when the held time is within this of it (time_boot_ms is whole milliseconds).
_REACHED_S = 0.0005
# Once the simulator holds for this companion it steps to a grant and stops there (a physics step past it at
# most). An answer further past everything granted is another vehicle's: one whose datagrams reach this
# companion's port (a vehicle still sending to the port of a companion that closed it, which the system then
# handed to this one), and to which this companion's grants and commands then go too.
FOREIGN_ANSWER_S = 0.5


class PacedClock:
    """Vehicle seconds, advanced by the simulator's PRELAND_PACE answers. `grant(time_ms)` sends a
    PRELAND_PACE grant (0 releases the simulator); it must not block, and grants must leave in order."""

    def __init__(self, *, grant: Callable[[int], None], answer_timeout_wall_s: float | None = None,
                 explain: Callable[[], str] | None = None) -> None:
        self._grant = grant
        self.answer_timeout_wall_s = PACE_ANSWER_WALL_S if answer_timeout_wall_s is None else answer_timeout_wall_s
        self._explain = explain  # what the granting side knows of an unanswered grant (sends, failures)
        self._failure: tuple[str, str] | None = None  # (operation, reason): the link behind the grants is gone
        self._now_s = 0.0
        self._started = False
        self._sleepers: list[tuple[float, int, asyncio.Future]] = []  # (deadline s, order, future): a heap
        self._order = itertools.count()
        self._participants: set[asyncio.Task] = set()
        self._sleeping: dict[asyncio.Task, int] = {}  # participant -> sleeps it is in
        self._granted_ms = 0
        self._after_ready = AfterReady(self._regrant)
        self._holds = 0
        self._answered_wall_s = time.monotonic()
        self.grants = 0
        self.answers = 0
        self._answers_before_start = 0
        self._start_wall_s = time.monotonic()
        self._start_s = 0.0

    # ------------------------------------------------------------ the simulator's side

    def start(self, now_s: float) -> None:
        """Begin at `now_s` (the vehicle's time as last observed): hold the simulator where it is."""
        self._now_s = self._start_s = now_s
        self._started = True
        self._answers_before_start = self.answers
        self._answered_wall_s = self._start_wall_s = time.monotonic()
        self._send(max(1, math.ceil(now_s * 1000)))

    def held(self, time_s: float) -> None:
        """The simulator holds at `time_s` (its PRELAND_PACE answer): wake every sleeper whose deadline it
        reached."""
        self._answered_wall_s = time.monotonic()
        self.answers += 1
        if self._started and self.answers > self._answers_before_start + 1 and \
                time_s > max(self._granted_ms / 1000, self._now_s) + FOREIGN_ANSWER_S:
            # The first answer may be past the grant: a simulator running free holds where the grant finds it.
            self.fail(operation="paced clock", reason=f"an answer holding at {time_s:.3f} s, past the "
                                                      f"{self._granted_ms} ms granted and the {self._now_s:.3f} s "
                                                      "held: another vehicle answers on this companion's port")
            return
        if time_s <= self._now_s:
            return
        self._now_s = time_s
        while self._sleepers and self._sleepers[0][0] <= time_s + _REACHED_S:
            _, _, future = heapq.heappop(self._sleepers)
            if not future.done():
                future.set_result(None)
        self._schedule_regrant()

    @property
    def rate(self) -> float:
        """Vehicle seconds per wall second since the start (how fast the two ran together)."""
        wall_s = time.monotonic() - self._start_wall_s
        return (self._now_s - self._start_s) / wall_s if wall_s > 0 else 0.0

    @property
    def answered_wall_s(self) -> float:
        """When (monotonic wall s) the simulator last said where it holds."""
        return self._answered_wall_s

    @property
    def granted_ms(self) -> int:
        return self._granted_ms

    @property
    def started(self) -> bool:
        return self._started

    def release(self) -> None:
        """Let the simulator run free (the trial is over)."""
        if self._started:
            self._started = False
            self._send(0)

    def fail(self, *, operation: str, reason: str) -> None:
        """The link that carries grants and answers is gone: every sleep raises LinkLost now, not after the
        wall bound."""
        self._failure = (operation, reason)
        for _, _, future in self._sleepers:
            if not future.done():
                future.set_result(None)

    # ------------------------------------------------------------ the Clock protocol

    def now_s(self) -> float:
        return self._now_s

    async def sleep(self, duration_s: float) -> None:
        self._raise_failure()
        if duration_s <= 0 or not self._started:
            await asyncio.sleep(0)
            return
        future = asyncio.get_running_loop().create_future()
        heapq.heappush(self._sleepers, (self._now_s + duration_s, next(self._order), future))
        task = asyncio.current_task()
        joined = task in self._participants
        if joined:
            self._sleeping[task] = self._sleeping.get(task, 0) + 1
        self._schedule_regrant()
        try:
            while not future.done():
                await asyncio.wait([future], timeout=self.answer_timeout_wall_s)
                silent_s = time.monotonic() - self._answered_wall_s
                if not future.done() and silent_s > self.answer_timeout_wall_s:
                    self._stalled(silent_s)
        finally:
            if not future.done():
                future.cancel()  # stays in the heap, skipped
            if joined:
                self._sleeping[task] -= 1
            self._schedule_regrant()
        self._raise_failure()

    def _raise_failure(self) -> None:
        if self._failure is not None:
            operation, reason = self._failure
            raise LinkLost(operation=operation, reason=reason)

    @contextlib.contextmanager
    def holding(self):
        """No time is granted while this is entered (an exchange with the vehicle is under way)."""
        self._holds += 1
        try:
            yield
        finally:
            self._holds -= 1
            if self._started:
                self._schedule_regrant()

    def _stalled(self, silent_s: float) -> None:
        if self._granted_ms > round(self._now_s * 1000):
            detail = self._explain() if self._explain is not None else ""
            raise LinkLost(operation="paced clock", reason=f"the simulator did not answer PRELAND_PACE for "
                                                           f"{silent_s:.1f} wall s (held at {self._now_s * 1000:.0f} "
                                                           f"ms, granted {self._granted_ms} ms"
                                                           f"{'; ' + detail if detail else ''})")
        holders = sorted(task.get_name() for task in self._participants if not self._sleeping.get(task))
        state = (f"sensor tasks {', '.join(holders)} hold the vehicle's time without sleeping on its clock"
                 if holders else "exchanges with the vehicle under way" if self._holds else "nothing to grant")
        raise WaitTimeout(operation="paced clock: time to pass", timeout_s=round(silent_s, 1), last_state=state)

    def join(self) -> None:
        """The running task reads sensors: while it is not sleeping on this clock, time stands still."""
        task = asyncio.current_task()
        if task is None or task in self._participants:
            return
        self._participants.add(task)
        task.add_done_callback(self._leave)

    def _leave(self, task: asyncio.Task) -> None:
        self._participants.discard(task)
        self._sleeping.pop(task, None)
        self._schedule_regrant()

    # ------------------------------------------------------------ granting

    def _schedule_regrant(self) -> None:
        # After the callbacks already ready (the tasks just woken) have run and gone back to sleep, so the
        # grant is the earliest of all their new deadlines.
        self._after_ready.schedule()

    def _regrant(self) -> None:
        if not self._started or self._holds:
            return
        while self._sleepers and self._sleepers[0][2].done():
            heapq.heappop(self._sleepers)
        if not self._sleepers:
            return
        if any(not self._sleeping.get(task) for task in self._participants):
            return  # a sensor reading is being made: the vehicle waits for it
        wanted_ms = math.ceil(self._sleepers[0][0] * 1000 - 1e-6)
        if wanted_ms > self._granted_ms:
            self._send(wanted_ms)

    def _send(self, time_ms: int) -> None:
        if time_ms:
            self._granted_ms = time_ms
            self.grants += 1
        self._grant(time_ms)


"""The vehicle clock of a physics that owns time (SITL on preland's physics): vehicle seconds are the
physics' own, and a reading is made at its vehicle time however slow this machine is.

SITL on its JSON interface waits for the physics after every servo packet, and the physics (the JSON
bridge) runs in this process, so the companion can hold it (`sim.step_gate.StepGate`). The rules are the
paced clock's (`paced_clock`) as far as SITL allows:

- time is the physics' time, read from the gate; a sleep ends when the physics reaches its deadline
  (the gate tells this clock from the physics thread);
- the physics may step up to the earliest deadline of all sleepers and no further, once the callbacks
  ready have run (tasks just woken go back to sleep first), so the companion acts at the vehicle times it
  asked for, as on the embedded simulator;
- tasks that read sensors join the clock (`join`): while one of them is awake (rendering a frame,
  detecting, sending its LANDING_TARGET) the physics holds where it is. So a frame shows the vehicle at
  the frame's time and its LANDING_TARGET is in SITL's socket before SITL's next step;
- unlike the simulator's MAVLink face, SITL answers nothing while held: while a task waits for an answer
  (a command and its COMMAND_ACK, a parameter: `exchanging`), time runs in EXCHANGE_STEP_S steps, until
  the answer has been read off the link; then the step under way ends where it was to end, and time holds
  until the task has the answer. Before the task goes on (`answered`), SITL stands at that step with its
  next packet in and all it sent is taken in, so what the task sends next reaches SITL at the same vehicle
  time and the same point of SITL's loop however fast this machine is (a request that arrives while SITL
  runs its loop is read a loop earlier than one that arrives while SITL waits for the physics).

Before the sleepers due at a hold wake, the companion takes in what SITL sent before it stopped there:
first SITL finishes its loop (it writes out what the loop sent, then asks for the next step: the physics
then waits at the hold), then the messages are taken in. With a relay between SITL and MAVSDK
(`runtime.sitl_relay`), the vehicle has then read as many of each message it uses (`taken_in` and
`listened`, set by the vehicle) as the relay passed on, and a message handed to MAVSDK counts as sent once the relay
has passed it to SITL (`handing`). Without one, the bytes in this machine's socket are read (`unread`),
then the sleepers wake once `activity` (set by the vehicle: its count of messages received and calls
returned) has not changed for SETTLE_WALL_S; the relay's counts start after such a wake. So what a task
reads at a vehicle time does not depend on how fast this machine moved the messages along.

A physics whose time stops while nothing holds it (SITL stopped or hung: it sends no servo packet) is
found by a wall bound: LinkLost after `stall_wall_s`.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import heapq
import itertools
import math
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

from ..errors import LinkLost, WaitTimeout
from ..sim.step_gate import REACHED_S, StepGate
from .after_ready import AfterReady

if TYPE_CHECKING:
    from ..runtime.sitl_relay import MavlinkRelay

# Wall seconds without the physics' time moving, while nothing here holds it, before the link counts as
# lost: far more than a loaded machine's stall, well inside a test's patience.
PHYSICS_STALL_WALL_S = 10.0
_CHECK_WALL_S = 1.0  # how often a sleeper looks whether the physics' time still moves (wall s)
# The vehicle time at which a lock-step trial's mission begins: after SITL's boot and the companion's
# connection, before ArduCopter can arm (about 42 s on the copter defaults, for its EKF and GPS), so every
# trial begins at the same vehicle time however long the connection took in wall time. SITL runs free
# while MAVSDK connects on its wall-clock timers: 15 to 20 vehicle s on 2 cores at 400 Hz physics steps.
MISSION_START_S = 30.0
# While a task waits for SITL's answer, time passes in steps of ArduCopter's main loop (400 Hz), so the
# answer is seen within one loop of its sending (vehicle s).
EXCHANGE_STEP_S = 0.0025
# What SITL sent before a hold is taken in when nothing more has come for this long (wall s), within the
# bound after it (wall s; a message later than that is read at a later vehicle time). Also how often a
# request's delivery is looked at without a relay (nothing then tells this clock when it is delivered).
SETTLE_WALL_S = 0.0005
SETTLE_MAX_WALL_S = 0.05
# How long MAVSDK's thread is given to send a message before the vehicle's time goes on (wall s).
DELIVERY_WALL_S = 0.001
# The same for a request that waits for an answer: MAVSDK sends it from a thread started for the call.
EXCHANGE_DELIVERY_WALL_S = 0.005
# With a relay between SITL and MAVSDK (`runtime.sitl_relay`), a wake waits until the vehicle has taken in as
# many of SITL's messages as the relay passed on, and a message handed to MAVSDK until the relay has passed it
# to SITL, each within this bound (wall s; then it goes on, and counts the wake unsettled).
RELAYED_MAX_WALL_S = 2.0
# How long SITL may take to finish its loop and ask for the next step before a wake goes on without it
# (wall s; far more than the loop takes, short enough for a hold the physics never reaches).
SITL_LOOP_MAX_WALL_S = 0.5
# A wait for a condition is woken when what it reads may have changed (`nudge`: the physics stands at its
# hold, the relay passed a datagram, the vehicle read a message); it also looks this often (wall s), so a
# change nothing told of costs this long, never the wait's bound.
LOOK_WALL_S = 0.005


class LockstepClock:
    """Vehicle seconds of the physics behind `gate`; see the module for the rules."""

    def __init__(self, *, gate: StepGate, stall_wall_s: float = PHYSICS_STALL_WALL_S,
                 unread: Callable[[], int] | None = None, relay: MavlinkRelay | None = None) -> None:
        if stall_wall_s <= 0:
            raise ValueError("stall_wall_s must be positive")
        self._gate = gate
        self._unread = unread  # the receive queue of this machine's socket from SITL (see the module)
        self.stall_wall_s = stall_wall_s
        self._loop: asyncio.AbstractEventLoop | None = None
        self._sleepers: list[tuple[float, int, asyncio.Future]] = []  # (deadline s, order, future): a heap
        self._order = itertools.count()
        self._participants: set[asyncio.Task] = set()
        self._asleep: dict[asyncio.Task, float] = {}  # participant -> the deadline it sleeps to
        self._exchanges = 0
        self._answered: list[Callable[[], bool]] = []  # of the exchanges running: is its answer in?
        self._undelivered: list[Callable[[], bool]] = []  # of the exchanges running: has SITL its request?
        self._exchange_step_s = -math.inf  # where the exchange's step under way ends (vehicle s)
        self._sending = 0  # messages just handed to MAVSDK, given DELIVERY_WALL_S to leave
        self._delivery_look: asyncio.TimerHandle | None = None  # at the undelivered requests (see _apply)
        self.activity: Callable[[], object] | None = None  # see the module: what settles before a wake
        self._relay = relay
        self.listened: collections.Counter[str] | None = None  # the vehicle's messages taken in, by name
        self.taken_in: frozenset[str] = frozenset()  # the names a wake counts (MAVSDK passes on those it knows)
        self._handed: collections.Counter[str] = collections.Counter()  # to MAVSDK, by the relay's key
        self._gated: set[str] = set()  # keys the relay passes only as handed here (`gate`)
        self._forgiven: collections.Counter[str] = collections.Counter()  # relayed, never taken in
        self._reconciled = False  # the counts above compared once after a quiet wake (see _settle_then_wake)
        self._settling = False
        self.waiting_for_sitl = False  # a wake waits for SITL to finish its loop and ask for the next step
        self.unsettled = 0  # wakes that went on before SITL asked for its next step or its messages stopped
        self.settles = 0
        self.settle_wall_s = 0.0  # wall s spent waiting for SITL's messages before wakes
        self._after_ready = AfterReady(self._apply)
        self._change_waiters: set[asyncio.Future] = set()  # waits woken by `nudge` (see `_until`)
        gate.on_waiting = self.nudge_threadsafe
        if relay is not None:
            relay.on_pass = self.nudge_threadsafe
        self._start_wall_s = time.monotonic()
        self._start_s = gate.time_s
        self.wakes = 0

    # ---------------------------------------------------------------- the Clock protocol

    def now_s(self) -> float:
        return self._gate.time_s

    async def sleep(self, duration_s: float) -> None:
        if duration_s <= 0:
            await asyncio.sleep(0)
            return
        loop = asyncio.get_running_loop()
        self._loop = loop
        deadline_s = self.now_s() + duration_s
        future = loop.create_future()
        heapq.heappush(self._sleepers, (deadline_s, next(self._order), future))
        task = asyncio.current_task()
        joined = task in self._participants
        if joined:
            self._asleep[task] = deadline_s
        self._update()
        try:
            seen_s, seen_wall_s = self.now_s(), time.monotonic()
            while not future.done():
                await asyncio.wait([future], timeout=_CHECK_WALL_S)
                now_s = self.now_s()
                if future.done():
                    break
                if now_s != seen_s:
                    seen_s, seen_wall_s = now_s, time.monotonic()
                elif time.monotonic() - seen_wall_s > self.stall_wall_s:
                    self._stalled(time.monotonic() - seen_wall_s)
        finally:
            if not future.done():
                future.cancel()  # stays in the heap, skipped
            if joined:
                self._asleep.pop(task, None)
            self._update()

    async def start_at(self, time_s: float = MISSION_START_S) -> float:
        """Sleep until vehicle time `time_s` (the mission begins there); returns the time it was called at,
        later than `time_s` when the connection took longer (the trial then begins where it is)."""
        called_s = self.now_s()
        if called_s < time_s:
            await self.sleep(time_s - called_s)
        return called_s

    @property
    def rate(self) -> float:
        """Vehicle seconds per wall second since the start (how fast the two ran together)."""
        wall_s = time.monotonic() - self._start_wall_s
        return (self.now_s() - self._start_s) / wall_s if wall_s > 0 else 0.0

    # ---------------------------------------------------------------- who holds time

    def join(self) -> None:
        """The running task reads sensors: while it is awake, the physics holds."""
        task = asyncio.current_task()
        if task is None or task in self._participants:
            return
        self._loop = asyncio.get_running_loop()
        self._participants.add(task)
        task.add_done_callback(self._leave)
        if not self._settling:  # (while settling, the physics already stands at the wake time)
            # Held from this moment, not from the loop's next turn: the task reads the time next and picks
            # its first reading's time from it, which the physics must not pass meanwhile.
            self._gate.hold_at(self.now_s())
        self._update()

    def _leave(self, task: asyncio.Task) -> None:
        self._participants.discard(task)
        self._asleep.pop(task, None)
        self._update()

    @contextlib.contextmanager
    def holding(self):
        """An exchange that needs no answer (a LANDING_TARGET sent): the physics keeps holding for it."""
        yield

    def gate(self, key: str) -> bool:
        """From now on, the messages `key` that reach SITL are those handed over here (`handing`), at the
        vehicle times they are handed, not those MAVSDK sends of its own on a wall-clock timer (the relay
        drops these; see `runtime.sitl_relay`). False without a relay (nothing gated)."""
        if self._relay is None:
            return False
        self._handed[key] = self._relay.gate(key)
        self._gated.add(key)
        return True

    def handing(self, key: str) -> Callable[[], bool] | None:
        """Before a message is handed to MAVSDK: whether it has reached SITL's socket, by the relay's count
        of `key` (see `runtime.sitl_relay`); None without a relay."""
        if self._relay is None:
            return None
        self._handed[key] += 1
        if key in self._gated:
            self._relay.allow(key)
        wanted, relayed = self._handed[key], self._relay.to_sitl
        return lambda: relayed[key] >= wanted

    async def sent(self, delivered: Callable[[], bool] | None = None) -> None:
        """The running task has just handed a message to MAVSDK, which sends it from a thread of its own:
        time stands until `delivered()` (from `handing`), else for DELIVERY_WALL_S, so the message is in
        SITL's socket before SITL's next step."""
        self._sending += 1
        self._update()
        try:
            if delivered is None:
                await asyncio.sleep(DELIVERY_WALL_S)
            else:
                await self._until(delivered, bound_wall_s=RELAYED_MAX_WALL_S, counted=False)
        finally:
            self._sending -= 1
            self._update()

    @contextlib.contextmanager
    def exchanging(self, answered: Callable[[], bool] | None = None, *, sends: str | None = None):
        """The running task waits for the vehicle's answer, which SITL gives only while time passes. Time
        stands for EXCHANGE_DELIVERY_WALL_S first (MAVSDK sends the request from a thread of its own, and it
        must be in SITL's socket before SITL's next step), then runs in EXCHANGE_STEP_S steps, and a sensor
        task that waits holds none. Once `answered()` is true (the answer has been read off the link), time
        holds until the exchange ends: how long the answer then takes to reach the waiting task is wall
        time, which must not move the vehicle's."""
        task = asyncio.current_task()
        marked = task in self._participants and task not in self._asleep
        if marked:
            self._asleep[task] = math.inf
        self._exchanges += 1
        entered_wall_s = time.monotonic()
        relayed = self.handing(sends) if sends is not None else None

        def delivered() -> bool:  # by the relay's count of `sends` (the request), else by wall time
            if relayed is not None and time.monotonic() - entered_wall_s < RELAYED_MAX_WALL_S:
                return relayed()
            return time.monotonic() - entered_wall_s >= EXCHANGE_DELIVERY_WALL_S

        self._undelivered.append(delivered)
        if answered is not None:
            self._answered.append(answered)
        self._update()  # which looks again until the request is delivered (see _apply)
        try:
            yield
        finally:
            self._exchanges -= 1
            self._undelivered.remove(delivered)
            if answered is not None:
                self._answered.remove(answered)
            if marked:
                self._asleep.pop(task, None)
            self._update()

    async def answered(self, answered: Callable[[], bool]) -> None:
        """In an exchange whose answer the running task has: return once this clock has read the answer off
        the link too (`answered()`), the physics stands at the end of the step under way with SITL's next
        packet in, and all SITL sent is taken in; each within its wall bound (the wake after is then counted
        in `unsettled`). What the task sends next then reaches SITL while SITL waits at that step. Before
        the clock holds anything (no task has slept on it yet: connecting), it returns at once."""
        if self._loop is None or not await self._until(answered, bound_wall_s=RELAYED_MAX_WALL_S):
            return
        self._update()
        if not await self._until(lambda: self._gate.waiting and self.now_s() >= self._exchange_step_s - REACHED_S,
                                 bound_wall_s=SITL_LOOP_MAX_WALL_S):
            return
        if self._relay is not None and self.listened is not None and self._reconciled:
            await self._take_in_relayed()

    async def _until(self, condition: Callable[[], bool], *, bound_wall_s: float, counted: bool = True) -> bool:
        """Wait until `condition()`, looking again at each `nudge` (at least every LOOK_WALL_S); False (counted
        in `unsettled` if `counted`) when `bound_wall_s` passed first."""
        if condition():
            return True
        loop = asyncio.get_running_loop()
        deadline_wall_s = time.monotonic() + bound_wall_s
        while True:
            remaining_wall_s = deadline_wall_s - time.monotonic()
            if remaining_wall_s < 0:
                if counted:
                    self.unsettled += 1
                return False
            changed = loop.create_future()
            # Registered before the condition is read again: a change made meanwhile on another thread
            # either shows in the condition or finds this wait to nudge.
            self._change_waiters.add(changed)
            try:
                if condition():
                    return True
                look = loop.call_later(min(remaining_wall_s, LOOK_WALL_S), _resolve, changed)
                try:
                    await changed
                finally:
                    look.cancel()
            finally:
                self._change_waiters.discard(changed)
            if condition():
                return True

    def nudge(self) -> None:
        """What a wait for a condition reads, or a request's delivery, may have changed: they are looked at
        again (on the event loop's thread)."""
        for changed in self._change_waiters:
            _resolve(changed)
        if self._delivery_look is not None:
            self._update()

    def nudge_threadsafe(self) -> None:
        """`nudge` from another thread (the physics', the relay's); nothing when nothing looks."""
        loop = self._loop
        if (self._change_waiters or self._delivery_look is not None) and loop is not None:
            try:
                loop.call_soon_threadsafe(self.nudge)
            except RuntimeError:  # the loop closed meanwhile: the trial is over
                pass

    def _holders(self) -> list[str]:
        return sorted(task.get_name() for task in self._participants if task not in self._asleep)

    def _update(self) -> None:
        # After the callbacks already ready (the tasks just woken) have run and gone back to sleep, so the
        # hold is the earliest of all their new deadlines.
        if self._loop is not None:
            self._after_ready.schedule(self._loop)

    def _apply(self) -> None:
        if self._settling:
            return  # the hold stays until the messages are in and the sleepers due are woken
        while self._sleepers and self._sleepers[0][2].done():
            heapq.heappop(self._sleepers)
        now_s = self.now_s()
        wake_s = self._sleepers[0][0] if self._sleepers else math.inf
        undelivered = not all(delivered() for delivered in self._undelivered)
        if undelivered and self._delivery_look is None:
            # Without a relay nothing tells this clock when a request is delivered (a wall time passes), and
            # with one the relay's nudge does: look again until it is, else time would stand.
            self._delivery_look = self._loop.call_later(SETTLE_WALL_S if self._relay is None else LOOK_WALL_S,
                                                        self._look_at_delivery)
        elif not undelivered and self._delivery_look is not None:
            # Delivered: no look is needed after this one.
            self._delivery_look.cancel()
            self._delivery_look = None
        if self._holders() or self._sending or undelivered:
            # A reading is being made or a request is on its way to SITL: the vehicle waits.
            hold_s = now_s
        elif any(answered() for answered in self._answered):
            # An answer is on its way to its task: the vehicle waits at the end of the step under way, the
            # same vehicle time whenever this machine read the answer.
            hold_s = max(now_s, self._exchange_step_s)
        elif self._exchanges:
            if self._exchange_step_s <= now_s + REACHED_S:
                self._exchange_step_s = now_s + EXCHANGE_STEP_S
            # Told there, to step on. A step under way keeps its end, however often this runs meanwhile.
            self._exchange_step_s = hold_s = wake_s = min(wake_s, self._exchange_step_s)
        else:
            hold_s = None if math.isinf(wake_s) else wake_s
        self._gate.hold_at(hold_s)
        if not math.isinf(wake_s):
            self._gate.wake_at(wake_s, self._woken)

    def _look_at_delivery(self) -> None:
        self._delivery_look = None
        self._update()

    # ---------------------------------------------------------------- waking

    def _woken(self, _time_s: float) -> None:
        """From the physics' thread (or this one): its time reached the earliest deadline."""
        loop = self._loop
        if loop is None or loop.is_closed():
            return
        try:
            loop.call_soon_threadsafe(self._wake_due)
        except RuntimeError:  # the loop closed meanwhile: the trial is over
            pass

    def _wake_due(self) -> None:
        if self.activity is not None:
            if not self._settling:
                self._settling = True
                asyncio.ensure_future(self._settle_then_wake())
            return
        self._wake_sleepers()

    async def _settle_then_wake(self) -> None:
        started_wall_s = time.monotonic()
        try:
            # SITL writes out what a loop sent before it asks for its next step (HAL_SITL: the loop, then
            # the serial ports' ticks, then the next servo packet): once the physics stands at the hold
            # with that packet, everything SITL sent up to this time is on its way here.
            self.waiting_for_sitl = True
            await self._until(lambda: self._gate.waiting, bound_wall_s=SITL_LOOP_MAX_WALL_S)
            self.waiting_for_sitl = False
            if self._relay is not None and self.listened is not None and self._reconciled:
                await self._take_in_relayed()
                return
            deadline_wall_s = time.monotonic() + SETTLE_MAX_WALL_S
            while self._unread is not None and self._unread() > 0 and time.monotonic() < deadline_wall_s:
                await asyncio.sleep(0)
            seen = self.activity()
            while True:
                await asyncio.sleep(SETTLE_WALL_S)
                now = self.activity()
                if now == seen:
                    break
                seen = now
                if time.monotonic() > deadline_wall_s:
                    self.unsettled += 1
                    break
            if self._relay is not None and self.listened is not None:
                # What SITL sent before MAVSDK listened, or before the vehicle read MAVSDK's stream, was never
                # taken in: counted from here on, each message is.
                relayed, listened = self._relay.from_sitl, self.listened
                self._forgiven = collections.Counter({name: relayed[name] - listened[name] for name in self.taken_in
                                                      if relayed[name] > listened[name]})
                self._reconciled = True
        finally:
            self._settling = False
            self.settles += 1
            self.settle_wall_s += time.monotonic() - started_wall_s
            self._wake_sleepers()

    async def _take_in_relayed(self) -> None:
        """Wait until the relay has passed on all SITL sent and the vehicle has taken in as many of each
        message it reads as the relay passed on; one never taken in within the bound is forgiven after."""
        if not await self._until(lambda: not self._behind(), bound_wall_s=RELAYED_MAX_WALL_S):
            self._forgiven.update({name: count for name, count in self._behind().items() if name in self.taken_in})

    def _behind(self) -> dict[str, int]:
        """What the vehicle has yet to take in of what the relay passed on, by name ("(relay)": the relay has
        yet to pass on something of SITL's)."""
        if not self._relay.idle():
            return {"(relay)": 1}
        relayed, listened = self._relay.from_sitl, self.listened
        return {name: relayed[name] - self._forgiven[name] - listened[name] for name in self.taken_in
                if relayed[name] - self._forgiven[name] > listened[name]}

    def _wake_sleepers(self) -> None:
        now_s = self.now_s()
        while self._sleepers and self._sleepers[0][0] <= now_s + REACHED_S:
            _, _, future = heapq.heappop(self._sleepers)
            if not future.done():
                future.set_result(None)
                self.wakes += 1
        self._update()

    def _stalled(self, silent_wall_s: float) -> None:
        holders = self._holders()
        if holders:
            raise WaitTimeout(operation="lock-step clock: time to pass", timeout_s=round(silent_wall_s, 1),
                              last_state=f"sensor tasks {', '.join(holders)} hold the vehicle's time")
        if any(answered() for answered in self._answered):
            raise WaitTimeout(operation="lock-step clock: time to pass", timeout_s=round(silent_wall_s, 1),
                              last_state="an answer read off the link has not reached the task waiting for it")
        if self._gate.waiting:  # SITL's packet is here, held by this clock: say what else holds it
            raise WaitTimeout(operation="lock-step clock: time to pass", timeout_s=round(silent_wall_s, 1),
                              last_state=f"the physics stands at {self.now_s():.3f} s with SITL's packet in, held "
                                         f"by this clock ({self._sending} messages being sent, "
                                         f"{self._exchanges} exchanges, settling {self._settling})")
        raise LinkLost(operation="lock-step physics", reason=f"SITL sent no servo packet for "
                                                             f"{silent_wall_s:.0f} wall s")


def _resolve(future: asyncio.Future) -> None:
    if not future.done():
        future.set_result(None)


def udp_receive_queue(port: int, *, table: str = "/proc/net/udp") -> int:
    """The receive queue (bytes the kernel holds for it, unread; 0 when all is read) of this machine's UDP
    socket bound to `port`, from Linux's /proc/net/udp; 0 where the table cannot be read or has no such
    socket."""
    try:
        with open(table, encoding="ascii") as rows:
            next(rows, None)
            for row in rows:
                fields = row.split()
                if len(fields) > 4 and int(fields[1].rpartition(":")[2], 16) == port:
                    return int(fields[4].partition(":")[2], 16)
    except (OSError, ValueError):
        pass
    return 0

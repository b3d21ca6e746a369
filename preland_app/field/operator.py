"""The person beside the vehicle in a field campaign: what the campaign asks them, and the answers.

A field campaign asks three things: to carry the vehicle back to the start
(`between_trials: operator`), to deal with a pause (swap the battery, land
after a takeover, fix what a preflight check refused), and after each landing
the tape-measured error. `TerminalOperator` asks at the terminal;
`ScriptedOperator` reads the measurements from an answers file (`--answers`,
for rehearsals and tests) and, having nobody to act on a pause, stops the
campaign there so that `--resume` continues it.

The answers file is CSV with the header `scenario,trial,error_cm,x_cm,y_cm`
(`x_cm`, `y_cm` may be left empty or left out); `trial` counts from 0;
`error_cm` is a number in cm, or `skip` (stored as not measured), `redo` (the
trial is flown again) or `abort` (the campaign stops). A trial flown more than
once takes its rows in order: `redo` then a number answers a redone trial.
"""

from __future__ import annotations

import csv
import enum
import math
from collections import defaultdict, deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

from ..campaign.field_records import OFFSET_TOLERANCE_CM
from ..errors import PrelandError

ANSWER_COLUMNS = ("scenario", "trial", "error_cm", "x_cm", "y_cm")
REQUIRED_COLUMNS = ANSWER_COLUMNS[:3]


class AnswersError(PrelandError):
    """An answers file that cannot be used: the message names the file, the line and the field."""


class Verdict(enum.Enum):
    """The operator's answer after a landing."""

    MEASURED = "measured"
    SKIP = "skip"
    REDO = "redo"
    ABORT = "abort"


class Pause(enum.Enum):
    """Why a field campaign waits for the operator."""

    CARRY_BACK = "carry the vehicle back to the start"
    BATTERY = "battery swap"
    TAKEOVER = "pilot takeover"
    LINK_LOST = "link lost"
    PREFLIGHT = "preflight check failed"
    VEHICLE_AWAY = "vehicle away from the start"


@dataclass(frozen=True, kw_only=True)
class Measurement:
    """What the operator answered after a landing: a verdict, and for MEASURED the error in cm and, if
    taken, its offsets (`x_cm` north, `y_cm` east, cm)."""

    verdict: Verdict
    error_cm: float | None = None
    x_cm: float | None = None
    y_cm: float | None = None


class Operator(Protocol):
    """The person beside the vehicle."""

    def confirm(self, pause: Pause, message: str) -> bool:
        """Ask the operator to act on `pause` (`message` says what is needed); True once done, False to stop
        the campaign there (it resumes with `--resume`)."""

    def measure(self, *, scenario: str, trial_index: int) -> Measurement:
        """The tape-measured result of the trial that just landed."""


def parse_answer(text: str, *, where: str) -> Measurement:
    """An `error_cm` answer: a number of cm >= 0, or skip, redo, abort; AnswersError naming `where`."""
    word = text.strip().lower()
    for verdict in (Verdict.SKIP, Verdict.REDO, Verdict.ABORT):
        if word == verdict.value:
            return Measurement(verdict=verdict)
    value = _number(text, where=where)
    if value is None:
        raise AnswersError(f"{where}: empty (a number of cm, skip, redo or abort)")
    if value < 0:
        raise AnswersError(f"{where}: {value:g} cm is negative (a distance is >= 0)")
    return Measurement(verdict=Verdict.MEASURED, error_cm=value)


def _number(text: str, *, where: str) -> float | None:
    if not text.strip():
        return None
    try:
        value = float(text)
    except ValueError:
        raise AnswersError(f"{where}: {text.strip()!r} is not a number, skip, redo or abort") from None
    if not math.isfinite(value):
        raise AnswersError(f"{where}: {text.strip()!r} is not a finite number")
    return value


def load_answers(path: str | Path, *, trials: dict[str, int]) -> dict[tuple[str, int], deque[Measurement]]:
    """Read an answers file against the campaign's scenarios (`trials`: label -> trials in it). AnswersError
    names the file, line and column of the first problem: an unknown column or scenario, a trial out of
    range, a value that is not a number, skip, redo or abort."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as error:
        raise AnswersError(f"{path}: cannot read it ({error.strerror or error})") from None
    except UnicodeDecodeError:
        raise AnswersError(f"{path}: not a UTF-8 text file") from None
    reader = csv.DictReader(text.splitlines())
    header = tuple(name.strip() for name in reader.fieldnames or ())
    unknown = [name for name in header if name not in ANSWER_COLUMNS]
    missing = [name for name in REQUIRED_COLUMNS if name not in header]
    if unknown or missing:
        raise AnswersError(f"{path} line 1: the header must be {','.join(ANSWER_COLUMNS)} (x_cm, y_cm optional); "
                           + (f"unknown column {unknown[0]!r}" if unknown else f"missing column {missing[0]!r}"))
    answers: dict[tuple[str, int], deque[Measurement]] = defaultdict(deque)
    for line, raw in enumerate(reader, start=2):
        row = {(key or "").strip(): (value or "") for key, value in raw.items()}
        scenario = row["scenario"].strip()
        if scenario not in trials:
            raise AnswersError(f"{path} line {line}, scenario: {scenario!r} is not a scenario of the campaign "
                               f"(it has: {', '.join(trials)})")
        try:
            trial = int(row["trial"])
        except ValueError:
            raise AnswersError(f"{path} line {line}, trial: {row['trial'].strip()!r} is not a trial number") from None
        if not 0 <= trial < trials[scenario]:
            raise AnswersError(f"{path} line {line}, trial: {trial} is out of range (scenario {scenario!r} has "
                               f"trials 0..{trials[scenario] - 1})")
        answer = parse_answer(row["error_cm"], where=f"{path} line {line}, error_cm")
        x_cm = _number(row.get("x_cm", ""), where=f"{path} line {line}, x_cm")
        y_cm = _number(row.get("y_cm", ""), where=f"{path} line {line}, y_cm")
        if (x_cm is None) != (y_cm is None):
            raise AnswersError(f"{path} line {line}, x_cm/y_cm: give both offsets or neither")
        if x_cm is not None and answer.verdict is not Verdict.MEASURED:
            raise AnswersError(f"{path} line {line}, x_cm/y_cm: offsets only with a measured error_cm")
        if x_cm is not None and abs(math.hypot(x_cm, y_cm) - answer.error_cm) > OFFSET_TOLERANCE_CM:
            raise AnswersError(f"{path} line {line}, x_cm/y_cm: their length {math.hypot(x_cm, y_cm):.1f} cm is "
                               f"not error_cm {answer.error_cm:g} cm (within {OFFSET_TOLERANCE_CM:g} cm)")
        answers[(scenario, trial)].append(Measurement(verdict=answer.verdict, error_cm=answer.error_cm,
                                                      x_cm=x_cm, y_cm=y_cm))
    return dict(answers)


class ScriptedOperator:
    """Answers from an answers file (`load_answers`); nobody to act on a pause, so a pause stops the campaign
    (except carrying the vehicle back, confirmed at once: a rehearsal's vehicle needs nobody to carry it).
    `said` keeps every line the campaign addressed to the operator."""

    def __init__(self, answers: dict[tuple[str, int], deque[Measurement]], *, source: str = "answers") -> None:
        self._answers = {key: deque(rows) for key, rows in answers.items()}
        self.source = source
        self.said: list[str] = []

    def confirm(self, pause: Pause, message: str) -> bool:
        self.said.append(message)
        return pause is Pause.CARRY_BACK

    def measure(self, *, scenario: str, trial_index: int) -> Measurement:
        rows = self._answers.get((scenario, trial_index))
        if not rows:
            raise AnswersError(f"{self.source}: no answer for scenario {scenario!r} trial {trial_index}")
        return rows.popleft()


class TerminalOperator:
    """Asks at the terminal: `ask(prompt) -> str` reads one answer (typer.prompt in the CLI) and `say`
    prints a line."""

    def __init__(self, *, ask: Callable[[str], str], say: Callable[[str], None]) -> None:
        self._ask = ask
        self._say = say

    def confirm(self, pause: Pause, message: str) -> bool:
        self._say(message)
        while True:
            answer = self._ask("press Enter when done, or type abort to stop here").strip().lower()
            if answer in ("", "y", "yes", "done", "ok"):
                return True
            if answer == "abort":
                return False

    def measure(self, *, scenario: str, trial_index: int) -> Measurement:
        where = f"{scenario} #{trial_index}"
        while True:
            try:
                answer = parse_answer(self._ask(f"{where}: landing error in cm (or skip, redo, abort)"),
                                      where="error")
                break
            except AnswersError as error:
                self._say(str(error))
        if answer.verdict is not Verdict.MEASURED:
            return answer
        while True:  # the offsets, asked again until they are none or agree with the error
            offsets = self._ask("x (north) and y (east) offsets in cm, e.g. 3.5 -2 (Enter: not taken)").split()
            if not offsets:
                return answer
            try:
                x_cm, y_cm = (float(value) for value in offsets)
            except ValueError:
                self._say("offsets: give two numbers, x then y, or nothing")
                continue
            if abs(math.hypot(x_cm, y_cm) - answer.error_cm) > OFFSET_TOLERANCE_CM:
                self._say(f"offsets: their length {math.hypot(x_cm, y_cm):.1f} cm is not the error "
                          f"{answer.error_cm:g} cm; measure again")
                continue
            return Measurement(verdict=Verdict.MEASURED, error_cm=answer.error_cm, x_cm=x_cm, y_cm=y_cm)

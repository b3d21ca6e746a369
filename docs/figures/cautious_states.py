"""figures/cautious-states.png: the cautious landing's states and transitions, from the code.

Two machines run during a cautious landing: the companion's (`landing/cautious_retry.py`, `RetryPhase`: the
thesis' sequence, which normally acts first, 1 s after the last target value) and the embedded autopilot's own
retry (`sim/precland_retry.py`, `RetryState`: ArduPilot's AC_PrecLand_StateMachine). The states are each
enum's members, iterated, so a new one appears (dashed, at the bottom) until its transitions are drawn. The
transitions are written here from reading the code; `entered_in_code` finds, with `ast`, every state the code
enters, and the test checks that the drawn transitions arrive at exactly those. The defaults in the footers
are `CautiousSpec`'s fields and the modules' constants.
"""

from __future__ import annotations

import ast
import dataclasses
import enum
import sys
from dataclasses import dataclass
from pathlib import Path

if __name__ == "__main__":  # run alone: no __pycache__ in docs/, the site's source
    sys.dont_write_bytecode = True
import _figkit  # noqa: E402

import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

from preland_app.landing import cautious_retry  # noqa: E402
from preland_app.landing.cautious import CautiousSpec  # noqa: E402
from preland_app.sim import precland_retry  # noqa: E402

SEEN, RETRY, SPENT = "#2e7d32", "#1565c0", "#c62828"  # lane colours: target back, new attempt, retries spent


@dataclass(frozen=True)
class Machine:
    """One state machine as drawn: states top to bottom (`order`; members missing from it go last), arrows
    between neighbours (`steps`: source, target, label), lanes that gather several sources into one target
    (`lanes`: side, colour, sources, target, label) and notes on what a state does while it stays."""

    title: str
    states: type[enum.Enum]
    source: Path
    order: tuple[str, ...]
    steps: tuple[tuple[str, str, str], ...]
    lanes: tuple[tuple[str, str, tuple[str, ...], str, str], ...]
    notes: tuple[tuple[str, str, str], ...]
    footer: str

    def members(self) -> list[str]:
        """Every state of the enum, in the drawing's order."""
        names = [member.name for member in self.states]
        return [n for n in self.order if n in names] + [n for n in names if n not in self.order]

    def targets(self) -> set[str]:
        """The states the drawn transitions arrive at."""
        return {target for _, target, _ in self.steps} | {lane[3] for lane in self.lanes}


def entered_in_code(source: Path, enum_name: str) -> set[str]:
    """The states `source` enters: `Enum.MEMBER` in the arguments of its `_enter(...)` and `_go(...)` calls,
    directly or through a name the same function assigned (`arrived = Enum.A if ... else Enum.B`)."""
    def members(node) -> set[str]:
        return {n.attr for n in ast.walk(node) if isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name)
                and n.value.id == enum_name}

    entered = set()
    for function in ast.walk(ast.parse(source.read_text(encoding="utf-8"))):
        if not isinstance(function, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        assigned: dict[str, set[str]] = {}
        for node in ast.walk(function):
            if isinstance(node, ast.Assign):
                for target in node.targets:
                    if isinstance(target, ast.Name):
                        assigned.setdefault(target.id, set()).update(members(node.value))
        for node in ast.walk(function):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) \
                    and node.func.attr in ("_enter", "_go"):
                for argument in node.args:
                    entered |= members(argument)
                    if isinstance(argument, ast.Name):
                        entered |= assigned.get(argument.id, set())
    return entered


def _defaults() -> str:
    spec = CautiousSpec()
    return ", ".join(f"{f.name} {getattr(spec, f.name):g}" if not isinstance(getattr(spec, f.name), bool)
                     else f"{f.name} {str(getattr(spec, f.name)).lower()}" for f in dataclasses.fields(spec))


PACKAGE = _figkit.ROOT / "preland_app"
COMPANION = Machine(
    title="The cautious landing on the companion: landing/cautious_retry.py, RetryPhase",
    states=cautious_retry.RetryPhase,
    source=PACKAGE / "landing" / "cautious_retry.py",
    order=("TRACKING", "PAUSED", "RETURNING", "AT_LAST_SEEN", "CLIMBING", "AT_DEFAULT", "FAILSAFE", "BLIND"),
    steps=(
        ("TRACKING", "PAUSED", "target lost (no new value for lost_after_s) in LAND,\n"
                               "rangefinder within PLND_ALT_MIN..PLND_ALT_MAX,\n"
                               "PLND_STRICT != 0: GUIDED, hold (hold_while_waiting)"),
        ("RETURNING", "AT_LAST_SEEN", f"within {cautious_retry.ARRIVED_M:g} m of the goal "
                                      f"(or {cautious_retry.MOVE_TIMEOUT_S:g} s)"),
        ("AT_LAST_SEEN", "CLIMBING", f"PLND_TIMEOUT, goal over {cautious_retry.ARRIVED_M:g} m below\n"
                                     "retry_height_m (> 0): climb to it"),
        ("CLIMBING", "AT_DEFAULT", f"within {cautious_retry.ARRIVED_M:g} m (or {cautious_retry.MOVE_TIMEOUT_S:g} s)"),
        ("FAILSAFE", "BLIND", "failsafe_hold_s, PLND_STRICT != 2:\nLAND without the target"),
    ),
    lanes=(
        ("left", SEEN, ("PAUSED", "AT_LAST_SEEN", "AT_DEFAULT", "FAILSAFE"), "TRACKING",
         "target seen since\nentering the state:\nLAND"),
        ("right", RETRY, ("PAUSED", "AT_LAST_SEEN", "AT_DEFAULT"), "RETURNING",
         "PLND_TIMEOUT, retries <\nPLND_RET_MAX (from AT_LAST_SEEN:\nno climb needed): attempt + 1,\n"
         f"back to where it last saw the\ntarget, {cautious_retry.RETRY_OFFSET_ALT_M:g} m higher"),
        ("right", SPENT, ("PAUSED", "AT_LAST_SEEN", "AT_DEFAULT"), "FAILSAFE",
         "PLND_TIMEOUT, retries =\nPLND_RET_MAX: hold there"),
    ),
    notes=(
        ("TRACKING", "right", "lost outside PLND_ALT_MIN..PLND_ALT_MAX,\nor PLND_STRICT 0: LAND goes on"),
        ("FAILSAFE", "below", "PLND_STRICT 2: hover until the\ntarget is back (or the land timeout)"),
    ),
    footer="defaults (landing/cautious.py, CautiousSpec): " + _defaults(),
)
AUTOPILOT = Machine(
    title="The embedded autopilot's own retry, as ArduPilot's: sim/precland_retry.py, RetryState",
    states=precland_retry.RetryState,
    source=PACKAGE / "sim" / "precland_retry.py",
    order=("TRACKING", "WAITING", "RETRY_CLIMB", "RETRY_SETTLE", "FAILSAFE_HOLD", "BLIND"),
    steps=(
        ("TRACKING", "WAITING", "target lost after a first sighting, rangefinder\n"
                                "within PLND_ALT_MIN..PLND_ALT_MAX, PLND_STRICT != 0"),
        ("WAITING", "RETRY_CLIMB", "PLND_TIMEOUT (descending meanwhile),\nretries < PLND_RET_MAX: retries + 1"),
        ("RETRY_CLIMB", "RETRY_SETTLE", f"within {precland_retry.MAX_POS_ERROR_M:g} m of where it last saw it, "
                                        f"{precland_retry.RETRY_OFFSET_ALT_M:g} m up\n(PLND_RET_BEHAVE 1: above the "
                                        "target's\nestimate)"),
        ("RETRY_SETTLE", "FAILSAFE_HOLD", f"back down to that height (within {precland_retry.MAX_POS_ERROR_M:g} m):"
                                          "\nretry completed"),
        ("FAILSAFE_HOLD", "BLIND", f"{precland_retry.FAILSAFE_INIT_TIMEOUT_S:g} s, PLND_STRICT != 2:\n"
                                   "descend without the target"),
    ),
    lanes=(
        ("left", SEEN, ("WAITING", "RETRY_CLIMB", "RETRY_SETTLE", "FAILSAFE_HOLD"), "TRACKING",
         "target found:\ndescend on it"),
        ("right", SPENT, ("WAITING",), "FAILSAFE_HOLD", "PLND_TIMEOUT,\nretries = PLND_RET_MAX"),
    ),
    notes=(
        ("TRACKING", "right", "each new LAND starts here\nwith no retries (reset)"),
        ("FAILSAFE_HOLD", "below", "PLND_STRICT 2: hold until\nthe target is found"),
    ),
    footer="the companion acts first: lost_after_s 1 s against the autopilot's 2 s without a LANDING_TARGET",
)
MACHINES = (COMPANION, AUTOPILOT)

# Panel geometry, data units: one column of states, lanes beside it, labels in the gaps.
COLUMN_X, BOX_W, BOX_H, ROW = 6.2, 3.5, 0.78, 1.62
LEFT_LANE_X = COLUMN_X - BOX_W / 2 - 0.75
RIGHT_LANES_X = (11.7, 12.3)
WIDTH = 17.0


def _draw(axes, machine: Machine) -> None:
    members = machine.members()
    y = {name: -ROW * i for i, name in enumerate(members)}
    unknown = set(members) - set(machine.order)
    for name in members:
        new = name in unknown
        fill = _figkit.COLORS["end"] if name == "BLIND" else _figkit.COLORS["state"]
        value = machine.states[name].value
        _figkit.box(axes, COLUMN_X, y[name], BOX_W, BOX_H, name,
                    (f"'{value}'" + ("  new: transitions not drawn" if new else ""),),
                    fill="#ffffff" if new else fill, linestyle="--" if new else "-", title_size=10, line_size=8)
    right_edge, left_edge = COLUMN_X + BOX_W / 2, COLUMN_X - BOX_W / 2
    for source, target, label in machine.steps:
        if members.index(target) != members.index(source) + 1:
            raise ValueError(f"{machine.title}: step {source} -> {target} is not to the next state; make it a lane")
        _figkit.arrow(axes, (COLUMN_X, y[source] - BOX_H / 2), (COLUMN_X, y[target] + BOX_H / 2), label=label,
                      label_pos=0.5, label_offset=(0.18, 0), label_ha="left", label_size=8.3)
    rights = [lane for lane in machine.lanes if lane[0] == "right"]
    for side, color, sources, target, label in machine.lanes:
        if side == "left":
            x, edge, dy = LEFT_LANE_X, left_edge, 0.0
        else:
            index = rights.index((side, color, sources, target, label))
            x, edge = RIGHT_LANES_X[index], right_edge
            dy = 0.14 * (1 - 2 * index) if len(rights) > 1 else 0.0  # two lanes' stubs apart on one box
        ys = [y[s] + dy for s in sources] + [y[target] + dy]
        for s in sources:
            axes.add_line(Line2D([edge, x], [y[s] + dy] * 2, color=color, lw=1.4, zorder=2))
            axes.plot([x], [y[s] + dy], marker="o", ms=3.5, color=color, zorder=2)
        axes.add_line(Line2D([x, x], [min(ys), max(ys)], color=color, lw=1.4, zorder=2))
        _figkit.arrow(axes, (x, y[target] + dy), (edge, y[target] + dy), color=color, width=1.4)
        if side == "left":
            middle = (y[target] + y[sources[0]]) / 2
            axes.text(x - 0.2, middle, label, ha="right", va="center", fontsize=8.3, color=color)
        else:
            axes.text(RIGHT_LANES_X[-1] + 0.3, y[target] + dy, label, ha="left", va="center", fontsize=8.3,
                      color=color)
    for name, where, text in machine.notes:
        if where == "right":
            axes.text(right_edge + 0.25, y[name], text, ha="left", va="center", fontsize=8.3, style="italic",
                      color="#424242")
        else:
            axes.text(COLUMN_X - 0.18, y[name] - ROW / 2, text, ha="right", va="center", fontsize=8.3,
                      style="italic", color="#424242")
    axes.set_xlim(0, WIDTH)
    bottom = y[members[-1]] - BOX_H / 2 - 0.75
    axes.set_ylim(bottom, BOX_H / 2 + 0.35)
    axes.set_title(machine.title, fontsize=11, fontweight="bold", loc="left")
    axes.text(0.1, bottom + 0.3, machine.footer, fontsize=7.6, color="#455a64", ha="left", va="center", wrap=True)
    axes.set_axis_off()


def make(out_dir: Path) -> list[Path]:
    heights = [len(machine.members()) * ROW + 1.3 for machine in MACHINES]
    scale = 9.3 / WIDTH  # inches per data unit, the same in both panels and both directions
    figure, panels = plt.subplots(len(MACHINES), 1, figsize=(9.3, sum(heights) * scale + 0.4),
                                  gridspec_kw={"height_ratios": heights}, layout="constrained")
    for axes, machine in zip(panels, MACHINES):
        _draw(axes, machine)
    return [_figkit.save(figure, out_dir / "cautious-states.png")]


if __name__ == "__main__":
    _figkit.run_alone(make)

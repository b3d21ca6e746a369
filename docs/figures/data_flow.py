"""figures/data-flow.png: one trial's data flow, from the campaign file to the report, each box naming the
modules (paths under `preland_app/`) and the functions and classes that do that step.

The layout is drawn by hand; the names are checked: `unknown_names()` parses each named module with `ast`
and lists every path or name it does not define, and `make` refuses to draw a box that names one.
"""

from __future__ import annotations

import ast
import re
import sys
from dataclasses import dataclass
from pathlib import Path

if __name__ == "__main__":  # run alone: no __pycache__ in docs/, the site's source
    sys.dont_write_bytecode = True
import _figkit  # noqa: E402

import matplotlib.pyplot as plt  # noqa: E402

PACKAGE = _figkit.ROOT / "preland_app"


@dataclass(frozen=True)
class Box:
    """A step: centre (x, y) and size in data units, a title, and lines `path.py: Name, Name` (paths under
    preland_app/, or under the repository for other files; a folder path ends in `/`) or plain text."""

    key: str
    x: float
    y: float
    width: float
    height: float
    title: str
    lines: tuple[str, ...]
    color: str


C = _figkit.COLORS
BOXES = (
    Box("file", 2.35, 12.4, 4.3, 1.55, "campaign file", ("campaigns/thesis_table3.yaml", "mission, base_seed,",
                                                         "scenarios (land, faults)"), C["input"]),
    Box("scenario", 7.25, 12.4, 4.9, 1.55, "scenarios", ("campaign/spec.py:", "load_campaign,",
                                                         "resolve_scenarios"), C["campaign"]),
    Box("trial", 12.45, 12.4, 4.9, 1.55, "trials and seeds", ("campaign/trials.py:", "plan_trials, TrialJob,",
                                                              "derive_seed"), C["campaign"]),
    Box("driver", 17.55, 12.4, 4.7, 1.55, "driver, executors", ("campaign/driver.py: run_campaign",
                                                                "campaign/executors/:", "LocalExecutor, RayExecutor"),
        C["campaign"]),
    Box("sensors", 3.9, 9.4, 7.4, 2.1, "sensors (the companion's)", (
        "sensing/suite.py: SensorSuite", "sensing/virtual_camera.py: VirtualCamera",
        "sensing/marker.py: TrackingMarkerDetector", "sensing/irlock.py: IrLockModel",
        "sensing/faults.py: FaultInjector"), C["sensing"]),
    Box("runtime", 15.55, 9.4, 8.5, 2.1, "runtime (sim:, sitl:, mavlink+): fly()", (
        "runtime/base.py: TrialRequest, open_runtime", "runtime/embedded.py: EmbeddedRuntime",
        "runtime/sitl.py: SitlRuntime", "runtime/mavlink.py: MavlinkRuntime"),
        C["runtime"]),
    Box("land", 3.65, 6.45, 6.5, 1.55, "land mode", ("landing/base.py: LandStrategy, LandingContext",
                                                    "landing/precision.py: PrecisionLanding",
                                                    "landing/boundary.py: SensorView"), C["mission"]),
    Box("runner", 10.85, 6.45, 4.3, 1.55, "mission runner", ("mission.py: MissionRunner",
                                                            "take-off, path, hand-over"), C["mission"]),
    Box("vehicle", 7.6, 3.85, 12.6, 1.3, "Vehicle protocol", (
        "vehicle/protocol.py: Vehicle, Vehicle.send_landing_target",
        "vehicle/sim_backend.py: SimVehicle | vehicle/mavlink_backend.py: MavlinkVehicle"), C["vehicle"]),
    Box("autopilot", 7.3, 1.3, 8.6, 1.55, "autopilot (LAND, precision landing)", (
        "sim/autopilot.py: Autopilot", "sim/precland.py: PrecisionLandingEstimator",
        "ArduPilot AC_PrecLand (SITL, a drone)"), C["autopilot"]),
    Box("truth", 17.4, 3.85, 5.0, 1.3, "ground truth", ("sim/simulator.py: Simulator.true_pose",
                                                        "runtime/mavlink.py: SimStateTruth"), C["runtime"]),
    Box("score", 17.4, 1.3, 5.0, 1.55, "scoring", ("outcome.py: score_touchdown",
                                                   "runtime/recorder.py:", "TrajectoryRecorder"), C["results"]),
    Box("outcome", 15.1, -1.35, 4.4, 1.3, "TrialOutcome", ("outcome.py: TrialOutcome",
                                                           "campaign/trials.py: run_job"), C["results"]),
    Box("store", 8.9, -1.35, 4.6, 1.3, "results store (SQLite)", ("campaign/store.py:",
                                                                  "ResultsStore, TrialRecord"), C["results"]),
    Box("report", 2.9, -1.35, 5.2, 1.3, "report", ("campaign/report.py: write_report",
                                                   "campaign/figures.py: write_figures"), C["results"]),
)

# (from, to, label, from side, to side, label offset, x): sides are where on the boxes the arrow starts and ends;
# x: where a vertical arrow runs (None: the middle of what the boxes share in x).
ARROWS = (
    ("file", "scenario", None, "right", "left", (0, 0), None),
    ("scenario", "trial", None, "right", "left", (0, 0), None),
    ("trial", "driver", None, "right", "left", (0, 0), None),
    ("driver", "runtime", "run_job: a TrialRequest per trial", "bottom", "top", (-2.1, 0), None),
    ("runtime", "sensors", "build_sensor_suite", "left", "right", (0, 0.28), None),
    ("runtime", "runner", "MissionRunner(spec, vehicle,\nstrategy, sensors)", "bottom", "top", (-1.75, 0), 12.2),
    ("runtime", "vehicle", "its Vehicle\nbackend", "bottom", "top", (0.75, 0.4), 13.55),
    ("runner", "land", "land(context)", "left", "right", (0, 0.3), None),
    ("sensors", "land", "frames, readings (faults drop values)", "bottom", "top", (0, 0), None),
    ("runner", "vehicle", "arm, takeoff, goto_ned", "bottom", "top", (0, 0), None),
    ("land", "vehicle", "LANDING_TARGET", "bottom", "top", (0, 0), None),
    ("vehicle", "autopilot", "commands and LANDING_TARGET (MAVLink, or direct calls)",
     "bottom", "top", (0, 0), None),
    ("autopilot", "truth", "flies the vehicle", "right", "left", (0, 0), None),
    ("truth", "score", "touchdown, path", "bottom", "top", (0, 0), None),
    ("score", "outcome", None, "bottom", "top", (0, 0), None),
    ("outcome", "store", "TrialRecord", "left", "right", (0, 0.27), None),
    ("store", "report", None, "left", "right", (0, 0), None),
)

_LINE = re.compile(r"^(?P<path>(?:\w+/)+[\w.]*|\w+\.py)(?::\s*(?P<names>.*))?$")  # `path` or `path: names`
_NAMES = re.compile(r"[\w.]+(?:\s*,\s*[\w.]+)*,?")  # a line that only goes on with names


def _defined(path: Path) -> set[str]:
    """Top-level functions, classes and assignments of a module, and `Class.member` for each class member."""
    names = set()
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
            if isinstance(node, ast.ClassDef):
                names.update(f"{node.name}.{member.name}" for member in node.body
                             if isinstance(member, (ast.FunctionDef, ast.AsyncFunctionDef)))
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names.update(t.id for t in targets if isinstance(t, ast.Name))
    return names


def _named(box: Box) -> list[tuple[str, list[str]]]:
    """(path, names) for each module or file a box names; `path:` alone, or names ending in a comma, take
    the names on the next line too."""
    named, pending = [], None
    for line in box.lines:
        for part in (p.strip() for p in line.split(" | ")):
            match = _LINE.match(part)
            if match:
                rest = (match["names"] or "").strip()
                entry = (match["path"], [n.strip() for n in rest.split(",") if n.strip()])
                named.append(entry)
                pending = entry if match["names"] is not None and (not rest or rest.endswith(",")) else None
            elif pending is not None and _NAMES.fullmatch(part):
                pending[1].extend(n.strip() for n in part.split(",") if n.strip())
                pending = pending if part.endswith(",") else None
            else:
                pending = None
    return named


def unknown_names(boxes: tuple[Box, ...] = BOXES) -> list[str]:
    """Every module path or name the boxes give that the tree does not have ('path' or 'path: name')."""
    unknown = []
    for box in boxes:
        for path_text, names in _named(box):
            path = (PACKAGE / path_text) if not path_text.startswith(("campaigns/", "missions/")) \
                else _figkit.ROOT / path_text
            if not path.exists():
                unknown.append(path_text)
                continue
            if path.suffix not in (".py", "") or not names:
                continue
            modules = [path] if path.is_file() else sorted(path.glob("*.py"))
            defined = set().union(*(_defined(module) for module in modules))
            unknown.extend(f"{path_text}: {name}" for name in names if name not in defined)
    return unknown


def _anchor(box: Box, side: str) -> tuple[float, float]:
    return {"left": (box.x - box.width / 2, box.y), "right": (box.x + box.width / 2, box.y),
            "top": (box.x, box.y + box.height / 2), "bottom": (box.x, box.y - box.height / 2)}[side]


def make(out_dir: Path) -> list[Path]:
    unknown = unknown_names()
    if unknown:
        raise ValueError(f"data-flow boxes name what the tree does not have: {', '.join(unknown)}")
    figure, axes = plt.subplots(figsize=(9.4, 8.3), layout="constrained")
    boxes = {box.key: box for box in BOXES}
    for box in BOXES:
        _figkit.box(axes, box.x, box.y, box.width, box.height, box.title, box.lines,
                    fill=box.color, title_size=9.5, line_size=7.4)
    for source, target, label, side_a, side_b, offset, x in ARROWS:
        a, b = boxes[source], boxes[target]
        start, end = _anchor(a, side_a), _anchor(b, side_b)
        if side_a == "bottom" and side_b == "top":
            # Straight down where the boxes overlap in x: the middle of their common span.
            left = max(a.x - a.width / 2, b.x - b.width / 2)
            right = min(a.x + a.width / 2, b.x + b.width / 2)
            if x is not None:
                start, end = (x, start[1]), (x, end[1])
            elif left < right:
                middle = (left + right) / 2 if not (left <= a.x <= right) else a.x
                start, end = (middle, start[1]), (middle, end[1])
        _figkit.arrow(axes, start, end, label=label, label_offset=offset, label_size=7.6)
    axes.set_xlim(-0.1, 20.0)
    axes.set_ylim(-2.2, 13.4)
    axes.set_aspect("equal")
    axes.set_axis_off()
    axes.set_title("One trial's data flow (module paths are under preland_app/)", fontsize=11, fontweight="bold")
    return [_figkit.save(figure, out_dir / "data-flow.png")]


if __name__ == "__main__":
    _figkit.run_alone(make)

"""figures/module-map.png: preland_app's packages and top-level modules and who imports whom, computed from
the source with `ast`.

A unit is a subpackage (`campaign`, with its own subpackages) or a top-level module (`mission.py`). An edge
A -> B: some module of A imports from B; solid when it is imported on loading A, dashed when only inside
functions (the CLI defers nearly all its imports so `preland --help` starts fast). Imports for type checkers
only (`if TYPE_CHECKING:`) are no dependency at run time and are left out. The base modules that nearly
everything imports are drawn as one row at the bottom, and each box lists which of them its unit imports
instead of an arrow to each.
"""

from __future__ import annotations

import ast
import sys
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

if __name__ == "__main__":  # run alone: no __pycache__ in docs/, the site's source
    sys.dont_write_bytecode = True
import _figkit  # noqa: E402

import matplotlib.pyplot as plt  # noqa: E402

PACKAGE = _figkit.ROOT / "preland_app"
AT_LOAD, DEFERRED = "at load", "deferred"
BASE_MIN_IMPORTERS = 3  # a top-level module imported by this many units, importing only base modules, is base


@dataclass
class Graph:
    """`modules`: unit -> number of modules in it; `edges`: (importer, imported) -> AT_LOAD or DEFERRED."""

    modules: dict[str, int] = field(default_factory=dict)
    edges: dict[tuple[str, str], str] = field(default_factory=dict)

    def importers(self, unit: str) -> set[str]:
        return {a for a, b in self.edges if b == unit}

    def imports(self, unit: str) -> set[str]:
        return {b for a, b in self.edges if a == unit}


def unit_of(parts: list[str], package: Path = PACKAGE) -> str:
    """The unit a dotted name under the package belongs to: a subpackage, a top-level module (`name.py`), or
    the package's own `__init__.py` (a name defined there, such as `__version__`)."""
    if parts and (package / parts[0]).is_dir():
        return parts[0]
    if parts and (package / f"{parts[0]}.py").is_file():
        return f"{parts[0]}.py"
    return "__init__.py"


def _imports(tree: ast.Module):
    """(node, inside a function) for every import statement, skipping `if TYPE_CHECKING:` blocks."""
    def walk(node, deferred):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
                for orelse in child.orelse:
                    yield from walk(orelse, deferred)
                continue
            if isinstance(child, (ast.Import, ast.ImportFrom)):
                yield child, deferred
            yield from walk(child, deferred or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef,
                                                                    ast.Lambda)))
    yield from walk(tree, False)


def import_graph(package: Path = PACKAGE) -> Graph:
    """Units and their imports of each other, from every module's source."""
    graph = Graph()
    name = package.name
    for path in sorted(package.rglob("*.py")):
        parts = list(path.relative_to(package).with_suffix("").parts)
        is_init = parts[-1] == "__init__"
        module_package = parts[:-1]  # the package a relative import starts from
        unit = unit_of(parts[:1] if len(parts) > 1 else ([] if is_init else parts), package)
        graph.modules[unit] = graph.modules.get(unit, 0) + 1
        for node, deferred in _imports(ast.parse(path.read_text(encoding="utf-8"))):
            targets: list[list[str]] = []
            if isinstance(node, ast.ImportFrom) and node.level:
                base = module_package[:len(module_package) - (node.level - 1)]
                module = node.module.split(".") if node.module else []
                targets = [base + module] if module else [base + [alias.name] for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == name:
                targets = [node.module.split(".")[1:] or [alias.name for alias in node.names][:1]]
            elif isinstance(node, ast.Import):
                targets = [alias.name.split(".")[1:] for alias in node.names if alias.name.split(".")[0] == name]
            for target in targets:
                imported = unit_of(target, package)
                if imported != unit:
                    edge = (unit, imported)
                    graph.edges[edge] = AT_LOAD if not deferred or graph.edges.get(edge) == AT_LOAD else DEFERRED
    return graph


def base_units(graph: Graph) -> list[str]:
    """Top-level modules nearly everything imports and that import only each other: the bottom row."""
    base: set[str] = set()
    changed = True
    while changed:
        changed = False
        for unit in sorted(graph.modules):
            if unit in base or not unit.endswith(".py") or unit == "__init__.py":
                continue
            if graph.imports(unit) <= base and len(graph.importers(unit)) >= BASE_MIN_IMPORTERS:
                base.add(unit)
                changed = True
    # Most imported first: errors.py leftmost.
    return sorted(base, key=lambda u: (-len(graph.importers(u)), u))


# Where each unit is drawn: (column, row), importers above what they import (but `__init__.py` and
# `clock_scaled.py`, leaves beside their importer cli), found for the computed graph by a search for a layout
# with no arrow over a box and kept here, so the map does not move between builds. `problems()` checks it (an
# arrow that would cross a box is bent, see `route`); a unit missing here (a new package) gets a dashed box in
# a row of its own above the base row.
POSITIONS = {
    "clock_scaled.py": (0, 0), "cli": (2, 0), "__init__.py": (4, 0), "api.py": (6, 0),
    "campaign": (0, 1),
    "runtime": (4, 2), "field": (6, 2),
    "outcome.py": (0, 3), "mission.py": (6, 3),
    "config": (2, 4),
    "vehicle": (0, 5), "landing": (4, 5), "sim": (6, 5),
    "mavlink": (6, 7),
    "sensing": (0, 8),
}
BOX_W, BOX_H, COLUMN_W, ROW_H = 3.7, 1.2, 3.2, 2.05
HIT_MARGIN = 0.1  # an arrow this close to a box it does not join counts as running over it
BENDS = (0.0, 0.18, -0.18, 0.32, -0.32, 0.5, -0.5)  # arc3 curvatures tried in turn


def _hits_box(points, rect) -> bool:
    return any(rect[0] <= x <= rect[2] and rect[1] <= y <= rect[3] for x, y in points)


def _curve(p, q, rad: float, samples: int = 40):
    """Points of matplotlib's arc3 curve from p to q: a quadratic Bezier through the control point at the
    chord's middle, moved `rad` times the chord's length to its side."""
    (x0, y0), (x1, y1) = p, q
    cx, cy = (x0 + x1) / 2 + rad * (y1 - y0), (y0 + y1) / 2 - rad * (x1 - x0)
    return [((1 - t) ** 2 * x0 + 2 * (1 - t) * t * cx + t * t * x1,
             (1 - t) ** 2 * y0 + 2 * (1 - t) * t * cy + t * t * y1) for t in (i / samples for i in range(samples + 1))]


@dataclass
class Drawing:
    """Box centres and each drawn edge's end points and curvature."""

    centres: dict[str, tuple[float, float]]
    base: list[str]
    unplaced: list[str]
    routes: dict[tuple[str, str], tuple[tuple[float, float], tuple[float, float], float]]

    def rect(self, unit: str, margin: float = 0.0):
        x, y = self.centres[unit]
        return (x - BOX_W / 2 - margin, y - BOX_H / 2 - margin, x + BOX_W / 2 + margin, y + BOX_H / 2 + margin)

    def over_boxes(self, edge, p, q, rad) -> list[str]:
        points = _curve(p, q, rad)[1:-1]
        return [u for u in self.centres if u not in edge and _hits_box(points, self.rect(u, HIT_MARGIN))]


def _ports(centres, edges):
    """Each edge's end points: the importer's bottom (top, when it imports upwards; a side, within a row) to
    the imported's top (bottom; side), at ports spread along the side in the order of the other ends, so
    arrowheads do not pile up."""
    sides = defaultdict(list)
    for a, b in edges:
        (xa, ya), (xb, yb) = centres[a], centres[b]
        if abs(ya - yb) < 1e-9:
            sides[(a, "right" if xb > xa else "left")].append((yb, (a, b), 0))
            sides[(b, "left" if xb > xa else "right")].append((ya, (a, b), 1))
            continue
        down = ya > yb
        sides[(a, "bottom" if down else "top")].append((xb, (a, b), 0))
        sides[(b, "top" if down else "bottom")].append((xa, (a, b), 1))
    ends = {edge: [None, None] for edge in edges}
    for (unit, side), attached in sides.items():
        attached.sort(key=lambda item: (item[0], item[1]))
        x, y = centres[unit]
        for i, (_, edge, which) in enumerate(attached):
            offset = (i + 0.5) / len(attached) - 0.5
            if side in ("top", "bottom"):
                ends[edge][which] = (x + offset * BOX_W * 0.8, y + (BOX_H / 2 if side == "top" else -BOX_H / 2))
            else:
                ends[edge][which] = (x + (BOX_W / 2 if side == "right" else -BOX_W / 2), y + offset * BOX_H * 0.5)
    return ends


def route(graph: Graph) -> Drawing:
    """Where everything goes: the hand-placed units, any others in a row of their own, the base row at the
    bottom, and each edge straight, or bent as little as keeps it off every box."""
    base = base_units(graph)
    others = [u for u in sorted(graph.modules) if u not in base]
    unplaced = [u for u in others if u not in POSITIONS]
    rows = max((POSITIONS[u][1] for u in others if u in POSITIONS), default=-1) + 1
    centres = {u: (POSITIONS[u][0] * COLUMN_W, -POSITIONS[u][1] * ROW_H) for u in others if u in POSITIONS}
    for i, unit in enumerate(unplaced):
        centres[unit] = (i * COLUMN_W, -rows * ROW_H)
    base_row = rows + (1 if unplaced else 0)
    for i, unit in enumerate(base):
        centres[unit] = (i * COLUMN_W * 2, -base_row * ROW_H)
    edges = [e for e in sorted(graph.edges) if e[1] not in base or e[0] in base]
    drawing = Drawing(centres=centres, base=base, unplaced=unplaced, routes={})
    for edge, (p, q) in _ports(centres, edges).items():
        rad = next((r for r in BENDS if not drawing.over_boxes(edge, p, q, r)), 0.0)
        drawing.routes[edge] = (p, q, rad)
    return drawing


def problems(drawing: Drawing) -> list[str]:
    """What keeps the map from being read: arrows over boxes, units without a place."""
    found = [f"{a} -> {b} runs over {', '.join(drawing.over_boxes((a, b), p, q, rad))}"
             for (a, b), (p, q, rad) in drawing.routes.items() if drawing.over_boxes((a, b), p, q, rad)]
    return found + [f"{unit} has no place in POSITIONS" for unit in drawing.unplaced]


# One colour per importer, so an arrow can be followed from where it leaves.
PALETTE = ("#1565c0", "#c62828", "#2e7d32", "#6a1b9a", "#ef6c00", "#00838f", "#ad1457", "#4e342e", "#283593",
           "#558b2f", "#d84315", "#37474f", "#00695c", "#8e24aa", "#f9a825")


def make(out_dir: Path) -> list[Path]:
    graph = import_graph()
    drawing = route(graph)
    xs = [x for x, _ in drawing.centres.values()]
    ys = [y for _, y in drawing.centres.values()]
    width, height = max(xs) - min(xs) + BOX_W + 0.6, max(ys) - min(ys) + BOX_H + 1.6
    scale = 9.4 / width
    figure, axes = plt.subplots(figsize=(9.4, height * scale + 0.5), layout="constrained")
    importers = sorted({a for a, _ in drawing.routes})
    colours = {unit: PALETTE[i % len(PALETTE)] for i, unit in enumerate(importers)}
    for (a, b), (p, q, rad) in drawing.routes.items():
        deferred = graph.edges[(a, b)] == DEFERRED
        _figkit.arrow(axes, p, q, color=colours[a], rad=rad, style=(0, (4, 2.5)) if deferred else "-", width=1.2)
    for unit, (x, y) in drawing.centres.items():
        count = graph.modules[unit]
        lines = [f"{count} modules" if count > 1 else "module"]
        if unit in drawing.base:
            lines = [f"imported by {len(graph.importers(unit))} units"]
        else:
            uses = [u.removesuffix(".py") for u in drawing.base if (unit, u) in graph.edges]
            if uses:
                lines.append("+ " + ", ".join(uses))
        fill = _figkit.COLORS["results"] if unit in drawing.base else (
            _figkit.COLORS["input"] if unit.endswith(".py") else _figkit.COLORS["campaign"])
        _figkit.box(axes, x, y, BOX_W, BOX_H, unit + ("" if unit.endswith(".py") else "/"), tuple(lines),
                    fill=fill, edge=colours.get(unit, _figkit.EDGE), title_size=9, line_size=6.9, mono_lines=False,
                    linestyle="--" if unit in drawing.unplaced else "-")
    base_y = drawing.centres[drawing.base[0]][1] if drawing.base else min(ys)
    axes.text(min(xs) - BOX_W / 2, base_y - BOX_H / 2 - 0.45,
              "Arrow: importer -> imported, coloured by importer; solid: imported on loading, dashed: only inside "
              "functions.\nImports of the base row (grey) are listed in each box (+ errors, ...) rather than "
              "drawn; type-checking-only imports are left out.", fontsize=7.6, color="#455a64", va="top")
    axes.set_xlim(min(xs) - BOX_W / 2 - 0.3, max(xs) + BOX_W / 2 + 0.3)
    axes.set_ylim(min(ys) - BOX_H / 2 - 1.3, max(ys) + BOX_H / 2 + 0.3)
    axes.set_aspect("equal")
    axes.set_axis_off()
    axes.set_title("preland_app: packages, top-level modules and their imports (computed from the source)",
                   fontsize=11, fontweight="bold")
    return [_figkit.save(figure, out_dir / "module-map.png")]


if __name__ == "__main__":
    _figkit.run_alone(make)

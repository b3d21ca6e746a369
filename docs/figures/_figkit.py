"""What the documentation's figure modules share: the repository's root, the web resolution, saving, boxes
and arrows for the diagrams, and running a module alone (`python docs/figures/NAME.py OUTDIR`).

Named `_figkit` (not `_style` or `common`) because the docs build imports other gen-files scripts' helpers into
the same process: a plain name could be taken by theirs.
"""

from __future__ import annotations

import io
import sys
from collections.abc import Callable
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # no display in a docs build
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch  # noqa: E402
from PIL import Image  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
DPI = 150  # plenty for the web; figures are sized in inches for ~1000-1400 px
PNG_LIMIT_BYTES = 300_000

if str(ROOT) not in sys.path:  # run alone from anywhere: preland_app from this tree, not an installed copy
    sys.path.insert(0, str(ROOT))

# One look for every diagram: a light fill per kind of step or unit, dark text and borders.
COLORS = {
    "input": "#e8f1fb", "campaign": "#fdf0dc", "runtime": "#e6f4ea", "vehicle": "#f3e8fb", "mission": "#fbe9e7",
    "sensing": "#fff8d6", "autopilot": "#e0f2f1", "results": "#eceff1", "state": "#e8f1fb", "end": "#eceff1",
}
EDGE = "#37474f"


def _write_reduced(image, path: Path) -> None:
    # 256 colours: a diagram has a handful plus anti-aliasing; full colour only makes the file heavier.
    image.convert("RGB").quantize(colors=256, dither=Image.Dither.NONE).save(path, format="PNG", optimize=True,
                                                                             dpi=(DPI, DPI))


def _check_size(path: Path) -> Path:
    size = path.stat().st_size
    if size > PNG_LIMIT_BYTES:
        raise RuntimeError(f"{path.name}: {size} bytes, over the {PNG_LIMIT_BYTES} bytes a docs figure may take")
    return path


def save(figure, path: Path) -> Path:
    """Write `figure` as a PNG at DPI, in 256 colours, and close it; refuse one too heavy for a web page."""
    path.parent.mkdir(parents=True, exist_ok=True)
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=DPI, facecolor="white")
    plt.close(figure)
    buffer.seek(0)
    with Image.open(buffer) as image:
        _write_reduced(image, path)
    return _check_size(path)


def fit(path: Path) -> Path:
    """A PNG someone else drew (the report's): kept as it is when light enough for a page, else reduced to
    256 colours; refused when still too heavy."""
    if path.stat().st_size > PNG_LIMIT_BYTES:
        with Image.open(path) as image:
            image.load()
        _write_reduced(image, path)
    return _check_size(path)


def box(axes, x: float, y: float, width: float, height: float, title: str, lines: tuple[str, ...] = (), *,
        fill: str = "#ffffff", edge: str = EDGE, title_size: float = 10.5, line_size: float = 8.5,
        mono_lines: bool = True, linestyle: str = "-"):
    """A rounded box centred at (x, y) in data units, a bold title over smaller lines (module paths in
    monospace). Returns the patch, for arrows to clip at."""
    patch = FancyBboxPatch((x - width / 2, y - height / 2), width, height, boxstyle="round,pad=0,rounding_size=0.08",
                           facecolor=fill, edgecolor=edge, linewidth=1.2, linestyle=linestyle, zorder=3)
    axes.add_patch(patch)
    if not lines:
        axes.text(x, y, title, ha="center", va="center", fontsize=title_size, fontweight="bold", zorder=4)
        return patch
    # Title and lines share the box's height: the title a little larger than a line.
    rows = len(lines) + 1.3
    step = height / (rows + 0.6)
    top = y + step * rows / 2
    axes.text(x, top - step * 0.55, title, ha="center", va="center", fontsize=title_size, fontweight="bold",
              zorder=4)
    for i, line in enumerate(lines):
        axes.text(x, top - step * (1.55 + i), line, ha="center", va="center", fontsize=line_size, zorder=4,
                  family="monospace" if mono_lines else None, color="#263238")
    return patch


def arrow(axes, start, end, *, label: str | None = None, color: str = EDGE,
          rad: float = 0.0, style: str = "-", width: float = 1.3, label_pos: float = 0.5,
          label_offset: tuple[float, float] = (0.0, 0.0), label_size: float = 8.0, zorder: float = 2,
          label_ha: str = "center"):
    """An arrow from `start` to `end`, optionally curved (`rad`, matplotlib's arc3), with a label on a white
    ground at `label_pos` of the straight line between them, moved by `label_offset` (data units)."""
    patch = FancyArrowPatch(start, end, arrowstyle="-|>", mutation_scale=12,
                            connectionstyle=f"arc3,rad={rad}", color=color, linewidth=width, linestyle=style,
                            zorder=zorder, shrinkA=2, shrinkB=2)
    axes.add_patch(patch)
    if label:
        x = start[0] + (end[0] - start[0]) * label_pos + label_offset[0]
        y = start[1] + (end[1] - start[1]) * label_pos + label_offset[1]
        axes.text(x, y, label, ha=label_ha, va="center", fontsize=label_size, color="#212121", zorder=5,
                  bbox=dict(boxstyle="round,pad=0.2", facecolor="white", edgecolor="none", alpha=0.92))
    return patch


def run_alone(make: Callable[[Path], list[Path]]) -> None:
    """`python docs/figures/NAME.py OUTDIR`: write the module's figures into OUTDIR and name them."""
    if len(sys.argv) != 2:
        raise SystemExit(f"usage: python {sys.argv[0]} OUTDIR")
    for path in make(Path(sys.argv[1])):
        print(path)

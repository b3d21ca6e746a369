"""figures/pad-thesis.png, figures/pad-paper.png: the shipped pads, drawn by the project's own printable-pad
renderer (`preland_app/sensing/pad_render.py`, what `preland pad render --preset NAME --out pad.png` runs).

The renderer draws at true scale, so its labels are print-sized: at page width they would be a few pixels
tall. The sheet is rendered at 1.5 times the web width and reduced (crisp marker edges), under a header of the same
facts in web-sized type.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

if __name__ == "__main__":  # run alone: no __pycache__ in docs/, the site's source
    sys.dont_write_bytecode = True
import _figkit  # noqa: E402

import cv2  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402

from preland_app.sensing.pad import PAD_PRESETS, PadSpec  # noqa: E402
from preland_app.sensing.pad_render import render_printable_pad  # noqa: E402

WIDTH_PX = 1100  # published width
HEADER_PX = 140
INCH_M = 0.0254


def _place(north_m: float, east_m: float) -> str:
    parts = [f"{abs(v) * 100:g} cm {(pos if v > 0 else neg)}" for v, pos, neg in
             ((north_m, "north", "south"), (east_m, "east", "west")) if v]
    return " and ".join(parts) + " of the centre" if parts else "at the centre"


def describe(preset: str, pad: PadSpec) -> tuple[str, str, str]:
    """The header's lines, from the pad's spec (the renderer's landing point is the sheet's centre)."""
    markers = "; ".join(f"id {m.id}: {m.side_m * 100:g} cm, {_place(*m.center_m)}" for m in pad.markers)
    beacon = f"IR beacon {_place(*pad.beacon_m)}" if pad.beacon_m is not None else "no IR beacon"
    return (f"'{preset}' pad: {pad.size_m * 100:g} x {pad.size_m * 100:g} cm sheet, {pad.dictionary}, north up",
            f"markers: {markers}", f"{beacon}; landing point at the centre")


def render(preset: str, out: Path) -> Path:
    pad = PAD_PRESETS[preset]
    # About 1.5 times the published width across the sheet, whatever its size (the paper's is 1.8 m).
    dpi = max(20, round(1.5 * WIDTH_PX * INCH_M / pad.size_m))
    with tempfile.TemporaryDirectory() as folder:
        printed, = render_printable_pad(pad, Path(folder) / "pad.png", dpi=dpi)
        image = cv2.imread(str(printed), cv2.IMREAD_GRAYSCALE)
    height = round(image.shape[0] * WIDTH_PX / image.shape[1])
    image = cv2.resize(image, (WIDTH_PX, height), interpolation=cv2.INTER_AREA)
    # figimage places the pixels one to one: no second resampling by an axes.
    figure = plt.figure(figsize=(WIDTH_PX / _figkit.DPI, (height + HEADER_PX) / _figkit.DPI))
    figure.figimage(image, xo=0, yo=0, cmap="gray", vmin=0, vmax=255, origin="upper")
    title, *lines = describe(preset, pad)
    lines.append(f"preland pad render --preset {preset} --out pad.png   (prints at true scale: 100 %)")
    total = height + HEADER_PX
    figure.text(0.5, 1 - 26 / total, title, ha="center", va="center", fontsize=12, fontweight="bold")
    for i, line in enumerate(lines):
        command = i == len(lines) - 1
        figure.text(0.5, 1 - (58 + 26 * i) / total, line, ha="center", va="center", fontsize=9.5,
                    family="monospace" if command else None, color="#455a64" if command else "black")
    return _figkit.save(figure, out)


def make(out_dir: Path) -> list[Path]:
    return [render(preset, out_dir / f"pad-{preset}.png") for preset in ("thesis", "paper")]


if __name__ == "__main__":
    _figkit.run_alone(make)

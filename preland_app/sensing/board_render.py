"""A printable ChArUco board at true scale, for `preland camera calibrate`.

The board is OpenCV's own drawing of the board `calibration.CharucoBoardSpec`
describes (squares across and down, square and marker sides, dictionary), placed
on a page sized so that a square prints at its stated side (print at 100 %),
with crop marks, a 10 cm scale bar and a caption giving the options to pass to
`camera calibrate`.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
matplotlib.rcParams["pdf.fonttype"] = 42
import matplotlib.pyplot as plt  # noqa: E402

from .calibration import CharucoBoardSpec  # noqa: E402
from .pad_render import LABEL_PT, _INCH_M, _crop_marks, _scale_bar  # noqa: E402

MARGIN_M = 0.03


def render_charuco_board(spec: CharucoBoardSpec, out: Path, *, dpi: int = 300) -> Path:
    """Write the board (.png or .pdf) at true scale; returns the path."""
    suffix = out.suffix.lower()
    if suffix not in (".png", ".pdf"):
        raise ValueError(f"{out}: the output must end in .png or .pdf")
    width_m, height_m = spec.squares_x * spec.square_m, spec.squares_y * spec.square_m
    px_per_square = max(20, round(spec.square_m / _INCH_M * dpi))
    image = spec.board().generateImage((spec.squares_x * px_per_square, spec.squares_y * px_per_square),
                                       marginSize=0, borderBits=1)
    page = (width_m + 2 * MARGIN_M, height_m + 2 * MARGIN_M + 0.03)
    figure = plt.figure(figsize=(page[0] / _INCH_M, page[1] / _INCH_M), dpi=dpi)
    axes = figure.add_axes((MARGIN_M / page[0], (MARGIN_M + 0.015) / page[1], width_m / page[0], height_m / page[1]))
    axes.imshow(image, cmap="gray", vmin=0, vmax=255, extent=(0, width_m, 0, height_m), interpolation="nearest")
    axes.set_axis_off()
    _crop_marks(figure, left=MARGIN_M, bottom=MARGIN_M + 0.015, width=width_m, height=height_m, page=page)
    figure.text(0.5, 0.010 / page[1],
                f"ChArUco {spec.squares_x} x {spec.squares_y}, squares {spec.square_m * 100:g} cm, markers "
                f"{spec.marker_m * 100:g} cm, {spec.dictionary}; print at 100 % and check the bar. "
                f"preland camera calibrate --squares-x {spec.squares_x} --squares-y {spec.squares_y} "
                f"--square-m {spec.square_m:g} --marker-m {spec.marker_m:g} --dictionary {spec.dictionary}",
                ha="center", va="center", fontsize=LABEL_PT * 0.75, wrap=True)
    _scale_bar(figure, x_m=MARGIN_M, y_m=page[1] - MARGIN_M * 0.6, page=page, font_pt=LABEL_PT * 0.85)
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out, dpi=dpi)
    plt.close(figure)
    return out

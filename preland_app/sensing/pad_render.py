"""Printable landing pads at true scale, with their dimensions annotated.

The page is the pad's sheet plus a margin for the annotations; the figure is
sized in inches so that one metre on the sheet prints as one metre (print at
100 % / "actual size"). The sheet has a thin outline and crop marks at its
corners to cut along. A sheet larger than the printer's paper is tiled onto A4
or A3 pages (`paper="A4"`): each page holds one tile with crop marks at its
corners, its row and column, and a 10 cm scale bar to check the print; cut
along the marks and butt the tiles together. PNG pages carry their DPI (one
file per tile, `NAME_r1c2.png`); PDF pages are vector around a raster of the
markers at the chosen DPI (all tiles in one file).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
matplotlib.rcParams["pdf.fonttype"] = 42
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

from .pad import PadSpec, render_pad_texture  # noqa: E402

_INCH_M = 0.0254
_MARGIN_M = 0.12  # around a whole sheet: room for the caption, scale bar and crop marks
PAGE_MARGIN_M = 0.012  # around a tile on a paper page: most printers cannot print closer to the edge
CROP_GAP_M = 0.003  # crop marks start this far outside the corner...
CROP_LENGTH_M = 0.008  # ...and run this long
LABEL_PT = 9.0  # labels stay legible: never smaller than this
_PDF_BAND_PX = 1024  # rows of the sheet's raster per embedded PDF image
PAPER_SIZES_M = {"A4": (0.210, 0.297), "A3": (0.297, 0.420)}  # portrait width x height


@dataclass(frozen=True)
class Tile:
    """One page of a tiled sheet: its row and column (from the top left, from 1) and the part of the sheet
    it holds, in m from the sheet's centre (x east/right, y north/up)."""

    row: int
    column: int
    x0_m: float
    x1_m: float
    y0_m: float
    y1_m: float


def plan_tiles(size_m: float, paper: str) -> tuple[tuple[float, float], list[Tile]]:
    """The page size (width, height in m; portrait or landscape, whichever needs fewer pages) and the tiles
    that cover a square sheet of `size_m`."""
    if paper not in PAPER_SIZES_M:
        raise ValueError(f"paper must be one of {', '.join(PAPER_SIZES_M)}")
    best = None
    for width, height in (PAPER_SIZES_M[paper], PAPER_SIZES_M[paper][::-1]):
        usable_w, usable_h = width - 2 * PAGE_MARGIN_M - 0.02, height - 2 * PAGE_MARGIN_M - 0.03
        columns, rows = math.ceil(size_m / usable_w - 1e-9), math.ceil(size_m / usable_h - 1e-9)
        if best is None or columns * rows < best[0]:
            best = (columns * rows, (width, height), columns, rows)
    _, page, columns, rows = best
    half = size_m / 2.0
    tiles = []
    for row in range(rows):
        for column in range(columns):
            x0 = -half + column * size_m / columns
            y1 = half - row * size_m / rows
            tiles.append(Tile(row=row + 1, column=column + 1, x0_m=x0, x1_m=x0 + size_m / columns,
                              y0_m=y1 - size_m / rows, y1_m=y1))
    return page, tiles


def _crop_marks(figure, *, left: float, bottom: float, width: float, height: float, page: tuple[float, float]) -> None:
    """Crop marks at the corners of a rectangle given in m on a page of `page` m: short lines continuing each
    edge outside the corner, so the cut line is found after the print is trimmed."""
    pw, ph = page
    for x in (left, left + width):
        for y in (bottom, bottom + height):
            sx = -1 if x == left else 1
            sy = -1 if y == bottom else 1
            start, end = CROP_GAP_M, CROP_GAP_M + CROP_LENGTH_M
            for (x0, y0), (x1, y1) in (((x + sx * start, y), (x + sx * end, y)),
                                       ((x, y + sy * start), (x, y + sy * end))):
                figure.add_artist(Line2D([x0 / pw, x1 / pw], [y0 / ph, y1 / ph], color="black", lw=0.7,
                                         transform=figure.transFigure))


def _crop(pad: PadSpec, texture: np.ndarray, view_m: tuple[float, float, float, float]):
    """The part of the sheet's texture a page shows (`view_m`: x0, x1, y0, y1 in m from the sheet's centre,
    x east, y north), and its extent in the same frame: a tile page holds only its own pixels."""
    half, ppm = pad.size_m / 2.0, texture.shape[1] / pad.size_m
    x0, x1, y0, y1 = view_m
    c0, c1 = max(0, math.floor((x0 + half) * ppm)), min(texture.shape[1], math.ceil((x1 + half) * ppm))
    r0, r1 = max(0, math.floor((half - y1) * ppm)), min(texture.shape[0], math.ceil((half - y0) * ppm))
    return texture[r0:r1, c0:c1], (-half + c0 / ppm, -half + c1 / ppm, half - r1 / ppm, half - r0 / ppm)


def _draw_pad(axes, pad: PadSpec, *, font_pt: float) -> None:
    """The sheet's outline and annotations (the texture itself is placed by `_save`)."""
    half = pad.size_m / 2.0
    axes.add_patch(Rectangle((-half, -half), pad.size_m, pad.size_m, fill=False, edgecolor="0.5", lw=0.6))
    for marker in pad.markers:
        corners = pad.marker_corners_pad_m(marker)
        top = corners[:, 0].max()
        left, right = corners[:, 1].min(), corners[:, 1].max()
        gap = marker.side_m * 0.04 + 0.004
        # A plotted dimension line (not an arrow annotation): a tile page clips it at the tile's edge.
        axes.plot([left, right], [top + gap] * 2, color="tab:red", lw=0.8, marker="|", markersize=font_pt)
        axes.text((left + right) / 2, top + gap * 1.4, f"id {marker.id}: {marker.side_m * 100:.1f} cm",
                  color="tab:red", ha="center", va="bottom", fontsize=font_pt, clip_on=True)
    if pad.beacon_m is not None:
        axes.plot([pad.beacon_m[1]], [pad.beacon_m[0]], marker="+", color="tab:orange", markersize=font_pt * 1.5)
    axes.plot([0], [0], marker="x", color="tab:blue", markersize=font_pt)
    axes.set_axis_off()


def _scale_bar(figure, *, x_m: float, y_m: float, page: tuple[float, float], font_pt: float) -> None:
    """A 10 cm bar to check the print's scale."""
    pw, ph = page
    bar = figure.add_axes((x_m / pw, y_m / ph, 0.10 / pw, 0.004 / ph))
    bar.set_facecolor("black")
    bar.set_xticks([])
    bar.set_yticks([])
    figure.text((x_m + 0.104) / pw, (y_m + 0.002) / ph, "10 cm", va="center", fontsize=font_pt)


def render_printable_pad(pad: PadSpec, out: Path, *, dpi: int = 300, paper: str | None = None) -> list[Path]:
    """Write the pad at true scale to `out` (.png or .pdf): one page, or tiles on `paper` (A4, A3) pages.
    Returns the files written (PNG tiles are `out`'s stem with `_rRcC`)."""
    suffix = out.suffix.lower()
    if suffix not in (".png", ".pdf"):
        raise ValueError(f"{out}: the output must end in .png or .pdf")
    out.parent.mkdir(parents=True, exist_ok=True)
    texture = render_pad_texture(pad, pixels_per_m=dpi / _INCH_M)
    caption = (f"preland pad '{pad.name}' | {pad.dictionary} | sheet {pad.size_m * 100:.0f} x {pad.size_m * 100:.0f} cm"
               " | print at 100 % (actual size) | x: landing point" + (" | +: IR beacon" if pad.beacon_m else ""))
    if paper is None:
        return [_single_page(pad, out, texture, dpi=dpi, caption=caption)]
    return _tiled(pad, out, texture, dpi=dpi, paper=paper, caption=caption)


def _save(figure, axes, pad: PadSpec, texture: np.ndarray, view_m, out: Path, *, dpi: int, pdf=None) -> None:
    """Write the page with the sheet's texture under its annotations, at true scale.

    A PDF embeds the texture as it is, in bands of rows (RGB bytes, interpolation "none": no resampling). A PNG is composed
    here: matplotlib draws the annotations on a transparent page, the texture's pixels are copied into
    place and the annotations laid over them. Matplotlib's own image path costs about 130 bytes a pixel
    (10 GB for the thesis pad at 300 dpi); this costs a few bytes a page pixel."""
    crop, extent = _crop(pad, texture, view_m)
    if pdf is not None or out.suffix.lower() == ".pdf":
        # RGB bytes in bands of rows: a grey array would go through the colour map in floats, and one image
        # of a whole sheet through the PDF writer's copies (gigabytes either way).
        x0, x1, y0, y1 = extent
        metres_per_px = (y1 - y0) / crop.shape[0]
        for start in range(0, crop.shape[0], _PDF_BAND_PX):
            band = crop[start:start + _PDF_BAND_PX]
            top = y1 - start * metres_per_px
            axes.imshow(np.repeat(band[:, :, None], 3, axis=2), interpolation="none", zorder=0,
                        extent=(x0, x1, top - band.shape[0] * metres_per_px, top))
        axes.set_xlim(view_m[0], view_m[1])
        axes.set_ylim(view_m[2], view_m[3])
        (pdf.savefig(figure, dpi=dpi) if pdf is not None else figure.savefig(out, dpi=dpi))
        return
    from PIL import Image

    figure.patch.set_alpha(0.0)
    figure.canvas.draw()
    overlay = np.asarray(figure.canvas.buffer_rgba())
    height_px = overlay.shape[0]
    page = np.full(overlay.shape[:2], 255, np.uint8)
    left_px, top_px = axes.transData.transform((extent[0], extent[3]))
    row, col = int(round(height_px - top_px)), int(round(left_px))
    rows = slice(max(row, 0), min(row + crop.shape[0], page.shape[0]))
    cols = slice(max(col, 0), min(col + crop.shape[1], page.shape[1]))
    page[rows, cols] = crop[rows.start - row:rows.stop - row, cols.start - col:cols.stop - col]
    image = np.empty((*page.shape, 3), np.uint8)
    for start in range(0, height_px, 512):  # in bands, so the blend's temporaries stay small
        band = overlay[start:start + 512]
        alpha = band[..., 3:4].astype(np.uint16)
        under = page[start:start + 512, :, None].astype(np.uint16)
        image[start:start + 512] = ((band[..., :3] * alpha + under * (255 - alpha) + 127) // 255).astype(np.uint8)
    Image.fromarray(image).save(out, dpi=(dpi, dpi))


def _single_page(pad: PadSpec, out: Path, texture, *, dpi: int, caption: str) -> Path:
    size_m = pad.size_m
    page_m = size_m + 2 * _MARGIN_M
    page = (page_m, page_m)
    figure = plt.figure(figsize=(page_m / _INCH_M, page_m / _INCH_M), dpi=dpi)
    # Axes in metres, pad frame: x east (right), y north (up), centred on the pad.
    axes = figure.add_axes((_MARGIN_M / page_m, _MARGIN_M / page_m, size_m / page_m, size_m / page_m))
    font_pt = max(LABEL_PT, min(14.0, size_m * 12))
    _draw_pad(axes, pad, font_pt=font_pt)
    half = size_m / 2.0
    axes.set_xlim(-half, half)
    axes.set_ylim(-half, half)
    _crop_marks(figure, left=_MARGIN_M, bottom=_MARGIN_M, width=size_m, height=size_m, page=page)
    figure.text(0.5, _MARGIN_M * 0.35 / page_m, caption, ha="center", va="center", fontsize=font_pt * 0.85)
    _scale_bar(figure, x_m=_MARGIN_M, y_m=_MARGIN_M + size_m + 0.03, page=page, font_pt=font_pt * 0.85)
    _save(figure, axes, pad, texture, (-half, half, -half, half), out, dpi=dpi)
    plt.close(figure)
    return out


def _tiled(pad: PadSpec, out: Path, texture, *, dpi: int, paper: str, caption: str) -> list[Path]:
    from matplotlib.backends.backend_pdf import PdfPages

    page, tiles = plan_tiles(pad.size_m, paper)
    columns = max(t.column for t in tiles)
    rows = max(t.row for t in tiles)
    pdf = PdfPages(out) if out.suffix.lower() == ".pdf" else None
    written: list[Path] = []
    try:
        for tile in tiles:
            pw, ph = page
            width, height = tile.x1_m - tile.x0_m, tile.y1_m - tile.y0_m
            left, bottom = (pw - width) / 2, PAGE_MARGIN_M + 0.03
            figure = plt.figure(figsize=(pw / _INCH_M, ph / _INCH_M), dpi=dpi)
            axes = figure.add_axes((left / pw, bottom / ph, width / pw, height / ph))
            _draw_pad(axes, pad, font_pt=LABEL_PT)
            axes.set_xlim(tile.x0_m, tile.x1_m)
            axes.set_ylim(tile.y0_m, tile.y1_m)
            _crop_marks(figure, left=left, bottom=bottom, width=width, height=height, page=page)
            neighbours = [text for text, present in (
                (f"r{tile.row}c{tile.column - 1} to the left", tile.column > 1),
                (f"r{tile.row}c{tile.column + 1} to the right", tile.column < columns),
                (f"r{tile.row - 1}c{tile.column} above", tile.row > 1),
                (f"r{tile.row + 1}c{tile.column} below", tile.row < rows)) if present]
            figure.text(0.5, (bottom + height + 0.012) / ph,
                        f"tile r{tile.row}c{tile.column} of {rows} x {columns} ({paper}): cut at the marks; joins "
                        + ", ".join(neighbours), ha="center", va="bottom", fontsize=LABEL_PT)
            figure.text(0.5, (PAGE_MARGIN_M + 0.006) / ph, caption, ha="center", va="center", fontsize=LABEL_PT * 0.8,
                        wrap=True)
            _scale_bar(figure, x_m=PAGE_MARGIN_M + 0.005, y_m=ph - PAGE_MARGIN_M - 0.006, page=page,
                       font_pt=LABEL_PT * 0.85)
            view = (tile.x0_m, tile.x1_m, tile.y0_m, tile.y1_m)
            if pdf is not None:
                _save(figure, axes, pad, texture, view, out, dpi=dpi, pdf=pdf)
            else:
                path = out.with_name(f"{out.stem}_r{tile.row}c{tile.column}{out.suffix}")
                _save(figure, axes, pad, texture, view, path, dpi=dpi)
                written.append(path)
            plt.close(figure)
    finally:
        if pdf is not None:
            pdf.close()
    return [out] if pdf is not None else written

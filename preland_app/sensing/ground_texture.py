"""The ground around the pad, as the virtual camera sees it: a grass-like texture drawn tile by tile.

The texture covers a square field (80 m at 24 px/m, 1920 px a side); a landing
sees a few hundred pixels of it. Each 128 px tile is drawn the first time a
frame reads it, from its own random stream, so a trial pays for the ground it
flies over, not for the whole field. The texture does not depend on which
tiles are drawn first, or whether they are: a tile's pixels come from the
field's seed and the tile's place only.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

FIELD_EXTENT_M = 80.0
FIELD_PX_PER_M = 24.0
TILE_PX = 128  # divides the field's 1920 px, and is a whole number of every coarse layer's cells
# Grass: smoothed noise at three scales (cells across the field, grey-level weight), mid grey, low contrast.
_COARSE_LAYERS = ((30, 30.0), (240, 18.0))
_FINE_WEIGHT = 10.0
_CUBIC_PAD_CELLS = 2  # bicubic interpolation reads two cells either side
_MEAN_GREY = 110.0
_GREY_RANGE = (40, 190)


class GrassTexture:
    """A `size_px` square uint8 texture (texture px: column east, row south of the field's north-west
    corner), drawn lazily in tiles. `pixels` is the whole array; call `ensure_read_by` before reading it."""

    def __init__(self, *, rng: np.random.Generator) -> None:
        self.size_px = int(FIELD_EXTENT_M * FIELD_PX_PER_M)
        size = self.size_px
        # The coarse scales: a few thousand cells, drawn whole. A tile's share of a bicubic upsampling by an
        # integer factor is a fixed linear map of the cells around it (tiles start on a cell boundary), so
        # each tile is W @ cells @ W.T, with W taken from cv2.resize itself; edge cells repeat outside.
        self._coarse = []
        for cells, weight in _COARSE_LAYERS:
            factor = size // cells
            block = TILE_PX // factor + 2 * _CUBIC_PAD_CELLS
            values = np.pad(rng.standard_normal((cells, cells)).astype(np.float32), _CUBIC_PAD_CELLS, mode="edge")
            spread = cv2.resize(np.eye(block, dtype=np.float32), (block, block * factor),
                                interpolation=cv2.INTER_CUBIC)
            start = _CUBIC_PAD_CELLS * factor
            self._coarse.append((factor, block, np.float32(weight) * values, spread[start:start + TILE_PX]))
        self._tile_seed = int(rng.integers(2**63))
        tiles = size // TILE_PX
        self._drawn = np.zeros((tiles, tiles), dtype=bool)
        self.pixels = np.empty((size, size), dtype=np.uint8)

    @property
    def tiles_drawn(self) -> int:
        return int(self._drawn.sum())

    def ensure_read_by(self, image_to_texture: np.ndarray, size_px: tuple[int, int]) -> None:
        """Draw every tile that a bilinear `cv2.warpPerspective` (inverse map `image_to_texture`, output
        `size_px` = (width, height), BORDER_REFLECT) reads."""
        tiles = self._drawn.shape[0]
        box = texels_read_by(image_to_texture, size_px)
        size = self.size_px
        if box is None or box[0] < 0 or box[1] < 0 or box[2] >= size or box[3] >= size:
            # The horizon crosses the output, or the warp reflects about the field's edge (rare: the field
            # reaches 40 m from the pad): draw everything.
            self._draw_tiles(0, tiles, 0, tiles)
            return
        u0, v0, u1, v1 = box
        self._draw_tiles(v0 // TILE_PX, v1 // TILE_PX + 1, u0 // TILE_PX, u1 // TILE_PX + 1)

    def _draw_tiles(self, row0: int, row1: int, col0: int, col1: int) -> None:
        block = self._drawn[row0:row1, col0:col1]
        if block.all():
            return
        for row, col in zip(*np.nonzero(~block)):
            self._draw_tile(int(row) + row0, int(col) + col0)

    def _draw_tile(self, row: int, col: int) -> None:
        y0, x0 = row * TILE_PX, col * TILE_PX
        # Fine grain: each tile from its own stream, keyed by the field's seed and the tile's place.
        rng = np.random.default_rng([self._tile_seed, row, col])
        tile = rng.standard_normal((TILE_PX, TILE_PX), dtype=np.float32)
        np.multiply(tile, np.float32(_FINE_WEIGHT), out=tile)
        for factor, block, cells, spread in self._coarse:
            r0, c0 = y0 // factor, x0 // factor
            tile += spread @ cells[r0:r0 + block, c0:c0 + block] @ spread.T
        tile += np.float32(_MEAN_GREY)
        np.clip(tile, *_GREY_RANGE, out=tile)
        self.pixels[y0:y0 + TILE_PX, x0:x0 + TILE_PX] = tile.astype(np.uint8)
        self._drawn[row, col] = True


def texels_read_by(image_to_texture: np.ndarray, size_px: tuple[int, int]) -> tuple[int, int, int, int] | None:
    """The texels (u0, v0, u1, v1; columns and rows, inclusive) that a bilinear inverse-map
    `cv2.warpPerspective` of `size_px` (width, height) output pixels can read: the taps reach floor(x) and
    floor(x) + 1, and one more pixel each way covers the warp's fixed-point rounding. None when the horizon
    crosses the output (a corner maps behind the camera). A projective map in front of the camera sends the
    output's edges to straight lines, so its four corners bound the rest."""
    width, height = size_px
    right, bottom = width - 1.0, height - 1.0
    h = image_to_texture.tolist()
    us, vs = [], []
    for x, y in ((0.0, 0.0), (right, 0.0), (0.0, bottom), (right, bottom)):
        depth = h[2][0] * x + h[2][1] * y + h[2][2]
        if depth <= 1e-9:
            return None
        us.append((h[0][0] * x + h[0][1] * y + h[0][2]) / depth)
        vs.append((h[1][0] * x + h[1][1] * y + h[1][2]) / depth)
    return (math.floor(min(us)) - 2, math.floor(min(vs)) - 2, math.floor(max(us)) + 3, math.floor(max(vs)) + 3)

"""The virtual camera's ground: drawn tile by tile as frames read it, the same whichever is drawn first."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from preland_app.sensing.camera import RPI_CAMERA_V2_640X480
from preland_app.sensing.ground_texture import TILE_PX, GrassTexture
from preland_app.sensing.pad import THESIS_PAD
from preland_app.sensing.virtual_camera import CameraPose, VirtualCamera, _rounded_normal_levels


def _all_drawn(texture: GrassTexture, order: np.ndarray) -> np.ndarray:
    tiles = texture.size_px // TILE_PX
    for index in order:
        texture._draw_tiles(index // tiles, index // tiles + 1, index % tiles, index % tiles + 1)
    assert texture.tiles_drawn == tiles * tiles
    return texture.pixels


def test_a_tile_is_the_same_whichever_tiles_are_drawn_before_it():
    tiles = GrassTexture(rng=np.random.default_rng(5)).size_px // TILE_PX
    in_rows = _all_drawn(GrassTexture(rng=np.random.default_rng(5)), np.arange(tiles * tiles))
    shuffled = _all_drawn(GrassTexture(rng=np.random.default_rng(5)),
                          np.random.default_rng(1).permutation(tiles * tiles))
    other_seed = _all_drawn(GrassTexture(rng=np.random.default_rng(6)), np.arange(tiles * tiles))
    assert np.array_equal(in_rows, shuffled)
    assert not np.array_equal(in_rows, other_seed)
    # Grass: mid grey, low contrast, no clipped flat areas to speak of.
    assert 105 < in_rows.mean() < 116 and 20 < in_rows.std() < 40
    assert np.mean((in_rows == 40) | (in_rows == 190)) < 0.05


def test_the_coarse_scales_are_the_whole_layer_upsampled():
    """Tile by tile, a coarse layer is what cv2.resize makes of the whole layer (away from the field's
    edges, where the tiles repeat the edge cells instead)."""
    texture = GrassTexture(rng=np.random.default_rng(2))
    tiles = texture.size_px // TILE_PX
    for factor, block, cells, spread in texture._coarse:
        whole = cv2.resize(cells[2:-2, 2:-2], (texture.size_px, texture.size_px), interpolation=cv2.INTER_CUBIC)
        by_tiles = np.vstack([np.hstack([
            spread @ cells[r * TILE_PX // factor:r * TILE_PX // factor + block,
                           c * TILE_PX // factor:c * TILE_PX // factor + block] @ spread.T
            for c in range(tiles)]) for r in range(tiles)])
        inner = slice(3 * factor, texture.size_px - 3 * factor)
        assert np.abs(whole[inner, inner] - by_tiles[inner, inner]).max() < 1e-3


@pytest.mark.parametrize("pose", [
    CameraPose(0.0, 0.0, -10.0, 0.0, 0.0, 0.0),
    CameraPose(2.0, -1.0, -20.0, 0.15, -0.1, 0.7),
    CameraPose(0.3, 0.2, -0.5, 0.05, 0.0, 2.0),
])
def test_a_frame_draws_only_the_ground_it_sees_and_the_same_pixels(pose):
    # (each camera below draws its frame from a fresh generator: the same noise draws, so equal pixels)
    camera = RPI_CAMERA_V2_640X480
    lazy = VirtualCamera(camera=camera, pad=THESIS_PAD, pad_origin_ned_m=(0.0, 0.0), rng=np.random.default_rng(8))
    eager = VirtualCamera(camera=camera, pad=THESIS_PAD, pad_origin_ned_m=(0.0, 0.0), rng=np.random.default_rng(8))
    tiles = eager._ground.size_px // TILE_PX
    eager._ground._draw_tiles(0, tiles, 0, tiles)
    image = lazy.render(pose)
    assert np.array_equal(image, eager.render(pose))
    # The tiles the frame reads (every 4th pixel's ground point), and the box of tiles around them.
    shot = lazy.capture(pose)
    u, v = np.meshgrid(np.arange(0, camera.width_px, 4.0), np.arange(0, camera.height_px, 4.0))
    read = shot.image_to_background @ np.vstack([u.ravel(), v.ravel(), np.ones(u.size)])
    cols, rows = (read[:2] / read[2] // TILE_PX).astype(int)
    box_tiles = (rows.max() - rows.min() + 3) * (cols.max() - cols.min() + 3)
    drawn = lazy._ground._drawn
    assert drawn[rows, cols].all()
    assert drawn.sum() <= box_tiles < tiles * tiles / 2
    # A region draws no more than the whole frame does, and the same pixels there.
    region = VirtualCamera(camera=camera, pad=THESIS_PAD, pad_origin_ned_m=(0.0, 0.0), rng=np.random.default_rng(8))
    fresh = VirtualCamera(camera=camera, pad=THESIS_PAD, pad_origin_ned_m=(0.0, 0.0), rng=np.random.default_rng(8))
    fresh._ground._draw_tiles(0, tiles, 0, tiles)
    assert np.array_equal(region.render_shot(region.capture(pose), (200, 100, 360, 220)),
                          fresh.render_shot(fresh.capture(pose), (200, 100, 360, 220)))
    assert region._ground.tiles_drawn <= lazy._ground.tiles_drawn


def test_sensor_noise_levels_follow_a_rounded_gaussian():
    table = _rounded_normal_levels(2.0)
    assert table.shape == (65536,)
    gauss = lambda x: 0.5 * (1.0 + math.erf(x / (2.0 * math.sqrt(2.0))))  # noqa: E731
    for level in range(-6, 7):
        expected = gauss(level + 0.5) - gauss(level - 0.5)
        assert abs(np.mean(table == level) - expected) <= 1.0 / 65536
    assert abs(float(table.mean())) < 1e-3 and abs(float(table.std()) - math.sqrt(4.0 + 1.0 / 12.0)) < 0.01

"""Generate the demos' small textures: boards, tiles, plaster, parquet, stone, wallpaper and grass.

Procedural and deterministic (a fixed seed), so an unchanged generator rewrites
the same files. Every image wraps seamlessly (noise is built from whole periods
of the image), since the demos repeat them across walls and floors. The new
ones are pale and low in contrast: they multiply a mesh's colour, which tints
them, and must stay quiet under the picture. Regenerate with ``python -m demos.assets.make_textures``.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
from PIL import Image

HERE = Path(__file__).resolve().parent
SIZE = 64


def planks(size: int = SIZE, boards: int = 4, seed: int = 7) -> np.ndarray:
    """Vertical boards with a wavy grain and dark seams, (size, size, 3) uint8."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size] / size
    board = np.floor(x * boards).astype(int)
    tone = rng.uniform(0.8, 1.1, boards)[board]
    grain = 0.5 + 0.5 * np.sin(2 * np.pi * (x * boards * 6 + 0.6 * np.sin(2 * np.pi * (y * 2 + board * 0.37))))
    wood = np.array([0.62, 0.42, 0.24]) * (0.85 + 0.15 * grain)[..., None] * tone[..., None]
    seam = (x * boards) % 1.0 < 0.06
    wood[seam] *= 0.45
    return np.clip(wood * 255 + 0.5, 0, 255).astype(np.uint8)


def tiles(size: int = SIZE, count: int = 4, seed: int = 11) -> np.ndarray:
    """Glazed square tiles in two blues with light grout, (size, size, 3) uint8."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size] / size
    cell = np.floor(x * count).astype(int) + count * np.floor(y * count).astype(int)
    pick = rng.integers(0, 2, count * count)[cell]
    glaze = np.where(pick[..., None] == 1, np.array([0.22, 0.42, 0.66]), np.array([0.36, 0.6, 0.78]))
    shine = 1.0 + 0.12 * (1.0 - ((x * count) % 1.0 + (y * count) % 1.0))
    colour = glaze * shine[..., None]
    grout = ((x * count) % 1.0 < 0.07) | ((y * count) % 1.0 < 0.07)
    colour[grout] = (0.88, 0.86, 0.8)
    return np.clip(colour * 255 + 0.5, 0, 255).astype(np.uint8)


def _noise(size: int, cells: int, rng: np.random.Generator) -> np.ndarray:
    """Smooth value noise in [0, 1] that wraps at the image's edges: ``cells`` random values per side, bicubic."""
    grid = rng.uniform(0.0, 1.0, (cells, cells))
    t = np.arange(size) * cells / size
    i = np.floor(t).astype(int)
    f = t - i
    f = f * f * (3.0 - 2.0 * f)
    rows = grid[i % cells] * (1 - f)[:, None] + grid[(i + 1) % cells] * f[:, None]
    return rows[:, i % cells] * (1 - f)[None, :] + rows[:, (i + 1) % cells] * f[None, :]


def _fractal(size: int, rng: np.random.Generator, base: int = 4, octaves: int = 4) -> np.ndarray:
    """Octaves of :func:`_noise`, each twice as fine and half as strong, normalised to [0, 1]."""
    total = np.zeros((size, size))
    for k in range(octaves):
        total = total + 0.5**k * _noise(size, base * 2**k, rng)
    return (total - total.min()) / max(float(np.ptp(total)), 1e-9)


def _rgb(colour: np.ndarray) -> np.ndarray:
    return np.clip(colour * 255 + 0.5, 0, 255).astype(np.uint8)


def plaster(size: int = 128, seed: int = 3) -> np.ndarray:
    """Near-white trowelled plaster: a faint cloudy mottle, to be tinted by the wall's colour."""
    rng = np.random.default_rng(seed)
    tone = 0.9 + 0.1 * _fractal(size, rng, 4, 5)
    return _rgb(np.stack([tone, tone * 0.99, tone * 0.97], axis=-1))


def parquet(size: int = 128, rows: int = 4, seed: int = 5) -> np.ndarray:
    """Floorboards laid along x in staggered lengths, pale honey wood with a soft grain."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size] / size
    row = np.floor(y * rows).astype(int)
    shifted = (x + 0.5 * (row % 2) + 0.25 * (row % 3 == 2)) % 1.0
    board = row * 2 + np.floor(shifted * 2).astype(int)
    tone = rng.uniform(0.86, 1.06, rows * 2)[board]
    grain = _fractal(size, rng, 2, 3)
    streak = 0.5 + 0.5 * np.sin(2 * np.pi * (y * rows * 5 + 1.5 * grain))
    wood = np.array([0.80, 0.62, 0.42]) * (0.9 + 0.1 * streak)[..., None] * tone[..., None]
    seam = ((y * rows) % 1.0 < 0.05) | ((shifted * 2) % 1.0 < 0.02)
    wood[seam] *= 0.6
    return _rgb(wood)


def stone(size: int = 128, rows: int = 4, seed: int = 13) -> np.ndarray:
    """Ashlar: courses of pale stone blocks in running bond with grey mortar, each block its own shade."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size] / size
    row = np.floor(y * rows).astype(int)
    shifted = (x * 2 + 0.5 * (row % 2)) % 2.0
    cell = row * 2 + np.floor(shifted).astype(int)
    tone = rng.uniform(0.84, 1.0, rows * 2)[cell]
    grit = 0.9 + 0.1 * _fractal(size, rng, 8, 3)
    colour = np.array([0.92, 0.89, 0.82]) * (tone * grit)[..., None]
    mortar = ((y * rows) % 1.0 < 0.06) | (shifted % 1.0 < 0.03)
    colour[mortar] = (0.62, 0.6, 0.57)
    return _rgb(colour)


def wallpaper(size: int = 128, count: int = 4) -> np.ndarray:
    """A quiet damask: small diamonds on a lattice over a pale ground, the same either way up (box faces turn
    their UVs differently, so a pattern with a direction would run sideways on some walls)."""
    y, x = np.mgrid[0:size, 0:size] / size
    u, v = (x * count) % 1.0 - 0.5, (y * count) % 1.0 - 0.5
    diamond = np.abs(u) + np.abs(v) < 0.22
    ring = np.abs(np.abs(u) + np.abs(v) - 0.42) < 0.03
    tone = np.where(diamond, 0.84, np.where(ring, 0.9, 1.0))
    return _rgb(np.stack([tone, tone * 0.97, tone * 0.92], axis=-1))


def grass(size: int = 128, seed: int = 17) -> np.ndarray:
    """Mown grass: green with soft patches and fine blades, no stripes (the lawn is tinted by its colour)."""
    rng = np.random.default_rng(seed)
    patches = _fractal(size, rng, 4, 3)
    blades = rng.uniform(0.0, 1.0, (size, size))
    tone = 0.78 + 0.14 * patches + 0.08 * blades
    return _rgb(np.array([0.92, 1.0, 0.86]) * tone[..., None])


#: The generated images, by file name.
TEXTURES: dict[str, Callable[[], np.ndarray]] = {
    "planks.png": planks,
    "tiles.png": tiles,
    "plaster.png": plaster,
    "parquet.png": parquet,
    "stone.png": stone,
    "wallpaper.png": wallpaper,
    "grass.png": grass,
}


def main() -> int:
    for name, make in TEXTURES.items():
        image = make()
        Image.fromarray(image).save(HERE / name, optimize=True)
        print(f"wrote {HERE / name} ({image.shape[1]}x{image.shape[0]})")
    return 0


if __name__ == "__main__":
    sys.exit(main())

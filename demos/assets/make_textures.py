"""Generate the demos' small textures: ``planks.png`` (wood boards) and ``tiles.png`` (glazed tiles).

Procedural and deterministic (a fixed seed), so an unchanged generator rewrites
the same files. Regenerate with ``python -m demos.assets.make_textures``.
"""

from __future__ import annotations

import sys
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


def main() -> int:
    for name, image in (("planks.png", planks()), ("tiles.png", tiles())):
        Image.fromarray(image).save(HERE / name, optimize=True)
        print(f"wrote {HERE / name} ({image.shape[1]}x{image.shape[0]})")
    return 0


if __name__ == "__main__":
    sys.exit(main())

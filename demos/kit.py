"""Shared building blocks for the demo levels: world-checkered blocks, rooms with doorways, a palette.

Not a demo (not in the registry): the levels import it so that walls, floors
and doorways are built the same way everywhere, and a doorway and the portal
that fills it always agree on their size.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from engine.scene import Scene

#: A unit cube without UVs: its checker is world-space, so cells are square on every face of every size
#: of block, and a deformed region shows as deformed cells.
BLOCK_PATH = Path(__file__).resolve().parent / "assets" / "block.obj"
BLOCK = "block"
#: The generated textures (demos/assets/make_textures.py).
ASSETS = Path(__file__).resolve().parent / "assets"
#: World units one repeat of a texture covers on a textured block (each image holds about four boards,
#: courses or tiles across, so a board is about 0.75 units wide).
TILE = 3.0
#: How far neighbouring pieces of a textured block reach into each other (world units).
SEAM = 5e-3

Vec3 = tuple[float, float, float]
Color = tuple[float, float, float]

# A palette that reads well under one directional light and 35 % ambient.
CHALK: Color = (0.93, 0.91, 0.86)
SAND: Color = (0.86, 0.77, 0.60)
CLAY: Color = (0.80, 0.45, 0.32)
RED: Color = (0.86, 0.22, 0.20)
BLUE: Color = (0.22, 0.42, 0.88)
GREEN: Color = (0.25, 0.70, 0.35)
PURPLE: Color = (0.56, 0.30, 0.80)
GOLD: Color = (0.98, 0.76, 0.30)
TEAL: Color = (0.18, 0.60, 0.62)
NAVY: Color = (0.16, 0.20, 0.38)
SLATE: Color = (0.42, 0.46, 0.54)
CORAL: Color = (0.95, 0.50, 0.42)
MINT: Color = (0.62, 0.86, 0.74)
LAWN: Color = (0.42, 0.62, 0.30)
CHARCOAL: Color = (0.06, 0.06, 0.07)
ROSE: Color = (0.88, 0.55, 0.68)
SKY: Color = (0.56, 0.72, 0.90)
IVORY: Color = (0.97, 0.95, 0.88)


def use_blocks(scene: Scene) -> None:
    """Register the world-checkered block asset (call once per scene before :func:`block`)."""
    scene.add_asset(BLOCK, path=BLOCK_PATH)


def texture(name: str) -> str:
    """The path of a generated texture by its stem (``"plaster"``, ``"parquet"``, ``"stone"``...)."""
    return str(ASSETS / f"{name}.png")


def block(
    scene: Scene,
    name: str,
    lo: Sequence[float],
    hi: Sequence[float],
    color: Color,
    checker: float = 0.0,
    *,
    image: str = "",
    tile: float = TILE,
) -> int:
    """An axis-aligned block between the corners ``lo`` and ``hi`` (easier to lay out than centre and size).

    With an ``image`` (a path, see :func:`texture`) the block is built of ``box`` primitives, whose UVs
    span each face once, about ``tile`` units on a side each, so the texture repeats at one world scale
    whatever the block's size (``checker`` then counts cells per repeat). Returns the (first) entity.
    """
    lo, hi = [min(a, b) for a, b in zip(lo, hi, strict=True)], [max(a, b) for a, b in zip(lo, hi, strict=True)]
    if not image:
        centre = tuple(0.5 * (a + b) for a, b in zip(lo, hi, strict=True))
        size = tuple(b - a for a, b in zip(lo, hi, strict=True))
        return scene.add_mesh(name, BLOCK, position=centre, scale=size, color=color, checker=checker)
    counts = [max(1, round((b - a) / tile)) for a, b in zip(lo, hi, strict=True)]
    first = -1
    for cell in itertools.product(*(range(n) for n in counts)):
        # Neighbouring pieces overlap by SEAM at the faces they share, so no ray (nor a point on the seam)
        # falls between two separately transformed boxes; the block's outer faces stay where they were asked.
        spans = [
            (a + c * (b - a) / n - (SEAM if c > 0 else 0.0), a + (c + 1) * (b - a) / n + (SEAM if c < n - 1 else 0.0))
            for a, b, n, c in zip(lo, hi, counts, cell, strict=True)
        ]
        piece = name if counts == [1, 1, 1] else f"{name}_{cell[0]}_{cell[1]}_{cell[2]}"
        entity = scene.add_mesh(
            piece, "box", position=tuple(0.5 * (u + v) for u, v in spans), scale=tuple(v - u for u, v in spans),
            color=color, checker=checker, texture=image,
        )  # fmt: skip
        first = entity if first < 0 else first
    return first


@dataclass(frozen=True)
class Door:
    """An opening in a wall: ``offset`` of its centre along the wall from the wall's middle, its width and height.

    Along a north or south wall the offset is along +x, along an east or west wall along +z.
    """

    offset: float = 0.0
    width: float = 1.6
    height: float = 2.4


#: Wall sides: which axis the wall is perpendicular to and on which end of the room it stands.
SIDES: dict[str, tuple[int, int]] = {"west": (0, 0), "east": (0, 1), "north": (2, 0), "south": (2, 1)}


def doorway(
    lo: Sequence[float], hi: Sequence[float], side: str, door: Door, thickness: float, *, inward: bool = False
) -> dict[str, object]:
    """Position, rotation and scale of a portal filling ``door`` (in the middle of the wall's thickness).

    The portal's front (+Z) points out of the room, or into it with
    ``inward``. A portal maps its front to its target's front, so a pair that
    leads out of one room *into* another has one doorway of each kind.
    """
    axis, end = SIDES[side]
    along = 2 if axis == 0 else 0
    centre = [0.5 * (lo[0] + hi[0]), lo[1] + 0.5 * door.height, 0.5 * (lo[2] + hi[2])]
    centre[axis] = (hi[axis] + 0.5 * thickness) if end else (lo[axis] - 0.5 * thickness)
    centre[along] += door.offset
    yaw = {"west": -90.0, "east": 90.0, "north": 180.0, "south": 0.0}[side] + (180.0 if inward else 0.0)
    return {
        "position": tuple(centre),
        "euler_deg": (0.0, yaw, 0.0),
        "scale": (0.5 * door.width, 0.5 * door.height, 1.0),
    }


def room(
    scene: Scene,
    prefix: str,
    lo: Sequence[float],
    hi: Sequence[float],
    *,
    wall: Color,
    floor: Color,
    ceiling: Color | None = None,
    thickness: float = 0.3,
    checker: float = 0.5,
    floor_checker: float = 1.0,
    doors: dict[str, Sequence[Door]] | None = None,
    wall_colors: dict[str, Color] | None = None,
    wall_image: str = "",
    floor_image: str = "",
    ceiling_image: str = "",
) -> None:
    """A closed room whose *interior* is the box ``lo``..``hi``: floor, walls (with openings) and ceiling.

    Walls, floor and ceiling are built outside the interior, ``thickness``
    thick, so the interior measures exactly what was asked. ``ceiling=None``
    leaves the room open to the sky. ``*_image`` textures the walls, floor or ceiling (see :func:`block`;
    a textured surface's checker, if any, counts cells per repeat).
    """
    doors = doors or {}
    wall_colors = wall_colors or {}
    t = thickness
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    block(scene, f"{prefix}_floor", (x0 - t, y0 - t, z0 - t), (x1 + t, y0, z1 + t), floor, floor_checker,
          image=floor_image)  # fmt: skip
    if ceiling is not None:
        # Plain: a checkered ceiling is noise over the picture.
        block(scene, f"{prefix}_ceiling", (x0 - t, y1, z0 - t), (x1 + t, y1 + t, z1 + t), ceiling, image=ceiling_image)
    for side, (axis, end) in SIDES.items():
        along = 2 if axis == 0 else 0
        # North/south walls run over the corners; east/west walls fit between them.
        start, stop = (x0 - t, x1 + t) if along == 0 else (z0, z1)
        middle = 0.5 * ((x0 + x1) if along == 0 else (z0 + z1))
        plane = (hi[axis], hi[axis] + t) if end else (lo[axis] - t, lo[axis])
        color = wall_colors.get(side, wall)
        openings = sorted((middle + d.offset - 0.5 * d.width, d.width, d.height) for d in doors.get(side, ()))
        pieces: list[tuple[float, float, float, float]] = []  # (along from, along to, y from, y to)
        cursor = start
        for a, width, height in openings:
            b = a + width
            if a > cursor:
                pieces.append((cursor, a, y0, y1))
            if y0 + height < y1:
                pieces.append((a, b, y0 + height, y1))  # the lintel over the door
            cursor = b
        if cursor < stop:
            pieces.append((cursor, stop, y0, y1))
        for i, (a, b, ya, yb) in enumerate(pieces):
            c0, c1 = [0.0, ya, 0.0], [0.0, yb, 0.0]
            c0[axis], c1[axis] = plane
            c0[along], c1[along] = a, b
            block(scene, f"{prefix}_{side}_{i}", c0, c1, color, checker, image=wall_image)

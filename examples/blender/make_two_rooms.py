"""Build ``two_rooms.glb`` beside this file: two rooms joined by a portal doorway, one stretched by an aberration.

The starting file for the Blender workflow (README, "glTF scenes from Blender"):
open it in Blender, move the rooms, the doorway's portals or the aberration's
box, edit their ``aberrant`` custom property, export it back as glTF 2.0 with
custom properties, and play it with ``aberrant play two_rooms.glb``.

Run from anywhere: ``python examples/blender/make_two_rooms.py [OUT.glb]``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import aberrant
from demos.kit import CHALK, CLAY, GOLD, SAND, SKY, TEAL, Door, block, doorway, room, use_blocks

HERE = Path(__file__).resolve().parent
#: The doorway both rooms share, in the middle of the first room's east wall and the second room's west wall.
DOOR = Door(width=1.6, height=2.4)
#: The second room stands far from the first: only the portals join them.
SECOND = 40.0


def build() -> aberrant.Scene:
    """Room A (8 x 3 x 8) with a doorway east into room B, whose hall is twice as long inside as outside."""
    scene = aberrant.Scene("two_rooms", settings=aberrant.Settings(background=(0.55, 0.7, 0.9), ambient=0.4))
    use_blocks(scene)
    a_lo, a_hi = (-4.0, 0.0, -4.0), (4.0, 3.0, 4.0)
    b_lo, b_hi = (SECOND - 4.0, 0.0, -4.0), (SECOND + 4.0, 3.0, 4.0)
    room(scene, "room_a", a_lo, a_hi, wall=CHALK, floor=SAND, ceiling=CHALK, doors={"east": [DOOR]})
    room(scene, "room_b", b_lo, b_hi, wall=TEAL, floor=SAND, ceiling=CHALK, doors={"west": [DOOR]})
    block(scene, "crate", (-2.5, 0.0, -2.5), (-1.5, 1.0, -1.5), CLAY, 0.5)
    for i in range(4):  # pillars down room B: inside the aberration they are spread twice as far apart
        x = SECOND - 2.5 + 1.6 * i
        block(scene, f"pillar_{i}", (x - 0.2, 0.0, 2.0), (x + 0.2, 3.0, 2.4), GOLD)
    scene.add_aberration("long_hall", (1.0, 0.0, 0.0), position=(SECOND + 0.5, 1.5, 0.0), scale=(6.0, 3.0, 7.6))
    scene.add_portal_pair(
        "door_a",
        "door_b",
        a=doorway(a_lo, a_hi, "east", DOOR, 0.3),
        b=doorway(b_lo, b_hi, "west", DOOR, 0.3, inward=True),
    )
    scene.add_mesh("sky_marker", "sphere", position=(SECOND + 3.0, 1.2, -2.5), scale=0.6, color=SKY)
    scene.set_camera((-2.5, 1.6, 2.5), look_at=(4.0, 1.3, 0.0))
    return scene


def main(argv: list[str]) -> int:
    out = Path(argv[1]) if len(argv) > 1 else HERE / "two_rooms.glb"
    scene = build()
    try:
        aberrant.export_gltf(scene, out)
    finally:
        scene.close()
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv))

"""The thesis's geometry-changing room: step between a wall and a column, and the room around you is another.

Two rooms that share nothing but one gap: a warm rectangular room (sand
walls, a checkered floor, a knot on a plinth) and a cool octagonal hall
(teal walls, a ring of pyramids and spheres), 40 units apart. In each, a
partition runs from the west wall to the middle, and a column stands two units
past its end; the gap between the end of the wall and the column holds one
portal of a pair. From the warm room the gap is a window into the back of the
hall, while beside the column the warm room goes on; walk through the gap and
you are in the hall, walk round the column and you are not. Looking back
through the gap from the hall shows the warm room. The thesis's point: any
number of rooms fit in a small scene.
"""

from __future__ import annotations

import math

from demos.kit import (
    BLOCK,
    CLAY,
    CORAL,
    GOLD,
    IVORY,
    MINT,
    NAVY,
    SAND,
    SKY,
    TEAL,
    block,
    room,
    texture,
    use_blocks,
)
from demos.starter import KNOT_PATH
from engine.scene import Scene
from engine.settings import Settings
from systems.camera_path import CameraPath
from systems.route import Stop, with_scene

#: Place in the demo gallery (``aberrant demos``); see demos/__init__.py.
ORDER = 3

HEIGHT = 3.6
#: Where the hall is, relative to the warm room (the portals map one onto the other by this shift).
HALL = 40.0
#: The gap: from the end of the partition (x = -1) to the column (x = +1), at z = 0.
GAP = 1.0
EYE = 1.7
START = (2.2, 1.8, 5.4)
START_LOOK = (-0.2, 1.3, -3.0)


def warm_room(scene: Scene) -> None:
    """The rectangular room at the origin: sand and clay, warm light wood floor."""
    room(scene, "warm", (-6.0, 0.0, -6.0), (6.0, HEIGHT, 6.0), wall=SAND, floor=(0.95, 0.82, 0.68),
         ceiling=IVORY, checker=1.2, floor_checker=0.0, floor_image=texture("parquet"),
         wall_colors={"north": CLAY})  # fmt: skip
    block(scene, "warm_partition", (-6.0, 0.0, -0.2), (-GAP, HEIGHT, 0.2), CLAY, 1.2)
    block(scene, "warm_column", (GAP, 0.0, -0.5), (GAP + 1.0, HEIGHT, 0.5), CLAY, 1.2)
    # The back of the room, seen beside the column (and, from the hall, through the gap).
    scene.add_mesh(
        "warm_plinth", "cylinder", smooth=True, position=(-3.2, 0.45, -3.2), scale=(1.6, 0.9, 1.6), color=IVORY
    )
    scene.add_mesh(
        "warm_knot",
        "knot",
        smooth=True,
        position=(-3.2, 1.75, -3.2),
        euler_deg=(90.0, 20.0, 0.0),
        scale=2.0,
        color=GOLD,
    )
    block(scene, "warm_crate", (3.0, 0.0, -5.0), (4.6, 1.6, -3.4), CORAL, 0.4)
    block(scene, "warm_crate_top", (3.4, 1.6, -4.6), (4.2, 2.4, -3.8), GOLD, 0.4)
    scene.add_mesh("warm_ball", "sphere", smooth=True, position=(-4.2, 0.6, 3.8), scale=1.2, color=CORAL, checker=0.3)


def octagon_hall(scene: Scene) -> None:
    """The octagonal hall at x = HALL: teal walls, navy floor, pyramids and spheres in a ring."""
    apothem, side = 7.0, 2.0 * 7.0 * math.tan(math.radians(22.5)) + 0.6
    block(scene, "hall_floor", (HALL - 8.0, -0.3, -8.0), (HALL + 8.0, 0.0, 8.0), NAVY, 0.5)
    block(scene, "hall_ceiling", (HALL - 8.0, HEIGHT, -8.0), (HALL + 8.0, HEIGHT + 0.3, 8.0), MINT, 1.0)
    for k in range(8):
        angle = 45.0 * k  # 0 = the west wall (the one the partition starts from)
        a = math.radians(angle)
        centre = (HALL - (apothem + 0.15) * math.cos(a), 0.5 * HEIGHT, (apothem + 0.15) * math.sin(a))
        scene.add_mesh(
            f"hall_wall_{k}", BLOCK, position=centre, euler_deg=(0.0, angle, 0.0), scale=(0.3, HEIGHT, side),
            color=TEAL if k % 2 else SKY, checker=0.6,
        )  # fmt: skip
    block(scene, "hall_partition", (HALL - apothem, 0.0, -0.2), (HALL - GAP, HEIGHT, 0.2), SKY, 0.6)
    scene.add_mesh("hall_column", "cylinder", smooth=True, position=(HALL + GAP + 0.5, 0.5 * HEIGHT, 0.0),
                   scale=(1.0, HEIGHT, 1.0), color=SKY)  # fmt: skip
    # Pyramids and spheres about the room, clear of the walk through the gap and round the column.
    for k, (dx, dz) in enumerate(((-1.8, -4.4), (3.4, -3.8), (-4.6, -2.6), (-4.2, 3.6), (4.4, 4.4))):
        if k % 2:
            scene.add_mesh(f"hall_sphere_{k}", "sphere", position=(HALL + dx, 0.7, dz), scale=1.4, color=GOLD,
                           smooth=True, checker=0.25)  # fmt: skip
        else:
            scene.add_mesh(f"hall_pyramid_{k}", "pyramid", position=(HALL + dx, 0.8, dz),
                           euler_deg=(0.0, 20.0 * k, 0.0), scale=1.6, color=CORAL)  # fmt: skip
    scene.add_mesh(
        "hall_dais", "cylinder", smooth=True, position=(HALL + 0.6, 0.2, 4.8), scale=(2.4, 0.4, 2.4), color=IVORY
    )


def build() -> Scene:
    """Both rooms and the portal pair in their gaps; the camera in the warm room, facing the gap."""
    scene = Scene("geometry_room", settings=Settings(background=(0.05, 0.05, 0.07), light_dir=(0.35, 0.9, 0.45)))
    use_blocks(scene)
    scene.add_asset("knot", path=KNOT_PATH)
    warm_room(scene)
    octagon_hall(scene)
    # The gap between the end of the partition and the column, full height, in the middle of the partition.
    gap = {"scale": (GAP, 0.5 * HEIGHT, 1.0)}
    scene.add_portal_pair(
        "warm_gap", "hall_gap", a={"position": (0.0, 0.5 * HEIGHT, 0.0), **gap},
        b={"position": (HALL, 0.5 * HEIGHT, 0.0), **gap}, color=GOLD,
    )  # fmt: skip
    scene.set_camera(START, look_at=START_LOOK, fov_deg=65.0, speed=3.0)
    return scene


def stops() -> list[Stop]:
    """Through the gap into the hall, look back at the warm room, round the column, and look again."""
    return [
        Stop(START, START_LOOK),
        Stop((0.0, EYE, 3.2), (0.0, EYE - 0.1, -3.0)),
        Stop((HALL, EYE, -2.4), (HALL + 0.8, EYE - 0.3, -6.0), via="warm_gap"),
        Stop((HALL + 0.4, EYE, -2.6), (HALL + 0.2, EYE - 0.1, 2.0)),
        Stop((HALL + 3.3, EYE, -1.5), (HALL + 3.3, EYE, 2.0)),
        Stop((HALL + 3.3, EYE, 2.6), (HALL, EYE - 0.1, -2.0)),
        Stop((HALL + 1.5, EYE, 4.0), (HALL - 0.4, EYE - 0.2, -2.0)),
    ]


def camera_path() -> CameraPath:
    """The walk of :func:`stops`, converted for the real systems (aberrations, portals)."""
    return with_scene(build, stops())

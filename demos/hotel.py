"""A hotel corridor of 50 doors, each onto a different room far bigger than the corridor has room for.

The corridor is 4 units wide and 64 long; 25 doors a side, 2.4 units apart,
each filled by a portal whose partner is the door of a room 7 to 14 units
wide and 8 to 18 deep, far under the corridor where no ray from it reaches: 50 rooms
that could not fit behind those doors, side by side, each its own colours
and furniture (bedrooms, libraries, a pool, a garden, a dining room...).
One of them, the suite, holds a room inside the room: a closet in its middle
whose door opens onto a ballroom bigger than the whole suite. And the
ballroom's far door leads back to where the walk started, the corridor's
south end, so walking straight on from the ballroom one comes out in the
corridor facing its 50 doors again. 104 portals in all, every one a doorway.
"""

from __future__ import annotations

import numpy as np

from demos.kit import (
    BLUE,
    CHALK,
    CLAY,
    CORAL,
    GOLD,
    GREEN,
    IVORY,
    LAWN,
    MINT,
    NAVY,
    PURPLE,
    RED,
    ROSE,
    SAND,
    SKY,
    SLATE,
    TEAL,
    Color,
    Door,
    Vec3,
    block,
    doorway,
    room,
    texture,
    use_blocks,
)
from engine.scene import Scene
from engine.settings import Settings
from systems.camera_path import CameraPath
from systems.route import Stop, with_scene

WALL = 0.3
DOOR = Door(width=1.6, height=2.5)
#: The corridor's interior; doors every 2.4 units along both long walls, the first 4 units from the south end.
CORRIDOR = ((-2.0, 0.0, -64.0), (2.0, 3.2, 0.0))
DOORS_PER_SIDE = 25
DOOR_PITCH, FIRST_DOOR = 2.4, -4.0
#: The rooms lie on a grid this far under the corridor, 30 units apart (the largest is 15 x 19).
ROOMS_Y = -80.0
ROOM_PITCH = 30.0
#: The suite is the room behind the third east door; the closet in it and the ballroom it opens onto.
SUITE_DOOR = 2
CLOSET_DOOR = Door(width=1.0, height=2.1)
CLOSET_WALL = 0.15
BALLROOM = ((-12.0, -200.0, -16.0), (12.0, -193.0, 16.0))
EXIT_DOOR = Door(width=1.6, height=2.5)
EYE = 1.7
START = (-1.1, 1.7, -1.6)
START_LOOK = (2.0, 1.25, -7.5)
#: Wall, floor and accent colours the rooms cycle through.
SCHEMES: tuple[tuple[Color, Color, Color], ...] = (
    (CORAL, SAND, GOLD),
    (SKY, NAVY, IVORY),
    (MINT, CLAY, RED),
    (ROSE, SLATE, TEAL),
    (SAND, GREEN, PURPLE),
    (TEAL, CHALK, CORAL),
    (PURPLE, IVORY, GOLD),
    (IVORY, RED, BLUE),
    (GOLD, NAVY, MINT),
    (BLUE, SAND, ROSE),
)
THEMES: tuple[str, ...] = ("bedroom", "library", "pool", "garden", "dining", "gallery", "columns")

Box = tuple[Vec3, Vec3]


def door_z(k: int) -> float:
    """The centre (z) of the k-th door from the south, on either side of the corridor."""
    return FIRST_DOOR - DOOR_PITCH * k


def room_box(index: int) -> tuple[Box, float]:
    """Room ``index``'s interior and its door's offset along its door wall (sizes vary with the index)."""
    rng = np.random.default_rng(1000 + index)
    width = float(rng.uniform(7.0, 14.0)) if index != SUITE_DOOR else 13.0
    depth = float(rng.uniform(8.0, 18.0)) if index != SUITE_DOOR else 15.0
    height = float(rng.uniform(3.0, 4.4))
    offset = float(rng.uniform(-0.5, 0.5) * (depth - 3.0)) if index != SUITE_DOOR else 0.0
    cx = 40.0 + ROOM_PITCH * (index % 10)
    cz = -ROOM_PITCH * (index // 10)
    lo = (cx - 0.5 * width, ROOMS_Y, cz - 0.5 * depth)
    hi = (cx + 0.5 * width, ROOMS_Y + height, cz + 0.5 * depth)
    return (lo, hi), offset


def corridor(scene: Scene) -> None:
    """The corridor: doors down both sides, a runner, lamps, and the door back at its south end."""
    lo, hi = CORRIDOR
    side_doors = [corridor_door(k) for k in range(DOORS_PER_SIDE)]
    room(scene, "corridor", lo, hi, wall=CHALK, floor=(0.86, 0.74, 0.6), ceiling=IVORY, thickness=WALL,
         checker=0.0, floor_checker=0.0, wall_image=texture("plaster"), floor_image=texture("parquet"),
         doors={"east": side_doors, "west": side_doors, "south": [EXIT_DOOR]},
         wall_colors={"north": NAVY})  # fmt: skip
    block(scene, "corridor_runner", (-0.7, 0.0, lo[2]), (0.7, 0.02, hi[2]), RED)
    block(scene, "corridor_painting", (-1.0, 1.0, lo[2]), (1.0, 2.4, lo[2] + 0.05), GOLD)
    for k in range(0, DOORS_PER_SIDE, 3):
        z = door_z(k) - 0.5 * DOOR_PITCH
        block(scene, f"corridor_lamp_{k}", (-0.25, hi[1] - 0.1, z - 0.25), (0.25, hi[1], z + 0.25), GOLD)


def corridor_door(k: int) -> Door:
    """The k-th door from the south on either long wall (its offset is from the wall's middle)."""
    return Door(door_z(k) - 0.5 * (CORRIDOR[0][2] + CORRIDOR[1][2]), DOOR.width, DOOR.height)


def furnish(scene: Scene, prefix: str, box: Box, door_wall: str, theme: str, accent: Color, seed: int) -> None:
    """A few pieces by the room's theme, laid out in (u, z): u the distance from the door wall, so that they
    stand towards the far wall whichever side the door is on."""
    (x0, y, z0), (x1, top, z1) = box
    width, zm = x1 - x0, 0.5 * (z0 + z1)
    sign, wall_x = (1.0, x0) if door_wall == "west" else (-1.0, x1)
    rng = np.random.default_rng(seed)

    def x(u: float) -> float:
        return wall_x + sign * u

    def piece(name: str, u: tuple[float, float], ys: tuple[float, float], zs: tuple[float, float], color: Color,
              checker: float = 0.0) -> None:  # fmt: skip
        block(scene, f"{prefix}_{name}", (x(u[0]), y + ys[0], zs[0]), (x(u[1]), y + ys[1], zs[1]), color, checker)

    def ball(name: str, u: float, height: float, z: float, size: float, color: Color, checker: float = 0.0) -> None:
        scene.add_mesh(f"{prefix}_{name}", "sphere", position=(x(u), y + height, z), scale=size, color=color,
                       smooth=True, checker=checker)  # fmt: skip

    far = width
    if theme == "bedroom":
        piece("bed", (far - 2.4, far - 0.1), (0.0, 0.6), (zm - 1.1, zm + 1.1), IVORY)
        piece("blanket", (far - 1.6, far - 0.1), (0.6, 0.68), (zm - 1.1, zm + 1.1), accent, 0.3)
        piece("table", (far - 0.9, far - 0.1), (0.0, 0.7), (zm + 1.4, zm + 2.2), CLAY)
        ball("lamp", far - 0.5, 1.0, zm + 1.8, 0.5, GOLD)
    elif theme == "library":
        third = (z1 - z0 - 0.8) / 3.0
        for i in range(3):
            z = z0 + 0.4 + i * third
            piece(f"shelf_{i}", (far - 0.6, far), (0.0, 2.6), (z, z + 0.8 * third), accent, 0.3)
        ball("globe", 0.55 * far, 0.7, zm, 1.2, GOLD, 0.2)
    elif theme == "pool":
        piece("pool", (0.45 * far, far - 1.0), (0.0, 0.05), (z0 + 1.0, z1 - 1.0), (0.2, 0.5, 0.85), 0.5)
        for i in range(2):
            z = z0 + 1.5 + 2.0 * i
            piece(f"chair_{i}", (0.45 * far - 1.6, 0.45 * far - 0.8), (0.0, 0.4), (z, z + 1.6), accent)
    elif theme == "garden":
        piece("lawn", (0.0, far), (0.0, 0.03), (z0, z1), LAWN, 0.5)
        for i in range(3):
            u, z = float(rng.uniform(0.5 * far, far - 1.0)), float(rng.uniform(z0 + 1.0, z1 - 1.0))
            scene.add_mesh(f"{prefix}_trunk_{i}", "cylinder", position=(x(u), y + 0.8, z), scale=(0.3, 1.6, 0.3),
                           smooth=True, color=(0.45, 0.3, 0.2))  # fmt: skip
            ball(f"crown_{i}", u, 2.0, z, 1.4, accent)
    elif theme == "dining":
        piece("table", (0.5 * far - 0.5, 0.5 * far + 1.3), (0.7, 0.8), (z0 + 1.5, z1 - 1.5), IVORY)
        piece("leg", (0.5 * far + 0.2, 0.5 * far + 0.6), (0.0, 0.7), (zm - 0.2, zm + 0.2), CLAY)
        for i in range(4):
            z = z0 + 2.0 + i * (z1 - z0 - 4.0) / 3.0
            piece(f"chair_{i}", (0.5 * far + 1.6, 0.5 * far + 2.2), (0.0, 0.9), (z - 0.3, z + 0.3), accent)
    elif theme == "gallery":
        for i in range(4):
            z = z0 + 1.0 + i * (z1 - z0 - 2.0) / 4.0
            color = SCHEMES[(i + int(rng.integers(10))) % len(SCHEMES)][2]
            piece(f"panel_{i}", (far - 0.06, far), (1.0, 2.4), (z, z + 1.2), color)
        scene.add_mesh(f"{prefix}_statue", "pyramid", position=(x(0.6 * far), y + 0.8, zm), scale=1.6, color=accent)
    else:  # columns
        for i in range(4):
            u, z = (0.4 if i % 2 else 0.75) * far, zm + (2.0 if i // 2 else -2.0)
            scene.add_mesh(f"{prefix}_column_{i}", "cylinder", smooth=True, position=(x(u), 0.5 * (y + top), z),
                           scale=(0.6, top - y, 0.6), color=accent)  # fmt: skip


def suite_furniture(scene: Scene, box: Box) -> None:
    """The suite: a rug before the closet, armchairs and a sofa along its walls (the closet is built apart)."""
    (x0, y, z0), (x1, _, z1) = box
    zm = 0.5 * (z0 + z1)
    block(scene, "suite_rug", (x0 + 2.0, y, zm - 1.5), (x1 - 5.5, y + 0.03, zm + 1.5), PURPLE, 0.4)
    block(scene, "suite_sofa", (x1 - 1.0, y, zm - 2.0), (x1 - 0.1, y + 0.8, zm + 2.0), TEAL)
    for i, z in enumerate((z0 + 1.0, z1 - 2.0)):
        block(scene, f"suite_chair_{i}", (x0 + 4.0, y, z), (x0 + 5.0, y + 0.9, z + 1.0), CORAL)
    scene.add_mesh("suite_lamp", "sphere", smooth=True, position=(x1 - 0.6, y + 1.4, z0 + 0.6), scale=0.6, color=GOLD)


def rooms(scene: Scene) -> None:
    """The 50 rooms and the 50 portal pairs between their doors and the corridor's."""
    for index in range(2 * DOORS_PER_SIDE):
        side, k = ("east", index) if index < DOORS_PER_SIDE else ("west", index - DOORS_PER_SIDE)
        box, offset = room_box(index)
        wall, floor, accent = SCHEMES[index % len(SCHEMES)]
        # An east door of the corridor leads into a room through the room's west wall, and the other way round.
        door_wall = "west" if side == "east" else "east"
        door = Door(offset, DOOR.width, DOOR.height)
        prefix = "suite" if index == SUITE_DOOR else f"room{index}"
        room(scene, prefix, *box, wall=wall, floor=floor, ceiling=IVORY, thickness=WALL, checker=0.0,
             floor_checker=0.5, doors={door_wall: [door]})  # fmt: skip
        if index == SUITE_DOOR:
            suite_furniture(scene, box)
        else:
            furnish(scene, prefix, box, door_wall, THEMES[index % len(THEMES)], accent, index)
        scene.add_portal_pair(
            f"door_{side[0]}{k}",
            f"{prefix}_door",
            a=doorway(*CORRIDOR, side, corridor_door(k), WALL),
            b=doorway(*box, door_wall, door, WALL, inward=True),
            color=accent,
        )


def closet_box() -> Box:
    """The closet's interior: in the suite's middle, its door facing the suite's door (west)."""
    (lo, hi), _ = room_box(SUITE_DOOR)
    xm, zm = 0.5 * (lo[0] + hi[0]), 0.5 * (lo[2] + hi[2])
    return (xm + 1.0, lo[1], zm - 1.0), (xm + 3.0, lo[1] + 2.6, zm + 1.0)


def ballroom(scene: Scene) -> None:
    """The ballroom: two rows of columns, chandeliers, a stage, a rug from door to door (west in, east out)."""
    lo, hi = BALLROOM
    room(scene, "ballroom", lo, hi, wall=(0.55, 0.12, 0.18), floor=IVORY, ceiling=GOLD, thickness=WALL, checker=0.0,
         floor_checker=1.0, doors={"west": [CLOSET_DOOR], "east": [EXIT_DOOR]})  # fmt: skip
    height = hi[1] - lo[1]
    for i in range(5):
        x = -8.0 + 4.0 * i
        for side, z in (("north", -5.0), ("south", 5.0)):
            scene.add_mesh(f"ballroom_column_{side}_{i}", "cylinder", position=(x, lo[1] + 0.5 * height, z),
                           smooth=True, scale=(0.9, height, 0.9), color=IVORY)  # fmt: skip
    for i in range(3):
        scene.add_mesh(f"ballroom_chandelier_{i}", "sphere", position=(-6.0 + 6.0 * i, hi[1] - 1.5, 0.0), scale=1.6,
                       smooth=True, color=GOLD, checker=0.2)  # fmt: skip
    block(scene, "ballroom_stage", (lo[0], lo[1], lo[2]), (hi[0], lo[1] + 0.8, lo[2] + 4.0), PURPLE, 0.5)
    block(scene, "ballroom_rug", (lo[0] + 2.0, lo[1], -2.5), (hi[0] - 2.0, lo[1] + 0.03, 2.5), RED, 0.5)


def build() -> Scene:
    """The corridor, its 50 rooms, the suite's closet, the ballroom, and the 52 portal pairs."""
    scene = Scene("hotel", settings=Settings(background=(0.05, 0.05, 0.08), light_dir=(0.45, 0.8, 0.35), ambient=0.4))
    use_blocks(scene)
    corridor(scene)
    rooms(scene)
    closet_lo, closet_hi = closet_box()
    room(scene, "closet", closet_lo, closet_hi, wall=SLATE, floor=CLAY, ceiling=SLATE, thickness=CLOSET_WALL,
         checker=0.0, doors={"west": [CLOSET_DOOR]})  # fmt: skip
    ballroom(scene)
    # Into the closet (its door faces out of it) is into the ballroom (its west door faces out of it too).
    scene.add_portal_pair(
        "closet_door", "ballroom_west",
        a=doorway(closet_lo, closet_hi, "west", CLOSET_DOOR, CLOSET_WALL),
        b=doorway(*BALLROOM, "west", CLOSET_DOOR, WALL), color=GOLD,
    )  # fmt: skip
    # Out of the ballroom's east door is into the corridor at its south end, turned to face the doors.
    scene.add_portal_pair(
        "ballroom_exit", "corridor_south",
        a=doorway(*BALLROOM, "east", EXIT_DOOR, WALL),
        b=doorway(*CORRIDOR, "south", EXIT_DOOR, WALL, inward=True), color=TEAL,
    )  # fmt: skip
    scene.set_camera(START, look_at=START_LOOK, fov_deg=64.0, speed=3.0)
    return scene


def stops() -> list[Stop]:
    """Up the corridor, into the suite, into its closet (the ballroom), across it and out: back at the start."""
    z = door_z(SUITE_DOOR)
    (lo, hi), _ = room_box(SUITE_DOOR)
    suite_z, suite_y = 0.5 * (lo[2] + hi[2]), lo[1] + EYE
    closet_lo, closet_hi = closet_box()
    closet_z = 0.5 * (closet_lo[2] + closet_hi[2])
    ball_lo, ball_hi = BALLROOM
    ball_y = ball_lo[1] + EYE
    return [
        Stop(START, START_LOOK),
        Stop((0.0, EYE, z + 1.2), (0.0, EYE - 0.1, -30.0)),
        Stop((-0.6, EYE, z), (4.0, EYE - 0.2, z)),
        Stop((lo[0] + 1.2, suite_y, suite_z), (closet_lo[0], suite_y - 0.3, closet_z), via=f"door_e{SUITE_DOOR}"),
        Stop((closet_lo[0] - 1.6, suite_y, closet_z), (closet_lo[0], suite_y - 0.2, closet_z)),
        Stop((ball_lo[0] + 2.0, ball_y, 0.0), (ball_hi[0], ball_y, 0.0), via="closet_door"),
        Stop((ball_hi[0] - 2.0, ball_y, 0.0), (ball_hi[0], ball_y - 0.1, 0.0)),
        Stop((0.0, EYE, -2.4), (0.0, EYE - 0.1, -30.0), via="ballroom_exit"),
    ]


def views() -> dict[str, tuple[Vec3, Vec3]]:
    """Named views of the level (eye, point looked at): its own camera, down the corridor, in the suite before
    the closet (the ballroom through its door), and in a room looking back out at the corridor."""
    closet_lo, closet_hi = closet_box()
    closet_z = 0.5 * (closet_lo[2] + closet_hi[2])
    suite_y = closet_lo[1] + EYE
    (lo, hi), offset = room_box(7)
    room_y, door_z = lo[1] + EYE, 0.5 * (lo[2] + hi[2]) + offset
    return {
        "start": (START, START_LOOK),
        "corridor": ((0.6, EYE, -20.0), (-1.0, EYE - 0.3, -45.0)),
        "suite": ((closet_lo[0] - 3.5, suite_y, closet_z + 1.2), (closet_lo[0], suite_y - 0.4, closet_z)),
        "room": ((hi[0] - 1.0, room_y, door_z - 1.0), (lo[0], room_y - 0.2, door_z)),
    }


def camera_path() -> CameraPath:
    """The walk of :func:`stops`, converted for the real systems (portals)."""
    return with_scene(build, stops())

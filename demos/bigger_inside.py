"""A hut that is bigger on the inside: 4 × 4 outside, through its door a pillared hall four times as big.

A ``metric`` aberration fits the hut's hull exactly (walls, floor and roof
slab included) with D = (-0.75, 0, -0.75): s = 1 + D = 1/4 along x and z, so
inside every horizontal distance looks, and walks, four times as long (D =
-0.5 would double it). The height is left alone on purpose: stretching all
three axes alike bends no ray (only the perceived depth and the walking speed
would change), so the room would not *look* any bigger.

From outside, the walls are flush with the box faces and look normal; through
the door the floor runs back four times as far as the hut is deep. Everything
inside is stretched with it, so the furniture and pillars are built squeezed
by s: inside, they look their normal shape. The camera walks in at a quarter
of its speed and, having crossed the hall, looks back at the little door.
The low sun shines in at the door: its patch on the floor is stretched too.
"""

from __future__ import annotations

from demos.kit import (
    CLAY,
    CORAL,
    GOLD,
    IVORY,
    LAWN,
    NAVY,
    SAND,
    SKY,
    TEAL,
    Color,
    Door,
    Vec3,
    block,
    room,
    texture,
    use_blocks,
)
from engine.scene import Scene
from engine.settings import Settings
from systems.camera_path import CameraPath
from systems.route import Stop, with_scene

#: Place in the demo gallery (``aberrant demos``); see demos/__init__.py.
ORDER = 6

HALF, HEIGHT, WALL = 2.0, 3.2, 0.25
DOOR = Door(width=2.0, height=2.5)
#: s = 1 + D: a quarter of the world distance per perceived unit along x and z, the height unchanged.
STRETCH = (-0.75, 0.0, -0.75)
EYE = 1.6
START = (1.6, 1.7, 6.8)
START_LOOK = (0.1, 1.2, 0.0)


def furniture(scene: Scene) -> None:
    """Furniture laid out as it should *look* (a 16 × 16 hall), built squeezed by s so that it does."""
    kx, kz = 1.0 + STRETCH[0], 1.0 + STRETCH[2]

    def squeezed(name: str, lo: Vec3, hi: Vec3, color: Color, checker: float = 0.0) -> None:
        block(scene, name, (kx * lo[0], lo[1], kz * lo[2]), (kx * hi[0], hi[1], kz * hi[2]), color, checker)

    def ball(name: str, x: float, y: float, z: float, size: float, color: Color, checker: float = 0.0) -> None:
        scene.add_mesh(name, "sphere", smooth=True, position=(kx * x, y, kz * z), scale=(kx * size, size, kz * size),
                       color=color, checker=checker)  # fmt: skip

    squeezed("rug", (-4.0, 0.0, -3.0), (4.0, 0.03, 5.0), CORAL, 0.5)
    squeezed("table", (-4.2, 0.0, -2.8), (-1.8, 0.75, -1.2), CLAY)
    ball("lamp", -3.0, 1.0, -2.0, 0.5, GOLD)
    squeezed("shelf", (-6.5, 0.0, -7.95), (-1.5, 2.2, -7.3), TEAL, 0.4)
    squeezed("bed", (2.0, 0.0, -7.95), (4.6, 0.55, -5.0), IVORY)
    squeezed("blanket", (2.0, 0.55, -6.6), (4.6, 0.62, -5.0), SKY, 0.3)
    squeezed("chest", (-7.6, 0.0, 2.5), (-6.4, 0.7, 4.5), CLAY, 0.35)
    ball("globe", 2.5, 0.5, 2.0, 1.0, GOLD, 0.15)
    for i, (x, z) in enumerate(((-5.0, -4.0), (5.0, -4.0), (-5.0, 3.0), (5.0, 3.0))):
        scene.add_mesh(f"pillar_{i}", "cylinder", smooth=True, position=(kx * x, 0.5 * HEIGHT, kz * z),
                       scale=(0.8 * kx, HEIGHT, 0.8 * kz), color=IVORY)  # fmt: skip


def build() -> Scene:
    """The hut on a lawn, its stretched interior, and a tree beside it for scale."""
    scene = Scene("bigger_inside", settings=Settings(background=(0.62, 0.76, 0.93), light_dir=(0.55, 0.75, 0.4)))
    use_blocks(scene)
    # A sun low in the south: the hut and the tree cast shadows on the lawn, and through the door a stripe
    # of sunlight falls onto the stretched hall's floor (its own sky is its ceiling).
    scene.add_light("sun", "sun", look_at=(-0.3, -0.45, -0.84), color=(1.0, 0.96, 0.88), intensity=1.25)
    block(scene, "lawn", (-40.0, -0.45, -40.0), (40.0, -0.25, 40.0), LAWN, 1.0)
    lo, hi = (-HALF, 0.0, -HALF), (HALF, HEIGHT, HALF)
    room(scene, "hut", lo, hi, wall=SAND, floor=(0.92, 0.82, 0.7), ceiling=IVORY, thickness=WALL,
         checker=0.0, floor_checker=0.0,
         wall_image=texture("plaster"), floor_image=texture("parquet"),
         doors={"south": [DOOR]}, wall_colors={"north": NAVY})  # fmt: skip
    scene.add_mesh("roof", "pyramid", position=(0.0, HEIGHT + WALL + 0.8, 0.0), scale=(5.0, 1.6, 5.0), color=CLAY)
    furniture(scene)
    scene.add_mesh(
        "tree_trunk",
        "cylinder",
        smooth=True,
        position=(-4.2, 1.0, 1.2),
        scale=(0.45, 2.5, 0.45),
        color=(0.45, 0.3, 0.2),
    )
    scene.add_mesh(
        "tree_crown", "sphere", smooth=True, position=(-4.2, 3.0, 1.2), scale=2.4, color=(0.2, 0.5, 0.25), checker=0.5
    )
    # The box is the hut's hull: its faces are flush with the outer faces of walls, floor and ceiling.
    scene.add_aberration(
        "inside",
        STRETCH,
        position=(0.0, 0.5 * HEIGHT, 0.0),
        scale=(2.0 * (HALF + WALL), HEIGHT + 2.0 * WALL, 2.0 * (HALF + WALL)),
        mode="metric",
        color=GOLD,
    )
    scene.set_camera(START, look_at=START_LOOK, fov_deg=58.0, speed=3.0)
    return scene


def stops() -> list[Stop]:
    """Walk in at the door (at a quarter of the speed inside), cross to the back, and turn round to the door."""
    return [
        Stop(START, START_LOOK),
        Stop((0.0, EYE, 4.5), (0.0, EYE - 0.3, 0.0)),
        Stop((0.2, EYE, 1.0), (0.2, EYE - 0.5, -2.0)),
        Stop((0.35, EYE, -0.7), (1.2, EYE - 0.7, -2.0)),
        Stop((0.35, EYE, -0.9), (0.0, EYE - 0.3, 2.5)),
    ]


def camera_path() -> CameraPath:
    """The walk of :func:`stops`, converted for the real systems (aberrations, portals)."""
    return with_scene(build, stops())

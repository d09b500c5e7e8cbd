"""The thesis's multi-room house: a cottage on a lawn whose front door opens into a hall far bigger than it.

The cottage is 6 × 6 outside. Its front door leads into a 14 × 14 hall with
columns; the hall's doors lead on: north into a long red gallery, west into a
blue bedroom, and east back out onto the lawn, but *behind* the cottage,
walking away from it. None of the rooms could fit in the cottage (they lie
far below the lawn, unseen), and walking straight through the hall turns you
round the house: the thesis's "rooms that should not exist" and "traversal
that changes locations and orientations". Four portal pairs join them, each
filling a doorway in the middle of its wall; from the lawn one sees the hall
through the front door, and the gallery through the hall's far door: a portal
seen through a portal. A low sun casts the cottage's and the trees' shadows
on the lawn and, through the front door, a stripe of sunlight onto the hall's
floor: shadow rays pass the portals as camera rays do, and the rooms' own sky
is blocked by their ceilings.
"""

from __future__ import annotations

from demos.kit import (
    BLUE,
    CHALK,
    CLAY,
    CORAL,
    GOLD,
    IVORY,
    LAWN,
    MINT,
    PURPLE,
    RED,
    ROSE,
    SAND,
    SKY,
    SLATE,
    TEAL,
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

#: Place in the demo gallery (``aberrant demos``); see demos/__init__.py.
ORDER = 4

WALL = 0.3
DOOR = Door(width=2.0, height=2.5)
#: Interiors (lo, hi). The rooms lie 60 units under the lawn, where no ray from it reaches.
HOUSE = ((-3.0, 0.0, -3.0), (3.0, 3.0, 3.0))
HALL = ((-7.0, -60.0, -14.0), (7.0, -55.5, 0.0))
GALLERY = ((-2.0, -60.0, -126.0), (2.0, -56.6, -100.0))
BEDROOM = ((-106.0, -60.0, -10.5), (-99.0, -57.0, -3.5))
EYE = 1.7
START = (0.5, 1.8, 9.0)
START_LOOK = (0.0, 1.75, 0.0)
#: The way the sun shines (it stands towards the opposite direction: south, a little east, 33 degrees up).
SUN_LOOK = (-0.1, -0.55, -0.83)


def cottage(scene: Scene) -> None:
    """The lawn, the cottage (doors front and back, a pyramid roof), a path and two trees."""
    block(scene, "lawn", (-80.0, -0.4, -80.0), (80.0, -0.3, 80.0), LAWN, 2.0)
    room(scene, "cottage", *HOUSE, wall=CHALK, floor=SAND, ceiling=CHALK, thickness=WALL, checker=0.0,
         doors={"south": [DOOR], "north": [DOOR]}, wall_colors={"east": IVORY, "west": IVORY})  # fmt: skip
    scene.add_mesh("cottage_roof", "pyramid", position=(0.0, 4.4, 0.0), scale=(7.6, 2.2, 7.6), color=RED, checker=0.5)
    scene.add_mesh("chimney", "box", position=(1.8, 4.6, -1.2), scale=(0.6, 1.8, 0.6), color=CLAY)
    for i in range(5):
        z = 4.0 + 1.5 * i
        block(scene, f"stone_{i}", (-0.6, -0.3, z), (0.6, -0.22, z + 1.0), SLATE)
    # Behind the cottage, where the hall's east door lets out: a pond and more trees.
    scene.add_mesh(
        "pond", "cylinder", smooth=True, position=(1.0, -0.28, -17.0), scale=(6.0, 0.1, 4.0), color=(0.25, 0.5, 0.75)
    )
    scene.add_mesh(
        "pond_rim", "cylinder", smooth=True, position=(1.0, -0.3, -17.0), scale=(6.8, 0.12, 4.8), color=SLATE
    )
    for name, x, z in (("tree_east", 7.0, -2.0), ("tree_west", -7.5, 3.0), ("tree_north", -5.0, -19.0),
                       ("tree_far", 8.0, -22.0)):  # fmt: skip
        scene.add_mesh(
            f"{name}_trunk",
            "cylinder",
            smooth=True,
            position=(x, 1.0, z),
            scale=(0.5, 2.6, 0.5),
            color=(0.45, 0.3, 0.2),
        )
        scene.add_mesh(
            f"{name}_crown", "sphere", smooth=True, position=(x, 3.2, z), scale=2.8, color=(0.2, 0.5, 0.25), checker=0.5
        )


def hall(scene: Scene) -> None:
    """The big hall: four columns, a rug, doors on all four sides."""
    lo, hi = HALL
    room(scene, "hall", lo, hi, wall=SAND, floor=(0.9, 0.78, 0.66), ceiling=IVORY, thickness=WALL,
         checker=0.0, floor_checker=0.0,
         wall_image=texture("plaster"), floor_image=texture("parquet"),
         doors={side: [DOOR] for side in ("south", "east", "north", "west")},
         wall_colors={"north": CORAL})  # fmt: skip
    for i, (x, z) in enumerate(((-3.5, -3.5), (3.5, -3.5), (-3.5, -10.5), (3.5, -10.5))):
        scene.add_mesh(
            f"hall_column_{i}",
            "cylinder",
            smooth=True,
            position=(x, lo[1] + 2.25, z),
            scale=(0.9, 4.5, 0.9),
            color=IVORY,
        )
    block(scene, "hall_rug", (-2.0, lo[1], -9.5), (2.0, lo[1] + 0.04, -4.5), PURPLE, 0.5)
    scene.add_mesh(
        "hall_globe", "sphere", smooth=True, position=(-4.6, lo[1] + 0.9, -7.0), scale=1.4, color=GOLD, checker=0.3
    )


def gallery(scene: Scene) -> None:
    """A long red gallery with coloured panels on its walls and a statue at the end."""
    lo, hi = GALLERY
    room(scene, "gallery", lo, hi, wall=(0.62, 0.16, 0.16), floor=CHALK, ceiling=IVORY, thickness=WALL,
         checker=0.0, floor_checker=0.0,
         floor_image=texture("stone"), wall_image=texture("wallpaper"),
         doors={"south": [DOOR]})  # fmt: skip
    colors = (GOLD, SKY, MINT, ROSE, TEAL)
    for i in range(5):
        z = lo[2] + 3.0 + 4.8 * i
        block(scene, f"panel_west_{i}", (lo[0], lo[1] + 1.0, z), (lo[0] + 0.06, lo[1] + 2.6, z + 2.4), colors[i])
        block(
            scene,
            f"panel_east_{i}",
            (hi[0] - 0.06, lo[1] + 1.0, z + 1.2),
            (hi[0], lo[1] + 2.6, z + 3.0),
            colors[-1 - i],
        )
    # Two lamps down the gallery (no shadows: the sun's is the scene's one shadowing light); their range
    # keeps them in the gallery, which no other room comes near.
    for i, z in enumerate((lo[2] + 7.0, lo[2] + 19.0)):
        scene.add_light(f"gallery_lamp_{i}", "point", position=(0.0, hi[1] - 1.0, z), color=(1.0, 0.9, 0.75),
                        intensity=3.2, shadows=False, range=14.0)  # fmt: skip
    scene.add_mesh("gallery_plinth", "box", position=(0.0, lo[1] + 0.5, lo[2] + 1.5), scale=1.0, color=IVORY)
    scene.add_mesh("gallery_statue", "pyramid", position=(0.0, lo[1] + 1.6, lo[2] + 1.5), scale=1.2, color=GOLD)


def bedroom(scene: Scene) -> None:
    """A small blue bedroom: a bed, a bedside table and a lamp."""
    lo, hi = BEDROOM
    room(scene, "bedroom", lo, hi, wall=BLUE, floor=(0.9, 0.8, 0.7), ceiling=IVORY, thickness=WALL,
         checker=0.0, floor_checker=0.0,
         wall_image=texture("wallpaper"), floor_image=texture("planks"),
         doors={"east": [DOOR]})  # fmt: skip
    block(scene, "bed", (lo[0], lo[1], lo[2]), (lo[0] + 2.2, lo[1] + 0.6, lo[2] + 3.2), IVORY)
    block(scene, "pillow", (lo[0] + 0.2, lo[1] + 0.6, lo[2] + 0.2), (lo[0] + 2.0, lo[1] + 0.8, lo[2] + 0.8), SKY)
    block(scene, "table", (lo[0] + 2.5, lo[1], lo[2]), (lo[0] + 3.3, lo[1] + 0.7, lo[2] + 0.8), CLAY)
    scene.add_light("bedroom_lamp_light", "point", position=(lo[0] + 2.9, lo[1] + 1.6, lo[2] + 0.9),
                    color=(1.0, 0.85, 0.6), intensity=2.8, shadows=False, range=9.0)  # fmt: skip
    scene.add_mesh(
        "lamp", "sphere", smooth=True, position=(lo[0] + 2.9, lo[1] + 1.0, lo[2] + 0.4), scale=0.6, color=GOLD
    )


def build() -> Scene:
    """The cottage, its three impossible rooms and the four portal pairs between their doorways."""
    scene = Scene("house", settings=Settings(background=(0.58, 0.74, 0.92), ambient=0.25))
    use_blocks(scene)
    # A low sun from the south (behind the start, shining through the front door): the rooms have
    # ceilings, so the hall is lit only by the stripe of sunlight its south door lets in from the lawn.
    scene.add_light("sun", "sun", look_at=SUN_LOOK, color=(1.0, 0.96, 0.88), intensity=1.3)
    cottage(scene)
    hall(scene)
    gallery(scene)
    bedroom(scene)

    def door(where: tuple[Vec3, Vec3], side: str, inward: bool = False) -> dict[str, object]:
        return doorway(*where, side, DOOR, WALL, inward=inward)

    # A portal maps its front (+Z) to its partner's front. The cottage's doors face out of it; the hall's out
    # of the hall too (out of the cottage is into the hall); the side rooms' doors face into their room.
    scene.add_portal_pair("front_door", "hall_south", a=door(HOUSE, "south"), b=door(HALL, "south"), color=GOLD)
    scene.add_portal_pair("back_door", "hall_east", a=door(HOUSE, "north"), b=door(HALL, "east"), color=TEAL)
    scene.add_portal_pair(
        "hall_north", "gallery_door", a=door(HALL, "north"), b=door(GALLERY, "south", inward=True), color=RED
    )
    scene.add_portal_pair(
        "hall_west", "bedroom_door", a=door(HALL, "west"), b=door(BEDROOM, "east", inward=True), color=BLUE
    )
    scene.set_camera(START, look_at=START_LOOK, fov_deg=60.0, speed=3.0)
    return scene


def stops() -> list[Stop]:
    """In at the front door, across the hall, out of its east door: behind the cottage; turn and look."""
    y = HALL[0][1] + EYE
    return [
        Stop(START, START_LOOK),
        Stop((0.0, EYE, 6.5), (0.0, EYE - 0.2, 0.0)),
        Stop((0.0, y, -2.5), (0.0, y - 0.2, -14.0), via="front_door"),
        Stop((0.0, y, -4.8), (-6.0, y - 0.4, -14.0)),
        Stop((1.8, y, -7.0), (7.0, y - 0.2, -7.0)),
        Stop((5.6, y, -7.0), (8.0, y - 0.2, -7.0)),
        Stop((0.0, EYE, -7.0), (0.0, EYE, -12.0), via="hall_east"),
        Stop((0.0, EYE + 0.4, -9.5), (0.0, EYE, 0.0)),
        Stop((1.5, EYE + 0.6, -11.5), (0.0, 1.5, -3.0)),
    ]


def camera_path() -> CameraPath:
    """The walk of :func:`stops`, converted for the real systems (aberrations, portals)."""
    return with_scene(build, stops())

"""A doorway into a squeezed hall, and at its end a second doorway onto a garden whose low sun shines back through both.

Three places, joined by two portal pairs in free-standing door frames:

1. a white atrium, where the first frame stands;
2. a green hall, filled end to end by a ``metric`` aberration with D = (1, 0, 0):
   inside it everything looks (and is walked) half as wide; the first pair's
   other end stands at its near end, *inside* the box, the second pair's first
   end at its far end, also inside;
3. a walled garden (high above everything else, so no ray strays out of it).

From the atrium one looks through the first frame into the hall, squeezed by
the box that the portal opens into, and through the thin frame at the hall's
end into the garden: a portal seen through a portal through an aberration.
The garden itself looks normal, as a ray leaves the box when it is
teleported. Each primary ray that reaches the garden makes at least two
portal events. The garden's low sun shines back along the same line, through the
gate, down the hall and out of the atrium's frame: a warm stripe on two roofed
floors, the fountain's column shadowed into it. The flythrough walks straight
through both frames.
"""

from __future__ import annotations

from demos.kit import (
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
    ROSE,
    SAND,
    TEAL,
    Color,
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
ORDER = 8

#: The door frames' opening (width, height) and where the three places are.
OPENING = (2.0, 2.6)
HALL_X = 50.0
GARDEN_Y = 200.0
#: The hall's squeeze: twice as narrow inside.
SQUEEZE = (1.0, 0.0, 0.0)
SUNSET = (0.98, 0.62, 0.42)
EYE = 1.7
START = (0.0, 1.8, 4.6)
START_LOOK = (0.0, 1.5, -6.0)


def frame(scene: Scene, name: str, x: float, y: float, z: float, color: Color) -> dict[str, object]:
    """A free-standing door frame around the opening centred at (x, z) on the floor at y; its portal's placement."""
    w, h = OPENING
    post, depth = 0.35, 0.4
    z0, z1, top = z - 0.5 * depth, z + 0.5 * depth, y + h + post
    block(scene, f"{name}_post_w", (x - 0.5 * w - post, y, z0), (x - 0.5 * w, top, z1), color)
    block(scene, f"{name}_post_e", (x + 0.5 * w, y, z0), (x + 0.5 * w + post, top, z1), color)
    block(scene, f"{name}_lintel", (x - 0.5 * w, y + h, z0), (x + 0.5 * w, top, z1), color)
    return {"position": (x, y + 0.5 * h, z), "scale": (0.5 * w, 0.5 * h, 1.0)}


def build() -> Scene:
    """The atrium, the squeezed hall, the garden, and the two portal pairs between their frames."""
    scene = Scene("portal_in_aberration", settings=Settings(background=SUNSET, light_dir=(0.45, 0.7, 0.55)))
    use_blocks(scene)
    # The setting sun, low behind the garden's far hedge, almost straight down the line of the doorways: it
    # shines back through the gate, down the squeezed hall and out of the atrium's frame, a long warm patch
    # on the floors of two roofed rooms (the fountain's column stands in it and casts a shadow through both).
    scene.add_light("sun", "sun", look_at=(0.03, -0.185, 0.98), color=(1.0, 0.72, 0.48), intensity=2.4)

    # 1. The atrium: white walls, a stone floor, the first frame in the middle.
    room(scene, "atrium", (-5.0, 0.0, -6.0), (5.0, 3.6, 6.0), wall=CHALK, floor=SAND, ceiling=IVORY,
         checker=0.0, floor_checker=0.0,
         wall_image=texture("plaster"), floor_image=texture("stone"),
         wall_colors={"west": CORAL, "east": (0.55, 0.78, 0.8)})  # fmt: skip
    first = frame(scene, "atrium_frame", 0.0, 0.0, -1.0, CLAY)
    scene.add_mesh("atrium_urn", "sphere", smooth=True, position=(-3.4, 0.6, 3.4), scale=1.2, color=CORAL, checker=0.25)
    scene.add_mesh("atrium_cone", "pyramid", position=(3.4, 0.6, -4.0), scale=1.2, color=TEAL)

    # 2. The hall: green walls, two rows of pillars, a frame at each end; the box fills it, walls included.
    room(scene, "hall", (HALL_X - 5.0, 0.0, -14.0), (HALL_X + 5.0, 4.0, 4.0), wall=GREEN, floor=NAVY,
         ceiling=MINT, checker=1.0, floor_checker=1.0)  # fmt: skip
    near = frame(scene, "hall_near_frame", HALL_X, 0.0, 0.0, GOLD)
    far = frame(scene, "hall_far_frame", HALL_X, 0.0, -10.0, GOLD)
    for i in range(4):
        z = -1.5 - 3.0 * i
        for side, dx in (("w", -3.0), ("e", 3.0)):
            scene.add_mesh(
                f"hall_pillar_{side}{i}",
                "cylinder",
                smooth=True,
                position=(HALL_X + dx, 2.0, z),
                scale=(0.8, 4.0, 0.8),
                color=IVORY,
            )
    scene.add_aberration(
        "hall_squeeze", SQUEEZE, position=(HALL_X, 2.0, -5.0), scale=(10.6, 4.6, 18.6), mode="metric", color=GREEN
    )

    # 3. The garden: a lawn walled by hedges, open to the sunset, a fountain and two trees.
    g = GARDEN_Y
    block(scene, "garden_lawn", (-12.0, g - 0.3, -16.0), (12.0, g, 6.0), LAWN, image=texture("grass"), tile=4.0)
    for name, lo, hi in (("hedge_w", (-12.0, g, -16.0), (-11.0, g + 2.4, 6.0)),
                         ("hedge_e", (11.0, g, -16.0), (12.0, g + 2.4, 6.0)),
                         ("hedge_n", (-12.0, g, -16.0), (12.0, g + 2.4, -15.0)),
                         ("hedge_s", (-12.0, g, 5.0), (12.0, g + 2.4, 6.0))):  # fmt: skip
        block(scene, name, lo, hi, (0.16, 0.40, 0.2), 0.5)
    gate = frame(scene, "garden_gate", 0.0, g, 0.0, ROSE)
    scene.add_mesh(
        "fountain_basin", "cylinder", smooth=True, position=(0.0, g + 0.3, -8.0), scale=(4.0, 0.6, 4.0), color=CHALK
    )
    scene.add_mesh(
        "fountain_column", "cylinder", smooth=True, position=(0.0, g + 1.2, -8.0), scale=(0.6, 1.8, 0.6), color=CHALK
    )
    scene.add_mesh(
        "fountain_globe", "sphere", smooth=True, position=(0.0, g + 2.5, -8.0), scale=1.0, color=GOLD, checker=0.2
    )
    for name, x, z in (("tree_w", -6.5, -10.0), ("tree_e", 6.5, -6.0)):
        scene.add_mesh(
            f"{name}_trunk",
            "cylinder",
            smooth=True,
            position=(x, g + 1.2, z),
            scale=(0.5, 2.4, 0.5),
            color=(0.45, 0.3, 0.2),
        )
        scene.add_mesh(
            f"{name}_crown", "sphere", smooth=True, position=(x, g + 3.2, z), scale=3.0, color=PURPLE, checker=0.5
        )

    # The portals face +z (towards the approach): walking through one walks on out of its partner.
    scene.add_portal_pair("atrium_door", "hall_door", a=first, b=near, color=GOLD)
    scene.add_portal_pair("hall_gate", "garden_door", a=far, b=gate, color=ROSE)
    scene.set_camera(START, look_at=START_LOOK, fov_deg=55.0, speed=3.0)
    return scene


def stops() -> list[Stop]:
    """Straight through the atrium's frame into the squeezed hall, down it, and through its far frame."""
    return [
        Stop(START, START_LOOK),
        Stop((0.0, EYE, 2.5), (0.0, EYE - 0.2, -6.0)),
        Stop((HALL_X, EYE, -2.0), (HALL_X, EYE - 0.2, -10.0), via="atrium_door"),
        Stop((HALL_X, EYE, -7.0), (HALL_X, EYE - 0.1, -14.0)),
        Stop((0.0, GARDEN_Y + EYE, -3.0), (0.0, GARDEN_Y + 1.8, -8.0), via="hall_gate"),
        Stop((-2.5, GARDEN_Y + EYE + 0.4, -4.0), (0.0, GARDEN_Y + 1.4, 0.0)),
    ]


def camera_path() -> CameraPath:
    """The walk of :func:`stops`, converted for the real systems (aberrations, portals)."""
    return with_scene(build, stops())

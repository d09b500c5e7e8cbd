"""The thesis's aberration room: a black wall splits it, space squeezed along x on the left, along y on the right.

Rebuilt from the thesis's own scene file (``tests/data/tello/Scenes/AberrationRoom``)
with its dimensions and deformations: a floor 20 × 40 (top at y = 1), side
walls at x = ±10.5, a ceiling at y = 10, and a black dividing wall (1 × 9 × 28)
down the middle. Each half holds a ``radial`` aberration along world axes with
the ``restore`` exit rule (the thesis's method), 10.5 × 10 × 27 and centred at
(±5.25, 5.5, 0): D = (1, 0, 0) in the half at +x, D = (0, 1, 0) in the half at
-x. The thesis's box pivot is its bottom face (local z in [0, 1]), so its
position z = -13.5 is our centre z = 0.

Seen from the thesis's viewpoint (the -z end, looking along +z) the +x half is
on the left, as its text says. What this level adds, so that the deformation
shows: end walls closing the room, a world-space checker on every surface
(the thesis mixed a checker texture into every box), a light tint per half,
and the same props in each half (a sphere, a cube and a column), which look
slim on the left and squat on the right. A lamp hangs in each half; the left
one's shadows are squeezed with its space. Radial boxes scale the camera's speed
along world axes too, so strafing across the left half is twice as fast.
"""

from __future__ import annotations

from demos.kit import CHALK, CHARCOAL, CORAL, GOLD, SAND, SLATE, TEAL, block, use_blocks
from engine.scene import Scene
from engine.settings import Settings
from systems.camera_path import CameraPath
from systems.route import Stop, with_scene

#: Place in the demo gallery (``aberrant demos``); see demos/__init__.py.
ORDER = 1

#: The two aberrations, exactly as in the thesis's file (D, centre, size).
ABERRATIONS = {
    "squeeze_x": ((1.0, 0.0, 0.0), (5.25, 5.5, 0.0), (10.5, 10.0, 27.0)),
    "squeeze_y": ((0.0, 1.0, 0.0), (-5.25, 5.5, 0.0), (10.5, 10.0, 27.0)),
}
EYE = 4.2
#: The thesis's walls were white; a light tint per half (the colour of its props) tells the halves apart.
LEFT_TINT = (0.78, 0.92, 0.90)
RIGHT_TINT = (0.97, 0.84, 0.80)
#: The thesis's viewpoint: the -z end of the room, looking along +z at both halves.
START = (0.0, 6.5, -19.5)
START_LOOK = (0.0, 2.5, 5.0)


def build() -> Scene:
    """The room as the thesis built it, plus props and end walls, seen from its -z end."""
    scene = Scene("aberration_room", settings=Settings(background=(0.1, 0.1, 0.12), light_dir=(-0.35, 0.85, -0.4)))
    use_blocks(scene)
    # The room is closed, so no sun: a lamp hanging in each half. The left one casts shadows,
    # squeezed along x with the space they fall in; the right one only lights (one shadowing light per frame).
    scene.add_light("lamp_left", "point", position=(5.25, 6.5, -8.0), color=(1.0, 0.95, 0.85), intensity=22.0)
    scene.add_light(
        "lamp_right", "point", position=(-5.25, 6.5, -8.0), color=(1.0, 0.95, 0.85), intensity=22.0, shadows=False
    )

    # The thesis's five boxes (its unit box has its pivot at the bottom: these are the same extents).
    block(scene, "floor", (-10.0, 0.0, -20.0), (10.0, 1.0, 20.0), SAND, 1.0)
    block(scene, "wall_left", (10.0, 0.0, -20.0), (11.0, 10.0, 20.0), LEFT_TINT, 1.0)
    block(scene, "wall_right", (-11.0, 0.0, -20.0), (-10.0, 10.0, 20.0), RIGHT_TINT, 1.0)
    block(scene, "divider", (-0.5, 1.0, -14.0), (0.5, 10.0, 14.0), CHARCOAL)
    block(scene, "ceiling", (-11.0, 10.0, -20.0), (11.0, 11.0, 20.0), CHALK, 2.0)
    # Added: end walls, so the room is closed.
    block(scene, "wall_far", (-11.0, 0.0, 20.0), (11.0, 11.0, 21.0), SLATE, 1.0)
    block(scene, "wall_near", (-11.0, 0.0, -21.0), (11.0, 11.0, -20.0), SLATE, 1.0)

    # The same props in each half: what they look like tells the two deformations apart.
    for side, x, color in (("left", 6.4, TEAL), ("right", -6.4, CORAL)):
        scene.add_mesh(
            f"{side}_sphere", "sphere", smooth=True, position=(x, 2.6, -5.0), scale=3.2, color=color, checker=0.4
        )
        block(scene, f"{side}_cube", (x - 1.25, 1.0, 2.0), (x + 1.25, 3.5, 4.5), GOLD, 0.5)
        scene.add_mesh(
            f"{side}_column", "cylinder", smooth=True, position=(x, 5.5, 10.0), scale=(1.6, 9.0, 1.6), color=color
        )

    for name, (deformation, centre, size) in ABERRATIONS.items():
        scene.add_aberration(name, deformation, position=centre, scale=size, mode="radial", exit="restore")

    scene.set_camera(START, look_at=START_LOOK, fov_deg=70.0, speed=4.0)
    return scene


def stops() -> list[Stop]:
    """Step into the squeezed-x half, walk its length, round the end of the wall and come back down the other."""
    return [
        Stop(START, START_LOOK),
        Stop((3.0, EYE, -15.5), (4.0, EYE - 0.6, 0.0)),
        Stop((3.0, EYE, -8.0), (4.0, EYE - 0.6, 0.0), pace=3.0),
        Stop((3.0, EYE, 6.0), (3.5, EYE - 0.3, 20.0), pace=3.0),
        Stop((3.0, EYE, 16.5), (-6.0, EYE, 17.0)),
        Stop((-3.0, EYE, 16.5), (-4.0, EYE - 0.6, 0.0)),
        Stop((-3.0, EYE, 6.0), (-4.0, EYE - 0.6, -10.0), pace=3.0),
        Stop((-3.0, EYE, -8.0), (-3.5, EYE - 0.6, -20.0), pace=3.0),
    ]


def camera_path() -> CameraPath:
    """The walk of :func:`stops`, converted for the real systems (aberrations, portals)."""
    return with_scene(build, stops())

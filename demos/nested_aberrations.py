"""Nested aberrations: down a colonnade, a box squeezing depth holds one stretching it, a third overlaps.

Two rows of identical pillars, two units apart, run away from the camera
through three ``metric`` boxes; the runner down the middle is coloured by the
box that is *active* there:

* orange, priority 0, z in [-30, -4]: D = (0, 0, 2) squeezes depth threefold: the pillars bunch up;
* cyan, priority 1, inside the orange box, z in [-20, -12]: D = (0, 0, -0.5) stretches
  depth: the inner box wins where both contain a point, and the pillars spread out;
* magenta, priority 2, z in [-36, -26], overlapping the orange box's far end: D = (1, 0, 0)
  squeezes width: it wins the overlap, so there the rows close in but no longer bunch.

At every point at most one box is active, the containing one with the highest
priority (docs/semantics.md, "Aberrations"). The flythrough walks down the colonnade: the
same steps carry the camera three times as far in orange, half as far in cyan, at
normal pace in magenta. A sun from the south-east lays the pillars' shadows
across the floor, deformed with the boxes they fall in.
"""

from __future__ import annotations

from demos.kit import CHALK, GOLD, IVORY, NAVY, ROSE, SAND, SKY, SLATE, block, use_blocks
from engine.scene import Scene
from engine.settings import Settings
from systems.camera_path import CameraPath
from systems.route import Stop, with_scene

#: Place in the demo gallery (``aberrant demos``); see demos/__init__.py.
ORDER = 7

ORANGE = (1.0, 0.55, 0.1)
CYAN = (0.1, 0.8, 0.95)
MAGENTA = (0.9, 0.2, 0.75)
#: name, z range, D, priority, colour. Every box spans the colonnade's width and height.
BOXES = (
    ("squeeze_depth", (-30.0, -4.0), (0.0, 0.0, 2.0), 0, ORANGE),
    ("stretch_depth", (-20.0, -12.0), (0.0, 0.0, -0.5), 1, CYAN),
    ("squeeze_width", (-36.0, -26.0), (1.0, 0.0, 0.0), 2, MAGENTA),
)
#: The runner's pieces: where each box is the active one (the priorities resolved).
ACTIVE = ((-12.0, -4.0, ORANGE), (-20.0, -12.0, CYAN), (-26.0, -20.0, ORANGE), (-36.0, -26.0, MAGENTA))
BOX_X, BOX_Y = (-6.0, 6.0), (-0.3, 5.5)
ROWS_X = 2.4
EYE = 1.8
START = (0.5, 5.0, 7.0)
START_LOOK = (0.0, 1.0, -16.0)


def build() -> Scene:
    """The colonnade, the runner coloured by the active box, and the three boxes."""
    scene = Scene("nested_aberrations", settings=Settings(background=(0.08, 0.09, 0.12), ambient=0.28))
    use_blocks(scene)
    # A sun from the south-east, high behind the start: the pillars' shadows fall down and across the
    # floor, squeezed and stretched with the space they fall in (a shadow ray bends at the boxes as a
    # camera ray does), and the east wall's shadow stays narrow.
    scene.add_light("sun", "sun", look_at=(-0.4, -0.7, -0.6), color=(1.0, 0.95, 0.85), intensity=1.25)
    block(scene, "floor", (-6.0, -0.3, -46.0), (6.0, 0.0, 9.0), SAND, 1.0)
    block(scene, "back_wall", (-6.5, 0.0, -47.0), (6.5, 5.5, -46.0), CHALK, 1.0)
    for i in range(22):
        z = 2.0 - 2.0 * i
        for side, x in (("w", -ROWS_X), ("e", ROWS_X)):
            scene.add_mesh(
                f"pillar_{side}{i:02d}",
                "cylinder",
                smooth=True,
                position=(x, 1.2, z),
                scale=(0.6, 2.4, 0.6),
                color=IVORY,
            )
            scene.add_mesh(f"ball_{side}{i:02d}", "sphere", smooth=True, position=(x, 2.75, z), scale=0.7, color=GOLD)
    block(scene, "runner", (-0.8, 0.0, -46.0), (0.8, 0.02, 9.0), SLATE)
    for k, (z0, z1, color) in enumerate(ACTIVE):
        block(scene, f"runner_{k}", (-0.8, 0.02, z0), (0.8, 0.04, z1), color)
    # Side walls: their checker is squeezed and stretched with the space, like the spacing of the pillars.
    block(scene, "wall_w", (-6.5, 0.0, -46.5), (-6.0, 5.5, 9.0), SKY, 1.0)
    block(scene, "wall_e", (6.0, 0.0, -46.5), (6.5, 5.5, 9.0), ROSE, 1.0)
    block(scene, "kerb_w", (-6.0, 0.0, -46.0), (-5.6, 0.2, 9.0), NAVY)
    block(scene, "kerb_e", (5.6, 0.0, -46.0), (6.0, 0.2, 9.0), NAVY)

    for name, (z0, z1), deformation, priority, color in BOXES:
        scene.add_aberration(
            name, deformation, position=(0.5 * sum(BOX_X), 0.5 * sum(BOX_Y), 0.5 * (z0 + z1)),
            scale=(BOX_X[1] - BOX_X[0], BOX_Y[1] - BOX_Y[0], z1 - z0), mode="metric", priority=priority, color=color,
        )  # fmt: skip
    scene.set_camera(START, look_at=START_LOOK, fov_deg=60.0, speed=3.0)
    return scene


def stops() -> list[Stop]:
    """Walk down the colonnade through all three boxes, then turn to look back up it."""
    return [
        Stop(START, START_LOOK),
        Stop((0.0, EYE, 0.0), (0.0, EYE - 0.3, -20.0)),
        Stop((0.0, EYE, -38.0), (0.0, EYE - 0.3, -46.0), pace=2.4),
        Stop((0.0, EYE + 0.6, -40.0), (0.0, EYE, 0.0)),
    ]


def camera_path() -> CameraPath:
    """The walk of :func:`stops`, converted for the real systems (aberrations, portals)."""
    return with_scene(build, stops())

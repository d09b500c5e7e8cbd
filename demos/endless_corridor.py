"""An endless corridor: its two ends are one portal pair, so it repeats forever, with light at the end.

One 12-unit stretch of corridor (arches, lamps, a runner, and one globe on a
pedestal, so that each repeat is easy to count), with a portal filling each
open end: leaving by the north end is arriving by the south end. Looking down
it, every repeat costs a ray one portal event; after ``max_events`` of them
(10, about 115 units away) the ray stops with the event-limit colour, chosen
here as a warm white, so the far end of the corridor glows like daylight at
the end of a tunnel instead of showing an error colour. Walk as far as you
like: the flythrough walks three stretches and never reaches the light.
"""

from __future__ import annotations

from demos.kit import CHALK, CLAY, GOLD, IVORY, NAVY, RED, SAND, TEAL, block, use_blocks
from engine.scene import Scene
from engine.settings import Settings
from systems.camera_path import CameraPath
from systems.route import Stop, with_scene

#: Place in the demo gallery (``aberrant demos``); see demos/__init__.py.
ORDER = 5

HALF_WIDTH, HEIGHT, HALF_LENGTH = 2.0, 3.2, 6.0
#: Portal events before a ray gives up: about 115 units of corridor, a small square of light at the end.
MAX_EVENTS = 10
DAYLIGHT = (1.0, 0.93, 0.74)
EYE = 1.7
START = (0.9, 1.9, 4.5)
START_LOOK = (-0.2, 1.5, -6.0)


def build() -> Scene:
    """One stretch of corridor whose open ends are a portal pair."""
    scene = Scene(
        "endless_corridor",
        settings=Settings(
            background=(0.0, 0.0, 0.0), light_dir=(0.3, 0.75, 0.6), max_events=MAX_EVENTS,
            event_limit_color=DAYLIGHT, ambient=0.4,
        ),
    )  # fmt: skip
    use_blocks(scene)
    w, h, half, t = HALF_WIDTH, HEIGHT, HALF_LENGTH, 0.3
    block(scene, "floor", (-w - t, -t, -half), (w + t, 0.0, half), SAND, 0.5)
    block(scene, "ceiling", (-w - t, h, -half), (w + t, h + t, half), IVORY)
    block(scene, "runner", (-0.8, 0.0, -half), (0.8, 0.02, half), RED, 0.4)
    # Walls: a wainscot below, plaster above, in alternating colours along the corridor.
    for side, x0, x1 in (("west", -w - t, -w), ("east", w, w + t)):
        block(scene, f"{side}_wainscot", (x0, 0.0, -half), (x1, 1.0, half), NAVY)
        for i in range(4):
            z0 = -half + 3.0 * i
            color = TEAL if (i + (side == "east")) % 2 else CHALK
            block(scene, f"{side}_panel_{i}", (x0, 1.0, z0), (x1, h, z0 + 3.0), color)
    # Arches every 6 units: two pillars and a beam, standing a little into the corridor.
    for i in range(2):
        z = -half + 3.0 + 6.0 * i
        block(scene, f"arch_{i}_west", (-w, 0.0, z - 0.2), (-w + 0.25, h, z + 0.2), CLAY)
        block(scene, f"arch_{i}_east", (w - 0.25, 0.0, z - 0.2), (w, h, z + 0.2), CLAY)
        block(scene, f"arch_{i}_beam", (-w, h - 0.3, z - 0.2), (w, h, z + 0.2), CLAY)
        block(scene, f"lamp_{i}", (-0.3, h - 0.12, z + 2.7), (0.3, h, z + 3.3), GOLD)
    # A lamp under each lamp block, the two at the ends being one lamp seen from either side of the seam: with
    # a range of one lamp spacing, every point is lit by the same lamps at the same distances in every repeat,
    # so the seam stays invisible. No shadows: a shadowing lamp at an end would be shadowed on one side only.
    for i, z in enumerate((-half, 0.0, half)):
        scene.add_light(f"lamp_light_{i}", "point", position=(0.0, h - 0.9, z), color=(1.0, 0.9, 0.72),
                        intensity=2.6, shadows=False, range=half)  # fmt: skip
    # The one landmark of the stretch: a globe on a pedestal, to count the repeats by.
    block(scene, "pedestal", (w - 1.0, 0.0, -0.4), (w - 0.2, 1.0, 0.4), IVORY)
    scene.add_mesh("globe", "sphere", smooth=True, position=(w - 0.6, 1.35, 0.0), scale=0.7, color=GOLD, checker=0.15)

    # The open ends: leaving by one is arriving by the other.
    end = {"scale": (w, 0.5 * h, 1.0)}
    scene.add_portal_pair(
        "north_end", "south_end", a={"position": (0.0, 0.5 * h, -half), **end},
        b={"position": (0.0, 0.5 * h, half), **end}, color=DAYLIGHT,
    )  # fmt: skip
    scene.set_camera(START, look_at=START_LOOK, fov_deg=62.0, speed=3.0)
    return scene


def stops() -> list[Stop]:
    """Walk north for three stretches of corridor, glancing at the globe as it comes round again."""
    # Positions here are "unrolled": each stretch walked is one more trip through the north end.
    return [
        Stop(START, START_LOOK),
        Stop((0.0, EYE, 1.5), (0.0, EYE - 0.1, -10.0)),
        Stop((0.0, EYE, 1.5), (0.0, EYE - 0.1, -10.0), via="north_end"),
        Stop((-0.3, EYE, 1.0), (2.0, EYE - 0.5, -2.0), via="north_end"),
        Stop((-0.3, EYE, -3.0), (-0.3, EYE - 0.1, -14.0)),
    ]


def camera_path() -> CameraPath:
    """The walk of :func:`stops`, converted for the real systems (aberrations, portals)."""
    return with_scene(build, stops())

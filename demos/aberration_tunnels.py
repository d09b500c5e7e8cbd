"""The thesis's four tunnels: equal outside, but inside red is short, blue long, green narrow and purple low.

Four tunnels with the same width, height and length, fanned out so that from
the start one looks straight down each; each is filled by an
aberration box that fits its outer hull exactly (walls and roof included, so
only the inside is deformed): red compresses space along z (shorter inside,
crossed twice as fast), blue stretches it along z (twice as long inside, crossed
at half speed), green compresses x (narrower), purple compresses y (lower).

The thesis used its radial method; these boxes are ``metric`` instead, on
purpose: its rule is the one the camera moves by (docs/semantics.md, "Aberrations"), so the
perceived length of a tunnel is exactly the time it takes to walk it. The
flythrough shows it: red zips by, blue drags on. The world-space checker on
walls and ground turns into short, long, thin or flat cells inside, and so
does the sunlight that falls in at the mouths (shadow rays bend as camera rays do).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from demos.kit import BLOCK, BLUE, CHALK, GOLD, GREEN, IVORY, PURPLE, RED, SAND, SLATE, Color, block, use_blocks
from engine.scene import Scene
from engine.settings import Settings
from systems.camera_path import CameraPath
from systems.route import Stop, with_scene

#: Place in the demo gallery (``aberrant demos``); see demos/__init__.py.
ORDER = 2

#: Inside width, height and length of every tunnel, and its wall thickness.
WIDTH, HEIGHT, LENGTH, WALL = 2.6, 3.0, 10.0, 0.3
#: name, heading (degrees from -z, + to the right), colour, deformation along the tunnel's own axes
#: (x across, y up, z along it; D = 1 compresses an axis by half, D = -0.5 stretches it twice).
TUNNELS = (
    ("red", -33.0, RED, (0.0, 0.0, 1.0)),
    ("blue", -11.0, BLUE, (0.0, 0.0, -0.5)),
    ("green", 11.0, GREEN, (1.0, 0.0, 0.0)),
    ("purple", 33.0, PURPLE, (0.0, 1.0, 0.0)),
)
#: The tunnels fan out from this point on the ground, their mouths this far from it, so that from
#: the start one looks straight down each of them.
FOCUS = np.array([0.0, 0.0, 14.0])
MOUTH = 9.0
EYE = 1.6
START = (0.0, 1.8, 14.0)
START_LOOK = (0.0, 1.75, 0.0)


def axis(heading: float) -> np.ndarray:
    """Unit direction along a tunnel, away from the focus."""
    a = math.radians(heading)
    return np.array([math.sin(a), 0.0, -math.cos(a)])


def along(heading: float, distance: float, height: float = 0.0) -> tuple[float, float, float]:
    """The point ``distance`` from the focus along a tunnel's axis, ``height`` above the ground."""
    p = FOCUS + distance * axis(heading)
    return (float(p[0]), height, float(p[2]))


def piece(scene: Scene, name: str, heading: float, lo: Sequence[float], hi: Sequence[float], color: Color) -> None:
    """A block given in a tunnel's own frame (x across, y up, z from the mouth (0) to the far end (-LENGTH))."""
    centre = np.array([0.5 * (a + b) for a, b in zip(lo, hi, strict=True)])
    size = tuple(abs(b - a) for a, b in zip(lo, hi, strict=True))
    a = math.radians(heading)
    # Yaw -heading turns local -z onto the tunnel's axis.
    c, s = math.cos(a), math.sin(a)
    world = np.array([c * centre[0] - s * centre[2], centre[1], s * centre[0] + c * centre[2]])
    position = np.array(along(heading, MOUTH)) + world
    scene.add_mesh(
        name, BLOCK, position=tuple(position), euler_deg=(0.0, -heading, 0.0), scale=size, color=color, checker=0.5
    )


def build() -> Scene:
    """Four tunnels fanned out on a checkered plaza, a gold marker beyond each far end."""
    scene = Scene(
        "aberration_tunnels",
        settings=Settings(background=(0.55, 0.68, 0.85), light_dir=(0.45, 0.8, 0.55), max_events=16),
    )
    use_blocks(scene)
    # A sun from the left, a little behind the start: the tunnels cast their shadows across the plaza, and
    # the light that falls in at their mouths is squeezed or stretched with the space inside.
    scene.add_light("sun", "sun", look_at=(0.7, -0.6, -0.25), color=(1.0, 0.96, 0.88), intensity=1.15)
    block(scene, "ground", (-24.0, -0.3, -26.0), (24.0, 0.0, 20.0), SAND, 1.0)
    block(scene, "back_wall", (-24.0, 0.0, -26.0), (24.0, 8.0, -25.0), SLATE, 1.0)

    # Behind the start, a legend: a post in each tunnel's colour, so looking back shows where one came from.
    for i, (name, _, color, _) in enumerate(TUNNELS):
        x = -4.5 + 3.0 * i
        block(scene, f"{name}_post", (x - 0.3, 0.0, 19.0), (x + 0.3, 2.2, 19.6), IVORY)
        scene.add_mesh(f"{name}_finial", "sphere", smooth=True, position=(x, 2.6, 19.3), scale=0.9, color=color)

    half = 0.5 * WIDTH
    for name, heading, color, deformation in TUNNELS:
        # Two walls and a roof; the ground is the tunnel's floor.
        piece(scene, f"{name}_wall_left", heading, (-half - WALL, 0.0, -LENGTH), (-half, HEIGHT, 0.0), color)
        piece(scene, f"{name}_wall_right", heading, (half, 0.0, -LENGTH), (half + WALL, HEIGHT, 0.0), color)
        piece(scene, f"{name}_roof", heading, (-half - WALL, HEIGHT, -LENGTH), (half + WALL, HEIGHT + WALL, 0.0), CHALK)
        # A marker past the far end, on the tunnel's axis: seen through the tunnel, it is deformed too.
        p = along(heading, MOUTH + LENGTH + 4.0)
        block(scene, f"{name}_plinth", (p[0] - 0.5, 0.0, p[2] - 0.5), (p[0] + 0.5, 1.0, p[2] + 0.5), IVORY)
        scene.add_mesh(f"{name}_marker", "sphere", smooth=True, position=(p[0], 1.6, p[2]), scale=1.2, color=GOLD)
        # The aberration fits the outer hull exactly and turns with the tunnel (metric boxes use their own axes).
        centre = along(heading, MOUTH + 0.5 * LENGTH, 0.5 * (HEIGHT + WALL))
        scene.add_aberration(
            f"{name}_space",
            deformation,
            position=centre,
            euler_deg=(0.0, -heading, 0.0),
            scale=(WIDTH + 2.0 * WALL, HEIGHT + WALL, LENGTH),
            mode="metric",
            color=color,
        )

    scene.set_camera(START, look_at=START_LOOK, fov_deg=72.0, speed=3.0)
    return scene


def stops() -> list[Stop]:
    """Walk through red (fast), turn round past the markers, come back through blue (slow), and look back."""
    red, blue = TUNNELS[0][1], TUNNELS[1][1]
    return [
        Stop(START, START_LOOK),
        Stop(along(red, MOUTH - 3.0, EYE), along(red, MOUTH + LENGTH, EYE - 0.2)),
        Stop(along(red, MOUTH + LENGTH + 1.8, EYE), along(red, MOUTH + LENGTH + 6.0, EYE - 0.2)),
        Stop(along(0.5 * (red + blue), MOUTH + LENGTH + 4.5, EYE), along(blue, MOUTH + LENGTH + 6.0, EYE)),
        Stop(along(blue, MOUTH + LENGTH + 2.5, EYE), along(blue, MOUTH, EYE - 0.2)),
        Stop(along(blue, MOUTH - 1.5, EYE), along(blue, 0.0, EYE - 0.1)),
        Stop(along(blue, MOUTH - 4.5, EYE + 0.3), along(0.0, MOUTH, EYE)),
    ]


def camera_path() -> CameraPath:
    """The walk of :func:`stops`, converted for the real systems (aberrations, portals)."""
    return with_scene(build, stops())

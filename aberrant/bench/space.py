"""The ``space-count`` scenes: a floor and 30 boxes, plus N portals or N aberration boxes, out of view or in view.

What a frame costs as the number of portals and boxes grows, with the same
picture to trace: every scene's frame is timed against the plain scene's
(N = 0), frames alternated (``SceneSpec.baseline``), so the ratio is what the
N portals or boxes add. *Out of view*, they stand behind the camera, where
no ray goes: ideally they cost nothing. *In view*, they fill a grid on a
plane across the view between the camera and the boxes, covering the same
quarter of the image whatever N is (each is smaller as N grows), so a ray
passes at most one of them and the work the picture needs stays the same:
ideally the ratio does not grow with N.

In-view portals are linked in horizontal neighbours: a ray through one
comes out of the other's back, shifted sideways by one grid cell, and goes
on to the boxes (one event). In-view boxes are small ``metric`` aberrations
that bend the rays passing through them (two events).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from engine.maths import look_at_quat, quat_to_matrix
from engine.scene import Scene

#: The counts swept (portal entities, i.e. N / 2 linked pairs; or boxes).
COUNTS: tuple[int, ...] = (4, 16, 64, 256, 1024)
KINDS: tuple[str, ...] = ("portals", "boxes")
PLACEMENTS: tuple[str, ...] = ("out", "in")
PLAIN = "space-0"
EYE = (0.0, 4.0, 4.0)
LOOK_AT = (0.0, 0.3, -3.3)
FOV_DEG = 60.0
#: The in-view grid lies this far along the view direction; the boxes stand 5-10 units away.
GRID_DISTANCE = 3.0
#: The fraction of the grid's square the portals or boxes cover, whatever their number.
COVERAGE = 0.25
LENS = (0.25, -0.2, 0.25)
#: Out of view: the first row stands this far behind the camera.
BEHIND = 6.0


def space_name(kind: str, placement: str, count: int) -> str:
    return f"space-{kind}-{placement}-{count}"


def thirty_boxes(folder: Path | None = None) -> Scene:
    """A checkered floor and 30 boxes in five rows, all in view: the plain frame of the sweep."""
    scene = Scene(PLAIN)
    scene.add_mesh("floor", "plane", scale=(40.0, 1.0, 40.0), checker=1.0)
    rng = np.random.default_rng(3)
    for k in range(30):
        row, col = divmod(k, 6)
        scene.add_mesh(
            f"box{k}",
            "box",
            position=(-3.4 + 1.36 * col + 0.3 * (row % 2), 0.45 + 0.15 * (k % 3), -0.5 - 1.4 * row),
            euler_deg=(0.0, 13.0 * k, 0.0),
            scale=0.9,
            color=tuple(rng.uniform(0.2, 1.0, 3)),
        )
    scene.set_camera(EYE, look_at=LOOK_AT, fov_deg=FOV_DEG)
    return scene


@dataclass(frozen=True)
class Slot:
    """Where one portal or box goes: centre, rotation (quaternion) and half size."""

    position: tuple[float, float, float]
    rotation: tuple[float, float, float, float]
    half: float


def _side(count: int) -> int:
    """The grid's side: the smallest even number whose square holds ``count``."""
    side = max(2, math.ceil(math.sqrt(count)))
    return side + side % 2


def in_view_slots(count: int) -> Iterator[Slot]:
    """A ``side x side`` grid on the plane ``GRID_DISTANCE`` ahead, facing the camera, inside the view.

    The grid spans 80 % of the view's height at that distance, so every slot is wholly in the frustum
    (for any aspect of at least 1), and each slot's square covers :data:`COVERAGE` of its cell.
    """
    q = look_at_quat(EYE, LOOK_AT)
    rotation = (float(q[0]), float(q[1]), float(q[2]), float(q[3]))
    axes = quat_to_matrix(rotation)  # columns: right, up, back
    side = _side(count)
    span = 0.8 * 2.0 * GRID_DISTANCE * math.tan(math.radians(FOV_DEG) / 2.0)
    cell = span / side
    half = 0.5 * cell * math.sqrt(COVERAGE)
    centre = np.asarray(EYE) - GRID_DISTANCE * axes[:, 2]
    for k in range(count):
        row, col = divmod(k, side)
        u = (col + 0.5) * cell - 0.5 * span
        v = 0.5 * span - (row + 0.5) * cell
        p = centre + u * axes[:, 0] + v * axes[:, 1]
        yield Slot((float(p[0]), float(p[1]), float(p[2])), rotation, half)


def out_of_view_slots(count: int) -> Iterator[Slot]:
    """Unit slots on a grid of rows behind the camera (z from ``EYE.z + BEHIND`` on), facing away from it."""
    side = _side(count)
    for k in range(count):
        layer, rest = divmod(k, side * side)
        row, col = divmod(rest, side)
        x = 2.0 * (col - 0.5 * side)
        y = 0.5 + 2.0 * row
        z = EYE[2] + BEHIND + 2.0 * layer
        yield Slot((x, y, z), (0.0, 0.0, 0.0, 1.0), 0.5)


def add_space(scene: Scene, kind: str, placement: str, count: int) -> None:
    """``count`` portals (linked in neighbouring pairs) or aberration boxes, in view or out of it."""
    slots = list((in_view_slots if placement == "in" else out_of_view_slots)(count))
    if kind == "portals":
        for k in range(0, count, 2):
            a, b = slots[k], slots[k + 1]
            scene.add_portal_pair(
                f"portal{k}",
                f"portal{k + 1}",
                a={"position": a.position, "rotation": a.rotation, "scale": (a.half, a.half, 1.0)},
                b={"position": b.position, "rotation": b.rotation, "scale": (b.half, b.half, 1.0)},
            )
    else:
        for k, s in enumerate(slots):
            scene.add_aberration(f"lens{k}", LENS, position=s.position, rotation=s.rotation, scale=2.0 * s.half)


def space_scene(kind: str, placement: str, count: int) -> Scene:
    """The plain scene plus ``count`` portals or boxes placed ``in`` or ``out`` of view."""
    if kind not in KINDS or placement not in PLACEMENTS:
        raise ValueError(f"kind must be one of {KINDS}, placement one of {PLACEMENTS}")
    if kind == "portals" and count % 2:
        raise ValueError("portals come in linked pairs: the count must be even")
    scene = thirty_boxes()
    scene.name = space_name(kind, placement, count)
    add_space(scene, kind, placement, count)
    return scene


def space_cases() -> Iterator[tuple[str, Callable[[Path], Scene], str]]:
    """(name, builder, description) of every swept scene, N = 0 excluded (it is the baseline)."""
    for kind in KINDS:
        for placement in PLACEMENTS:
            where = "in view, a grid covering a quarter of it" if placement == "in" else "out of view"
            for count in COUNTS:

                def build(folder: Path, kind: str = kind, placement: str = placement, count: int = count) -> Scene:
                    return space_scene(kind, placement, count)

                what = f"{count // 2} portal pairs" if kind == "portals" else f"{count} aberration boxes"
                yield space_name(kind, placement, count), build, f"30 boxes and {what} {where}"


def parse_space_name(name: str) -> tuple[str, str, int] | None:
    """``space-portals-in-64`` -> ``("portals", "in", 64)``; ``None`` for any other scene."""
    parts = name.split("-")
    if len(parts) != 4 or parts[0] != "space" or parts[1] not in KINDS or parts[2] not in PLACEMENTS:
        return None
    return (parts[1], parts[2], int(parts[3])) if parts[3].isdigit() else None

"""Walking through a portal is seamless: the real systems, tick by tick, with a tracer.

Corridor B is an exact copy of corridor A moved by ``X`` (a turn and a
translation far away), and door B is door A moved by the same ``X``: so
looking through door A shows what corridor A would show without the door,
and the door is invisible by construction. The camera walks straight through
door A in small steps (``systems.app.App`` with a ``ScriptedInput``: camera
movement, portal teleport, upload, render). The frames just before and just
after the crossing differ in <= 1 % of the pixels, and no step of the
crossing walk changes the frame more than twice the largest change of a
control walk: the same steps in the corridor without the doors, so the same
view with no portal anywhere (a walk further back sees its objects from
further away and changes less per step: it would measure the room, not the
portal). Tick by tick, the two walks even render the same frames.
"""

from __future__ import annotations

import itertools

import numpy as np

from engine.camera_view import scene_camera
from engine.input import InputState, ScriptedInput
from engine.maths import quat_from_euler_deg, quat_multiply, quat_to_matrix
from engine.scene import Scene
from engine.settings import Settings
from systems.app import App

#: Corridor B = X(corridor A): a quarter turn about y, then far away.
TURN_DEG = 90.0
OFFSET = np.array([100.0, 0.0, 50.0])
#: A pixel "changes" when a colour channel moves by more than this many levels.
THRESHOLD = 8
STEP = 0.02


def to_b(p) -> tuple[float, float, float]:
    """A point of corridor A mapped to corridor B."""
    rotation = quat_to_matrix(quat_from_euler_deg((0.0, TURN_DEG, 0.0)))
    return tuple(float(c) for c in rotation @ np.asarray(p, dtype=np.float64) + OFFSET)


def corridor(with_doors: bool = True) -> Scene:
    """Corridor A (along z, door A at z = 0 in open space), its copy B, the camera 1 unit before door A.

    The light is overhead, so the quarter turn about y leaves the shading of the copy as it is.
    """
    scene = Scene("seamless", settings=Settings(light_dir=(0.0, 1.0, 0.0)))
    parts = [
        # name, asset, position, euler_deg, scale, colour, checker
        ("floor", "box", (0.0, -0.5, 0.0), (0, 0, 0), (6.0, 1.0, 32.0), (0.9, 0.9, 0.85), 0.125),
        ("ceiling", "box", (0.0, 3.5, 0.0), (0, 0, 0), (6.0, 1.0, 32.0), (0.6, 0.6, 0.7), 0.0),
        ("left", "box", (-2.5, 1.5, 0.0), (0, 0, 0), (1.0, 4.0, 32.0), (0.85, 0.55, 0.45), 0.25),
        ("right", "box", (2.5, 1.5, 0.0), (0, 0, 0), (1.0, 4.0, 32.0), (0.45, 0.75, 0.55), 0.25),
        ("end_far", "box", (0.0, 1.5, -15.5), (0, 0, 0), (6.0, 4.0, 1.0), (0.5, 0.5, 0.9), 0.2),
        ("end_near", "box", (0.0, 1.5, 15.5), (0, 0, 0), (6.0, 4.0, 1.0), (0.9, 0.9, 0.4), 0.2),
        ("crate", "box", (-1.2, 0.4, -6.0), (0, 30, 0), (0.8, 0.8, 0.8), (0.9, 0.6, 0.2), 0.25),
        ("ball", "sphere", (1.0, 0.6, -8.5), (0, 0, 0), (1.2, 1.2, 1.2), (0.3, 0.5, 0.95), 0.0),
        ("post", "cylinder", (1.3, 1.5, -4.5), (0, 0, 0), (0.3, 3.0, 0.3), (0.8, 0.3, 0.5), 0.0),
        ("block", "box", (-1.0, 2.4, -9.0), (20, 10, 0), (0.9, 0.7, 0.9), (0.4, 0.9, 0.9), 0.3),
        ("behind", "box", (0.8, 0.5, 9.0), (0, 45, 0), (1.0, 1.0, 1.0), (0.9, 0.3, 0.3), 0.0),
    ]
    rotation = quat_from_euler_deg((0.0, TURN_DEG, 0.0))
    for copy in ("a", "b"):
        for name, asset, position, euler, scale, colour, checker in parts:
            q = quat_from_euler_deg(euler)
            if copy == "b":
                position = to_b(position)
                q = quat_multiply(rotation, q)
            scene.add_mesh(f"{copy}_{name}", asset, position=position, rotation=q, scale=scale, color=colour,
                           checker=checker)  # fmt: skip
    if with_doors:
        door = {"position": (0.0, 1.4, 0.0), "scale": (1.0, 1.1, 1.0)}
        scene.add_portal_pair(
            "door_a",
            "door_b",
            a=door,
            b={"position": to_b(door["position"]), "rotation": rotation, "scale": (1, 1.1, 1)},
        )
    scene.set_camera((0.137, 1.5, 1.0), look_at=(0.137, 1.5, -10.0), fov_deg=70.0)
    return scene


def walk(backend, start_z: float, ticks: int, size, with_doors: bool = True) -> tuple[list[np.ndarray], list]:
    """Frames and camera positions of ``ticks`` steps forward from ``start_z`` (frame 0: before the first step)."""
    scene = corridor(with_doors)
    try:
        camera = scene.camera_entity
        scene.set_camera((0.137, 1.5, start_z), look_at=(0.137, 1.5, start_z - 11.0), fov_deg=70.0)
        assert scene.camera_entity == camera
        script = ScriptedInput([None] + [InputState(move=(0.0, 0.0, -1.0), speed=STEP)] * ticks)
        frames, positions = [], []
        with App(scene, backend, size=size, aovs=("color",), input_source=script) as app:
            for _ in range(ticks + 1):
                frame = app.tick(1.0)
                assert frame is not None and frame.color is not None
                frames.append(frame.color[..., :3].astype(np.int16))
                positions.append(scene_camera(scene).position.copy())
        return frames, positions
    finally:
        scene.close()


def changed(a: np.ndarray, b: np.ndarray) -> float:
    """Fraction of pixels whose colour moved by more than THRESHOLD levels in some channel."""
    return float(np.mean(np.abs(a - b).max(axis=2) > THRESHOLD))


def check_walks(backend, size, ticks: int) -> dict[str, float]:
    """Walk through door A (it is at z = 0) and, as a control, the same steps without the doors."""
    start = STEP * ticks / 2 + STEP / 4
    frames, positions = walk(backend, start, ticks, size)
    control, control_positions = walk(backend, start, ticks, size, with_doors=False)
    assert all(p[0] < 50.0 for p in control_positions), "the control walk must not cross"
    crossed = [k for k, p in enumerate(positions) if p[0] > 50.0]
    assert crossed and crossed == list(range(crossed[0], len(positions))), "exactly one crossing, mid-walk"
    k = crossed[0]
    # Just before: in corridor A, short of the plane; just after: at the mapped position in corridor B.
    assert 0.0 < positions[k - 1][2] < STEP and np.allclose(
        positions[k], to_b((0.137, 1.5, positions[k - 1][2] - STEP))
    )
    steps = [changed(a, b) for a, b in itertools.pairwise(frames)]
    control_steps = [changed(a, b) for a, b in itertools.pairwise(control)]
    result = {
        "across": changed(frames[k - 1], frames[k]),
        "largest": max(steps),
        "control": max(control_steps),
        # Tick by tick the walk through the door sees what the doorless corridor shows.
        "vs_doorless": max(changed(a, b) for a, b in zip(frames, control, strict=True)),
    }
    assert result["across"] <= 0.01, result
    assert result["largest"] <= 2.0 * result["control"], result
    assert result["control"] > 0.0, "the walk should change the view"
    assert result["vs_doorless"] <= 0.002, result
    return result


def test_walking_through_a_portal_is_seamless_glsl(backend_factory):
    check_walks(backend_factory("glsl", "f32"), (128, 96), ticks=40)


def test_walking_through_a_portal_is_seamless_reference(backend_factory):
    check_walks(backend_factory("reference"), (80, 60), ticks=20)


def test_the_door_is_invisible_by_construction(backend_factory):
    """The corridor with the doors renders as the corridor without them (the door is in open space)."""
    backend = backend_factory("glsl", "f32")
    colours = []
    for with_doors in (True, False):
        scene = corridor(with_doors)
        try:
            with App(scene, backend, size=(128, 96), aovs=("color", "events")) as app:
                frame = app.tick(0.0)
            assert frame is not None
            if with_doors:
                assert (frame.events == 1).mean() > 0.2, "the door should fill much of the view"
            colours.append(frame.color[..., :3].astype(np.int16))
        finally:
            scene.close()
    assert changed(*colours) <= 0.002

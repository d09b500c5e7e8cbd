"""Hard portal cases: facing portals, the camera along, on and at the edge of a quad, two portals
in one tick, and a portal 1e5 from the origin -- rays in every backend and the camera through the systems.

The rules (docs/semantics.md section 3, systems/portal_teleport.py):

* **edges are inclusive**: a ray hits the closed square ``|x| <= 1, |y| <= 1`` of the
  quad's local space, and a camera segment that passes through it exactly at
  ``|x| = 1`` or ``|y| = 1`` (an edge or a corner) is teleported; just outside
  (the next float) it is not. Rays and camera agree, in every backend;
* **in the plane**: a ray in the quad's plane never hits it, and a camera moving in
  the plane is never teleported;
* **on the plane**: a camera standing exactly on the quad sees what lies beyond it
  on its own side (its rays start on the quad, which is skipped), and stepping off
  the plane either way does not teleport it -- it walks into what it sees; a step
  that ends on or crosses the plane does teleport;
* **facing portals** end every looping ray at ``max_events`` with the event-limit
  colour; the camera stops after MAX_CROSSINGS crossings a tick.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np
import pytest
from scenes import EVERY, FAST, ReferenceFrames, aim, aimed_pixel, assert_agrees, render_scene, upload_to_reference
from test_parity import FAR, assert_clean, compare, translated
from test_parity_portals import rooms

from backends.base import AOVS, Backend, Frame
from backends.reference.shading import to_uint8
from components import Transform
from engine.input import InputState, ScriptedInput
from engine.maths import quat_from_euler_deg, quat_to_matrix
from engine.scene import Scene
from engine.settings import Settings
from systems.app import App
from systems.portal_teleport import MAX_CROSSINGS

Vec3 = tuple[float, float, float]
N = 97
SIZE = (N, N)
MAGENTA = (1.0, 0.0, 1.0)
#: Door A: the quad x in [-2, 2], y in [0, 4] at z = 0 (power-of-two sizes: exact local coordinates).
DOOR_A = {"position": (0.0, 2.0, 0.0), "scale": (2.0, 2.0, 1.0)}
B_X = 100.0


@pytest.fixture
def scenes() -> Iterator[list[Scene]]:
    made: list[Scene] = []
    yield made
    for scene in made:
        scene.close()


def walls_and_door(
    b: dict | None = None, camera: Vec3 = (0.0, 2.0, 4.0), doors: bool = True, **settings: object
) -> Scene:
    """A checkered wall behind door A (room A), another behind door B at x = 100 (room B); an aimed camera."""
    scene = Scene("walls-and-door", settings=Settings(**settings))
    scene.add_mesh("wall_a", "box", position=(0.0, 2.0, -6.5), scale=(40.0, 40.0, 1.0), color=(0.9, 0.5, 0.5),
                   checker=0.5)  # fmt: skip
    scene.add_mesh("wall_b", "box", position=(B_X, 2.0, -6.5), scale=(40.0, 40.0, 1.0), color=(0.5, 0.9, 0.5),
                   checker=0.5)  # fmt: skip
    if doors:
        b = b or {"position": (B_X, 2.0, 0.0), "scale": (2.0, 2.0, 1.0)}
        scene.add_portal_pair("door_a", "door_b", a=DOOR_A, b=b)
    else:  # stand-ins, so that entity ids (the instance AOV) are those of the scene with the doors
        scene.create_entity("door_a", Transform())
        scene.create_entity("door_b", Transform())
    aim(scene, camera, N)
    return scene


def position(scene: Scene) -> np.ndarray:
    assert scene.camera_entity is not None
    return np.array(scene.get(scene.camera_entity, Transform).position)


def rotation(scene: Scene) -> np.ndarray:
    assert scene.camera_entity is not None
    return quat_to_matrix(scene.get(scene.camera_entity, Transform).rotation)


def step(scene: Scene, move: Vec3, ticks: int = 1, speed: float = 3.0, dt: float = 0.1) -> list[list[tuple[int, int]]]:
    """Walk ``ticks`` ticks in the camera's local direction ``move``; the crossings of each tick."""
    crossings = []
    with App(scene, input_source=ScriptedInput([InputState(move=move, speed=speed)] * ticks)) as app:
        for _ in range(ticks):
            app.tick(dt)
            crossings.append(list(app.motion.crossings))
    return crossings


def reference_ray(scene: Scene, origin: Sequence[float], direction: Sequence[float]) -> tuple[int, int]:
    """(events, instance) of one exact float64 ray through the scene."""
    backend = upload_to_reference(scene)
    try:
        d = np.asarray(direction, dtype=np.float64)
        result = backend.trace_rays(np.asarray(origin, dtype=np.float64), (d / np.linalg.norm(d))[None])
        return int(result.events[0]), int(result.instance[0])
    finally:
        backend.release()


# --- facing portals --------------------------------------------------------------------------------------------


def facing_corridor(max_events: int = 8, turn_deg: float = 0.0) -> Scene:
    """A closed corridor; doors A (z = -1/2) and B (z = +1/2), 8 x 8, face each other across it: a ray into A
    comes out of B going the same way and meets A again, and so on; one that drifts past a door's edge
    hits the corridor. Door B may be turned about the corridor's axis (each pass turns the ray). The
    corridor is a little wider than the doors and not square, so no pixel's ray meets a corner line
    where two of its walls meet exactly (which wall is hit there is decided by rounding)."""
    scene = Scene("facing-corridor", settings=Settings(max_events=max_events, event_limit_color=MAGENTA))
    grey = (0.8, 0.8, 0.75)
    for name, pos, scale in (
        ("floor", (0.0, -2.7, 0.0), (10.0, 1.0, 16.0)),  # top at y = -2.2
        ("ceiling", (0.0, 6.8, 0.0), (10.0, 1.0, 16.0)),  # bottom at y = 6.3
        ("left", (-4.65, 2.0, 0.0), (1.0, 10.0, 16.0)),  # inner face at x = -4.15
        ("right", (4.65, 2.0, 0.0), (1.0, 10.0, 16.0)),
        ("near_end", (0.0, 2.0, 7.5), (10.0, 10.0, 1.0)),
        ("far_end", (0.0, 2.0, -7.5), (10.0, 10.0, 1.0)),
    ):
        scene.add_mesh(name, "box", position=pos, scale=scale, color=grey, checker=0.5)
    scene.add_portal_pair(
        "a", "b", a={"position": (0.0, 2.0, -0.5), "scale": (4.0, 4.0, 1.0)},
        b={"position": (0.0, 2.0, 0.5), "euler_deg": (0.0, 0.0, turn_deg), "scale": (4.0, 4.0, 1.0)},
    )  # fmt: skip
    aim(scene, (0.0, 2.0, 0.0), N)
    return scene


def looping_pixels(max_events: int, margin: float = 0.05) -> np.ndarray:
    """Pixels of the (unturned) facing corridor whose ray stays inside the doors for ``max_events`` passes.

    The ray of slopes (sx, sy) meets door A half a unit ahead at (sx, sy) / 2 from the corridor's axis,
    and each pass adds (sx, sy): computed here in float64, with a margin from the doors' edges.
    """
    slope = (np.arange(N) - (N - 1) / 2) / ((N - 1) / 2)
    sx, sy = np.meshgrid(slope, -slope)
    ok = np.ones((N, N), dtype=bool)
    for k in range(max_events):
        x, y = (0.5 + k) * sx, (0.5 + k) * sy
        ok &= (np.abs(x) <= 4.0 - margin) & (np.abs(y) <= 4.0 - margin)
    return ok


@pytest.mark.parametrize("max_events", [8, 64, 300])
@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_facing_portals_end_at_the_event_limit(backend_factory, backend_name, precision, max_events):
    """Every pixel whose ray keeps looping ends at max_events with the event-limit colour; the others
    drift into the corridor's walls. Always an answer: no hang, no NaN. (The events AOV is uint8: a
    count above 255 reads 255 in every backend.)"""
    backend = backend_factory(backend_name, precision)
    frame = render_scene(backend, lambda: facing_corridor(max_events), SIZE)
    assert_clean(frame)
    looping = looping_pixels(max_events)
    assert looping[48, 48] and (looping.sum() >= 25 or max_events > 64)
    limit = frame.events == min(max_events, 255)
    if max_events > 255:  # a saturated count: tell the limit by its colour and missing hit
        limit = (frame.events == 255) & (frame.instance == -1)
    assert np.all(limit[looping])
    assert np.all(frame.color[limit][:, :3] == to_uint8(np.array(MAGENTA)))
    assert np.all(frame.instance[limit] == -1) and np.all(np.isinf(frame.depth[limit]))
    assert np.all(frame.instance[~limit] >= 0), "a ray that stops looping hits the corridor"
    assert np.all(frame.events <= min(max_events, 255))


@pytest.fixture(scope="module")
def reference() -> Iterator[ReferenceFrames]:
    frames = ReferenceFrames()
    yield frames
    frames.release()


@pytest.mark.parametrize("turn_deg", [0.0, 90.0, 33.0])
@pytest.mark.parametrize(("backend_name", "precision"), FAST)
def test_facing_portals_agree_with_the_reference(backend_factory, reference, backend_name, precision, turn_deg):
    """The facing corridor, plain and with door B turned about the axis (each pass turns the ray)."""
    backend = backend_factory(backend_name, precision)
    ref = reference(f"facing-{turn_deg}", lambda: facing_corridor(8, turn_deg), SIZE)
    fast = render_scene(backend, lambda: facing_corridor(8, turn_deg), SIZE)
    assert (ref.events == 8).mean() > 0.005
    assert_agrees(fast, ref, precision)


def test_facing_portals_stop_the_camera_after_the_crossing_cap(scenes):
    """A camera running through the facing corridor: MAX_CROSSINGS crossings per tick, then it stays on B."""
    scene = facing_corridor()
    scenes.append(scene)
    a, b = scene.entity("a"), scene.entity("b")
    crossings = step(scene, (0.0, 0.0, -1.0), ticks=3, speed=200.0)
    assert crossings == [[(a, b)] * MAX_CROSSINGS] * 3
    assert np.allclose(position(scene), (0.0, 2.0, 0.5), atol=1e-12)


# --- along the plane ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("euler", [(0.0, 0.0, 0.0), (20.0, 35.0, 10.0)])
@pytest.mark.parametrize("move", [(1.0, 0.0, 0.0), (0.6, -0.8, 0.0)])
def test_moving_exactly_along_the_plane_never_teleports(scenes, euler, move):
    """The camera slides across the quad in its plane (turned with the door, moving along the door's own
    axes), passing through the middle of the quad: no crossing, the walk goes straight on."""
    scene = walls_and_door()
    scenes.append(scene)
    q = quat_from_euler_deg(euler)
    door = scene.entity("door_a")
    scene.set(door, Transform(DOOR_A["position"], tuple(q), DOOR_A["scale"]))
    axes = quat_to_matrix(q)
    direction = axes @ np.array(move)
    start = np.array(DOOR_A["position"]) - 5.0 * direction
    scene.set_camera(tuple(start), rotation=tuple(q))
    crossings = step(scene, move, ticks=40, speed=2.5)
    assert not any(crossings)
    np.testing.assert_allclose(position(scene), start + 10.0 * direction, atol=1e-12)


@pytest.mark.parametrize("door_b_euler", [(0.0, 0.0, 0.0), (180.0, 0.0, 0.0)])
def test_rays_in_the_plane_never_hit_the_quad(scenes, door_b_euler):
    """Exact float64 rays in door A's plane z = 0 (from beside the quad, and from a point on it) go on as if
    there were no door, whatever door B is (a half turn is exact too); the same rays tilted off the plane
    by 1e-9 do go through. (A rotated quad's plane is not exact in floating point, so rendered rays are
    aimed here only at unrotated quads: see the on-the-plane and edge tests.)"""
    scene = walls_and_door(b={"position": (B_X, 2.0, 0.0), "euler_deg": door_b_euler, "scale": (2.0, 2.0, 1.0)})
    scene.add_mesh("post", "box", position=(8.0, 2.5, 0.0), scale=(1.0, 8.0, 1.0))  # in the plane, beyond
    scenes.append(scene)
    post = scene.entity("post")
    for origin, direction, k in [
        ((-5.0, 2.5, 0.0), (1.0, 0.0, 0.0), 4.0),  # across the whole quad
        ((0.5, 2.5, 0.0), (1.0, 0.0, 0.0), 0.5),  # from a point on it
        ((-3.0, -1.0, 0.0), (1.1, 0.35, 0.0), 4.0),  # in through its bottom edge, out through its right
    ]:
        assert reference_ray(scene, origin, direction) == (0, post), (origin, direction)
        # Tilted: from 1e-9 k above the plane, down 1e-9 per unit of direction: through origin + k direction.
        tilted = np.array(direction) + np.array([0.0, 0.0, -1e-9])
        start = np.array(origin) + np.array([0.0, 0.0, 1e-9 * k])
        events, _ = reference_ray(scene, start, tilted)
        assert events == 1, (origin, "tilted into the plane: crosses the quad")


# --- edges ----------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_rays_through_a_quad_edge_are_teleported(backend_factory, backend_name, precision):
    """Column 72 passes exactly through door A's edge x = 2, row 24 through its top edge y = 4, pixel (24, 72)
    through the corner: all inside (inclusive); the next column and row outside."""
    backend = backend_factory(backend_name, precision)
    scene = walls_and_door()
    try:
        wall_a, wall_b = scene.entity("wall_a"), scene.entity("wall_b")
    finally:
        scene.close()
    assert aimed_pixel(N, 0.5, 0.5) == (24, 72)
    frame = render_scene(backend, walls_and_door, SIZE)
    assert_clean(frame)
    assert np.all(frame.instance[24:73, 72] == wall_b) and np.all(frame.instance[24, 24:73] == wall_b)
    assert np.all(frame.instance[24:73, 24] == wall_b) and np.all(frame.instance[72, 24:73] == wall_b)
    assert np.all(frame.instance[23:74, 73] == wall_a) and np.all(frame.instance[23, 23:74] == wall_a)
    assert np.all(frame.events[24:73, 24:73] == 1)


@pytest.mark.parametrize(
    ("x", "y", "teleported"),
    [
        (2.0, 2.5, True),  # on the edge x = 2
        (float(np.nextafter(2.0, 3.0)), 2.5, False),  # just outside it
        (-2.0, 4.0, True),  # a corner
        (0.5, 0.0, True),  # the bottom edge
        (0.5, -1e-15, False),  # just below it: local y = -1.0000000000000004
    ],
)
def test_camera_through_a_quad_edge_follows_the_ray_rule(scenes, x, y, teleported):
    """The camera walks through the plane exactly at an edge or corner: teleported iff the ray along its
    path is (inclusive edges), and then to the mapped point."""
    scene = walls_and_door(camera=(x, y, 1.0))
    scenes.append(scene)
    events, _ = reference_ray(scene, (x, y, 1.0), (0.0, 0.0, -1.0))
    crossings = step(scene, (0.0, 0.0, -1.0), ticks=4)
    assert (events == 1) == teleported
    assert bool(crossings[3]) == teleported and not any(crossings[:3])
    expected = (x + B_X, y, -0.2) if teleported else (x, y, -0.2)
    np.testing.assert_allclose(position(scene), expected, atol=1e-12)


# --- on the plane ----------------------------------------------------------------------------------------------------


def test_camera_on_the_plane_stepping_forward_and_back(scenes):
    """Standing on door A: a step either way stays in room A; a step back onto the plane, or through it, is
    a crossing (the door is two-sided), arriving on door B; from there, walking on never goes back."""
    scene = walls_and_door(camera=(0.5, 2.5, 0.0))
    scenes.append(scene)
    a, b = scene.entity("door_a"), scene.entity("door_b")
    assert step(scene, (0.0, 0.0, -1.0)) == [[]]  # forward off the plane: room A, behind the door
    np.testing.assert_allclose(position(scene), (0.5, 2.5, -0.3), atol=1e-12)
    assert step(scene, (0.0, 0.0, 1.0)) == [[(a, b)]]  # back onto the plane: through door A
    np.testing.assert_allclose(position(scene), (B_X + 0.5, 2.5, 0.0), atol=1e-12)
    assert step(scene, (0.0, 0.0, 1.0), ticks=2) == [[], []]  # on from door B, never back through it
    np.testing.assert_allclose(position(scene), (B_X + 0.5, 2.5, 0.6), atol=1e-12)

    scene2 = walls_and_door(camera=(0.5, 2.5, 0.0))
    scenes.append(scene2)
    a2, b2 = scene2.entity("door_a"), scene2.entity("door_b")
    assert step(scene2, (0.0, 0.0, 1.0)) == [[]]  # back off the plane: room A, in front of the door
    assert step(scene2, (0.0, 0.0, -1.0), ticks=2) == [[(a2, b2)], []]  # forward through it, on in room B
    np.testing.assert_allclose(position(scene2), (B_X + 0.5, 2.5, -0.3), atol=1e-12)


@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_camera_on_the_plane_sees_its_own_side(backend_factory, backend_name, precision):
    """From exactly on door A, looking through it, the rays start on the quad and skip it: room A, as if
    there were no door -- where the next step forward goes. A millimetre before it: room B."""
    backend = backend_factory(backend_name, precision)
    on = render_scene(backend, lambda: walls_and_door(camera=(0.5, 2.5, 0.0)), SIZE)
    before = render_scene(backend, lambda: walls_and_door(camera=(0.5, 2.5, 1e-3)), SIZE)
    scene = walls_and_door()
    try:
        wall_a, wall_b = scene.entity("wall_a"), scene.entity("wall_b")
    finally:
        scene.close()
    assert_clean(on)
    assert np.all(on.instance == wall_a) and np.all(on.events == 0)
    assert np.all(before.instance == wall_b) and np.all(before.events == 1)


# --- two portals in one tick ------------------------------------------------------------------------------------


def test_a_very_fast_camera_crosses_two_portals_in_one_tick(scenes):
    """100 units in one tick: through A (to B, turned a quarter), on along -x through C (to D, turned back)."""
    scene = Scene("two-in-one-tick")
    scenes.append(scene)
    scene.add_portal_pair("A", "B", a=DOOR_A, b={"position": (50.0, 2.0, 10.0), "euler_deg": (0.0, 90.0, 0.0),
                                                 "scale": (2.0, 2.0, 1.0)})  # fmt: skip
    scene.add_portal_pair("C", "D", a={"position": (20.0, 2.0, 10.0), "euler_deg": (0.0, 90.0, 0.0),
                                       "scale": (2.0, 2.0, 1.0)}, b={"position": (0.0, 2.0, -50.0),
                                                                     "scale": (2.0, 2.0, 1.0)})  # fmt: skip
    scene.set_camera((0.0, 2.5, 1.0), rotation=(0.0, 0.0, 0.0, 1.0))
    ids = [scene.entity(name) for name in "ABCD"]
    crossings = step(scene, (0.0, 0.0, -1.0), ticks=1, speed=1000.0)
    # 1 unit to A; arrive at B (50, 2.5, 10) heading -x; 30 units to C; arrive at D (0, 2.5, -50) heading -z;
    # the remaining 100 - 1 - 30 = 69 units on.
    assert crossings == [[(ids[0], ids[1]), (ids[2], ids[3])]]
    np.testing.assert_allclose(position(scene), (0.0, 2.5, -50.0 - 69.0), atol=1e-9)
    np.testing.assert_allclose(rotation(scene), np.eye(3), atol=1e-12)


# --- far from the origin ------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def far_reference() -> Iterator[ReferenceFrames]:
    frames = ReferenceFrames({"doors": lambda: rooms("doors"), "edges": walls_and_door}, (112, 84))
    yield frames
    frames.release()


@pytest.mark.parametrize("case", ["doors", "edges"])
@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_a_portal_1e5_from_the_origin_renders_as_at_the_origin(
    backend_factory, far_reference, backend_name, precision, case
):
    """Rooms, doors and camera moved by about 1e5 (the edge case too, its edge pixels included)."""
    backend = backend_factory(backend_name, precision)
    build = {"doors": lambda: rooms("doors"), "edges": walls_and_door}[case]
    fast = render_scene(backend, lambda: translated(build(), FAR), (112, 84))
    assert_clean(fast)
    result = compare(fast, far_reference(case))
    assert result.mismatch <= 2e-3 and result.depth_median <= 1e-5, result


def door_walk(
    backend: Backend, offset: tuple[float, float, float], ticks: int = 30
) -> tuple[list[Frame], list[np.ndarray], list[list[tuple[int, int]]]]:
    """Walk through door A of the two rooms (moved by ``offset``), rendering every tick: frames, positions
    (relative to the offset) and each tick's crossings."""
    scene = translated(rooms("walk"), offset)
    try:
        start = np.array([0.3, 1.7, 0.75]) + offset
        scene.set_camera(tuple(start), look_at=tuple(start + np.array([0.0, -0.1, -5.0])), fov_deg=70.0)
        script = ScriptedInput([InputState(move=(0.0, 0.0, -1.0), speed=0.5)] * ticks)
        frames, positions, crossings = [], [], []
        with App(scene, backend, size=(64, 48), aovs=AOVS, input_source=script) as app:
            for _ in range(ticks):
                frames.append(app.tick(0.1))
                positions.append(position(scene) - offset)
                crossings.append(list(app.motion.crossings))
        return frames, positions, crossings
    finally:
        scene.close()


@pytest.mark.parametrize(("backend_name", "precision"), [pytest.param("glsl", "f32", id="glsl-f32"),
                                                         pytest.param("opencl", "f32", id="opencl-f32")])  # fmt: skip
def test_walking_through_a_portal_1e5_from_the_origin(backend_factory, backend_name, precision):
    """The systems and a float32 tracer 1e5 from the origin: the same crossing tick, the same path, and
    tick by tick the frames of the same walk at the origin."""
    backend = backend_factory(backend_name, precision)
    near = door_walk(backend, (0.0, 0.0, 0.0))
    far = door_walk(backend, FAR)
    crossed = [k for k, c in enumerate(near[2]) if c]
    assert len(crossed) == 1 and 5 < crossed[0] < 25, "one crossing, mid-walk"
    assert [bool(c) for c in far[2]] == [bool(c) for c in near[2]]
    np.testing.assert_allclose(np.array(far[1]), np.array(near[1]), atol=1e-6)
    for k, (a, b) in enumerate(zip(near[0], far[0], strict=True)):
        assert_clean(b)
        assert np.mean(a.instance != b.instance) <= 2e-3, k
    assert (near[0][0].events == 1).mean() > 0.5, "the walk starts looking through the door"
    assert (near[0][-1].events == 0).mean() > 0.9, "and ends in the other room, the door behind"

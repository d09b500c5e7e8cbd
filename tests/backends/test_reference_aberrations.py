"""Aberrations in the float64 reference tracer: closed forms, rules on single rays, walking, hard inputs.

The rules are those of docs/semantics.md ("Aberrations", rules 3-9).
Expected values are computed here by hand (independently of the tracer's code).
"""

from __future__ import annotations

import numpy as np
import pytest
from scenes import upload_to_reference as upload

from backends.reference.aberrations import SigmaBounds, sigma
from backends.reference.backend import ReferenceBackend
from backends.reference.trace import TraceResult
from components import Aberration, Transform
from engine.camera_view import scene_camera
from engine.input import InputState, ScriptedInput
from engine.maths import quat_from_euler_deg, quat_to_matrix, trs_inverse
from engine.scene import Scene
from engine.settings import Settings
from systems.app import App
from systems.camera_movement import speed_boxes, walk

#: The wall's front face lies in the plane z = WALL_Z.
WALL_Z = -5.5


def one_ray(backend: ReferenceBackend, origin, direction, sigma_bounds=None) -> TraceResult:
    d = np.asarray(direction, dtype=np.float64)
    return backend.trace_rays(np.asarray(origin, dtype=np.float64), (d / np.linalg.norm(d))[None], sigma_bounds)


def wall_scene(scenes: list[Scene], camera=(0.0, 0.0, 5.0), look_at=(0.0, 0.0, 0.0), **settings) -> tuple[Scene, int]:
    """A wide wall whose front face is the plane z = WALL_Z, and a camera."""
    scene = Scene(settings=Settings(**settings))
    scenes.append(scene)
    wall = scene.add_mesh("wall", "box", position=(0.0, 0.0, WALL_Z - 0.5), scale=(60.0, 60.0, 1.0), checker=0.5)
    scene.set_camera(camera, look_at=look_at)
    return scene, wall


def unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


# --- D = 0 changes nothing ----------------------------------------------------------------------------


@pytest.mark.parametrize("mode", ["metric", "additive", "radial"])
def test_zero_deformation_changes_nothing(scenes, mode):
    def build(with_box: bool) -> Scene:
        scene, _ = wall_scene(scenes, camera=(0.7, 0.9, 6.0), look_at=(0.0, 0.0, -2.0))
        scene.add_mesh("ball", "sphere", position=(1.0, 0.5, -3.0), color=(0.2, 0.8, 0.3))
        scene.add_mesh("cube", "box", position=(-1.5, -0.5, -2.0), euler_deg=(10.0, 30.0, 0.0), checker=0.2)
        if with_box:
            scene.add_aberration(
                "zero", (0.0, 0.0, 0.0), mode=mode, position=(0.2, 0.1, 1.5), euler_deg=(15.0, 25.0, 5.0),
                scale=(2.5, 1.8, 1.2),
            )  # fmt: skip
        return scene

    w, h = 48, 36
    plain_scene, scene = build(False), build(True)
    plain = upload(plain_scene).render(scene_camera(plain_scene), w, h)
    boxed = upload(scene).render(scene_camera(scene), w, h)
    for name in ("color", "depth", "perceived", "instance"):
        assert np.array_equal(plain.aov(name), boxed.aov(name)), name
    assert np.all(plain.events == 0)
    # Exactly the rays that cross the box count its two faces.
    camera = scene_camera(scene)
    m = trs_inverse((0.2, 0.1, 1.5), quat_from_euler_deg((15.0, 25.0, 5.0)), (2.5, 1.8, 1.2))
    a = m[:3, :3] @ camera.position + m[:3, 3]
    v = camera.primary_directions(w, h).reshape(-1, 3) @ m[:3, :3].T
    t1, t2 = (-0.5 - a) / v, (0.5 - a) / v
    near, far = np.minimum(t1, t2).max(axis=1), np.maximum(t1, t2).min(axis=1)
    events = boxed.events.reshape(-1)
    crossing, clear = near < far - 1e-6, near > far + 1e-6
    assert crossing.sum() > 100 and clear.sum() > 100
    assert np.all(events[crossing] == 2) and np.all(events[clear] == 0)


# --- metric: closed forms ----------------------------------------------------------------------------------


def test_metric_box_on_axis_closed_form(scenes):
    """Camera on the axis of a D_z = 2 box of length 4: perceived 3 + 4/3 + 3.5, world 3 + 4 + 3.5."""
    scene, wall = wall_scene(scenes)
    scene.add_aberration("squeeze", (0.0, 0.0, 2.0), scale=(10.0, 10.0, 4.0))
    backend = upload(scene)
    ray = one_ray(backend, (0.0, 0.0, 5.0), (0.0, 0.0, -1.0))
    assert ray.instance.tolist() == [wall] and ray.events.tolist() == [2]
    assert ray.depth[0] == pytest.approx(10.5, rel=1e-14)
    assert ray.perceived[0] == pytest.approx(3.0 + 4.0 / 3.0 + 3.5, rel=1e-14)
    frame = backend.render(scene_camera(scene), 33, 25)  # odd size: the centre pixel looks along the axis
    assert frame.depth[12, 16] == np.float32(10.5)
    assert frame.perceived[12, 16] == np.float32(3.0 + 4.0 / 3.0 + 3.5)


def test_metric_box_off_axis_bends_by_the_formula(scenes):
    scene, wall = wall_scene(scenes)
    scene.add_aberration("squeeze", (0.0, 0.0, 2.0), scale=(10.0, 10.0, 4.0))
    w = unit((0.12, -0.07, -1.0))
    inside = np.array([w[0], w[1], 3.0 * w[2]])  # s ⊙ w with s = (1, 1, 3)
    r = unit(inside)
    l1, l2, l3 = 3.0 / -w[2], 4.0 / -r[2], 3.5 / -w[2]
    ray = one_ray(upload(scene), (0.0, 0.0, 5.0), w)
    assert ray.instance.tolist() == [wall] and ray.events.tolist() == [2]
    assert ray.depth[0] == pytest.approx(l1 + l2 + l3, rel=1e-13)
    assert ray.perceived[0] == pytest.approx(l1 + l2 / np.linalg.norm(inside) + l3, rel=1e-13)
    # The lateral bend too: a small target where the bent ray meets the wall is hit, and only because of the bend.
    hit = np.array([0.0, 0.0, 5.0]) + l1 * w + l2 * r + l3 * w
    target = scene.add_mesh("target", "box", position=(hit[0], hit[1], WALL_Z + 0.01), scale=(0.04, 0.04, 0.02))
    backend = upload(scene)
    assert one_ray(backend, (0.0, 0.0, 5.0), w).instance.tolist() == [target]
    scene.remove(scene.entity("squeeze"), Aberration)
    assert one_ray(upload(scene), (0.0, 0.0, 5.0), w).instance.tolist() == [wall]


def _expected_metric_ray(origin, w, position, euler, scale, deformation) -> tuple[float, float]:
    """World and perceived length to the wall for one ray crossing one rotated metric box (by hand)."""
    m = trs_inverse(position, quat_from_euler_deg(euler), scale)
    rotation = quat_to_matrix(quat_from_euler_deg(euler))
    s = 1.0 + np.asarray(deformation, dtype=np.float64)

    def slab(p, d):
        a, v = m[:3, :3] @ p + m[:3, 3], m[:3, :3] @ d
        t1, t2 = (-0.5 - a) / v, (0.5 - a) / v
        return np.minimum(t1, t2).max(), np.maximum(t1, t2).min()

    o = np.asarray(origin, dtype=np.float64)
    t_in, t_out = slab(o, w)
    assert 0.0 < t_in < t_out
    p1 = o + t_in * w
    scaled = s * (rotation.T @ w)
    r = unit(rotation @ scaled)
    inside = slab(p1, r)[1]
    p2 = p1 + inside * r
    rest = (WALL_Z - p2[2]) / w[2]
    assert rest > 0.0
    return t_in + inside + rest, t_in + inside / np.linalg.norm(scaled) + rest


def test_rotated_metric_box_matches_a_hand_computation(scenes):
    position, euler, scale, deformation = (0.3, -0.2, 0.5), (20.0, 35.0, 10.0), (3.0, 2.5, 2.0), (0.5, -0.3, 1.2)
    scene, wall = wall_scene(scenes)
    scene.add_aberration("turned", deformation, position=position, euler_deg=euler, scale=scale)
    backend = upload(scene)
    origin = np.array([0.0, 0.0, 5.0])
    for direction in [(0.0, 0.0, -1.0), (0.1, 0.05, -1.0), (-0.08, 0.12, -1.0), (0.02, -0.15, -1.0)]:
        w = unit(direction)
        depth, perceived = _expected_metric_ray(origin, w, position, euler, scale, deformation)
        ray = one_ray(backend, origin, w)
        assert ray.instance.tolist() == [wall] and ray.events.tolist() == [2]
        assert ray.depth[0] == pytest.approx(depth, rel=1e-12)
        assert ray.perceived[0] == pytest.approx(perceived, rel=1e-12)


def test_camera_inside_a_metric_box(scenes):
    scene, wall = wall_scene(scenes, camera=(0.0, 0.0, 1.0), look_at=(0.0, 0.0, -1.0))
    scene.add_aberration("squeeze", (0.0, 0.0, 2.0), scale=(10.0, 10.0, 4.0))
    backend = upload(scene)
    ray = one_ray(backend, (0.0, 0.0, 1.0), (0.0, 0.0, -1.0))
    assert ray.events.tolist() == [1] and ray.instance.tolist() == [wall]
    assert ray.depth[0] == pytest.approx(3.0 + 3.5, rel=1e-14)
    assert ray.perceived[0] == pytest.approx(1.0 + 3.5, rel=1e-14)
    # An oblique ray starts with the metric direction: (wx, wy, 3 wz) normalised.
    w = unit((0.2, 0.1, -1.0))
    r = unit((w[0], w[1], 3.0 * w[2]))
    expected = 3.0 / -r[2] + 3.5 / -w[2]
    assert one_ray(backend, (0.0, 0.0, 1.0), w).depth[0] == pytest.approx(expected, rel=1e-13)


def test_camera_exactly_on_a_face_and_touching_boxes(scenes):
    """Rays from a face point belong to the box they go into; a face shared by two boxes is one event."""
    scene, wall = wall_scene(scenes, camera=(0.0, 0.0, 2.0), look_at=(0.0, 0.0, -1.0))
    scene.add_aberration("low", (0.0, 0.0, 3.0), position=(0.0, 0.0, -1.0), scale=(10.0, 10.0, 2.0))
    scene.add_aberration("high", (0.0, 0.0, 1.0), position=(0.0, 0.0, 1.0), scale=(10.0, 10.0, 2.0))
    backend = upload(scene)
    ray = one_ray(backend, (0.0, 0.0, 1.0 + 1.0), (0.0, 0.0, -1.0))  # on the +z face of "high"
    assert ray.instance.tolist() == [wall] and ray.events.tolist() == [2]
    assert ray.perceived[0] == pytest.approx(2.0 / 2.0 + 2.0 / 4.0 + 3.5, rel=1e-14)
    ray = one_ray(backend, (0.0, 0.0, 5.0), (0.0, 0.0, -1.0))
    assert ray.events.tolist() == [3] and ray.depth[0] == pytest.approx(10.5, rel=1e-14)
    assert ray.perceived[0] == pytest.approx(3.0 + 1.0 + 0.5 + 3.5, rel=1e-14)
    away = one_ray(backend, (0.0, 0.0, 2.0), (0.0, 0.0, 1.0))  # leaves the face outwards: never in the box
    assert away.events.tolist() == [0] and np.isinf(away.depth[0])


@pytest.mark.parametrize(
    ("inner_first", "inner_priority", "expected"),
    [
        (False, 1, 6.0),  # the higher priority wins
        (True, 1, 6.0),
        (False, -1, 6.5),  # a lower priority box is never active inside the other
        (False, 0, 6.0),  # equal priority: the later entity wins
        (True, 0, 6.5),
    ],
)
def test_overlapping_boxes_by_priority(scenes, inner_first, inner_priority, expected):
    """Outer z in [-4, 4] with D_z = 1, inner z in [-1, 1] with D_z = 3, the wall at -5.5; camera at z = 5."""
    scene, wall = wall_scene(scenes)
    boxes = [
        ("outer", (0.0, 0.0, 1.0), (10.0, 10.0, 8.0), 0),
        ("inner", (0.0, 0.0, 3.0), (10.0, 10.0, 2.0), inner_priority),
    ]
    for name, d, scale, priority in boxes[::-1] if inner_first else boxes:
        scene.add_aberration(name, d, scale=scale, priority=priority)
    ray = one_ray(upload(scene), (0.0, 0.0, 5.0), (0.0, 0.0, -1.0))
    assert ray.events.tolist() == [4] and ray.instance.tolist() == [wall]
    assert ray.depth[0] == pytest.approx(10.5, rel=1e-14)
    # 1 + 3/2 + 2/4 + 3/2 + 1.5 with the inner box active, 1 + 8/2 + 1.5 without.
    assert ray.perceived[0] == pytest.approx(expected, rel=1e-14)


def test_wall_flush_with_a_box_face_is_hit_not_skipped(scenes):
    """A box face in the wall's plane ties with the wall: the wall wins, so no ray passes through it."""
    scene, wall = wall_scene(scenes, camera=(0.4, 0.3, 5.0), look_at=(0.0, 0.0, WALL_Z))
    scene.add_aberration("flush", (0.0, 0.0, 1.0), position=(0.0, 0.0, WALL_Z + 2.0), scale=(30.0, 30.0, 4.0))
    camera = scene_camera(scene)
    frame = upload(scene).render(camera, 41, 31)
    assert np.all(frame.instance == wall)
    w = camera.primary_directions(41, 31)
    r_z = 2.0 * w[..., 2] / np.linalg.norm(w * [1.0, 1.0, 2.0], axis=-1)
    expected = (5.0 - WALL_Z - 4.0) / -w[..., 2] + 4.0 / -r_z  # to the front face, not through the wall
    np.testing.assert_allclose(frame.depth, expected, rtol=1e-6)
    assert np.all(frame.perceived < frame.depth)


# --- radial and additive ------------------------------------------------------------------------------------


def _smoothstep(lo: float, hi: float, x: float) -> float:
    t = min(max((x - lo) / (hi - lo), 0.0), 1.0)
    return t * t * (3.0 - 2.0 * t)


def test_sigma_rule_and_collapsed_axis():
    bounds = SigmaBounds(np.array([-0.5, -0.3, -0.9]), np.array([0.5, 0.3, -0.9 + 1e-7]))
    v = np.array([[-0.5, 0.3, -0.2], [0.0, 0.0, 0.3], [-0.25, 0.15, 0.0], [2.0, -2.0, -1.0]])
    expected = [
        [-1.0, 1.0, -1.0],  # at the bounds; z collapsed: sign
        [0.0, 0.0, 1.0],
        [2.0 * _smoothstep(-0.5, 0.5, -0.25) - 1.0, 2.0 * _smoothstep(-0.3, 0.3, 0.15) - 1.0, 0.0],
        [1.0, -1.0, -1.0],  # clamped beyond the bounds
    ]
    assert expected[2][0] == pytest.approx(-0.6875)
    np.testing.assert_allclose(sigma(v, bounds), expected, rtol=0, atol=1e-15)


#: The bend box: z in [-1, 1], wide; the camera at z = 5; a ray w0 slightly off the axis.
BEND_BOX = {"scale": (20.0, 20.0, 2.0)}
BOUNDS = (np.array([-0.6, -0.4, -1.0]), np.array([0.6, 0.4, -0.8]))
W0 = unit((0.1, -0.05, -1.0))


def _bent(mode: str, d: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The entry rule by hand."""
    if mode == "additive":
        return unit(w + d)
    lo, hi = BOUNDS
    s = np.array([2.0 * _smoothstep(lo[k], hi[k], w[k]) - 1.0 for k in range(3)])
    return unit(w + d * s)


@pytest.mark.parametrize("mode", ["radial", "additive"])
@pytest.mark.parametrize("exit_rule", ["restore", "repeat", "invert"])
def test_entry_and_exit_rules_on_one_ray(scenes, mode, exit_rule):
    d = np.array([0.3, -0.2, 0.25])
    scene, wall = wall_scene(scenes)
    scene.add_aberration("bend", tuple(d), mode=mode, exit=exit_rule, **BEND_BOX)
    w1 = _bent(mode, d, W0)
    w2 = {"restore": W0, "repeat": _bent(mode, d, w1), "invert": _bent(mode, -d, w1)}[exit_rule]
    expected = 4.0 / -W0[2] + 2.0 / -w1[2] + 4.5 / -w2[2]
    ray = one_ray(upload(scene), (0.0, 0.0, 5.0), W0, BOUNDS)
    assert ray.instance.tolist() == [wall] and ray.events.tolist() == [2]
    assert ray.depth[0] == pytest.approx(expected, rel=1e-13)
    assert ray.perceived[0] == ray.depth[0]  # bends do not rescale length


def test_exit_rules_differ(scenes):
    depths = {}
    for exit_rule in ("restore", "repeat", "invert"):
        scene, _ = wall_scene(scenes)
        scene.add_aberration("bend", (0.4, 0.2, 0.0), mode="additive", exit=exit_rule, **BEND_BOX)
        depths[exit_rule] = one_ray(upload(scene), (0.0, 0.0, 5.0), W0).depth[0]
    assert len(set(depths.values())) == 3


@pytest.mark.parametrize("mode", ["radial", "additive"])
def test_camera_inside_a_bending_box_pre_deforms(scenes, mode):
    d = np.array([0.3, -0.2, 0.25])
    scene, wall = wall_scene(scenes, camera=(0.0, 0.0, 0.0), look_at=(0.0, 0.0, -1.0))
    scene.add_aberration("bend", tuple(d), mode=mode, **BEND_BOX)
    backend = upload(scene)
    w1 = _bent(mode, d, W0)
    ray = one_ray(backend, (0.0, 0.0, 0.0), W0, BOUNDS)
    assert ray.events.tolist() == [1] and ray.instance.tolist() == [wall]
    assert ray.depth[0] == pytest.approx(1.0 / -w1[2] + 4.5 / -W0[2], rel=1e-13)  # restore: back to W0


def test_render_uses_the_camera_sigma_bounds(scenes):
    """A level camera: the z range of the corner rays collapses, so σ_z = sign; x and y are smoothsteps."""
    d = np.array([0.3, 0.2, 0.5])
    scene, _ = wall_scene(scenes)
    scene.add_aberration("bend", tuple(d), mode="radial", exit="repeat", **BEND_BOX)
    backend = upload(scene)
    camera = scene_camera(scene)
    w, h = 9, 7
    frame = backend.render(camera, w, h)
    lo, hi = camera.sigma_bounds(w / h)
    assert hi[2] - lo[2] < 1e-6
    directions = camera.primary_directions(w, h).reshape(-1, 3)
    for k in (0, 10, 31, 62):
        w0 = directions[k]
        s1 = np.array([2.0 * _smoothstep(lo[0], hi[0], w0[0]) - 1.0, 2.0 * _smoothstep(lo[1], hi[1], w0[1]) - 1.0, -1])
        w1 = unit(w0 + d * s1)
        s2 = np.array([2.0 * _smoothstep(lo[0], hi[0], w1[0]) - 1.0, 2.0 * _smoothstep(lo[1], hi[1], w1[1]) - 1.0, -1])
        w2 = unit(w1 + d * s2)
        expected = 4.0 / -w0[2] + 2.0 / -w1[2] + 4.5 / -w2[2]
        assert frame.depth.reshape(-1)[k] == pytest.approx(expected, rel=1e-6)


# --- what you see is where you go ---------------------------------------------------------------------------


def _walked_to_wall(scene: Scene, dt: float = 0.05) -> float:
    """Perceived distance the movement system walks forward at unit speed until it reaches the wall plane."""
    boxes = speed_boxes(scene)
    assert scene.camera_entity is not None
    camera = scene.get(scene.camera_entity, Transform)
    position = np.array(camera.position, dtype=np.float64)
    v = quat_to_matrix(camera.rotation) @ np.array([0.0, 0.0, -1.0])
    elapsed = 0.0
    for _ in range(10_000):
        end = walk(boxes, position, v, dt)[-1]
        if end[2] > WALL_Z:
            position, elapsed = end, elapsed + dt
            continue
        lo, hi = 0.0, dt  # bisection on the last tick's time
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if walk(boxes, position, v, mid)[-1][2] > WALL_Z else (lo, mid)
        return elapsed + 0.5 * (lo + hi)
    raise AssertionError("never reached the wall")


WALK_CASES = [
    ((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), [((0.0, 0.0, 2.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (10.0, 10.0, 4.0), 0)]),
    ((0.3, 0.2, 5.0), (0.8, 0.4, -5.0), [((1.0, 0.0, -0.5), (0.0, 30.0, 0.0), (0.2, 0.0, 0.5), (3.0, 4.0, 2.0), 0)]),
    ((0.1, 0.0, 0.5), (0.5, -0.3, -5.0), [((-0.5, 0.3, 0.8), (15.0, -20.0, 5.0), (0.0, 0.0, 0.0), (4.0, 4.0, 4.0), 0)]),
    (
        (-0.2, 0.1, 4.0),
        (0.2, 0.0, -5.0),
        [
            ((1.0, 0.5, 1.0), (0.0, 10.0, 0.0), (0.0, 0.0, 0.0), (5.0, 5.0, 6.0), 0),
            ((-0.6, 0.0, 2.5), (10.0, 0.0, 40.0), (0.0, 0.0, -1.0), (2.0, 2.0, 1.5), 1),
        ],
    ),
]


@pytest.mark.parametrize(("camera", "look_at", "boxes"), WALK_CASES)
def test_what_you_see_is_where_you_go(scenes, camera, look_at, boxes):
    scene, wall = wall_scene(scenes, camera=camera, look_at=look_at)
    for i, (d, euler, position, scale, priority) in enumerate(boxes):
        scene.add_aberration(f"box{i}", d, position=position, euler_deg=euler, scale=scale, priority=priority)
    frame = upload(scene).render(scene_camera(scene), 33, 25)
    assert frame.instance[12, 16] == wall and frame.events[12, 16] >= 1
    seen = float(frame.perceived[12, 16])
    assert seen != pytest.approx(float(frame.depth[12, 16]), rel=0.02)  # the boxes matter
    assert _walked_to_wall(scene) == pytest.approx(seen, rel=0.01)


def test_what_you_see_is_where_you_go_through_the_app(scenes):
    scene, _ = wall_scene(scenes)
    scene.set_camera((0.0, 0.0, 5.0), look_at=(0.0, 0.0, 0.0), speed=1.0)
    scene.add_aberration("stretch", (0.0, 0.0, -0.5), scale=(10.0, 10.0, 4.0))
    seen = float(upload(scene).render(scene_camera(scene), 33, 25).perceived[12, 16])
    assert seen == pytest.approx(3.0 + 8.0 + 3.5)
    dt, ticks = 0.02, 0
    with App(scene, input_source=ScriptedInput(lambda _: InputState(move=(0.0, 0.0, -1.0)))) as app:
        camera = scene.camera_entity
        assert camera is not None
        while scene.get(camera, Transform).position[2] > WALL_Z:
            app.tick(dt)
            ticks += 1
    assert ticks * dt == pytest.approx(seen, rel=0.01)


# --- hard inputs ------------------------------------------------------------------------------------------------


HARD_BOXES = [
    ("metric", (-0.999, 0.0, -0.999)),
    ("metric", (1e6, 1e6, 0.0)),
    ("radial", (1e6, -0.999, 1e6)),
    ("radial", (-0.999, -0.999, -1.0)),
    ("additive", (1e6, 0.0, -1e6)),
    ("additive", (0.0, 0.0, 1.0)),  # cancels the axis ray exactly: keeps the previous direction
]


@pytest.mark.parametrize(("mode", "d"), HARD_BOXES)
def test_no_nan_on_hard_inputs(scenes, mode, d):
    scene, _ = wall_scene(scenes, camera=(0.5, 0.5, 3.0), look_at=(0.5, 0.5, 0.0), max_events=8)
    scene.add_aberration("hard", d, mode=mode, scale=(1.0, 1.0, 1.0))
    scene.add_aberration("turned", d, mode=mode, position=(-0.5, 0.0, -2.0), euler_deg=(0.0, 45.0, 0.0))
    backend = upload(scene)
    frame = backend.render(scene_camera(scene), 24, 18)
    for name in ("depth", "perceived"):
        assert not np.any(np.isnan(frame.aov(name)))
    assert np.all(frame.events <= 8)
    assert np.array_equal(np.isinf(frame.depth), frame.instance == -1)
    # Rays along a face plane (y = 0.5), along an edge (x = y = 0.5), through a corner, along the axis.
    origins = [(0.0, 0.5, 3.0), (0.5, 0.5, 3.0), (-1.0, -1.0, 2.5), (0.0, 0.0, 3.0), (0.5, 0.5, 0.5)]
    directions = [(0.0, 0.0, -1.0), (0.0, 0.0, -1.0), (1.5, 1.5, -2.0), (0.0, 0.0, -1.0), (0.0, 0.0, -1.0)]
    for origin, direction in zip(origins, directions, strict=True):
        ray = one_ray(backend, origin, direction, BOUNDS)
        assert np.all(np.isfinite(ray.color)) and not np.isnan(ray.depth[0]) and not np.isnan(ray.perceived[0])
        assert ray.events[0] <= 8

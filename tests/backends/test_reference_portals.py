"""Portals in the float64 reference tracer: doors between rooms, closed forms, chains, hard cases.

The rules are those of docs/semantics.md ("Portals", rules 3 and 10).
Room A is around the origin, room B around x = 100 (and room D around x = 200):
far enough apart that nothing of one room is seen from another except
through a portal.
"""

from __future__ import annotations

import numpy as np
import pytest
from scenes import upload_to_reference as upload

from backends.base import AOVS
from backends.reference.backend import ReferenceBackend
from backends.reference.trace import TraceResult, to_uint8
from engine.camera_view import scene_camera
from engine.scene import Scene
from engine.settings import Settings

B = np.array([100.0, 0.0, 0.0])
#: A room's back wall: (entity name, centre, front face z).
A_WALL_Z, B_WALL_Z = -4.0, -8.0
CAMERA = (0.0, 0.0, 5.0)


def unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def one_ray(backend: ReferenceBackend, origin, direction) -> TraceResult:
    return backend.trace_rays(np.asarray(origin, dtype=np.float64), unit(direction)[None])


def wall(scene: Scene, name: str, x: float, z: float) -> int:
    """A wide wall at x whose face towards +z lies at z (checkered, so images have structure)."""
    return scene.add_mesh(name, "box", position=(x, 0.0, z - 0.5), scale=(20.0, 20.0, 1.0), checker=0.5)


def two_rooms(scenes: list[Scene], b: dict | None = None, a: dict | None = None, **settings) -> tuple[Scene, int, int]:
    """Walls of rooms A and B, the door pair A -> B, B -> A, and a camera in room A looking at door A."""
    scene = Scene(settings=Settings(**settings))
    scenes.append(scene)
    wall_a = wall(scene, "wall_a", 0.0, A_WALL_Z)
    wall_b = wall(scene, "wall_b", B[0], B_WALL_Z)
    scene.add_portal_pair("door_a", "door_b", a=a or {}, b=b or {"position": tuple(B)})
    scene.set_camera(CAMERA, look_at=(0.0, 0.0, 0.0))
    return scene, wall_a, wall_b


def door_pixels(scene: Scene, width: int, height: int, half: float = 1.0) -> np.ndarray:
    """Pixels whose primary ray meets the unit door quad at z = 0 (with a margin from its border)."""
    d = scene_camera(scene).primary_directions(width, height)
    s = CAMERA[2] / -d[..., 2]
    inside = (np.abs(s * d[..., 0]) < half - 0.02) & (np.abs(s * d[..., 1]) < half - 0.02)
    outside = (np.abs(s * d[..., 0]) > half + 0.02) | (np.abs(s * d[..., 1]) > half + 0.02)
    return np.where(inside, 1, np.where(outside, 0, -1))


# --- doors between rooms ------------------------------------------------------------------------------------


def test_door_shows_the_other_room(scenes):
    scene, wall_a, wall_b = two_rooms(scenes)
    backend = upload(scene)
    frame = backend.render(scene_camera(scene), 33, 25)
    where = door_pixels(scene, 33, 25)
    assert (where == 1).sum() > 20 and (where == 0).sum() > 200
    assert np.all(frame.instance[where == 1] == wall_b) and np.all(frame.events[where == 1] == 1)
    assert np.all(frame.instance[where == 0] == wall_a) and np.all(frame.events[where == 0] == 0)
    assert frame.depth[12, 16] == np.float32(5.0 + 8.0)  # to door A, then from door B on
    assert np.array_equal(frame.perceived, frame.depth)
    w = unit((0.06, -0.04, -1.0))
    ray = one_ray(backend, CAMERA, w)
    assert ray.instance.tolist() == [wall_b] and ray.events.tolist() == [1]
    assert ray.depth[0] == pytest.approx((5.0 + 8.0) / -w[2], rel=1e-13)


def test_door_pair_rotated_180_degrees(scenes):
    """Door B turned about y: rays leave it along +z, mirrored in x, and see room B's wall at z = +6."""
    scene, _, _ = two_rooms(scenes, b={"position": tuple(B), "euler_deg": (0.0, 180.0, 0.0)})
    front = scene.add_mesh("front_b", "box", position=(B[0], 0.0, 6.5), scale=(20.0, 20.0, 1.0))
    w = unit((0.06, -0.04, -1.0))
    p = np.array(CAMERA) + 5.0 / -w[2] * w  # on door A
    arrival = B + np.array([-p[0], p[1], 0.0])
    hit = arrival + 6.0 / -w[2] * np.array([-w[0], w[1], -w[2]])
    marker = scene.add_mesh("marker", "box", position=(hit[0], hit[1], 5.99), scale=(0.03, 0.03, 0.02))
    backend = upload(scene)
    centre = one_ray(backend, CAMERA, (0.0, 0.0, -1.0))
    assert centre.instance.tolist() == [front] and centre.depth[0] == pytest.approx(11.0, rel=1e-14)
    ray = one_ray(backend, CAMERA, w)
    assert ray.instance.tolist() == [marker] and ray.events.tolist() == [1]
    assert ray.depth[0] == pytest.approx((5.0 + 5.98) / -w[2], rel=1e-12)  # the marker faces -z at 5.98


def test_portals_of_different_non_uniform_scale(scenes):
    """L = diag(2, 0.5, 3): directions are renormalised, depth stays the world path length."""
    scene, _, wall_b = two_rooms(scenes, b={"position": tuple(B), "scale": (2.0, 0.5, 3.0)})
    backend = upload(scene)
    assert one_ray(backend, CAMERA, (0.0, 0.0, -1.0)).depth[0] == pytest.approx(13.0, rel=1e-14)
    w = unit((0.06, -0.04, -1.0))
    r = unit(w * [2.0, 0.5, 3.0])
    ray = one_ray(backend, CAMERA, w)
    assert ray.instance.tolist() == [wall_b]
    assert ray.depth[0] == pytest.approx(5.0 / -w[2] + 8.0 / -r[2], rel=1e-13)
    # The lateral direction too: a marker where the mapped ray meets room B's wall.
    p = np.array(CAMERA) + 5.0 / -w[2] * w
    hit = B + np.array([2.0 * p[0], 0.5 * p[1], 0.0]) + 8.0 / -r[2] * r
    marker = scene.add_mesh("marker", "box", position=(hit[0], hit[1], B_WALL_Z + 0.01), scale=(0.03, 0.03, 0.02))
    assert one_ray(upload(scene), CAMERA, w).instance.tolist() == [marker]


def test_portal_seen_through_a_portal(scenes):
    scene, _, _ = two_rooms(scenes)
    scene.add_portal_pair("door_c", "door_d", a={"position": (B[0], 0.0, -3.0)}, b={"position": (200.0, 0.0, 0.0)})
    wall_d = wall(scene, "wall_d", 200.0, -2.0)
    backend = upload(scene)
    ray = one_ray(backend, CAMERA, (0.0, 0.0, -1.0))
    assert ray.instance.tolist() == [wall_d] and ray.events.tolist() == [2]
    assert ray.depth[0] == pytest.approx(5.0 + 3.0 + 2.0, rel=1e-14)
    w = unit((0.05, 0.03, -1.0))
    assert one_ray(backend, CAMERA, w).depth[0] == pytest.approx(10.0 / -w[2], rel=1e-13)


def test_portal_inside_a_metric_aberration(scenes):
    """D_z = 2 around door A (z in [-2, 2]) and around door B: both ends of the trip are compressed."""
    scene, _, wall_b = two_rooms(scenes)
    scene.add_aberration("around_a", (0.0, 0.0, 2.0), scale=(10.0, 10.0, 4.0))
    backend = upload(scene)
    ray = one_ray(backend, CAMERA, (0.0, 0.0, -1.0))
    assert ray.instance.tolist() == [wall_b] and ray.events.tolist() == [2]  # the box face, the door
    assert ray.depth[0] == pytest.approx(13.0, rel=1e-14)
    assert ray.perceived[0] == pytest.approx(3.0 + 2.0 / 3.0 + 8.0, rel=1e-14)
    w = unit((0.1, 0.05, -1.0))
    inside = np.array([w[0], w[1], 3.0 * w[2]])
    r = unit(inside)
    expected = 3.0 / -w[2] + 2.0 / -r[2] + 8.0 / -w[2]  # bent inside the box, back to w after the door
    ray = one_ray(backend, CAMERA, w)
    assert ray.depth[0] == pytest.approx(expected, rel=1e-13)
    assert ray.perceived[0] == pytest.approx(3.0 / -w[2] + 2.0 / -r[2] / np.linalg.norm(inside) + 8.0 / -w[2])
    scene.add_aberration("around_b", (0.0, 0.0, 2.0), position=tuple(B), scale=(10.0, 10.0, 4.0))
    ray = one_ray(upload(scene), CAMERA, (0.0, 0.0, -1.0))
    assert ray.events.tolist() == [3] and ray.depth[0] == pytest.approx(13.0, rel=1e-14)
    assert ray.perceived[0] == pytest.approx(3.0 + 2.0 / 3.0 + 2.0 / 3.0 + 6.0, rel=1e-14)


def test_door_flush_with_a_wall_shows_the_portal(scenes):
    """Door A lies on wall A's face, door B on wall B's face turned to face into room B: exact ties go to the portal."""
    scene, _, _ = two_rooms(
        scenes,
        a={"position": (0.0, 0.0, A_WALL_Z)},
        b={"position": (B[0], 0.0, B_WALL_Z), "euler_deg": (0.0, 180.0, 0.0)},
    )
    front = scene.add_mesh("front_b", "box", position=(B[0], 0.0, 3.5), scale=(20.0, 20.0, 1.0))
    camera = scene_camera(scene)
    frame = upload(scene).render(camera, 41, 31)
    d = camera.primary_directions(41, 31)
    s = (CAMERA[2] - A_WALL_Z) / -d[..., 2]
    on_door = (np.abs(s * d[..., 0]) < 0.98) & (np.abs(s * d[..., 1]) < 0.98)
    assert on_door.sum() > 20
    assert np.all(frame.instance[on_door] == front) and np.all(frame.events[on_door] == 1)
    np.testing.assert_allclose(frame.depth[on_door], (9.0 + 11.0) / -d[..., 2][on_door], rtol=1e-6)


# --- hard cases ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("max_events", [5, 16])
def test_facing_portals_hit_the_event_limit(scenes, max_events):
    scene = Scene(settings=Settings(max_events=max_events, event_limit_color=(1.0, 0.0, 1.0)))
    scenes.append(scene)
    scene.add_portal_pair("a", "b", a={"scale": 50.0}, b={"position": (0.0, 0.0, 2.0), "scale": 50.0})
    scene.add_mesh("ball", "sphere", position=(0.0, 0.0, -3.0))  # behind door a: never reached
    scene.set_camera((0.0, 0.0, 1.0), look_at=(0.0, 0.0, 0.0))
    frame = upload(scene).render(scene_camera(scene), 24, 18)
    assert np.all(frame.color[..., :3] == to_uint8(np.array([1.0, 0.0, 1.0])))
    assert np.all(frame.events == max_events) and np.all(frame.instance == -1)
    assert np.all(np.isinf(frame.depth)) and np.all(np.isinf(frame.perceived))


def test_unlinked_portal_is_invisible(scenes):
    frames = []
    for with_portal in (False, True):
        scene, _, _ = two_rooms(scenes)
        scene.add_mesh("ball", "sphere", position=(0.5, 0.3, -1.0))
        if with_portal:
            scene.add_portal("loose", position=(0.3, 0.0, 2.0), euler_deg=(10.0, 20.0, 0.0), scale=2.0)
        frames.append(upload(scene).render(scene_camera(scene), 40, 30))
    for name in AOVS:
        assert np.array_equal(frames[0].aov(name), frames[1].aov(name)), name


def test_one_way_link(scenes):
    """A -> B only: A shows room B, but B (unlinked) is invisible from room B."""
    scene = Scene()
    scenes.append(scene)
    wall(scene, "wall_a", 0.0, A_WALL_Z)
    wall_b = wall(scene, "wall_b", B[0], B_WALL_Z)
    scene.add_portal("door_b", position=tuple(B))
    scene.add_portal("door_a", target="door_b")
    scene.set_camera(CAMERA, look_at=(0.0, 0.0, 0.0))
    backend = upload(scene)
    through = one_ray(backend, CAMERA, (0.0, 0.0, -1.0))
    assert through.instance.tolist() == [wall_b] and through.events.tolist() == [1]
    assert through.depth[0] == pytest.approx(13.0, rel=1e-14)
    at_b = one_ray(backend, B + np.array([0.0, 0.0, 5.0]), (0.0, 0.0, -1.0))
    assert at_b.instance.tolist() == [wall_b] and at_b.events.tolist() == [0]
    assert at_b.depth[0] == pytest.approx(13.0, rel=1e-14)


def test_no_nan_on_portal_edges_and_grazing_rays(scenes):
    scene, _, _ = two_rooms(
        scenes, b={"position": tuple(B), "euler_deg": (30.0, 200.0, 10.0), "scale": (3.0, 0.2, 5.0)}
    )
    backend = upload(scene)
    origins = [(1.0, 0.0, 5.0), (1.0, 1.0, 5.0), (-2.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 5.0)]
    directions = [(0.0, 0.0, -1.0), (0.0, 0.0, -1.0), (1.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 0.0, 0.0)]
    result = backend.trace_rays(np.zeros(3), np.zeros((0, 3)))
    for origin, direction in zip(origins, directions, strict=True):
        d = np.asarray(direction, dtype=np.float64)
        result = backend.trace_rays(np.asarray(origin, dtype=np.float64), d[None])
        assert not np.isnan(result.depth[0]) and not np.isnan(result.perceived[0])
        assert np.all(np.isfinite(result.color))
    frame = backend.render(scene_camera(scene), 24, 18)
    assert not np.any(np.isnan(frame.depth)) and not np.any(np.isnan(frame.perceived))

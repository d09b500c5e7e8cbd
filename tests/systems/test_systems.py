"""The four systems, headless: scripted camera movement, aberration-scaled walking, portal teleport, upload."""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence

import numpy as np
import pytest

from backends.base import AOVS, Backend, Frame
from components import Camera, Transform
from engine import layout
from engine.camera_view import CameraView
from engine.errors import SceneError
from engine.input import InputState, NoInput, ScriptedInput
from engine.maths import quat_from_euler_deg, quat_to_matrix
from engine.packed import PackedScene, TableUpdate
from engine.scene import Scene
from systems.app import App
from systems.camera_movement import MAX_SUBSTEPS, SPRINT_MULTIPLIER, speed_boxes, walk
from systems.portal_teleport import MAX_CROSSINGS

FORWARD = InputState(move=(0.0, 0.0, -1.0))
RIGHT = InputState(move=(1.0, 0.0, 0.0))


class RecordingBackend(Backend):
    """A stand-in tracer that records what the systems hand it."""

    name = "recording"

    def __init__(self) -> None:
        super().__init__()
        self.uploads: list[list[TableUpdate]] = []
        self.packed: list[PackedScene] = []
        self.cameras: list[CameraView] = []

    @classmethod
    def probe(cls) -> str | None:
        return None

    def upload(self, packed: PackedScene, updates: Sequence[TableUpdate]) -> int:
        self.uploads.append(list(updates))
        self.packed.append(packed)
        return packed.update_bytes(list(updates))

    def render(self, camera: CameraView, width: int, height: int, aovs: Sequence[str] = AOVS) -> Frame:
        self.cameras.append(camera)
        return Frame(width, height, depth=np.zeros((height, width), np.float32))


@pytest.fixture
def scenes() -> Iterator[list[Scene]]:
    """Scenes made by a test are closed afterwards (their esper worlds deleted)."""
    made: list[Scene] = []
    yield made
    for scene in made:
        scene.close()


@pytest.fixture
def make_scene(scenes: list[Scene]):
    def make(position=(0.0, 0.0, 0.0), euler_deg=None, speed: float = 3.0) -> Scene:
        scene = Scene("test")
        scene.set_camera(position, euler_deg=euler_deg, speed=speed)
        scenes.append(scene)
        return scene

    return make


def play(scene: Scene, script, dt: float = 0.1, ticks: int | None = None) -> App:
    """Run a scripted input on a headless app; returns the (closed) app for its motion record."""
    source = ScriptedInput(script)
    app = App(scene, input_source=source)
    app.run(len(script) if ticks is None else ticks, dt)
    app.close()
    return app


def camera(scene: Scene) -> Transform:
    assert scene.camera_entity is not None
    return scene.get(scene.camera_entity, Transform)


def position(scene: Scene) -> np.ndarray:
    return np.array(camera(scene).position)


def forward(scene: Scene) -> np.ndarray:
    return -quat_to_matrix(camera(scene).rotation)[:, 2]


def ry(deg: float) -> np.ndarray:
    return quat_to_matrix(quat_from_euler_deg((0.0, deg, 0.0)))


# --- scripted input and camera movement ---------------------------------------------------------


def test_walking_forward_lands_where_the_closed_form_says(make_scene):
    scene = make_scene(position=(1.0, 2.0, 3.0))
    play(scene, [FORWARD] * 10, dt=0.1)
    assert np.allclose(position(scene), (1.0, 2.0, 3.0 - 10 * 3.0 * 0.1), atol=1e-12)
    assert np.allclose(forward(scene), (0.0, 0.0, -1.0))


def test_script_end_means_no_input(make_scene):
    scene = make_scene()
    play(scene, [FORWARD] * 2, dt=0.1, ticks=5)
    assert np.allclose(position(scene), (0.0, 0.0, -0.6), atol=1e-12)


def test_callable_script_is_indexed_by_tick(make_scene):
    scene = make_scene()
    source = ScriptedInput(lambda i: RIGHT if i % 2 == 0 else None)
    with App(scene, input_source=source) as app:
        app.run(4, 0.5)
    assert np.allclose(position(scene), (2 * 3.0 * 0.5, 0.0, 0.0), atol=1e-12)


def test_strafing_and_diagonals_use_the_camera_frame_at_unit_speed(make_scene):
    scene = make_scene(euler_deg=(0.0, 90.0, 0.0))  # looking along -x, right is -z
    play(scene, [RIGHT] * 2, dt=0.1)
    assert np.allclose(position(scene), (0.0, 0.0, -0.6), atol=1e-12)
    scene2 = make_scene()
    play(scene2, [InputState(move=(1.0, 0.0, -1.0))], dt=1.0)  # normalised: not faster on a diagonal
    assert np.allclose(position(scene2), (3.0 / math.sqrt(2), 0.0, -3.0 / math.sqrt(2)), atol=1e-12)
    scene3 = make_scene()
    play(scene3, [InputState(move=(0.0, 5.0, 0.0))], dt=1.0)  # up, length ignored
    assert np.allclose(position(scene3), (0.0, 3.0, 0.0), atol=1e-12)


def test_sprint_multiplies_speed(make_scene):
    scene = make_scene()
    play(scene, [InputState(move=(0.0, 0.0, -1.0), sprint=True)] * 3, dt=0.1)
    assert np.allclose(position(scene), (0.0, 0.0, -3 * 3.0 * SPRINT_MULTIPLIER * 0.1), atol=1e-12)


def test_speed_override_replaces_camera_speed_for_one_tick(make_scene):
    scene = make_scene()
    camera_before = scene.get(scene.camera_entity, Camera)
    play(scene, [InputState(move=(0.0, 0.0, -1.0), speed=0.5), FORWARD], dt=1.0)
    assert np.allclose(position(scene), (0.0, 0.0, -0.5 - 3.0), atol=1e-12)
    assert scene.get(scene.camera_entity, Camera) == camera_before
    with pytest.raises(ValueError, match=r"InputState\.speed"):
        InputState(speed=-1.0)


def test_custom_sprint_multiplier(make_scene):
    scene = make_scene()
    with App(
        scene, input_source=ScriptedInput([InputState(move=(0, 0, -1), sprint=True)]), sprint_multiplier=5.0
    ) as app:
        app.tick(0.1)
    assert np.allclose(position(scene), (0.0, 0.0, -1.5), atol=1e-12)


def test_yaw_turns_about_world_up_and_walking_follows(make_scene):
    scene = make_scene()
    play(scene, [InputState(look=(30.0, 0.0))] * 3 + [FORWARD], dt=0.1)
    assert np.allclose(forward(scene), (-1.0, 0.0, 0.0), atol=1e-12)  # +90° yaw: left
    assert np.allclose(position(scene), (-0.3, 0.0, 0.0), atol=1e-12)


def test_pitch_looks_up_about_local_x(make_scene):
    scene = make_scene(euler_deg=(0.0, 90.0, 0.0))
    play(scene, [InputState(look=(0.0, 20.0))], dt=0.1)
    f = forward(scene)
    assert np.allclose(f, (-math.cos(math.radians(20)), math.sin(math.radians(20)), 0.0), atol=1e-12)
    up = quat_to_matrix(camera(scene).rotation)[:, 1]
    assert up[1] > 0.9  # no roll introduced


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_pitch_is_clamped_to_89_degrees(make_scene, sign):
    scene = make_scene(euler_deg=(0.0, 45.0, 0.0))
    play(scene, [InputState(look=(10.0, sign * 50.0))] * 3, dt=0.1)
    f = forward(scene)
    assert math.degrees(math.asin(f[1])) == pytest.approx(sign * 89.0, abs=1e-9)
    heading = math.degrees(math.atan2(-f[0], -f[2]))
    assert heading == pytest.approx(75.0, abs=1e-9)  # yaw still applied: 45 + 3 x 10
    play(scene, [InputState(look=(0.0, -sign * 9.0))], dt=0.1)  # coming back works
    assert math.degrees(math.asin(forward(scene)[1])) == pytest.approx(sign * 80.0, abs=1e-9)


def test_idle_tick_writes_nothing(make_scene):
    scene = make_scene()
    cursor = scene.cursor
    play(scene, [NoInput().poll(0.1)] * 3, dt=0.1)
    assert scene.cursor == cursor  # nothing journalled, so nothing re-uploaded


def test_dt_zero_does_not_move(make_scene):
    scene = make_scene()
    play(scene, [FORWARD], dt=0.0)
    assert np.array_equal(position(scene), (0.0, 0.0, 0.0))


# --- aberrations scale the walk -----------------------------------------------------------------


def test_metric_box_doubles_speed_along_its_x(make_scene):
    scene = make_scene(position=(-2.0, 0.0, 0.0))
    scene.add_aberration("fast", (1.0, 0.0, 0.0), scale=10.0)
    play(scene, [RIGHT] * 3, dt=0.1)
    assert np.allclose(position(scene), (-2.0 + 3 * 0.6, 0.0, 0.0), atol=1e-12)
    play(scene, [InputState(move=(0.0, 0.0, -1.0))] * 2, dt=0.1)  # along its z: D_z = 0
    assert np.allclose(position(scene), (-0.2, 0.0, -0.6), atol=1e-12)


def test_entering_a_box_mid_tick_scales_only_the_time_inside(make_scene):
    scene = make_scene(position=(-0.15, 0.0, 0.0))
    scene.add_aberration("fast", (1.0, 0.0, 0.0), position=(5.0, 0.0, 0.0), scale=10.0)  # x in [0, 10]
    play(scene, [RIGHT], dt=0.1)
    # 0.05 s to reach x = 0 at speed 3, then 0.05 s at speed 6
    assert np.allclose(position(scene), (0.3, 0.0, 0.0), atol=1e-12)


def test_a_box_thinner_than_one_step_is_not_skipped(make_scene):
    width, s = 0.05, 4.0
    scene = make_scene()
    scene.add_aberration("thin", (s - 1.0, 0.0, 0.0), position=(0.15, 0.0, 0.0), scale=(width, 1.0, 1.0))
    app = play(scene, [RIGHT], dt=0.1)  # 0.3 per tick: the box [0.125, 0.175] lies inside one step
    # the box is crossed in width / (3 s) seconds instead of width / 3: the saved time walks on outside
    expected = 0.3 + width * (1.0 - 1.0 / s)
    assert position(scene)[0] == pytest.approx(expected, abs=1e-12)
    assert [p[0] for p in app.motion.path] == pytest.approx([0.0, 0.125, 0.175, expected], abs=1e-12)


def test_a_compressing_box_slows_the_camera(make_scene):
    scene = make_scene()
    scene.add_aberration("slow", (-0.5, 0.0, 0.0), scale=10.0)
    play(scene, [RIGHT] * 4, dt=0.1)
    assert np.allclose(position(scene), (4 * 0.15, 0.0, 0.0), atol=1e-12)


def test_a_rotated_box_scales_along_its_own_axes(make_scene):
    scene = make_scene()
    scene.add_aberration("tilted", (1.0, 0.0, 0.0), euler_deg=(0.0, 45.0, 0.0), scale=20.0)
    play(scene, [RIGHT], dt=0.1)
    # v = (3, 0, 0); box x axis = (c, 0, -c), z axis = (c, 0, c) with c = cos 45°
    # the x component (3c) doubles, the z component (3c) stays: 6c·(c, 0, -c) + 3c·(c, 0, c) = (4.5, 0, -1.5)
    assert np.allclose(position(scene), (0.45, 0.0, -0.15), atol=1e-12)
    scene2 = make_scene()
    scene2.add_aberration("turned", (1.0, 0.0, 0.0), euler_deg=(0.0, 90.0, 0.0), scale=20.0)
    play(scene2, [RIGHT, FORWARD], dt=0.1)  # its x axis is world -z
    assert np.allclose(position(scene2), (0.3, 0.0, -0.6), atol=1e-12)


def test_overlapping_boxes_honour_priority_then_creation_order(make_scene):
    scene = make_scene()
    scene.add_aberration("big", (1.0, 0.0, 0.0), scale=20.0, priority=5)
    scene.add_aberration("inner-low", (9.0, 0.0, 0.0), scale=4.0, priority=0)  # ignored: lower priority
    play(scene, [RIGHT], dt=0.1)
    assert np.allclose(position(scene), (0.6, 0.0, 0.0), atol=1e-12)

    scene2 = make_scene()
    scene2.add_aberration("big", (1.0, 0.0, 0.0), scale=40.0, priority=0)
    scene2.add_aberration("inner-high", (3.0, 0.0, 0.0), scale=4.0, priority=1)  # x in [-2, 2]
    play(scene2, [RIGHT] * 2, dt=1.0)
    # tick 1: 0 -> 2 at speed 12 (1/6 s), then 5/6 s at speed 6: 2 + 5 = 7; tick 2: 6 more
    assert np.allclose(position(scene2), (13.0, 0.0, 0.0), atol=1e-9)

    scene3 = make_scene()
    scene3.add_aberration("first", (1.0, 0.0, 0.0), scale=20.0)
    scene3.add_aberration("later", (2.0, 0.0, 0.0), scale=20.0)  # same priority: the later entity wins
    play(scene3, [RIGHT], dt=0.1)
    assert np.allclose(position(scene3), (0.9, 0.0, 0.0), atol=1e-12)


def test_radial_boxes_scale_speed_too(make_scene):
    scene = make_scene()
    scene.add_aberration("radial", (1.0, 0.0, 0.0), mode="radial", scale=20.0)
    play(scene, [RIGHT], dt=0.1)
    assert np.allclose(position(scene), (0.6, 0.0, 0.0), atol=1e-12)


def test_substeps_are_capped_and_the_walk_still_uses_the_whole_tick(make_scene):
    scene = make_scene()
    for i in range(40):  # 80 faces in one tick
        scene.add_aberration(f"slab{i}", (1.0, 0.0, 0.0), position=(0.1 + 0.2 * i, 0.0, 0.0), scale=(0.1, 1.0, 1.0))
    path = walk(speed_boxes(scene), np.zeros(3), np.array([3.0, 0.0, 0.0]), 10.0)
    assert len(path) == MAX_SUBSTEPS + 2
    assert np.all(np.diff([p[0] for p in path]) >= 0.0)
    assert path[-1][0] > 30.0  # nothing lost: at least the unscaled distance


# --- portal teleport -------------------------------------------------------------------------------


def add_pair(scene: Scene, b_position=(10.0, 0.0, 0.0), b_euler=(0.0, 180.0, 0.0), b_scale=1.0) -> tuple[int, int]:
    return scene.add_portal_pair(
        "A", "B", a={"position": (0.0, 0.0, 0.0)}, b={"position": b_position, "euler_deg": b_euler, "scale": b_scale}
    )


def test_walking_through_a_translated_pair(make_scene):
    scene = make_scene(position=(0.3, 0.5, 1.0))
    a, b = add_pair(scene, b_position=(5.0, 0.0, -3.0), b_euler=(0.0, 0.0, 0.0))
    app = play(scene, [FORWARD] * 4, dt=0.1)  # tick 4 crosses z = 0 and goes 0.2 further
    assert app.motion.crossings == [(a, b)]
    assert np.allclose(position(scene), (5.3, 0.5, -3.2), atol=1e-9)
    assert np.allclose(forward(scene), (0.0, 0.0, -1.0), atol=1e-12)


def test_walking_through_a_180_degree_pair_maps_position_and_orientation(make_scene):
    scene = make_scene(position=(0.3, 0.5, 1.0))
    add_pair(scene)
    play(scene, [FORWARD] * 4, dt=0.1)
    # X = T(10, 0, 0) R_y(180): crossing (0.3, 0.5, 0) -> (9.7, 0.5, 0); the remaining (0, 0, -0.2) -> (0, 0, 0.2)
    assert np.allclose(position(scene), (9.7, 0.5, 0.2), atol=1e-9)
    assert np.allclose(quat_to_matrix(camera(scene).rotation), ry(180.0), atol=1e-12)
    play(scene, [FORWARD] * 3, dt=0.1)  # and walks on away from B, never back
    assert np.allclose(position(scene), (9.7, 0.5, 1.1), atol=1e-9)


def test_a_90_degree_scaled_pair_rotates_by_the_rotation_part_only(make_scene):
    scene = make_scene(position=(0.3, 0.5, 1.0))
    add_pair(scene, b_euler=(0.0, 90.0, 0.0), b_scale=2.0)
    play(scene, [FORWARD] * 4, dt=0.1)
    # L = 2 R_y(90): crossing -> 10 + 2 R (0.3, 0.5, 0); remaining 2 R (0, 0, -0.2)
    expected = np.array([10.0, 0.0, 0.0]) + 2.0 * ry(90.0) @ np.array([0.3, 0.5, -0.2])
    assert np.allclose(position(scene), expected, atol=1e-9)
    assert np.allclose(quat_to_matrix(camera(scene).rotation), ry(90.0), atol=1e-12)


def test_a_fast_camera_does_not_tunnel(make_scene):
    scene = make_scene(position=(0.0, 0.0, 1.0), speed=100.0)
    a, b = add_pair(scene)
    app = play(scene, [FORWARD], dt=0.1)  # one tick: z 1 -> -9, neither end near the quad
    assert app.motion.crossings == [(a, b)]
    assert np.allclose(position(scene), (10.0, 0.0, 9.0), atol=1e-9)


def test_passing_beside_the_quad_does_not_teleport(make_scene):
    scene = make_scene(position=(1.5, 0.0, 1.0), speed=100.0)
    add_pair(scene)
    app = play(scene, [FORWARD], dt=0.1)
    assert app.motion.crossings == []
    assert np.allclose(position(scene), (1.5, 0.0, -9.0), atol=1e-12)


def test_arriving_exactly_on_the_target_quad_does_not_oscillate(make_scene):
    scene = make_scene(position=(0.0, 0.0, 0.5), speed=2.0)
    a, b = add_pair(scene)
    with App(scene, input_source=ScriptedInput([FORWARD, None, FORWARD, FORWARD])) as app:
        app.tick(0.25)  # exactly 0.5: ends on A, teleported onto B with nothing left to walk
        assert app.motion.crossings == [(a, b)]
        assert np.allclose(position(scene), (10.0, 0.0, 0.0), atol=1e-12)
        app.tick(0.25)  # standing on B
        assert app.motion.crossings == []
        assert np.allclose(position(scene), (10.0, 0.0, 0.0), atol=1e-12)
        for _ in range(2):  # walking on from B does not go back through it
            app.tick(0.25)
            assert app.motion.crossings == []
    assert np.allclose(position(scene), (10.0, 0.0, 1.0), atol=1e-12)


def test_an_unlinked_portal_does_nothing(make_scene):
    scene = make_scene(position=(0.0, 0.0, 1.0))
    scene.add_portal("lonely")
    app = play(scene, [FORWARD] * 5, dt=0.1)
    assert app.motion.crossings == []
    assert np.allclose(position(scene), (0.0, 0.0, -0.5), atol=1e-12)


def test_a_one_way_link_teleports_only_from_its_source(make_scene):
    scene = make_scene(position=(10.0, 0.0, -1.0))
    scene.add_portal("B", position=(10.0, 0.0, 0.0), euler_deg=(0.0, 180.0, 0.0))
    scene.add_portal("A", target="B")
    play(scene, [InputState(move=(0.0, 0.0, 1.0))] * 5, dt=0.1)  # through B (inert): walks straight on
    assert np.allclose(position(scene), (10.0, 0.0, 0.5), atol=1e-12)


def test_facing_portals_stop_after_the_crossing_cap(make_scene):
    scene = make_scene(position=(0.0, 0.0, 0.25), speed=100.0)
    a, b = add_pair(scene, b_position=(0.0, 0.0, 0.5), b_euler=(0.0, 0.0, 0.0))  # an endless corridor
    with App(scene, input_source=ScriptedInput([FORWARD] * 3)) as app:
        for _ in range(3):
            app.tick(0.1)
            assert app.motion.crossings == [(a, b)] * MAX_CROSSINGS
            assert np.allclose(position(scene), (0.0, 0.0, 0.5), atol=1e-12)  # on B, never past A


def test_portal_inside_an_aberration_uses_the_walked_path(make_scene):
    scene = make_scene(position=(0.0, 0.0, 1.0))
    scene.add_aberration("fast", (0.0, 0.0, 1.0), scale=(4.0, 4.0, 1.0))  # z in [-0.5, 0.5], s_z = 2
    a, b = add_pair(scene, b_euler=(0.0, 0.0, 0.0))
    app = play(scene, [FORWARD], dt=0.5)
    # 1/6 s to the box (z = 0.5), then z 0.5 -> -0.5 at speed 6 (1/6 s) crossing A at z = 0 on the way,
    # then 1/6 s at speed 3: the mapped rest of the path ends at (10, 0, -1)
    assert app.motion.crossings == [(a, b)]
    assert np.allclose(position(scene), (10.0, 0.0, -1.0), atol=1e-9)


# --- GPU upload -----------------------------------------------------------------------------------


def test_static_tick_uploads_nothing_and_a_moved_entity_one_instance_row(make_scene):
    scene = make_scene(position=(0.0, 0.0, 5.0))
    scene.add_mesh("floor", "plane", position=(0.0, -1.0, 0.0), scale=10.0)
    box = scene.add_mesh("box", "box", position=(2.0, 0.0, 0.0))
    scene.add_mesh("ball", "sphere", position=(-2.0, 0.0, 0.0))
    backend = RecordingBackend()
    with App(scene, backend, size=(8, 6)) as app:
        app.tick(0.1)
        assert app.last_upload_bytes > 0
        assert {u.table for u in app.last_updates} >= {"triangles", "bvh_nodes", "instances"}
        assert backend.uploads == [app.last_updates]

        app.tick(0.1)
        assert app.last_upload_bytes == 0
        assert app.last_updates == []
        assert len(backend.uploads) == 1  # a static tick does not call upload at all

        scene.set(box, Transform((2.0, 0.01, 0.0)))  # a first move: its tight TLAS leaf grows fat
        app.tick(0.1)
        assert app.packed is not None
        k = list(app.packed.instance_entities).index(box)
        assert app.last_updates[0] == TableUpdate("instances", range(k, k + 1))
        assert {u.table for u in app.last_updates} == {"instances", "tlas_nodes"}

        scene.set(box, Transform((2.0, 0.05, 0.0)))  # within its fat TLAS leaf (a tenth of its size)
        app.tick(0.1)
        assert app.last_updates == [TableUpdate("instances", range(k, k + 1))]
        assert app.last_upload_bytes == app.packed.tables["instances"].dtype.itemsize
        assert backend.uploads[-1] == app.last_updates
        assert backend.packed[-1] is app.packed

        app.tick(0.1)
        assert app.last_updates == [] and app.last_upload_bytes == 0
        assert app.upload_stats.uploads == 3

        scene.set(box, Transform((2.0, 1.0, 0.0)))  # out of it: the row and a few TLAS rows, no mesh data
        app.tick(0.1)
        assert app.last_updates[0] == TableUpdate("instances", range(k, k + 1))
        tree_rows = sum(len(u.rows) for u in app.last_updates[1:] if u.table == "tlas_nodes" and u.rows)
        assert {u.table for u in app.last_updates} == {"instances", "tlas_nodes"} and 1 <= tree_rows <= 5


def test_walking_camera_uploads_nothing_within_its_origin_cell(make_scene):
    scene = make_scene(position=(0.0, 0.0, 5.0))
    scene.add_mesh("box", "box")
    backend = RecordingBackend()
    with App(scene, backend, size=(8, 6), input_source=ScriptedInput([FORWARD] * 3)) as app:
        app.run(4, 0.1)
        assert app.last_updates == []
        assert len(backend.uploads) == 1
        assert np.allclose(backend.cameras[-1].position, (0.0, 0.0, 5.0 - 0.9), atol=1e-12)


def test_packer_follows_the_backend_configuration(make_scene):
    class Float64Backend(RecordingBackend):
        precisions = ("f64",)
        camera_relative = False
        bvh_width = 4
        bvh_compact = False

    scene = make_scene(position=(100.0, 0.0, 0.0))
    scene.add_mesh("box", "box")
    with App(scene, Float64Backend(), size=(4, 4)) as app:
        app.tick(0.0)
        assert app.packed is not None
        assert app.packed.precision == "f64"
        assert np.array_equal(app.packed.origin, (0.0, 0.0, 0.0))
        assert app.packed.tables["bvh_nodes"].dtype == layout.BVH4_NODE_DTYPE


def test_a_portal_whose_target_is_not_a_portal_is_a_clear_error(make_scene):
    scene = make_scene(position=(0.0, 0.0, 1.0))
    scene.add_mesh("wall", "box", position=(5.0, 0.0, 0.0))
    scene.add_portal("A", target="wall")
    with pytest.raises(SceneError, match=r"'A'.*portal\.target.*not a portal"):
        play(scene, [FORWARD], dt=0.1)


def test_far_from_the_origin_walking_and_teleporting_stay_exact(make_scene):
    far = np.array([1.0e6, 0.0, -2.0e6])

    def at(x: float, y: float, z: float) -> tuple[float, ...]:
        return tuple(far + np.array([x, y, z]))

    scene = make_scene(position=at(0.0, 0.0, 1.0))
    scene.add_aberration("fast", (0.0, 0.0, 1.0), position=at(0.0, 0.0, -12.0), scale=(4.0, 4.0, 2.0))
    scene.add_portal_pair("A", "B", a={"position": at(0.0, 0.0, 0.0)}, b={"position": at(0.0, 0.0, -10.0)})
    play(scene, [FORWARD] * 4, dt=0.1)  # tick 4 crosses A into B, 0.2 further: z = -10.2 relative
    assert np.allclose(position(scene) - far, (0.0, 0.0, -10.2), atol=1e-6)
    play(scene, [FORWARD] * 10, dt=0.1)  # 0.8 at speed 3, the box [-13, -11] at speed 6, then 0.4 s at 3
    assert np.allclose(position(scene) - far, (0.0, 0.0, -14.2), atol=1e-6)

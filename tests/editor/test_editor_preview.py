"""Preview lines, picking, gizmo maths, the editor view and the backend host: no window needed."""

from __future__ import annotations

import math

import numpy as np
import pytest

from components import Aberration, Portal, Transform
from editor.backend_host import STILL_SPP, BackendHost
from editor.gizmo import matrix_to_transform, transform_matrix
from editor.model import EditorModel
from editor.overlay import preview_lines, thick_lines
from editor.picking import pick
from editor.view import EditorView, perspective, view_matrix
from engine.maths import quat_from_euler_deg, trs_matrix
from engine.scene import Scene

ORANGE = (1.0, 0.5, 0.0)
BLUE = (0.0, 0.4, 1.0)


def scene_with_overlays() -> Scene:
    """A wall at z = -6, an orange box in front of it, a blue portal pair, a hidden box behind the wall."""
    scene = Scene("overlays")
    scene.add_mesh("wall", "box", position=(0.0, 0.0, -6.0), scale=(20.0, 20.0, 0.5))
    scene.add_aberration("box", (1.0, 0.0, 0.0), position=(-1.5, 0.0, -3.0), scale=1.5, color=ORANGE)
    scene.add_portal_pair("a", "b", a={"position": (1.5, 0.0, -3.0)}, b={"position": (30.0, 0.0, 0.0)}, color=BLUE)
    scene.add_aberration("hidden", (1.0, 0.0, 0.0), position=(0.0, 0.0, -9.0), scale=1.0, color=(0.0, 1.0, 0.0))
    scene.set_camera((0.0, 0.0, 2.0), rotation=(0.0, 0.0, 0.0, 1.0), fov_deg=60.0)
    return scene


@pytest.fixture
def scene():
    s = scene_with_overlays()
    yield s
    s.close()


def test_preview_lines_colours_and_debug_draw(scene):
    segments, colors = preview_lines(scene, show_camera=False)
    assert segments.shape == (12 + 4 + 4 + 12, 2, 3)
    assert sum(np.allclose(c, ORANGE) for c in colors) == 12
    assert sum(np.allclose(c, BLUE) for c in colors) == 8
    box = scene.entity("box")
    scene.set(box, Aberration((1.0, 0.0, 0.0), debug_draw=False, color=ORANGE))
    scene.set(scene.entity("a"), Portal(None, BLUE))  # inert: drawn dimmed
    segments, colors = preview_lines(scene, show_camera=False)
    assert not any(np.allclose(c, ORANGE) for c in colors)
    assert sum(np.allclose(c, np.array(BLUE) * 0.45) for c in colors) == 4
    segments, colors = preview_lines(scene, box, show_camera=False)  # selected: white, even with debug draw off
    assert sum(np.allclose(c, (1.0, 1.0, 1.0)) for c in colors) == 12


def test_lights_draw_a_star_or_an_arrow_along_minus_z_in_their_colour(scene):
    scene.add_light("lamp", "point", position=(0.0, 3.0, 0.0), color=(1.0, 1.0, 0.0))
    scene.add_light("sun", "sun", euler_deg=(-90.0, 0.0, 0.0), color=(0.0, 1.0, 1.0))
    segments, colors = preview_lines(scene, show_camera=False)
    star = segments[[np.allclose(c, (1.0, 1.0, 0.0)) for c in colors]]
    arrow = segments[[np.allclose(c, (0.0, 1.0, 1.0)) for c in colors]]
    assert len(star) == 7 and np.allclose(star.reshape(-1, 3).mean(axis=0), (0.0, 3.0, 0.0))
    assert len(arrow) == 9 and np.allclose(arrow[0], [[0, 0, 0], [0, -1, 0]])  # the shaft: down, as it shines
    _, colors = preview_lines(scene, scene.entity("sun"), show_camera=False)
    assert sum(np.allclose(c, (1.0, 1.0, 1.0)) for c in colors) == 9


def test_box_edges_are_the_unit_box_placed(scene):
    segments, _ = preview_lines(scene, show_camera=False)
    box = segments[:12].reshape(-1, 3)
    assert np.allclose(box.min(axis=0), (-2.25, -0.75, -3.75)) and np.allclose(box.max(axis=0), (-0.75, 0.75, -2.25))


def test_thick_lines_clip_at_the_near_plane():
    view = EditorView(np.zeros(3))
    vp = perspective(60.0, 1.0) @ view_matrix(view.camera())
    segments = np.array([[[0.0, 0.0, 5.0], [0.0, 1.0, -5.0]], [[0.0, 0.0, 1.0], [1.0, 0.0, 2.0]]])  # 2nd: behind
    vertices = thick_lines(segments, np.ones((2, 3)), vp, (100, 100))
    assert vertices.shape == (6, 7)
    assert np.all(vertices[:, 2] + vertices[:, 3] >= -1e-6) and np.all(vertices[:, 3] > 0)


def test_preview_renderer_depth_tests_lines(scene):
    moderngl = pytest.importorskip("moderngl")
    try:
        ctx = moderngl.create_standalone_context(backend="egl", require=330)
    except Exception as e:  # no EGL here: the GL part cannot run, the NumPy part is tested above
        pytest.skip(f"no headless OpenGL 3.3 context: {e}")
    from editor.preview import PreviewRenderer

    renderer = PreviewRenderer(ctx)
    try:
        view = EditorView.from_transform(scene.get(scene.camera_entity, Transform))
        for shaded in (False, True):
            texture = renderer.render(scene, view.camera(), (160, 120), shaded=shaded)
            image = np.frombuffer(texture.read(), np.uint8).reshape(120, 160, 4)[::-1].astype(int)
            rgb = image[..., :3]
            orange = np.all(np.abs(rgb - (255, 128, 0)) <= 2, axis=-1)
            blue = np.all(np.abs(rgb - (0, 102, 255)) <= 2, axis=-1)
            green = np.all(np.abs(rgb - (0, 255, 0)) <= 2, axis=-1)
            assert orange[:, :80].sum() > 50 and blue[:, 80:].sum() > 50
            assert green.sum() == 0  # behind the wall: depth-tested away
            if not shaded:
                assert image[60, 80, 3] == 0  # only lines are drawn over a traced frame
    finally:
        renderer.release()
        ctx.release()


def test_picking(scene):
    view = EditorView(np.array([0.0, 0.0, 2.0]))
    assert pick(scene, *view.ray(50, 50, 100, 100)) == scene.entity("wall")
    origin = np.array([0.0, 0.0, 2.0])
    to_box = np.array([-1.5, 0.0, -3.0]) - origin
    assert pick(scene, origin, to_box / np.linalg.norm(to_box)) == scene.entity("box")
    to_portal = np.array([1.5, 0.2, -3.0]) - origin
    assert pick(scene, origin, to_portal / np.linalg.norm(to_portal)) == scene.entity("a")
    scene.add_mesh("inside", "sphere", position=(-1.5, 0.0, -3.0), scale=0.5)  # a mesh in a box is picked through it
    assert pick(scene, origin, to_box / np.linalg.norm(to_box)) == scene.entity("inside")
    assert pick(scene, origin, np.array([0.0, 0.0, 1.0])) is None


def test_gizmo_changes_only_what_the_operation_edits():
    old = Transform((1.0, 2.0, 3.0), tuple(quat_from_euler_deg((10.0, 20.0, 30.0))), (1.0, -2.0, 3.0))
    m = transform_matrix(old).astype(np.float32).astype(np.float64)  # what ImGuizmo hands back
    m[0, 3] += 0.5
    moved = matrix_to_transform(m, old, "translate")
    assert moved.position == (1.5, 2.0, 3.0) and moved.rotation == old.rotation and moved.scale == old.scale
    turn = trs_matrix((0, 0, 0), quat_from_euler_deg((0.0, 45.0, 0.0)), (1, 1, 1))
    rotated = matrix_to_transform(turn @ transform_matrix(old), old, "rotate")
    assert rotated.position == old.position and rotated.scale == old.scale
    assert not np.allclose(rotated.rotation, old.rotation)
    grown = transform_matrix(old) @ np.diag([2.0, 1.0, 1.0, 1.0])
    scaled = matrix_to_transform(grown, old, "scale")
    assert scaled.scale == pytest.approx((2.0, -2.0, 3.0)) and scaled.scale[1:] == old.scale[1:]
    assert matrix_to_transform(transform_matrix(old), old, "rotate") == old


def test_editor_view():
    pose = Transform((1.0, 2.0, 3.0), tuple(quat_from_euler_deg((-20.0, 35.0, 0.0))))
    view = EditorView.from_transform(pose)
    assert np.allclose(view.rotation, view.camera().rotation)
    assert np.allclose(view.transform().rotation, pose.rotation, atol=1e-9)
    origin, direction = view.ray(50, 50, 100, 100)
    assert np.allclose(origin, pose.position) and np.allclose(direction, -view.rotation[:, 2])
    view.look(10.0, 5.0)
    assert math.isclose(view.yaw, 35.0 - 10.0) and math.isclose(view.pitch, -15.0)
    start = view.position.copy()
    view.fly((0.0, 0.0, -1.0), 1.0)
    assert np.allclose(view.position - start, -view.rotation[:, 2] * view.speed)


def test_backend_host_renders_only_on_change(backend_factory):
    backend_factory("reference")  # skips (with the reason) where it cannot run
    model = EditorModel()
    host = BackendHost(None, model.error)
    try:
        assert host.select("reference") and host.aovs == ("color",)
        view = EditorView.from_transform(model.scene.get(model.scene.camera_entity, Transform)).camera()
        assert host.render_view(model.scene, view, (16, 12))
        assert host.frames == 1 and host.last_frame.color.shape == (12, 16, 4) and host.mrays[-1] > 0
        host.render_view(model.scene, view, (16, 12))
        assert host.frames == 1 and host.samples == 2  # nothing changed: no new frame, one more sample
        for _ in range(2 * STILL_SPP):
            host.render_view(model.scene, view, (16, 12))
        assert host.frames == 1 and host.samples == STILL_SPP  # then the still view rests
        model.add_primitive("box")
        host.render_view(model.scene, view, (16, 12))
        assert host.frames == 2 and host.samples == 1  # a change starts again from one sample
        assert not host.select("no-such-backend") and host.backend is None and "no-such-backend" in host.error
        assert not host.render_view(model.scene, view, (16, 12))
    finally:
        host.close()
        model.scene.close()

"""Lights and shadows through deformed space (docs/semantics.md, "Lights and shadows"): closed-form shadow
edges in the reference, and every backend's frames against the reference's.

The cases: a sun straight down casting a box's shadow; the same floor seen through a portal; a sun that
lights a room with a ceiling only through a portal in it; a 45-degree sun whose shadow a metric box
stretches. Each edge is measured on both sides of where the geometry puts it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scenes import EVERY, FAST, assert_agrees, render_aovs, upload_to_reference

from backends.base import AOVS
from components import Light
from engine.camera_view import scene_camera
from engine.errors import SceneError
from engine.scene import Scene

#: A sun shining straight down: its -Z turned onto -Y.
DOWN = (-90.0, 0.0, 0.0)
UP = np.array([0.0, 1.0, 0.0])
#: Points are probed this far on either side of a closed-form shadow edge.
EPS = 1e-3
#: The size of the parity frames.
SIZE = (64, 48)


def floor_and_box(scene: Scene, x: float = 0.0) -> None:
    """A floor (top at y = 0) and a unit box floating over it, bottom at y = 1, centred on (x, 1.5, 0)."""
    scene.add_mesh("floor", "box", position=(x, -0.5, 0.0), scale=(40.0, 1.0, 40.0), color=(0.9, 0.9, 0.9))
    scene.add_mesh("box", "box", position=(x, 1.5, 0.0), color=(0.8, 0.3, 0.2))


def box_shadow(x: float = 0.0, height: float = 6.0, back: float = 4.0) -> Scene:
    scene = Scene("box shadow")
    floor_and_box(scene, x)
    scene.add_light("sun", "sun", euler_deg=DOWN)
    scene.set_camera((x, height, back), look_at=(x, 0.0, 0.0))
    return scene


def box_shadow_through_portal() -> Scene:
    """The floor and box at x = 100, seen from above x = 0 through a horizontal portal pair."""
    scene = Scene("box shadow through a portal")
    floor_and_box(scene, 100.0)
    scene.add_light("sun", "sun", euler_deg=DOWN)
    flat = dict(euler_deg=(-90.0, 0.0, 0.0), scale=6.0)
    scene.add_portal_pair(
        "door", "far", a=dict(position=(0.0, 4.0, 0.0), **flat), b=dict(position=(100.0, 4.0, 0.0), **flat)
    )
    scene.set_camera((0.0, 8.0, 3.0), look_at=(0.0, 0.0, 0.0))
    return scene


def room_lit_through_portal(skylight: float = 2.99, plate: bool = False) -> Scene:
    """A floor under a ceiling (the sky blocked, its bottom at y = 3) at x = 100, a 2x2 portal at height
    skylight (just under the ceiling) whose pair lies in the open at x = 0: the sun reaches the floor only
    through it. plate: a small plate at y = 2 under the skylight, after the ceiling in instance rows."""
    scene = Scene("room lit through a portal")
    scene.add_mesh("floor", "box", position=(100.0, -0.5, 0.0), scale=(40.0, 1.0, 40.0))
    scene.add_mesh("ceiling", "box", position=(100.0, 3.5, 0.0), scale=(40.0, 1.0, 40.0))
    flat = dict(euler_deg=(-90.0, 0.0, 0.0))
    scene.add_portal_pair(
        "sky", "skylight", a=dict(position=(0.0, 3.0, 0.0), **flat), b=dict(position=(100.0, skylight, 0.0), **flat)
    )
    if plate:
        scene.add_mesh("plate", "box", position=(100.0, 2.0, 0.0), scale=(1.2, 0.05, 1.2))
    scene.add_light("sun", "sun", euler_deg=DOWN)
    scene.set_camera((96.0, 2.0, 4.0), look_at=(100.0, 0.0, 0.0))
    return scene


def stretched_shadow(box: bool = True) -> Scene:
    """A plate (x in [-0.5, 0.5], y in [1, 1.1]) under a 45-degree sun from +x, inside a metric box that
    doubles the world distance rays travel along x per unit of perceived distance (D = (1, 0, 0))."""
    scene = Scene("stretched shadow")
    scene.add_mesh("floor", "box", position=(0.0, -0.5, 0.0), scale=(40.0, 1.0, 40.0))
    scene.add_mesh("plate", "box", position=(0.0, 1.05, 0.0), scale=(1.0, 0.1, 4.0))
    if box:
        scene.add_aberration("stretch", (1.0, 0.0, 0.0), position=(0.0, 1.0, 0.0), scale=(30.0, 3.0, 30.0))
    scene.add_light("sun", "sun", look_at=(-1.0, -1.0, 0.0))
    scene.set_camera((-2.0, 7.0, 0.01), look_at=(-2.0, 0.0, 0.0))
    return scene


def lit_at(scene: Scene, xs, z: float = 0.0, towards=UP, x0: float = 0.0) -> list[bool]:
    """Whether the floor points (x0 + x, 0, z) are lit by a sun towards ``towards`` (the reference)."""
    ref = upload_to_reference(scene)
    try:
        points = np.array([[x0 + x, 0.0, z] for x in xs])
        return [bool(v) for v in ref.lit(points, UP, np.asarray(towards, np.float64))]
    finally:
        ref.release()


def test_a_box_shadows_the_floor_straight_below_it(scenes):
    scene = box_shadow()
    scenes.append(scene)
    assert lit_at(scene, [0.0, 0.5 - EPS, 0.5 + EPS, -0.5 + EPS, -0.5 - EPS]) == [False, False, True, False, True]
    assert lit_at(scene, [0.0, 0.0], z=0.5 + EPS) == [True, True]


def test_the_shadow_seen_through_a_portal_is_the_shadow_seen_directly(scenes, backend_factory):
    through, direct = box_shadow_through_portal(), box_shadow(100.0, 8.0, 3.0)
    scenes += [through, direct]
    assert lit_at(through, [0.0, 0.5 - EPS, 0.5 + EPS], x0=100.0) == [False, False, True]
    ref = backend_factory("reference")
    seen = render_aovs(ref, through, *SIZE).color.astype(int)
    straight = render_aovs(ref, direct, *SIZE).color.astype(int)
    off = np.abs(seen - straight).max(axis=2) > 2
    assert off.mean() <= 0.005  # the same picture: the portal shows the far floor and its shadow


def test_sunlight_pours_through_a_portal_into_a_room_with_a_ceiling(scenes):
    scene = room_lit_through_portal()
    scenes.append(scene)
    inside = lit_at(scene, [0.0, 1.0 - EPS, -1.0 + EPS], x0=100.0)
    outside = lit_at(scene, [1.0 + EPS, -1.0 - EPS, 3.0], x0=100.0)
    assert inside == [True, True, True] and outside == [False, False, False]
    assert lit_at(scene, [0.0], z=1.0 + EPS, x0=100.0) == [False]


def test_a_metric_box_stretches_the_shadow_along_its_axis(scenes):
    # Towards the sun w = (1, 1, 0)/sqrt(2); inside the box the world direction is along (2, 1, 0), so the
    # plate at heights 1..1.1 shades the floor where x + 2y meets [-0.5, 0.5]: x in [-2.7, -1.5].
    plain, stretched = stretched_shadow(box=False), stretched_shadow()
    scenes += [plain, stretched]
    sun = np.array([1.0, 1.0, 0.0]) / math.sqrt(2.0)
    assert lit_at(plain, [-0.5 + EPS, -0.5 - EPS, -1.6 + EPS, -1.6 - EPS], towards=sun) == [True, False, False, True]
    edges = [-1.5 + EPS, -1.5 - EPS, -2.7 + EPS, -2.7 - EPS, -1.0]
    assert lit_at(stretched, edges, towards=sun) == [True, False, False, True, True]


def point_lamp() -> Scene:
    """A point light at (0, 4, 0) over the box, a ceiling plate above it: behind the light, it casts nothing."""
    scene = Scene("point lamp")
    floor_and_box(scene)
    scene.add_mesh("ceiling", "box", position=(0.0, 6.0, 0.0), scale=(40.0, 0.2, 40.0))
    scene.add_light("lamp", "point", position=(0.0, 4.0, 0.0), intensity=16.0)
    scene.set_camera((0.0, 3.0, 6.0), look_at=(0.0, 0.0, 0.0))
    return scene


def test_a_point_light_is_blocked_only_before_its_distance(scenes):
    # From the floor point (x, 0, 0) the ray to the light at height 4 is at x (1 - y/4) at height y: it meets
    # the box (y in [1, 2], |x| <= 0.5) where its top edge, |x| / 2 <= 0.5, says: |x| <= 1. The ceiling at
    # y = 5.9 lies past the light: it never shades.
    scene = point_lamp()
    scenes.append(scene)
    ref = upload_to_reference(scene)
    try:
        xs = [0.0, 1.0 - EPS, 1.0 + EPS, 3.0]
        points = np.array([[x, 0.0, 0.0] for x in xs])
        d = np.array([0.0, 4.0, 0.0]) - points
        distance = np.linalg.norm(d, axis=1)
        lit = ref.lit(points, UP, d / distance[:, None], distance)
        assert [bool(v) for v in lit] == [False, False, True, True]
        assert not ref.lit(points[3:], UP, d[3:] / distance[3:, None]).any()  # with no reach the ceiling shades
    finally:
        ref.release()


CASES = {
    "lamp": point_lamp,
    "box": box_shadow,
    "portal": box_shadow_through_portal,
    "room": room_lit_through_portal,
    "stretched": stretched_shadow,
}


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize(("backend", "precision"), FAST)
def test_every_backend_draws_the_reference_shadows(case, backend, precision, backend_factory, scenes):
    scene = CASES[case]()
    scenes.append(scene)
    ref = render_aovs(backend_factory("reference"), scene, *SIZE, AOVS)
    fast = render_aovs(backend_factory(backend, precision), scene, *SIZE, AOVS)
    assert_agrees(fast, ref, precision, color_off_max=0.01)
    shade = ref.color[..., :3].astype(int).sum(axis=2)
    floor = ref.instance == scene.entity("floor")
    assert shade[floor].min() < 0.6 * shade[floor].max()  # a shadow is in view


@pytest.mark.parametrize(("backend", "precision"), [p for p in FAST if p.id.endswith("f32")])
def test_a_frame_without_colour_traces_no_shadow_rays_and_keeps_the_hits(backend, precision, backend_factory, scenes):
    """Without the colour nothing is shaded (SHADE 0), so the frame's variant has no shadows either."""
    scene = box_shadow_through_portal()
    scenes.append(scene)
    fast = backend_factory(backend, precision)
    full = render_aovs(fast, scene, *SIZE, AOVS)
    hits = render_aovs(fast, scene, *SIZE, ("depth", "instance", "events"))
    assert fast._features.shadows and not fast._frame_features(scene_camera(scene), *SIZE, shade=False).shadows
    for name in ("depth", "instance", "events"):
        np.testing.assert_array_equal(getattr(hits, name), getattr(full, name))


@pytest.mark.parametrize(("backend", "precision"), [p for p in FAST if p.id.endswith("f32")])
def test_a_shadow_ray_stops_at_a_mesh_only_where_the_nearest_hit_would_end_it(
    backend, precision, backend_factory, scenes
):
    # With the skylight 4e-5 inside the ceiling, a shadow ray under it meets the ceiling's bottom face, but the
    # portal lies within float32's tie window of it (about 2e-4 here; float64's is 1e-8) and takes the leg
    # (docs/semantics.md section 14): the floor stays lit. Under the plate the plate's hit comes first and
    # ends the ray, though the instance loop (no top-level tree: rows in order) finds the ceiling's first.
    tied, clear = room_lit_through_portal(3.00004, plate=True), room_lit_through_portal(plate=True)
    scenes += [tied, clear]
    fast = backend_factory(backend, precision)
    fast.extra_defines = {"USE_TLAS": 0}
    try:
        frames = [render_aovs(fast, scene, *SIZE) for scene in (tied, clear)]
    finally:
        fast.extra_defines = {}
    floor = frames[1].instance == clear.entity("floor")
    shade = [frame.color[..., :3].astype(int).sum(axis=2)[floor] for frame in frames]
    assert np.mean(np.abs(shade[0] - shade[1]) > 6) <= 0.002  # stopping at the ceiling: 1 % (the plate's shadow)
    lit = shade[1] > 0.8 * shade[1].max()
    ref = render_aovs(backend_factory("reference"), clear, *SIZE).color[..., :3].astype(int).sum(axis=2)[floor]
    assert 0.01 < lit.mean() < 0.5 and np.mean(lit != (ref > 0.8 * ref.max())) <= 0.005  # the plate's shadow too


def test_glsl_storage_buffers_draw_the_shadows_its_images_draw(scenes):
    from conftest import require_backend

    from backends.glsl.backend import GlslBackend

    require_backend("glsl")
    scene = box_shadow_through_portal()
    scenes.append(scene)
    frames = []
    for tables in ("image", "ssbo"):
        with GlslBackend(tables=tables) as backend:  # every AOV: the storage blocks still fit
            frames.append(render_aovs(backend, scene, *SIZE, AOVS))
    assert np.array_equal(frames[0].color, frames[1].color) and np.array_equal(frames[0].depth, frames[1].depth)


@pytest.mark.parametrize(("backend", "precision"), EVERY)
def test_a_scene_without_lights_renders_as_the_implicit_sun(backend, precision, backend_factory, scenes):
    plain = box_shadow()
    scenes.append(plain)
    sun = plain.entity("sun")
    light = plain.get(sun, Light)
    plain.delete(sun)
    settings_sun = Scene("settings sun")
    scenes.append(settings_sun)
    implicit = render_aovs(backend_factory(backend, precision), plain, *SIZE).color
    floor_and_box(settings_sun)
    direction = plain.settings.light_dir
    settings_sun.add_light("sun", "sun", look_at=tuple(-c for c in direction), shadows=False)
    settings_sun.set_camera((0.0, 6.0, 4.0), look_at=(0.0, 0.0, 0.0))
    explicit = render_aovs(backend_factory(backend, precision), settings_sun, *SIZE).color
    assert light.shadows
    assert np.abs(implicit.astype(int) - explicit.astype(int)).max() <= 1


def test_more_lights_than_the_kernels_hold_is_an_error_naming_the_entity(scenes):
    scene = box_shadow()
    scenes.append(scene)
    for k in range(8):
        scene.add_light(f"lamp{k}", "point", position=(k, 3.0, 0.0), intensity=9.0)
    with pytest.raises(SceneError, match=r"lamp7.*light.*at most 8"):
        scene.validate()

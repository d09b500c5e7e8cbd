"""Every registered demo builds, validates, round-trips through a scene file and renders headless."""

from __future__ import annotations

import numpy as np
import pytest

from aberrant.levels import open_level
from demos import build_demo, demo_module, demo_modules, demo_names, describe
from engine.errors import AberrantError
from engine.scene import Scene
from engine.scene_file import load_scene, save_scene

SIZE = (64, 48)


DEMOS = demo_modules()


@pytest.fixture(params=sorted(DEMOS))
def demo(request) -> str:
    return request.param


def test_registry_lists_every_demo_module():
    assert demo_names() == list(DEMOS)
    assert "starter" in DEMOS
    for name, module in DEMOS.items():
        assert module == f"demos.{name}"


def test_demo_module_has_a_description_and_build(demo):
    module = demo_module(demo)
    assert callable(module.build)
    description = describe(demo)
    assert description and "\n" not in description
    assert module.__doc__.strip().splitlines()[0].strip() == description


def test_unknown_demo_lists_the_demos():
    with pytest.raises(AberrantError) as e:
        build_demo("no_such_demo")
    assert "no_such_demo" in str(e.value)
    for name in DEMOS:
        assert name in str(e.value)
    with pytest.raises(AberrantError):
        describe("no_such_demo")


def test_demo_builds_and_validates(demo):
    scene = build_demo(demo)
    try:
        assert isinstance(scene, Scene)
        scene.validate()
        assert scene.camera_entity is not None
        assert len(scene.entities()) >= 4
    finally:
        scene.close()


def test_each_build_is_a_fresh_scene(demo):
    a, b = build_demo(demo), build_demo(demo)
    try:
        assert a.world != b.world
        assert [a.name_of(e) for e in a.entities()] == [b.name_of(e) for e in b.entities()]
    finally:
        a.close()
        b.close()


def test_demo_round_trips_through_a_scene_file(demo, tmp_path):
    scene = build_demo(demo)
    save_scene(scene, tmp_path / "a.json")
    loaded = load_scene(tmp_path / "a.json")
    save_scene(loaded, tmp_path / "b.json")
    assert (tmp_path / "a.json").read_bytes() == (tmp_path / "b.json").read_bytes()


def test_demo_renders_headless_with_the_reference_backend(demo, backend_factory):
    from systems.app import render_once

    backend = backend_factory("reference")
    scene = build_demo(demo)
    try:
        frame = render_once(scene, backend, SIZE)
    finally:
        scene.close()
    assert frame.color.shape == (SIZE[1], SIZE[0], 4)
    assert not np.isnan(frame.depth).any()
    assert not np.isnan(frame.perceived).any()
    visible = set(np.unique(frame.instance)) - {-1}
    assert len(visible) >= 4, f"only instances {sorted(visible)} are visible"
    hit = frame.instance >= 0
    assert hit.mean() > 0.5  # the camera looks at the scene, not at the background
    assert np.all(np.isfinite(frame.depth[hit]))
    assert len(np.unique(frame.color.reshape(-1, 4), axis=0)) > 20


# --- the showcase levels ---------------------------------------------------------

#: The thesis's four levels and the ones beyond it, after the starter.
SHOWCASE = (
    "aberration_room",
    "aberration_tunnels",
    "geometry_room",
    "house",
    "endless_corridor",
    "bigger_inside",
    "nested_aberrations",
    "portal_in_aberration",
    "hotel",
)
#: What must be seen through portals at the demo's camera: (at least this many events, mesh name prefixes).
THROUGH_PORTALS: dict[str, list[tuple[int, tuple[str, ...]]]] = {
    "geometry_room": [(1, ("hall_",))],
    "house": [(1, ("hall_",)), (2, ("gallery_",))],
    "endless_corridor": [(2, ("globe", "arch_", "floor", "runner", "west_", "east_"))],
    "portal_in_aberration": [(1, ("hall_",)), (2, ("garden_", "fountain_", "tree_", "hedge_"))],
    "hotel": [(1, ("room",))],
}
#: Where the flythrough may end up off its last stop (the spline rounds corners; ticks are chords of it).
WALK_TOLERANCE = 0.35


@pytest.fixture(scope="module")
def frames(backend_factory) -> dict[str, tuple[object, dict[int, str]]]:
    """Each demo rendered once at its own camera (frame, entity -> name), shared by the checks below."""
    from systems.app import render_once

    backend = backend_factory("reference")
    out = {}
    for name in DEMOS:
        scene = build_demo(name)
        try:
            out[name] = (render_once(scene, backend, SIZE), {e: scene.name_of(e) for e in scene.entities()})
        finally:
            scene.close()
    return out


def test_every_showcase_level_is_registered_after_the_starter():
    assert demo_names()[0] == "starter"
    assert set(SHOWCASE) <= set(DEMOS)
    for name in SHOWCASE:
        assert len(describe(name)) <= 120, "the description is one short line"


def test_demos_with_deformed_space_show_events(demo, frames):
    from components import Aberration, Portal

    scene = build_demo(demo)
    try:
        deformed = bool(scene.query(Aberration)) or bool(scene.query(Portal))
    finally:
        scene.close()
    frame, _ = frames[demo]
    assert np.all(np.isfinite(frame.perceived[frame.instance >= 0]))
    if deformed:
        assert (frame.events > 0).mean() > 0.02, "the camera should look through the level's aberrations or portals"


@pytest.mark.parametrize("demo_name", sorted(THROUGH_PORTALS))
def test_portal_demos_show_teleported_geometry(demo_name, frames):
    frame, names = frames[demo_name]
    for min_events, prefixes in THROUGH_PORTALS[demo_name]:
        seen = {names[int(i)] for i in np.unique(frame.instance[frame.events >= min_events]) if i >= 0}
        assert any(n.startswith(prefixes) for n in seen), (
            f"nothing named {prefixes} is seen through >= {min_events} portal(s); seen: {sorted(seen)}"
        )


def test_deformations_change_the_picture(demo, frames, backend_factory):
    """Without its aberrations and portals a level looks clearly different: they are where the camera looks."""
    from components import Aberration, Portal
    from systems.app import render_once

    scene = build_demo(demo)
    try:
        removed = [e for e, _ in scene.query(Aberration)] + [e for e, _ in scene.query(Portal)]
        if not removed:
            pytest.skip("plain Euclidean level")
        for entity in removed:
            scene.delete(entity)
        flat = render_once(scene, backend_factory("reference"), SIZE)
    finally:
        scene.close()
    frame, _ = frames[demo]
    changed = np.abs(flat.color[..., :3].astype(int) - frame.color[..., :3].astype(int)).max(axis=-1) > 24
    assert changed.mean() > 0.04


def _walk(demo: str, dt: float, ticks: int | None = None) -> tuple[object, list[str], np.ndarray]:
    """Walk the demo's camera path through the movement and teleport systems (no tracer); crossings and the end."""
    from aberrant.flythrough import path_for
    from components import Transform
    from systems.app import App

    level = open_level(demo)
    scene = level.scene
    try:
        path = path_for(level)
        path.place_camera(scene)
        crossings: list[str] = []
        with App(scene, None, input_source=path.inputs(scene)) as app:
            n = ticks if ticks is not None else int(np.ceil(path.duration / dt)) + 2
            for _ in range(n):
                app.tick(dt)
                crossings += [scene.name_of(a) for a, _ in app.motion.crossings]
                app.motion.crossings = []
        end = np.array(scene.get(scene.camera_entity, Transform).position)
    finally:
        scene.close()
    return path, crossings, end


def test_every_camera_path_is_valid_and_runs(demo):
    from systems.camera_path import CameraPath

    module = demo_module(demo)
    if not hasattr(module, "camera_path"):
        pytest.skip("no camera path: the flythrough uses the default walk")
    path = module.camera_path()
    assert isinstance(path, CameraPath)
    assert len(path.keyframes) >= 2 and 2.0 < path.duration < 60.0
    _, _, end = _walk(demo, 0.1, ticks=5)
    assert np.all(np.isfinite(end))


@pytest.mark.parametrize("demo_name", SHOWCASE)
def test_flythrough_walks_through_its_portals_and_ends_where_designed(demo_name):
    """The route's premise: the systems replay the path in perceived units and end at the last stop."""
    module = demo_module(demo_name)
    stops = module.stops()
    _, crossings, end = _walk(demo_name, 0.05)
    assert crossings == [s.via for s in stops if s.via is not None]
    assert np.linalg.norm(end - np.array(stops[-1].position)) < WALK_TOLERANCE


def test_a_few_flythrough_ticks_render(backend_factory):
    """Three ticks of a path through portals and an aberration, rendered by the reference backend."""
    from aberrant.flythrough import path_for
    from systems.app import App

    level = open_level("portal_in_aberration")
    scene = level.scene
    try:
        path = path_for(level)
        path.place_camera(scene)
        with App(scene, backend_factory("reference"), size=SIZE, input_source=path.inputs(scene)) as app:
            for _ in range(3):
                frame = app.tick(path.duration / 3.0)
                assert frame is not None and not np.isnan(frame.depth).any()
    finally:
        scene.close()

"""Every registered demo builds, validates, round-trips through a scene file and renders headless."""

from __future__ import annotations

import importlib

import numpy as np
import pytest

from demos import DEMOS, build_demo, demo_names, describe
from engine.errors import AberrantError
from engine.scene import Scene
from engine.scene_file import load_scene, save_scene

SIZE = (64, 48)


@pytest.fixture(params=sorted(DEMOS))
def demo(request) -> str:
    return request.param


def test_registry_lists_every_demo_module():
    assert demo_names() == list(DEMOS)
    assert "starter" in DEMOS
    for name, module in DEMOS.items():
        assert module == f"demos.{name}"


def test_demo_module_has_a_description_and_build(demo):
    module = importlib.import_module(DEMOS[demo])
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
    from engine.app import render_once

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

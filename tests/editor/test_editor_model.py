"""The editor's model, pure Python: adding, editing, undo/redo, portal targets, files, the discard prompt."""

from __future__ import annotations

from pathlib import Path

import pytest

from components import Aberration, Camera, Light, Mesh, Portal, Transform
from demos import build_demo
from editor.model import EditorModel
from engine.assets import PRIMITIVES
from engine.scene_file import load_scene, save_scene, scene_to_json

KNOT = Path(__file__).resolve().parents[2] / "demos" / "assets" / "knot.obj"


@pytest.fixture
def model():
    m = EditorModel(build_demo("starter"), demo="starter")
    yield m
    m.scene.close()


def text(m: EditorModel) -> str:
    return scene_to_json(m.scene, Path.cwd())


def names(m: EditorModel) -> list[str]:
    return [m.scene.name_of(e) for e in m.scene.entities()]


# --- adding ----------------------------------------------------------------------------------


@pytest.mark.parametrize("primitive", PRIMITIVES)
def test_add_primitive_is_one_undo_step(model, primitive):
    before = text(model)
    entity = model.add_primitive(primitive, (1.0, 2.0, 3.0))
    assert entity is not None and model.selected == entity
    assert model.scene.get(entity, Mesh).asset == primitive
    assert model.scene.get(entity, Transform).position == (1.0, 2.0, 3.0)
    assert model.dirty and model.title.startswith("*")
    model.undo()
    assert text(model) == before and not model.dirty and model.selected is None
    model.redo()
    assert model.scene.get(model.scene.entity(primitive), Mesh).asset == primitive


def test_add_each_kind(model):
    start = len(model.scene.entities())
    aberration = model.add_aberration((0.0, 1.0, 0.0))
    a = model.add_portal_pair((0.0, 1.0, 2.0))
    mesh = model.add_mesh_file(KNOT, (2.0, 0.0, 0.0))
    assert model.scene.get(aberration, Aberration).deformation == (1.0, 0.0, 0.0)
    pa = model.scene.get(a, Portal)
    b = model.scene.entity(pa.target)
    assert model.scene.get(b, Portal).target == model.scene.name_of(a)
    assert model.scene.get(mesh, Mesh).asset == "knot"  # the demo already registered this file
    assert len(model.scene.entities()) == start + 4
    model.scene.validate()
    for _ in range(3):
        model.undo()
    assert len(model.scene.entities()) == start


def test_add_lights_a_sun_and_a_point_light_each_one_undo_step(model):
    before = text(model)
    sun = model.add_light("sun", (0.0, 1.0, 0.0))
    lamp = model.add_light("point", (2.0, 0.0, 0.0))
    assert model.scene.get(sun, Light).kind == "sun" and model.scene.get(sun, Light).shadows
    assert model.scene.get(lamp, Light).kind == "point"
    assert model.scene.get(lamp, Transform).position == (2.0, 3.0, 0.0)
    assert [model.scene.name_of(e) for e in (sun, lamp)] == ["sun", "lamp"]
    assert model.edit(lamp, Light, range=8.0) is None and model.scene.get(lamp, Light).range == 8.0
    assert "range" in (model.edit(sun, Light, range=8.0) or "")  # a sun has none: refused, named
    model.scene.validate()
    for _ in range(3):
        model.undo()
    assert text(model) == before


def test_import_registers_a_new_asset_and_undo_removes_it(tmp_path):
    m = EditorModel()
    mesh_file = tmp_path / "my knot.obj"
    mesh_file.write_bytes(KNOT.read_bytes())
    before = text(m)
    entity = m.add_mesh_file(mesh_file)
    asset = m.scene.get(entity, Mesh).asset
    assert asset == "my_knot" and m.scene.assets[asset].path == str(mesh_file.resolve())
    m.undo()
    assert asset not in m.scene.assets and text(m) == before


def test_import_refuses_unreadable_files(model, tmp_path):
    bad = tmp_path / "broken.obj"
    bad.write_text("this is not a mesh\n")
    assert model.add_mesh_file(bad) is None
    assert model.add_mesh_file(tmp_path / "missing.obj") is None
    assert model.add_mesh_file(tmp_path / "scene.json") is None
    assert not model.dirty and model.last_message.level == "error"


def test_camera_from_view_creates_or_moves(model):
    camera = model.scene.camera_entity
    pose = Transform((1.0, 2.0, 3.0))
    assert model.add_camera(pose) == camera
    assert model.scene.get(camera, Transform) == pose
    model.undo()
    model.delete(camera)
    assert model.scene.camera_entity is None
    created = model.add_camera(pose)
    assert model.scene.camera_entity == created and model.scene.has(created, Camera)
    model.undo()
    model.undo()  # undo the delete: the camera comes back as the scene's camera
    assert model.scene.camera_entity is not None
    assert model.scene.name_of(model.scene.camera_entity) == "camera"


# --- editing, undo and redo ---------------------------------------------------------------------


def test_edit_field_undo_redo(model):
    crate = model.scene.entity("crate")
    before = text(model)
    assert model.edit(crate, Mesh, color=(0.1, 0.2, 0.3)) is None
    edited = text(model)
    assert model.scene.get(crate, Mesh).color == (0.1, 0.2, 0.3)
    model.undo()
    assert text(model) == before
    model.redo()
    assert text(model) == edited


def test_invalid_values_are_refused_with_the_field_named(model):
    entity = model.add_aberration()
    steps = len(model.undo_stack)
    error = model.edit(entity, Aberration, deformation=(-1.5, 0.0, 0.0))
    assert error is not None and "deformation[0]" in error
    assert model.edit(entity, Transform, scale=(0.0, 1.0, 1.0)) is not None
    assert model.scene.get(entity, Aberration).deformation == (1.0, 0.0, 0.0)
    assert len(model.undo_stack) == steps


def test_continuous_edits_merge_into_one_step(model):
    crate = model.scene.entity("crate")
    original = model.scene.get(crate, Transform)
    for x in (1.0, 1.5, 2.0):
        model.set_component(crate, Transform((x, 0.0, 0.0)), merge_key=("gizmo", "crate"))
    model.close_merge()
    model.set_component(crate, Transform((9.0, 0.0, 0.0)), merge_key=("gizmo", "crate"))
    assert model.scene.get(crate, Transform).position == (9.0, 0.0, 0.0)
    model.undo()
    assert model.scene.get(crate, Transform).position == (2.0, 0.0, 0.0)
    model.undo()
    assert model.scene.get(crate, Transform) == original


def test_delete_restores_order_and_portal_links_exactly(model):
    model.add_portal_pair((0.0, 1.0, 0.0))
    model.add_primitive("box")
    model.mark_saved()
    before = text(model)
    a = model.scene.entity("portal_a")
    model.delete(a)
    assert model.scene.get(model.scene.entity("portal_b"), Portal).target is None  # no dangling link
    model.scene.validate()
    model.undo()
    assert text(model) == before and names(model)[-3:] == ["portal_a", "portal_b", "box"]
    assert not model.dirty
    model.redo()
    assert "portal_a" not in names(model)


def test_rename_follows_portals_and_undoes_exactly(model):
    model.add_portal_pair()
    before = text(model)
    a = model.scene.entity("portal_a")
    assert model.rename(a, "door") is None
    assert model.scene.get(model.scene.entity("portal_b"), Portal).target == "door"
    assert model.selected_name == "door"
    assert model.rename(a, "crate") is not None  # taken
    model.undo()
    assert text(model) == before


def test_duplicate(model):
    crate = model.scene.entity("crate")
    copy = model.duplicate(crate)
    assert model.scene.name_of(copy) == "crate_2"
    assert model.scene.get(copy, Mesh) == model.scene.get(crate, Mesh)
    assert model.scene.name_of(model.duplicate(copy)) == "crate_3"
    assert model.duplicate(model.scene.camera_entity) is None


def test_portal_targets_are_portals_only(model):
    model.add_portal_pair()
    model.add_portal_pair()
    a = model.scene.entity("portal_a")
    targets = model.portal_targets(a)
    assert sorted(targets) == ["portal_a_2", "portal_b", "portal_b_2"]
    assert model.set_portal_target(a, "portal_a_2") is None
    assert model.scene.get(a, Portal).target == "portal_a_2"
    assert model.set_portal_target(a, "crate") is not None  # a mesh is not a portal
    assert model.set_portal_target(a, "portal_a") is not None  # nor is the portal itself
    assert model.set_portal_target(a, None) is None
    assert model.scene.get(a, Portal).target is None
    model.undo()
    assert model.scene.get(a, Portal).target == "portal_a_2"


def test_settings_and_scene_name(model):
    before = text(model)
    assert model.set_settings(ambient=0.5) is None
    assert model.set_settings(ambient=2.0) is not None
    model.set_scene_name("gallery")
    assert model.scene.name == "gallery" and model.scene.settings.ambient == 0.5
    model.undo()
    model.undo()
    assert text(model) == before


# --- files --------------------------------------------------------------------------------------------


def test_save_and_reload(model, tmp_path):
    model.add_aberration((0.0, 1.0, 0.0))
    model.add_portal_pair((1.0, 1.0, 1.0))
    assert model.save() is False and model.save_as_requested  # a demo has no file yet
    path = tmp_path / "level"
    assert model.save_as(path)
    assert model.path == tmp_path / "level.json" and not model.dirty
    assert not model.title.startswith("*") and "level.json" in model.title
    saved = model.path.read_text()
    reloaded = load_scene(model.path)
    try:
        assert scene_to_json(reloaded, tmp_path) == saved
    finally:
        reloaded.close()
    other = EditorModel()
    assert other.open_path(model.path)
    assert scene_to_json(other.scene, tmp_path) == saved and not other.dirty
    other.scene.close()


def test_open_failure_keeps_the_scene(model, tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{ not json")
    before = text(model)
    assert not model.open_path(bad)
    assert not model.open_path(tmp_path / "missing.json")
    assert text(model) == before
    assert "bad.json" in model.messages[-2].text and model.last_message.level == "error"


def test_discard_prompt(model, tmp_path):
    model.add_primitive("box")
    assert model.request("new") is False and model.pending is not None
    assert model.resolve_pending("cancel") is False and "box" in names(model)
    model.request("demo", "starter")
    assert model.resolve_pending("discard") is True
    assert "box" not in names(model) and model.demo == "starter" and not model.dirty
    # "save" without a file asks for one, then finishes the action
    model.add_primitive("sphere")
    model.request("new")
    model.resolve_pending("save")
    assert model.save_as_requested and "sphere" in names(model)
    assert model.save_as(tmp_path / "kept.json")
    assert "sphere" not in names(model) and names(model) == ["floor", "camera"]
    assert "sphere" in (tmp_path / "kept.json").read_text()
    # nothing to lose: no prompt
    assert model.request("quit") and model.quit_requested


def test_failed_save_keeps_the_old_file(model, tmp_path):
    path = tmp_path / "scene.json"
    save_scene(model.scene, path)
    old = path.read_text()
    model.add_primitive("box")
    assert not model.save_as(tmp_path / "missing-folder" / "scene.json")
    assert path.read_text() == old and model.dirty

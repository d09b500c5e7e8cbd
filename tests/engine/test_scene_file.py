"""Scene files: exact round trips, errors that name file/entity/field, atomic saves."""

from __future__ import annotations

import copy
import json
import os
import shutil
from pathlib import Path

import pytest

from components import Aberration, Camera, Light, Mesh, Portal, Transform
from demos import build_demo
from engine.scene import Scene
from engine.scene_file import SceneFileError, load_scene, save_scene, scene_to_json
from engine.settings import Settings

ROOT = Path(__file__).resolve().parents[2]
KNOT = ROOT / "demos" / "assets" / "knot.obj"
KINDS = (Transform, Camera, Mesh, Aberration, Portal, Light)


def snapshot(scene: Scene) -> dict[str, object]:
    """Everything a scene file carries, keyed by entity name (ids may differ after a load)."""
    entities = {scene.name_of(e): {kind.__name__: scene.try_get(e, kind) for kind in KINDS} for e in scene.entities()}
    assets = {name: scene.asset(name).content_hash for name in scene.assets}
    camera = None if scene.camera_entity is None else scene.name_of(scene.camera_entity)
    return {"name": scene.name, "settings": scene.settings, "entities": entities, "assets": assets, "camera": camera}


def assert_round_trip(scene: Scene, tmp_path: Path) -> Scene:
    first = tmp_path / "first.json"
    save_scene(scene, first)
    loaded = load_scene(first)
    second = tmp_path / "second.json"
    save_scene(loaded, second)
    assert first.read_bytes() == second.read_bytes()
    assert snapshot(loaded) == snapshot(scene)
    return loaded


def every_kind_scene(tmp_path: Path) -> Scene:
    """A scene with every component kind and option, and an imported mesh beside the file."""
    meshes = tmp_path / "meshes"
    meshes.mkdir()
    shutil.copy(KNOT, meshes / "knot.obj")
    scene = Scene(
        "every kind",
        settings=Settings(
            background=(0.1, 0.2, 0.30000000000000004),
            light_dir=(-1.0, 2.0, 0.5),
            max_events=7,
            event_limit_color=(0.0, 1.0, 0.0),
            ambient=0.2,
        ),
        base_dir=tmp_path,
    )
    scene.add_asset("knot", path="meshes/knot.obj")
    scene.add_asset("ball", primitive="sphere")
    scene.add_mesh("floor", "plane", scale=(8.0, 1.0, 8.0), checker=0.125, color=(0.9, 0.9, 0.85))
    scene.add_mesh("knot", "knot", position=(0.1, 0.2, 0.3), euler_deg=(10.0, 20.0, 30.0), scale=1.5,
                   color=(1.0, 0.5, 0.0), cull_backfaces=True)  # fmt: skip
    scene.add_mesh("ball", "ball", position=(1e-17, -3.25, 1e300), scale=(1.0, -2.0, 3.0))
    scene.add_aberration("metric", (1.0, -0.5, 0.25), scale=(2.0, 3.0, 4.0), priority=2)
    scene.add_aberration("radial", (0.3, 0.0, -2.0), mode="radial", exit="invert", debug_draw=False,
                         color=(0.0, 0.0, 1.0), euler_deg=(0.0, 45.0, 0.0))  # fmt: skip
    scene.add_aberration("additive", (0.1, 0.2, 0.3), mode="additive", exit="repeat", priority=-1)
    door_b = {"position": (2.0, 1.0, 0.0), "euler_deg": (0.0, 180.0, 0.0)}
    scene.add_portal_pair("door_a", "door_b", a={"position": (-2.0, 1.0, 0.0)}, b=door_b, color=(1.0, 0.0, 1.0))
    scene.add_portal("one_way", target="door_a", position=(0.0, 1.0, -3.0), debug_draw=False)
    scene.add_portal("inert", position=(0.0, 1.0, 3.0))
    scene.create_entity("marker", Transform(position=(0.5, 0.5, 0.5)))
    scene.add_light("sun", "sun", euler_deg=(-60.0, 30.0, 0.0), color=(1.0, 0.9, 0.8), intensity=1.25)
    scene.add_light("lamp", "point", position=(0.0, 2.5, 0.0), intensity=12.0, shadows=False, range=9.5)
    scene.set_camera((0.0, 1.6, 6.0), look_at=(0.0, 1.0, 0.0), fov_deg=72.5, speed=4.25, name="eye")
    return scene


def minimal(**extra: object) -> dict[str, object]:
    return {"format": "aberrant-scene", "version": 1, **extra}


def entity(name: str = "thing", **parts: object) -> dict[str, object]:
    return {"name": name, **parts}


# --- round trips -------------------------------------------------------------------


def test_starter_demo_round_trips_exactly(tmp_path):
    assert_round_trip(build_demo("starter"), tmp_path)


def test_every_component_kind_round_trips_exactly(tmp_path):
    scene = every_kind_scene(tmp_path)
    loaded = assert_round_trip(scene, tmp_path)
    assert loaded.name_of(loaded.camera_entity) == "eye"
    assert loaded.get(loaded.entity("inert"), Portal).target is None
    assert loaded.base_dir == tmp_path


def test_saved_file_is_canonical_json(tmp_path):
    scene = every_kind_scene(tmp_path)
    path = tmp_path / "scene.json"
    save_scene(scene, path)
    text = path.read_text()
    doc = json.loads(text)
    assert list(doc) == ["format", "version", "name", "settings", "camera", "assets", "entities"]
    assert doc["assets"] == {"ball": {"primitive": "sphere"}, "knot": {"path": "meshes/knot.obj"}}
    assert [e["name"] for e in doc["entities"]] == [
        "floor", "knot", "ball", "metric", "radial", "additive", "door_a", "door_b", "one_way", "inert", "marker",
        "sun", "lamp",
    ]  # fmt: skip
    assert doc["entities"][-1]["light"] == {
        "kind": "point", "color": [1.0, 1.0, 1.0], "intensity": 12.0, "shadows": False, "range": 9.5,
    }  # fmt: skip
    assert "look_at" not in text  # a point looked at is saved as the rotation it gave
    for e in doc["entities"]:  # angles given as angles stay angles, the rest are quaternions
        given = "euler_deg" if "euler_deg" in e["transform"] else "rotation"
        assert len(e["transform"][given]) == (3 if given == "euler_deg" else 4)
        assert ("rotation" in e["transform"]) != ("euler_deg" in e["transform"])
    assert "euler_deg" in text
    assert '\n  "settings": {\n    "background": [0.1, 0.2, 0.30000000000000004],' in text
    assert text.endswith("}\n")
    assert text == scene_to_json(scene, tmp_path)


def test_assets_outside_the_scene_folder_are_saved_absolute(tmp_path):
    scene = every_kind_scene(tmp_path)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    save_scene(scene, elsewhere / "scene.json")
    doc = json.loads((elsewhere / "scene.json").read_text())
    assert doc["assets"]["knot"]["path"] == str(tmp_path / "meshes" / "knot.obj")
    assert snapshot(load_scene(elsewhere / "scene.json")) == snapshot(scene)


def test_minimal_file_takes_defaults(tmp_path):
    path = tmp_path / "min.json"
    path.write_text(json.dumps(minimal(entities=[entity("a"), entity("b", mesh={"asset": "box"})])))
    scene = load_scene(path)
    assert scene.name == "untitled"
    assert scene.settings == Settings()
    assert scene.camera_entity is None
    assert scene.get(scene.entity("a"), Transform) == Transform()
    assert scene.get(scene.entity("b"), Mesh) == Mesh("box")


def test_alternative_rotation_forms_and_uniform_scale(tmp_path):
    path = tmp_path / "forms.json"
    doc = minimal(
        camera={"position": [0, 2, 5], "look_at": [0, 0, 0], "fov_deg": 50},
        entities=[
            entity("e", transform={"euler_deg": [0, 90, 0], "scale": 2}, mesh={"asset": "box"}),
            entity("q", transform={"rotation": [0, 0, 0, 1], "position": [1, 2, 3]}),
        ],
    )
    path.write_text(json.dumps(doc))
    scene = load_scene(path)
    t = scene.get(scene.entity("e"), Transform)
    assert t.scale == (2.0, 2.0, 2.0)
    assert t.rotation == pytest.approx((0.0, 2**-0.5, 0.0, 2**-0.5))
    assert scene.get(scene.entity("q"), Transform).position == (1.0, 2.0, 3.0)
    assert scene.get(scene.camera_entity, Camera).fov_deg == 50.0
    assert scene.name_of(scene.camera_entity) == "camera"


# --- errors ------------------------------------------------------------------------------


def write(tmp_path: Path, doc: object, name: str = "level.json") -> Path:
    path = tmp_path / name
    path.write_text(doc if isinstance(doc, str) else json.dumps(doc, indent=2))
    return path


def load_error(path: Path) -> SceneFileError:
    with pytest.raises(SceneFileError) as e:
        load_scene(path)
    message = str(e.value)
    assert "\n" not in message
    assert message.startswith(f"{path}: ")
    return e.value


def test_malformed_json_gives_line_and_column(tmp_path):
    path = write(tmp_path, '{\n  "format": "aberrant-scene",\n  "version": 1\n  "name": "x"\n}')
    error = load_error(path)
    assert "line 4, column 3" in str(error)
    assert "JSON" in str(error)


def test_missing_scene_file(tmp_path):
    assert "not found" in str(load_error(tmp_path / "nope.json"))


@pytest.mark.parametrize(
    ("doc", "fragment"),
    [
        ({"format": "something-else", "version": 1}, "field 'format'"),
        ({"version": 1}, "field 'format'"),
        (minimal(version=2), "field 'version': scene file version 2 is newer"),
        (minimal(version="1"), "field 'version'"),
        ([1, 2, 3], "expected an object, got an array"),
        (minimal(colour=1), "field 'colour': unknown key 'colour'; allowed keys: format, version, name,"),
        (minimal(settings={"max_events": 2.5}), "field 'settings.max_events': expected an integer"),
        (minimal(settings={"fog": 1}), "field 'settings.fog': unknown key"),
        (minimal(settings={"background": [0, 0, 2]}), "field 'settings.background[2]'"),
        (minimal(entities={"a": 1}), "field 'entities': expected an array"),
        (minimal(assets={"k": {"file": "k.obj"}}), "asset 'k': field 'assets.k.file': unknown key 'file'"),
        (minimal(assets={"k": {}}), "asset 'k': field 'assets.k': give exactly one"),
        (minimal(assets={"k": {"primitive": "torus"}}), "asset 'k': field 'assets.k.primitive': unknown primitive"),
        (minimal(assets={"k": {"path": 3}}), "asset 'k': field 'assets.k.path': expected a non-empty string"),
    ],
)
def test_document_level_errors(tmp_path, doc, fragment):
    assert fragment in str(load_error(write(tmp_path, doc)))


BAD_ENTITIES = [
    # (entity, field named, words in the message)
    (entity(mesh={"asset": "box", "colour": [1, 0, 0]}), "mesh.colour", "allowed keys: asset, color, checker"),
    (entity(transform={"pos": [0, 0, 0]}), "transform.pos", "allowed keys: position, rotation, euler_deg, scale"),
    (entity(velocity=1), "velocity", "allowed keys: name, transform, mesh, aberration, portal, light"),
    (entity(light={"kind": "spot"}), "light.kind", "'sun', 'point'"),
    (entity(light={"intensity": -1}), "light.intensity", ">= 0"),
    (entity(light={"color": [2, 0, 0]}), "light.color[0]", "[0, 1]"),
    (entity(light={"shadows": 1}), "light.shadows", "true or false"),
    (entity(light={"kind": "sun", "range": 5}), "light.range", "only a point light"),
    (entity(light={"kind": "point", "range": 0}), "light.range", "> 0"),
    (entity(light={"kind": "point", "radius": 1}), "light.radius", "allowed keys: kind, color, intensity"),
    (entity(transform={"position": "abc"}), "transform.position", "expected 3 numbers"),
    (entity(transform={"position": [0, "x", 0]}), "transform.position[1]", "expected a number"),
    (entity(transform={"position": [0, None, 0]}), "transform.position[1]", "expected a number"),
    (entity(transform={"scale": [1, 0, 1]}), "transform.scale[1]", "zero"),
    (entity(transform={"scale": 0}), "transform.scale[0]", "zero"),
    (entity(transform={"rotation": [0, 0, 0, 2]}), "transform.rotation", "unit length"),
    (entity(transform={"rotation": [0, 0, 0, 1], "euler_deg": [0, 0, 0]}), "transform.euler_deg", "only one"),
    (entity(transform={"euler_deg": [0, 0]}), "transform.euler_deg", "expected 3 numbers"),
    (entity(transform=[0, 0, 0]), "transform", "expected an object, got an array"),
    (entity(mesh="box"), "mesh", "expected an object, got a string"),
    (entity(mesh={}), "mesh.asset", "needs an 'asset'"),
    (entity(mesh={"asset": "teapot"}), "mesh.asset", "unknown asset 'teapot'"),
    (entity(mesh={"asset": "box", "color": [1.5, 0, 0]}), "mesh.color[0]", "[0, 1]"),
    (entity(mesh={"asset": "box", "checker": "fine"}), "mesh.checker", "expected a number"),
    (entity(mesh={"asset": "box", "cull_backfaces": "yes"}), "mesh.cull_backfaces", "true or false"),
    (entity(aberration={"deformation": [-1, 0, 0]}), "aberration.deformation[0]", "> -1"),
    (entity(aberration={"mode": "warp"}), "aberration.mode", "'metric', 'radial', 'additive'"),
    (entity(aberration={"exit": "bounce"}), "aberration.exit", "'restore', 'repeat', 'invert'"),
    (entity(aberration={"priority": 1.5}), "aberration.priority", "expected an integer"),
    (entity(portal={"target": 7}), "portal.target", "expected the name of a portal"),
    (entity(portal={"target": "nowhere"}), "portal.target", "no entity is named 'nowhere'"),
]


@pytest.mark.parametrize(("bad", "field", "words"), BAD_ENTITIES)
def test_entity_errors_name_file_entity_and_field(tmp_path, bad, field, words):
    path = write(tmp_path, minimal(entities=[entity("ok", mesh={"asset": "box"}), bad]))
    error = load_error(path)
    assert str(error).startswith(f"{path}: entity 'thing': field '{field}': ")
    assert words in str(error)
    assert (error.entity, error.field) == ("thing", field)


def test_more_lights_than_the_kernels_hold_names_the_first_past_the_limit(tmp_path):
    lamps = [entity(f"lamp{k}", light={"kind": "point"}) for k in range(9)]
    error = load_error(write(tmp_path, minimal(entities=lamps)))
    assert (error.entity, error.field) == ("lamp8", "light") and "at most 8" in str(error)


def test_target_that_is_not_a_portal(tmp_path):
    doc = minimal(entities=[entity("box", mesh={"asset": "box"}), entity("door_a", portal={"target": "box"})])
    error = load_error(write(tmp_path, doc))
    assert str(error) == f"{tmp_path / 'level.json'}: entity 'door_a': field 'portal.target': 'box' is not a portal"


def test_duplicate_entity_names(tmp_path):
    doc = minimal(entities=[entity("twin"), entity("twin")])
    assert "entity 'twin': field 'name':" in str(load_error(write(tmp_path, doc)))


def test_entity_named_like_the_camera(tmp_path):
    doc = minimal(camera={"position": [0, 0, 5]}, entities=[entity("camera")])
    assert "entity 'camera': field 'name':" in str(load_error(write(tmp_path, doc)))


def test_entity_without_a_name_is_located_by_index(tmp_path):
    doc = minimal(entities=[entity("a"), {"mesh": {"asset": "box"}}])
    assert "entities[1]: field 'name':" in str(load_error(write(tmp_path, doc)))


def test_duplicate_json_key_is_an_error(tmp_path):
    text = '{"format": "aberrant-scene", "version": 1, "entities": [{"name": "a", "name": "b"}]}'
    assert "field 'name': the key 'name' appears more than once" in str(load_error(write(tmp_path, text)))


def test_camera_errors(tmp_path):
    for camera, field in [
        ({"fov_deg": 0}, "camera.fov_deg"),
        ({"speed": -1}, "camera.speed"),
        ({"position": [0, 0, 0], "look_at": [0, 0, 0]}, "camera.look_at"),
        ({"look_at": [0, 0, -1], "rotation": [0, 0, 0, 1]}, "camera.look_at"),
        ({"zoom": 2}, "camera.zoom"),
    ]:
        error = load_error(write(tmp_path, minimal(camera=camera)))
        assert f"entity 'camera': field '{field}':" in str(error)


def test_missing_mesh_file_fails_at_load(tmp_path):
    doc = minimal(assets={"statue": {"path": "meshes/statue.obj"}}, entities=[entity(mesh={"asset": "statue"})])
    error = load_error(write(tmp_path, doc))
    assert "entity 'thing': field 'mesh.asset': asset 'statue':" in str(error)
    assert "statue.obj" in str(error) and "not found" in str(error)


def test_unused_missing_mesh_file_also_fails(tmp_path):
    doc = minimal(assets={"statue": {"path": "statue.obj"}})
    assert "asset 'statue': field 'assets.statue':" in str(load_error(write(tmp_path, doc)))


def test_mesh_file_with_no_triangles(tmp_path):
    (tmp_path / "points.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    doc = minimal(assets={"points": {"path": "points.obj"}}, entities=[entity(mesh={"asset": "points"})])
    error = load_error(write(tmp_path, doc))
    assert "entity 'thing': field 'mesh.asset': asset 'points':" in str(error)
    assert "no triangles" in str(error)


def test_asset_paths_are_relative_to_the_scene_file(tmp_path, monkeypatch):
    (tmp_path / "levels" / "meshes").mkdir(parents=True)
    shutil.copy(KNOT, tmp_path / "levels" / "meshes" / "knot.obj")
    doc = minimal(assets={"knot": {"path": "meshes/knot.obj"}}, entities=[entity(mesh={"asset": "knot"})])
    path = write(tmp_path / "levels", doc)
    monkeypatch.chdir(tmp_path)  # not the scene's folder
    scene = load_scene(Path("levels") / path.name)
    assert scene.asset("knot").triangle_count > 500


def test_non_finite_numbers_are_rejected_with_the_field(tmp_path):
    text = '{"format": "aberrant-scene", "version": 1, '
    text += '"entities": [{"name": "n", "transform": {"position": [0, NaN, 0]}}]}'
    assert "entity 'n': field 'transform.position[1]': must be finite" in str(load_error(write(tmp_path, text)))


def test_failed_load_leaves_no_world_behind(tmp_path):
    import esper

    before = set(esper.list_worlds())
    load_error(write(tmp_path, minimal(entities=[entity("a"), entity("a")])))
    assert set(esper.list_worlds()) == before


# --- atomic saves ----------------------------------------------------------------------


def test_failed_rename_keeps_the_old_file_and_no_temporary(tmp_path, monkeypatch):
    path = tmp_path / "scene.json"
    path.write_text("old contents")

    def broken_replace(src: object, dst: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", broken_replace)
    with pytest.raises(SceneFileError) as e:
        save_scene(build_demo("starter"), path)
    assert str(e.value).startswith(f"{path}: cannot save")
    assert path.read_text() == "old contents"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.json"]


def test_crash_while_writing_keeps_the_old_file(tmp_path, monkeypatch):
    path = tmp_path / "scene.json"
    path.write_text("old contents")

    def broken_fsync(fd: int) -> None:
        raise OSError(5, "Input/output error")

    monkeypatch.setattr(os, "fsync", broken_fsync)
    with pytest.raises(SceneFileError):
        save_scene(build_demo("starter"), path)
    assert path.read_text() == "old contents"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.json"]


def test_save_replaces_and_keeps_permissions(tmp_path):
    path = tmp_path / "scene.json"
    path.write_text("old")
    path.chmod(0o640)
    save_scene(build_demo("starter"), path)
    assert json.loads(path.read_text())["name"] == "starter"
    assert path.stat().st_mode & 0o777 == 0o640
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.json"]


def test_save_into_a_missing_folder_is_a_scene_file_error(tmp_path):
    with pytest.raises(SceneFileError, match="cannot save"):
        save_scene(build_demo("starter"), tmp_path / "missing" / "scene.json")


def test_loading_does_not_mutate_a_reloaded_document(tmp_path):
    """The loader only reads: the same file loads to equal scenes twice."""
    scene = every_kind_scene(tmp_path)
    path = tmp_path / "s.json"
    save_scene(scene, path)
    before = copy.deepcopy(path.read_bytes())
    assert snapshot(load_scene(path)) == snapshot(load_scene(path))
    assert path.read_bytes() == before

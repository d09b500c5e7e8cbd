"""TelloEngine import: both samples, baked hierarchies, the bottom pivot, portals, names, errors, a render."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from aberrant.cli import main
from aberrant.importers.tello import TelloError, import_tello, read_mesh_resource
from components import MAX_LIGHTS, Aberration, Light, Mesh, Portal, Transform
from engine.maths import quat_to_matrix, trs_matrix
from engine.scene_file import load_scene

REPO = Path(__file__).resolve().parents[2]
TELLO = REPO / "tests" / "data" / "tello"
BOX = -753313173  # the unit box resource: [-1/2, 1/2]^2 x [0, 1]


def raw(name: str) -> dict:
    return json.loads((TELLO / "Scenes" / name).read_bytes().rstrip(b"\0"))


def count(doc: dict, kind: int) -> int:
    return sum(1 for g in doc["game_objects"] for c in g["components"] if c["type"] == kind)


def transform(position=(0, 0, 0), rotation=(0, 0, 0, 1), scale=(1, 1, 1)) -> dict:
    return {"type": 0, "position": list(position), "rotation": list(rotation), "scale": list(scale)}


def obj(uuid: int, name: str, *components: dict, parent: int = 0) -> dict:
    return {"uuid": uuid, "parent": parent, "name": name, "components": list(components)}


def write_tello(path: Path, objects: list[dict], nul: bool = True) -> Path:
    path.write_bytes(json.dumps({"scene_name": "Test", "game_objects": objects}, indent=4).encode() + b"\0" * nul)
    return path


def by_name(scene, name: str) -> int:
    return scene.entity(name)


def world_matrix(doc: dict, uuid: int) -> np.ndarray:
    """Compose parent · child by hand from the raw JSON."""
    objects = {g["uuid"]: g for g in doc["game_objects"]}
    g = objects[uuid]
    t = next(c for c in g["components"] if c["type"] == 0)
    q = np.array(t["rotation"], dtype=float)
    local = trs_matrix(t["position"], q / np.linalg.norm(q), t["scale"])
    return local if g["parent"] == 0 else world_matrix(doc, g["parent"]) @ local


def entity_matrix(scene, name: str) -> np.ndarray:
    t = scene.get(scene.entity(name), Transform)
    return trs_matrix(t.position, t.rotation, t.scale)


# --- the samples --------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["AberrationRoom", "SceneTest"])
def test_samples_import_and_load_back_with_the_same_counts(tmp_path, name):
    doc = raw(name)
    result = import_tello(TELLO / "Scenes" / name, TELLO / "Mesh", tmp_path / "out.json")
    result.scene.close()
    scene = load_scene(tmp_path / "out.json")
    try:
        assert len(scene.query(Mesh)) == count(doc, 1)
        assert len(scene.query(Aberration)) == count(doc, 6)
        assert len(scene.query(Portal)) == count(doc, 7)
        assert scene.name == doc["scene_name"]
        for _, mesh in scene.query(Mesh):
            assert mesh.cull_backfaces
        for _, aberration in scene.query(Aberration):
            assert (aberration.mode, aberration.exit) == ("radial", "restore")
    finally:
        scene.close()


def test_aberration_room_names_transforms_and_bottom_pivot(tmp_path):
    doc = raw("AberrationRoom")
    import_tello(TELLO / "Scenes" / "AberrationRoom", TELLO / "Mesh", tmp_path / "room.json").scene.close()
    scene = load_scene(tmp_path / "room.json")
    try:
        names = [scene.name_of(e) for e, _ in scene.query(Mesh)]
        assert names == ["Box001", "Box001_2", "Box001_3", "Box001_4", "Box001_5"]
        # Box001_2 is the right wall, a child of "Walls": world = Walls · local, composed by hand.
        np.testing.assert_allclose(entity_matrix(scene, "Box001_2"), world_matrix(doc, -515122998), atol=1e-12)
        # The divider's colour 1e-6 is kept (clamped only outside [0, 1]).
        assert scene.get(scene.entity("Box001_4"), Mesh).color == (1e-06, 1e-06, 1e-06)
        # Left half: position (-5.25, 5.5, -13.5), scale (10.5, 10, 27), box [0, 1] in local z -> centre z = 0.
        left = scene.get(scene.entity("Aberration"), Transform)
        np.testing.assert_allclose(left.position, (-5.25, 5.5, 0.0), atol=1e-12)
        assert left.scale == (10.5, 10.0, 27.0)
        assert scene.get(scene.entity("Aberration"), Aberration).deformation == (0.0, 1.0, 0.0)
        assert scene.get(scene.entity("Aberration_2"), Aberration).deformation == (1.0, 0.0, 0.0)
    finally:
        scene.close()


def test_meshes_become_obj_files_with_the_stored_geometry(tmp_path):
    result = import_tello(TELLO / "Scenes" / "AberrationRoom", TELLO / "Mesh", tmp_path / "room.json")
    try:
        assert result.mesh_files == [tmp_path / "room_meshes" / f"{BOX}.obj"]
        asset = result.scene.asset(f"tello_mesh_{BOX}")
        stored = read_mesh_resource(TELLO / "Mesh" / str(BOX))
        np.testing.assert_array_equal(asset.vertices[asset.faces], stored.vertices[stored.faces])
        low, high = asset.bounds()
        np.testing.assert_array_equal(low, (-0.5, -0.5, 0.0))  # the pivot on the bottom face is kept
        np.testing.assert_array_equal(high, (0.5, 0.5, 1.0))
    finally:
        result.scene.close()


def test_imported_room_renders_with_the_reference_backend(tmp_path, capsys):
    from conftest import require_backend

    require_backend("reference")
    assert main(["import-tello", str(TELLO / "Scenes" / "AberrationRoom"), "--out", str(tmp_path / "r.json")]) == 0
    code = main(["render", str(tmp_path / "r.json"), "--backend", "reference", "--size", "64x48",
                 "--out", str(tmp_path / "r.png"), "--aovs", str(tmp_path / "r.npz")])  # fmt: skip
    assert code == 0, capsys.readouterr().err
    aovs = np.load(tmp_path / "r.npz")
    assert not np.isnan(aovs["depth"]).any() and not np.isnan(aovs["perceived"]).any()
    assert len(np.unique(aovs["instance"][aovs["instance"] >= 0])) > 1


# --- hand-made files: hierarchy, pivot, portals, cameras ------------------------------------


def test_nested_hierarchy_is_baked_into_world_transforms(tmp_path):
    half = math.sqrt(0.5)
    objects = [
        obj(1, "Root", transform((1, 2, 3), (0, math.sin(0.3), 0, math.cos(0.3)), (2, 2, 2))),
        obj(2, "Mid", transform((0.5, 0, -1), (math.sin(0.2), 0, 0, math.cos(0.2)), (0.5, 0.5, 0.5)), parent=1),
        obj(3, "Leaf", transform((0, 1, 0.25), (-half, 0, 0, half), (1, 3, 0.2)), {"type": 1, "mesh": BOX}, parent=2),
        obj(4, "Arm", transform((2, 0, 0), (0, 0, 0, 1), (1, 3, 1)), parent=1),
        obj(
            5, "Hand", transform((0, 1, 0), (0, 0, math.sin(0.25), math.cos(0.25))), {"type": 1, "mesh": BOX}, parent=4
        ),
    ]
    doc = {"game_objects": objects}
    result = import_tello(write_tello(tmp_path / "Nested", objects), TELLO / "Mesh", tmp_path / "n.json")
    try:
        assert [result.scene.name_of(e) for e, _ in result.scene.query(Mesh)] == ["Leaf", "Hand"]  # groups dropped
        np.testing.assert_allclose(entity_matrix(result.scene, "Leaf"), world_matrix(doc, 3), atol=1e-12)
        # Hand, turned 30° under Arm's non-uniform scale, is sheared: no T·R·S is exact; a warning says so.
        assert any("'Hand'" in w and "shear" in w for w in result.warnings)
        hand = result.scene.get(result.scene.entity("Hand"), Transform)
        np.testing.assert_allclose(hand.position, world_matrix(doc, 5)[:3, 3], atol=1e-12)
    finally:
        result.scene.close()


def test_a_rotated_aberration_box_is_centred_along_its_local_z(tmp_path):
    half = math.sqrt(0.5)
    objects = [obj(7, "Box", transform((1, 1, 1), (-half, 0, 0, half), (2, 3, 4)), {"type": 6, "deformationX": 0.5})]
    result = import_tello(write_tello(tmp_path / "Pivot", objects), TELLO / "Mesh", tmp_path / "p.json")
    try:
        box = result.scene.get(result.scene.entity("Box"), Transform)
        # -90° about X turns local +z into world +y; the centre is half the box's height (4) above the pivot.
        np.testing.assert_allclose(box.position, (1.0, 3.0, 1.0), atol=1e-12)
        corners = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
        world = corners * box.scale @ quat_to_matrix(box.rotation).T + box.position
        np.testing.assert_allclose(world.min(axis=0), (0.0, 1.0, -0.5), atol=1e-12)
        np.testing.assert_allclose(world.max(axis=0), (2.0, 5.0, 2.5), atol=1e-12)
    finally:
        result.scene.close()


def test_portals_are_linked_pairwise_with_unique_names(tmp_path):
    def portal(target: int) -> dict:
        return {"type": 7, "connectedGO": target, "debugDraw": True, "debugDrawColR": 2, "debugDrawColG": 0.5,
                "debugDrawColB": -1}  # fmt: skip

    objects = [
        obj(10, "Portal", transform((0, 1, -3)), portal(11)),
        obj(11, "Portal", transform((50, 1, 0), (0, 1, 0, 0)), portal(10)),
        obj(12, "Portal_2", transform((9, 9, 9)), portal(0)),
        obj(13, "Cam", transform((0, 1, 4), (0, 0, 0, 1)), {"type": 3}),
        obj(14, "Lamp", transform(), {"type": 4}),
        obj(15, "Blob", transform(), {"type": 5}),
    ]
    result = import_tello(write_tello(tmp_path / "Portals", objects, nul=False), TELLO / "Mesh", tmp_path / "q.json")
    result.scene.close()
    scene = load_scene(tmp_path / "q.json")
    try:
        targets = {scene.name_of(e): p.target for e, p in scene.query(Portal)}
        assert targets == {"Portal": "Portal_3", "Portal_3": "Portal", "Portal_2": None}
        assert scene.get(scene.entity("Portal"), Portal).color == (1.0, 0.5, 0.0)
        assert scene.get(scene.entity("Portal_3"), Transform).position == (50.0, 1.0, 0.0)  # same quad: no conversion
        camera = scene.get(scene.camera_entity, Transform)
        assert (scene.name_of(scene.camera_entity), camera.position) == ("Cam", (0.0, 1.0, 4.0))
        assert any("ProceduralMesh" in w and "Blob" in w for w in result.warnings)
        assert scene.get(scene.entity("Lamp_light"), Light).kind == "point"
    finally:
        scene.close()


def test_point_lights_become_shadowing_point_lights_at_their_world_position(tmp_path):
    objects = [
        obj(1, "Floor", transform((0, 0, 0), (-math.sqrt(0.5), 0, 0, math.sqrt(0.5)), (10, 10, 0.1)),
            {"type": 1, "mesh": BOX}),
        obj(2, "Group", transform((1, 2, 3))),
        obj(3, "Lamp", transform((0, 1, 0)), {"type": 4}, parent=2),
        *(obj(10 + k, f"Extra{k}", transform((k, 3, 0)), {"type": 4}) for k in range(MAX_LIGHTS)),
    ]  # fmt: skip
    result = import_tello(write_tello(tmp_path / "Lamps", objects), TELLO / "Mesh", tmp_path / "lamps.json")
    result.scene.close()
    scene = load_scene(tmp_path / "lamps.json")
    try:
        lights = scene.query(Light)
        assert len(lights) == MAX_LIGHTS and all(light.kind == "point" and light.shadows for _, light in lights)
        lamp = scene.entity("Lamp_light")
        assert scene.get(lamp, Transform).position == (1.0, 3.0, 3.0)  # the parent's offset composed
        assert scene.get(lamp, Light).intensity == pytest.approx((0.5 * 10) ** 2)  # the floor's extent
        assert any("dropped: game object" in w and "Extra7" in w for w in result.warnings)
    finally:
        scene.close()


# --- bad input ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("objects", "message"),
    [
        (
            [obj(5, "Odd", transform(), {"type": 9})],
            "game object 5 'Odd': field 'components[1].type': unknown component",
        ),
        (
            [obj(5, "Wall", transform(), {"type": 1, "mesh": 1234})],
            "'Wall': field 'components[1].mesh': mesh resource 1234",
        ),
        (
            [obj(5, "P", transform(), {"type": 7, "connectedGO": 6}), obj(6, "Rock", transform())],
            "game object 5 'P': field 'components[1].connectedGO': links to game object 6 'Rock', which has no Portal",
        ),
        ([obj(5, "Lost", transform(), parent=99)], "game object 5 'Lost': field 'parent': no game object has uuid 99"),
        ([obj(5, "T", transform(scale=(1, 0, 1)), {"type": 1, "mesh": BOX})], "field 'components[0].scale'"),
        ([obj(5, "T", transform(position=(1, "x", 2)))], "field 'components[0].position[1]'"),
    ],
)
def test_bad_files_give_one_line_errors_naming_object_and_field(tmp_path, objects, message):
    path = write_tello(tmp_path / "Bad", objects)
    with pytest.raises(TelloError) as info:
        import_tello(path, TELLO / "Mesh", tmp_path / "bad.json")
    assert str(info.value).startswith(str(path))
    assert message in str(info.value)
    assert not (tmp_path / "bad.json").exists()


def test_cli_errors_are_one_line_and_write_nothing(tmp_path, capsys):
    (tmp_path / "Garbage").write_bytes(b"{not json\0")
    code = main(["import-tello", str(tmp_path / "Garbage"), "--mesh-dir", str(TELLO / "Mesh"),
                 "--out", str(tmp_path / "g.json")])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith("aberrant: error: ") and "Garbage" in err and "not JSON" in err and err.count("\n") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["Garbage"]


def test_cli_import_prints_what_it_wrote(tmp_path, capsys):
    code = main(["import-tello", str(TELLO / "Scenes" / "SceneTest"), "--out", str(tmp_path / "t.json")])
    out = capsys.readouterr().out
    assert code == 0
    assert f"wrote {tmp_path / 't.json'}" in out and "1 aberrations" in out

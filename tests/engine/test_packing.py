"""Packing: tables match the scene, and syncs upload only what changed."""

from __future__ import annotations

import numpy as np
import pytest

from components import Aberration, Mesh, Portal, Transform
from engine.camera_view import CameraView, pack_camera
from engine.maths import quat_from_euler_deg, trs_matrix
from engine.packed import TableUpdate
from engine.packing import ScenePacker
from engine.scene import Scene
from engine.settings import Settings


def small_scene() -> Scene:
    scene = Scene("packing")
    scene.add_mesh("floor", "plane", scale=(10, 1, 10), checker=1.0)
    scene.add_mesh("box", "box", position=(1, 0.5, -2), euler_deg=(0, 30, 0), color=(1, 0, 0))
    scene.add_mesh("box2", "box", position=(-1, 0.5, -2), cull_backfaces=True)
    scene.add_aberration("hi", (1, 0, 0), position=(0, 1, 0), scale=2, priority=5)
    scene.add_aberration("lo", (0, 1, 0), position=(0, 1, 0), scale=3, priority=1, mode="radial")
    scene.add_portal_pair("a", "b", a=dict(position=(2, 1, 0)), b=dict(position=(-2, 1, 0), euler_deg=(0, 180, 0)))
    scene.set_camera((0, 1.5, 5), look_at=(0, 0.5, 0))
    return scene


def test_full_pack_tables_and_counts() -> None:
    scene = small_scene()
    packer = ScenePacker("f32")
    updates = packer.sync(scene)
    packed = packer.packed
    assert packed is not None
    assert {u.table for u in updates} == set(packed.tables) and all(u.rows is None for u in updates)
    assert packed.counts["instances"] == 3
    assert packed.counts["aberrations"] == 2
    assert packed.counts["portals"] == 2
    # box and box2 share one asset: triangles stored once (plane 2 + box 12).
    assert packed.counts["triangles"] == 14
    roots = packed.tables["instances"]["meta"][:3, 0]
    assert roots[1] == roots[2] != roots[0]
    assert list(packed.tables["instances"]["meta"][:3, 2]) == [scene.entity(n) for n in ("floor", "box", "box2")]
    assert packed.tables["materials"]["flags"][2, 0] == 1
    assert packed.tables["materials"]["color"][0, 3] == 1.0
    assert packed.features.portals and packed.features.aberration_modes == {"metric", "radial"}
    assert list(packed.tables["settings"]["counts"][0]) == [3, 2, 2, 16]


def test_aberrations_sorted_by_priority_last_wins() -> None:
    packer = ScenePacker("f64", camera_relative=False)
    scene = small_scene()
    packer.sync(scene)
    meta = packer.packed.tables["aberrations"]["meta"]
    assert list(meta[:, 2]) == [1, 5]
    assert list(meta[:, 3]) == [scene.entity("lo"), scene.entity("hi")]
    assert list(meta[:, 0]) == [1, 0]  # radial, metric


def test_instance_transform_is_world_to_object() -> None:
    scene = small_scene()
    packer = ScenePacker("f64", camera_relative=False)
    packer.sync(scene)
    t = scene.get(scene.entity("box"), Transform)
    w2o = packer.packed.tables["instances"]["world_to_object"][1]
    m = trs_matrix(t.position, t.rotation, t.scale)
    product = w2o[:, :3] @ m[:3, :3]
    np.testing.assert_allclose(product, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(w2o[:, :3] @ m[:3, 3] + w2o[:, 3], 0, atol=1e-12)


def test_camera_relative_origin_snaps_and_keeps_float32_small() -> None:
    scene = Scene("far")
    scene.add_mesh("box", "box", position=(1e5 + 1, 0, -3))
    scene.set_camera((1e5 + 3.0, 0, 0))
    packer = ScenePacker("f32", origin_cell=16.0)
    packer.sync(scene)
    origin = packer.packed.origin
    assert np.all(np.abs(origin - np.array([1e5 + 3.0, 0, 0])) <= 8.0)
    w2o = packer.packed.tables["instances"]["world_to_object"][0]
    assert np.all(np.abs(w2o[:, 3]) < 20)  # translation relative to the origin, not 1e5


def test_portal_transfer_maps_self_onto_target() -> None:
    scene = small_scene()
    packer = ScenePacker("f64", camera_relative=False)
    packer.sync(scene)
    x = packer.packed.tables["portals"]["transfer"][0]
    a, b = scene.get(scene.entity("a"), Transform), scene.get(scene.entity("b"), Transform)
    ma, mb = trs_matrix(a.position, a.rotation, a.scale), trs_matrix(b.position, b.rotation, b.scale)
    corner_a = ma @ np.array([1.0, 1.0, 0.0, 1.0])
    corner_b = mb @ np.array([1.0, 1.0, 0.0, 1.0])
    np.testing.assert_allclose(x[:, :3] @ corner_a[:3] + x[:, 3], corner_b[:3], atol=1e-12)
    assert list(packer.packed.tables["portals"]["meta"][:2, 0]) == [1, 0]


def test_static_sync_uploads_nothing() -> None:
    scene = small_scene()
    packer = ScenePacker()
    packer.sync(scene)
    assert packer.sync(scene) == []


def test_moving_one_mesh_updates_one_row() -> None:
    scene = small_scene()
    packer = ScenePacker()
    packer.sync(scene)
    box = scene.entity("box")
    # Its first move takes it out of its tight TLAS leaf: the leaf becomes fat (a few tree rows).
    scene.set(box, Transform((1, 0.52, -2), tuple(quat_from_euler_deg((0, 30, 0))), (1, 1, 1)))
    assert {u.table for u in packer.sync(scene)} == {"instances", "tlas_nodes"}
    # 0.03 more: within its fat leaf (the tree changes only for moves beyond a tenth of its size).
    scene.set(box, Transform((1, 0.55, -2), tuple(quat_from_euler_deg((0, 30, 0))), (1, 1, 1)))
    updates = packer.sync(scene)
    assert updates == [TableUpdate("instances", range(1, 2))]
    assert packer.packed.update_bytes(updates) == packer.packed.tables["instances"].dtype.itemsize


def test_recolouring_updates_material_row_only() -> None:
    scene = small_scene()
    packer = ScenePacker()
    packer.sync(scene)
    box2 = scene.entity("box2")
    scene.set(box2, Mesh("box", color=(0, 1, 0), cull_backfaces=True))
    updates = packer.sync(scene)
    assert TableUpdate("materials", range(2, 3)) in updates
    assert all(u.table in ("instances", "materials") and u.rows is not None for u in updates)


def test_moving_a_portal_updates_portal_rows_and_the_camera_moving_updates_nothing() -> None:
    scene = small_scene()
    packer = ScenePacker()
    packer.sync(scene)
    b = scene.entity("b")
    old = scene.get(b, Transform)
    scene.set(b, Transform((-2.5, 1, 0), old.rotation, old.scale))
    updates = packer.sync(scene)
    tables = {u.table for u in updates}
    assert "portals" in tables and "instances" not in tables and "triangles" not in tables
    cam = scene.camera_entity
    t = scene.get(cam, Transform)
    scene.set(cam, Transform((0.5, 1.5, 5), t.rotation, t.scale))  # within the origin cell
    assert packer.sync(scene) == []


def test_structural_change_repacks_everything() -> None:
    scene = small_scene()
    packer = ScenePacker()
    packer.sync(scene)
    scene.add_mesh("sphere", "sphere", position=(0, 1, -4))
    updates = packer.sync(scene)
    assert all(u.rows is None for u in updates)
    assert packer.packed.counts["instances"] == 4


def test_settings_change_updates_settings() -> None:
    scene = small_scene()
    packer = ScenePacker()
    packer.sync(scene)
    scene.settings = Settings(max_events=4)
    assert packer.sync(scene) == [TableUpdate("settings")]
    assert packer.packed.features.max_events == 4


def test_priority_change_reorders_aberrations() -> None:
    scene = small_scene()
    packer = ScenePacker()
    packer.sync(scene)
    lo = scene.entity("lo")
    scene.set(lo, Aberration((0, 1, 0), mode="radial", priority=9))
    updates = packer.sync(scene)
    assert any(u.table == "aberrations" for u in updates)
    assert packer.packed.tables["aberrations"]["meta"][1, 3] == lo


def test_retargeting_a_portal_changes_features() -> None:
    scene = small_scene()
    packer = ScenePacker()
    packer.sync(scene)
    for name in ("a", "b"):
        scene.set(scene.entity(name), Portal(None))
    packer.sync(scene)
    assert not packer.packed.features.portals
    assert list(packer.packed.tables["portals"]["meta"][:2, 0]) == [-1, -1]


def test_empty_scene_has_one_padding_row_per_table() -> None:
    scene = Scene("empty")
    scene.set_camera((0, 0, 0))
    packer = ScenePacker()
    packer.sync(scene)
    for name, table in packer.packed.tables.items():
        assert len(table) == 1, name
        assert packer.packed.counts[name] == (1 if name == "settings" else 0)


def test_camera_row_and_primary_rays() -> None:
    view = CameraView(np.array([1.0, 2.0, 3.0]), np.eye(3), 90.0)
    row = pack_camera(view, np.array([1.0, 2.0, 0.0]), "f32", 4, 2)
    assert list(row["position"][0, :3]) == [0, 0, 3]
    assert row["lens"][0, 0] == pytest.approx(1.0)
    assert row["lens"][0, 1] == pytest.approx(2.0)
    d = view.primary_directions(4, 2)
    assert d.shape == (2, 4, 3)
    np.testing.assert_allclose(np.linalg.norm(d, axis=2), 1.0)
    # Row 0 is the top: its rays point up.
    assert np.all(d[0, :, 1] > 0) and np.all(d[1, :, 1] < 0)
    # Left column points left.
    assert np.all(d[:, 0, 0] < 0) and np.all(d[:, -1, 0] > 0)
    lo, hi = view.sigma_bounds(2.0)
    np.testing.assert_allclose(lo[2], hi[2])  # the view axis of a level camera collapses


def test_wide_bvh_packing_points_leaves_at_triangle_blocks():
    """bvh_width=4 and 8: wide nodes whose leaves name blocks of 4 triangles; each triangle row in one block lane."""
    from engine import layout

    scene = small_scene()
    scene.add_mesh("ball", "sphere", position=(0, 2, -3))
    binary = ScenePacker(bvh_width=2)
    binary.sync(scene)
    wide = ScenePacker(bvh_width=4)
    wide.sync(scene)
    assert binary.packed is not None and wide.packed is not None
    assert binary.packed.counts["triangle_blocks"] == 0
    nodes, blocks = wide.packed.tables["bvh_nodes"], wide.packed.tables["triangle_blocks"]
    assert nodes.dtype == layout.BVH4_NODE_DTYPE and blocks.dtype == layout.TRIANGLE_BLOCK_DTYPE
    np.testing.assert_array_equal(wide.packed.tables["triangles"], binary.packed.tables["triangles"])
    n_tri, n_blocks = wide.packed.counts["triangles"], wide.packed.counts["triangle_blocks"]
    lanes = blocks["index"][:n_blocks].ravel()
    np.testing.assert_array_equal(np.sort(lanes[lanes >= 0]), np.arange(n_tri))
    tri = wide.packed.tables["triangles"]
    for k, axis in ((0, "x"), (1, "y"), (2, "z")):  # the lanes hold their triangle's vertices
        for v in ("v0", "v1", "v2"):
            got = blocks[f"{v}{axis}"][:n_blocks].ravel()
            np.testing.assert_array_equal(got[lanes >= 0], tri[v][lanes[lanes >= 0], k])
    count, child = nodes["count"], nodes["child"]
    assert (child[count > 0] + (count[count > 0] + 3) // 4 <= n_blocks).all()
    assert (child[count == 0] < wide.packed.counts["bvh_nodes"]).all()
    with pytest.raises(ValueError, match="bvh_width"):
        ScenePacker(bvh_width=3)
    wide8 = ScenePacker(bvh_width=8)
    wide8.sync(scene)
    assert wide8.packed is not None
    nodes8, blocks8 = wide8.packed.tables["bvh_nodes"], wide8.packed.tables["triangle_blocks"]
    assert nodes8.dtype == layout.BVH8_NODE_DTYPE
    n8 = wide8.packed.counts["triangle_blocks"]
    lanes8 = blocks8["index"][:n8].ravel()
    np.testing.assert_array_equal(np.sort(lanes8[lanes8 >= 0]), np.arange(n_tri))
    count8, child8 = nodes8["count"], nodes8["child"]
    assert (child8[count8 > 0] + (count8[count8 > 0] + 3) // 4 <= n8).all()
    assert (child8[count8 == 0] < wide8.packed.counts["bvh_nodes"]).all()


@pytest.mark.parametrize("width", [4, 8])
def test_reference_refuses_wide_trees(width):
    from backends.reference.backend import ReferenceBackend
    from engine.errors import AberrantError

    packer = ScenePacker("f64", camera_relative=False, bvh_width=width)
    updates = packer.sync(small_scene())
    assert packer.packed is not None
    with pytest.raises(AberrantError, match="bvh_width=2"):
        ReferenceBackend().upload(packer.packed, updates)


def test_compact_bvh_packing_links_every_asset():
    """bvh_compact=True: each asset's records start with a header the instances point at; links are absolute;
    the stack depth is the binary tree's; the reference refuses them; GLSL asks for them, OpenCL does not."""
    from backends import shared
    from backends.glsl.backend import GlslBackend
    from backends.opencl.backend import OpenClBackend
    from backends.reference.backend import ReferenceBackend
    from engine import layout
    from engine.errors import AberrantError

    scene = small_scene()
    scene.add_mesh("ball", "sphere", position=(0, 2, -3))
    binary = ScenePacker(bvh_width=2)
    binary.sync(scene)
    packer = ScenePacker(bvh_compact=True)
    updates = packer.sync(scene)
    assert binary.packed is not None and packer.packed is not None
    records, count = packer.packed.tables["bvh_nodes"], packer.packed.counts["bvh_nodes"]
    assert records.dtype == layout.BVH_COMPACT_NODE_DTYPE
    np.testing.assert_array_equal(packer.packed.tables["triangles"], binary.packed.tables["triangles"])
    roots = np.unique(packer.packed.tables["instances"]["meta"][: packer.packed.counts["instances"], 0])
    headers = np.flatnonzero(records["child1"][:count, 3] == -1)
    np.testing.assert_array_equal(roots, headers)
    assert len(headers) >= 2  # box and sphere: the second asset's links carry offsets
    mask = (1 << layout.BVH_LINK_SHIFT) - 1
    links = np.concatenate(
        [records["child0"][:count, 3], records["child1"][:count, 3][records["child1"][:count, 3] >= 0]]
    )
    leaf, inner = links[links & mask > 0], links[links & mask == 0] >> layout.BVH_LINK_SHIFT
    assert ((leaf >> layout.BVH_LINK_SHIFT) + (leaf & mask) <= packer.packed.counts["triangles"]).all()
    assert ((inner < count) & ~np.isin(inner, headers)).all()
    covered = np.concatenate([np.arange(k >> 7, (k >> 7) + (k & mask)) for k in leaf])
    np.testing.assert_array_equal(np.sort(covered), np.arange(packer.packed.counts["triangles"]))
    nodes = binary.packed.tables["bvh_nodes"]
    assert shared.bvh_depth(records, count) == shared.bvh_depth(nodes, binary.packed.counts["bvh_nodes"])
    assert shared.bvh_defines(records, count)["BVH_COMPACT"] == 1
    assert shared.bvh_defines(nodes, binary.packed.counts["bvh_nodes"])["BVH_COMPACT"] == 0
    with pytest.raises(AberrantError, match="bvh_compact=False"):
        ReferenceBackend().upload(packer.packed, updates)
    with pytest.raises(ValueError, match="bvh_compact"):
        ScenePacker(bvh_width=4, bvh_compact=True)
    assert GlslBackend.bvh_compact and GlslBackend.bvh_width == 2
    assert not OpenClBackend.bvh_compact and not ReferenceBackend.bvh_compact


def test_the_checker_feature_follows_the_materials() -> None:
    """No material with a checker compiles its code out; a mesh edit that adds or removes one changes the
    features (a new kernel variant), and the settings row goes up with them."""
    scene = small_scene()
    packer = ScenePacker("f32")
    packer.sync(scene)
    assert packer.packed is not None and packer.packed.features.checker
    assert packer.packed.features.defines()["HAS_CHECKER"] == 1
    floor = scene.entity("floor")
    scene.set(floor, Mesh("plane"))
    assert "settings" in {u.table for u in packer.sync(scene)}
    assert not packer.packed.features.checker and packer.packed.features.defines()["HAS_CHECKER"] == 0
    scene.set(floor, Mesh("plane", checker=0.25))
    assert "settings" in {u.table for u in packer.sync(scene)}
    assert packer.packed.features.checker

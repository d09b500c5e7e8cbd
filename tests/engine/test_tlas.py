"""The top-level tree over instances (engine/tlas.py, ``tlas_nodes``): its shape, its incremental updates, and
frames of many-instance scenes, moved instances included, against the reference in every backend."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from conftest import require_backend
from scenes import upload_to_reference
from test_parity import DEPTH_MEDIAN_MAX, F64_DEPTH_P99_MAX, FAST_BACKENDS, MISMATCH_MAX, assert_clean, compare

from backends.base import AOVS
from backends.upload import SceneUploader
from components import Transform
from engine.camera_view import scene_camera
from engine.layout import TLAS_NODE_DTYPE
from engine.packed import TableUpdate
from engine.packing import ScenePacker
from engine.scene import Scene
from engine.tlas import FAT_MARGIN, AabbTree, collect
from engine.tlas_wide import WideTlas


def random_bounds(n: int, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    lo = rng.uniform(-20.0, 20.0, (n, 3))
    return lo, lo + rng.uniform(0.0, 3.0, (n, 3)) * (rng.random((n, 3)) > 0.1)  # some flat (planes)


def check_tree(tree: AabbTree, lo: np.ndarray, hi: np.ndarray) -> None:
    """Every instance in exactly one leaf, reachable from the root; parents hold their children; fat leaves
    hold the exact bounds; parent links and depth agree with the nodes."""
    nodes = tree.nodes
    n = len(lo)
    assert nodes.dtype == TLAS_NODE_DTYPE
    if n == 0:
        assert tree.count == 0 and len(nodes) == 1
        return
    assert tree.count == len(nodes) == 2 * n - 1
    seen: list[int] = []
    stack, depth = [(0, 1)], 0
    while stack:
        node, level = stack.pop()
        depth = max(depth, level)
        if nodes["count"][node] > 0:
            assert nodes["count"][node] == 1
            row = int(nodes["first"][node])
            seen.append(row)
            assert tree.leaf[row] == node
            assert np.all(nodes["bounds_min"][node] <= lo[row]) and np.all(nodes["bounds_max"][node] >= hi[row])
            assert np.all(tree.fat_lo[row] <= lo[row]) and np.all(tree.fat_hi[row] >= hi[row])
            continue
        for kid in (int(nodes["first"][node]), int(nodes["first"][node]) + 1):
            assert tree.parent[kid] == node
            assert np.all(nodes["bounds_min"][node] <= nodes["bounds_min"][kid])
            assert np.all(nodes["bounds_max"][node] >= nodes["bounds_max"][kid])
            stack.append((kid, level + 1))
    assert sorted(seen) == list(range(n))
    assert depth == tree.depth


@pytest.mark.parametrize("n", [0, 1, 2, 3, 17, 300])
def test_build_reaches_every_instance_once_and_bounds_nest(n: int) -> None:
    lo, hi = random_bounds(n)
    tree = AabbTree.build(lo, hi)
    check_tree(tree, lo, hi)
    if n > 1:
        assert tree.depth <= 2 * int(np.ceil(np.log2(n))) + 2  # balanced enough for a small stack


def test_a_floor_spanning_the_scene_sits_near_the_root() -> None:
    """The SAH keeps a huge plane out of the small boxes' subtree: rays over the boxes never meet it."""
    lo, hi = random_bounds(40, seed=8)
    lo = np.vstack([lo * 0.1, [[-100.0, -1.0, -100.0]]])
    hi = np.vstack([hi * 0.1, [[100.0, -1.0, 100.0]]])
    tree = AabbTree.build(lo, hi)
    check_tree(tree, lo, hi)
    floor_leaf = int(tree.leaf[40])
    assert tree.parent[floor_leaf] == 0


def test_small_nodes_split_by_surface_area_not_at_the_median() -> None:
    """Seven boxes, two at one end of a street and five at the other: the SAH keeps the two apart (a median
    split would put a far box with them, and a ray near them would walk both ends)."""
    x = np.array([0.0, 1.0, 100.0, 101.0, 102.0, 103.0, 104.0])
    lo = np.column_stack([x, np.zeros(7), np.zeros(7)])
    hi = lo + 0.5
    tree = AabbTree.build(lo, hi)
    check_tree(tree, lo, hi)
    first = int(tree.nodes["first"][0])
    halves = [sorted(collect(tree.nodes, child, lambda a, b: True)) for child in (first, first + 1)]
    assert sorted(halves) == [[0, 1], [2, 3, 4, 5, 6]]


def test_leaves_start_tight_and_a_moved_instance_gets_a_fat_box() -> None:
    """Static instances keep their exact boxes (a ray walks no more than they need); the first move out of
    one gives that instance alone a fat box, each axis grown by the margin."""
    lo, hi = np.array([[0.0, 0.0, 0.0], [0.0, 5.0, 0.0]]), np.array([[2.0, 1.0, 4.0], [40.0, 5.0, 40.0]])
    tree = AabbTree.build(lo, hi)
    np.testing.assert_array_equal(tree.fat_lo, lo)
    np.testing.assert_array_equal(tree.fat_hi, hi)
    lo, hi = lo + 0.5, hi + 0.5
    tree.update([0, 1], lo, hi)  # both escape: a rebuild, over the new fat boxes
    np.testing.assert_allclose(tree.fat_hi[0] - hi[0], FAT_MARGIN * np.array([2.0, 1.0, 4.0]))
    # A plane's thin axis grows by a tenth of its width's margin, not by nothing (and not by its width).
    np.testing.assert_allclose(tree.fat_hi[1] - hi[1], FAT_MARGIN * np.array([40.0, 4.0, 40.0]))


def test_update_inside_the_fat_box_changes_nothing_outside_refits_the_path() -> None:
    lo, hi = random_bounds(64)
    tree = AabbTree.build(lo, hi)
    lo[5] += 1e-3
    hi[5] += 1e-3
    assert tree.update([5], lo[5:6], hi[5:6])  # out of its tight leaf: now a fat one
    before = tree.nodes.copy()
    nudge = 0.5 * np.min(tree.fat_hi[5] - hi[5])
    assert tree.update([5], lo[5:6] + nudge, hi[5:6] + nudge) == []
    np.testing.assert_array_equal(tree.nodes, before)
    lo[5] += 30.0
    hi[5] += 30.0
    changed = tree.update([5], lo[5:6], hi[5:6])
    assert changed is not None and 1 <= len(changed) <= tree.depth
    assert int(tree.leaf[5]) in changed and 0 in changed
    differs = np.flatnonzero(
        np.any(
            before.view(np.uint8).reshape(len(before), -1) != tree.nodes.view(np.uint8).reshape(len(before), -1), axis=1
        )
    )
    assert set(differs) <= set(changed)
    check_tree(tree, lo, hi)
    assert tree.refits == 2 and tree.rebuilds == 1


def test_many_escaping_at_once_rebuild() -> None:
    lo, hi = random_bounds(64)
    tree = AabbTree.build(lo, hi)
    rows = np.arange(0, 64, 2)
    lo[rows] += 10.0
    hi[rows] += 10.0
    assert tree.update(rows, lo[rows], hi[rows]) is None
    assert tree.rebuilds == 2
    check_tree(tree, lo, hi)


def test_translate_keeps_the_tree_valid() -> None:
    lo, hi = random_bounds(50)
    tree = AabbTree.build(lo, hi)
    delta = np.array([16.0, -32.0, 0.0])
    tree.translate(delta, lo - delta, hi - delta)
    check_tree(tree, lo - delta, hi - delta)


# --- the packer ---------------------------------------------------------------------------------------


def many_boxes(count: int = 60, seed: int = 11) -> Scene:
    """A floor and ``count`` boxes of random size and turn, spread in front of the camera."""
    rng = np.random.default_rng(seed)
    scene = Scene("many-boxes")
    scene.add_mesh("floor", "plane", position=(0.0, -2.0, -4.0), scale=(30.0, 1.0, 30.0), checker=0.5)
    for k in range(count):
        scene.add_mesh(
            f"box{k}",
            "box",
            position=tuple(rng.uniform([-6.0, -2.0, -12.0], [6.0, 3.0, 1.0])),
            euler_deg=tuple(rng.uniform(-180.0, 180.0, 3)),
            scale=tuple(rng.uniform(0.2, 1.2, 3)),
            color=tuple(rng.uniform(0.2, 1.0, 3)),
        )
    scene.set_camera((0.0, 1.5, 5.0), look_at=(0.0, 0.0, -4.0), fov_deg=70.0)
    return scene


def move(scene: Scene, name: str, by: tuple[float, float, float]) -> None:
    entity = scene.entity(name)
    t = scene.get(entity, Transform)
    scene.set(entity, replace(t, position=tuple(np.add(t.position, by))))


def check_wide(wide: WideTlas, tree: AabbTree) -> None:
    """The wide table is the binary tree's: each instance row in one leaf lane, each lane's box its binary
    node's (refits included), interior lanes naming later rows, empty lanes last in their row."""
    width, nodes = wide.width, wide.nodes
    if width == 2:
        assert nodes is tree.nodes and wide.count == tree.count
        return
    kind = nodes["count"].reshape(len(nodes), width)
    child = nodes["child"].reshape(len(nodes), width)
    assert sorted(child[kind == 1]) == list(range(len(tree.leaf)))
    inner = child[kind == 0]
    assert sorted(inner) == list(range(1, len(nodes))) and np.all(inner > np.nonzero(kind == 0)[0])
    assert np.all(np.diff(kind == -1, axis=1) >= 0)  # used lanes are a prefix
    for node in np.flatnonzero(wide.lane >= 0):
        row, k = divmod(int(wide.lane[node]), width)
        for axis, name in enumerate("xyz"):
            assert nodes[f"lo_{name}"][row].reshape(-1)[k] == tree.nodes["bounds_min"][node, axis]
            assert nodes[f"hi_{name}"][row].reshape(-1)[k] == tree.nodes["bounds_max"][node, axis]
    leaves = np.flatnonzero(tree.nodes["count"] > 0)
    assert np.all(wide.lane[leaves] >= 0)


def packed_tree_is_valid(packer: ScenePacker) -> None:
    packed = packer.packed
    assert packed is not None
    n = packed.counts["instances"]
    table = packed.tables["instances"]
    check_tree(packer.tlas, table["bounds_min"][:n, :3].astype(float), table["bounds_max"][:n, :3].astype(float))
    assert packed.tables["tlas_nodes"] is packer.tlas_wide.nodes
    assert packed.counts["tlas_nodes"] == len(packer.tlas_wide.nodes)
    check_wide(packer.tlas_wide, packer.tlas)


@pytest.mark.parametrize("width", [4, 8])
@pytest.mark.parametrize("n", [0, 1, 2, 5, 40, 300])
def test_wide_tree_holds_the_binary_trees_boxes(width: int, n: int) -> None:
    tree = AabbTree.build(*random_bounds(n))
    wide = WideTlas.of(tree, width)
    if n == 0:
        assert wide.count == 0 and len(wide.nodes) == 1 and np.all(wide.nodes["count"] == -1)
        return
    check_wide(wide, tree)
    assert len(wide.nodes) < max(2, len(tree.nodes) / (width - 2))  # about (n - 1) / (width - 1) rows


@pytest.mark.parametrize("width", [2, 4, 8])
def test_packer_small_move_one_instance_row_large_move_a_few_tree_rows(width: int) -> None:
    scene = many_boxes()
    packer = ScenePacker(tlas_width=width)
    packer.sync(scene)
    packed_tree_is_valid(packer)
    row = packer._instance_row[scene.entity("box7")]
    move(scene, "box7", (0.01, 0.0, 0.0))  # out of its tight leaf: the leaf becomes fat, its path refitted
    updates = packer.sync(scene)
    assert updates[0] == TableUpdate("instances", range(row, row + 1))
    assert {u.table for u in updates[1:]} == {"tlas_nodes"} and all(u.rows is not None for u in updates[1:])
    move(scene, "box7", (0.01, 0.0, 0.0))
    assert packer.sync(scene) == [TableUpdate("instances", range(row, row + 1))]
    move(scene, "box7", (5.0, 0.0, 0.0))
    updates = packer.sync(scene)
    assert updates[0] == TableUpdate("instances", range(row, row + 1))
    tree_rows = [u.rows for u in updates if u.table == "tlas_nodes"]
    assert {u.table for u in updates} == {"instances", "tlas_nodes"} and all(r is not None for r in tree_rows)
    assert 1 <= sum(len(r) for r in tree_rows) <= packer.tlas.depth  # the leaf's row and some of its ancestors
    packed_tree_is_valid(packer)
    assert packer.sync(scene) == []


@pytest.mark.parametrize("width", [2, 8])
def test_packer_rebuilds_on_added_deleted_or_many_moved_instances(width: int) -> None:
    scene = many_boxes()
    packer = ScenePacker(tlas_width=width)
    packer.sync(scene)
    scene.add_mesh("extra", "sphere", position=(0.0, 4.0, -3.0))
    assert TableUpdate("tlas_nodes") in packer.sync(scene)
    packed_tree_is_valid(packer)
    scene.delete(scene.entity("box3"))
    assert TableUpdate("tlas_nodes") in packer.sync(scene)
    packed_tree_is_valid(packer)
    for k in range(0, 40, 2):
        move(scene, f"box{k}", (0.0, 6.0, 0.0))
    updates = packer.sync(scene)
    assert TableUpdate("tlas_nodes") in updates and packer.tlas.rebuilds >= 2
    packed_tree_is_valid(packer)


@pytest.mark.parametrize("width", [2, 8])
def test_origin_shift_moves_the_tree_with_the_instances(width: int) -> None:
    scene = many_boxes()
    packer = ScenePacker(origin_cell=4.0, tlas_width=width)
    packer.sync(scene)
    camera = scene.camera_entity
    t = scene.get(camera, Transform)
    scene.set(camera, replace(t, position=(9.0, 1.5, 5.0)))
    updates = packer.sync(scene)
    assert TableUpdate("instances") in updates and TableUpdate("tlas_nodes") in updates
    packed_tree_is_valid(packer)


# --- frames --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("backend_name", "precision"), FAST_BACKENDS)
def test_moved_instances_render_as_the_reference_sees_them(backend_factory, backend_name, precision) -> None:
    """60 boxes; some moved within their fat leaves, some far (refits), uploaded incrementally: the
    device's tree is the host's, and the frame matches the reference's within the parity thresholds."""
    require_backend(backend_name)
    backend = backend_factory(backend_name, precision)
    scene = many_boxes()
    size = (96, 72)
    try:
        uploader = SceneUploader(backend)
        uploader.sync(scene)
        for name, by in (("box1", (0.02, 0.0, 0.0)), ("box2", (-4.0, 1.0, 2.0)), ("box9", (3.0, -1.0, -5.0))):
            move(scene, name, by)
            uploader.sync(scene)
        tree = uploader.packer.tlas_wide.nodes
        assert backend.read_table("tlas_nodes")[: tree.nbytes] == tree.tobytes()
        fast = backend.render(scene_camera(scene), *size, AOVS)
        truth = upload_to_reference(scene).render(scene_camera(scene), *size, AOVS)
    finally:
        scene.close()
    assert_clean(fast)
    result = compare(fast, truth)
    assert (truth.instance >= 0).mean() > 0.5
    assert result.mismatch <= MISMATCH_MAX, result
    if precision == "f64":
        assert result.depth_p99 <= F64_DEPTH_P99_MAX, result
    else:
        assert result.depth_median <= DEPTH_MEDIAN_MAX, result


@pytest.mark.parametrize("backend_name", ["glsl", "opencl"])
def test_the_tree_and_the_loop_give_identical_frames(backend_factory, backend_name) -> None:
    """Traversal order is unseen: hits at equal t go to the lower instance row either way."""
    require_backend(backend_name)
    backend = backend_factory(backend_name, "f32")
    scene = many_boxes(seed=4)
    # Coincident duplicates: equal t on two instances, the lower row must win in both orders.
    scene.add_mesh("twin", "box", position=(0.0, 0.0, -2.0), scale=1.5)
    scene.add_mesh("twin2", "box", position=(0.0, 0.0, -2.0), scale=1.5)
    twin = scene.entity("twin")
    try:
        SceneUploader(backend).sync(scene)
        frames = []
        for use in (1, 0):
            backend.extra_defines = {"USE_TLAS": use}
            frames.append(backend.render(scene_camera(scene), 80, 60, AOVS))
    finally:
        backend.extra_defines = {}
        scene.close()
    for name in AOVS:
        np.testing.assert_array_equal(frames[0].aov(name), frames[1].aov(name), err_msg=name)
    assert twin in frames[0].instance

"""The space tables (engine/packing_space.py): portal and box rows and their trees, kept per entity; the boxes'
clearances (engine/box_clearance.py) found through trees, the same as the brute force over every pair."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scenes import crowded

from components import Aberration, Transform
from engine import clearances as clearances_module
from engine.affine_batch import rotation_batch, trs_inverse_batch
from engine.box_clearance import CLEARANCE_SLACK, box_solids, separation
from engine.camera_view import CAMERA_BOX_PER_RAY, camera_box
from engine.clearances import BoxClearances, box_clearances
from engine.packed import TableUpdate
from engine.packing import ScenePacker
from engine.packing_space import BOX_CORNERS, QUAD_CORNERS, corner_bounds
from engine.scene import Scene
from engine.space_wide import ROWS
from engine.tlas import AabbTree

# --- the clearances against every pair --------------------------------------------------------------------


def brute_clearances(world_to_local: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """box_clearances by its definition: every box against every instance and every other box."""
    n = len(world_to_local)
    if n == 0:
        return np.zeros(0), np.zeros(0)
    centre, half, normals = box_solids(world_to_local)
    slack = CLEARANCE_SLACK * (1.0 + np.linalg.norm(centre, axis=1) + 2.0 * np.linalg.norm(half, axis=(1, 2)))
    instance = np.full(n, 1e30)
    if len(lo):
        c2, h2 = 0.5 * (lo + hi), np.einsum("mj,jk->mjk", 0.5 * (hi - lo), np.eye(3))
        slack_i = CLEARANCE_SLACK * (np.linalg.norm(c2, axis=1) + np.linalg.norm(hi - lo, axis=1))
        for b in range(n):
            world = np.broadcast_to(np.eye(3), (len(lo), 3, 3))
            axes = np.concatenate([np.broadcast_to(normals[b], (len(lo), 3, 3)), world], axis=1)
            gap = separation(centre[b], half[b], c2, h2, axes) - slack_i
            instance[b] = gap.min() if np.isfinite(gap).all() else 0.0
    boxes = np.full(n, 1e30)
    for b in range(n):
        for c in range(n):
            if c != b:
                axes = np.concatenate([normals[b], normals[c]], axis=0)
                gap = float(separation(centre[b], half[b], centre[c], half[c], axes)) - slack[c]
                boxes[b] = min(boxes[b], gap if np.isfinite(gap) else 0.0)
    instance = np.where(np.isfinite(instance), instance - slack, 0.0)
    boxes = np.where(np.isfinite(boxes), boxes - slack, 0.0)
    return np.maximum(instance, 0.0), np.maximum(boxes, 0.0)


def random_boxes(rng: np.random.Generator, n: int, spread: float) -> np.ndarray:
    p = rng.uniform(-spread, spread, (n, 3))
    return trs_inverse_batch(p, rotation_batch(rng.normal(size=(n, 4))), rng.uniform(0.1, 3.0, (n, 3)))


def random_instances(rng: np.random.Generator, m: int, spread: float) -> tuple[np.ndarray, np.ndarray]:
    lo = rng.uniform(-spread, spread, (m, 3))
    return lo, lo + rng.uniform(0.0, 2.0, (m, 3)) * (rng.random((m, 3)) > 0.1)


class Pairs:
    """BRUTE_PAIRS set for a block: 0 takes the trees' branch and bound for every search among boxes, a large
    value every pair at once (below it, the moves' searches do by default)."""

    def __init__(self, limit: int) -> None:
        self.limit = limit

    def __enter__(self) -> None:
        self.saved, clearances_module.BRUTE_PAIRS = clearances_module.BRUTE_PAIRS, self.limit

    def __exit__(self, *_: object) -> None:
        clearances_module.BRUTE_PAIRS = self.saved


SEARCHES = [pytest.param(0, id="trees"), pytest.param(1 << 20, id="every-pair")]


@pytest.mark.parametrize("limit", SEARCHES)
@settings(max_examples=40, deadline=None)
@given(n=st.integers(0, 60), m=st.integers(0, 40), spread=st.floats(1.0, 30.0), seed=st.integers(0, 2**32 - 1))
def test_box_clearances_are_the_brute_forces(limit, n, m, spread, seed):
    rng = np.random.default_rng(seed)
    boxes, (lo, hi) = random_boxes(rng, n, spread), random_instances(rng, m, spread)
    with Pairs(limit):
        fast = box_clearances(boxes, lo, hi)
    truth = brute_clearances(boxes, lo, hi)
    np.testing.assert_array_equal(fast[0], truth[0])
    np.testing.assert_array_equal(fast[1], truth[1])


@pytest.mark.parametrize("limit", SEARCHES)
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(n=st.integers(2, 50), m=st.integers(1, 30), seed=st.integers(0, 2**32 - 1))
def test_clearances_after_moves_are_the_brute_forces(limit, n, m, seed):
    """Boxes and instances moved a few at a time: the values searched again where a partner moved, lowered
    where a mover came nearer, equal the brute force's over the moved scene every time, through the trees
    and through every pair."""
    with Pairs(limit):
        moved_clearances_match(n, m, seed)


def moved_clearances_match(n: int, m: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    boxes, (lo, hi) = random_boxes(rng, n, 6.0), random_instances(rng, m, 6.0)
    clearances = BoxClearances()
    clearances.full(boxes, lo, hi)
    for _ in range(4):
        moved_boxes = sorted(set(rng.integers(0, n, int(rng.integers(0, 3))).tolist()))
        moved_instances = sorted(set(rng.integers(0, m, int(rng.integers(0, 3))).tolist()))
        boxes, lo, hi = boxes.copy(), lo.copy(), hi.copy()
        if moved_boxes:
            boxes[moved_boxes] = random_boxes(rng, len(moved_boxes), 6.0)
        step = rng.normal(size=(len(moved_instances), 3)) * 2.0
        lo[moved_instances] += step
        hi[moved_instances] += step
        clearances.moved(boxes, lo, hi, moved_boxes, moved_instances)
        instance, box = brute_clearances(boxes, lo, hi)
        np.testing.assert_array_equal(clearances.instance, instance)
        np.testing.assert_array_equal(clearances.box, box)


def test_degenerate_boxes_give_zero_clearances_as_the_brute_force():
    rng = np.random.default_rng(1)
    boxes, (lo, hi) = random_boxes(rng, 6, 5.0), random_instances(rng, 4, 5.0)
    boxes[2, 0, 0] = np.inf
    with np.errstate(all="ignore"):
        fast, truth = box_clearances(boxes, lo, hi), brute_clearances(boxes, lo, hi)
    np.testing.assert_array_equal(fast[0], truth[0])
    np.testing.assert_array_equal(fast[1], truth[1])


# --- the trees ------------------------------------------------------------------------------------------------


@settings(max_examples=30, deadline=None)
@given(st.integers(1, 200), st.integers(0, 2**32 - 1))
def test_tree_queries_find_every_box_they_should(n, seed):
    """rows_at / rows_on_segment / rows_in_box hold every row whose fat box the point, segment or box meets
    (brute force over the fat boxes), after a build and after moves (refits and rebuilds)."""
    rng = np.random.default_rng(seed)
    lo = rng.uniform(-20.0, 20.0, (n, 3))
    hi = lo + rng.uniform(0.0, 3.0, (n, 3))
    tree = AabbTree.build(lo, hi, slack=1e-5)
    for _ in range(3):
        rows = np.unique(rng.integers(0, n, int(rng.integers(1, 4))))
        shift = rng.normal(size=(len(rows), 3)) * 4.0
        lo[rows] += shift
        hi[rows] += shift
        tree.update(rows, lo[rows], hi[rows])
        assert np.all(tree.fat_lo <= lo) and np.all(tree.fat_hi >= hi)
        a, b = rng.uniform(-25.0, 25.0, (2, 3))
        box_lo, box_hi = np.minimum(a, b), np.maximum(a, b)
        inside = np.flatnonzero(np.all((tree.fat_lo <= a) & (a <= tree.fat_hi), axis=1))
        assert set(inside) <= set(tree.rows_at(a))
        overlap = np.flatnonzero(np.all((tree.fat_lo <= box_hi) & (box_lo <= tree.fat_hi), axis=1))
        assert set(overlap) <= set(tree.rows_in_box(box_lo, box_hi))
        ts = np.linspace(0.0, 1.0, 257)[:, None, None]
        points = a + ts * (b - a)
        crossed = np.flatnonzero(np.any(np.all((tree.fat_lo <= points) & (points <= tree.fat_hi), axis=2), axis=0))
        assert set(crossed) <= set(tree.rows_on_segment(a, b))


def move(scene: Scene, name: str, by: tuple[float, float, float]) -> None:
    entity = scene.entity(name)
    t = scene.get(entity, Transform)
    scene.set(entity, replace(t, position=tuple(np.add(t.position, by))))


@pytest.mark.parametrize("precision", ["f32", "f64"])
@pytest.mark.parametrize("kind", ["portals", "boxes"])
def test_moves_repack_rows_and_refit_and_equal_a_fresh_pack(precision, kind):
    """A moved portal re-packs its row and its source's and the gaps it changed; a moved box its row and the
    clearances it changed; each refits a few tree rows. The tables are byte for byte a fresh packer's of the
    moved scene."""
    scene = crowded(kind, 200, seed=11)
    scene.add_mesh("mover", "box", position=(0.0, 1.0, -1.0))
    packer = ScenePacker(precision)
    packer.sync(scene)
    table = "portals" if kind == "portals" else "aberrations"
    prefix = "p" if kind == "portals" else "a"
    for k, by in enumerate(((0.001, 0.0, 0.0), (3.0, 0.0, -2.0), (0.0, -0.5, 4.0))):
        move(scene, f"{prefix}{10 + 7 * k}", by)
        updates = packer.sync(scene)
        rows = sum(len(u.rows) for u in updates if u.table == table)
        assert all(u.rows is not None for u in updates), updates
        assert 1 <= rows <= 40, updates
        nodes = sum(len(u.rows) for u in updates if u.table == "space_nodes")
        # the leaf's path in the binary tree and in the 4-wide one (at most a wide node a binary level)
        assert nodes <= (2 + ROWS) * (packer.space.portal_tree.depth + packer.space.box_tree.depth)
        space, stored = packer.space, packer.packed.tables["space_nodes"]
        for wide, tree, root in zip(space._wide, (space.portal_tree, space.box_tree), space.wide_roots, strict=True):
            rows = wide.rows(tree.nodes, root)  # the wide form of the refit tree, whole: what the refit wrote
            assert stored[root : root + len(rows)].tobytes() == rows.tobytes()
    move(scene, "mover", (0.5, 0.0, 0.0))
    packer.sync(scene)
    fresh = ScenePacker(precision)
    fresh.sync(scene)
    for name in ("portals", "aberrations", "settings"):
        assert packer.packed.tables[name].tobytes() == fresh.packed.tables[name].tobytes(), name
    assert packer.sync(scene) == []
    scene.close()


def test_a_priority_change_repacks_the_boxes_and_a_mode_change_the_features():
    scene = crowded("boxes", 30, seed=12)
    packer = ScenePacker()
    packer.sync(scene)
    entity = scene.entity("a4")
    box = scene.get(entity, Aberration)
    scene.set(entity, replace(box, priority=box.priority + 10))
    updates = packer.sync(scene)
    assert TableUpdate("aberrations") in updates and TableUpdate("space_nodes") in updates
    assert packer.packed.tables["aberrations"]["meta"][29, 3] == entity  # the highest priority: the last row
    for k in range(30):
        entity = scene.entity(f"a{k}")
        scene.set(entity, replace(scene.get(entity, Aberration), mode="metric"))
    packer.sync(scene)
    assert packer.packed.features.aberration_modes == {"metric"}
    scene.close()


@pytest.mark.parametrize("seed", range(6))
def test_the_camera_box_through_the_tree_is_the_loops(seed):
    """Among many boxes the camera's box comes from the boxes whose leaves hold the camera: the loop's box
    wherever the loop gives one (per ray only where a box near the camera demands it)."""
    scene = crowded("boxes", 120, seed=seed)
    rng = np.random.default_rng(seed)
    packer = ScenePacker("f32")
    packer.sync(scene)
    packed = packer.packed
    rows = packed.tables["aberrations"][: packed.counts["aberrations"]]
    tree = (packed.tables["space_nodes"], int(packed.tables["settings"]["space_roots"][0, 1]))
    for _ in range(40):
        p = rng.uniform([-4.0, 0.2, -7.0], [4.0, 3.0, 0.5]) - packed.origin
        loop, fast = camera_box(p, rows), camera_box(p, rows, tree)
        assert fast == loop or loop == CAMERA_BOX_PER_RAY
    scene.close()


@pytest.mark.parametrize("kind", ["portals", "boxes"])
def test_an_origin_shift_repacks_the_rows_and_moves_the_trees(kind):
    """The camera leaves its cell: every portal and box row is packed anew around the new origin (a fresh
    packer's bytes), and the trees still hold every quad and box."""
    scene = crowded(kind, 60, seed=13)
    packer = ScenePacker("f32", origin_cell=4.0)
    packer.sync(scene)
    camera = scene.camera_entity
    t = scene.get(camera, Transform)
    scene.set(camera, replace(t, position=(9.0, 1.8, 6.0)))
    updates = packer.sync(scene)
    table = "portals" if kind == "portals" else "aberrations"
    assert TableUpdate(table) in updates and TableUpdate("space_nodes") in updates
    fresh = ScenePacker("f32", origin_cell=4.0)
    fresh.sync(scene)
    assert np.array_equal(packer.packed.origin, fresh.packed.origin)
    assert packer.packed.tables[table].tobytes() == fresh.packed.tables[table].tobytes()
    tree = packer.space.portal_tree if kind == "portals" else packer.space.box_tree
    rows = packer.packed.tables[table]["world_to_local"][: packer.packed.counts[table]].astype(np.float64)
    linear = np.linalg.inv(rows[:, :, :3])
    forward = np.concatenate([linear, -np.einsum("nij,nj->ni", linear, rows[:, :, 3])[:, :, None]], axis=2)
    lo, hi = corner_bounds(forward, QUAD_CORNERS if kind == "portals" else BOX_CORNERS)
    assert np.all(tree.fat_lo <= lo + 1e-5) and np.all(tree.fat_hi >= hi - 1e-5)
    scene.close()

"""The 4-wide forms of the trees over portals and boxes (engine/space_wide.py)."""

from __future__ import annotations

import numpy as np
import pytest

from backends.shared import wide_space_depth
from engine.space_wide import ROWS, WIDTH, WideTree, reserved_rows
from engine.tlas import SPACE_SLACK, AabbTree


def tree_over(n: int, seed: int) -> AabbTree:
    rng = np.random.default_rng(seed)
    lo = rng.uniform(-20.0, 20.0, (n, 3))
    return AabbTree.build(lo, lo + rng.uniform(0.1, 2.0, (n, 3)), slack=SPACE_SLACK)


def lanes(rows: np.ndarray, wide: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(lo (4, 3), hi (4, 3), child (4,)) of wide node ``wide`` in stored rows."""
    raw = rows.view(np.float32).reshape(-1, ROWS * 8)[wide]
    lo = raw[0:12].reshape(3, WIDTH).T
    hi = raw[12:24].reshape(3, WIDTH).T
    return lo, hi, raw[24:28].view(np.int32)


@pytest.mark.parametrize("n", [1, 2, 3, 5, 17, 300])
def test_every_leaf_in_one_slot_and_each_slot_the_binary_nodes_box(n):
    tree = tree_over(n, n)
    wide = WideTree(tree.nodes, tree.count)
    base = 1000
    rows = wide.rows(tree.nodes, base)
    assert len(rows) <= reserved_rows(n)
    leaves: list[int] = []
    for w in range(len(wide.slots)):
        lo, hi, child = lanes(rows, w)
        for slot, binary in enumerate(wide.slots[w]):
            if binary < 0:
                assert child[slot] == 0
                continue
            assert np.array_equal(lo[slot], tree.nodes["bounds_min"][binary])
            assert np.array_equal(hi[slot], tree.nodes["bounds_max"][binary])
            if tree.nodes["count"][binary] > 0:
                leaves.append(~int(child[slot]))
            else:
                assert child[slot] > base and (child[slot] - base) % ROWS == 0
    assert sorted(leaves) == list(range(n))
    assert wide.depth <= tree.depth
    table = np.concatenate([np.zeros(base, rows.dtype), rows])
    assert wide_space_depth(table, base) == wide.depth


def test_a_refit_names_the_wide_nodes_on_the_moved_leafs_path():
    """Only the wide nodes holding a changed binary node change: rewriting those gives the whole form."""
    tree = tree_over(200, 3)
    wide = WideTree(tree.nodes, tree.count)
    before = wide.rows(tree.nodes, 0).view(np.int32).reshape(-1, ROWS * 8)  # bits: a leaf link is a NaN
    changed = tree.update([17], tree.fat_lo[[17]] + 30.0, tree.fat_hi[[17]] + 30.0)
    assert changed
    touched = wide.changed(changed)
    assert 1 <= len(touched) <= wide.depth and int(wide.wide_of[tree.leaf[17]]) in touched
    after = wide.rows(tree.nodes, 0).view(np.int32).reshape(-1, ROWS * 8)
    differ = np.flatnonzero(np.any(before != after, axis=1))
    assert set(differ.tolist()) <= set(touched) and differ.size

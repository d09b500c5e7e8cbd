"""The BVH's other forms: the 4- and 8-wide trees collapsed from the binary SAH tree (OpenCL) with their
blocks of 4 triangles, and the compact binary records on a 16-bit grid (GLSL on llvmpipe); each checked
against the binary tree it comes from. The binary build itself is in ``test_bvh.py``.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from bvh_meshes import (
    MESHES,
    PARAMS,
    PLAIN,
    from_corners,
    integer_soups,
    refuse_to_build,
    same_tree,
    soup,
)
from hypothesis import given, settings
from hypothesis import strategies as st

import engine.bvh_cache as cache_mod
import engine.bvh_compact as compact_mod
from engine import layout
from engine.bvh import Bvh, BvhParams, build_bvh
from engine.bvh_cache import cached_bvh, clear_memory_cache
from engine.bvh_compact import compact, offset_compact
from engine.bvh_wide import collapse, leaf_blocks
from engine.layout import BVH4_NODE_DTYPE, BVH8_NODE_DTYPE

# --- the 4- and 8-wide trees (collapse) and their triangle blocks ----------------------

WIDE = [4, 8]


def check_wide(wide: Bvh, binary: Bvh, verts: np.ndarray, faces: np.ndarray, width: int = 4) -> None:
    """Every triangle in exactly one leaf slot, every wide node reached once, child boxes hold their subtree."""
    nodes, m = wide.nodes, len(faces)
    assert nodes.dtype == {4: BVH4_NODE_DTYPE, 8: BVH8_NODE_DTYPE}[width] and wide.width == width
    np.testing.assert_array_equal(wide.triangle_order, binary.triangle_order)

    def lanes(field: str) -> np.ndarray:  # (N, width): width 8 stores two 4-vector rows per field
        return nodes[field].reshape(len(nodes), width)

    lo = np.stack([lanes("lo_x"), lanes("lo_y"), lanes("lo_z")], axis=-1)  # (N, width, 3)
    hi = np.stack([lanes("hi_x"), lanes("hi_y"), lanes("hi_z")], axis=-1)
    child, count = lanes("child").astype(np.int64), lanes("count").astype(np.int64)
    assert (count[:, 0] >= 0).all(), "slot 0 is never empty"
    used = count >= 0
    assert (used[:, 1:] <= used[:, :-1]).all(), "empty slots come last"
    visits = np.zeros(len(nodes), np.int64)
    covered = np.zeros(m, np.int64)
    corners = verts[faces[binary.triangle_order]]  # (m, 3, 3) in leaf order

    def walk(i: int) -> tuple[np.ndarray, np.ndarray, int]:
        """Visit node i; returns the exact bounds of the triangles under it and its number of leaves."""
        visits[i] += 1
        box_lo, box_hi = np.full(3, np.inf, np.float32), np.full(3, -np.inf, np.float32)
        leaves_under = 0
        for s in range(width):
            if count[i, s] < 0:
                continue
            if count[i, s] > 0:
                f, n = child[i, s], count[i, s]
                assert f >= 0 and f + n <= m
                covered[f : f + n] += 1
                pts = corners[f : f + n].reshape(-1, 3)
                sub_lo, sub_hi = pts.min(axis=0), pts.max(axis=0)
                leaves_under += 1
            else:
                assert i < child[i, s] < len(nodes), f"node {i}: bad child {child[i, s]}"
                sub_lo, sub_hi, sub_leaves = walk(int(child[i, s]))
                leaves_under += sub_leaves
            assert (lo[i, s] < sub_lo).all() and (sub_hi < hi[i, s]).all(), "child box holds its subtree (outward)"
            box_lo, box_hi = np.minimum(box_lo, sub_lo), np.maximum(box_hi, sub_hi)
        if (count[i] == 0).any():
            assert leaves_under > width, f"node {i}: its {leaves_under} leaves would fit in its own slots"
        return box_lo, box_hi, leaves_under

    walk(0)
    assert (visits == 1).all(), "every wide node is reached exactly once"
    assert (covered == 1).all(), "every triangle is in exactly one leaf"
    leaves = np.sort(count[count > 0])
    np.testing.assert_array_equal(leaves, np.sort(binary.nodes["count"][binary.nodes["count"] > 0]))
    assert wide.depth() <= binary.depth()


@pytest.mark.parametrize("width", WIDE)
@pytest.mark.parametrize("params", PARAMS, ids=["default", "leaf1-bins2", "leaf8-bins32"])
@pytest.mark.parametrize("name", list(MESHES))
def test_collapse_to_wide(name, params, width):
    verts, faces = MESHES[name]()
    binary = build_bvh(verts, faces, params)
    wide = collapse(binary, width)
    check_wide(wide, binary, verts, faces, width)
    if len(binary.nodes) > 1:  # a lone leaf gains a root node; otherwise pulling nodes up only removes terms
        assert wide.sah_cost() <= binary.sah_cost() + 1e-9
    if len(binary.nodes) >= 7:  # enough nodes to pull: the wide tree is strictly cheaper and shallower
        assert wide.sah_cost() < binary.sah_cost()
        assert len(wide.nodes) < len(binary.nodes)


@settings(max_examples=30, deadline=None)
@given(
    corners=integer_soups(60),
    leaf=st.integers(1, 5),
    width=st.sampled_from(WIDE),
)
def test_collapse_on_small_integer_soups(corners, leaf, width):
    verts, faces = from_corners(np.array(corners, np.float32) * 0.5)
    binary = build_bvh(verts, faces, BvhParams(split_ratio=0.0, max_leaf_size=leaf, bins=4))
    check_wide(collapse(binary, width), binary, verts, faces, width)


def test_collapse_fills_nodes_and_pulls_the_largest_child():
    """A balanced tree of 16 leaves collapses to a root of 4 nodes of 4 leaves each: 5 wide nodes."""
    verts, faces = from_corners([[[x, y, 0], [x + 0.5, y, 0], [x, y + 0.5, 0]] for x in range(4) for y in range(4)])
    binary = build_bvh(verts * 10, faces, BvhParams(split_ratio=0.0, max_leaf_size=1))
    wide = collapse(binary)
    check_wide(wide, binary, verts * 10, faces)
    assert len(wide.nodes) == 5 and (wide.nodes["count"] >= 0).all()
    with pytest.raises(ValueError, match="binary"):
        collapse(wide)
    with pytest.raises(ValueError, match="widths"):
        collapse(binary, 3)


def test_collapse_to_eight_fills_nodes():
    """The same 16 leaves at width 8: the root opens one half of 8 leaves whole (its subtree fits in 8 slots)
    beside the other half's two nodes, which fill a full node and one of 2 leaves: 3 wide nodes, where
    pulling by area alone made 9 (a root of 8 inner nodes of 2 leaves each)."""
    verts, faces = from_corners([[[x, y, 0], [x + 0.5, y, 0], [x, y + 0.5, 0]] for x in range(4) for y in range(4)])
    binary = build_bvh(verts * 10, faces, BvhParams(split_ratio=0.0, max_leaf_size=1))
    wide = collapse(binary, 8)
    check_wide(wide, binary, verts * 10, faces, 8)
    count = wide.nodes["count"].reshape(-1, 8)
    assert len(wide.nodes) == 3 and (count[0] >= 0).all() and (count[0] == 0).sum() == 2
    assert (count[1] == 1).all() and (count[2, :2] == 1).all() and (count[2, 2:] == -1).all()
    assert wide.sah_cost() < binary.sah_cost()


def test_collapse_keeps_few_half_empty_nodes():
    """A torus's 8-wide tree: most leaves share full nodes (top-down filling by area alone left 2 leaves in
    most nodes of the tori: 15408 of 25445 at 200k triangles)."""

    mesh = trimesh.creation.torus(major_radius=1.0, minor_radius=0.4, major_sections=60, minor_sections=30)
    verts, faces = np.asarray(mesh.vertices, np.float32), np.asarray(mesh.faces, np.int64)
    binary = build_bvh(verts, faces, PLAIN)
    wide = collapse(binary, 8)
    check_wide(wide, binary, verts, faces, 8)
    count = wide.nodes["count"].reshape(-1, 8)
    leaves = int((count > 0).sum())
    assert len(wide.nodes) < 2 * (leaves - 1) / 7, "within twice the fewest 8-wide nodes that hold the leaves"


@pytest.mark.parametrize("width", WIDE)
def test_leaf_blocks_cover_every_leaf_in_fours(width):
    verts, faces = soup(3000, seed=3)
    wide = collapse(build_bvh(verts, faces, BvhParams(split_ratio=0.0, max_leaf_size=6)), width)
    lanes, child = leaf_blocks(wide)
    count = wide.nodes["count"]
    assert lanes.shape[1] == 4 and child.shape == count.shape
    np.testing.assert_array_equal(child[count == 0], wide.nodes["child"][count == 0])
    seen = []
    for first_block, n, first_tri in zip(
        child[count > 0], count[count > 0], wide.nodes["child"][count > 0], strict=True
    ):
        block = lanes[first_block : first_block + (n + 3) // 4].ravel()
        np.testing.assert_array_equal(block[:n], np.arange(first_tri, first_tri + n))
        assert (block[n:] == -1).all(), "padding lanes are -1"
        seen.append(block[:n])
    np.testing.assert_array_equal(np.sort(np.concatenate(seen)), np.arange(len(faces)))
    assert len(lanes) == int(((count[count > 0] + 3) // 4).sum())


def test_wide_trees_are_cached_by_width(tmp_path, fresh_memory, monkeypatch):
    verts, faces = MESHES["icosphere"]()
    binary = cached_bvh(verts, faces, cache_dir=tmp_path)
    wide = cached_bvh(verts, faces, cache_dir=tmp_path, width=4)
    wide8 = cached_bvh(verts, faces, cache_dir=tmp_path, width=8)
    assert binary.width == 2 and wide.width == 4 and wide8.width == 8
    assert len(list((tmp_path / "bvh").glob("*.npz"))) == 3, "the width is part of the key"
    clear_memory_cache()
    monkeypatch.setattr(cache_mod, "build_bvh", refuse_to_build)
    monkeypatch.setattr(cache_mod, "collapse", refuse_to_build)
    same_tree(cached_bvh(verts, faces, cache_dir=tmp_path, width=4), wide)
    same_tree(cached_bvh(verts, faces, cache_dir=tmp_path, width=8), wide8)
    with pytest.raises(ValueError, match="width"):
        cached_bvh(verts, faces, cache_dir=tmp_path, width=3)


# --- compact records (GLSL) ------------------------------------------------------------------------


def _decodings(q: np.ndarray, origin: np.ndarray, scale: np.ndarray) -> list[np.ndarray]:
    """``origin + q * scale`` as a float32 kernel may compute it: unfused, fused (one rounding), and
    either with subnormals flushed to zero (inputs and result)."""
    q32 = q.astype(np.float32)
    tiny = np.finfo(np.float32).tiny

    def ftz(x: np.ndarray) -> np.ndarray:
        return np.where(np.abs(x) < tiny, np.float32(0), x).astype(np.float32)

    out = []
    for o, s in ((origin, scale), (ftz(origin), ftz(scale))):
        with np.errstate(over="ignore"):
            unfused = q32 * s + o
            fused = (q32.astype(np.float64) * s.astype(np.float64) + o.astype(np.float64)).astype(np.float32)
        out += [unfused, fused, ftz(unfused), ftz(fused)]
    return out


def _unpack(words: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(qlo, qhi) (N, 3) from a record's child.xyz words (N, 3)."""
    w = words.view(np.uint32).astype(np.int64)
    lo = np.stack([w[:, 0] & 0xFFFF, w[:, 0] >> 16, w[:, 1] & 0xFFFF], axis=1)
    hi = np.stack([w[:, 1] >> 16, w[:, 2] & 0xFFFF, w[:, 2] >> 16], axis=1)
    return lo, hi


def check_compact(records: np.ndarray, binary: Bvh) -> None:
    """Records mirror the binary tree: the header's frame and root link, each interior node's children's links,
    and decoded child boxes that contain the exact ones however the kernel rounds."""
    nodes = binary.nodes
    shift = layout.BVH_LINK_SHIFT
    origin = records["child0"][0, :3].copy().view(np.float32)
    scale = records["child1"][0, :3].copy().view(np.float32)
    assert records["child1"][0, 3] == -1 and (scale >= np.finfo(np.float32).tiny).all()
    for top in _decodings(np.full(3, layout.BVH_GRID_MAX), origin, scale):
        assert (top >= nodes["bounds_max"][0]).all() and (origin <= nodes["bounds_min"][0]).all()
    inner = np.flatnonzero(nodes["count"] == 0)
    assert len(records) == 1 + len(inner)
    record_of = {int(node): 1 + r for r, node in enumerate(inner)}

    def link(node: int) -> int:
        if nodes["count"][node] == 0:
            return record_of[node] << shift
        return int(nodes["first"][node]) << shift | int(nodes["count"][node])

    assert records["child0"][0, 3] == link(0)
    for field, offset in (("child0", 0), ("child1", 1)):
        kids = nodes["first"][inner] + offset
        np.testing.assert_array_equal(records[field][1:, 3], [link(int(k)) for k in kids])
        qlo, qhi = _unpack(records[field][1:, :3])
        for lo in _decodings(qlo, origin, scale):
            assert (lo <= nodes["bounds_min"][kids]).all(), field
        for hi in _decodings(qhi, origin, scale):
            assert (hi >= nodes["bounds_max"][kids]).all(), field


@pytest.mark.parametrize("params", PARAMS, ids=["default", "leaf1-bins2", "leaf8-bins32"])
@pytest.mark.parametrize("name", list(MESHES))
def test_compact_records_mirror_the_tree_conservatively(name, params):
    verts, faces = MESHES[name]()
    binary = build_bvh(verts, faces, params)
    check_compact(compact(binary), binary)


@settings(max_examples=40, deadline=None)
@given(
    corners=st.lists(
        st.lists(st.lists(st.floats(-1e3, 1e3, width=32), min_size=3, max_size=3), min_size=3, max_size=3),
        min_size=1,
        max_size=40,
    ),
    offset=st.sampled_from([0.0, 1e-30, 1e-39, -1e-39, 3.0, -7e4, 1e6]),
    leaf=st.integers(1, 4),
)
def test_compact_records_on_float_soups(corners, offset, leaf):
    """Any float boxes, near or far from the origin (grid steps below an ulp there): still conservative."""
    verts, faces = from_corners(np.array(corners, np.float32) + np.float32(offset))
    binary = build_bvh(verts, faces, BvhParams(split_ratio=0.0, max_leaf_size=leaf, bins=4))
    check_compact(compact(binary), binary)


@pytest.mark.parametrize(
    ("lo", "hi"),
    [
        ([-2e-38, 1e-40, -1e-40], [2e-40, 3e-40, 5e-39]),  # subnormal origins and decodings (flushed or not)
        ([0.0, 0.0, 0.0], [1.0, 0.0, 2.0]),  # a flat axis: scale is the smallest normal, every q decodes to 0
        ([1e-40, -1e-39, 0.0], [2e-40, 1e-39, 1e-45]),  # subnormal extents: never a subnormal scale
        ([1000.0, -1000.0, 5.0], [1000.0001, -999.9999, 5.0000005]),  # extents of an ulp or two
        ([-3e38, -1.0, 1e38], [3e38, 1.0, 3.4e38]),  # decoding overflows to +-inf: still conservative
    ],
)
def test_compact_frame_and_boxes_at_the_edges(lo, hi):
    rng = np.random.default_rng(3)
    root_lo, root_hi = np.array(lo, np.float32), np.array(hi, np.float32)
    origin, scale = compact_mod.compact_frame(root_lo, root_hi)
    assert (scale >= np.finfo(np.float32).tiny).all() and np.isfinite(scale).all()
    # boxes inside the root box: random corners, the root's own bounds, and points on them
    t = rng.uniform(size=(200, 2, 3))
    pts = (root_lo.astype(np.float64) + t * (root_hi.astype(np.float64) - root_lo)).astype(np.float32)
    pts = np.clip(pts, root_lo, root_hi)
    box_lo = np.concatenate([pts.min(axis=1), [root_lo, root_hi, root_lo]])
    box_hi = np.concatenate([pts.max(axis=1), [root_hi, root_hi, root_lo]])
    qlo, qhi = compact_mod.compact_boxes(box_lo, box_hi, origin, scale)
    assert ((qlo >= 0) & (qhi <= layout.BVH_GRID_MAX) & (qlo <= qhi)).all()
    for decoded in _decodings(qlo, origin, scale):
        assert (decoded <= box_lo).all()
    for decoded in _decodings(qhi, origin, scale):
        assert (decoded >= box_hi).all()


def test_compact_lone_leaf_and_links():
    """A lone leaf is the header's root link; records need a binary tree; links carry offsets."""
    verts, faces = from_corners(np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], np.float32))
    lone = build_bvh(verts, faces, PLAIN)
    records = compact(lone)
    assert len(records) == 1 and records["child0"][0, 3] == (0 << layout.BVH_LINK_SHIFT | 1)
    moved = offset_compact(records, node_base=10, tri_base=5)
    assert moved["child0"][0, 3] == (5 << layout.BVH_LINK_SHIFT | 1) and moved["child1"][0, 3] == -1
    verts, faces = MESHES["icosphere"]()
    binary = build_bvh(verts, faces, PLAIN)
    records = compact(binary)
    moved = offset_compact(records, node_base=10, tri_base=5)
    mask = (1 << layout.BVH_LINK_SHIFT) - 1
    for field in ("child0", "child1"):
        old, new = records[field][1:, 3], moved[field][1:, 3]
        np.testing.assert_array_equal(new & mask, old & mask)
        np.testing.assert_array_equal((new >> 7) - (old >> 7), np.where(old & mask == 0, 10, 5))
    with pytest.raises(ValueError, match="binary"):
        compact(collapse(binary))

"""The BVH builder: node layout, structural invariants, SAH quality, ray queries, caching, bad input."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

import engine.bvh_cache as cache_mod
import engine.bvh_compact as compact_mod
from engine import layout
from engine.bvh import Bvh, BvhParams, build_bvh
from engine.bvh_cache import cached_bvh, clear_memory_cache
from engine.bvh_compact import compact, offset_compact
from engine.bvh_wide import collapse, leaf_blocks
from engine.layout import BVH4_NODE_DTYPE, BVH8_NODE_DTYPE, BVH_NODE_DTYPE

# --- meshes ------------------------------------------------------------------


def _from_corners(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """An unindexed mesh: every triangle owns its three vertices."""
    corners = np.asarray(corners, np.float32).reshape(-1, 3, 3)
    return corners.reshape(-1, 3), np.arange(3 * len(corners), dtype=np.int32).reshape(-1, 3)


def _soup(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Small random triangles scattered in a 10-unit cube."""
    rng = np.random.default_rng(seed)
    centres = rng.random((n, 1, 3)) * 10
    return _from_corners(centres + rng.normal(scale=0.2, size=(n, 3, 3)))


def _icosphere(subdivisions: int = 3) -> tuple[np.ndarray, np.ndarray]:
    m = trimesh.creation.icosphere(subdivisions=subdivisions)
    return m.vertices.astype(np.float32), m.faces.astype(np.int32)


def _degenerate(n: int = 400, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Zero-area triangles only: points (three equal corners) and segments (collinear corners)."""
    rng = np.random.default_rng(seed)
    points = np.repeat(rng.random((n // 2, 1, 3)), 3, axis=1)
    a, b = rng.random((n - n // 2, 1, 3)), rng.random((n - n // 2, 1, 3))
    segments = a + (b - a) * np.array([0.0, 0.5, 1.0])[None, :, None]
    return _from_corners(np.concatenate([points, segments]))


def _identical(n: int = 300) -> tuple[np.ndarray, np.ndarray]:
    """The same triangle, many times over, sharing its three vertices."""
    verts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    return verts, np.tile(np.arange(3, dtype=np.int32), (n, 1))


MESHES = {
    "single": lambda: _from_corners([[0, 0, 0], [1, 0, 0], [0, 1, 0]]),
    "two": lambda: (
        np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32),
        np.array([[0, 1, 2], [0, 2, 3]], np.int32),
    ),
    "icosphere": _icosphere,
    "soup5000": lambda: _soup(5000),
    "degenerate": _degenerate,
    "identical": _identical,
}
#: The builder without pre-splitting: the exact one-leaf-per-triangle invariants below hold for it.
PLAIN = BvhParams(split_ratio=0.0)
PARAMS = [
    BvhParams(split_ratio=0.0),
    BvhParams(split_ratio=0.0, max_leaf_size=1, bins=2),
    BvhParams(split_ratio=0.0, max_leaf_size=8, bins=32, traversal_cost=2.5),
]


# --- invariants ----------------------------------------------------------------


def check_invariants(bvh: Bvh, verts: np.ndarray, faces: np.ndarray, *, identical: bool = False) -> None:
    """Everything a kernel relies on, checked by walking the tree from the root."""
    nodes, order, m = bvh.nodes, bvh.triangle_order, len(faces)
    assert nodes.dtype == BVH_NODE_DTYPE
    assert order.dtype == np.int32 and order.shape == (m,)
    assert np.array_equal(np.sort(order), np.arange(m)), "triangle_order is not a permutation"
    first = nodes["first"].astype(np.int64)
    count = nodes["count"].astype(np.int64)
    lo, hi = nodes["bounds_min"], nodes["bounds_max"]
    assert (count >= 0).all()
    visits = np.zeros(len(nodes), np.int64)
    covered = np.zeros(m, np.int64)
    stack = [0]
    while stack:
        i = stack.pop()
        visits[i] += 1
        assert (lo[i] <= hi[i]).all()
        if count[i] > 0:
            assert first[i] >= 0 and first[i] + count[i] <= m
            covered[first[i] : first[i] + count[i]] += 1
            pts = verts[faces[order[first[i] : first[i] + count[i]]]].reshape(-1, 3)
            # exact bounds of the vertices, rounded outward by one float32 step
            np.testing.assert_array_equal(lo[i], np.nextafter(pts.min(axis=0), np.float32(-np.inf)))
            np.testing.assert_array_equal(hi[i], np.nextafter(pts.max(axis=0), np.float32(np.inf)))
        else:
            c = first[i]
            assert i < c and c + 1 < len(nodes), f"node {i}: bad children {c}, {c + 1}"
            for child in (c, c + 1):
                assert (lo[i] <= lo[child]).all() and (hi[child] <= hi[i]).all()
            stack += [c, c + 1]
    assert (visits == 1).all(), "every node is reached exactly once"
    assert (covered == 1).all(), "every triangle is in exactly one leaf"
    leaves = count[count > 0]
    assert len(nodes) == 2 * len(leaves) - 1
    limit = bvh.params.max_leaf_size
    assert leaves.max() <= (limit if identical else 4 * limit)


@pytest.mark.parametrize("params", PARAMS, ids=["default", "leaf1-bins2", "leaf8-bins32"])
@pytest.mark.parametrize("name", list(MESHES))
def test_structural_invariants(name, params):
    verts, faces = MESHES[name]()
    bvh = build_bvh(verts, faces, params)
    check_invariants(bvh, verts, faces, identical=name == "identical")
    assert bvh.params == params
    assert 1 <= bvh.depth() <= len(bvh.nodes)


@settings(max_examples=40, deadline=None)
@given(
    corners=st.lists(
        st.lists(st.lists(st.integers(-3, 3), min_size=3, max_size=3), min_size=3, max_size=3),
        min_size=1,
        max_size=40,
    ),
    leaf=st.integers(1, 5),
    bins=st.integers(2, 8),
)
def test_invariants_on_small_integer_soups(corners, leaf, bins):
    """Coarse integer corners give coincident centroids, shared faces and degenerate triangles."""
    verts, faces = _from_corners(np.array(corners, np.float32) * 0.5)
    check_invariants(build_bvh(verts, faces, BvhParams(split_ratio=0.0, max_leaf_size=leaf, bins=bins)), verts, faces)


def test_node_dtype_layout():
    assert BVH_NODE_DTYPE.itemsize == 32
    offsets = [BVH_NODE_DTYPE.fields[name][1] for name in ("bounds_min", "first", "bounds_max", "count")]
    assert offsets == [0, 12, 16, 28]


def test_small_trees_and_reports():
    verts, faces = MESHES["single"]()
    one = build_bvh(verts, faces, PLAIN)
    assert len(one.nodes) == 1 and one.nodes["count"][0] == 1 and one.depth() == 1
    assert one.sah_cost() == pytest.approx(1.0)
    verts, faces = MESHES["two"]()
    # SAH: both halves of the quad span all of it, so a split costs 1 + 1 + 1 = 3 > 2 (a leaf) ...
    assert len(build_bvh(verts, faces, BvhParams(split_ratio=0.0, max_leaf_size=1)).nodes) == 1
    # ... while two far-apart triangles are worth separating.
    verts, faces = _from_corners([[[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[9, 0, 0], [10, 0, 0], [9, 1, 0]]])
    two = build_bvh(verts, faces, BvhParams(split_ratio=0.0, max_leaf_size=1))
    assert len(two.nodes) == 3 and two.depth() == 2
    assert two.sah_cost() < 2.0
    assert not two.nodes.flags.writeable and not two.triangle_order.flags.writeable


def test_degenerate_triangles_are_kept_and_float64_input_accepted():
    verts, faces = _degenerate(50)
    bvh = build_bvh(verts.astype(np.float64), faces.astype(np.int64), PLAIN)
    check_invariants(bvh, verts, faces)


# --- SAH quality -------------------------------------------------------------------


def _median_split_bvh(verts: np.ndarray, faces: np.ndarray, leaf: int = 4) -> Bvh:
    """A naive tree for comparison: object median on the longest centroid axis."""
    corners = verts[faces]
    cent = corners.mean(axis=1)
    order = np.arange(len(faces))
    nodes: list[list[int]] = [[0, len(faces), -1]]  # start, count, first child
    stack = [0]
    while stack:
        i = stack.pop()
        start, n, _ = nodes[i]
        if n <= leaf:
            continue
        idx = order[start : start + n]
        c = cent[idx]
        axis = int(np.argmax(c.max(axis=0) - c.min(axis=0)))
        order[start : start + n] = idx[np.argsort(c[:, axis], kind="stable")]
        nodes[i][2] = len(nodes)
        nodes += [[start, n // 2, -1], [start + n // 2, n - n // 2, -1]]
        stack += [len(nodes) - 2, len(nodes) - 1]
    out = np.zeros(len(nodes), BVH_NODE_DTYPE)
    for i, (start, n, child) in enumerate(nodes):
        pts = corners[order[start : start + n]].reshape(-1, 3)
        out[i] = (pts.min(axis=0), child if child >= 0 else start, pts.max(axis=0), 0 if child >= 0 else n)
    return Bvh(nodes=out, triangle_order=order.astype(np.int32), params=BvhParams(split_ratio=0.0, max_leaf_size=leaf))


def test_sah_beats_median_split_on_random_soup():
    verts, faces = _soup(5000, seed=3)
    sah = build_bvh(verts, faces, PLAIN)
    median = _median_split_bvh(verts, faces)
    assert sah.sah_cost() < median.sah_cost()


# --- ray queries ----------------------------------------------------------------------


def _moller_trumbore(o: np.ndarray, d: np.ndarray, v0: np.ndarray, v1: np.ndarray, v2: np.ndarray):
    """Plain float64 Möller–Trumbore, broadcasting; +inf where there is no hit with t > 0."""
    e1, e2 = v1 - v0, v2 - v0
    p = np.cross(d, e2)
    det = (e1 * p).sum(axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = o - v0
        u = (s * p).sum(axis=-1) * inv
        q = np.cross(s, e1)
        v = (d * q).sum(axis=-1) * inv
        t = (e2 * q).sum(axis=-1) * inv
    hit = (det != 0) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
    return np.where(hit, t, np.inf)


def _tracer(bvh: Bvh, corners: np.ndarray):
    """A nearest-hit query by stack traversal with slab tests; ties go to the lower triangle index."""
    lo = bvh.nodes["bounds_min"].astype(np.float64).tolist()  # plain floats: numpy is slow on 3-vectors
    hi = bvh.nodes["bounds_max"].astype(np.float64).tolist()
    first, count, order = bvh.nodes["first"].tolist(), bvh.nodes["count"].tolist(), bvh.triangle_order

    def trace(o: np.ndarray, d: np.ndarray) -> tuple[float, int]:
        o3, inv = o.tolist(), (1.0 / d).tolist()
        best_t, best = np.inf, -1
        stack = [0]
        while stack:
            i = stack.pop()
            near, far = 0.0, best_t
            for a in range(3):
                t0, t1 = (lo[i][a] - o3[a]) * inv[a], (hi[i][a] - o3[a]) * inv[a]
                near, far = max(near, min(t0, t1)), min(far, max(t0, t1))
            if far < near:
                continue
            if count[i] == 0:
                stack += [first[i], first[i] + 1]
                continue
            ids = order[first[i] : first[i] + count[i]]
            ts = _moller_trumbore(o, d, *(corners[ids, k] for k in range(3)))
            for t, tri in zip(ts.tolist(), ids.tolist(), strict=True):
                if t < best_t or (t == best_t and tri < best):
                    best_t, best = t, tri
        return best_t, best

    return trace


def _brute_force(corners: np.ndarray, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ts = _moller_trumbore(o[:, None], d[:, None], *(corners[None, :, k] for k in range(3)))
    best = np.argmin(ts, axis=1)  # first minimum: the lower index on ties
    best_t = ts[np.arange(len(o)), best]
    return best_t, np.where(np.isfinite(best_t), best, -1)


@pytest.mark.parametrize("name", ["soup", "icosphere"])
def test_traversal_matches_brute_force(name):
    verts, faces = _soup(1500, seed=5) if name == "soup" else _icosphere(3)
    bvh = build_bvh(verts, faces, PLAIN)
    corners = verts[faces].astype(np.float64)
    rng = np.random.default_rng(7)
    lo, hi = corners.reshape(-1, 3).min(axis=0), corners.reshape(-1, 3).max(axis=0)
    span = hi - lo
    n = 1000
    origins = lo - span + rng.random((n, 3)) * 3 * span
    origins[: n // 4] = lo + rng.random((n // 4, 3)) * span  # some start inside the mesh
    targets = lo + rng.random((n, 3)) * span
    dirs = targets - origins
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    want_t, want = _brute_force(corners, origins, dirs)
    trace = _tracer(bvh, corners)
    got = [trace(o, d) for o, d in zip(origins, dirs, strict=True)]
    got_t, got_ids = np.array([g[0] for g in got]), np.array([g[1] for g in got])
    assert np.isfinite(want_t).mean() > 0.3, "the rays should mostly hit"
    np.testing.assert_array_equal(got_ids, want)
    np.testing.assert_array_equal(got_t, want_t)


# --- cache ----------------------------------------------------------------------------


@pytest.fixture
def fresh_memory():
    clear_memory_cache()
    yield
    clear_memory_cache()


def _same(a: Bvh, b: Bvh) -> None:
    assert a.nodes.tobytes() == b.nodes.tobytes()
    np.testing.assert_array_equal(a.triangle_order, b.triangle_order)
    assert a.params == b.params


def _refuse_to_build(*args, **kwargs):
    raise AssertionError("build_bvh called although a cached tree exists")


def test_memory_cache_returns_the_same_tree(tmp_path, fresh_memory):
    verts, faces = _icosphere(2)
    first = cached_bvh(verts, faces, cache_dir=tmp_path)
    assert cached_bvh(verts.copy(), faces.copy(), cache_dir=tmp_path) is first
    assert cached_bvh(verts, faces, BvhParams(split_ratio=0.0, bins=8), cache_dir=tmp_path) is not first


def test_disk_cache_is_used(tmp_path, fresh_memory, monkeypatch):
    verts, faces = _icosphere(2)
    built = cached_bvh(verts, faces, cache_dir=tmp_path)
    files = sorted((tmp_path / "bvh").iterdir())
    assert len(files) == 1 and files[0].suffix == ".npz", "one file, no temp files left behind"
    clear_memory_cache()
    monkeypatch.setattr(cache_mod, "build_bvh", _refuse_to_build)
    _same(cached_bvh(verts, faces, cache_dir=tmp_path), built)


def test_default_cache_dir_from_environment(tmp_path, fresh_memory, monkeypatch):
    monkeypatch.setenv("ABERRANT_CACHE_DIR", str(tmp_path))
    verts, faces = MESHES["two"]()
    cached_bvh(verts, faces)
    assert len(list((tmp_path / "bvh").glob("*.npz"))) == 1


@pytest.mark.parametrize("damage", ["garbage", "truncated", "empty"])
def test_corrupt_cache_file_is_rebuilt(tmp_path, fresh_memory, monkeypatch, damage):
    verts, faces = _soup(300)
    good = build_bvh(verts, faces)
    cached_bvh(verts, faces, cache_dir=tmp_path)
    (path,) = (tmp_path / "bvh").glob("*.npz")
    data = path.read_bytes()
    path.write_bytes({"garbage": b"not a zip file at all", "truncated": data[: len(data) // 2], "empty": b""}[damage])
    clear_memory_cache()
    _same(cached_bvh(verts, faces, cache_dir=tmp_path), good)
    clear_memory_cache()
    monkeypatch.setattr(cache_mod, "build_bvh", _refuse_to_build)
    _same(cached_bvh(verts, faces, cache_dir=tmp_path), good)  # the file was rewritten whole


# --- bad input ------------------------------------------------------------------------


def _tri() -> tuple[np.ndarray, np.ndarray]:
    return np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32), np.array([[0, 1, 2]], np.int32)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda v, f: (np.where(np.arange(9).reshape(3, 3) == 4, np.nan, v), f), "non-finite"),
        (lambda v, f: (np.where(np.arange(9).reshape(3, 3) == 0, np.inf, v), f), "non-finite"),
        (lambda v, f: (v.astype(np.float64) * 1e300, f), "non-finite"),
        (lambda v, f: (v, f + 1), "out of range"),
        (lambda v, f: (v, f - 1), "out of range"),
        (lambda v, f: (v[:, :2], f), r"vertices must have shape \(N, 3\)"),
        (lambda v, f: (v.ravel(), f), r"vertices must have shape \(N, 3\)"),
        (lambda v, f: (v, np.array([[0, 1, 2, 0]], np.int32)), r"faces must have shape \(M, 3\)"),
        (lambda v, f: (v, f[:0]), "faces is empty"),
        (lambda v, f: (v, f.astype(np.float32)), "integer"),
    ],
)
@pytest.mark.parametrize("entry", [build_bvh, cached_bvh])
def test_bad_input_is_refused(tmp_path, entry, change, message):
    verts, faces = change(*_tri())
    kwargs = {"cache_dir": tmp_path} if entry is cached_bvh else {}
    with pytest.raises(ValueError, match=message):
        entry(verts, faces, **kwargs)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"max_leaf_size": 0}, "max_leaf_size"),
        ({"max_leaf_size": 65}, "max_leaf_size"),
        ({"max_leaf_size": 2.0}, "max_leaf_size"),
        ({"bins": 1}, "bins"),
        ({"bins": 257}, "bins"),
        ({"traversal_cost": 0.0}, "traversal_cost"),
        ({"traversal_cost": float("nan")}, "traversal_cost"),
        ({"traversal_cost": float("inf")}, "traversal_cost"),
    ],
)
def test_bad_params_are_refused(kwargs, field):
    with pytest.raises(ValueError, match=field):
        BvhParams(**kwargs)


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
    corners=st.lists(
        st.lists(st.lists(st.integers(-3, 3), min_size=3, max_size=3), min_size=3, max_size=3),
        min_size=1,
        max_size=60,
    ),
    leaf=st.integers(1, 5),
    width=st.sampled_from(WIDE),
)
def test_collapse_on_small_integer_soups(corners, leaf, width):
    verts, faces = _from_corners(np.array(corners, np.float32) * 0.5)
    binary = build_bvh(verts, faces, BvhParams(split_ratio=0.0, max_leaf_size=leaf, bins=4))
    check_wide(collapse(binary, width), binary, verts, faces, width)


def test_collapse_fills_nodes_and_pulls_the_largest_child():
    """A balanced tree of 16 leaves collapses to a root of 4 nodes of 4 leaves each: 5 wide nodes."""
    verts, faces = _from_corners([[[x, y, 0], [x + 0.5, y, 0], [x, y + 0.5, 0]] for x in range(4) for y in range(4)])
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
    verts, faces = _from_corners([[[x, y, 0], [x + 0.5, y, 0], [x, y + 0.5, 0]] for x in range(4) for y in range(4)])
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
    import trimesh

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
    verts, faces = _soup(3000, seed=3)
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
    monkeypatch.setattr(cache_mod, "build_bvh", _refuse_to_build)
    monkeypatch.setattr(cache_mod, "collapse", _refuse_to_build)
    _same(cached_bvh(verts, faces, cache_dir=tmp_path, width=4), wide)
    _same(cached_bvh(verts, faces, cache_dir=tmp_path, width=8), wide8)
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
    verts, faces = _from_corners(np.array(corners, np.float32) + np.float32(offset))
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
    verts, faces = _from_corners(np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], np.float32))
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

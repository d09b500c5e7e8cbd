"""The BVH builder: node layout, structural invariants, SAH quality, ray queries, caching, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from bvh_meshes import (
    MESHES,
    PARAMS,
    PLAIN,
    degenerate,
    from_corners,
    icosphere,
    integer_soups,
    refuse_to_build,
    same_tree,
    soup,
)
from hypothesis import given, settings
from hypothesis import strategies as st

import engine.bvh_cache as cache_mod
from engine.bvh import Bvh, BvhParams, build_bvh
from engine.bvh_cache import cached_bvh, clear_memory_cache
from engine.layout import BVH_NODE_DTYPE

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
    corners=integer_soups(40),
    leaf=st.integers(1, 5),
    bins=st.integers(2, 8),
)
def test_invariants_on_small_integer_soups(corners, leaf, bins):
    """Coarse integer corners give coincident centroids, shared faces and degenerate triangles."""
    verts, faces = from_corners(np.array(corners, np.float32) * 0.5)
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
    verts, faces = from_corners([[[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[9, 0, 0], [10, 0, 0], [9, 1, 0]]])
    two = build_bvh(verts, faces, BvhParams(split_ratio=0.0, max_leaf_size=1))
    assert len(two.nodes) == 3 and two.depth() == 2
    assert two.sah_cost() < 2.0
    assert not two.nodes.flags.writeable and not two.triangle_order.flags.writeable


def test_degenerate_triangles_are_kept_and_float64_input_accepted():
    verts, faces = degenerate(50)
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
    verts, faces = soup(5000, seed=3)
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
    verts, faces = soup(1500, seed=5) if name == "soup" else icosphere(3)
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


def test_memory_cache_returns_the_same_tree(tmp_path, fresh_memory):
    verts, faces = icosphere(2)
    first = cached_bvh(verts, faces, cache_dir=tmp_path)
    assert cached_bvh(verts.copy(), faces.copy(), cache_dir=tmp_path) is first
    assert cached_bvh(verts, faces, BvhParams(split_ratio=0.0, bins=8), cache_dir=tmp_path) is not first


def test_disk_cache_is_used(tmp_path, fresh_memory, monkeypatch):
    verts, faces = icosphere(2)
    built = cached_bvh(verts, faces, cache_dir=tmp_path)
    files = sorted((tmp_path / "bvh").iterdir())
    assert len(files) == 1 and files[0].suffix == ".npz", "one file, no temp files left behind"
    clear_memory_cache()
    monkeypatch.setattr(cache_mod, "build_bvh", refuse_to_build)
    same_tree(cached_bvh(verts, faces, cache_dir=tmp_path), built)


def test_default_cache_dir_from_environment(tmp_path, fresh_memory, monkeypatch):
    monkeypatch.setenv("ABERRANT_CACHE_DIR", str(tmp_path))
    verts, faces = MESHES["two"]()
    cached_bvh(verts, faces)
    assert len(list((tmp_path / "bvh").glob("*.npz"))) == 1


@pytest.mark.parametrize("damage", ["garbage", "truncated", "empty"])
def test_corrupt_cache_file_is_rebuilt(tmp_path, fresh_memory, monkeypatch, damage):
    verts, faces = soup(300)
    good = build_bvh(verts, faces)
    cached_bvh(verts, faces, cache_dir=tmp_path)
    (path,) = (tmp_path / "bvh").glob("*.npz")
    data = path.read_bytes()
    path.write_bytes({"garbage": b"not a zip file at all", "truncated": data[: len(data) // 2], "empty": b""}[damage])
    clear_memory_cache()
    same_tree(cached_bvh(verts, faces, cache_dir=tmp_path), good)
    clear_memory_cache()
    monkeypatch.setattr(cache_mod, "build_bvh", refuse_to_build)
    same_tree(cached_bvh(verts, faces, cache_dir=tmp_path), good)  # the file was rewritten whole


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

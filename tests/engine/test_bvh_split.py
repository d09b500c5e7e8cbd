"""Pre-split BVHs: every part of every triangle stays reachable, and frames do not change."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scenes import write_obj

from backends.base import AOVS
from backends.upload import SceneUploader
from engine.bvh import Bvh, BvhParams, build_bvh
from engine.bvh_cache import _cache_key, cached_bvh, clear_memory_cache
from engine.bvh_split import split_references
from engine.bvh_wide import collapse
from engine.camera_view import scene_camera
from engine.scene import Scene

SPLIT = BvhParams(split_ratio=4.0, split_budget=1.0)


def _planks(count: int = 40, length: float = 30.0, width: float = 0.25, angle_deg: float = 35.0):
    """Long strips side by side in XZ, turned about +Y: boxes far bigger than the triangles."""
    a = np.radians(angle_deg)
    along, across = np.array([np.cos(a), 0.0, np.sin(a)]), np.array([-np.sin(a), 0.0, np.cos(a)])
    verts, faces = [], []
    for i in range(count):
        base = (i - count / 2) * width * across - 0.5 * length * along
        p = [base, base + length * along, base + length * along + width * across, base + width * across]
        k = 4 * i
        verts += p
        faces += [[k, k + 2, k + 1], [k, k + 3, k + 2]]
    rng = np.random.default_rng(3)
    small = rng.uniform(-5, 5, (60, 3))[:, None, :] + rng.uniform(-0.3, 0.3, (60, 3, 3))
    verts += list(small.reshape(-1, 3))
    faces += (4 * count + np.arange(180).reshape(60, 3)).tolist()
    return np.array(verts, np.float32), np.array(faces, np.int32)


def _leaf_boxes(bvh: Bvh) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per leaf: (first, count, lo, hi), checking on the way that every box holds its children's."""
    n = bvh.nodes
    first, count, lo, hi = n["first"], n["count"], n["bounds_min"], n["bounds_max"]
    inner = np.flatnonzero(count == 0)
    for child in (first[inner], first[inner] + 1):
        assert (lo[inner] <= lo[child]).all() and (hi[child] <= hi[inner]).all()
    leaf = count > 0
    return first[leaf], count[leaf], lo[leaf], hi[leaf]


def test_split_references_bound_their_parts_and_respect_the_budget():
    verts, faces = _planks()
    corners = verts[faces]
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    tri, rlo, rhi = split_references(corners, lo, hi, 4.0, 1.0)
    m = len(faces)
    assert m < len(tri) <= 2 * m
    assert (np.bincount(tri, minlength=m) >= 1).all()
    assert (np.bincount(tri, minlength=m)[4 * 40 // 2 * 2 :] == 1).all(), "small triangles stay whole"
    assert (rlo >= lo[tri]).all() and (rhi <= hi[tri]).all() and (rlo <= rhi).all()
    # Points across each triangle (its corners too) lie in a box of one of its references.
    rng = np.random.default_rng(0)
    w = np.concatenate([np.eye(3), rng.dirichlet(np.ones(3), 200)])
    pts = np.einsum("sk,mkx->msx", w, corners.astype(np.float64)).astype(np.float32)  # (M, S, 3)
    inside = np.zeros(pts.shape[:2], bool)
    for r in range(len(tri)):
        inside[tri[r]] |= ((pts[tri[r]] >= rlo[r]) & (pts[tri[r]] <= rhi[r])).all(axis=1)
    assert inside.all()


def test_split_tree_reaches_every_part_of_every_triangle():
    verts, faces = _planks()
    plain, split = build_bvh(verts, faces, BvhParams(split_ratio=0.0)), build_bvh(verts, faces, SPLIT)
    m, order = len(faces), split.triangle_order
    assert len(plain.triangle_order) == m and m < len(order) <= m * 2
    assert (np.bincount(order, minlength=m) >= 1).all()
    assert split.sah_cost() < 0.8 * plain.sah_cost()
    first, count, lo, hi = _leaf_boxes(split)
    assert first.min() == 0 and (first + count).max() == len(order) and count.sum() == len(order)
    rng = np.random.default_rng(1)
    w = np.concatenate([np.eye(3), rng.dirichlet(np.ones(3), 100)])
    corners = verts[faces].astype(np.float64)
    inside = np.zeros((m, len(w)), bool)
    for f, c, a, b in zip(first, count, lo, hi, strict=True):
        for t in order[f : f + c]:
            p = (w @ corners[t]).astype(np.float32)
            inside[t] |= ((p >= a) & (p <= b)).all(axis=1)
    assert inside.all(), "a part of a triangle lies in no leaf that references it"
    wide = collapse(split, 8)
    np.testing.assert_array_equal(wide.triangle_order, order)


def test_no_long_triangles_means_the_same_tree():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    verts, faces = np.asarray(sphere.vertices, np.float32), np.asarray(sphere.faces)
    a, b = build_bvh(verts, faces, BvhParams(split_ratio=0.0)), build_bvh(verts, faces, BvhParams(split_ratio=50.0))
    assert a.nodes.tobytes() == b.nodes.tobytes()
    np.testing.assert_array_equal(a.triangle_order, b.triangle_order)


def test_split_parameters_are_in_the_cache_key(tmp_path):
    verts, faces = _planks(8)
    keys = {
        _cache_key(verts, faces, p)
        for p in (BvhParams(split_ratio=0.0), SPLIT, BvhParams(split_ratio=4.0, split_budget=0.3))
    }
    assert len(keys) == 3
    clear_memory_cache()
    built = cached_bvh(verts, faces, SPLIT, tmp_path)
    clear_memory_cache()
    loaded = cached_bvh(verts, faces, SPLIT, tmp_path)  # from disk: duplicates are allowed back in
    clear_memory_cache()
    assert loaded.nodes.tobytes() == built.nodes.tobytes()
    np.testing.assert_array_equal(loaded.triangle_order, built.triangle_order)


def test_bad_split_parameters_are_refused():
    with pytest.raises(ValueError, match="split_ratio"):
        BvhParams(split_ratio=-1.0)
    with pytest.raises(ValueError, match="split_budget"):
        BvhParams(split_budget=float("inf"))


@pytest.mark.parametrize("name", ["reference", "glsl", "opencl"])
def test_frames_are_identical_with_and_without_splitting(name, backend_factory, tmp_path, scenes):
    verts, faces = _planks()
    scene = Scene("planks")
    scenes.append(scene)
    scene.add_asset("deck", path=write_obj(tmp_path / "deck.obj", verts, faces))
    scene.add_mesh("deck", "deck", color=(0.7, 0.5, 0.3), checker=0.5)
    scene.add_mesh("beam", "box", position=(0.0, 1.0, -3.0), euler_deg=(0.0, 30.0, 5.0), scale=(30.0, 0.1, 0.1))
    scene.set_camera((0.0, 2.0, 6.0), look_at=(0.0, 0.0, -4.0), fov_deg=70.0)
    backend, camera = backend_factory(name), scene_camera(scene)
    frames = []
    for params in (BvhParams(split_ratio=0.0), SPLIT):
        uploader = SceneUploader(backend, bvh_params=params)
        uploader.sync(scene)
        frames.append(backend.render(camera, 64, 48, AOVS))
    assert uploader.packed is not None and uploader.packed.counts["triangles"] > len(faces) + 12
    assert (frames[0].aov("instance") >= 0).mean() > 0.3
    for aov in AOVS:
        np.testing.assert_array_equal(frames[0].aov(aov), frames[1].aov(aov), err_msg=aov)

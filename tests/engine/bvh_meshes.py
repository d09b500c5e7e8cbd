"""Meshes and helpers the BVH tests share: small hand-made meshes, random soups, degenerate and repeated
triangles, and the builder's parameter sets."""

from __future__ import annotations

import numpy as np
import trimesh
from hypothesis import strategies as st

from engine.bvh import Bvh, BvhParams


def from_corners(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """An unindexed mesh: every triangle owns its three vertices."""
    corners = np.asarray(corners, np.float32).reshape(-1, 3, 3)
    return corners.reshape(-1, 3), np.arange(3 * len(corners), dtype=np.int32).reshape(-1, 3)


def soup(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Small random triangles scattered in a 10-unit cube."""
    rng = np.random.default_rng(seed)
    centres = rng.random((n, 1, 3)) * 10
    return from_corners(centres + rng.normal(scale=0.2, size=(n, 3, 3)))


def icosphere(subdivisions: int = 3) -> tuple[np.ndarray, np.ndarray]:
    m = trimesh.creation.icosphere(subdivisions=subdivisions)
    return m.vertices.astype(np.float32), m.faces.astype(np.int32)


def degenerate(n: int = 400, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Zero-area triangles only: points (three equal corners) and segments (collinear corners)."""
    rng = np.random.default_rng(seed)
    points = np.repeat(rng.random((n // 2, 1, 3)), 3, axis=1)
    a, b = rng.random((n - n // 2, 1, 3)), rng.random((n - n // 2, 1, 3))
    segments = a + (b - a) * np.array([0.0, 0.5, 1.0])[None, :, None]
    return from_corners(np.concatenate([points, segments]))


def identical(n: int = 300) -> tuple[np.ndarray, np.ndarray]:
    """The same triangle, many times over, sharing its three vertices."""
    verts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    return verts, np.tile(np.arange(3, dtype=np.int32), (n, 1))


MESHES = {
    "single": lambda: from_corners([[0, 0, 0], [1, 0, 0], [0, 1, 0]]),
    "two": lambda: (
        np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32),
        np.array([[0, 1, 2], [0, 2, 3]], np.int32),
    ),
    "icosphere": icosphere,
    "soup5000": lambda: soup(5000),
    "degenerate": degenerate,
    "identical": identical,
}
#: The builder without pre-splitting: the exact one-leaf-per-triangle invariants below hold for it.
PLAIN = BvhParams(split_ratio=0.0)
PARAMS = [
    BvhParams(split_ratio=0.0),
    BvhParams(split_ratio=0.0, max_leaf_size=1, bins=2),
    BvhParams(split_ratio=0.0, max_leaf_size=8, bins=32, traversal_cost=2.5),
]


def same_tree(a: Bvh, b: Bvh) -> None:
    """The two trees are the same, node for node."""
    assert a.nodes.tobytes() == b.nodes.tobytes()
    np.testing.assert_array_equal(a.triangle_order, b.triangle_order)
    assert a.params == b.params


def refuse_to_build(*args: object, **kwargs: object) -> None:
    """A stand-in for build_bvh where a cached tree must be used."""
    raise AssertionError("build_bvh called although a cached tree exists")


def integer_soups(max_size: int) -> st.SearchStrategy[list[list[list[int]]]]:
    """Up to ``max_size`` triangles with small integer corners: many shared planes, edges and duplicates."""
    corner = st.lists(st.integers(-3, 3), min_size=3, max_size=3)
    return st.lists(st.lists(corner, min_size=3, max_size=3), min_size=1, max_size=max_size)

"""Packing the scene's distinct mesh assets: their triangles, UVs, BVH nodes (binary, compact or wide, with the
wide trees' triangle blocks), smooth corner normals and texels, each asset once however many instances use it.

These tables change only when the set of assets does; the per-instance rows that point into them (``instances``,
``materials``) are :class:`engine.packing.ScenePacker`'s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from components import Mesh, Transform
from engine import layout
from engine.bvh import BvhParams
from engine.bvh_cache import cached_bvh
from engine.bvh_compact import compact, offset_compact
from engine.bvh_wide import leaf_blocks
from engine.normals import corner_normals
from engine.scene import Scene
from engine.textures import pack_atlas


@dataclass
class PackedGeometry:
    """The asset tables and where each asset's part of them starts."""

    #: ``triangles``, ``triangle_uvs``, ``bvh_nodes``, ``triangle_blocks``, ``triangle_normals``, ``texels``
    #: (possibly empty: the packer pads each to one row).
    tables: dict[str, np.ndarray]
    #: Asset content hash -> its root row in ``bvh_nodes``.
    roots: dict[str, int]
    #: Asset content hash -> its instance flags (``INSTANCE_FLAG_HAS_UVS``).
    flags: dict[str, int]
    #: (asset content hash, crease angle) -> the offset from a triangle's row to its corner normals' row.
    normal_offset: dict[tuple[str, float], int]
    #: Texture content hash -> its first texel row.
    texture_first: dict[str, int]


def pack_geometry(
    scene: Scene,
    meshes: list[tuple[int, tuple[Transform, Mesh]]],
    bvh_params: BvhParams,
    bvh_width: int,
    bvh_compact: bool,
    texture_budget_mib: float,
) -> PackedGeometry:
    """The asset tables of ``meshes`` (``scene.query(Transform, Mesh)``), trees of ``bvh_width`` children
    (binary ones as compact records when ``bvh_compact``)."""
    tris, uvs, nodes, blocks = [], [], [], []
    roots: dict[str, int] = {}
    flags: dict[str, int] = {}
    orders: dict[str, tuple[int, np.ndarray]] = {}  # each asset's first triangle row and triangle order
    node_base = tri_base = block_base = 0
    for _, (_, mesh) in meshes:
        asset = scene.asset(mesh.asset)
        if asset.content_hash in roots:
            continue
        bvh = cached_bvh(asset.vertices, asset.faces, bvh_params, width=bvh_width)
        faces = asset.faces[bvh.triangle_order]
        t = np.zeros(len(faces), dtype=layout.TRIANGLE_DTYPE)
        for k, name in enumerate(("v0", "v1", "v2")):
            t[name][:, :3] = asset.vertices[faces[:, k]]
        u = np.zeros(len(faces), dtype=layout.TRIANGLE_UV_DTYPE)
        if asset.uvs is not None:
            u["uv01"][:, :2] = asset.uvs[faces[:, 0]]
            u["uv01"][:, 2:] = asset.uvs[faces[:, 1]]
            u["uv2"][:, :2] = asset.uvs[faces[:, 2]]
        if bvh_compact:
            n = offset_compact(compact(bvh), node_base, tri_base)
        elif bvh_width == 2:
            n = bvh.nodes.copy()
            n["first"] += np.where(n["count"] > 0, tri_base, node_base)
        else:  # leaves point at their blocks of 4 triangles; empty slots (count < 0) keep child 0
            n = bvh.nodes.copy()
            lanes, child = leaf_blocks(bvh)
            n["child"] = child + np.where(n["count"] > 0, block_base, np.where(n["count"] == 0, node_base, 0))
            b = np.zeros(len(lanes), dtype=layout.TRIANGLE_BLOCK_DTYPE)
            for k in range(3):
                for a, axis in enumerate("xyz"):
                    b[f"v{k}{axis}"] = np.where(lanes >= 0, t[f"v{k}"][np.maximum(lanes, 0), a], 0.0)
            b["index"] = np.where(lanes >= 0, lanes + tri_base, -1)
            blocks.append(b)
            block_base += len(b)
        roots[asset.content_hash] = node_base
        orders[asset.content_hash] = (tri_base, bvh.triangle_order)
        flags[asset.content_hash] = layout.INSTANCE_FLAG_HAS_UVS if asset.uvs is not None else 0
        tris.append(t)
        uvs.append(u)
        nodes.append(n)
        node_base += len(n)
        tri_base += len(t)
    node_dtype = layout.BVH_COMPACT_NODE_DTYPE if bvh_compact else layout.BVH_WIDTHS[bvh_width]
    normals, normal_offset = _pack_normals(scene, [m for _, (_, m) in meshes], orders)
    texels, texture_first = _pack_texels(scene, meshes, texture_budget_mib)
    tables = {
        "triangles": np.concatenate(tris) if tris else np.zeros(0, layout.TRIANGLE_DTYPE),
        "triangle_uvs": np.concatenate(uvs) if uvs else np.zeros(0, layout.TRIANGLE_UV_DTYPE),
        "bvh_nodes": np.concatenate(nodes) if nodes else np.zeros(0, node_dtype),
        "triangle_blocks": np.concatenate(blocks) if blocks else np.zeros(0, layout.TRIANGLE_BLOCK_DTYPE),
        "triangle_normals": normals,
        "texels": texels,
    }
    return PackedGeometry(tables, roots, flags, normal_offset, texture_first)


def _pack_normals(
    scene: Scene, meshes: list[Mesh], orders: dict[str, tuple[int, np.ndarray]]
) -> tuple[np.ndarray, dict[tuple[str, float], int]]:
    """Corner normals of each (asset, crease angle) a smooth mesh uses, in its triangles' packed order."""
    offsets: dict[tuple[str, float], int] = {}
    chunks: list[np.ndarray] = []
    base = 0
    for mesh in meshes:
        asset = scene.asset(mesh.asset)
        key = (asset.content_hash, mesh.crease_deg)
        if not mesh.smooth or key in offsets:
            continue
        tri_base, order = orders[asset.content_hash]
        corners = corner_normals(asset.vertices, asset.faces, mesh.crease_deg, asset.normals)[order]
        rows = np.zeros(len(corners), dtype=layout.TRIANGLE_NORMAL_DTYPE)
        for k, name in enumerate(("n0", "n1", "n2")):
            rows[name][:, :3] = corners[:, k]
        offsets[key] = base - tri_base
        chunks.append(rows)
        base += len(rows)
    return (np.concatenate(chunks) if chunks else np.zeros(0, layout.TRIANGLE_NORMAL_DTYPE)), offsets


def _pack_texels(
    scene: Scene, meshes: list[tuple[int, tuple[Transform, Mesh]]], budget_mib: float
) -> tuple[np.ndarray, dict[str, int]]:
    """Every distinct texture the meshes sample, in one table within the texel budget."""
    images = []
    for entity, (_, mesh) in meshes:
        texture = scene.texture(mesh) if scene.asset(mesh.asset).uvs is not None else None
        if texture is not None:
            images.append((f"{scene.name_of(entity)}.mesh.texture", texture))
    return pack_atlas(images, budget_mib)

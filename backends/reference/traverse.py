"""Nearest mesh hit over all instances: an instance tree, then breadth-first BVH traversal.

Python cannot afford a loop per ray, so traversal is *breadth-first over
(ray, node) pairs*: one iteration slab-tests every pair of the frontier at
once, replaces interior nodes by their two children and expands leaves into
(ray, triangle) pairs that are tested in one batch. The nearest ``t`` found
so far prunes pairs whose box is entered beyond it. The number of NumPy calls
is proportional to the BVH depth, not to the number of rays or nodes. The
same scheme walks a small tree over the instances' world bounds
(:mod:`backends.reference.tlas`) to find which instances each ray can hit.

Rays are transformed into each instance's object space without normalising
the direction, so ``t`` means the same distance in world and object space.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from backends.reference.intersect import intersect_triangles, safe_inverse, shear_rays, slab
from backends.reference.tlas import InstanceTree, build_instance_tree, instance_pairs

#: Rays traced per traversal batch (bounds the frontier's memory).
RAY_BATCH = 16384
#: Relative padding of instance world bounds (f64 bounds are not rounded outward by the packer).
_BOUNDS_PAD = 1e-9


@dataclass(frozen=True)
class Geometry:
    """The packed mesh tables as float64 arrays (only the live rows)."""

    v0: np.ndarray  # (T, 3)
    v1: np.ndarray
    v2: np.ndarray
    uv: np.ndarray  # (T, 3, 2)
    normals: np.ndarray  # (TN, 3, 3) corner normals of smooth meshes' triangles
    texels: np.ndarray  # (X, 4) the texture atlas, rgba
    node_lo: np.ndarray  # (N, 3)
    node_hi: np.ndarray
    node_first: np.ndarray  # (N,) int64
    node_count: np.ndarray
    world_to_object: np.ndarray  # (I, 3, 4)
    inst_lo: np.ndarray  # (I, 3), padded
    inst_hi: np.ndarray
    root: np.ndarray  # (I,) int64
    material: np.ndarray
    entity: np.ndarray
    flags: np.ndarray
    color: np.ndarray  # (M, 4): rgb, checker cell size
    cull: np.ndarray  # (M,) bool
    texture: np.ndarray  # (M, 4) int64: first texel, width, height, normal row offset
    tree: InstanceTree  # over the instance world bounds

    @property
    def instance_count(self) -> int:
        return len(self.root)

    @staticmethod
    def from_tables(
        tables: Mapping[str, np.ndarray], counts: Mapping[str, int], reuse_mesh_data: Geometry | None = None
    ) -> Geometry:
        """Convert the packed tables (any precision) to float64, dropping padding rows.

        ``reuse_mesh_data`` keeps the triangle, UV and BVH arrays of an earlier
        conversion (when only instances or materials changed: a moved entity
        must not re-convert a 200k-triangle mesh).
        """
        if reuse_mesh_data is not None:
            mesh = {name: getattr(reuse_mesh_data, name) for name in _MESH_FIELDS}
        else:
            mesh = _mesh_arrays(tables, counts)
        inst = tables["instances"][: counts["instances"]]
        mats = tables["materials"][: max(counts.get("materials", 0), 1)]
        lo = inst["bounds_min"][:, :3].astype(np.float64)
        hi = inst["bounds_max"][:, :3].astype(np.float64)
        pad = _BOUNDS_PAD * np.maximum(1.0, np.maximum(np.abs(lo), np.abs(hi)))
        lo, hi = lo - pad, hi + pad
        meta = inst["meta"].astype(np.int64)
        return Geometry(
            **mesh,
            world_to_object=inst["world_to_object"].astype(np.float64),
            inst_lo=lo,
            inst_hi=hi,
            root=meta[:, 0],
            material=meta[:, 1],
            entity=meta[:, 2],
            flags=meta[:, 3],
            color=mats["color"].astype(np.float64),
            cull=mats["flags"][:, 0] != 0,
            texture=mats["texture"].astype(np.int64),
            tree=build_instance_tree(lo, hi),
        )


_MESH_FIELDS = ("v0", "v1", "v2", "uv", "normals", "texels", "node_lo", "node_hi", "node_first", "node_count")


def _mesh_arrays(tables: Mapping[str, np.ndarray], counts: Mapping[str, int]) -> dict[str, np.ndarray]:
    """Triangles, UVs and BVH nodes as float64 / int64 arrays."""
    tri = tables["triangles"][: counts["triangles"]]
    uvs = tables["triangle_uvs"][: counts["triangles"]]
    nodes = tables["bvh_nodes"][: counts["bvh_nodes"]]
    normals = tables["triangle_normals"][: counts.get("triangle_normals", 0)]
    uv = np.empty((len(uvs), 3, 2))
    uv[:, 0] = uvs["uv01"][:, :2]
    uv[:, 1] = uvs["uv01"][:, 2:]
    uv[:, 2] = uvs["uv2"][:, :2]
    return {
        "v0": tri["v0"][:, :3].astype(np.float64),
        "v1": tri["v1"][:, :3].astype(np.float64),
        "v2": tri["v2"][:, :3].astype(np.float64),
        "uv": uv,
        "normals": np.stack([normals[k][:, :3] for k in ("n0", "n1", "n2")], axis=1).astype(np.float64),
        "texels": tables["texels"][: counts.get("texels", 0)]["rgba"].astype(np.float64),
        "node_lo": nodes["bounds_min"].astype(np.float64),
        "node_hi": nodes["bounds_max"].astype(np.float64),
        "node_first": nodes["first"].astype(np.int64),
        "node_count": nodes["count"].astype(np.int64),
    }


@dataclass(frozen=True)
class MeshHits:
    """Nearest hit per ray: ``t`` (+inf: none), instance row and triangle (-1: none), barycentrics."""

    t: np.ndarray
    instance: np.ndarray
    triangle: np.ndarray
    bary: np.ndarray  # (R, 3)

    @staticmethod
    def none(n: int) -> MeshHits:
        return MeshHits(np.full(n, np.inf), np.full(n, -1, np.int64), np.full(n, -1, np.int64), np.zeros((n, 3)))


def valid_rays(origin: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Rays that can be traced: finite origin and direction, direction not zero."""
    finite = np.all(np.isfinite(origin), axis=1) & np.all(np.isfinite(direction), axis=1)
    return finite & np.any(direction != 0.0, axis=1)


def nearest_mesh_hits(
    geo: Geometry, origin: np.ndarray, direction: np.ndarray, t_min: np.ndarray, t_max: np.ndarray | None = None
) -> MeshHits:
    """The nearest triangle hit with ``t_min < t < t_max`` of each world ray (N rays, rows)."""
    n = len(origin)
    hits = MeshHits.none(n)
    if geo.instance_count == 0 or n == 0:
        return hits
    limit = np.full(n, np.inf) if t_max is None else np.asarray(t_max, dtype=np.float64).copy()
    todo = np.flatnonzero(valid_rays(origin, direction))
    for start in range(0, len(todo), RAY_BATCH):
        rays = todo[start : start + RAY_BATCH]
        _trace_batch(geo, origin[rays], direction[rays], t_min[rays], limit[rays], hits, rays)
    return hits


def _trace_batch(
    geo: Geometry,
    origin: np.ndarray,
    direction: np.ndarray,
    t_min: np.ndarray,
    best_t: np.ndarray,
    out: MeshHits,
    out_rows: np.ndarray,
) -> None:
    """Traverse one batch of rays; writes the hits found into ``out`` at ``out_rows``.

    Each ray first traverses the instance whose box it enters first, then the
    others whose box it enters before the nearest hit found: in a crowded
    scene most far instances are then never opened.
    """
    ray, inst, entry = instance_pairs(
        geo.tree, geo.inst_lo, geo.inst_hi, origin, safe_inverse(direction), t_min, best_t
    )
    if ray.size == 0:
        return
    order = np.lexsort((entry, ray))
    ray, inst, entry = ray[order], inst[order], entry[order]
    nearest = np.concatenate([[True], ray[1:] != ray[:-1]])
    n = len(origin)
    best = _Best(best_t, np.full(n, -1, np.int64), np.full(n, -1, np.int64), np.zeros((n, 3)))
    _traverse(geo, origin, direction, t_min, ray[nearest], inst[nearest], best)
    rest = ~nearest
    rest[rest] = entry[rest] <= best.t[ray[rest]]
    _traverse(geo, origin, direction, t_min, ray[rest], inst[rest], best)
    found = best.triangle >= 0
    rows = out_rows[found]
    out.t[rows] = best.t[found]
    out.instance[rows] = best.instance[found]
    out.triangle[rows] = best.triangle[found]
    out.bary[rows] = best.bary[found]


@dataclass(frozen=True)
class _Best:
    """The nearest hit so far per ray of a batch (updated in place)."""

    t: np.ndarray
    instance: np.ndarray
    triangle: np.ndarray
    bary: np.ndarray


@dataclass(frozen=True)
class _SubRays:
    """(ray, instance) pairs as object-space rays."""

    ray: np.ndarray
    inst: np.ndarray
    o: np.ndarray
    inverse: np.ndarray
    perm: np.ndarray
    shear: np.ndarray
    cull: np.ndarray
    t_min: np.ndarray


def _traverse(
    geo: Geometry,
    origin: np.ndarray,
    direction: np.ndarray,
    t_min: np.ndarray,
    ray: np.ndarray,
    inst: np.ndarray,
    best: _Best,
) -> None:
    """Breadth-first BVH traversal of (ray, instance) pairs, in object space."""
    if ray.size == 0:
        return
    m = geo.world_to_object[inst]
    sub_d = np.einsum("nij,nj->ni", m[:, :, :3], direction[ray])
    sheared = shear_rays(sub_d)
    sub = _SubRays(
        ray=ray, inst=inst, o=np.einsum("nij,nj->ni", m[:, :, :3], origin[ray]) + m[:, :, 3],
        inverse=safe_inverse(sub_d), perm=sheared.perm, shear=sheared.shear,
        cull=geo.cull[geo.material[inst]], t_min=t_min[ray],
    )  # fmt: skip
    f_sub = np.arange(len(ray))
    f_node = geo.root[inst]
    while f_sub.size:
        near, far = slab(sub.o[f_sub], sub.inverse[f_sub], geo.node_lo[f_node], geo.node_hi[f_node])
        keep = (far >= np.maximum(near, sub.t_min[f_sub])) & (near <= best.t[ray[f_sub]])
        f_sub, f_node = f_sub[keep], f_node[keep]
        count = geo.node_count[f_node]
        leaf = count > 0
        if np.any(leaf):
            l_sub, l_first, l_count = f_sub[leaf], geo.node_first[f_node[leaf]], count[leaf]
            p_sub = np.repeat(l_sub, l_count)
            starts = np.cumsum(l_count) - l_count
            p_tri = np.repeat(l_first - starts, l_count) + np.arange(len(p_sub))
            _test_pairs(geo, sub, p_sub, p_tri, best)
        inner = ~leaf
        first = geo.node_first[f_node[inner]]
        f_sub = np.repeat(f_sub[inner], 2)
        f_node = np.stack([first, first + 1], axis=1).reshape(-1)


def _test_pairs(geo: Geometry, sub: _SubRays, p_sub: np.ndarray, p_tri: np.ndarray, best: _Best) -> None:
    """Test (subray, triangle) pairs; keep per ray the hit smallest in (t, instance, triangle)."""
    hit = intersect_triangles(
        sub.o[p_sub], sub.perm[p_sub], sub.shear[p_sub], geo.v0[p_tri], geo.v1[p_tri], geo.v2[p_tri], sub.cull[p_sub]
    )
    p_ray = sub.ray[p_sub]
    ok = (hit.t > sub.t_min[p_sub]) & (hit.t <= best.t[p_ray]) & np.isfinite(hit.t)
    if not np.any(ok):
        return
    idx = np.flatnonzero(ok)
    t, r, i, tri = hit.t[idx], p_ray[idx], sub.inst[p_sub[idx]], p_tri[idx]
    order = np.lexsort((tri, i, t, r))
    r_sorted = r[order]
    first = order[np.concatenate([[True], r_sorted[1:] != r_sorted[:-1]])]
    t, r, i, tri = t[first], r[first], i[first], tri[first]
    cur_t, cur_i, cur_tri = best.t[r], best.instance[r], best.triangle[r]
    better = (cur_tri < 0) | (t < cur_t) | ((t == cur_t) & ((i < cur_i) | ((i == cur_i) & (tri < cur_tri))))
    r = r[better]
    best.t[r] = t[better]
    best.instance[r] = i[better]
    best.triangle[r] = tri[better]
    best.bary[r] = hit.bary[idx[first[better]]]

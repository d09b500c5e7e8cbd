"""Vertex normals for smooth shading (docs/semantics.md, "Meshes and shading").

A smooth mesh is shaded with a normal interpolated from its triangle's three
corner normals: the mesh file's own vertex normals where it has them, else
each corner's face normal averaged (area-weighted) with those of the faces
around the same vertex *position* (so UV seams do not show) whose normals lie
within the crease angle of it. A cube stays a cube; a sphere turns round.
"""

from __future__ import annotations

import math

import numpy as np

#: Corners sharing one position beyond this are left flat (their pairwise crease test would be quadratic).
MAX_FAN = 512


def corner_normals(
    vertices: np.ndarray, faces: np.ndarray, crease_deg: float, file_normals: np.ndarray | None = None
) -> np.ndarray:
    """Unit object-space normals of every triangle corner, (F, 3, 3) float32 (corner k of face f at [f, k])."""
    v = vertices.astype(np.float64)
    f = faces.astype(np.int64)
    if file_normals is not None:
        n = file_normals.astype(np.float64)[f]
        norm = np.linalg.norm(n, axis=2, keepdims=True)
        if np.all(norm > 0):
            return (n / norm).astype(np.float32)
    face_n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])  # length: twice the area
    area = np.linalg.norm(face_n, axis=1)
    unit = np.where(area[:, None] > 0, face_n / np.where(area > 0, area, 1.0)[:, None], 0.0)
    _, position = np.unique(v, axis=0, return_inverse=True)
    corner_pos = position.reshape(-1)[f.reshape(-1)]  # (3F,)
    corner_face = np.repeat(np.arange(len(f)), 3)
    order = np.argsort(corner_pos, kind="stable")
    sorted_pos = corner_pos[order]
    starts = np.flatnonzero(np.r_[True, sorted_pos[1:] != sorted_pos[:-1]])
    sizes = np.diff(np.r_[starts, len(order)])
    out = unit[corner_face].copy()
    cos_crease = math.cos(math.radians(crease_deg)) - 1e-9
    small = sizes <= MAX_FAN
    # All (corner, neighbour) pairs within each fan, built group by group size so memory stays linear.
    for k in np.unique(sizes[small]):
        group_starts = starts[small & (sizes == k)]
        members = order[group_starts[:, None] + np.arange(k)]  # (G, k) corner ids
        faces_of = corner_face[members]  # (G, k)
        n_self = unit[faces_of]  # (G, k, 3)
        weighted = face_n[faces_of]  # (G, k, 3)
        cos = np.einsum("gai,gbi->gab", n_self, n_self)
        keep = cos >= cos_crease
        summed = np.einsum("gab,gbi->gai", keep.astype(np.float64), weighted)
        length = np.linalg.norm(summed, axis=2, keepdims=True)
        smooth = np.where(length > 0, summed / np.where(length > 0, length, 1.0), n_self)
        out[members.reshape(-1)] = smooth.reshape(-1, 3)
    return out.reshape(len(f), 3, 3).astype(np.float32)

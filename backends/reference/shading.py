"""Shading (docs/semantics.md, "Meshes and shading") of mesh hits, and the colour quantisation every backend shares."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from backends.reference.traverse import Geometry, MeshHits
from engine.layout import LIGHT_KINDS


@dataclass(frozen=True)
class ShadingSettings:
    """The scene settings the tracer needs, in float64."""

    background: np.ndarray  # (3,)
    light_dir: np.ndarray  # (3,) unit, towards the light
    event_limit_color: np.ndarray  # (3,)
    ambient: float
    max_events: int

    @staticmethod
    def from_table(settings: np.ndarray) -> ShadingSettings:
        row = settings[0]
        light = row["light_dir"][:3].astype(np.float64)
        norm = np.linalg.norm(light)
        return ShadingSettings(
            background=row["background"][:3].astype(np.float64),
            light_dir=light / norm if norm > 0 else np.array([0.0, 1.0, 0.0]),
            event_limit_color=row["event_limit_color"][:3].astype(np.float64),
            ambient=float(row["shading"][0]),
            max_events=max(1, int(row["counts"][3])),
        )


def world_normals(geo: Geometry, instance: np.ndarray, triangle: np.ndarray) -> np.ndarray:
    """Unit geometric normals in world space: object normals through the inverse transpose."""
    n_obj = np.cross(geo.v1[triangle] - geo.v0[triangle], geo.v2[triangle] - geo.v0[triangle])
    linear = geo.world_to_object[instance][:, :, :3]
    n = np.einsum("nji,nj->ni", linear, n_obj)
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(norm > 0, n / np.where(norm > 0, norm, 1.0), 0.0)


def shade(
    geo: Geometry,
    settings: ShadingSettings,
    hits: MeshHits,
    direction: np.ndarray,
    world_position: np.ndarray,
    lighting: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
) -> np.ndarray:
    """``base · texture · checker · (ambient + (1 − ambient)·Σ)``; ``Σ`` is ``lighting(n_s, n)`` (the lights' sum,
    :func:`light_sum`) or, without it, the implicit sun's ``max(0, n_s·l)``.

    n is the geometric normal turned to face the ray; n_s the shading normal (:func:`shading_normals`).
    """
    n = world_normals(geo, hits.instance, hits.triangle)
    flipped = np.sum(n * direction, axis=1) > 0.0
    n = np.where(flipped[:, None], -n, n)
    n_s = shading_normals(geo, hits, n, flipped)
    material = geo.material[hits.instance]
    base = geo.color[material, :3] * texture_colors(geo, hits)
    cell = geo.color[material, 3]
    factor = checker_factor(geo, hits, n, world_position, cell)
    if lighting is None:
        lambert = np.maximum(0.0, n_s @ settings.light_dir)
        color = base * (factor * (settings.ambient + (1.0 - settings.ambient) * lambert))[:, None]
    else:
        color = base * (factor[:, None] * (settings.ambient + (1.0 - settings.ambient) * lighting(n_s, n)))
    return np.where(np.isfinite(color), color, 0.0)


@dataclass(frozen=True)
class Lights:
    """The live rows of the ``lights`` table in float64 (docs/semantics.md, "Lights and shadows")."""

    vector: np.ndarray  # (L, 3) a sun's unit direction towards it, a point light's packed position
    color: np.ndarray  # (L, 3) colour x intensity
    range: np.ndarray  # (L,) 0 for none
    point: np.ndarray  # (L,) bool: a point light (else a sun)
    shadows: np.ndarray  # (L,) bool

    def __len__(self) -> int:
        return len(self.range)

    @staticmethod
    def from_table(table: np.ndarray, count: int) -> Lights:
        rows = table[:count]
        meta = rows["meta"].astype(np.int64).reshape(-1, 4)
        return Lights(
            vector=rows["vector"][:, :3].astype(np.float64),
            color=rows["color"][:, :3].astype(np.float64),
            range=rows["color"][:, 3].astype(np.float64),
            point=meta[:, 0] == LIGHT_KINDS["point"],
            shadows=meta[:, 1] != 0,
        )


#: ``lit(rows, normals, towards, reach)``: whether shadow rays from the hits ``rows`` (off the surface along
#: their normals, towards the light, reaching that far) get there.
ShadowTest = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def light_sum(lights: Lights, n_s: np.ndarray, n: np.ndarray, position: np.ndarray, lit: ShadowTest) -> np.ndarray:
    """``Σ colour·max(0, n·l)·falloff·lit`` over the lights (N, 3): a sun's falloff is 1; a point light's is
    ``1/d²``, times ``clamp(1 − (d/range)⁴, 0, 1)²`` with a range. A light behind the surface sends no shadow
    ray; a shadowing light's rays decide ``lit``, the others' are lit. The shading normal ``n_s`` weighs, the
    shadow rays leave along the geometric ``n``."""
    total = np.zeros((len(n), 3))
    for k in range(len(lights)):
        if lights.point[k]:
            d = lights.vector[k] - position
            distance = np.linalg.norm(d, axis=1)
            towards = d / np.where(distance > 0.0, distance, 1.0)[:, None]
            falloff = np.where(distance > 0.0, 1.0 / np.where(distance > 0.0, distance, 1.0) ** 2, 0.0)
            if lights.range[k] > 0.0:
                falloff *= np.clip(1.0 - (distance / lights.range[k]) ** 4, 0.0, 1.0) ** 2
            reach = distance
        else:
            towards = np.broadcast_to(lights.vector[k], n.shape)
            falloff = np.ones(len(n))
            reach = np.full(len(n), np.inf)
        weight = np.maximum(0.0, np.sum(n_s * towards, axis=1)) * falloff
        rows = np.flatnonzero(weight > 0.0)
        if lights.shadows[k] and rows.size:
            weight[rows] *= lit(rows, n[rows], np.ascontiguousarray(towards[rows]), reach[rows])
        total += lights.color[k] * weight[:, None]
    return total


def shading_normals(geo: Geometry, hits: MeshHits, n: np.ndarray, flipped: np.ndarray) -> np.ndarray:
    """Unit world normals to light by: smooth instances' corner normals interpolated at the hit (through the
    inverse transpose, turned with the geometric normal ``n``), else ``n`` itself."""
    out = n.copy()
    rows = np.flatnonzero((geo.flags[hits.instance] & 2) != 0)
    if rows.size == 0:
        return out
    index = hits.triangle[rows] + geo.texture[geo.material[hits.instance[rows]], 3]
    n_obj = np.einsum("nk,nkj->nj", hits.bary[rows], geo.normals[index])
    linear = geo.world_to_object[hits.instance[rows]][:, :, :3]
    s = np.einsum("nji,nj->ni", linear, n_obj)
    norm = np.linalg.norm(s, axis=1, keepdims=True)
    s = np.where(norm > 0, s / np.where(norm > 0, norm, 1.0), n[rows])
    out[rows] = np.where(flipped[rows, None] & (norm > 0), -s, s)
    return out


def texture_colors(geo: Geometry, hits: MeshHits) -> np.ndarray:
    """(R, 3) texture colour at each hit's UV, 1 where the instance samples none.

    Bilinear between texel centres with repeat wrap: with ``f = u − floor(u)``, ``g = v − floor(v)``,
    ``s = f·W − ½`` and ``t = (1 − g)·H − ½`` (image row 0 is the top, v = 1), the four texels around
    ``(s, t)`` (indices wrapped mod W, H) weighted by the fractions of ``s`` and ``t``.
    """
    out = np.ones((len(hits.t), 3))
    material = geo.material[hits.instance]
    tex = geo.texture[material]
    rows = np.flatnonzero((tex[:, 1] > 0) & ((geo.flags[hits.instance] & 1) != 0))
    if rows.size == 0:
        return out
    first, w, h = tex[rows, 0], tex[rows, 1], tex[rows, 2]
    uv = np.einsum("nk,nkj->nj", hits.bary[rows], geo.uv[hits.triangle[rows]])
    s = (uv[:, 0] - np.floor(uv[:, 0])) * w - 0.5
    t = (1.0 - (uv[:, 1] - np.floor(uv[:, 1]))) * h - 0.5
    x0, y0 = np.floor(s), np.floor(t)
    ax, ay = (s - x0)[:, None], (t - y0)[:, None]
    x0, y0 = np.mod(x0.astype(np.int64), w), np.mod(y0.astype(np.int64), h)
    x1, y1 = np.where(x0 + 1 >= w, 0, x0 + 1), np.where(y0 + 1 >= h, 0, y0 + 1)

    def texel(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return geo.texels[first + y * w + x, :3]

    top = (1.0 - ax) * texel(x0, y0) + ax * texel(x1, y0)
    bottom = (1.0 - ax) * texel(x0, y1) + ax * texel(x1, y1)
    out[rows] = (1.0 - ay) * top + ay * bottom
    return out


def checker_factor(
    geo: Geometry, hits: MeshHits, normal: np.ndarray, world_position: np.ndarray, cell: np.ndarray
) -> np.ndarray:
    """1 in even cells, 0.5 in odd ones: UV cells when the asset has UVs, else world triplanar.

    Triplanar uses the two world axes other than the dominant axis of the
    normal. Parity is ``(floor(a/c) + floor(b/c)) mod 2``; 1 (odd) is dark.
    """
    factor = np.ones(len(cell))
    on = cell > 0.0
    if not np.any(on):
        return factor
    rows = np.flatnonzero(on)
    has_uv = (geo.flags[hits.instance[rows]] & 1) != 0
    uv = np.einsum("nk,nkj->nj", hits.bary[rows], geo.uv[hits.triangle[rows]])
    axis = np.argmax(np.abs(normal[rows]), axis=1)
    p = world_position[rows]
    k = np.arange(len(rows))
    a = np.where(has_uv, uv[:, 0], p[k, (axis + 1) % 3])
    b = np.where(has_uv, uv[:, 1], p[k, (axis + 2) % 3])
    c = cell[rows]
    parity = np.mod(np.floor(a / c) + np.floor(b / c), 2.0)
    factor[rows] = np.where(parity == 1.0, 0.5, 1.0)
    return factor


def to_uint8(color: np.ndarray) -> np.ndarray:
    """``round(clip(c, 0, 1) · 255)``, halves rounded up (``floor(x + 0.5)``, the same on every backend)."""
    c = np.where(np.isfinite(color), color, 0.0)
    return np.floor(np.clip(c, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)

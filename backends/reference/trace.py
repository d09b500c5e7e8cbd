"""The ray's journey (DESIGN.md section 5) and shading (section 4), vectorised over rays in float64.

Every ray carries the full state of section 5 as arrays: origin ``o``, world
direction ``r``, perceived direction ``w``, primary direction ``d0``, the
active aberration, path length ``L``, perceived length ``Λ``, event count
``n`` and the surface it is leaving. Each iteration of :func:`trace` finds the
next event of every live ray (:func:`_next_event`), finishes the rays whose
event ends them (a mesh hit, a miss) and advances the others (aberration
faces and portals: the places where those slot in are marked). Rays whose
count reaches ``max_events`` get the event-limit colour.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from backends.reference.traverse import Geometry, MeshHits, nearest_mesh_hits

# Event kinds.
MISS, MESH, ABERRATION, PORTAL = 0, 1, 2, 3
#: No surface (the ``leaving`` id of a ray that starts in free space).
NO_SURFACE = -1
#: ``t_min`` is this fraction of the origin's magnitude (at least of 1).
T_MIN_RELATIVE = 1e-9


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


@dataclass
class RayState:
    """Live rays: ``index`` says which output pixel each row writes."""

    index: np.ndarray  # (N,) int64
    o: np.ndarray  # (N, 3)
    r: np.ndarray  # (N, 3) world direction
    w: np.ndarray  # (N, 3) perceived direction (unit)
    d0: np.ndarray  # (N, 3) primary direction (carried through portals)
    aberration: np.ndarray  # (N,) active aberration row, -1 for none
    length: np.ndarray  # (N,) L
    perceived: np.ndarray  # (N,) Λ
    events: np.ndarray  # (N,) n
    leaving: np.ndarray  # (N,) id of the surface the ray is leaving, NO_SURFACE for none

    @staticmethod
    def primary(origin: np.ndarray, directions: np.ndarray) -> RayState:
        n = len(directions)
        o = np.broadcast_to(np.asarray(origin, dtype=np.float64), (n, 3)).copy()
        d = np.asarray(directions, dtype=np.float64)
        return RayState(
            index=np.arange(n), o=o, r=d.copy(), w=d.copy(), d0=d.copy(),
            aberration=np.full(n, -1, np.int64), length=np.zeros(n), perceived=np.zeros(n),
            events=np.zeros(n, np.int64), leaving=np.full(n, NO_SURFACE, np.int64),
        )  # fmt: skip

    def __len__(self) -> int:
        return len(self.index)

    def subset(self, rows: np.ndarray) -> RayState:
        return RayState(**{name: value[rows] for name, value in vars(self).items()})


@dataclass
class TraceResult:
    """Per ray (in input order): linear colour, L, Λ, entity id, event count."""

    color: np.ndarray  # (N, 3) float64 in [0, 1]
    depth: np.ndarray
    perceived: np.ndarray
    instance: np.ndarray  # int64 entity id, -1
    events: np.ndarray

    @staticmethod
    def empty(n: int, background: np.ndarray) -> TraceResult:
        return TraceResult(
            np.broadcast_to(background, (n, 3)).copy(), np.full(n, np.inf), np.full(n, np.inf),
            np.full(n, -1, np.int64), np.zeros(n, np.int64),
        )  # fmt: skip


@dataclass(frozen=True)
class Event:
    """The next event of each live ray: its kind, distance ``t`` along ``r`` and the mesh hit."""

    kind: np.ndarray  # (N,) MISS / MESH / ABERRATION / PORTAL
    t: np.ndarray
    mesh: MeshHits


def t_min_of(o: np.ndarray) -> np.ndarray:
    """Hits at or below this ``t`` are ignored: relative to the magnitude of the origin."""
    return T_MIN_RELATIVE * np.maximum(1.0, np.linalg.norm(o, axis=1))


def trace(
    geo: Geometry, settings: ShadingSettings, origin: np.ndarray, directions: np.ndarray, world_origin: np.ndarray
) -> TraceResult:
    """Trace primary rays from ``origin`` (packed coordinates) along unit ``directions`` (N, 3).

    ``world_origin`` is the packed origin, added back where world coordinates
    matter (the triplanar checker).
    """
    result = TraceResult.empty(len(directions), settings.background)
    state = RayState.primary(origin, directions)
    with np.errstate(all="ignore"):
        while len(state):
            limited = state.events >= settings.max_events
            if np.any(limited):
                _finish_limit(state.subset(np.flatnonzero(limited)), settings, result)
                state = state.subset(np.flatnonzero(~limited))
                if not len(state):
                    break
            event = _next_event(geo, state)
            missed = event.kind == MISS
            _finish_miss(state.subset(np.flatnonzero(missed)), result)
            hit = np.flatnonzero(event.kind == MESH)
            if hit.size:
                _finish_mesh(geo, settings, state.subset(hit), _subset_hits(event.mesh, hit), world_origin, result)
            moving = np.flatnonzero((event.kind == ABERRATION) | (event.kind == PORTAL))
            state = _advance(state.subset(moving), event.kind[moving], event.t[moving])
    return result


def _next_event(geo: Geometry, state: RayState) -> Event:
    """The nearest of: a mesh triangle, an aberration face, a portal quad.

    Only meshes exist in this backend so far. Aberration faces and portals
    will be intersected here too (each skipping ``state.leaving`` by id) and
    compete for the smallest ``t``; their kind then replaces MESH/MISS. A mesh
    hit ends the ray, so no mesh is ever the surface being left.
    """
    t_min = t_min_of(state.o)
    mesh = nearest_mesh_hits(geo, state.o, state.r, t_min)
    kind = np.where(np.isfinite(mesh.t), MESH, MISS)
    # Aberration faces (DESIGN.md section 6) and portal quads (section 7) slot in here.
    return Event(kind, mesh.t, mesh)


def _advance(state: RayState, kind: np.ndarray, t: np.ndarray) -> RayState:
    """Move rays across an aberration face or through a portal; ``n += 1``.

    Not reachable yet (no aberration or portal events are produced); kept so
    the loop's structure is the final one.
    """
    step = t * np.linalg.norm(state.r, axis=1)
    state.o = state.o + t[:, None] * state.r
    state.length = state.length + step
    state.perceived = state.perceived + step * _perceived_per_world(state)
    state.events = state.events + 1
    return state


def _perceived_per_world(state: RayState) -> np.ndarray:
    """Perceived length per world length along ``r``: 1 outside every aberration box."""
    return np.ones(len(state))


def _subset_hits(hits: MeshHits, rows: np.ndarray) -> MeshHits:
    return MeshHits(hits.t[rows], hits.instance[rows], hits.triangle[rows], hits.bary[rows])


def _finish_limit(state: RayState, settings: ShadingSettings, out: TraceResult) -> None:
    """Rays that used all their events: event-limit colour, no depth, no instance."""
    out.color[state.index] = settings.event_limit_color
    out.events[state.index] = state.events


def _finish_miss(state: RayState, out: TraceResult) -> None:
    """Rays that found nothing keep the background colour and +inf depth."""
    out.events[state.index] = state.events


def _finish_mesh(
    geo: Geometry,
    settings: ShadingSettings,
    state: RayState,
    hits: MeshHits,
    world_origin: np.ndarray,
    out: TraceResult,
) -> None:
    """Shade mesh hits and record L, Λ, entity id and event count."""
    step = hits.t * np.linalg.norm(state.r, axis=1)
    position = state.o + hits.t[:, None] * state.r
    out.color[state.index] = shade(geo, settings, hits, state.r, position + world_origin)
    out.depth[state.index] = state.length + step
    out.perceived[state.index] = state.perceived + step * _perceived_per_world(state)
    out.instance[state.index] = geo.entity[hits.instance]
    out.events[state.index] = state.events


def world_normals(geo: Geometry, instance: np.ndarray, triangle: np.ndarray) -> np.ndarray:
    """Unit geometric normals in world space: object normals through the inverse transpose."""
    n_obj = np.cross(geo.v1[triangle] - geo.v0[triangle], geo.v2[triangle] - geo.v0[triangle])
    linear = geo.world_to_object[instance][:, :, :3]
    n = np.einsum("nji,nj->ni", linear, n_obj)
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(norm > 0, n / np.where(norm > 0, norm, 1.0), 0.0)


def shade(
    geo: Geometry, settings: ShadingSettings, hits: MeshHits, direction: np.ndarray, world_position: np.ndarray
) -> np.ndarray:
    """``base · checker · (ambient + (1 − ambient)·max(0, n·l))`` with n turned to face the ray."""
    n = world_normals(geo, hits.instance, hits.triangle)
    n = np.where(np.sum(n * direction, axis=1, keepdims=True) > 0.0, -n, n)
    lambert = np.maximum(0.0, n @ settings.light_dir)
    material = geo.material[hits.instance]
    base = geo.color[material, :3]
    cell = geo.color[material, 3]
    factor = checker_factor(geo, hits, n, world_position, cell)
    color = base * (factor * (settings.ambient + (1.0 - settings.ambient) * lambert))[:, None]
    return np.where(np.isfinite(color), color, 0.0)


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

"""The ray's journey (docs/semantics.md sections 1-13), vectorised over rays in float64.

Every ray carries the full state of semantics section 1 as arrays: origin ``o``, world
direction ``r``, perceived direction ``w``, primary direction ``d0``, the
active aberration, path length ``L``, perceived length ``Λ``, event count
``n`` and the surface it is leaving. Primary rays first take the transition
into the box that contains the camera (:func:`enter_at_start`). Each
iteration of :func:`trace` then finds the next event of every live ray
(:func:`next_event`), finishes the rays whose event ends them (a mesh hit, a
miss) and advances the others across an aberration face or through a portal
(:func:`advance`). Rays whose count reaches ``max_events`` get the
event-limit colour. Finished rays drop out of the live set.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from backends.reference.aberrations import (
    NO_BOX,
    Boxes,
    SigmaBounds,
    containing_box,
    nearest_box_faces,
    perceived_per_world,
    transition,
)
from backends.reference.portals import Portals, nearest_portal_hits, teleport
from backends.reference.shading import Lights, ShadingSettings, light_sum, shade, to_uint8
from backends.reference.traverse import Geometry, MeshHits, nearest_mesh_hits

__all__ = [
    "Event",
    "RayState",
    "ShadingSettings",
    "Space",
    "TraceResult",
    "advance",
    "enter_at_start",
    "journey",
    "next_event",
    "nudge_of",
    "shadow_rays_lit",
    "t_min_of",
    "tie_window",
    "to_uint8",
    "trace",
]

# Event kinds; also the kinds of surface a ray can be leaving (MISS: none).
MISS, MESH, ABERRATION, PORTAL = 0, 1, 2, 3
# How a journey ends besides MESH and MISS: out of events, or a shadow ray's reach covered.
LIMIT, REACHED = 4, 5
#: The id of "no surface" (``leaving_id`` of a ray that starts in free space).
NO_SURFACE = -1
#: ``t_min`` is this fraction of the origin's magnitude (at least of 1): hits at or below it are ignored.
T_MIN_RELATIVE = 1e-9
#: Candidates within ``TIE_RELATIVE·max(1, |o| + t)`` of the nearest one count as tied (at least 2·t_min
#: of the event point, so nothing a tie gives up would be skipped by ``t_min`` after the event).
TIE_RELATIVE = 2e-9
#: After an event the active box is looked up this far (relative, at least 1) past the event point along
#: the ray: beyond every face that ``t_min`` will skip.
NUDGE_RELATIVE = 1e-8


@dataclass(frozen=True)
class Space:
    """What bends and teleports rays: aberration boxes, portals, and the radial mode's camera bounds."""

    boxes: Boxes = field(default_factory=Boxes.empty)
    portals: Portals = field(default_factory=Portals.empty)
    sigma: SigmaBounds = field(default_factory=SigmaBounds.default)


@dataclass
class RayState:
    """Live rays: ``index`` says which output pixel each row writes."""

    index: np.ndarray  # (N,) int64
    o: np.ndarray  # (N, 3)
    r: np.ndarray  # (N, 3) world direction
    w: np.ndarray  # (N, 3) perceived direction (unit)
    d0: np.ndarray  # (N, 3) primary direction (carried through portals)
    aberration: np.ndarray  # (N,) active aberration row, NO_BOX for none
    length: np.ndarray  # (N,) L
    perceived: np.ndarray  # (N,) Λ
    events: np.ndarray  # (N,) n
    leaving_kind: np.ndarray  # (N,) MISS (none), ABERRATION (a box face) or PORTAL
    leaving_id: np.ndarray  # (N,) box face id (6·row + face) or portal row; NO_SURFACE for none

    @staticmethod
    def primary(origin: np.ndarray, directions: np.ndarray) -> RayState:
        n = len(directions)
        o = np.broadcast_to(np.asarray(origin, dtype=np.float64), (n, 3)).copy()
        d = np.asarray(directions, dtype=np.float64)
        return RayState(
            index=np.arange(n), o=o, r=d.copy(), w=d.copy(), d0=d.copy(),
            aberration=np.full(n, NO_BOX, np.int64), length=np.zeros(n), perceived=np.zeros(n),
            events=np.zeros(n, np.int64), leaving_kind=np.full(n, MISS, np.int64),
            leaving_id=np.full(n, NO_SURFACE, np.int64),
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
    """The next event of each live ray: its kind, distance ``t`` along ``r`` and what was hit."""

    kind: np.ndarray  # (N,) MISS / MESH / ABERRATION / PORTAL
    t: np.ndarray
    mesh: MeshHits
    face: np.ndarray  # (N,) box face id of ABERRATION events
    portal: np.ndarray  # (N,) portal row of PORTAL events

    def subset(self, rows: np.ndarray) -> Event:
        mesh = MeshHits(self.mesh.t[rows], self.mesh.instance[rows], self.mesh.triangle[rows], self.mesh.bary[rows])
        return Event(self.kind[rows], self.t[rows], mesh, self.face[rows], self.portal[rows])


def t_min_of(o: np.ndarray) -> np.ndarray:
    """Hits at or below this ``t`` are ignored: relative to the magnitude of the origin."""
    return T_MIN_RELATIVE * np.maximum(1.0, np.linalg.norm(o, axis=1))


def tie_window(o: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Candidates this close to the nearest (at ``t``) are tied with it; ``|o| + t`` bounds the event point's size."""
    return TIE_RELATIVE * np.maximum(1.0, np.linalg.norm(o, axis=1) + t)


def nudge_of(o: np.ndarray) -> np.ndarray:
    """How far past an event point the active box is looked up (world units along the ray)."""
    return NUDGE_RELATIVE * np.maximum(1.0, np.linalg.norm(o, axis=1))


def trace(
    geo: Geometry,
    settings: ShadingSettings,
    origin: np.ndarray,
    directions: np.ndarray,
    world_origin: np.ndarray,
    space: Space | None = None,
    lights: Lights | None = None,
) -> TraceResult:
    """Trace primary rays from ``origin`` (packed coordinates) along unit ``directions`` (N, 3).

    ``world_origin`` is the packed origin, added back where world coordinates
    matter (the triplanar checker). ``space`` holds the aberrations and portals
    (none when omitted); ``lights`` the Light entities (none: the implicit sun along ``light_dir``).
    """
    space = space or Space()
    result = TraceResult.empty(len(directions), settings.background)
    state = RayState.primary(origin, directions)
    with np.errstate(all="ignore"):
        enter_at_start(space, state)
        end = journey(geo, space, state, settings.max_events)
        result.events[:] = end.state.events
        result.color[end.kind == LIMIT] = settings.event_limit_color
        hit = np.flatnonzero(end.kind == MESH)
        if hit.size:
            _finish_mesh(geo, settings, space, end.state.subset(hit), end.mesh, hit, world_origin, result, lights)
    return result


@dataclass(frozen=True)
class JourneyEnd:
    """How each ray's journey ended (in input order): its kind, final state and mesh hit."""

    kind: np.ndarray  # (N,) MESH, MISS, LIMIT or REACHED
    state: RayState  # the state before the final event
    mesh: MeshHits  # the hit of MESH rays


def journey(
    geo: Geometry, space: Space, state: RayState, max_events: int, reach: np.ndarray | None = None
) -> JourneyEnd:
    """Run rays event after event until a mesh hit, a miss, ``max_events`` or (``reach``, world path length per
    ray) the length reached: the camera's rays and the shadow rays take the same journey."""
    n = len(state)
    kind = np.full(n, MISS, np.int64)
    mesh = MeshHits(np.full(n, np.inf), np.full(n, -1, np.int64), np.full(n, -1, np.int64), np.zeros((n, 3)))
    ended: list[RayState] = []
    while len(state):
        limited = state.events >= max_events
        if np.any(limited):
            kind[state.index[limited]] = LIMIT
            ended.append(state.subset(np.flatnonzero(limited)))
            state = state.subset(np.flatnonzero(~limited))
            if not len(state):
                break
        event = next_event(geo, space, state)
        if reach is not None:  # an event (or the sky) at or past the reach: the ray got there unblocked
            past = state.length + event.t * np.linalg.norm(state.r, axis=1) >= reach[state.index]
            event = Event(np.where(past, REACHED, event.kind), event.t, event.mesh, event.face, event.portal)
        done = np.flatnonzero((event.kind == MISS) | (event.kind == MESH) | (event.kind == REACHED))
        rows = state.index[done]
        kind[rows] = event.kind[done]
        for name in ("t", "instance", "triangle", "bary"):
            getattr(mesh, name)[rows] = getattr(event.mesh, name)[done]
        ended.append(state.subset(done))
        moving = np.flatnonzero((event.kind == ABERRATION) | (event.kind == PORTAL))
        state = advance(space, state.subset(moving), event.subset(moving))
    return JourneyEnd(kind, _in_order(ended, n), mesh)


def _in_order(parts: list[RayState], n: int) -> RayState:
    """The rays of ``parts`` (each ray in exactly one) as one state, row i the ray of index i."""
    if not parts:
        return RayState.primary(np.zeros(3), np.zeros((0, 3)))
    joined = {name: np.concatenate([vars(p)[name] for p in parts]) for name in vars(parts[0])}
    order = np.argsort(joined["index"], kind="stable")
    return RayState(**{name: value[order] for name, value in joined.items()})


#: A shadow ray starts this far (relative to the point's size, at least 1) off the surface along its
#: normal: beyond the rounding of the hit point, so the surface it leaves is never hit (float32: SHADOW_BIAS).
SHADOW_BIAS_RELATIVE = 1e-7


def shadow_rays_lit(
    geo: Geometry,
    settings: ShadingSettings,
    space: Space,
    points: np.ndarray,
    normals: np.ndarray,
    towards: np.ndarray,
    reach: np.ndarray,
) -> np.ndarray:
    """Whether each point (packed coordinates) is lit: its shadow ray, started off the surface along its
    normal towards the light, ends in the sky or past ``reach`` (docs/semantics.md, "Lights and shadows")."""
    bias = SHADOW_BIAS_RELATIVE * np.maximum(1.0, np.linalg.norm(points, axis=1))
    state = RayState.primary(points + bias[:, None] * normals, towards)
    enter_at_start(space, state)
    end = journey(geo, space, state, settings.max_events, reach)
    return (end.kind == MISS) | (end.kind == REACHED)


def enter_at_start(space: Space, state: RayState) -> None:
    """Primary rays take the transition from no box into the box at the camera (looked up just along each ray)."""
    if not len(space.boxes):
        return
    start = containing_box(space.boxes, state.o + nudge_of(state.o)[:, None] * state.r)
    state.w, state.r = transition(space.boxes, space.sigma, state.aberration, start, state.w, state.r, state.d0)
    state.aberration = start


def next_event(geo: Geometry, space: Space, state: RayState) -> Event:
    """The nearest of a linked portal quad, a mesh triangle and an aberration box face along ``r``.

    Each search skips hits with ``t <= t_min`` and the surface the ray is
    leaving. Candidates within :func:`tie_window` of the nearest are tied and
    resolved portal, then mesh, then box face: a door flush with a wall shows
    the portal, and a wall flush with a box face is hit rather than skipped
    (after a box-face event, ``t_min`` would skip the wall and the ray would
    pass through it). The mesh search is cut off where it can no longer win.
    """
    t_min = t_min_of(state.o)
    skip_face = np.where(state.leaving_kind == ABERRATION, state.leaving_id, NO_SURFACE)
    skip_portal = np.where(state.leaving_kind == PORTAL, state.leaving_id, NO_SURFACE)
    t_portal, portal = nearest_portal_hits(space.portals, state.o, state.r, t_min, skip_portal)
    t_box, face = nearest_box_faces(space.boxes, state.o, state.r, t_min, skip_face)
    t_max = np.minimum(t_portal, t_box + tie_window(state.o, t_box))
    mesh = nearest_mesh_hits(geo, state.o, state.r, t_min, t_max)
    nearest = np.minimum(np.minimum(t_portal, mesh.t), t_box)
    limit = nearest + tie_window(state.o, nearest)
    found = np.isfinite(nearest)
    kind = np.full(len(state), MISS, np.int64)
    t = np.full(len(state), np.inf)
    for candidate, t_candidate in ((ABERRATION, t_box), (MESH, mesh.t), (PORTAL, t_portal)):  # lowest precedence first
        wins = found & (t_candidate <= limit)
        kind, t = np.where(wins, candidate, kind), np.where(wins, t_candidate, t)
    return Event(kind, t, mesh, face, portal)


def advance(space: Space, state: RayState, event: Event) -> RayState:
    """Move rays to their box face or portal, add the segment to L and Λ, apply the event; ``n += 1``.

    A box face: the ray stays at the face point and is leaving that face. A
    portal: the ray continues from the target quad (:func:`backends.reference.portals.teleport`) and is
    leaving it. Either way the active box is then looked up just past the new
    origin along ``r`` and the transition rule updates ``w`` and ``r``.
    """
    if not len(state):
        return state
    step = event.t * np.linalg.norm(state.r, axis=1)
    state.length = state.length + step
    state.perceived = state.perceived + step * perceived_per_world(space.boxes, state.aberration, state.w)
    state.o = state.o + event.t[:, None] * state.r
    state.events = state.events + 1
    crossing = event.kind == ABERRATION
    state.leaving_kind = np.where(crossing, ABERRATION, PORTAL)
    state.leaving_id = np.where(crossing, event.face, event.portal)
    through = np.flatnonzero(event.kind == PORTAL)
    if through.size:
        o, r, w, d0, arrival = teleport(
            space.portals,
            event.portal[through],
            state.o[through],
            state.r[through],
            state.w[through],
            state.d0[through],
        )
        state.o[through], state.r[through], state.w[through], state.d0[through] = o, r, w, d0
        state.leaving_id[through] = arrival
    if len(space.boxes):
        active = containing_box(space.boxes, state.o + nudge_of(state.o)[:, None] * state.r)
        state.w, state.r = transition(space.boxes, space.sigma, state.aberration, active, state.w, state.r, state.d0)
        state.aberration = active
    return state


def _finish_mesh(
    geo: Geometry,
    settings: ShadingSettings,
    space: Space,
    state: RayState,
    mesh: MeshHits,
    rows: np.ndarray,
    world_origin: np.ndarray,
    out: TraceResult,
    lights: Lights | None = None,
) -> None:
    """Shade mesh hits and record L, Λ, entity id and event count (``rows`` select the hits of ``mesh``)."""
    hits = MeshHits(mesh.t[rows], mesh.instance[rows], mesh.triangle[rows], mesh.bary[rows])
    step = hits.t * np.linalg.norm(state.r, axis=1)
    position = state.o + hits.t[:, None] * state.r
    lighting = None
    if lights is not None and len(lights):

        def lit(at: np.ndarray, n: np.ndarray, towards: np.ndarray, reach: np.ndarray) -> np.ndarray:
            return shadow_rays_lit(geo, settings, space, position[at], n, towards, reach)

        def lighting(n_s: np.ndarray, n: np.ndarray) -> np.ndarray:
            return light_sum(lights, n_s, n, position, lit)

    out.color[state.index] = shade(geo, settings, hits, state.r, position + world_origin, lighting)
    out.depth[state.index] = state.length + step
    out.perceived[state.index] = state.perceived + step * perceived_per_world(space.boxes, state.aberration, state.w)
    out.instance[state.index] = geo.entity[hits.instance]
    out.events[state.index] = state.events

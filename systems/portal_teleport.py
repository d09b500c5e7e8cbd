"""Portal teleport: the camera's path this tick, tested against the linked portal quads it may pass.

The second system of a tick (docs/design.md section 6). The test is on the *segment* walked this tick, not on
the end point, so a fast camera cannot tunnel through a portal; the camera
arrives on the target quad and the target is skipped for the rest of that
segment (and a segment that starts on a quad does not cross it), so it never
oscillates; at most :data:`MAX_CROSSINGS` crossings per tick, so facing
portals terminate. Each tick tests only the quads whose bounds the segment
meets (:class:`PortalLinks`, through :class:`engine.space_index.SpaceIndex`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import esper
import numpy as np

from components import Portal, Transform
from engine.errors import SceneError
from engine.maths import quat_from_matrix, quat_to_matrix, trs_inverse, trs_matrix
from engine.scene import Scene
from engine.space_index import SpaceIndex
from systems.state import MotionRecord

#: Portal crossings allowed per tick; after the last one the camera stays where it arrived.
MAX_CROSSINGS = 4
#: Relative tolerance (of the coordinate magnitude) for "on the portal's plane".
PLANE_EPS = 1e-11


@dataclass(frozen=True)
class PortalLink:
    """A linked portal: its quad and the mapping ``X = M_target · M_self⁻¹`` into its target."""

    entity: int
    target: int
    to_local: np.ndarray  # (4, 4): world -> portal local (quad [-1, 1]^2 at z = 0)
    z_scale: float  # world length of one local z unit (plane tolerance)
    transfer: np.ndarray  # (4, 4): X
    rotation: np.ndarray  # (3, 3): rotation part of X's linear part L

    def local(self, point: np.ndarray) -> np.ndarray:
        return self.to_local[:3, :3] @ point + self.to_local[:3, 3]

    def map_point(self, point: np.ndarray) -> np.ndarray:
        return self.transfer[:3, :3] @ point + self.transfer[:3, 3]


def rotation_part(linear: np.ndarray) -> np.ndarray:
    """The rotation nearest ``linear`` (polar decomposition by SVD; a reflection's sign is dropped)."""
    u, _, vt = np.linalg.svd(linear)
    r = u @ vt
    if np.linalg.det(r) < 0.0:
        u[:, -1] = -u[:, -1]
        r = u @ vt
    return r


def portal_target(scene: Scene, entity: int, portal: Portal) -> int:
    """The entity a linked portal leads into (a SceneError naming the portal when that is no portal)."""
    assert portal.target is not None
    try:
        target = scene.entity(portal.target)
    except SceneError:
        raise SceneError(
            f"no entity is named {portal.target!r}", entity=scene.name_of(entity), field="portal.target"
        ) from None
    if not (scene.has(target, Transform) and scene.has(target, Portal)):
        raise SceneError(
            f"{portal.target!r} is not a portal (a portal's target must be another portal)",
            entity=scene.name_of(entity),
            field="portal.target",
        )
    return target


def portal_link(scene: Scene, entity: int, transform: Transform, portal: Portal) -> PortalLink | None:
    """The link of one portal entity, ``None`` for an inert one (no target)."""
    if portal.target is None:
        return None
    target = portal_target(scene, entity, portal)
    target_transform = scene.get(target, Transform)
    inverse = trs_inverse(transform.position, transform.rotation, transform.scale)
    transfer = trs_matrix(target_transform.position, target_transform.rotation, target_transform.scale) @ inverse
    return PortalLink(entity, target, inverse, abs(transform.scale[2]), transfer, rotation_part(transfer[:3, :3]))


def portal_links(scene: Scene) -> list[PortalLink]:
    """Every portal with a target, in creation order (inert portals are left out)."""
    links = [portal_link(scene, entity, t, p) for entity, (t, p) in scene.query(Transform, Portal)]
    return [link for link in links if link is not None]


class PortalLinks:
    """The scene's portal links near a segment: the quads whose bounds it meets (a
    :class:`engine.space_index.SpaceIndex` query), in creation order as :func:`portal_links` has them. A link
    is made again only when its portal or its target changed."""

    def __init__(self, scene: Scene, index: SpaceIndex | None = None) -> None:
        self.scene = scene
        self.index = index or SpaceIndex()
        self._links: dict[int, tuple[object, PortalLink | None]] = {}
        self._checked: tuple[int, int] | None = None

    def sync(self) -> PortalLinks:
        """Catch up with the scene; a portal that changed (every one, when the set changed) must lead into a
        portal, or a SceneError names it."""
        self.index.sync(self.scene)
        changed, self._checked = self.index.portals_changed(self._checked)
        for entity in changed:
            portal = self.scene.get(entity, Portal)
            if portal.target is not None:
                portal_target(self.scene, entity, portal)
        return self

    def __len__(self) -> int:
        return self.index.portal_count

    def near(self, start: np.ndarray, end: np.ndarray) -> list[PortalLink]:
        links = (self._link(entity) for entity in self.index.portals_on_segment(start, end))
        return [link for link in links if link is not None]

    def _link(self, entity: int) -> PortalLink | None:
        portal = self.scene.get(entity, Portal)
        target = None if portal.target is None else portal_target(self.scene, entity, portal)
        key = (self.index.version(entity), portal.target, None if target is None else self.index.version(target))
        cached = self._links.get(entity)
        if cached is None or cached[0] != key:
            cached = (key, portal_link(self.scene, entity, self.scene.get(entity, Transform), portal))
            self._links[entity] = cached
        return cached[1]


def _near(links: Sequence[PortalLink] | PortalLinks, start: np.ndarray, end: np.ndarray) -> Sequence[PortalLink]:
    return links.near(start, end) if isinstance(links, PortalLinks) else links


def segment_crossing(link: PortalLink, start: np.ndarray, end: np.ndarray) -> float | None:
    """Parameter in [0, 1] where the segment passes through the quad (either side), or ``None``.

    A segment that starts on the quad's plane is leaving it, not passing
    through (that is where a teleport lands); one that ends on it counts.
    """
    eps = PLANE_EPS * (1.0 + float(np.max(np.abs(start)))) / link.z_scale
    a, b = link.local(start), link.local(end)
    if abs(a[2]) <= eps:
        return None
    if abs(b[2]) > eps and (a[2] > 0.0) == (b[2] > 0.0):
        return None
    t = min(max(a[2] / (a[2] - b[2]), 0.0), 1.0) if a[2] != b[2] else 1.0
    hit = a + t * (b - a)
    if abs(hit[0]) <= 1.0 and abs(hit[1]) <= 1.0:
        return t
    return None


def first_crossing(
    links: Sequence[PortalLink] | PortalLinks, start: np.ndarray, end: np.ndarray, skip: int | None = None
) -> tuple[float, PortalLink] | None:
    """The earliest portal the segment passes through (ties: the earlier entity), skipping ``skip``."""
    best: tuple[float, PortalLink] | None = None
    for link in _near(links, start, end):
        if link.entity == skip:
            continue
        t = segment_crossing(link, start, end)
        if t is not None and (best is None or t < best[0]):
            best = (t, link)
    return best


@dataclass
class TeleportResult:
    """Where a path ends after portals, the rotation they applied, and which were crossed."""

    position: np.ndarray
    rotation: np.ndarray  # (3, 3), applied on the left of the camera's rotation
    crossings: list[PortalLink] = field(default_factory=list)


def teleport_path(
    links: Sequence[PortalLink] | PortalLinks, path: Sequence[np.ndarray], max_crossings: int = MAX_CROSSINGS
) -> TeleportResult:
    """Follow a polyline through portals: at each first crossing, map the rest of it through ``X``."""
    points = [np.asarray(p, dtype=np.float64) for p in path]
    rotation = np.eye(3)
    crossings: list[PortalLink] = []
    skip: int | None = None
    i = 0
    while i < len(points) - 1:
        hit = first_crossing(links, points[i], points[i + 1], skip if i == 0 else None)
        if hit is None:
            i += 1
            continue
        t, link = hit
        crossing = points[i] + t * (points[i + 1] - points[i])
        arrival = link.map_point(crossing)
        crossings.append(link)
        rotation = link.rotation @ rotation
        if len(crossings) >= max_crossings:
            return TeleportResult(arrival, rotation, crossings)
        points = [arrival, *(link.map_point(p) for p in points[i + 1 :])]
        skip = link.target
        i = 0
    return TeleportResult(points[-1], rotation, crossings)


class PortalTeleportProcessor(esper.Processor):
    """Teleports the camera along this tick's path (from :class:`systems.state.MotionRecord`) through linked portals."""

    def __init__(
        self, scene: Scene, motion: MotionRecord, max_crossings: int = MAX_CROSSINGS, index: SpaceIndex | None = None
    ) -> None:
        self.scene = scene
        self.motion = motion
        self.max_crossings = max_crossings
        self.links = PortalLinks(scene, index)

    def process(self, dt: float) -> None:
        entity = self.scene.camera_entity
        if entity is None or not self.motion.moved:
            return
        links = self.links.sync()
        if not links:
            return
        result = teleport_path(links, self.motion.path, self.max_crossings)
        if not result.crossings:
            return
        self.motion.crossings = [(link.entity, link.target) for link in result.crossings]
        transform = self.scene.get(entity, Transform)
        rotation = quat_from_matrix(result.rotation @ quat_to_matrix(transform.rotation))
        self.scene.set(
            entity,
            Transform(
                tuple(float(c) for c in result.position),
                tuple(float(c) for c in rotation),
                transform.scale,
            ),
        )

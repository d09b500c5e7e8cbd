"""Where a scene's portals and aberration boxes are, in world space, for the camera's walk and the editor.

The camera's movement asks which boxes hold a point and which box faces its step crosses; its teleport,
which portal quads its path passes through; the editor's picking, what a click ray meets, and its preview,
what the view's frustum holds. A loop over every portal and box per tick grows with the
scene; this index keeps two dynamic AABB trees (:class:`engine.tlas.AabbTree`, world coordinates) in
step with the scene's change journal, so a query costs what is near the camera, and a tick the entities
that changed since the last one. Each indexed entity has a version, bumped when it changes, for the
callers' caches of what they derive from it.
"""

from __future__ import annotations

import numpy as np

from components import Aberration, Portal, Transform
from engine.affine_batch import transform_arrays, trs_forward
from engine.packing_space import BOX_CORNERS, QUAD_CORNERS, corner_bounds
from engine.scene import Scene
from engine.tlas import FAT_MARGIN, SPACE_SLACK, AabbTree

#: Journal kinds that move an indexed entity or change what callers derive from it.
_PORTAL_KINDS = ("transform", "portal", "name")
_BOX_KINDS = ("transform", "aberration")
#: Changed portals kept for callers' cursors before they are asked to look at every one again.
_LOG_MAX = 65536


class _Set:
    """The entities of one kind, their rows in the tree, and the tree."""

    def __init__(self, corners: np.ndarray) -> None:
        self.corners = corners
        self.entities: list[int] = []
        self.row: dict[int, int] = {}
        self.tree = AabbTree.build(np.zeros((0, 3)), np.zeros((0, 3)), FAT_MARGIN, SPACE_SLACK)

    def bounds(self, scene: Scene, entities: list[int]) -> tuple[np.ndarray, np.ndarray]:
        if not entities:
            return np.zeros((0, 3)), np.zeros((0, 3))
        p, r, s = transform_arrays([scene.get(e, Transform) for e in entities], np.zeros(3))
        return corner_bounds(trs_forward(p, r, s), self.corners)

    def rebuild(self, scene: Scene, entities: list[int]) -> None:
        self.entities = entities
        self.row = {e: i for i, e in enumerate(entities)}
        self.tree = AabbTree.build(*self.bounds(scene, entities), FAT_MARGIN, SPACE_SLACK)

    def moved(self, scene: Scene, entities: set[int]) -> None:
        known = sorted(e for e in entities if e in self.row)
        if known:
            self.tree.update([self.row[e] for e in known], *self.bounds(scene, known))

    def pick(self, rows: list[int]) -> list[int]:
        """Entities of ``rows``, in creation order."""
        return sorted(self.entities[r] for r in rows)


class SpaceIndex:
    """World-space trees over a scene's portals and aberration boxes, synced from its journal."""

    def __init__(self) -> None:
        self._world: str | None = None
        self._cursor = -1
        self._portals = _Set(QUAD_CORNERS)
        self._boxes = _Set(BOX_CORNERS)
        self._versions: dict[int, int] = {}
        self._generation = 0
        #: Full rebuilds so far (tests and benchmarks: a tick should not cause one).
        self.rebuilds = 0
        #: Portal entities in the order syncs found them changed, since the last rebuild (callers keep a cursor).
        self._portal_log: list[int] = []

    def sync(self, scene: Scene) -> SpaceIndex:
        """Catch up with the scene's journal: rebuild when entities or components came or went, else refit the
        entities that moved. Returns the index."""
        changes = None if self._world != scene.world else scene.changes_since(self._cursor)
        if changes is None or any(c.kind in ("structure", "assets") for c in changes):
            self._rebuild(scene)
        else:
            portals = {c.entity for c in changes if c.kind in _PORTAL_KINDS and c.entity in self._portals.row}
            boxes = {c.entity for c in changes if c.kind in _BOX_KINDS and c.entity in self._boxes.row}
            for entity in portals | boxes:
                self._versions[entity] = self._versions.get(entity, 0) + 1
            self._portals.moved(scene, portals)
            self._boxes.moved(scene, boxes)
            self._portal_log += sorted(portals)
            if len(self._portal_log) > _LOG_MAX:  # callers then look at every portal once, as after a rebuild
                self._generation += 1
                self._portal_log = []
        self._world = scene.world
        self._cursor = scene.cursor
        return self

    def _rebuild(self, scene: Scene) -> None:
        self._portals.rebuild(scene, [e for e, _ in scene.query(Transform, Portal)])
        self._portal_log = []
        self._boxes.rebuild(scene, [e for e, _ in scene.query(Transform, Aberration)])
        # Every version moves on: what callers derived before may refer to entities that are gone.
        self._generation += 1
        self._versions = {}
        self.rebuilds += 1

    def portals_changed(self, since: tuple[int, int] | None) -> tuple[list[int], tuple[int, int]]:
        """The portal entities changed after the cursor ``since`` (every one when the index was rebuilt since,
        or for ``None``), and the cursor to pass next time."""
        cursor = (self._generation, len(self._portal_log))
        if since is None or since[0] != self._generation:
            return list(self._portals.entities), cursor
        return sorted(set(self._portal_log[since[1] :])), cursor

    def version(self, entity: int) -> tuple[int, int]:
        """Changes whenever the entity changed (or the index was rebuilt) since a caller last looked."""
        return (self._generation, self._versions.get(entity, 0))

    # --- queries ------------------------------------------------------------------------------

    def portals_on_segment(self, start: np.ndarray, end: np.ndarray) -> list[int]:
        """Portal entities whose quad the segment may pass through (a superset), in creation order."""
        return self._portals.pick(self._portals.tree.rows_on_segment(start, end))

    def boxes_at(self, point: np.ndarray) -> list[int]:
        """Aberration entities whose box may hold ``point`` (a superset), in creation order."""
        return self._boxes.pick(self._boxes.tree.rows_at(point))

    def boxes_on_segment(self, start: np.ndarray, end: np.ndarray) -> list[int]:
        """Aberration entities whose box the segment may meet (a superset), in creation order."""
        return self._boxes.pick(self._boxes.tree.rows_on_segment(start, end))

    def portals_on_ray(self, origin: np.ndarray, direction: np.ndarray, t_max: float = np.inf) -> list[int]:
        """Portal entities whose quad the ray may cross within ``t_max`` (a superset), in creation order."""
        return self._portals.pick(self._portals.tree.rows_on_ray(origin, direction, t_max))

    def boxes_on_ray(self, origin: np.ndarray, direction: np.ndarray, t_max: float = np.inf) -> list[int]:
        """Aberration entities whose box the ray may meet within ``t_max`` (a superset), in creation order."""
        return self._boxes.pick(self._boxes.tree.rows_on_ray(origin, direction, t_max))

    def portals_in_planes(self, planes: np.ndarray) -> list[int]:
        """Portal entities whose quad may lie inside the planes (a view's frustum; a superset), in creation order."""
        return self._portals.pick(self._portals.tree.rows_in_planes(planes))

    def boxes_in_planes(self, planes: np.ndarray) -> list[int]:
        """Aberration entities whose box may reach inside the planes (a superset), in creation order."""
        return self._boxes.pick(self._boxes.tree.rows_in_planes(planes))

    @property
    def portal_count(self) -> int:
        return len(self._portals.entities)

    @property
    def box_count(self) -> int:
        return len(self._boxes.entities)

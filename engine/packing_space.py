"""Packing portal quads and aberration boxes: their rows (``portals``, ``aberrations``) and the trees over them
(``space_nodes``), one entity at a time.

The kernels find the portal a ray passes, the box face it crosses and the box that holds a point through two
dynamic AABB trees (:class:`engine.tlas.AabbTree`), one over the portals' quads, one over the boxes, stored one
after the other in ``space_nodes`` (roots in the settings' ``space_roots``), then each tree's 4-wide form
(:mod:`engine.space_wide`, which OpenCL's ray walks take). A moved portal or box re-packs its own row (and, for
a portal, the rows of the portals that lead into it) and refits its leaf's path, in both forms, only when it
left its fat box; the tree is rebuilt, and every row re-packed, only when the set changes. Boxes keep their
clearances and portals their gaps to each other (:class:`engine.clearances.BoxClearances`, a quad as a thin
box) in step with the moves.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np

from components import Aberration, Portal, Transform
from engine import layout
from engine.affine_batch import compose_affine, transform_arrays, trs_forward, trs_inverse_batch
from engine.clearances import BoxClearances
from engine.packed import PackedScene, TableUpdate
from engine.records import Precision
from engine.scene import Scene
from engine.space_wide import ROWS, WideTree, reserved_rows
from engine.tlas import FAT_MARGIN, SPACE_SLACK, AabbTree

#: Corners of a portal's quad ([-1, 1]^2 at z = 0) and of an aberration's unit box, in their local frames.
QUAD_CORNERS = np.array([[x, y, 0.0] for x in (-1.0, 1.0) for y in (-1.0, 1.0)])
BOX_CORNERS = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
#: Half the thickness a portal quad gets as a solid for its gap to the others, in its local units.
QUAD_THICKNESS = 1e-6
#: A portal's world-to-local rows scaled to the unit box's [-0.5, 0.5] (the quad's [-1, 1], its plane
#: +-QUAD_THICKNESS).
QUAD_AS_BOX = np.array([0.5, 0.5, 0.5 / QUAD_THICKNESS])[:, None]


def corner_bounds(forward: np.ndarray, corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World bounds (n, 3) of ``corners`` (k, 3) mapped by the affine maps ``forward`` (n, 3, 4)."""
    world = np.einsum("nij,kj->nki", forward[:, :, :3], corners) + forward[:, None, :, 3]
    return world.min(axis=1), world.max(axis=1)


def _order_boxes(scene: Scene) -> list[int]:
    """Aberration entities in row order: by priority, then entity (the last containing row wins)."""
    rows = scene.query(Aberration)
    return [entity for entity, _ in sorted(rows, key=lambda row: (row[1].priority, row[0]))]


@dataclass
class _Rows:
    """Which entity each row holds, and the inverse."""

    entities: list[int]
    row: dict[int, int]

    @staticmethod
    def of(entities: list[int]) -> _Rows:
        return _Rows(entities, {e: i for i, e in enumerate(entities)})

    def __len__(self) -> int:
        return len(self.entities)


class SpaceTables:
    """The ``portals``, ``aberrations`` and ``space_nodes`` tables of a :class:`engine.packed.PackedScene`,
    kept per entity."""

    def __init__(self, precision: Precision, margin: float = FAT_MARGIN) -> None:
        self.precision: Precision = precision
        self.margin = margin
        self.portals = _Rows.of([])
        self.boxes = _Rows.of([])
        self.portal_tree = AabbTree.build(np.zeros((0, 3)), np.zeros((0, 3)), margin, SPACE_SLACK)
        self.box_tree = AabbTree.build(np.zeros((0, 3)), np.zeros((0, 3)), margin, SPACE_SLACK)
        #: The trees' 4-wide forms for the kernels' ray walks, stored after both binary trees.
        self._wide = (WideTree(self.portal_tree.nodes, 0), WideTree(self.box_tree.nodes, 0))
        #: Portal rows leading into each portal row (their transfer holds its transform).
        self._sources: dict[int, set[int]] = {}
        #: Per portal row its packed target row; per box row its packed priority and mode.
        self._targets: list[int] = []
        self._priorities: list[int] = []
        self._box_modes: list[str] = []
        self._modes: Counter[str] = Counter()
        self._linked = 0
        #: The boxes' clearances to the instances and to each other (rotation rows' w).
        self.clearances = BoxClearances()
        #: Each portal quad's gap to every other one (meta.z), kept as the boxes' gaps are.
        self.portal_gaps = BoxClearances()

    # --- what the packer asks ----------------------------------------------------------------

    @property
    def box_root(self) -> int:
        """The row of the boxes' tree's root in ``space_nodes`` (the portals' tree comes first)."""
        return self.portal_tree.count

    @property
    def wide_roots(self) -> tuple[int, int]:
        """The rows in ``space_nodes`` of the portals' and the boxes' 4-wide roots (engine/space_wide.py), after
        both binary trees. Each wide tree has the rows its set's size reserves, so they stay put while the set
        does."""
        portals = self.portal_tree.count + self.box_tree.count
        return portals, portals + reserved_rows(len(self.portals))

    @property
    def modes(self) -> frozenset[str]:
        """The aberration modes in use."""
        return frozenset(mode for mode, n in self._modes.items() if n > 0)

    @property
    def linked(self) -> bool:
        """Whether any portal has a target."""
        return self._linked > 0

    def full(self, scene: Scene, packed: PackedScene, instances: tuple[np.ndarray, np.ndarray]) -> None:
        """Pack every portal and box row and build both trees (the set changed, or the first sync)."""
        self.portals = _Rows.of([entity for entity, _ in scene.query(Transform, Portal)])
        self.boxes = _Rows.of([e for e in _order_boxes(scene) if scene.has(e, Transform)])
        self._full_portals(scene, packed)
        self._full_boxes(scene, packed, instances)
        self._store_nodes(packed)

    def translate(self, scene: Scene, packed: PackedScene, delta: np.ndarray, instances: tuple) -> list[TableUpdate]:
        """The packed origin moved by ``delta``: every row again, the trees shifted with them."""
        lo, hi = self._pack_portal_rows(scene, packed, list(range(len(self.portals))))
        self.portal_tree.translate(delta, lo, hi)
        self._store_portal_gaps(packed, self.portal_gaps.full(*self._portal_solids(packed)))
        lo, hi = self._pack_box_rows(scene, packed, list(range(len(self.boxes))))
        self.box_tree.translate(delta, lo, hi)
        self._store_clearances(packed, self.clearances.full(self._box_matrices(packed), *instances))
        self._store_nodes(packed)
        return [TableUpdate("portals"), TableUpdate("aberrations"), TableUpdate("space_nodes")]

    def update(
        self,
        scene: Scene,
        packed: PackedScene,
        portals: set[int],
        boxes: set[int],
        instances: tuple[np.ndarray, np.ndarray],
        moved_instances: list[int],
    ) -> list[TableUpdate] | None:
        """Re-pack the rows of the changed ``portals`` and ``boxes`` (entities) and refit their leaves; the
        boxes' clearances after those boxes and the instance rows ``moved_instances`` moved. Returns the
        updates, or ``None`` when the rows must be packed anew (a box's priority changed its row's place)."""
        updates: list[TableUpdate] = []
        if boxes and any(self._reordered(scene, e) for e in boxes):
            return None
        if portals:
            moved = sorted({self.portals.row[e] for e in portals if e in self.portals.row})
            rows = sorted(set(moved).union(*(self._sources.get(r, set()) for r in moved)))
            lo, hi = self._pack_portal_rows(scene, packed, rows)
            updates += [TableUpdate("portals", range(r, r + 1)) for r in rows]
            updates += self._refit(packed, self.portal_tree, rows, lo, hi, 0)
            gaps = self._store_portal_gaps(packed, self.portal_gaps.moved(*self._portal_solids(packed), moved, []))
            updates += [u for u in gaps if u.rows is None or u.rows.start not in rows]  # not uploaded twice
        box_rows = sorted(self.boxes.row[e] for e in boxes if e in self.boxes.row)
        if box_rows:
            lo, hi = self._pack_box_rows(scene, packed, box_rows)
            updates += [TableUpdate("aberrations", range(r, r + 1)) for r in box_rows]
            updates += self._refit(packed, self.box_tree, box_rows, lo, hi, self.box_root)
        if len(self.boxes) and (box_rows or moved_instances):
            changed = self.clearances.moved(self._box_matrices(packed), *instances, box_rows, moved_instances)
            updates += self._store_clearances(packed, changed)
        return updates

    # --- portals ----------------------------------------------------------------------------------

    def _full_portals(self, scene: Scene, packed: PackedScene) -> None:
        n = len(self.portals)
        packed.counts["portals"] = n
        packed.tables["portals"] = np.zeros(max(n, 1), dtype=layout.portal_dtype(self.precision))
        self._sources = {}
        self._targets = [-1] * n
        self._linked = 0
        lo, hi = self._pack_portal_rows(scene, packed, list(range(n)))
        self.portal_tree = AabbTree.build(lo, hi, self.margin, SPACE_SLACK)
        self.portal_gaps = BoxClearances()
        self._store_portal_gaps(packed, self.portal_gaps.full(*self._portal_solids(packed)))

    def _portal_solids(self, packed: PackedScene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The portal quads as the boxes' clearances take solids: each a unit box's world-to-local map, its
        quad's plane thickened by :data:`QUAD_THICKNESS` local units (a thicker solid only lowers the gap),
        and no instances."""
        m = packed.tables["portals"]["world_to_local"][: len(self.portals)].astype(np.float64)
        return m * QUAD_AS_BOX, np.zeros((0, 3)), np.zeros((0, 3))

    def _store_portal_gaps(self, packed: PackedScene, rows: list[int]) -> list[TableUpdate]:
        """Write the gaps of portal ``rows`` into their meta.z as float32 bits, rounded down; the rows whose
        bytes changed."""
        meta = packed.tables["portals"]["meta"]
        updates = []
        for row in rows:
            gap = np.float32(self.portal_gaps.box[row])
            if float(gap) > self.portal_gaps.box[row]:
                gap = np.nextafter(gap, np.float32(0.0))
            bits = int(gap.view(np.int32))
            if meta[row, 2] != bits:
                meta[row, 2] = bits
                updates.append(TableUpdate("portals", range(row, row + 1)))
        return updates

    def _target_row(self, scene: Scene, portal: Portal) -> int:
        return -1 if portal.target is None else self.portals.row[scene.entity(portal.target)]

    def _pack_portal_rows(self, scene: Scene, packed: PackedScene, rows: list[int]) -> tuple[np.ndarray, np.ndarray]:
        """Pack portal ``rows``; returns their quads' world bounds (camera-relative)."""
        table = packed.tables["portals"]
        if not rows:
            return np.zeros((0, 3)), np.zeros((0, 3))
        entities = [self.portals.entities[r] for r in rows]
        transforms = [scene.get(e, Transform) for e in entities]
        p, r, s = transform_arrays(transforms, packed.origin)
        forward, inverse = trs_forward(p, r, s), trs_inverse_batch(p, r, s)
        table["world_to_local"][rows] = inverse
        targets = np.array([self._target_row(scene, scene.get(e, Portal)) for e in entities], dtype=np.int64)
        transfer = np.zeros((len(rows), 3, 4))
        transfer[:, :, :3] = np.eye(3)
        linked = np.flatnonzero(targets >= 0)
        if linked.size:
            tp, tr, ts = transform_arrays([scene.get(self.portals.entities[t], Transform) for t in targets[linked]],
                                          packed.origin)  # fmt: skip
            transfer[linked] = compose_affine(trs_forward(tp, tr, ts), inverse[linked])
        table["transfer"][rows] = transfer
        for row, target, entity in zip(rows, targets.tolist(), entities, strict=True):
            old = self._targets[row]
            if old >= 0:
                self._sources[old].discard(row)
                self._linked -= 1
            if target >= 0:
                self._sources.setdefault(target, set()).add(row)
                self._linked += 1
            self._targets[row] = target
            table["meta"][row] = (target, entity, table["meta"][row, 2], 0)  # z: the gap, kept
        return corner_bounds(forward, QUAD_CORNERS)

    # --- boxes ------------------------------------------------------------------------------------

    def _full_boxes(self, scene: Scene, packed: PackedScene, instances: tuple[np.ndarray, np.ndarray]) -> None:
        n = len(self.boxes)
        packed.counts["aberrations"] = n
        packed.tables["aberrations"] = np.zeros(max(n, 1), dtype=layout.aberration_dtype(self.precision))
        self._modes = Counter()
        self._priorities = [0] * n
        self._box_modes = [""] * n
        lo, hi = self._pack_box_rows(scene, packed, list(range(n)))
        self.box_tree = AabbTree.build(lo, hi, self.margin, SPACE_SLACK)
        self.clearances = BoxClearances()
        if n:
            self._store_clearances(packed, self.clearances.full(self._box_matrices(packed), *instances))

    def _reordered(self, scene: Scene, entity: int) -> bool:
        """Whether a changed box no longer sits in its row's place (its priority changed), or is new."""
        row = self.boxes.row.get(entity)
        if row is None:
            return scene.has(entity, Aberration) and scene.has(entity, Transform)
        return scene.get(entity, Aberration).priority != self._priorities[row]

    def _pack_box_rows(self, scene: Scene, packed: PackedScene, rows: list[int]) -> tuple[np.ndarray, np.ndarray]:
        """Pack box ``rows`` but their clearances; returns their world bounds (camera-relative)."""
        table = packed.tables["aberrations"]
        if not rows:
            return np.zeros((0, 3)), np.zeros((0, 3))
        entities = [self.boxes.entities[r] for r in rows]
        p, r, s = transform_arrays([scene.get(e, Transform) for e in entities], packed.origin)
        table["world_to_local"][rows] = trs_inverse_batch(p, r, s)
        table["rotation"][rows, :, :3] = r
        for row, entity in zip(rows, entities, strict=True):
            ab = scene.get(entity, Aberration)
            table["deformation"][row, :3] = ab.deformation
            mode, exit_rule = layout.ABERRATION_MODES[ab.mode], layout.ABERRATION_EXITS[ab.exit]
            table["meta"][row] = (mode, exit_rule, ab.priority, entity)
            if self._box_modes[row]:
                self._modes[self._box_modes[row]] -= 1
            self._modes[ab.mode] += 1
            self._box_modes[row] = ab.mode
            self._priorities[row] = ab.priority
        return corner_bounds(trs_forward(p, r, s), BOX_CORNERS)

    def _box_matrices(self, packed: PackedScene) -> np.ndarray:
        return packed.tables["aberrations"]["world_to_local"][: len(self.boxes)]

    def _store_clearances(self, packed: PackedScene, rows: list[int]) -> list[TableUpdate]:
        """Write the clearances of box ``rows`` into their rotation rows' w; the rows whose bytes changed."""
        table = packed.tables["aberrations"]
        updates = []
        for row in rows:
            instance, box = self.clearances.instance[row], self.clearances.box[row]
            if table["rotation"][row, 0, 3] != instance or table["rotation"][row, 1, 3] != box:
                table["rotation"][row, 0, 3] = instance
                table["rotation"][row, 1, 3] = box
                updates.append(TableUpdate("aberrations", range(row, row + 1)))
        return updates

    # --- the trees --------------------------------------------------------------------------------

    def _refit(
        self, packed: PackedScene, tree: AabbTree, rows: list[int], lo: np.ndarray, hi: np.ndarray, base: int
    ) -> list[TableUpdate]:
        """A tree after ``rows`` got bounds ``lo``/``hi``: its changed node rows in ``space_nodes`` (at ``base``)."""
        changed = tree.update(rows, lo, hi)
        if changed is None:
            self._store_nodes(packed)
            return [TableUpdate("space_nodes")]
        table = packed.tables["space_nodes"]
        for node in changed:
            table[base + node] = self._offset(tree.nodes[node : node + 1], base)[0]
        updates = [TableUpdate("space_nodes", range(base + n, base + n + 1)) for n in changed]
        which = 0 if tree is self.portal_tree else 1
        wide, at = self._wide[which], self.wide_roots[which]
        for w in wide.changed(changed):
            start = at + ROWS * w
            table[start : start + ROWS] = wide.rows(tree.nodes, at, [w])
            updates.append(TableUpdate("space_nodes", range(start, start + ROWS)))
        return updates

    @staticmethod
    def _offset(nodes: np.ndarray, base: int) -> np.ndarray:
        """Node rows as stored at ``base``: interior nodes' children move with them, leaves keep their row."""
        out = nodes.copy()
        out["first"] += np.where(out["count"] == 0, base, 0).astype(out["first"].dtype)
        return out

    def _store_nodes(self, packed: PackedScene) -> None:
        portal, box = self.portal_tree, self.box_tree
        self._wide = (WideTree(portal.nodes, portal.count), WideTree(box.nodes, box.count))
        parts = [portal.nodes[: portal.count], self._offset(box.nodes[: box.count], self.box_root)]
        sizes = (len(self.portals), len(self.boxes))
        for tree, wide, at, n in zip((portal, box), self._wide, self.wide_roots, sizes, strict=True):
            part = np.zeros(reserved_rows(n), layout.SPACE_NODE_DTYPE)
            rows = wide.rows(tree.nodes, at)
            part[: len(rows)] = rows
            parts.append(part)
        nodes = np.concatenate(parts)
        packed.counts["space_nodes"] = len(nodes)
        packed.tables["space_nodes"] = nodes if len(nodes) else np.zeros(1, layout.SPACE_NODE_DTYPE)
